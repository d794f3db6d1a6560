// haptic_device.h - the one factory behind `--haptic KIND:ARGS`: the device a live session
// drives, and the check of the renderer's gains against the device's capabilities.
//   sim              the scene's simulated device pulled by its scripted hand (default)
//   null             zero force, the HIP fixed where the scene's script starts
//   playback:FILE    replays the HIP of a trace.csv (`isotouch run`) or a recording (.rec)
//   hid:VID:PID[:SERIAL] | hid:/dev/hidrawN   a USB HID device (isotouch protocol v1)
//   polhem:VID:PID[:SERIAL] | polhem:/dev/hidrawN | polhem:emu:SOCKET [,config=v1|v3]   a Polhem
//                    with that configuration's kinematics (default v3; the description names its source)
//   emu:SOCKET       isotouch-devemu on a Unix-domain socket (protocol v1)
//   openhaptics[:NAME], forcedimension[:INDEX]   vendor SDKs loaded at run time (sdk_haptic_device.h)
//   igtl:HOST:PORT[:STREAM]  an OpenIGTLink source (a PlusServer): service/igtl_device.h
#pragma once
#include <memory>
#include <string>

#include "isotouch/core/vec3.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/workspace.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"

// Named by pointer or reference only (IgtlLoop: a declaration's return): the back-ends' classes (internal: servo/report_device.h,
// sdk_device.h, service/igtl_device.h) and the scene's types (io/scene.h, run/scene_setup.h).
namespace isotouch::service {
class IgtlDevice;
struct IgtlLoop;
}
namespace isotouch::servo {
class ReportDevice;
class SdkDevice;
}  // namespace isotouch::servo
namespace isotouch::engine {
struct Volume;
}
namespace isotouch::io {
struct Scene;
}
namespace isotouch::run {
struct SceneSetup;
}

namespace isotouch::run {

/// An opened device and what it needs to live.
struct HapticDevice {
  std::string kind;                         ///< "sim", "null", "playback", "hid", "emu"
  std::string description;                  ///< for the log ("emu:/tmp/d.sock (isotouch-devemu, 1000 Hz)")
  std::unique_ptr<servo::HapticDeviceIO> io;
  servo::ReportDevice* report = nullptr;    ///< io as a report device (hid, emu), else null
  servo::SdkDevice* sdk = nullptr;          ///< io as a vendor SDK device (openhaptics, forcedimension), else null
  service::IgtlDevice* igtl = nullptr;      ///< io as an OpenIGTLink stream (igtl), else null
  std::unique_ptr<sim::SimDevice> sim;      ///< the simulated device behind io (sim only)
};

/// What a device is opened for: the scene's device model and rate, the renderer its caps are
/// checked against, the workspace map, and where the HIP starts.
struct DeviceSetup {
  const io::Scene* scene = nullptr;              ///< device model, servo rate, button-down times
  const engine::Volume* volume = nullptr;        ///< a trace.csv's physical frame -> world
  servo::HriParams hri;                          ///< checked against the device's caps
  servo::WorkspaceTransform world_T_device;      ///< world = translation + scale * device
  /// The scripted hand of `sim` (which needs it: null refuses `sim`); the HIP of `null`
  /// stays at the script's start, else at `start_world_m`.
  const sim::TouchScript* script = nullptr;
  core::Vec3 start_world_m{};                    ///< `null`'s fixed HIP without a script [m, world]
};

/// The DeviceSetup of a scene set up for `isotouch run` (its script, volume, renderer, map).
DeviceSetup device_setup(const io::Scene& scene, const SceneSetup& setup);

/// Parses and opens `spec` for `ds` (see DeviceSetup).
/// @throws std::invalid_argument on a bad spec (names the kind and what is wrong, lists the
/// kinds), std::runtime_error if the device cannot be opened or its capabilities refuse the
/// scene's renderer (check_caps).
/// `io_fifo_priority` > 0: a hid or emu device's reader and writer threads ask for SCHED_FIFO.
HapticDevice open_haptic_device(const std::string& spec, const DeviceSetup& ds, int io_fifo_priority = 0);

/// The loop a link to the scene's device closes (its servo, hand, device, round trip and the
/// peer's controller): what `--haptic igtl:` and serve's TRANSFORM stream judge their
/// stiffness by (service::judge_link_stiffness).
service::IgtlLoop scene_link_loop(const io::Scene& scene);

/// "" if the renderer's stiffness, damping and force limit are within the device's
/// capabilities, else one line naming each offending value and the device's limit.
std::string check_caps(const servo::HriParams& hri, const servo::DeviceCaps& caps);

}  // namespace isotouch::run
