#include "isotouch/session/live_session.h"

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/spsc_ring.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/exit_zero.h"

#include "isotouch/core/exit_codes.h"

#include <fcntl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <stdexcept>

#include "isotouch/io/output_file.h"

namespace isotouch::session {
namespace {

// The servo's clock (CLOCK_MONOTONIC, as steady_clock on Linux): tick times and submit() times compare.
std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// observe() reads Observed through servo::LatestValue, which holds trivially copyable values.
static_assert(std::is_trivially_copyable_v<Observed>);

/// What an exception says (one that is not a std::exception: that it is not).
std::string what_of(const std::exception_ptr& p) {
  try {
    std::rethrow_exception(p);
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "an exception that is not a std::exception";
  }
}

std::string os_error(const std::string& path, const char* what) {
  return path + ": " + what + ": " + std::strerror(errno);
}

io::RecordedTick recorded(const servo::TickRecord& r, double t_s) {
  io::RecordedTick t;
  t.t_s = t_s;
  t.dt_s = r.dt_s;
  t.hip_m = r.hip_m;
  t.button = (r.buttons & 1u) != 0;
  t.force_n = r.out.force_n;
  t.vhip_m = r.out.vhip_m;
  t.version = r.version;
  t.fault = r.out.fault;
  t.held = r.paused || r.device_status != servo::DeviceStatus::kOk;
  t.reset = r.reset;
  if (r.passivity_clock_s >= 0) {
    t.passivity_clock_s = r.passivity_clock_s;
    t.sent_n = r.force_sent_n;
  }
  return t;
}

}  // namespace

// The session's state and threads (live_session.h keeps only a pointer to it). It is the
// servo thread's TickObserver itself: a tick calls Impl::on_tick through the one virtual
// call it always made, not through LiveSession.
class LiveSession::Impl final : private servo::TickObserver {
 public:
  Impl(EditSession& edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
       servo::HapticDeviceIO& device, LiveSessionConfig config);
  Impl(EditSession* edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
       LiveSessionConfig config);
  ~Impl();
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  std::string start();
  void pause(bool paused) {
    if (servo_) servo_->pause(paused);
  }
  void stop();
  std::vector<sim::TraceRow> run_simulated(const SimulatedRun& run);
  std::vector<sim::TraceRow> step_simulated(const SimulatedRun& run, long ticks);
  void finish_simulated();
  bool submit(const EditEvent& e);
  Observed observe() const;
  double elapsed_s() const;
  LiveStats stats(std::size_t latency_tail) const;
  const servo::ServoThread* servo_thread() const { return servo_.get(); }

 private:
  struct Request {            // an edit on its way to the edit thread
    EditEvent event;
    std::int64_t asked_ns = 0;  // when it was asked for (tick start or submit())
  };
  // Applies one request (stroke nesting, listener, counters); `rethrow`: simulated mode.
  void apply_request(Request& q, EditSource source, long ticks_done, bool rethrow);
  void notify(const EditEvent& e, const EditOutcome& out, EditSource source, bool rethrow);
  std::int64_t clock_ns() const;
  void on_tick(const servo::TickRecord& r) noexcept override;
  void edit_loop();
  void resolve_seen_locked() const;
  void wake_edit_thread();  // API side: submit(), stop()
  void record_loop();
  void record_chunk(bool final);
  void publish_observed(const servo::TickRecord& r) noexcept;

  void open_recording();
  void finish_recording();  // end record, fsync, rename (after the producers stopped)
  void drain_simulated(long ticks_done);
  void begin_simulated(bool stepped);
  // The session's side of simulated tick k (its row already rendered): the tick record, the
  // after-tick hook, the observer, the queued edits, the recorder's chunk.
  void simulated_tick(const SimulatedRun& run, long k, sim::TraceRow& row);

  EditSession* edits_;  // null: nothing to edit
  servo::TripleBuffer<core::SampleField>& buffer_;
  servo::Renderer& renderer_;
  LiveSessionConfig cfg_;
  std::unique_ptr<servo::ServoThread> servo_;  // null: simulated only
  servo::SpscRing<servo::TickRecord> ticks_;
  servo::SpscRing<Request> servo_edits_, api_edits_;
  // submit() wakes the edit thread at once (the servo side cannot: no syscall in a tick, so
  // the edit thread also looks at the servo's ring every 0.2 ms).
  std::mutex wake_mu_;
  std::condition_variable wake_cv_;
  bool api_pending_ = false;  // guarded by wake_mu_
  std::atomic<bool> running_{false}, stop_edits_{false}, stop_recorder_{false};
  std::thread edit_thread_, record_thread_;
  std::int64_t start_ns_ = 0;
  // Simulated mode: the simulated clock (start of the current tick) and ticks run.
  bool simulated_ = false;
  bool stepped_ = false;   // simulated by step_simulated()
  bool finished_ = false;  // finish_simulated() ran: no more ticks
  std::atomic<std::int64_t> sim_now_ns_{0};
  long sim_ticks_ = 0;
  int stroke_depth_ = 0;  // strokes opened by either source and not closed (edit thread only)
  bool button_stroke_ = false;  // the button's press is held: its begin seen, its end not (edit thread)

  // Servo-thread state (on_tick only).
  bool button_ = false;
  long press_tick_ = 0;
  std::uint64_t last_version_ = 0;
  // The first tick that read each version: its start and the version, in slot version % size.
  // The servo writes both when the version changes; the edit thread reads them (the version
  // matches: that version's tick; a later version may have taken the slot only after `size`
  // more publications read, far beyond any backlog).
  std::unique_ptr<std::atomic<std::int64_t>[]> seen_ns_;
  std::unique_ptr<std::atomic<std::uint64_t>[]> seen_version_;
  std::size_t seen_size_ = 0;

  // |period error| histogram (servo writes with relaxed increments; stats() reads).
  std::array<std::atomic<std::uint32_t>, kPeriodBins> period_hist_{};

  // What observe() reads: the last tick, written by the servo thread (a seqlock).
  servo::LatestValue<Observed> observed_;

  std::atomic<long> dropped_edits_{0}, dropped_ticks_{0}, requested_{0};
  // Edit thread -> recorder and stats (not real time: a mutex is fine here).
  mutable std::mutex edits_mu_;
  std::vector<EditEvent> applied_pending_;  // not yet written
  // (version, asked_ns) not yet read; latencies of the versions read (stats() resolves too).
  mutable std::vector<std::pair<std::uint64_t, std::int64_t>> published_;
  mutable std::vector<double> edit_to_haptics_ms_;
  long applied_ = 0, refused_ = 0, merged_ = 0, publications_ = 0;
  long listener_errors_ = 0;
  std::string listener_error_;

  // Recorder thread.
  int fd_ = -1;
  std::string part_path_;
  long recorded_ticks_ = 0, recorded_edits_ = 0;
  double last_t_ = 0;
  std::string record_error_;  // written by the recorder (or stop()) under edits_mu_: stats() reads it
  bool stopped_ = false;
};

LiveSession::Impl::Impl(EditSession& edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
                         servo::HapticDeviceIO& device, LiveSessionConfig config)
    : Impl(&edits, buffer, renderer, std::move(config)) {
  servo::ServoThreadConfig c = cfg_.servo;
  c.observer = this;
  // What on_tick touches, locked with the servo's own memory (ServoThreadConfig::lock_memory).
  c.lock_ranges.push_back({this, sizeof(*this)});
  if (fd_ >= 0) c.lock_ranges.push_back(ticks_.storage());
  if (cfg_.drill) c.lock_ranges.push_back(servo_edits_.storage());
  c.lock_ranges.push_back({seen_ns_.get(), seen_size_ * sizeof(seen_ns_[0])});
  c.lock_ranges.push_back({seen_version_.get(), seen_size_ * sizeof(seen_version_[0])});
  servo_ = std::make_unique<servo::ServoThread>(buffer, renderer, device, std::move(c));
}

LiveSession::Impl::Impl(EditSession* edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
                         LiveSessionConfig config)
    : edits_(edits),
      buffer_(buffer),
      renderer_(renderer),
      cfg_(std::move(config)),
      ticks_(std::size_t(std::max(2.0, std::ceil(std::clamp(cfg_.servo.rate_hz, 1.0, 1e5) * 2.0)))),
      servo_edits_(cfg_.edit_queue),
      api_edits_(cfg_.edit_queue) {
  if (!(cfg_.servo.rate_hz >= 1 && cfg_.servo.rate_hz <= 1e5))
    throw std::invalid_argument("live session: servo rate " + std::to_string(cfg_.servo.rate_hz) + " Hz is not in [1, 100000]");
  if (!(cfg_.flush_interval_s > 0 && cfg_.flush_interval_s <= 1.0))
    throw std::invalid_argument("live session: flush interval " + std::to_string(cfg_.flush_interval_s) +
                                " s is not in (0, 1]");
  if (cfg_.drill && cfg_.drill->every_ticks < 1)
    throw std::invalid_argument("live session: drill every_ticks must be >= 1");
  if (edits_) edits_->set_log_limit(0);  // the session records its edits itself; memory stays bounded
  if (cfg_.latency_slots < 1) throw std::invalid_argument("live session: latency_slots must be >= 1");
  seen_size_ = cfg_.latency_slots;
  seen_ns_ = std::make_unique<std::atomic<std::int64_t>[]>(seen_size_);
  seen_version_ = std::make_unique<std::atomic<std::uint64_t>[]>(seen_size_);
  for (std::size_t i = 0; i < seen_size_; ++i) {
    seen_ns_[i].store(-1, std::memory_order_relaxed);
    seen_version_[i].store(0, std::memory_order_relaxed);  // none (published versions are > 0)
  }
  if (!cfg_.record_path.empty()) open_recording();
}

void LiveSession::Impl::open_recording() {
  cfg_.record_header.format_version = 3;
  // What the session knows itself: the servo's rate and the volume it edits (as it starts).
  if (cfg_.record_header.rate_hz == 0) cfg_.record_header.rate_hz = cfg_.servo.rate_hz;
  if (!cfg_.record_header.volume_crc32 && edits_) cfg_.record_header.volume_crc32 = io::volume_crc32(edits_->volume());
  cfg_.record_header.ticks.clear();
  cfg_.record_header.edits.clear();
  part_path_ = cfg_.record_path + ".part";
  // Refuse what cannot take a recording before anything runs (a directory, a socket...).
  try {
    io::classify_output(cfg_.record_path);
  } catch (const io::OutputError& e) {
    throw io::RecordingError(e.what());
  }
  // A new file only (O_EXCL, which also never follows a symbolic link): FILE.part left by a
  // run that was killed is that run's recording, readable by isotouch replay.
  fd_ = ::open(part_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0 && errno == EEXIST)
    throw io::RecordingError(part_path_ +
                             ": exists: the recording of a session that did not finish (isotouch replay reads it); "
                             "move or delete it, or record to another name");
  if (fd_ < 0) throw io::RecordingError(os_error(part_path_, "cannot create the recording"));
  try {
    const std::string header = io::recording_header_line(cfg_.record_header, cfg_.record_path);
    io::write_all(fd_, header.data(), header.size(), part_path_);
    if (::fdatasync(fd_) != 0) throw io::RecordingError(os_error(part_path_, "fdatasync failed"));
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    ::unlink(part_path_.c_str());
    throw;
  }
}

LiveSession::Impl::~Impl() {
  try {
    stop();
  } catch (const ServoAbandoned& e) {
    // Destroyed without stop() (unwinding from another error): the caller frees the
    // renderer, the field and the device next, while the stuck thread may read them.
    end_process_servo_stuck("live session (destroyed while running)", e.what());
  } catch (...) {
    // The destructor cannot report; stop() called explicitly does.
  }
  if (fd_ >= 0) ::close(fd_);
}

std::string LiveSession::Impl::start() {
  if (!servo_) throw std::logic_error("live session: start() needs a device (this session is for run_simulated() only)");
  if (simulated_) throw std::logic_error("live session: start() after run_simulated()");
  // Without a snapshot every tick would render nothing and send zero force, silently.
  if (!buffer_.ever_published())
    throw std::logic_error(
        "live session: start() before the first snapshot was published: call "
        "buffer.publish(edits.current()) (TripleBuffer::publish) before start()");
  if (running_.exchange(true)) return "";
  start_ns_ = now_ns();
  stop_edits_.store(false);
  stop_recorder_.store(false);
  if (fd_ >= 0) record_thread_ = std::thread([this] { record_loop(); });
  // The servo first: the edit thread keeps off the CPU it was pinned to.
  std::string note = servo_->start();
  if (edits_) edit_thread_ = std::thread([this] { edit_loop(); });
  return note;
}

std::int64_t LiveSession::Impl::clock_ns() const {
  return simulated_ ? sim_now_ns_.load(std::memory_order_relaxed) : now_ns();
}

double LiveSession::Impl::elapsed_s() const { return double(clock_ns() - start_ns_) * 1e-9; }

bool LiveSession::Impl::submit(const EditEvent& e) {
  requested_.fetch_add(1, std::memory_order_relaxed);
  if (!edits_) {  // nothing to edit: refused, never queued
    std::lock_guard lock(edits_mu_);
    ++refused_;
    return false;
  }
  if (!api_edits_.push(Request{e, clock_ns()})) {
    dropped_edits_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  wake_edit_thread();
  return true;
}

void LiveSession::Impl::wake_edit_thread() {
  {
    std::lock_guard lock(wake_mu_);
    api_pending_ = true;
  }
  wake_cv_.notify_one();
}

// ---------------------------------------------------------------- servo thread

void LiveSession::Impl::publish_observed(const servo::TickRecord& r) noexcept {
  Observed o;
  o.tick = r.k;
  o.hip_m = r.hip_m;
  o.vhip_m = r.out.vhip_m;
  o.force_n = r.out.force_n;
  o.plane = r.out.plane;
  o.contact = r.out.contact;
  o.version = r.version;
  o.rendered = r.device_status == servo::DeviceStatus::kOk && !r.paused;
  observed_.store(o);
}

Observed LiveSession::Impl::observe() const { return observed_.load(); }

void LiveSession::Impl::on_tick(const servo::TickRecord& r) noexcept {
  if (r.version != last_version_) {
    last_version_ = r.version;
    const std::size_t slot = r.version % seen_size_;
    // A seqlock of one writer: the tag cleared, the time, the tag (resolve_seen_locked).
    seen_version_[slot].store(0, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    seen_ns_[slot].store(r.t_ns, std::memory_order_relaxed);
    seen_version_[slot].store(r.version, std::memory_order_release);
  }
  if (fd_ >= 0 && !ticks_.push(r)) dropped_ticks_.fetch_add(1, std::memory_order_relaxed);
  if (r.period_s > 0) {  // the period error's histogram (no allocation, no lock)
    const double err_us = std::fabs(r.period_s - 1.0 / cfg_.servo.rate_hz) * 1e6;
    const std::size_t bin = std::min(kPeriodBins - 1, std::size_t(err_us / kPeriodBinUs));
    period_hist_[bin].fetch_add(1, std::memory_order_relaxed);
  }
  publish_observed(r);
  if (!cfg_.drill || !edits_) return;
  // The button drill at the VHIP (see ButtonDrill).
  const bool down = (r.buttons & 1u) != 0;
  // Simulated: the scene's clock k / rate exactly (as the timeline's); live: the servo's.
  const double t = simulated_ ? double(r.k) / cfg_.servo.rate_hz : double(r.t_ns - start_ns_) * 1e-9;
  auto ask = [&](EditEvent::Kind kind, const Brush& b) {
    EditEvent e;
    e.kind = kind;
    e.tick = r.k;
    e.t_s = t;
    e.brush = b;
    requested_.fetch_add(1, std::memory_order_relaxed);
    if (!servo_edits_.push(Request{e, r.t_ns})) dropped_edits_.fetch_add(1, std::memory_order_relaxed);
  };
  if (down && !button_) {
    press_tick_ = r.k;
    ask(EditEvent::Kind::kBeginStroke, {});
  }
  if (!down && button_) ask(EditEvent::Kind::kEndStroke, {});
  button_ = down;
  if (down && !r.paused && r.out.contact && r.out.penetration_m > 0 && (r.k - press_tick_) % cfg_.drill->every_ticks == 0) {
    Brush b = cfg_.drill->brush;
    b.centre_m = r.out.vhip_m;
    b.force_n = core::norm(r.out.force_n);
    ask(EditEvent::Kind::kBrush, b);
  }
}

// ---------------------------------------------------------------- edit thread

void LiveSession::Impl::apply_request(Request& q, EditSource source, long ticks_done, bool rethrow) {
  using Kind = EditEvent::Kind;
  EditEvent& e = q.event;
  // The tick after which it is applied: ticks from ticks_done on may read it.
  e.tick = ticks_done;
  if (source == EditSource::kApi && !simulated_) e.t_s = double(q.asked_ns - start_ns_) * 1e-9;
  if (source == EditSource::kButton && e.kind == Kind::kBeginStroke) button_stroke_ = true;
  if (source == EditSource::kButton && e.kind == Kind::kEndStroke) button_stroke_ = false;
  // Strokes nest: a stroke opened by one source while the other's is open joins it; only
  // the outermost begin and end reach the history (one undo step).
  // Nothing to apply (counted as merged: requested = applied + refused + dropped + merged
  // once the queues are empty).
  const bool merged = (e.kind == Kind::kBeginStroke && stroke_depth_++ > 0) ||
                      (e.kind == Kind::kEndStroke && (stroke_depth_ == 0 || --stroke_depth_ > 0));
  if (merged) {
    std::lock_guard lock(edits_mu_);
    ++merged_;
    return;
  }
  EditOutcome out;
  try {
    out = edits_->apply(e, &buffer_);
  } catch (...) {
    if (rethrow) {
      std::lock_guard lock(edits_mu_);
      ++refused_;
      throw;
    }
    out.error = what_of(std::current_exception());
    // Counted after the listener has seen it (LiveStats: a settled count is the listener's too).
    struct Count {
      Impl& s;
      ~Count() {
        std::lock_guard lock(s.edits_mu_);
        ++s.refused_;
      }
    } count{*this};
    notify(e, out, source, rethrow);
    return;
  }
  const bool undo_or_redo = e.kind == Kind::kUndo || e.kind == Kind::kRedo;
  if (undo_or_redo) stroke_depth_ = 0;  // they end an open stroke
  {
    std::lock_guard lock(edits_mu_);
    applied_pending_.push_back(e);
    if (out.published) {
      ++publications_;
      published_.emplace_back(edits_->current()->version, q.asked_ns);
      resolve_seen_locked();
    }
  }
  {
    // Counted once the listener has seen it (also when it throws): a caller that waits for
    // the count (serve's save) reads what the listener wrote (its mirror of the bricks).
    struct Count {
      Impl& s;
      ~Count() {
        std::lock_guard lock(s.edits_mu_);
        ++s.applied_;
      }
    } count{*this};
    notify(e, out, source, rethrow);
  }
  // A press still held goes on in a stroke of its own (one undo step), as a new press would.
  if (undo_or_redo && button_stroke_) {
    Request begin;
    begin.event.kind = Kind::kBeginStroke;
    begin.event.t_s = e.t_s;
    begin.asked_ns = q.asked_ns;
    apply_request(begin, EditSource::kButton, ticks_done, rethrow);
  }
}

// The listener sees the edit; what it throws is counted, not let through to the edit
// thread (where it would end the process); simulated mode (`rethrow`) lets it through.
void LiveSession::Impl::notify(const EditEvent& e, const EditOutcome& out, EditSource source, bool rethrow) {
  if (!cfg_.on_applied) return;
  try {
    cfg_.on_applied(e, out, source);
  } catch (...) {
    if (rethrow) throw;
    std::lock_guard lock(edits_mu_);
    if (listener_errors_++ == 0) listener_error_ = what_of(std::current_exception());
  }
}

// Each publication up to the newest one a tick has read: its latency (first reading tick's
// start - submit) if a tick read it. Older ones no tick read are dropped: the servo reads
// the newest snapshot only, so it never will. Publications after that stay pending.
// Holds edits_mu_.
void LiveSession::Impl::resolve_seen_locked() const {
  auto read_at = [&](std::uint64_t version, std::int64_t& t_ns) {
    const std::size_t slot = version % seen_size_;
    if (seen_version_[slot].load(std::memory_order_acquire) != version) return false;
    t_ns = seen_ns_[slot].load(std::memory_order_relaxed);
    // The servo clears the tag before it writes a later version's time: a tag still
    // `version` after the time was read means the time is that version's.
    std::atomic_thread_fence(std::memory_order_acquire);
    return seen_version_[slot].load(std::memory_order_relaxed) == version;
  };
  std::size_t read = 0;  // publications up to and with the newest one a tick has read
  std::int64_t t_ns = 0;
  for (std::size_t i = published_.size(); i-- > 0;)
    if (read_at(published_[i].first, t_ns)) {
      read = i + 1;
      break;
    }
  for (std::size_t i = 0; i < read; ++i) {
    const auto [version, asked] = published_[i];
    if (read_at(version, t_ns) && t_ns >= asked) edit_to_haptics_ms_.push_back(double(t_ns - asked) * 1e-6);
  }
  published_.erase(published_.begin(), published_.begin() + std::ptrdiff_t(read));
}

void LiveSession::Impl::edit_loop() {
  const servo::ScopedOffCpu off(servo_->pinned_cpu());  // not stopped by each tick and its spin
  Request q;
  while (!stop_edits_.load(std::memory_order_acquire)) {
    // One request from each queue in turn: an undo from the UI waits for at most one brush
    // of a long drill, not for the drill to end.
    bool any = false;
    for (bool more = true; more && !stop_edits_.load(std::memory_order_relaxed);) {
      more = false;
      if (api_edits_.pop(q)) {
        apply_request(q, EditSource::kApi, servo_->ticks(), false);
        more = true;
      }
      if (!stop_edits_.load(std::memory_order_relaxed) && servo_edits_.pop(q)) {
        apply_request(q, EditSource::kButton, servo_->ticks(), false);
        more = true;
      }
      any = any || more;
    }
    if (!any) {  // until submit() wakes it, or 0.2 ms for the servo's ring (not real time)
      std::unique_lock lock(wake_mu_);
      wake_cv_.wait_for(lock, std::chrono::microseconds(200), [this] { return api_pending_; });
      api_pending_ = false;
    }
  }
}

// ---------------------------------------------------------------- simulated mode

void LiveSession::Impl::drain_simulated(long ticks_done) {
  Request q;
  // The API side first (a scene's timeline), then the button drill: the order `isotouch run`
  // has always applied them in.
  while (api_edits_.pop(q)) apply_request(q, EditSource::kApi, ticks_done, !stepped_);
  while (servo_edits_.pop(q)) apply_request(q, EditSource::kButton, ticks_done, !stepped_);
}

void LiveSession::Impl::begin_simulated(bool stepped) {
  if (running_.load()) throw std::logic_error("live session: simulated mode on a session that was started");
  if (simulated_ && (!stepped_ || !stepped)) throw std::logic_error("live session: run_simulated() on a session that ran");
  if (finished_) throw std::logic_error("live session: step_simulated() after finish_simulated()");
  simulated_ = true;
  stepped_ = stepped;
  start_ns_ = 0;
}

void LiveSession::Impl::simulated_tick(const SimulatedRun& run, long k, sim::TraceRow& row) {
  const double rate = cfg_.servo.rate_hz;
  const long flush_ticks = std::max(1L, long(std::llround(cfg_.flush_interval_s * rate)));
  servo::TickRecord r;
  r.k = k;
  r.t_ns = std::int64_t(std::llround(double(k) * 1e9 / rate));
  r.dt_s = 0;  // the nominal period
  r.hip_m = row.hip_m;
  const double t = double(k) / rate;
  for (const auto& iv : run.button_down)
    if (t >= iv[0] && t < iv[1]) r.buttons = 1;
  row.button = r.buttons != 0;
  r.out.force_n = row.force_n;
  r.out.vhip_m = row.vhip_m;
  r.out.plane = row.plane;
  r.out.penetration_m = row.penetration_m;
  r.out.contact = row.contact;
  r.out.plane_update = row.plane_update;
  r.out.saturated = row.saturated;
  r.out.fault = row.fault;
  r.version = row.version;
  sim_now_ns_.store(r.t_ns, std::memory_order_relaxed);
  if (run.after_tick) run.after_tick(k, row);
  on_tick(r);
  sim_ticks_ = k + 1;
  if (edits_) drain_simulated(k + 1);
  if (fd_ >= 0 && sim_ticks_ % flush_ticks == 0) record_chunk(false);
}

std::vector<sim::TraceRow> LiveSession::Impl::run_simulated(const SimulatedRun& run) {
  if (!run.device || !run.script) throw std::invalid_argument("live session: run_simulated() needs a device and a script");
  begin_simulated(false);
  const sim::TickHook hook = [&](long k, sim::TraceRow& row) { simulated_tick(run, k, row); };
  std::vector<sim::TraceRow> trace = sim::run_headless(buffer_, renderer_, *run.device, run.world_T_device, *run.script,
                                                       cfg_.servo.rate_hz, run.progress, run.progress_every, hook);
  finish_simulated();
  return trace;
}

std::vector<sim::TraceRow> LiveSession::Impl::step_simulated(const SimulatedRun& run, long ticks) {
  if (!run.device || !run.script) throw std::invalid_argument("live session: step_simulated() needs a device and a script");
  if (ticks < 0) throw std::invalid_argument("live session: step_simulated() of " + std::to_string(ticks) + " ticks");
  begin_simulated(true);
  std::vector<sim::TraceRow> rows;
  rows.reserve(std::size_t(ticks));
  for (long i = 0; i < ticks; ++i) {
    const long k = sim_ticks_;
    rows.push_back(sim::headless_tick(buffer_, renderer_, *run.device, run.world_T_device, *run.script,
                                      cfg_.servo.rate_hz, k));
    simulated_tick(run, k, rows.back());
  }
  return rows;
}

void LiveSession::Impl::finish_simulated() {
  if (!simulated_ || finished_) return;
  finished_ = true;
  if (!edits_) return;
  drain_simulated(sim_ticks_);  // what was submitted after the last tick
  if (stroke_depth_ > 0) {  // a stroke left open (button still down at the end)
    stroke_depth_ = 1;
    Request q;
    q.event.kind = EditEvent::Kind::kEndStroke;
    q.event.t_s = double(sim_ticks_ - 1) / cfg_.servo.rate_hz;
    q.asked_ns = sim_now_ns_.load(std::memory_order_relaxed);
    apply_request(q, EditSource::kEndOfRun, sim_ticks_, !stepped_);
  }
}

// ---------------------------------------------------------------- recorder thread

void LiveSession::Impl::record_chunk(bool final) {
  std::string text;
  std::vector<EditEvent> edits;
  {
    std::lock_guard lock(edits_mu_);
    edits.swap(applied_pending_);
  }
  // Ticks first: an edit's tick count never exceeds the ticks pushed before it was taken.
  servo::TickRecord r;
  while (ticks_.pop(r)) {
    // t: the session's servo clock, strictly ascending (two ticks never share a reading,
    // but a recording must not depend on that).
    double t = double(r.t_ns - start_ns_) * 1e-9;
    if (recorded_ticks_ > 0 && !(t > last_t_)) t = std::nextafter(last_t_, INFINITY);
    last_t_ = t;
    text += io::recording_tick_line(recorded_ticks_, recorded(r, t), 3, cfg_.record_path);
    ++recorded_ticks_;
  }
  for (const EditEvent& e : edits) {
    text += io::recording_edit_line(e, cfg_.record_path);
    ++recorded_edits_;
  }
  if (final) text += io::recording_end_line(std::size_t(recorded_ticks_), std::size_t(recorded_edits_));
  if (!text.empty()) io::write_all(fd_, text.data(), text.size(), part_path_);
  if (::fdatasync(fd_) != 0) throw io::RecordingError(os_error(part_path_, "fdatasync failed"));
}

void LiveSession::Impl::record_loop() {
  const auto interval = std::chrono::duration<double>(cfg_.flush_interval_s);
  auto next = std::chrono::steady_clock::now() + interval;
  while (!stop_recorder_.load(std::memory_order_acquire)) {
    const timespec ts{0, 1000000};
    nanosleep(&ts, nullptr);
    if (std::chrono::steady_clock::now() < next) continue;
    next += interval;
    if (!record_error_.empty()) continue;
    try {
      record_chunk(false);
    } catch (const std::exception& e) {
      std::lock_guard lock(edits_mu_);  // stats() reads it meanwhile
      record_error_ = e.what();
    }
  }
}

// ---------------------------------------------------------------- stop

void LiveSession::Impl::stop() {
  if (simulated_) {
    if (stopped_) return;
    stopped_ = true;
    Request q;  // submitted after the last tick and not finished: dropped, as live
    while (servo_edits_.pop(q) || api_edits_.pop(q)) dropped_edits_.fetch_add(1, std::memory_order_relaxed);
    finish_recording();
    return;
  }
  if (!running_.load() && fd_ >= 0) {  // never started: no recording to keep
    ::close(fd_);
    fd_ = -1;
    ::unlink(part_path_.c_str());
    return;
  }
  if (!running_.load() || stopped_) return;
  stopped_ = true;
  // The device's last force: an exact zero; a renderer stuck past the timeout: force off, an error.
  const std::string servo_error = servo_->stop();
  stop_edits_.store(true, std::memory_order_release);
  wake_edit_thread();
  if (edit_thread_.joinable()) edit_thread_.join();
  Request q;
  while (servo_edits_.pop(q) || api_edits_.pop(q)) dropped_edits_.fetch_add(1, std::memory_order_relaxed);
  stop_recorder_.store(true, std::memory_order_release);
  if (record_thread_.joinable()) record_thread_.join();
  if (servo_error.empty()) return finish_recording();
  try {
    finish_recording();
  } catch (const std::exception& e) {
    throw ServoAbandoned("live session: " + servo_error + "; " + e.what());
  }
  throw ServoAbandoned("live session: " + servo_error);
}

void stop_or_end_process(LiveSession& live, const std::string& program,
                         const std::function<void(const std::string& what)>& on_abandoned) {
  try {
    live.stop();
  } catch (const ServoAbandoned& e) {
    try {
      if (on_abandoned) on_abandoned(e.what());
    } catch (...) {
      // Ending the process matters more than what the callback could not write.
    }
    end_process_servo_stuck(program, e.what());
  }
}

void end_process_servo_stuck(const std::string& program, const std::string& what) noexcept {
  std::fflush(stdout);
  std::fprintf(stderr, "%s: %s; ending the process (exit %d) without freeing what the stuck servo thread may read\n",
               program.c_str(), what.c_str(), exit_code::kServoStuck);
  std::fflush(stderr);
  servo::send_exit_zeros(5000);  // a link's peer (PLUS) holds the last force it got (exit_zero.h)
  std::_Exit(exit_code::kServoStuck);
}

void LiveSession::Impl::finish_recording() {
  if (fd_ < 0) return;
  if (record_error_.empty()) {
    try {
      if (dropped_ticks_.load() > 0)
        throw io::RecordingError(part_path_ + ": " + std::to_string(dropped_ticks_.load()) +
                                 " ticks were not recorded (the recorder fell behind): the recording is incomplete");
      record_chunk(true);
    } catch (const std::exception& e) {
      std::lock_guard lock(edits_mu_);
      record_error_ = e.what();
    }
  }
  ::close(fd_);
  fd_ = -1;
  if (!record_error_.empty()) throw io::RecordingError(record_error_ + " (what was written is in " + part_path_ + ")");
  try {
    io::place_output(part_path_, cfg_.record_path);
  } catch (const io::OutputError& e) {
    std::lock_guard lock(edits_mu_);
    record_error_ = e.what();
    throw io::RecordingError(record_error_);
  }
}

LiveStats LiveSession::Impl::stats(std::size_t latency_tail) const {
  LiveStats s;
  if (servo_) {
    s.ticks = servo_->ticks();
    s.missed_deadlines = servo_->missed_deadlines();
    s.faults = servo_->faults();
    s.passivity = servo_->passivity();
  } else {
    s.ticks = sim_ticks_;
  }
  s.edits_requested = requested_.load();
  s.edits_dropped = dropped_edits_.load();
  s.ticks_not_recorded = dropped_ticks_.load();
  std::uint64_t total = 0;
  for (const auto& b : period_hist_) total += b.load(std::memory_order_relaxed);
  if (total > 0) {
    const auto rank = std::uint64_t(std::ceil(0.99 * double(total)));
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kPeriodBins; ++i) {
      seen += period_hist_[i].load(std::memory_order_relaxed);
      if (seen >= rank) {
        s.period_error_p99_beyond = i + 1 == kPeriodBins;
        s.period_error_p99_us = s.period_error_p99_beyond ? kPeriodRangeUs : double(i + 1) * kPeriodBinUs;
        break;
      }
    }
  }
  std::lock_guard lock(edits_mu_);
  s.edits_applied = applied_;
  s.edits_refused = refused_;
  s.edits_merged = merged_;
  s.publications = publications_;
  resolve_seen_locked();
  const std::size_t tail = std::min(latency_tail, edit_to_haptics_ms_.size());
  s.edit_to_haptics_ms.assign(edit_to_haptics_ms_.end() - std::ptrdiff_t(tail), edit_to_haptics_ms_.end());
  s.edit_to_haptics_taken = edit_to_haptics_ms_.size();
  s.record_error = record_error_;
  s.listener_errors = listener_errors_;
  s.listener_error = listener_error_;
  return s;
}

// ---------------------------------------------------------------- LiveSession: forwards to Impl

LiveSession::LiveSession(EditSession& edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
                         servo::HapticDeviceIO& device, LiveSessionConfig config)
    : impl_(std::make_unique<Impl>(edits, buffer, renderer, device, std::move(config))) {}

LiveSession::LiveSession(EditSession* edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
                         LiveSessionConfig config)
    : impl_(std::make_unique<Impl>(edits, buffer, renderer, std::move(config))) {}

LiveSession::~LiveSession() = default;

std::string LiveSession::start() { return impl_->start(); }
void LiveSession::pause(bool paused) { impl_->pause(paused); }
void LiveSession::stop() { impl_->stop(); }
std::vector<sim::TraceRow> LiveSession::run_simulated(const SimulatedRun& run) { return impl_->run_simulated(run); }
std::vector<sim::TraceRow> LiveSession::step_simulated(const SimulatedRun& run, long ticks) {
  return impl_->step_simulated(run, ticks);
}
void LiveSession::finish_simulated() { impl_->finish_simulated(); }
bool LiveSession::submit(const EditEvent& e) { return impl_->submit(e); }
Observed LiveSession::observe() const { return impl_->observe(); }
double LiveSession::elapsed_s() const { return impl_->elapsed_s(); }
LiveStats LiveSession::stats(std::size_t latency_tail) const { return impl_->stats(latency_tail); }
const servo::ServoThread* LiveSession::servo_thread() const { return impl_->servo_thread(); }

}  // namespace isotouch::session
