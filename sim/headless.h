// headless.h - step the servo at a fixed rate in simulated time (deterministic).
#pragma once
#include "isotouch/sim/servo_names.h"
#include <cstdint>
#include <functional>
#include <vector>

#include "isotouch/servo/hri.h"
#include "isotouch/servo/renderer.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/servo/workspace.h"

namespace isotouch::sim {

/// One row of the trace (one servo tick).
struct TraceRow {
  double t_s = 0;           ///< simulated time [s]
  Vec3 hip_m;               ///< HIP, world [m]
  Vec3 vhip_m;              ///< VHIP, world [m]
  Vec3 force_n;             ///< force sent to the device [N]
  Vec3 hand_target_m;       ///< operator's hand target, world [m]
  double penetration_m = 0; ///< |HIP - VHIP| [m] in contact
  std::int64_t tick_ns = 0; ///< wall time of HriRenderer::tick [ns]
  bool contact = false;
  bool plane_update = false;
  bool saturated = false;
  bool fault = false;
  bool button = false;        ///< the device's button (set by the after-tick hook; false without one)
  std::uint64_t version = 0;  ///< SampleField::version of the snapshot this tick read
  servo::VirtualPlane plane;  ///< the plane in use after this tick (HRI; invalid for the baselines)
};

/// The row of a tick at `t_s` [s] whose renderer answered `out` for `hip_m` (world [m]) in
/// `tick_ns` [ns]; the hand target, button and version are the caller's to set.
TraceRow trace_row(double t_s, const Vec3& hip_m, const servo::HriTick& out, std::int64_t tick_ns);

/// Called after tick k's render (and the device step) with that tick's row, before tick
/// k + 1 acquires its samples: what it publishes, tick k + 1 reads (the edit pipeline's
/// determinism rule, session/edit_session.h). It may set row.button. Outside the timed section.
using TickHook = std::function<void(long k, TraceRow& row)>;

/// Tick k of run_headless (t = k / rate_hz): acquire the newest published samples, read
/// the device, time Renderer::tick, command the force, advance the device one period toward
/// the script's hand target at t + period. A caller that owns the clock (a window's frame
/// loop on a simulated clock) runs ticks one at a time through this; run_headless is a loop of it.
/// Throws std::runtime_error if nothing was ever published.
TraceRow headless_tick(TripleBuffer<SampleField>& samples, servo::Renderer& renderer, SimDevice& device,
                       const WorkspaceTransform& world_T_device, const TouchScript& script, double rate_hz, long k);

/// Runs the script to its end at `rate_hz`. Each tick: acquire the newest published
/// samples, read the device, time Renderer::tick (nominal period) with steady_clock, command the force
/// (held over the period), then advance the device. `progress(tick, total)` is called
/// every `progress_every` ticks, outside the timed section. Throws std::runtime_error
/// if nothing was ever published. `after_tick`, if set, is called at the end of every tick
/// (TickHook); without it the loop is exactly what it was before hooks existed.
std::vector<TraceRow> run_headless(TripleBuffer<SampleField>& samples, servo::Renderer& renderer,
                                   SimDevice& device, const WorkspaceTransform& world_T_device,
                                   const TouchScript& script, double rate_hz,
                                   const std::function<void(long, long)>& progress = {},
                                   long progress_every = 250, const TickHook& after_tick = {});

}  // namespace isotouch::sim
