#include "isotouch/bench/bench_serve.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <future>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

#include "isotouch/bench/servo_bench.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/eval/stats.h"
#include "isotouch/io/scene.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/service/serve.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::bench {
namespace {
using Clock = std::chrono::steady_clock;

std::string fixed(double v, int digits = 1) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

std::int64_t now_ns() { return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count(); }

/// Steady-clock ns as an OpenIGTLink stamp (32.32 fixed-point seconds) and back: the server
/// echoes a pose's stamp in the force that answers it.
std::uint64_t to_stamp(std::int64_t ns) {
  const auto sec = std::uint64_t(ns / 1'000'000'000), sub = std::uint64_t(ns % 1'000'000'000);
  return (sec << 32) | ((sub << 32) / 1'000'000'000);
}
std::int64_t from_stamp(std::uint64_t s) {
  return std::int64_t(s >> 32) * 1'000'000'000 + std::int64_t(((s & 0xffffffffu) * 1'000'000'000 + (1u << 31)) >> 32);
}

/// A sphere of material (2000) in empty space (0), a 3 mm ramp at its surface, 1 mm voxels,
/// centred on the tracker's path so that the path crosses its surface as it crosses the skull's.
engine::Volume sphere(int n) {
  engine::Volume v;
  v.grid.dims = {n, n, n};
  v.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  const core::Vec3 c{0.080, 0.1024, 0.0165};  // LPS [m]
  v.grid.origin_m = c - core::Vec3{1, 1, 1} * ((n - 1) * 0.5e-3);
  v.voxels.resize(std::size_t(n) * std::size_t(n) * std::size_t(n));
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double r = core::norm(v.index_to_physical({double(x), double(y), double(z)}) - c);
        v.voxels[(std::size_t(z) * std::size_t(n) + std::size_t(y)) * std::size_t(n) + std::size_t(x)] =
            float(2000.0 * std::clamp((0.055 - r) / 0.003 + 0.5, 0.0, 1.0));
      }
  v.path = "synthetic:sphere";
  v.update_stats();
  return v;
}

/// The tracker: poses at `rate_hz` along a line in and out of the skull (1 Hz), each stamped
/// with its send time; the forces that echo a stamp give the round trip.
struct Tracker {
  std::shared_ptr<service::Connection> conn;
  std::atomic<bool> stop{false};
  std::atomic<long> sent{0};
  std::mutex mu;
  std::vector<double> rtt_us;
  std::int64_t t0_ns = 0;
  // Per pose, in sending order: its send time, how late the tracker sent it against its
  // schedule [ns], and whether a force answered it (which poses go unanswered, and when).
  std::vector<std::int64_t> sent_ns, sent_late_ns;
  std::vector<char> answered;

  void send_loop(double rate_hz) {
    const auto start = Clock::now();
    for (long k = 0; !stop; ++k) {
      const auto due = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(double(k) / rate_hz));
      std::this_thread::sleep_until(due);
      const double u = 0.5 - 0.5 * std::cos(2 * M_PI * double(k) / rate_hz);  // 0 .. 1 .. 0 each second
      const double t[3] = {-9.6 - u * 30.0, -102.4, 16.5};  // RAS [mm]: outside, then 3.6 voxels into bone
      const std::int64_t ns = now_ns();
      {
        std::lock_guard<std::mutex> lock(mu);
        sent_ns.push_back(ns);
        sent_late_ns.push_back(ns - std::chrono::duration_cast<std::chrono::nanoseconds>(due.time_since_epoch()).count());
        answered.push_back(0);
      }
      if (!conn->send(service::pack_translation("Stylus", t, to_stamp(ns)))) break;
      sent.fetch_add(1);
    }
  }
  /// Marks the pose sent at `ns` (an echoed stamp, within 2 ns of it) answered; mu held.
  void mark(std::int64_t ns) {
    const auto it = std::lower_bound(sent_ns.begin(), sent_ns.end(), ns - 2);
    if (it != sent_ns.end() && *it <= ns + 2) answered[std::size_t(it - sent_ns.begin())] = 1;
  }
  void read_loop() {
    for (;;) {
      const service::Incoming in = service::read_message(*conn, service::MessageLimits{});
      if (in.kind == service::Incoming::Kind::kClosed || in.kind == service::Incoming::Kind::kBroken) break;
      if (in.kind != service::Incoming::Kind::kTransform || in.device != "Force") continue;
      const std::int64_t now = now_ns(), echoed = from_stamp(in.stamp);
      if (echoed < t0_ns || echoed > now) continue;  // the display's Force (wall-clock stamp), not an answer
      std::lock_guard<std::mutex> lock(mu);
      rtt_us.push_back(double(now - echoed) * 1e-3);
      mark(echoed);
    }
  }
};

/// Which poses no force answered: those in the phase's first second (the servo learning the
/// stream's phase), those the tracker itself sent kLateNs or more behind its schedule, and
/// those right after another unanswered one; and the tracker's own lateness (p99, p99.9).
void unanswered(const Tracker& tr, double rate_hz, BenchServePhase& ph) {
  constexpr std::int64_t kLateNs = 250'000;
  const auto first_second = std::size_t(rate_hz);
  std::vector<double> late_us;
  for (std::size_t k = 0; k < tr.answered.size(); ++k) {
    late_us.push_back(double(tr.sent_late_ns[k]) * 1e-3);
    if (tr.answered[k]) continue;
    ++ph.unanswered;
    ph.unanswered_first_second += k < first_second;
    ph.unanswered_sent_late += tr.sent_late_ns[k] >= kLateNs;
    ph.unanswered_after_unanswered += k > 0 && !tr.answered[k - 1];
  }
  if (late_us.empty()) return;
  ph.tracker_late_p99_us = eval::percentile(late_us, 0.99);
  ph.tracker_late_p999_us = eval::percentile(late_us, 0.999);
}

/// Slicer's side: an IMAGE every `every_s`, its answers read and dropped.
void send_images(service::Connection& c, const std::vector<std::uint8_t>& image, double every_s, const std::atomic<bool>& stop,
                 std::atomic<long>& sent) {
  std::thread drain([&c] {
    while (true) {
      const service::Incoming in = service::read_message(c, service::MessageLimits{});
      if (in.kind == service::Incoming::Kind::kClosed || in.kind == service::Incoming::Kind::kBroken) break;
    }
  });
  auto next = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(every_s / 2));
  while (!stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (Clock::now() < next) continue;
    if (c.send(image)) sent.fetch_add(1);
    next += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(every_s));
  }
  c.shutdown();
  drain.join();
}

BenchServePhase run_phase(const io::Scene& scene, const BenchServeOptions& o, const std::vector<std::uint8_t>* image) {
  service::ServeOptions so;
  so.port = 0;
  so.stream = "Stylus";
  so.reply_force = true;
  so.image_hz = 0;
  so.seconds = o.seconds + 3;
  so.journal = false;  // a bench keeps no edits: no journal in the user's state folder
  so.sched_fifo = o.sched_fifo;
  so.run.device = o.device;
  so.run.progress = false;
  std::promise<int> port;
  so.on_listening = [&port](int p) { port.set_value(p); };
  service::ServeStats st;
  std::ostringstream serve_log;
  std::thread server([&] {
    try {
      service::serve(scene, so, serve_log, st);
    } catch (...) {
      try {
        port.set_exception(std::current_exception());
      } catch (...) {  // already listening: the phase's figures say what was measured
      }
    }
  });
  BenchServePhase ph;
  ph.name = image ? "tracking + a " + std::to_string(o.image_size) + "^3 IMAGE every " + fixed(o.image_every_s, 1) + " s"
                  : "tracking alone";
  try {
    const int p = port.get_future().get();
    Tracker tr;
    tr.t0_ns = now_ns();
    tr.conn = std::make_shared<service::Connection>(service::connect_tcp("127.0.0.1", p, 3000), 2000, 60000, &tr.stop);
    std::atomic<bool> stop_images{false};
    std::atomic<long> images_sent{0};
    std::unique_ptr<service::Connection> slicer;
    if (image) slicer = std::make_unique<service::Connection>(service::connect_tcp("127.0.0.1", p, 3000), 2000, 60000, &stop_images);
    // The tracker's threads as a tracking device's own I/O threads would run (SCHED_FIFO when
    // allowed, below the servo): what is measured is the server's answer, not their wake-up.
    auto realtime = [&o] {
      if (o.sched_fifo) servo::make_thread_realtime("bench tracker", true, 60, false, -1);
    };
    std::thread reader([&] { realtime(), tr.read_loop(); });
    std::thread sender([&] { realtime(), tr.send_loop(o.rate_hz); });
    std::thread images;
    if (image) images = std::thread([&] { send_images(*slicer, *image, o.image_every_s, stop_images, images_sent); });
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    stop_images = true;
    if (images.joinable()) images.join();
    tr.stop = true;
    sender.join();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the last answers
    tr.conn->shutdown();
    reader.join();
    ph.poses = tr.sent;
    ph.answered = long(tr.rtt_us.size());
    unanswered(tr, o.rate_hz, ph);
    if (!tr.rtt_us.empty()) {
      ph.p50_us = eval::percentile(tr.rtt_us, 0.50);
      ph.p99_us = eval::percentile(tr.rtt_us, 0.99);
      ph.max_us = *std::max_element(tr.rtt_us.begin(), tr.rtt_us.end());
    }
  } catch (const std::exception& e) {
    std::cerr << "bench serve: " << ph.name << ": " << e.what() << "\n";
  }
  server.join();
  ph.images = st.images;
  ph.ticks = st.ticks;
  ph.missed = st.missed_deadlines;
  ph.stall_answers = st.stall_replies;
  ph.to_servo_p50_us = st.to_servo_p50_us, ph.to_servo_p99_us = st.to_servo_p99_us;
  ph.to_send_p50_us = st.to_send_p50_us, ph.to_send_p99_us = st.to_send_p99_us;
  ph.stream_late_us = st.stream_late_us;
  ph.input_waits = st.input_waits;
  ph.input_wait_timeouts = st.input_wait_timeouts;
  ph.passed_over = st.passed_over;
  ph.overtaken = st.overtaken;
  ph.dropped = st.replies_dropped;
  ph.overtaken_gaps = st.overtaken_gaps;
  return ph;
}

}  // namespace

std::vector<std::string> bench_serve_verdicts(const BenchServePhase& alone, const BenchServePhase& traffic) {
  std::vector<std::string> v;
  const bool measured = traffic.answered > 0;
  v.push_back("p99 round trip (TRANSFORM in to force TRANSFORM out) with Slicer-like traffic = " +
              (measured ? fixed(traffic.p99_us) : std::string("none answered")) + " us: target <= 1000 us " +
              (measured && traffic.p99_us <= 1000 ? "met" : "NOT met"));
  for (const BenchServePhase* p : {&alone, &traffic}) {
    const double pct = p->poses > 0 ? 100.0 * double(p->answered) / double(p->poses) : 0.0;
    v.push_back("poses answered " + (p == &alone ? std::string("alone") : std::string("with traffic")) + " " +
                std::to_string(p->answered) + " of " + std::to_string(p->poses) + " = " + fixed(pct, 2) +
                " %: target >= 99 % " + (p->poses > 0 && 100 * p->answered >= 99 * p->poses ? "met" : "NOT met"));
  }
  const double ref = double(alone.missed), limit = ref + 3 * std::sqrt(ref);
  v.push_back("servo misses with traffic " + std::to_string(traffic.missed) + " <= " + std::to_string(alone.missed) +
              " without + 3 sqrt(" + std::to_string(alone.missed) + ") = " + fixed(limit) + ": " +
              (alone.ticks > 0 && traffic.ticks > 0 && double(traffic.missed) <= limit ? "met" : "NOT met"));
  return v;
}

int run_bench_serve(const BenchServeOptions& o, std::ostream& log) {
  const std::string path =
      o.scene.empty() ? (std::filesystem::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string() : o.scene;
  const io::Scene scene = io::load_scene(path);
  const std::string load_before = load_average();
  const std::vector<std::uint8_t> image = service::pack_image(sphere(o.image_size), "Sphere", service::VoxelBox{});
  log << "bench serve: isotouch serve on loopback (" << scene.name << ", servo " << scene.hri.rate_hz
      << " Hz, --reply-force): a tracker streams TRANSFORMs at " << o.rate_hz << " Hz, each answered by a force "
      << "TRANSFORM echoing its stamp; " << o.seconds << " s per phase, the second with a " << o.image_size << "^3 float32 IMAGE ("
      << image.size() / (1 << 20) << " MiB) every " << o.image_every_s << " s taken as the session's volume\n";
  const BenchServePhase alone = run_phase(scene, o, nullptr);
  const BenchServePhase traffic = run_phase(scene, o, &image);
  log << "\n| phase | poses sent | answered | answered by the stall rule | p50 [us] | p99 [us] | max [us] | IMAGEs taken | servo ticks | missed |\n"
      << "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchServePhase* p : {&alone, &traffic})
    log << "| " << p->name << " | " << p->poses << " | " << p->answered << " | " << p->stall_answers << " | " << fixed(p->p50_us)
        << " | " << fixed(p->p99_us) << " | " << fixed(p->max_us) << " | " << p->images << " | " << p->ticks << " | "
        << p->missed << " |\n";
  log << "\nWhere the time goes (inside the server, 10 us bins; the rest of the round trip is the two\n"
      << "loopback messages and the tracker's threads):\n\n"
      << "| phase | pose -> servo's write p50 / p99 [us] | write -> reply sent p50 / p99 [us] | rest at p50 [us] | "
         "poses' lateness p99.5 at the end (the servo's lead >= it + 25 us) [us] | ticks that waited for a later pose (of them, in vain) |\n"
      << "|---|---|---|---|---|---|\n";
  for (const BenchServePhase* p : {&alone, &traffic})
    log << "| " << p->name << " | " << fixed(p->to_servo_p50_us) << " / " << fixed(p->to_servo_p99_us) << " | "
        << fixed(p->to_send_p50_us) << " / " << fixed(p->to_send_p99_us) << " | "
        << fixed(p->p50_us - p->to_servo_p50_us - p->to_send_p50_us) << " | " << fixed(p->stream_late_us) << " | " << p->input_waits << " (" << p->input_wait_timeouts << ") |\n";
  log << "\nWhich poses no force answered (the tracker's lateness: its send time against its own schedule):\n\n"
      << "| phase | unanswered | in the phase's first second | sent >= 250 us late by the tracker | right after another unanswered | "
         "the tracker's lateness p99 / p99.9 [us] | the server passed over (of them, the servo never read) | replies the server dropped |\n"
      << "|---|---|---|---|---|---|---|---|\n";
  for (const BenchServePhase* p : {&alone, &traffic})
    log << "| " << p->name << " | " << p->unanswered << " | " << p->unanswered_first_second << " | " << p->unanswered_sent_late
        << " | " << p->unanswered_after_unanswered << " | " << fixed(p->tracker_late_p99_us) << " / "
        << fixed(p->tracker_late_p999_us) << " | " << p->passed_over << " (" << p->overtaken << ") | " << p->dropped << " |\n";
  log << "\nThe poses the servo never read, by how soon the next pose came after them (a burst from the\n"
      << "tracker, or a servo tick not made in between):\n\n"
      << "| phase | < 0.1 ms | 0.1-0.3 ms | 0.3-0.7 ms | 0.7-1.3 ms | > 1.3 ms |\n|---|---|---|---|---|---|\n";
  for (const BenchServePhase* p : {&alone, &traffic}) {
    log << "| " << p->name;
    for (long n : p->overtaken_gaps) log << " | " << n;
    log << " |\n";
  }
  log << "\n";
  for (const std::string& v : bench_serve_verdicts(alone, traffic)) log << "verdict  " << v << "\n";
  log << "machine  " << cpu_model() << ", " << std::thread::hardware_concurrency() << " CPUs; load average before "
      << load_before << ", after " << load_average() << "\n";
  return alone.answered > 0 && traffic.answered > 0 ? 0 : 1;
}

}  // namespace isotouch::bench
