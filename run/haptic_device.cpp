#include "isotouch/run/haptic_device.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/names.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/sdk_device.h"

#include <sstream>
#include <stdexcept>

#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/hid_device.h"
#include "isotouch/sim/null_device_io.h"
#include "isotouch/sim/playback_device_io.h"
#include "isotouch/io/record.h"
#include "isotouch/sim/sim_device_io.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/run/sdk_haptic_device.h"
#include "isotouch/service/igtl_device.h"

namespace isotouch::run {
namespace {
constexpr const char* kKinds =
    "sim, null, playback:FILE, hid:VID:PID[:SERIAL], hid:/dev/hidrawN, polhem:VID:PID[:SERIAL]|/dev/hidrawN|emu:SOCKET[,config=v1|v3], "
    "emu:SOCKET, openhaptics[:NAME], forcedimension[:INDEX], igtl:HOST:PORT[:STREAM]";

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

/// The HIPs of a trace.csv (physical frame) or a recording (world), in device metres.
std::vector<sim::PlaybackSample> playback_samples(const std::string& file, const DeviceSetup& ds) {
  std::vector<sim::PlaybackSample> out;
  const servo::WorkspaceTransform& xf = ds.world_T_device;
  if (file.size() > 4 && file.substr(file.size() - 4) == ".rec") {
    const io::Recording rec = io::load_recording(file, true);
    for (const io::RecordedTick& t : rec.ticks) out.push_back({t.t_s, xf.to_device(t.hip_m), t.button ? 1u : 0u});
    if (out.empty()) throw std::runtime_error(file + ": the recording has no ticks");
    return out;
  }
  out = sim::load_trace_hips(file);
  for (sim::PlaybackSample& s : out) s.position_m = xf.to_device(ds.volume->to_grid(s.position_m));
  return out;
}

HapticDevice open_report(const std::string& kind, const std::string& arg, int fifo) {
  HapticDevice d;
  d.kind = kind;
  std::unique_ptr<servo::ReportDevice> dev;
  std::string note;
  if (kind == "polhem") {
    const servo::PolhemSpec ps = servo::parse_polhem_spec(arg);
    dev = servo::open_polhem(ps, fifo);
    note = "; " + servo::polhem_config_note(ps);
  } else if (kind == "hid") {
    dev = servo::open_hid_device(arg, fifo);
  } else {
    servo::ReportDeviceOptions o;
    o.fifo_priority = fifo;
    dev = std::make_unique<servo::ReportDevice>(std::make_unique<servo::SocketLink>(arg),
                                                std::make_unique<servo::V1Protocol>(), o);
    dev->open();
  }
  const servo::DeviceCaps c = dev->caps();
  d.description = dev->name() + " (" + c.name + ", " + num(c.native_rate_hz) + " Hz, max " + num(c.max_force_n) + " N)" + note;
  if (!dev->warning().empty()) d.description += "; warning: " + dev->warning();
  d.report = dev.get();
  d.io = std::move(dev);
  return d;
}
}  // namespace

std::string check_caps(const servo::HriParams& hri, const servo::DeviceCaps& caps) {
  std::string e;
  auto over = [&](const char* what, double v, const char* limit, double max) {
    if (v > max) e += std::string(e.empty() ? "" : "; ") + what + " " + num(v) + " exceeds the device's " + limit + " " + num(max);
  };
  over("servo.stiffness_n_per_m", hri.stiffness_n_per_m, "maximum stiffness", caps.max_stiffness_n_per_m);
  over("servo.damping_n_s_per_m", hri.damping_n_s_per_m, "maximum damping", caps.max_damping_n_s_per_m);
  over("servo.force_limit_n", hri.force_limit_n, "maximum force", caps.max_force_n);
  return e;
}

DeviceSetup device_setup(const io::Scene& scene, const SceneSetup& setup) {
  DeviceSetup ds;
  ds.scene = &scene;
  ds.volume = &setup.volume;
  ds.hri = setup.hri;
  ds.world_T_device = setup.world_T_device;
  ds.script = &setup.script;
  return ds;
}

service::IgtlLoop scene_link_loop(const io::Scene& scene) {
  return {scene.hri.rate_hz, scene.device.damping_n_s_per_m + scene.device.hand_damping_n_s_per_m,
          scene.hri.damping_n_s_per_m, scene.hri.stiffness_n_per_m, scene.allow_unstable_stiffness,
          scene.device, scene.link_round_trip_s, scene.link_passivity_control};
}

HapticDevice open_haptic_device(const std::string& spec, const DeviceSetup& ds, int io_fifo_priority) {
  const std::size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
  const bool sdk = kind == "openhaptics" || kind == "forcedimension";  // optional argument
  if (kind != "sim" && kind != "null" && kind != "playback" && kind != "hid" && kind != "polhem" && kind != "emu" && kind != "igtl" && !sdk)
    throw std::invalid_argument("--haptic " + spec + ": unknown kind '" + kind + "' (kinds: " + kKinds + ")");
  const bool needs_arg = kind == "playback" || kind == "hid" || kind == "polhem" || kind == "emu" || kind == "igtl";
  if (needs_arg && arg.empty()) throw std::invalid_argument("--haptic " + spec + ": " + kind + " needs an argument (" + kKinds + ")");
  if (!needs_arg && !sdk && colon != std::string::npos)
    throw std::invalid_argument("--haptic " + spec + ": " + kind + " takes no argument");
  if (kind == "sim" && !ds.script)
    throw std::invalid_argument("--haptic " + spec + ": sim needs the scene's scripted hand, which this front end has not");
  core::Vec3 start_w = ds.start_world_m, v0;
  if (ds.script) ds.script->at(0.0, start_w, v0);
  const io::Scene& scene = *ds.scene;
  const double T = 1.0 / scene.hri.rate_hz;
  HapticDevice d;
  d.kind = kind;
  if (kind == "sim") {
    d.sim = std::make_unique<sim::SimDevice>(scene.device, ds.world_T_device.to_device(start_w));
    d.io = std::make_unique<sim::SimDeviceIO>(*d.sim, *ds.script, T, ds.world_T_device, &scene.edits.button_down);
    d.description = "sim (the scene's simulated device and scripted hand)";
  } else if (kind == "null") {
    d.io = std::make_unique<sim::NullDeviceIO>(ds.world_T_device.to_device(start_w));
    d.description = "null (zero force, fixed at the script's start)";
  } else if (kind == "playback") {
    auto p = std::make_unique<sim::PlaybackDeviceIO>(playback_samples(arg, ds), T);
    d.description = "playback:" + arg + " (" + num(p->duration_s()) + " s)";
    d.io = std::move(p);
  } else if (sdk) {
    auto dev = open_sdk_device(kind, arg, d.description);
    d.sdk = dev.get();
    d.io = std::move(dev);
  } else if (kind == "igtl") {  // the loop closes at the stream's rate: its stiffness bound is checked there
    auto dev = service::open_igtl_device(arg, scene_link_loop(scene), d.description, io_fifo_priority, scene.link_max_force_n);
    d.igtl = dev.get();
    d.io = std::move(dev);
  } else {
    d = open_report(kind, arg, io_fifo_priority);
  }
  if (const std::string e = check_caps(ds.hri, d.io->caps()); !e.empty())
    throw std::runtime_error("--haptic " + spec + ": the scene's renderer does not fit the device: " + e);
  // A device that keeps its last force when the host stops sending is driven only on purpose.
  if (d.report && !(d.io->caps().watchdog_s > 0) && !scene.allow_no_watchdog)
    throw std::runtime_error("--haptic " + spec + ": " + d.report->warning() +
                             "; refused (the scene's device.allow_no_watchdog: true drives it anyway)");
  return d;
}

}  // namespace isotouch::run
