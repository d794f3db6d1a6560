// haptic_device.h - the one factory behind `--haptic KIND:ARGS`: the device a live session
// drives, and the check of the renderer's gains against the device's capabilities.
//   sim              the scene's simulated device pulled by its scripted hand (default)
//   null             zero force, the HIP fixed where the scene's script starts
//   playback:FILE    replays the HIP of a trace.csv (`isotouch run`) or a recording (.rec)
//   hid:VID:PID[:SERIAL] | hid:/dev/hidrawN   a USB HID device (isotouch protocol v1, Polhem)
//   emu:SOCKET       isotouch-devemu on a Unix-domain socket (protocol v1)
#pragma once
#include <memory>
#include <string>

#include "device_io.h"
#include "hri.h"
#include "report_device.h"
#include "run_job.h"
#include "sim_device.h"
#include "workspace.h"

namespace isotouch::app {

/// An opened device and what it needs to live.
struct HapticDevice {
  std::string kind;                         ///< "sim", "null", "playback", "hid", "emu"
  std::string description;                  ///< for the log ("emu:/tmp/d.sock (isotouch-devemu, 1000 Hz)")
  std::unique_ptr<servo::HapticDeviceIO> io;
  servo::ReportDevice* report = nullptr;    ///< io as a report device (hid, emu), else null
  std::unique_ptr<sim::SimDevice> sim;      ///< the simulated device behind io (sim only)
};

/// Parses and opens `spec` for `scene` (its script, device model, rate and workspace map).
/// @throws std::invalid_argument on a bad spec (names the kind and what is wrong, lists the
/// kinds), std::runtime_error if the device cannot be opened or its capabilities refuse the
/// scene's renderer (check_caps).
/// `io_fifo_priority` > 0: a hid or emu device's reader and writer threads ask for SCHED_FIFO.
HapticDevice open_haptic_device(const std::string& spec, const io::Scene& scene, const SceneSetup& setup,
                                int io_fifo_priority = 0);

/// "" if the renderer's stiffness, damping and force limit are within the device's
/// capabilities, else one line naming each offending value and the device's limit.
std::string check_caps(const servo::HriParams& hri, const servo::DeviceCaps& caps);

}  // namespace isotouch::app
