#include "bench_cmd.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>

#include "cpu_gradient.h"
#include "files.h"
#include "gradient_pass.h"
#include "servo_thread.h"
#include "synthetic.h"
#include "vk_context.h"

namespace isotouch::app {

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
      << engine_name << " and publishes it; " << std::thread::hardware_concurrency() << " CPUs\n";

  std::ostringstream csv;
  csv << "rate_hz,seconds,ticks,missed_deadlines,period_err_p50_us,period_err_p99_us,period_err_p999_us,"
         "period_err_max_us,publications\n";
  log << "   rate   ticks  missed   |err| p50 [us]  p99 [us]  p99.9 [us]  max [us]  publications\n";
  for (double rate : {1000.0, 4000.0, 10000.0}) {
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
    cfg.cpu = o.cpu;
    cfg.record_ticks = std::size_t(rate * o.seconds * 1.1) + 16;
    ServoThread servo(published, renderer, io, cfg);

    std::atomic<bool> stop{false};
    std::atomic<long> publications{0};
    std::thread engine_thread([&] {
      std::uint64_t v = 1;
      while (!stop.load()) {
        const double r = 20.0 + 1.5 * std::sin(double(v) * 0.3);  // the sculpt: radius breathes
        const engine::Volume vol = engine::make_sphere({64, 64, 64}, 1e-3, r);
        auto f = std::make_shared<SampleField>(pass ? pass->run(vol) : engine::compute_samples_cpu(vol));
        f->version = ++v;
        published.publish(std::move(f));
        publications.fetch_add(1);
      }
    });
    const std::string note = servo.start();
    if (!note.empty() && rate == 1000.0) log << "note: " << note << "\n";
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
    log << std::setw(7) << long(rate) << std::setw(8) << servo.ticks() << std::setw(8) << servo.missed_deadlines()
        << std::fixed << std::setprecision(1) << std::setw(17) << pct(0.5) << std::setw(10) << pct(0.99)
        << std::setw(12) << pct(0.999) << std::setw(10) << mx << std::setw(14) << publications.load() << "\n"
        << std::defaultfloat;
    csv << rate << ',' << o.seconds << ',' << servo.ticks() << ',' << servo.missed_deadlines() << ',' << pct(0.5)
        << ',' << pct(0.99) << ',' << pct(0.999) << ',' << mx << ',' << publications.load() << '\n';
  }
  log << "period error = |actual period - nominal|; missed = ticks that started a whole period late.\n";
  if (!o.out_csv.empty()) {
    write_file_atomic(o.out_csv, csv.str());
    log << "wrote " << o.out_csv << "\n";
  }
  return 0;
}

}  // namespace isotouch::app
