// igtl_plus_peer - the PLUS side of `--haptic igtl:`, built on the OpenIGTLink library's
// server socket and messages (as a PlusServer's OpenHaptics device serves its stylus): waits
// for one client, streams the TRANSFORM "StylusToTracker" at RATE_HZ for STREAM_S seconds
// (P0 [mm] until MOVE_AT seconds, then a line to P1 over MOVE_S seconds, then P1), then sends nothing for
// SILENT_S seconds and closes; prints every "Force" TRANSFORM it receives.
// Usage: igtl_plus_peer PORT RATE_HZ STREAM_S MOVE_AT MOVE_S SILENT_S X0 Y0 Z0 X1 Y1 Z1
// Prints (t: seconds since the client connected):
//   "connected", "clock S" (t = 0 on the steady clock, CLOCK_MONOTONIC [s]: a test's
//   python time.monotonic() on the same machine), "pose T X Y Z" for the last pose sent, "stopped T" when the stream stops,
//   "force T FX FY FZ" per Force TRANSFORM received, "closed T" when the client closed.
#include <igtlMessageHeader.h>
#include <igtlServerSocket.h>
#include <igtlTransformMessage.h>

#include <algorithm>
#include <csignal>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>

#include "igtl_force_reader.h"

namespace {
using Clock = std::chrono::steady_clock;
std::mutex out_mu;
Clock::time_point t0;

double since() { return std::chrono::duration<double>(Clock::now() - t0).count(); }

void read_forces(igtl::ClientSocket* sock) {
  isotouch::test::read_forces(sock, [](float fx, float fy, float fz) {
    std::lock_guard<std::mutex> lock(out_mu);
    std::printf("force %.6f %.6g %.6g %.6g\n", since(), fx, fy, fz);
  });
  std::lock_guard<std::mutex> lock(out_mu);
  std::printf("closed %.6f\n", since());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 13) {
    std::fprintf(stderr, "usage: igtl_plus_peer PORT RATE_HZ STREAM_S MOVE_AT MOVE_S SILENT_S X0 Y0 Z0 X1 Y1 Z1\n");
    return 2;
  }
  const double rate = std::atof(argv[2]), stream_s = std::atof(argv[3]), move_at = std::atof(argv[4]),
               move_s = std::atof(argv[5]), silent_s = std::atof(argv[6]);
  double p0[3], p1[3];
  for (int a = 0; a < 3; ++a) p0[a] = std::atof(argv[7 + a]), p1[a] = std::atof(argv[10 + a]);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // every line out at once, whenever this ends
  std::signal(SIGPIPE, SIG_IGN);  // the library's Send on a closed peer raises it
  igtl::ServerSocket::Pointer server = igtl::ServerSocket::New();
  if (server->CreateServer(std::atoi(argv[1])) < 0) {
    std::fprintf(stderr, "igtl_plus_peer: cannot listen on port %s\n", argv[1]);
    return 1;
  }
  std::printf("listening\n");
  std::fflush(stdout);
  igtl::ClientSocket::Pointer sock = server->WaitForConnection(60000);
  if (!sock) {
    std::fprintf(stderr, "igtl_plus_peer: no client within 60 s\n");
    return 1;
  }
  t0 = Clock::now();
  std::printf("connected\nclock %.6f\n", std::chrono::duration<double>(t0.time_since_epoch()).count());
  std::thread reader([&] { read_forces(sock); });
  igtl::TransformMessage::Pointer t = igtl::TransformMessage::New();
  t->SetDeviceName("StylusToTracker");
  double p[3] = {p0[0], p0[1], p0[2]};
  for (long k = 0;; ++k) {
    std::this_thread::sleep_until(t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(double(k) / rate)));
    const double s = since();
    if (s >= stream_s) break;
    const double u = std::clamp(move_s > 0 ? (s - move_at) / move_s : s >= move_at ? 1.0 : 0.0, 0.0, 1.0);
    igtl::Matrix4x4 m;
    igtl::IdentityMatrix(m);
    for (int a = 0; a < 3; ++a) m[a][3] = float(p[a] = p0[a] + u * (p1[a] - p0[a]));
    t->SetMatrix(m);
    t->Pack();
    if (sock->Send(t->GetPackPointer(), t->GetPackSize()) == 0) break;
  }
  {
    std::lock_guard<std::mutex> lock(out_mu);
    std::printf("pose %.6f %g %g %g\nstopped %.6f\n", since(), p[0], p[1], p[2], since());
    std::fflush(stdout);
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(silent_s));
  sock->CloseSocket();
  reader.join();
  std::fflush(stdout);
  return 0;
}
