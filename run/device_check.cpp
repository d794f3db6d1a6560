#include "isotouch/run/device_check.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <istream>
#include <ostream>
#include <sstream>
#include <thread>

#include "isotouch/run/safety_drill.h"
#include "isotouch/run/sdk_haptic_device.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/hid_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/servo/triple_buffer.h"

namespace isotouch::run {
namespace {
using core::Vec3;

std::unique_ptr<servo::HapticDeviceIO> open_for_check(const std::string& spec, std::string& what) {
  const std::size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon), arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (kind == "openhaptics" || kind == "forcedimension") return open_sdk_device(kind, arg, what);
  std::unique_ptr<servo::ReportDevice> d;
  std::string note;
  if (kind == "polhem") {
    const servo::PolhemSpec ps = servo::parse_polhem_spec(arg);
    d = servo::open_polhem(ps);
    note = "; " + servo::polhem_config_note(ps);
  } else if (kind == "hid") {
    d = servo::open_hid_device(arg);
  } else if (kind == "emu") {
    d = std::make_unique<servo::ReportDevice>(std::make_unique<servo::SocketLink>(arg),
                                              std::make_unique<servo::V1Protocol>());
    d->open();
  } else {
    throw std::invalid_argument("--check " + spec + ": kinds: openhaptics[:NAME], forcedimension[:INDEX], emu:SOCKET, hid:..., polhem:...");
  }
  what = d->name() + " (" + d->caps().name + ")" + note;
  return d;
}

/// A horizontal wall at device z = `z` (solid below), soft and bounded.
class SoftWall final : public servo::Renderer {
 public:
  SoftWall(double z, double k, double fmax) : z_(z), k_(k), fmax_(fmax) {}
  const char* name() const override { return "soft wall"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const Vec3& hip, double) override {
    servo::HriTick t;
    if (hip.z < z_) t.force_n = {0, 0, std::min(fmax_, k_ * (z_ - hip.z))}, t.contact = true;
    return t;
  }

 private:
  double z_, k_, fmax_;
};

std::string mm(const Vec3& p) {
  std::ostringstream s;
  // + 0.0 turns -0.0 into 0.0: a device at rest prints no "-0.0".
  s << std::fixed << std::setprecision(1) << '(' << p.x * 1e3 + 0.0 << ", " << p.y * 1e3 + 0.0 << ", "
    << p.z * 1e3 + 0.0 << ") mm";
  return s.str();
}

/// Reads the pose with force off for `seconds`; false if it is not finite or not fresh.
bool read_pose(servo::HapticDeviceIO& d, double seconds, Vec3& rest, std::ostream& out) {
  Vec3 lo{INFINITY, INFINITY, INFINITY}, hi = lo * -1.0;
  const auto t0 = std::chrono::steady_clock::now();
  bool ok = true;
  for (int i = 0; std::chrono::steady_clock::now() - t0 < std::chrono::duration<double>(seconds); ++i) {
    const servo::DeviceReading r = d.read();
    const Vec3 p = r.position_m;
    const bool finite = std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
    ok = ok && finite && r.status == servo::DeviceStatus::kOk;
    if (finite) lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)}, hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    if (i % 50 == 0)
      out << "  pose " << mm(p) << " (x right, y away from you, z up), buttons " << r.buttons << ", "
          << servo::to_string(r.status) << "\n";
    rest = p;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  out << "range moved: x " << (hi.x - lo.x) * 1e3 << " mm, y " << (hi.y - lo.y) * 1e3 << " mm, z " << (hi.z - lo.z) * 1e3
      << " mm: move the handle right, away from you and up, and check the signs above\n";
  return ok;
}
}  // namespace

int check_device(const DeviceCheckOptions& o, std::istream& in, std::ostream& out) {
  std::string what;
  std::unique_ptr<servo::HapticDeviceIO> dev;
  try {
    dev = open_for_check(o.spec, what);
  } catch (const std::exception& e) {
    out << "check: " << e.what() << "\n";
    return 1;
  }
  const servo::DeviceCaps c = dev->caps();
  out << "device   " << what << "\n         max force " << c.max_force_n << " N, stiffness " << c.max_stiffness_n_per_m
      << " N/m, workspace " << mm(c.workspace_min_m) << " to " << mm(c.workspace_max_m) << "\n"
      << "reading the pose for " << o.read_seconds << " s with force output off (nothing moves):\n";
  Vec3 rest;
  if (!read_pose(*dev, o.read_seconds, rest, out)) {
    out << "check: the pose was not finite or not fresh (status above): no force will be rendered\n";
    if (const auto* r = dynamic_cast<const servo::ReportDevice*>(dev.get()); r && !r->last_refusal().empty())
      out << "check: " << r->last_refusal() << "\n";  // the reason the device gave or its protocol found
    return 1;
  }
  const double k = std::min(o.wall_stiffness_n_per_m, 0.1 * c.max_stiffness_n_per_m);
  const double fmax = std::min(o.wall_force_n, c.max_force_n);
  const double z = rest.z - o.wall_depth_m;
  out << "render a soft wall " << o.wall_depth_m * 1e3 << " mm below the handle (z = " << z * 1e3 << " mm), " << k
      << " N/m, at most " << fmax << " N, for " << o.wall_seconds << " s? Hold the handle. [y/N] " << std::flush;
  std::string answer;
  std::getline(in, answer);
  out << "\n";
  if (answer != "y" && answer != "Y") {
    out << "no force rendered\n";
    return 0;
  }
  servo::TripleBuffer<core::SampleField> none;  // the wall reads no field
  none.publish(std::make_shared<const core::SampleField>());
  SoftWall wall(z, k, fmax);
  servo::ServoThreadConfig sc;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = false;
  servo::ServoThread servo(none, wall, *dev, sc);
  servo.start();
  std::this_thread::sleep_for(std::chrono::duration<double>(o.wall_seconds));
  servo.stop();  // the device's last force: an exact zero
  const servo::DeviceCounters dc = servo.device_counters();
  out << "wall     " << servo.ticks() << " ticks; stale " << dc.stale << ", disconnected " << dc.disconnected
      << ", fault " << dc.fault << "; push down to feel it\n";
  SafetyDrillOptions drill;
  drill.force_n = std::min(o.wall_force_n, 1.0);
  out << "run the safety drill: " << std::min(drill.force_n, c.max_force_n)
      << " N up, a step (the rate limit), a " << drill.stall_ms
      << " ms renderer stall (the force off) and the ramp back? Hold the handle. [y/N] " << std::flush;
  answer.clear();
  std::getline(in, answer);
  out << "\n";
  if (answer != "y" && answer != "Y") return 0;
  return run_safety_drill(*dev, drill, out) ? 0 : 1;
}

}  // namespace isotouch::run
