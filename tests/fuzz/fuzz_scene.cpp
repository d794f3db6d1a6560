// libFuzzer target for the scene parser: any input either parses or throws SceneError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "isotouch/io/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const isotouch::io::Scene s = isotouch::io::parse_scene(text, "fuzz.json");
    // Whatever parses must be usable: the invariants the servo relies on hold.
    if (!(s.hri.stiffness_n_per_m > 0) || !(s.hri.force_limit_n > 0) || s.hri.plane_update_period < 1 ||
        !(s.hri.rate_hz > 0) || !(s.device.mass_kg > 0))
      __builtin_trap();
    // The script's ray starts near the volume box, and the device can be simulated.
    for (int a = 0; a < 3; ++a)
      if (!(s.script.ray_origin_frac[a] >= isotouch::sim::kRayOriginFracMin &&
            s.script.ray_origin_frac[a] <= isotouch::sim::kRayOriginFracMax))
        __builtin_trap();
    if (isotouch::sim::min_stable_substeps(s.device, 1.0 / s.hri.rate_hz) > 10000) __builtin_trap();
  } catch (const isotouch::io::SceneError&) {
  }
  return 0;
}
