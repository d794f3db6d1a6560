// igtl_hand_peer - a PLUS-like OpenIGTLink server whose stylus is a simulated hand and device
// (sim/sim_device.h: an 80 g end effector with 1 N s/m of its own damping, held by a weak
// hand, 50 N/m and no damping: the hard case of sim/linked_contact.h), for
// `--haptic igtl:` over a slow, delayed link. The device runs its own 1 kHz loop on the
// steady clock and holds the last Force TRANSFORM it received (as PLUS holds the last
// TRANSFORM); its stylus TRANSFORM "StylusToTracker" goes out every 1/RATE_HZ s. Each
// message, either way, is taken up half the round trip after it was sent (poses leave late,
// forces are applied late, in order). With CONTROLLER 1 the device end runs the time-domain
// passivity observer and controller (servo/port_passivity.h) on its own clock, as
// sim/linked_contact.h does: the place a delayed link's controller has to be.
//
// The hand: the stylus waits at P0 [mm] until 1.6 s (the run measures the stream's rate
// first), then the hand's target moves along DIR at 20 mm/s for TRAVEL_MM and stays there;
// the device follows on the hand's spring. Ends after DURATION_S and closes.
// Usage: igtl_hand_peer PORT RATE_HZ ROUND_TRIP_MS DURATION_S CONTROLLER X0 Y0 Z0 DX DY DZ TRAVEL_MM
// Prints "listening", "connected", then one line per device tick once the hand moves:
//   "tick T S F H" - T device time [s], S the device's true position along DIR from P0 [mm],
//   F the force it applied along -DIR (pushing it back out) [N], H the force it holds from
//   the link along -DIR (before its controller) [N]; "still T" when the hand's
//   target stops;
// and at the end "energy J" (the largest work the applied force did on the device less its
// own damper's loss, over the run [J]), "pc ACTIVE_TICKS DISSIPATED_J" and "late TICKS
// WORST_S" (ticks that began over 2 ms late, and the largest lag: the loop lost the CPU);
// "lag T L" for each tick that began more than 10 ms (a link period) late.
#include <igtlMessageHeader.h>
#include <igtlServerSocket.h>
#include <igtlTransformMessage.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

#include "isotouch/servo/port_passivity.h"
#include "isotouch/sim/sim_device.h"
#include "igtl_force_reader.h"

namespace {
using Clock = std::chrono::steady_clock;
using isotouch::core::Vec3;

struct Timed {
  double t_s;  ///< when it was sent or arrived, on the device loop's own clock [s]
  Vec3 v;
};

std::mutex forces_mu;
std::deque<Timed> forces_in;  // Force TRANSFORMs received, in order, with their arrival time
Clock::time_point t0;
std::atomic<double> loop_now_s{0};  // the device loop's clock: the time of its latest tick [s]

void read_forces(igtl::ClientSocket* sock) {
  isotouch::test::read_forces(sock, [](float fx, float fy, float fz) {
    // Stamped on the loop's clock, not the wall's: a loop that fell behind and catches up
    // still applies each force half the round trip after it arrived, in its own time.
    std::lock_guard<std::mutex> lock(forces_mu);
    forces_in.push_back({loop_now_s.load(), {fx, fy, fz}});
  });
}

bool send_pose(igtl::ClientSocket* sock, igtl::TransformMessage* t, const Vec3& p_mm) {
  igtl::Matrix4x4 m;
  igtl::IdentityMatrix(m);
  m[0][3] = float(p_mm.x), m[1][3] = float(p_mm.y), m[2][3] = float(p_mm.z);
  t->SetMatrix(m);
  t->Pack();
  return sock->Send(t->GetPackPointer(), t->GetPackSize()) != 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 13) {
    std::fprintf(stderr,
                 "usage: igtl_hand_peer PORT RATE_HZ ROUND_TRIP_MS DURATION_S CONTROLLER X0 Y0 Z0 DX DY DZ TRAVEL_MM\n");
    return 2;
  }
  const double rate = std::atof(argv[2]), half_s = 0.5e-3 * std::atof(argv[3]), duration = std::atof(argv[4]);
  const bool controller = std::atoi(argv[5]) != 0;
  const Vec3 p0_m = Vec3{std::atof(argv[6]), std::atof(argv[7]), std::atof(argv[8])} * 1e-3;
  const Vec3 dir = isotouch::core::normalized_or({std::atof(argv[9]), std::atof(argv[10]), std::atof(argv[11])}, {1, 0, 0});
  const double travel_m = std::atof(argv[12]) * 1e-3;
  constexpr double T = 1e-3, kMoveAt = 1.6, kHandSpeed = 0.02;
  const long link_every = std::max(1L, std::lround(1.0 / (rate * T)));
  std::setvbuf(stdout, nullptr, _IOFBF, 1 << 20);  // one tick a line: buffered, flushed at the end
  std::signal(SIGPIPE, SIG_IGN);

  isotouch::sim::SimDeviceParams dp;  // sim/linked_contact.h's press: the hard case
  dp.damping_n_s_per_m = 1.0;
  dp.hand_stiffness_n_per_m = 50;
  dp.hand_damping_n_s_per_m = 0;
  dp.force_max_n = 1e3;
  dp.substeps = 20;
  isotouch::sim::SimDevice dev(dp, p0_m);
  isotouch::servo::PortPassivity pc(controller, 0.5 * dp.mass_kg / T, dp.force_max_n);

  igtl::ServerSocket::Pointer server = igtl::ServerSocket::New();
  if (server->CreateServer(std::atoi(argv[1])) < 0) {
    std::fprintf(stderr, "igtl_hand_peer: cannot listen on port %s\n", argv[1]);
    return 1;
  }
  std::printf("listening\n");
  std::fflush(stdout);
  igtl::ClientSocket::Pointer sock = server->WaitForConnection(60000);
  if (!sock) {
    std::fprintf(stderr, "igtl_hand_peer: no client within 60 s\n");
    return 1;
  }
  t0 = Clock::now();
  std::printf("connected\n");
  std::fflush(stdout);
  std::thread reader([&] { read_forces(sock); });
  igtl::TransformMessage::Pointer msg = igtl::TransformMessage::New();
  msg->SetDeviceName("StylusToTracker");

  std::deque<Timed> poses_out;  // poses waiting for half the round trip
  Vec3 held{};                  // the force the device holds [N], device frame
  double energy = 0;
  bool open = true, still = false;
  long late = 0;  // ticks that began more than 2 ms after their time (the loop lost the CPU)
  double worst_lag = 0;
  for (long k = 0; open && double(k) * T < duration; ++k) {
    const double t = double(k) * T;
    const Clock::time_point due = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(t));
    std::this_thread::sleep_until(due);
    const double lag = std::chrono::duration<double>(Clock::now() - due).count();
    late += lag > 2e-3, worst_lag = std::max(worst_lag, lag);
    if (lag > 10e-3) std::printf("lag %.4f %.6f\n", t, lag);  // a link period lost: the device's time stood still
    loop_now_s.store(t);
    const Vec3 x = dev.position();
    if (k % link_every == 0) poses_out.push_back({t, x * 1e3});
    while (open && !poses_out.empty() && poses_out.front().t_s + half_s <= t) {
      open = send_pose(sock, msg, poses_out.front().v);
      poses_out.pop_front();
    }
    {
      std::lock_guard<std::mutex> lock(forces_mu);
      while (!forces_in.empty() && forces_in.front().t_s + half_s <= t) held = forces_in.front().v, forces_in.pop_front();
    }
    dev.command_force(pc.step(t, x, held));
    const double s = std::clamp(kHandSpeed * (t - kMoveAt), 0.0, travel_m);
    const bool moving = t >= kMoveAt;
    if (s == travel_m && !still) std::printf("still %.4f\n", t), still = true;
    dev.step(T, p0_m + dir * s, moving && s < travel_m ? dir * kHandSpeed : Vec3{});
    energy = std::max(energy, dev.rendered_work_j() - dev.damping_dissipated_j());
    if (moving)
      std::printf("tick %.4f %.6f %.6f %.6f\n", t, dot(dev.true_position() - p0_m, dir) * 1e3, -dot(dev.applied_force(), dir),
                  -dot(held, dir));
  }
  std::printf("energy %.9g\npc %ld %.9g\nlate %ld %.6f\n", energy, pc.active_ticks(), pc.dissipated_j(), late, worst_lag);
  std::fflush(stdout);
  sock->CloseSocket();
  reader.join();
  return 0;
}
