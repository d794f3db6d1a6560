// report_device.h - a haptic device that talks in reports over a link (hidapi, or a
// Unix-domain socket to isotouch-devemu): the link and protocol interfaces, and the device
// with its reader and writer threads. The servo thread only touches two latest-value cells.
#pragma once
#include "isotouch/servo/core_names.h"
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>

#include "isotouch/servo/device_io.h"
#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/stall_rule.h"

namespace isotouch::servo {

/// A byte link to a device: one whole report per read or write. Used by the device's
/// reader and writer threads (never the servo's). Only the reader thread opens and closes.
/// ReportDevice never runs two of open, close, read, write and get_feature at once (hidapi
/// keeps state per handle, its error string, that both hid_read and hid_write free and
/// replace); only wait_readable() runs beside them.
class ReportLink {
 public:
  virtual ~ReportLink() = default;
  /// "hid:1234:0006", "emu:/tmp/devemu.sock" (for messages).
  virtual std::string name() const = 0;
  /// Opens or reopens the link; "" on success, else why not.
  virtual std::string open() = 0;
  virtual void close() = 0;
  /// One report into `buf`, waiting at most `timeout_ms`: its size; 0 on timeout; -1 if
  /// the link is down (EOF, unplugged).
  virtual int read(std::span<std::uint8_t> buf, int timeout_ms) = 0;
  /// Waits at most `timeout_ms` for a report to read without reading it, touching nothing
  /// the other calls use (it runs beside write()): false on timeout; true if one may be
  /// there or the link is down (read() then says which). Default, for links that cannot
  /// wait apart from a read (hidapi): sleeps kPollUs and returns true.
  virtual bool wait_readable(int timeout_ms);
  static constexpr int kPollUs = 50;  ///< the default wait [us]: a report waits this long at most
  /// Sends one report (byte 0: the report ID, 0 for devices without IDs). False if down.
  virtual bool write(std::span<const std::uint8_t> report) = 0;
  /// Reads feature report `id` into `buf` (byte 0 = id): its size, or -1.
  virtual int get_feature(std::uint8_t id, std::span<std::uint8_t> buf) = 0;
};

/// How a device's reports are read and written. decode_input() runs on the reader thread,
/// encode_output() on the writer thread (implementations keep shared state in atomics).
class DeviceProtocol {
 public:
  virtual ~DeviceProtocol() = default;
  virtual const char* name() const = 0;
  /// Whether input reports carry sequence numbers (counted for gaps, duplicates, reordering).
  virtual bool sequenced() const { return true; }
  /// After (re)opening: reads the capabilities; "" or why the device is refused.
  virtual std::string handshake(ReportLink& link, DeviceCaps& caps) = 0;
  /// One input report -> `r` (position, buttons, sequence, device time, status); "" or
  /// why it is refused (garbage).
  virtual std::string decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) = 0;
  /// The report that commands `force_n` [N, device] (enable false: zero force, disabled);
  /// `answers`: the input sequence the force was computed from. Returns the size in `buf`.
  virtual std::size_t encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                                    std::span<std::uint8_t> buf) = 0;
  /// A report to send after decode_input() when the device asked for something (Polhem:
  /// calibration); 0 = none.
  virtual std::size_t pending_command(std::span<std::uint8_t> buf) {
    (void)buf;
    return 0;
  }
  /// Why decode_input() set DeviceStatus::kFault or kUncalibrated, when the protocol itself
  /// found it (Polhem: not calibrated yet, or the unit is not of the configured kinematics);
  /// "" otherwise. Reader thread (the view lives until the next decode_input()); noted as the
  /// device's last refusal (the host refuses to drive it) once per run of such readings and
  /// again whenever the reason changes (not calibrated, then of the other kinematics); the
  /// note is taken back (last_refusal() and last_error() "" again, unless something else was
  /// noted since) by the first reading that is neither.
  virtual std::string_view fault() const { return {}; }
};

/// Counters of the link (reader and writer threads; any thread may read).
struct LinkCounters {
  long reports = 0;     ///< input reports accepted
  long garbage = 0;     ///< input reports refused by the protocol
  long gaps = 0;        ///< input reports missing by their sequence numbers
  long duplicates = 0;  ///< input reports with the sequence number of the previous one (dropped)
  long reordered = 0;   ///< input reports older than one already accepted (dropped)
  long disconnects = 0; ///< times the link went down
  long reconnects = 0;  ///< times it came back
  long writes = 0;      ///< output reports sent
  long write_errors = 0;
  long watchdog_trips = 0;  ///< input reports that raised the device's watchdog flag (its force was zeroed)
  long busy_reads = 0;   ///< read()s that found a store in progress too long and kept the last reading
  long stalls = 0;      ///< times the writer took the force off because the servo stopped writing
};

struct ReportDeviceOptions {
  double reconnect_interval_s = 0.05;  ///< between attempts to reopen a link that is down [s]
  double write_poll_us = 20;           ///< the writer looks for a new force this often [us] while one is due (WriteInterval)
  /// With nothing new to send, resend the current output this often [s]: the servo's last
  /// force while it writes, zero with enable cleared once it stalled.
  double keepalive_s = 0.01;
  /// The stall time when enable_force() is given none [s].
  double default_stall_s = 0.01;
  /// > 0: the reader and writer threads ask for SCHED_FIFO at this priority (below the
  /// servo's 80: they feed it). Refused (no CAP_SYS_NICE): they run under the default
  /// scheduler, said by realtime_note().
  int fifo_priority = 0;
};

/// When the device's writer thread looks for the servo's next write: the servo writes once
/// a tick, so the writer learns the interval between writes (the shortest of the last 8, per
/// write when it saw several at once) and sleeps until a lead of max(3 polls, 1/8 interval)
/// before the next is due, then polls. Times are CLOCK_MONOTONIC [ns]. Writer thread only.
class WriteInterval {
 public:
  /// The writer saw `writes` new writes (the count's step) at `t_ns`. One found on the first
  /// look after sleeping to the window, past its due time, counts as written when due (the
  /// writer woke late: its lateness does not carry into the next window).
  void saw(std::int64_t t_ns, std::uint64_t writes);
  /// The interval between writes [ns]; 0 before two were seen.
  std::int64_t estimate_ns() const;
  /// When to look next, at `now_ns`: `now_ns + poll_ns` without an estimate or inside the
  /// window, else the window's start (the last write + interval - lead).
  std::int64_t next_look_ns(std::int64_t now_ns, std::int64_t poll_ns);

 private:
  std::array<std::int64_t, 8> ring_{};
  std::size_t next_ = 0;
  std::int64_t last_ns_ = -1;  // when the last write seen is taken to be written
  bool slept_ = false;         // the last next_look_ns() slept to the window (not a poll)
};

/// A device behind a ReportLink and a DeviceProtocol. open() connects and reads the
/// capabilities (failure: std::runtime_error naming the link and the reason); then a reader
/// thread publishes each accepted input report (DeviceReading, received_ns = arrival) into a
/// latest-value cell that read() loads, and a writer thread sends each force the servo
/// wrote (the servo makes no syscall: the writer polls every write_poll_us from shortly
/// before the write its WriteInterval predicts, asleep until then). Once the servo has not
/// written for the stall time enable_force() was given, the writer sends zero force with
/// enable cleared (counted: LinkCounters::stalls) until a write made after the servo could
/// see that count; the first such write is sent as zero (the servo ramps in from 0). A link that
/// goes down publishes kDisconnected at once and is reopened every reconnect_interval_s; a
/// reopened link increments DeviceReading::connection (the servo ramps the force in). Refused
/// reports, sequence gaps, duplicates and reordering are counted; the last refusal's
/// reason is kept (last_error()).
class ReportDevice final : public HapticDeviceIO {
 public:
  ReportDevice(std::unique_ptr<ReportLink> link, std::unique_ptr<DeviceProtocol> protocol,
               ReportDeviceOptions options = {});
  ~ReportDevice() override;  ///< close()
  /// Connects, reads the capabilities, starts the threads and waits for the first input
  /// report (1 s at most). @throws std::runtime_error naming the link and the reason.
  void open();
  /// Sends a disabled zero force, stops the threads, closes the link. Idempotent.
  void close();

  // HapticDeviceIO (servo thread: loads and stores of latest-value cells only).
  Vec3 read_position_m() override { return read().position_m; }
  std::uint32_t buttons() override { return read().buttons; }
  /// The newest reading, or the last one this thread read if the reader thread was
  /// preempted inside a store (counted: LinkCounters::busy_reads). One thread (the servo).
  DeviceReading read() override {
    reading_.load(last_read_);
    return last_read_;
  }
  void write_force_n(const Vec3& force_n) override;
  void answer(std::uint64_t sequence) override { answers_ = sequence; }
  DeviceCaps caps() const override;
  /// Returns the writer's stall count (LinkCounters::stalls).
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override;

  LinkCounters counters() const;
  std::string last_error() const;    ///< why the link last dropped or a report was last refused ("" none)
  /// Why the last refused report (or the device, by its protocol's fault(), while it lasts)
  /// was refused ("" none).
  std::string last_refusal() const;
  std::string name() const { return link_->name(); }
  /// "" or a warning about the device's capabilities (no watchdog), valid after open().
  std::string warning() const { return warning_; }
  /// "" or why the I/O threads did not get SCHED_FIFO (valid after open()).
  std::string realtime_note() const;

 private:
  void reader_loop();
  void ask_fifo();
  void writer_loop();
  bool reconnect();
  void accept(const DeviceReading& r);
  void link_down(const std::string& why);
  void note(const std::string& error, bool refusal = false);
  /// Takes back a note of `error` (last_refusal(), last_error()) if nothing was noted since.
  void unnote(const std::string& error);
  bool send(std::span<const std::uint8_t> report);

  std::unique_ptr<ReportLink> link_;
  std::unique_ptr<DeviceProtocol> protocol_;
  ReportDeviceOptions opt_;
  DeviceCaps caps_;
  LatestValue<DeviceReading> reading_;
  StallRule rule_;                          // the servo's force and the stall rule (stall_rule.h)
  std::uint64_t answers_ = 0;               // servo thread only
  DeviceReading last_read_;                 // servo thread only: read()'s fallback
  std::atomic<bool> stop_{false}, up_{false};
  std::uint32_t connection_ = 0;            // reader thread
  std::uint32_t last_sequence_ = 0;         // reader thread
  bool have_sequence_ = false;              // reader thread: last_sequence_ is set
  std::string fault_noted_;                 // reader thread: the protocol's fault() last noted ("": none in this run of faults)
  bool tripped_ = false;                    // reader thread: the last report had the watchdog flag
  mutable std::mutex link_mu_;              // every link call but wait_readable (not the servo)
  mutable std::mutex note_mu_;
  std::string last_error_, last_refusal_, realtime_note_;
  std::string warning_;  // set by open() before the threads start
  std::atomic<long> reports_{0}, garbage_{0}, gaps_{0}, duplicates_{0}, reordered_{0}, disconnects_{0},
      reconnects_{0}, sent_{0}, write_errors_{0}, watchdog_trips_{0};
  std::thread reader_, writer_;
};

}  // namespace isotouch::servo
