// plus_peer.h - a PLUS-like OpenIGTLink peer on loopback, for the tests and `isotouch bench
// device`: it streams a tracked tool's poses (TRANSFORMs, translation in mm) at a steady rate
// and keeps every "Force" TRANSFORM it receives with its arrival time, as PLUS's device loop
// would apply them. It either listens (PLUS's own server: `--haptic igtl:` connects to it) or
// connects (a client of `isotouch serve --reply-force`). Times are [ns, CLOCK_MONOTONIC]
// (std::chrono::steady_clock), the servo's clock. Part of isotouch::plus_peer.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/core/vec3.h"
#include "isotouch/service/igtl_socket.h"

namespace isotouch::service {

struct PlusPeerOptions {
  double rate_hz = 1000;                    ///< poses a second (a late thread skips poses, never bursts them)
  std::string stream = "StylusToTracker";   ///< the poses' device name
  core::Vec3 pose_mm;                       ///< the translation sent [mm]
  double stream_s = 0;  ///< stop streaming this long after the stream began (0: never); stay connected
  double close_s = 0;   ///< close the connection this long after the stream began (0: at finish())
  int fifo_priority = 0;  ///< SCHED_FIFO for its threads where allowed (PLUS's device loop is); 0: none
  /// "" : listen on 127.0.0.1, any free port (port()), and serve the first client; else the
  /// server to connect to (with connect_port).
  std::string connect_host;
  int connect_port = 0;
};

/// One "Force" TRANSFORM the peer received.
struct PeerForce {
  std::int64_t t_ns = 0;      ///< when it arrived
  core::Vec3 f;               ///< its translation [N]
  std::uint64_t stamp = 0;    ///< its header's time stamp
};

class PlusPeer {
 public:
  /// Listens (or connects, in its own thread) at once.
  /// @throws std::runtime_error if it cannot listen.
  explicit PlusPeer(PlusPeerOptions o);
  ~PlusPeer();  ///< finish()
  PlusPeer(const PlusPeer&) = delete;
  PlusPeer& operator=(const PlusPeer&) = delete;

  int port() const;  ///< the listening port (listen mode)
  /// Stops streaming, closes and joins: the logs below are complete after it.
  void finish();
  /// While true, no pose goes out (a gap in the tool's stream); the connection stays.
  void pause(bool on) { pause_.store(on); }

  std::vector<PeerForce> forces() const;        ///< every Force so far, in arrival order
  std::vector<std::int64_t> poses_ns() const;   ///< when each pose went out
  std::int64_t started_ns() const { return started_ns_.load(); }  ///< the stream began (0: not yet)
  std::int64_t stopped_ns() const { return stopped_ns_.load(); }  ///< stream_s ended it (0: not)
  /// When the peer began to close the connection (0: not yet); taken before the shutdown, so
  /// a client that sees the close saw it after this.
  std::int64_t closed_ns() const { return closed_ns_.load(); }
  bool client_gone() const { return client_gone_.load(); }  ///< the reader saw the connection end
  bool connected() const { return connected_.load(); }

  static std::int64_t now_ns();

 private:
  void run();
  void read_forces(Connection& conn);
  void stream(Connection& conn);
  PlusPeerOptions o_;
  std::unique_ptr<Listener> listener_;
  std::atomic<bool> stop_{false}, pause_{false}, client_gone_{false}, connected_{false};
  std::atomic<std::int64_t> started_ns_{0}, stopped_ns_{0}, closed_ns_{0};
  mutable std::mutex mu_;
  std::vector<PeerForce> forces_;
  std::vector<std::int64_t> poses_;
  std::thread thread_;
};

}  // namespace isotouch::service
