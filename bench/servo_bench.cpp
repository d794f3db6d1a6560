#include "isotouch/bench/servo_bench.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <thread>

#include "isotouch/bench/passivity_cost.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/io/files.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/sim/sim_device_io.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/servo/baselines.h"
#include "isotouch/core/brick_field.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/hri.h"
#include "isotouch/eval/sweep.h"
#include "isotouch/bench/tool_bench.h"

#include <fstream>
#include "isotouch/engine/vk_context.h"

namespace isotouch::bench {
using eval::median_ns_per_tick;
using eval::prepare_sweep_scene;
using eval::reference_params;
using io::write_file_atomic;
using sim::make_touch_script;
using sim::SimDevice;
using sim::SimDeviceIO;
using core::SampleField;
using core::Vec3;
using eval::SweepScene;
using servo::BaselineParams;
using servo::HriParams;
using servo::Intersection;
using servo::NormalSource;
using servo::Renderer;
using servo::ServoThread;
using servo::ServoThreadConfig;
using servo::TripleBuffer;
using servo::Variant;
using sim::ScriptParams;
using sim::TouchScript;

std::string load_average() {
  std::ifstream f("/proc/loadavg");
  double a = 0, b = 0, c = 0;
  if (!(f >> a >> b >> c)) return "unknown";
  std::ostringstream o;
  o << a << ", " << b << ", " << c;
  return o.str();
}

/// Threads spinning on a register from construction to destruction: CPU load that makes no
/// syscall, touches no shared memory and cannot hold a CPU against a SCHED_FIFO thread.
class BusyThreads {
 public:
  explicit BusyThreads(int n) {
    try {
      for (int i = 0; i < n; ++i)
        threads_.emplace_back([this] {
          std::uint64_t x = 1;
          while (!stop_.load(std::memory_order_relaxed))
            for (int k = 0; k < 4096; ++k) x = x * 6364136223846793005ULL + 1442695040888963407ULL;
          sink_.fetch_add(x, std::memory_order_relaxed);
        });
    } catch (...) {  // a thread that could not start: stop and join the others first
      join_all();
      throw;
    }
  }
  ~BusyThreads() { join_all(); }
  BusyThreads(const BusyThreads&) = delete;
  BusyThreads& operator=(const BusyThreads&) = delete;

 private:
  void join_all() {
    stop_.store(true);
    for (auto& t : threads_) t.join();
  }
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> sink_{0};
  std::vector<std::thread> threads_;
};

int run_bench_servo_rt(const ServoRtOptions& o, std::ostream& log) {
  using namespace servo;
  engine::ContextOptions co;
  co.device = o.device;
  auto ctx = engine::VulkanContext::create(co);
  std::unique_ptr<engine::GradientPass> pass;
  std::string engine_name = "CPU reference (no Vulkan device: " + ctx.error + ")";
  if (ctx) {
    pass = std::make_unique<engine::GradientPass>(**ctx.value);
    engine_name = (*ctx.value)->info().name;
  }
  log << "bench servo-rt: " << o.seconds << " s per rate; engine thread recomputes a 64^3 sculpted sphere on "
      << engine_name << " and publishes it; " << std::thread::hardware_concurrency()
      << " CPUs; load average (1/5/15 min) " << load_average() << "\n";
  const BusyThreads busy(o.busy_threads);
  if (o.busy_threads > 0)
    log << o.busy_threads << " threads spin in user space throughout (default scheduling, no syscalls)\n";

  std::ostringstream csv;
  csv << "rate_hz,seconds,scheduling,ticks,missed_deadlines,period_err_p50_us,period_err_p99_us,period_err_p999_us,"
         "period_err_max_us,publications\n";
  log << "   rate  scheduling                           ticks  missed  |err| p50 [us]  p99 [us]  p99.9 [us]  max [us]  "
         "publications\n";
  std::string last_note;
  long ticks_10k = 0, missed_10k = 0;
  double p999_10k = 0;
  // The last case runs the same loop with the engine idle: what the machine alone allows.
  const std::pair<double, bool> cases[] = {{1000.0, true}, {4000.0, true}, {10000.0, true}, {10000.0, false}};
  long ticks_idle = 0, missed_idle = 0;
  double p999_idle = 0;
  for (const auto& [rate, engine_on] : cases) {
    TripleBuffer<SampleField> published;
    auto first = std::make_shared<SampleField>(engine::compute_samples_cpu(engine::make_sphere({64, 64, 64}, 1e-3, 20)));
    first->version = 1;
    published.publish(first);

    HriParams hp;
    hp.tau = 0;
    hp.plane_update_period = 5;
    hp.rate_hz = rate;
    HriRenderer renderer(hp);
    ScriptParams sp;
    sp.ray_origin_frac = {0.5, 0.5, 1.2};
    sp.press_depth_m = 0.004;
    sp.stroke_length_m = 0.02;
    const TouchScript script = make_touch_script(*first, hp, sp);
    Vec3 p0, v0;
    script.at(0, p0, v0);
    SimDevice dev({}, p0);
    SimDeviceIO io(dev, script, 1.0 / rate);
    ServoThreadConfig cfg;
    cfg.rate_hz = rate;
    cfg.sched_fifo = o.sched_fifo;
    cfg.pin_cpu = o.pin_cpu;
    cfg.cpu = o.cpu;
    cfg.lock_memory = o.lock_memory;
    cfg.record_ticks = std::size_t(rate * o.seconds * 1.1) + 16;
    ServoThread servo(published, renderer, io, cfg);

    std::atomic<bool> stop{false};
    std::atomic<long> publications{0};
    std::thread engine_thread([&] {
      std::uint64_t v = 1;
      while (engine_on && !stop.load()) {
        const double r = 20.0 + 1.5 * std::sin(double(v) * 0.3);  // the sculpt: radius breathes
        const engine::Volume vol = engine::make_sphere({64, 64, 64}, 1e-3, r);
        auto f = std::make_shared<SampleField>(pass ? pass->run(vol) : engine::compute_samples_cpu(vol));
        f->version = ++v;
        published.publish(std::move(f));
        publications.fetch_add(1);
      }
    });
    const std::string note = servo.start();
    if (!note.empty() && note != last_note) log << note;
    last_note = note;
    std::string sched = servo.got_fifo() ? "FIFO" : "default";
    sched += servo.pinned_cpu() >= 0 ? ", CPU " + std::to_string(servo.pinned_cpu()) : ", unpinned";
    sched += servo.memory_locked() ? ", mlock" : "";
    sched += engine_on ? "" : "; engine idle";
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    servo.stop();
    stop = true;
    engine_thread.join();

    std::vector<std::int64_t> e = servo.period_errors_ns();
    for (auto& x : e) x = x < 0 ? -x : x;
    std::sort(e.begin(), e.end());
    auto pct = [&](double q) {
      if (e.empty()) return 0.0;
      return double(e[std::min(e.size() - 1, std::size_t(q * double(e.size())))]) * 1e-3;
    };
    const double mx = e.empty() ? 0.0 : double(e.back()) * 1e-3;
    log << std::setw(7) << long(rate) << "  " << std::left << std::setw(32) << sched << std::right << std::setw(10)
        << servo.ticks() << std::setw(8) << servo.missed_deadlines() << std::fixed << std::setprecision(1)
        << std::setw(16) << pct(0.5) << std::setw(10) << pct(0.99) << std::setw(12) << pct(0.999) << std::setw(10)
        << mx << std::setw(14) << publications.load() << "\n"
        << std::defaultfloat;
    csv << rate << ',' << o.seconds << ",\"" << sched << "\"," << servo.ticks() << ',' << servo.missed_deadlines()
        << ',' << pct(0.5) << ',' << pct(0.99) << ',' << pct(0.999) << ',' << mx << ',' << publications.load()
        << '\n';
    if (rate == 10000.0) {
      (engine_on ? ticks_10k : ticks_idle) = servo.ticks();
      (engine_on ? missed_10k : missed_idle) = servo.missed_deadlines();
      (engine_on ? p999_10k : p999_idle) = pct(0.999);
    }
  }
  log << "period error = |actual period - nominal|; missed = ticks that started a whole period late. "
         "Load average after: " << load_average() << "\n";
  const double miss_per_10k = ticks_10k > 0 ? 1e4 * double(missed_10k) / double(ticks_10k) : 0.0;
  const bool met = ticks_10k > 0 && p999_10k <= 20.0 && miss_per_10k <= 1.0;
  log << std::fixed << std::setprecision(1) << "10 kHz target (p99.9 <= 20 us, <= 1 miss per 10,000 ticks): "
      << (met ? "met" : "NOT met") << ": p99.9 " << p999_10k << " us, " << std::setprecision(2) << miss_per_10k
      << " misses per 10,000 ticks (" << missed_10k << " in " << ticks_10k << "); with the engine idle: p99.9 "
      << std::setprecision(1) << p999_idle << " us, " << std::setprecision(2)
      << (ticks_idle > 0 ? 1e4 * double(missed_idle) / double(ticks_idle) : 0.0) << " misses per 10,000 ticks\n"
      << std::defaultfloat;
  if (!o.out_csv.empty()) {
    write_file_atomic(o.out_csv, csv.str());
    log << "wrote " << o.out_csv << "\n";
  }
  return 0;
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const auto c = line.find(':');
      return c == std::string::npos ? line : line.substr(c + 2);
    }
  return "unknown CPU";
}

std::string table1_verdict(const std::vector<Table1Row>& rows) {
  auto ratio = [](double num, double den) {
    const double r = num / den;
    return num > 0 && den > 0 && std::isfinite(r) ? r : std::numeric_limits<double>::infinity();
  };
  int k = 0, k_paper = 0;
  double worst = -1;
  std::string worst_scene;
  for (const Table1Row& r : rows) {
    const double q = ratio(r.hri_us, r.avila_us);
    if (q <= 1.0) ++k;
    if (ratio(r.hri_paper_us, r.avila_us) <= 1.0) ++k_paper;
    if (q > worst) {
      worst = q;
      worst_scene = r.scene;
    }
  }
  std::ostringstream s;
  s << std::fixed << std::setprecision(2) << "HRI/Avila <= 1 on " << k << " of " << rows.size() << " scenes";
  if (!rows.empty()) s << " (worst: " << worst_scene << " " << worst << ")";
  s << "; paper variant (Figure 2 as printed): " << k_paper << " of " << rows.size();
  return s.str();
}

std::string table1_bricked_verdict(const std::vector<Table1Row>& rows) {
  auto ratio = [](double num, double den) {
    const double r = num / den;
    return num > 0 && den > 0 && std::isfinite(r) ? r : std::numeric_limits<double>::infinity();
  };
  int k = 0;
  double worst = -1, worst16 = -1;
  std::string worst_scene, worst16_scene;
  for (const Table1Row& r : rows) {
    const double q = ratio(r.hri_bricked_us, r.hri_us), q16 = ratio(r.hri_fp16_us, r.hri_us);
    if (q <= 1.10) ++k;
    if (q > worst) {
      worst = q;
      worst_scene = r.scene;
    }
    if (q16 > worst16) {
      worst16 = q16;
      worst16_scene = r.scene;
    }
  }
  std::ostringstream s;
  s << std::fixed << std::setprecision(2) << "bricked/dense <= 1.10 on " << k << " of " << rows.size() << " scenes";
  if (!rows.empty()) s << " (worst: " << worst_scene << " " << worst << "); fp16/dense: worst " << worst16_scene << " "
                       << worst16;
  return s.str();
}

namespace {
/// The floor of an HRI tick on a stroke: the least work each kind of tick does, with no
/// robust rule. An update: the values at the HIP and at the VHIP (here the HIP of the tick
/// before), p by the linear rule, N by central differences at p (half a voxel), eq. 2 and 3;
/// a contact tick: eq. 2 and 3 on the held plane (no read); a free tick: one value read.
/// Each replays the whole stroke through a FieldView made per tick, as Renderer::tick does.
struct TickFloor {
  double update_ns = 0, contact_ns = 0, free_ns = 0;
};

template <class Tick>
double stroke_ns_per_tick(const std::vector<Vec3>& hips, Tick tick) {
  const auto t0 = std::chrono::steady_clock::now();
  for (const Vec3& h : hips) tick(h);
  return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
         double(std::max<std::size_t>(hips.size(), 1));
}

/// Median floor of `reps` replays of each kind, interleaved.
TickFloor hri_tick_floor(const SweepScene& s, double stiffness, int reps) {
  const SampleField& f = *s.field;
  const core::Isosurface iso{s.tau, s.inside};
  volatile double sink = 0;
  Vec3 prev = s.hip.empty() ? Vec3{} : s.hip[0], n_held{0, 0, 1}, p_held = prev;
  auto update = [&](const Vec3& x) {
    const core::FieldView v(f);
    const double e1 = iso.excess(v.value(x)), e0 = iso.excess(v.value(prev));
    double t = -e0 / (e1 - e0);
    t = std::isfinite(t) ? std::clamp(t, 0.0, 1.0) : 0.0;
    const Vec3 p = prev + (x - prev) * t;
    const Vec3 n = core::normalized_or(iso.outward(v.central_difference(p, v.grid().spacing_m * 0.5)), n_held);
    const Vec3 force = n * (stiffness * core::dot(n, p - x));
    sink = sink + force.x;
    prev = x;
    n_held = n;
    p_held = p;
  };
  auto contact = [&](const Vec3& x) {
    const core::FieldView v(f);
    const Vec3 vhip = x + n_held * core::dot(n_held, p_held - x);
    const Vec3 force = (vhip - x) * stiffness;
    sink = sink + force.x + core::norm(force) + double(v.version());
  };
  auto free_tick = [&](const Vec3& x) {
    const core::FieldView v(f);
    sink = sink + iso.excess(v.value(x));
  };
  std::vector<double> t[3];
  for (int r = 0; r < reps; ++r) {
    t[0].push_back(stroke_ns_per_tick(s.hip, update));
    t[1].push_back(stroke_ns_per_tick(s.hip, contact));
    t[2].push_back(stroke_ns_per_tick(s.hip, free_tick));
  }
  double med[3];
  for (int k = 0; k < 3; ++k) {
    std::sort(t[k].begin(), t[k].end());
    med[k] = t[k].empty() ? 0.0 : t[k][t[k].size() / 2];
  }
  return {med[0], med[1], med[2]};
}
}  // namespace

int run_bench_table1(const Table1Options& o, std::ostream& log) {
  using namespace servo;
  engine::ContextOptions co;
  co.device = o.device;
  auto ctx = engine::VulkanContext::create(co);
  engine::VulkanContext* vk = ctx ? ctx.value->get() : nullptr;
  log << "bench table1: " << cpu_model() << ", " << std::thread::hardware_concurrency()
      << " CPUs; one thread; samples from " << (vk ? vk->info().name : "the CPU reference") << "; "
      << o.warmup << " warm-up + " << o.repetitions
      << " timed replays of each stroke per algorithm, interleaved round by round, median; "
      << (o.realtime ? "timed as the servo thread runs (SCHED_FIFO on one CPU, where allowed: see the last line)"
                     : "timed under the default scheduler, unpinned")
      << "\n";
  std::string rt_used;  // the scheduling the replays got (the first scene's)
  struct PaperRow {
    const char* scene;
    const char* label;
    double hri, blezek, avila;  // us per loop
  };
  const PaperRow paper[] = {{"sphere", "sphere (64x64x64)", 39.00, 47.10, 38.30},
                            {"knot", "knot (64x64x64)", 42.00, 49.10, 41.20},
                            {"head", "head (paper 128x128x64; here 64x64x93)", 48.00, 59.70, 47.40},
                            {"chest", "lung (paper 128x128x64; here chest 256x256x64)", 46.80, 57.60, 46.20}};
  std::ostringstream csv;
  csv << "scene,algorithm,us_per_loop,rate_khz,paper_us_per_loop,paper_rate_khz\n";
  std::ostringstream tab;
  tab << std::fixed;
  tab << "\n| scene | HRI n=5 [us] | (paper) | HRI as printed [us] | Blezek-Robb [us] | (paper) | "
         "Avila-Sobierajski [us] | (paper) | HRI rate [kHz] | HRI/Avila | (paper) | HRI as printed/Avila | "
         "Blezek/HRI | (paper) | HRI bricked fp32 [us] | bricked/dense | HRI bricked fp16 [us] | fp16/dense |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::vector<Table1Row> rows;
  std::vector<ToolTickRow> tool_rows;  // every tick of the stroke timed: point and tools side by side
  std::ostringstream bytes, tools, floors;
  for (const PaperRow& pr : paper) {
    const SweepScene s = prepare_sweep_scene(pr.scene, vk, log);
    HriParams hp = reference_params(s);
    hp.plane_update_period = 5;
    hp.intersection = Intersection::kLinear;
    hp.normal = NormalSource::kCentral;
    HriParams hp_paper = hp;
    hp_paper.variant = Variant::kPaper;
    BaselineParams bp;
    bp.tau = s.tau;
    bp.inside = s.inside;
    bp.stiffness_n_per_m = s.stiffness_n_per_m;
    bp.force_limit_n = 1e3;
    HriRenderer hri(hp);
    HriRenderer hri_paper(hp_paper);
    BlezekRenderer blezek(bp);
    AvilaRenderer avila(bp);
    HriRenderer hri_bricked(hp), hri_fp16(hp);
    // The same stroke with a spherical tool of 2 voxels' radius (HriParams::tool_radius_m).
    HriParams hp_tool = hp;
    hp_tool.tool_radius_m = 2.0 * std::min({s.field->grid.spacing_m.x, s.field->grid.spacing_m.y, s.field->grid.spacing_m.z});
    HriRenderer hri_tool(hp_tool);
    // The bricked snapshots of the same samples (fp32: bit-identical reads in active bricks).
    const core::BrickedInput bin = core::bricked_input_from_dense(*s.field, core::Isosurface{s.tau, s.inside});
    SweepScene s32, s16;
    s32.field = std::make_shared<const SampleField>(core::make_bricked_field(bin, core::SampleFormat::kFp32));
    s16.field = std::make_shared<const SampleField>(core::make_bricked_field(bin, core::SampleFormat::kFp16));
    s32.hip = s16.hip = s.hip;
    const SweepScene* scenes[] = {&s, &s, &s, &s, &s32, &s16, &s};
    Renderer* algos[] = {&hri, &hri_paper, &blezek, &avila, &hri_bricked, &hri_fp16, &hri_tool};
    constexpr int kAlgos = 7, kTable = 6;  // the table's algorithms; then the spherical tool
    // Interleaved rounds: every algorithm of the table sees the same clock, cache and load
    // state. The spherical tool's replays (50-110 x the point's time) run in rounds of their
    // own after the table's: with one in every round of the table, HRI/Avila rose by
    // 0.04-0.07 on this project's test machine while Avila's own time did not move.
    // Each round starts one algorithm later than the round before, so that every algorithm
    // follows every other one as often.
    std::vector<double> t[kAlgos];
    auto rounds = [&](int first, int last) {
      const int k = last - first;
      for (int a = first; a < last; ++a) median_ns_per_tick(*algos[a], *scenes[a], o.warmup, 1);
      for (int rep = 0; rep < o.repetitions; ++rep)
        for (int j = 0; j < k; ++j) {
          const int a = first + (rep + j) % k;
          t[a].push_back(median_ns_per_tick(*algos[a], *scenes[a], 0, 1));
        }
    };
    // The timing as the servo thread runs (Table1Options::realtime) for the rest of this
    // scene: its rounds and the floor (the snapshot byte counts in between are
    // single-threaded). Not the preparation: its worker threads must not inherit it.
    std::optional<servo::ScopedRealtime> rt;
    if (o.realtime) rt.emplace("bench table1");
    if (rt_used.empty()) {
      if (!rt) {
        rt_used = "default scheduler, unpinned (--no-realtime)";
      } else {
        const servo::RealtimeSetup& g = rt->setup();
        rt_used = std::string(g.fifo ? "SCHED_FIFO" : "default scheduler") + ", " +
                  (g.cpu >= 0 ? "CPU " + std::to_string(g.cpu) : std::string("unpinned"));
        if (!g.note.empty()) rt_used += "; " + g.note;
      }
    }
    rounds(0, kTable);
    rounds(kTable, kAlgos);
    tool_rows.push_back(measure_tool_ticks(s, hp, {1, 3, 10}, 1, std::max(3, o.repetitions / 10)));
    double med[kAlgos];
    for (int a = 0; a < kAlgos; ++a) {
      std::sort(t[a].begin(), t[a].end());
      med[a] = t[a][t[a].size() / 2] * 1e-3;
    }
    Table1Row row{pr.scene, med[0], med[1], med[2], med[3], med[4], med[5]};
    {
      const double dense = double(core::snapshot_bytes(*s.field));
      const core::BrickUsage use = core::brick_usage(*s32.field);
      bytes << std::fixed << std::setprecision(1) << "  " << pr.scene << ": " << use.active << " of " << use.total
            << " bricks active (" << 100.0 * double(use.active) / double(std::max<std::size_t>(use.total, 1))
            << " %); fp32 " << 100.0 * double(core::snapshot_bytes(*s32.field)) / dense << " %, fp16 "
            << 100.0 * double(core::snapshot_bytes(*s16.field)) / dense << " %, unorm16 "
            << 100.0 * double(core::snapshot_bytes(core::make_bricked_field(bin, core::SampleFormat::kUnorm16))) / dense
            << " % of the dense fp32 " << std::setprecision(2) << dense / (1024.0 * 1024.0) << " MiB\n";
    }
    rows.push_back(row);
    {
      const TickFloor fl = hri_tick_floor(s, hp.stiffness_n_per_m, o.repetitions);
      const double n = hp.plane_update_period;
      const double contact_stroke = ((n - 1) * fl.contact_ns + fl.update_ns) / n;
      floors << std::fixed << std::setprecision(1) << "  " << pr.scene << ": update " << fl.update_ns << " ns ("
             << std::setprecision(2) << fl.update_ns / (1e3 * row.avila_us) << " x Avila's tick), contact "
             << std::setprecision(1) << fl.contact_ns << " ns, free " << fl.free_ns << " ns; contact ticks at n = "
             << int(n) << ": " << contact_stroke << " ns (" << std::setprecision(2)
             << contact_stroke / (1e3 * row.avila_us) << " x Avila); HRI as shipped " << std::setprecision(1)
             << 1e3 * row.hri_us << " ns, Avila " << 1e3 * row.avila_us << " ns\n";
      const double pc_ns = port_passivity_ns_per_tick(s.hip, 1000000, 5);
      floors << "    passivity controller (servo/port_passivity, on, 10^6 ticks of the stroke): " << std::setprecision(1)
             << pc_ns << " ns per tick, " << 100.0 * pc_ns / fl.update_ns << " % of the update's floor (target < 10 %)\n";
      const double live_ns = live_passivity_ns_per_tick(s.hip, 1000000, 5);
      floors << "    passivity stage on the live path (servo/live_passivity: step and sent, the device's clock, "
             << "atomics): " << live_ns << " ns per tick, " << 100.0 * live_ns / fl.update_ns << " % of the update's floor\n";
    }
    tools << std::fixed << std::setprecision(3) << "  " << pr.scene << ": HRI with a spherical tool of radius "
          << hp_tool.tool_radius_m * 1e3 << " mm (2 voxels) " << med[6] << " us per tick, " << std::setprecision(2)
          << med[6] / row.hri_us << " x the point (the table's " << std::setprecision(3) << row.hri_us << " us)\n";
    tab << std::setprecision(3) << "| " << pr.label << " | " << row.hri_us << " | " << std::setprecision(2) << pr.hri
        << " | " << std::setprecision(3) << row.hri_paper_us << " | " << row.blezek_us << " | "
        << std::setprecision(2) << pr.blezek << " | " << std::setprecision(3) << row.avila_us << " | "
        << std::setprecision(2) << pr.avila << " | " << std::setprecision(0) << 1e3 / row.hri_us << " | "
        << std::setprecision(2) << row.hri_us / row.avila_us << " | " << pr.hri / pr.avila << " | "
        << row.hri_paper_us / row.avila_us << " | " << row.blezek_us / row.hri_us << " | " << pr.blezek / pr.hri
        << " | " << std::setprecision(3) << row.hri_bricked_us << " | " << std::setprecision(2)
        << row.hri_bricked_us / row.hri_us << " | " << std::setprecision(3) << row.hri_fp16_us << " | "
        << std::setprecision(2) << row.hri_fp16_us / row.hri_us << " |\n";
    for (const auto& [name, tt, p] :
         {std::tuple{"HRI", row.hri_us, pr.hri}, std::tuple{"HRI as printed", row.hri_paper_us, pr.hri},
          std::tuple{"Blezek-Robb", row.blezek_us, pr.blezek}, std::tuple{"Avila-Sobierajski", row.avila_us, pr.avila},
          std::tuple{"HRI bricked fp32", row.hri_bricked_us, pr.hri}, std::tuple{"HRI bricked fp16", row.hri_fp16_us, pr.hri}})
      csv << pr.scene << ',' << name << ',' << tt << ',' << 1e3 / tt << ',' << p << ',' << 1e3 / p << '\n';
  }
  log << tab.str() << "\n" << table1_verdict(rows) << " (the paper: HRI/Avila 1.01-1.02)\n"
      << table1_bricked_verdict(rows) << " (HRI tick on the bricked snapshot at most 10 % above dense)\n"
      << "The same strokes with a spherical tool (the HIP is the tool's centre; its surface meets the isosurface "
         "earlier, so contact differs from the point's; timed after the table, in rounds of its own):\n"
      << tools.str()
      << "Every tick of the same strokes timed on its own (point and tools in the same rounds, after the table's; "
         "targets: p99 <= 50 us, so that 4 kHz holds with margin, and median within 20 x the point's):\n";
  for (const ToolTickRow& t : tool_rows) log << tool_tick_lines(t);
  log << tool_tick_verdict(tool_rows) << "\n"
      << "The floor of an HRI tick (no robust rule; median of the same number of replays after the table's): an "
         "update reads the values at the HIP and the VHIP, p by the linear rule, N by central differences at p, "
         "eq. 2-3; a contact tick applies eq. 2-3 on the held plane; a free tick reads one value:\n"
      << floors.str()
      << "Snapshot bytes (brick table + tiles + pool [+ unorm16 decode] over voxels * 16):\n"
      << bytes.str()
      << "\nTimes are Renderer::tick only (no device I/O), averaged over the whole stroke (free motion and "
         "contact), on this machine; the paper's are whole GHOST servo loops on a 1999 SGI Octane R10000. "
         "\"HRI as printed\" is the paper's Figure 2 without the departures listed in servo/hri.h.\n"
      << "Scheduling of the timed replays: " << rt_used << (rt_used.back() == '\n' ? "" : "\n");
  if (!o.out_csv.empty()) {
    write_file_atomic(o.out_csv, csv.str());
    log << "wrote " << o.out_csv << "\n";
  }
  return 0;
}

}  // namespace isotouch::bench
