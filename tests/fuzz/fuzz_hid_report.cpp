// libFuzzer target for the device report parsers (protocol v1 input, output and capability
// reports, the Polhem's input report): any bytes either decode or are refused with a reason;
// what decodes re-encodes to the same bytes (v1) and gives a finite position (Polhem).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>

#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/hid_report.h"

using namespace isotouch::servo;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> b(data, size);
  hid::InputReport in;
  if (const hid::Decoded d = hid::decode(b, in); d) {
    const auto again = hid::encode(in);
    if (!std::equal(again.begin(), again.end(), b.begin(), b.end())) __builtin_trap();
    if (!std::isfinite(in.position_m.x) || !std::isfinite(in.position_m.z)) __builtin_trap();
  } else if (d.error.empty()) {
    __builtin_trap();
  }
  hid::OutputReport out;
  if (hid::decode(b, out) && !(std::isfinite(out.force_n.x) && std::isfinite(out.force_n.y))) __builtin_trap();
  DeviceCaps caps;
  if (hid::decode_caps(b, caps) && !(caps.max_force_n > 0)) __builtin_trap();
  hid::polhem::Input p;
  if (hid::polhem::decode(b, p)) {
    const auto pos = hid::polhem::position_m(p.encoder, hid::polhem::Config::kV1);
    if (!std::isfinite(pos.x) || !std::isfinite(pos.y) || !std::isfinite(pos.z)) __builtin_trap();
    // polhem_v3's linkage does not close everywhere: such a pose is refused, never used.
    const auto pos3 = hid::polhem::position_m(p.encoder, hid::polhem::Config::kV3);
    if (!(std::isfinite(pos3.x) && std::isfinite(pos3.y) && std::isfinite(pos3.z)) &&
        hid::polhem::check_pose(pos3, hid::polhem::Config::kV3).empty())
      __builtin_trap();
  }
  // The protocol object as the reader thread uses it.
  V1Protocol v1;
  DeviceReading r;
  (void)v1.decode_input(b, r);
  return 0;
}
