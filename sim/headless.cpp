#include "isotouch/sim/headless.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

namespace isotouch::sim {

TraceRow trace_row(double t_s, const Vec3& hip_m, const servo::HriTick& out, std::int64_t tick_ns) {
  TraceRow r;
  r.t_s = t_s;
  r.hip_m = hip_m;
  r.vhip_m = out.vhip_m;
  r.force_n = out.force_n;
  r.penetration_m = out.penetration_m;
  r.plane = out.plane;
  r.tick_ns = tick_ns;
  r.contact = out.contact;
  r.plane_update = out.plane_update;
  r.saturated = out.saturated;
  r.fault = out.fault;
  return r;
}

TraceRow headless_tick(TripleBuffer<SampleField>& samples, servo::Renderer& renderer, SimDevice& device,
                       const WorkspaceTransform& xf, const TouchScript& script, double rate_hz, long k) {
  using clock = std::chrono::steady_clock;
  const double period = 1.0 / rate_hz;
  const double t = double(k) * period;
  const SampleField* field = samples.acquire();
  if (!field) throw std::runtime_error("servo: no sample field was published");
  const Vec3 hip = xf.to_world(device.position());

  const auto t0 = clock::now();
  const HriTick out = renderer.tick(*field, hip);  // the nominal period
  const auto t1 = clock::now();

  device.command_force(out.force_n);
  const Vec3 sent = device.applied_force();
  Vec3 tgt_w, tgt_v;
  script.at(t + period, tgt_w, tgt_v);
  device.step(period, xf.to_device(tgt_w), tgt_v / xf.scale);

  TraceRow r = trace_row(t, hip, out, std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count());
  r.force_n = sent;  // what the device took (refused: 0; clipped at its maximum)
  r.hand_target_m = tgt_w;
  r.version = field->version;
  return r;
}

std::vector<TraceRow> run_headless(TripleBuffer<SampleField>& samples, servo::Renderer& renderer,
                                   SimDevice& device, const WorkspaceTransform& xf,
                                   const TouchScript& script, double rate_hz,
                                   const std::function<void(long, long)>& progress,
                                   long progress_every, const TickHook& after_tick) {
  const long ticks = long(std::ceil(script.duration_s * rate_hz)) + 1;
  std::vector<TraceRow> trace(std::size_t(ticks), TraceRow{});
  for (long k = 0; k < ticks; ++k) {
    TraceRow& r = trace[std::size_t(k)];
    r = headless_tick(samples, renderer, device, xf, script, rate_hz, k);
    if (after_tick) after_tick(k, r);
    if (progress && (k % progress_every == 0 || k + 1 == ticks)) progress(k + 1, ticks);
  }
  return trace;
}

}  // namespace isotouch::sim
