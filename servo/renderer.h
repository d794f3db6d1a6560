// renderer.h - the interface every haptic renderer of an isosurface implements.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/core/field_view.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"

namespace isotouch::servo {

/// The virtual plane (N, p) of eq. 1: N . (x - p) = 0, N the unit outward normal.
struct VirtualPlane {
  Vec3 n;              ///< unit outward normal (volume frame)
  Vec3 p;              ///< point on the isosurface (world [m])
  bool valid = false;  ///< false = the paper's VirtualPlane = (0, 0)
};

/// What one servo tick produced (common to HRI and the baselines).
struct HriTick {
  Vec3 force_n;               ///< force on the device [N], device axes (= volume axes)
  Vec3 vhip_m;                ///< VHIP (contact point) after this tick, world [m]
  VirtualPlane plane;         ///< the plane in use after this tick (HRI only)
  double penetration_m = 0;   ///< |HIP - VHIP| in world [m] while in contact, else 0
  bool contact = false;       ///< a contact force was rendered this tick
  bool plane_update = false;  ///< the plane was (re)computed this tick
  bool saturated = false;     ///< |F| hit the force limit
  bool fault = false;         ///< non-finite HIP or force: zero force was sent
};
using RenderTick = HriTick;

/// A servo-side renderer: one call per tick, reading published samples only. tick()
/// must allocate nothing, take no lock and make no syscall.
class Renderer {
 public:
  virtual ~Renderer() = default;
  /// Short name for reports ("HRI", "Avila-Sobierajski", "Blezek-Robb").
  virtual const char* name() const = 0;
  /// Forget contact state.
  virtual void reset() = 0;
  /// One tick. @param field the published samples, read only through core::FieldView
  /// (dense or, later, bricked: the renderer cannot tell); @param hip_world_m HIP in
  /// grid-world [m]; @param dt_s the measured time since the previous tick [s]; dt_s <= 0
  /// or non-finite means the nominal period 1/rate_hz (simulations, tests).
  /// Every renderer overrides this one. The default renders nothing (zero force,
  /// fault = true): it is not pure only so that a wrapper written before FieldView that
  /// overrides the SampleField overload alone (tests/test_servo_thread.cpp's spy) still
  /// compiles; make it pure once none is left.
  virtual HriTick tick(const FieldView& field, const Vec3& hip_world_m, double dt_s) {
    (void)field;
    (void)hip_world_m;
    (void)dt_s;
    HriTick t;
    t.fault = true;
    return t;
  }
  /// Tick on a dense field: makes the FieldView (a few copies, no allocation) and calls
  /// the overload above. Virtual only for the wrappers described there.
  virtual HriTick tick(const SampleField& field, const Vec3& hip_world_m, double dt_s) {
    return tick(FieldView(field), hip_world_m, dt_s);
  }
  /// Tick at the nominal period (same as dt_s = 0).
  HriTick tick(const SampleField& field, const Vec3& hip_world_m) {
    return tick(field, hip_world_m, 0.0);  // the virtual SampleField overload: wrappers see it
  }
  HriTick tick(const FieldView& field, const Vec3& hip_world_m) { return tick(field, hip_world_m, 0.0); }
};

}  // namespace isotouch::servo
