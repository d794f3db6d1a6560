// igtl_session_client - a small OpenIGTLink client built on the library's messages (the way
// Slicer drives a session): streams a tracked tool, sends STRING commands, LABELMETA and
// IMAGE messages, and keeps what the server sends back: the STATUS answers, the Force
// transforms, and the edited IMAGEs, applied (their sub-volume) to a copy of BASE.
// Usage: igtl_session_client HOST PORT BASE ACTION...
//   move X Y Z SECS   the tool "Stylus" moves in a line to X Y Z [mm, RAS] over SECS, then
//                     stays (streamed at 500 Hz from the first move on)
//   wait SECS
//   pause SECS        the tool's stream stops for SECS (then goes on where it was)
//   points            prints the HIP and Proxy TRANSFORMs received so far and how many were off
//                     the tool: "points HIP K Proxy L, off: HIP A Proxy B, last HIP X Y Z" (off:
//                     more than 10 mm (HIP) or 20 mm (Proxy) from the last pose this client
//                     sent, or any before it sent one; X Y Z the newest HIP [mm, RAS])
//   register NAME M00 M01 M02 M03 M10 ... M23   a TRANSFORM named NAME, the 4x4's first three
//                     rows (the last 0 0 0 1); prints the STATUS answer
//   cmd TEXT          a STRING (device "CMD"); prints the STATUS answer "STATUS code C: TEXT"
//                     (the first STATUS under the device name sent, within 15 s; so for `image`,
//                     and for `ramp` and `checker` within 90 s)
//   at SECS           waits until SECS after the client started; fails ("at SECS: already T s")
//                     when that time has passed (the actions before it were too slow)
//   force             prints the mean of the newest 10 Force transforms once they settle (3 s at
//                     most) and how many came so far: "force X Y Z |F| N, K received, ..., from
//                     A to B s" (A, B: when it began and printed, since the client started)
//   hz N              the stream's rate from now on: a pose every 1 / N s (default 500 Hz)
//   peak              prints the largest |F| of every Force transform received so far:
//                     "peak |F| P N of K received, last |F| L N" (what the peer's device was sent
//                     at most, and holds now)
//   images SECS       waits until no IMAGE has arrived for SECS; prints "images K" (K: all so far)
//   compare FILE      prints "compare FILE: D voxels differ, geometry G" (D: the copy of BASE
//                     with every IMAGE received applied against FILE; G: "ok" when every
//                     IMAGE's dimensions, spacing, directions and centre were BASE's within 1e-3)
//   labelmeta NAME    a LBMETA describing the image NAME as a label map
//   lbmeta NAME N (LABEL VALUE R G B) x N   a LBMETA of N elements for the label map NAME:
//                     each a label LABEL of voxel value VALUE and colour R G B (0-255, alpha 255)
//   labelmap NAME DX N T1..TN  an int16 label map IMAGE named NAME on BASE's grid, its centre
//                     moved DX mm along R; each voxel the number of thresholds Ti at or below
//                     BASE's value there; prints "labelmap NAME: voxels C0 C1 ... CN" (how
//                     many voxels hold each value 0..N), then the STATUS answer
//   unchanged FILE LO prints "unchanged FILE: A voxels differ where BASE >= LO, B below" (FILE
//                     against BASE itself, voxel for voxel)
//   image NAME        BASE as an IMAGE named NAME; prints the STATUS answer
//   ramp NAME NX NY NZ  an NX x NY x NZ uint8 IMAGE named NAME (1 mm voxels, RAS, centred on
//                     the origin; value x % 256); prints the STATUS answer
//   checker NAME NX NY NZ  as ramp, int16, 0 and 2000 in 5-voxel cubes (surfaces in every
//                     brick: a session slow to build)
//   ball NAME N R1 R2 an N^3 int16 IMAGE named NAME in Hounsfield units (1 mm voxels, RAS,
//                     centred on the origin): bone (1000 HU) within R1 mm of the centre,
//                     tissue (40 HU) to R2 mm, air (-1024 HU) beyond; prints the STATUS answer
//   statuses SECS     waits SECS, then prints the STATUS answers not printed yet
//   rebase            the copy starts again from BASE (what the server holds once it took
//                     an `image`); IMAGEs received later apply to it
//   first SECS        waits up to SECS for the first TRANSFORM "Force"; prints "first transform
//                     T s after connecting" (fails when none came: "no transform within SECS s")
//   mark              the Force arrival times kept for `gaps` start again from now
//   gaps              prints "gaps N transforms, p50 A p99 B max C ms": the times between the
//                     Force TRANSFORMs received since `mark` (or the connection)
//   cmds N TEXT       N STRING commands TEXT (device "CMDS"), one every 20 ms whether answered
//                     or not; prints "cmds N answered, p50 A p99 B max C ms" (each one's send to
//                     its STATUS; fails when not all were answered within 15 s)
//   noread            stops reading what the server sends (a client that does not read)
//   closed SECS       waits up to SECS for the server to close the connection; prints "closed
//                     after T s" (T since connecting) or "open after SECS s"
//   refusal SECS      waits up to SECS for the first STATUS under the stream's name ("Stylus":
//                     the server refusing the stream), then 0.3 s more; prints "refusal: held |F|
//                     H N at the STATUS, K Forces before it; first Force after it |F| A N, T ms
//                     later" (H: the last Force received before the STATUS, what the peer's
//                     device applies when the stream is refused; "none after it" when no Force
//                     followed); fails ("no refusal within SECS s") when no such STATUS came
// Exit 0 when every action completed, 1 otherwise (a STATUS that never came, ...).
#include <igtlClientSocket.h>
#include <igtlImageMessage.h>
#include <igtlLabelMetaMessage.h>
#include <igtlMessageHeader.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTransformMessage.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <iostream>
#include <mutex>
#include <optional>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/io/volume_io.h"
#include "isotouch/tests/igtl_test_sender.h"

namespace {
using Clock = std::chrono::steady_clock;

struct Shared {
  std::mutex mu;
  std::condition_variable cv;
  std::deque<std::pair<std::string, std::string>> statuses;  // device name, "STATUS code C: TEXT"
  std::deque<std::array<double, 3>> forces;
  long hips = 0, proxies = 0, hips_off = 0, proxies_off = 0;  // HIP / Proxy received, and off the tool
  std::array<double, 3> last_hip{0, 0, 0};
  bool sent_pose = false;
  std::array<double, 3> last_pose{0, 0, 0};  // [mm, RAS], the last the stream sent
  long forces_received = 0;
  double peak_force = 0;  // the largest |F| of every Force received [N]
  isotouch::engine::Volume copy;  // BASE with the received IMAGEs applied
  int images = 0;
  bool geometry_ok = true;
  bool closed = false;
  bool noread = false;  // `noread`: the reader stops
  Clock::time_point connected = Clock::now(), closed_at;
  std::vector<Clock::time_point> force_times;  // Force TRANSFORM arrivals since `mark` (sent every display tick)
  std::vector<Clock::time_point> cmds_answered;  // arrivals of the STATUS answers to `cmds`
  std::optional<Clock::time_point> first_force;
  // `refusal`: the first STATUS under the stream's name, the Force held then, the Force after.
  long forces_at_refusal = -1;  // Forces received before it (-1: none came)
  double held_at_refusal = 0;   // |F| of the last Force before it [N] (0: none)
  Clock::time_point refused_at;
  std::optional<std::pair<double, Clock::time_point>> after_refusal;  // |F| and arrival of the first Force after it
};

/// "p50 A p99 B max C ms" of `v` [ms] (sorted here).
std::string percentiles(std::vector<double> v) {
  if (v.empty()) return "p50 - p99 - max - ms";
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5))]; };
  char b[128];
  std::snprintf(b, sizeof b, "p50 %.1f p99 %.1f max %.1f ms", at(0.5), at(0.99), v.back());
  return b;
}

/// The header of `m` matches BASE's as the server must send it (RAS, centre).
bool same_geometry(igtl::ImageMessage& m, const isotouch::engine::Volume& v) {
  int dims[3];
  float sp[3];
  m.GetDimensions(dims);
  m.GetSpacing(sp);
  igtl::Matrix4x4 mat;
  m.GetMatrix(mat);
  const isotouch::core::Vec3 c = v.index_to_physical({(dims[0] - 1) / 2.0, (dims[1] - 1) / 2.0, (dims[2] - 1) / 2.0});
  const double centre[3] = {-c.x * 1e3, -c.y * 1e3, c.z * 1e3};
  bool ok = m.GetCoordinateSystem() == igtl::ImageMessage::COORDINATE_RAS;
  for (int a = 0; a < 3; ++a) {
    ok = ok && dims[a] == v.grid.dims[std::size_t(a)];
    ok = ok && std::abs(sp[a] - (a == 0 ? v.grid.spacing_m.x : a == 1 ? v.grid.spacing_m.y : v.grid.spacing_m.z) * 1e3) < 1e-3;
    ok = ok && std::abs(mat[a][3] - centre[a]) < 1e-3;
    for (int b = 0; b < 3; ++b)
      ok = ok && std::abs(mat[a][b] - (a < 2 ? -1 : 1) * v.direction[std::size_t(3 * a + b)]) < 1e-3;
  }
  return ok;
}

/// The sub-volume of an IMAGE (float32, little-endian) written into `s.copy`.
void apply_image(igtl::ImageMessage& m, Shared& s) {
  int size[3], off[3];
  m.GetSubVolume(size, off);
  const bool ok = same_geometry(m, s.copy) && m.GetScalarType() == igtl::ImageMessage::TYPE_FLOAT32 &&
                  m.GetEndian() == igtl::ImageMessage::ENDIAN_LITTLE;
  s.geometry_ok = s.geometry_ok && ok;
  if (!ok) return;
  const auto* p = static_cast<const float*>(m.GetScalarPointer());
  const auto& n = s.copy.grid.dims;
  for (int z = off[2]; z < off[2] + size[2]; ++z)
    for (int y = off[1]; y < off[1] + size[1]; ++y)
      for (int x = off[0]; x < off[0] + size[0]; ++x)
        s.copy.voxels[(std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(x)] = *p++;
  ++s.images;
}

template <class M>
typename M::Pointer body_of(igtl::ClientSocket* sock, igtl::MessageHeader* h) {
  typename M::Pointer m = M::New();
  m->SetMessageHeader(h);
  m->AllocatePack();
  sock->Receive(m->GetPackBodyPointer(), m->GetPackBodySize());
  if (!(m->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) return nullptr;
  return m;
}

void read_loop(igtl::ClientSocket* sock, Shared& s) {
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(s.mu);
      s.cv.wait(lock, [&] { return !s.noread || s.closed; });
      if (s.closed) break;
    }
    igtl::MessageHeader::Pointer h = igtl::MessageHeader::New();
    h->InitPack();
    if (sock->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) break;
    h->Unpack();
    const std::string type = h->GetDeviceType(), name = h->GetDeviceName();
    std::lock_guard<std::mutex> lock(s.mu);
    // The display stream's Force goes every tick (HIP and Proxy only while a fresh pose is
    // rendered: none without a tracker).
    if (type == "TRANSFORM" && name == "Force") {
      const auto now = Clock::now();
      if (!s.first_force) s.first_force = now;
      s.force_times.push_back(now);
    }
    if (type == "STATUS" && name == "CMDS") {
      if (body_of<igtl::StatusMessage>(sock, h)) s.cmds_answered.push_back(Clock::now());
    } else if (type == "STATUS") {
      if (auto st = body_of<igtl::StatusMessage>(sock, h)) {
        s.statuses.emplace_back(name, "STATUS code " + std::to_string(st->GetCode()) + ": " + st->GetStatusString());
        if (name == "Stylus" && s.forces_at_refusal < 0) {
          s.forces_at_refusal = s.forces_received;
          s.held_at_refusal = s.forces.empty() ? 0.0 : std::hypot(s.forces.back()[0], s.forces.back()[1], s.forces.back()[2]);
          s.refused_at = Clock::now();
        }
      }
    } else if (type == "TRANSFORM" && name == "Force") {
      if (auto t = body_of<igtl::TransformMessage>(sock, h)) {
        igtl::Matrix4x4 m;
        t->GetMatrix(m);
        s.forces.push_back({m[0][3], m[1][3], m[2][3]});
        s.peak_force = std::max(s.peak_force, std::hypot(double(m[0][3]), double(m[1][3]), double(m[2][3])));
        ++s.forces_received;
        if (s.forces.size() > 10) s.forces.pop_front();
        if (s.forces_at_refusal >= 0 && !s.after_refusal)
          s.after_refusal.emplace(std::hypot(double(m[0][3]), double(m[1][3]), double(m[2][3])), Clock::now());
      }
    } else if (type == "TRANSFORM" && (name == "HIP" || name == "Proxy")) {
      if (auto t = body_of<igtl::TransformMessage>(sock, h)) {
        igtl::Matrix4x4 m;
        t->GetMatrix(m);
        const double d = std::hypot(m[0][3] - s.last_pose[0], m[1][3] - s.last_pose[1], m[2][3] - s.last_pose[2]);
        const bool hip = name == "HIP";
        (hip ? s.hips : s.proxies) += 1;
        if (hip) s.last_hip = {m[0][3], m[1][3], m[2][3]};
        if (!s.sent_pose || d > (hip ? 10.0 : 20.0)) (hip ? s.hips_off : s.proxies_off) += 1;
      }
    } else if (type == "IMAGE") {
      if (auto im = body_of<igtl::ImageMessage>(sock, h)) apply_image(*im, s);
    } else {
      sock->Skip(h->GetBodySizeToRead(), 0);
    }
    s.cv.notify_all();
  }
  std::lock_guard<std::mutex> lock(s.mu);
  if (!s.closed) s.closed_at = Clock::now();
  s.closed = true;
  s.cv.notify_all();
}

/// The tool's path: a line from `from` to `to` over [t0, t1], then `to`.
struct Path {
  std::mutex mu;
  double from[3] = {0, 0, 0}, to[3] = {0, 0, 0};
  Clock::time_point t0, t1;
  bool started = false;
  Clock::time_point paused_until;  // no pose sent before it
  void at(Clock::time_point t, double out[3]) {
    std::lock_guard<std::mutex> lock(mu);
    const double span = std::chrono::duration<double>(t1 - t0).count();
    const double u = span <= 0 ? 1.0 : std::clamp(std::chrono::duration<double>(t - t0).count() / span, 0.0, 1.0);
    for (int a = 0; a < 3; ++a) out[a] = from[a] + u * (to[a] - from[a]);
  }
};

std::mutex send_mu;
std::atomic<long> stream_period_us{2000};  // `hz`: the time between the stream's poses
void send(igtl::ClientSocket* sock, igtl::MessageBase* m) {
  m->Pack();
  std::lock_guard<std::mutex> lock(send_mu);
  sock->Send(m->GetPackPointer(), m->GetPackSize());
}

void stream_loop(igtl::ClientSocket* sock, Path& path, Shared& shared, const std::atomic<bool>& done) {
  igtl::TransformMessage::Pointer t = igtl::TransformMessage::New();
  t->SetDeviceName("Stylus");
  // Paced on its own schedule, as a tracker's device clock paces PLUS's stream: a late wake-up
  // (a loaded machine) is caught up with the next poses, so the stream's rate stays the one
  // asked (a stream of sleeps would slow down with the machine's load); more than 5 periods
  // behind, the schedule starts again from now (no burst).
  auto next = Clock::now();
  while (!done) {
    const auto period = std::chrono::microseconds(stream_period_us.load());
    next += period;
    if (Clock::now() - next > 5 * period) next = Clock::now();
    std::this_thread::sleep_until(next);
    {
      std::lock_guard<std::mutex> lock(path.mu);
      if (!path.started || Clock::now() < path.paused_until) continue;
    }
    double p[3];
    path.at(Clock::now(), p);
    igtl::Matrix4x4 m;
    igtl::IdentityMatrix(m);
    for (int a = 0; a < 3; ++a) m[a][3] = float(p[a]);
    t->SetMatrix(m);
    {
      std::lock_guard<std::mutex> lock(shared.mu);  // before it can arrive: the HIP it moves is never "off"
      for (int a = 0; a < 3; ++a) shared.last_pose[std::size_t(a)] = m[a][3];
      shared.sent_pose = true;
    }
    send(sock, t);
  }
}

/// Prints the first STATUS under `device` (the answer to what was sent under it; others,
/// such as the server's own about the edited IMAGE, wait for `statuses`).
bool wait_status(Shared& s, const std::string& device, int timeout_s = 15) {
  std::unique_lock<std::mutex> lock(s.mu);
  auto mine = [&] {
    return std::find_if(s.statuses.begin(), s.statuses.end(), [&](const auto& st) { return st.first == device; });
  };
  if (!s.cv.wait_for(lock, std::chrono::seconds(timeout_s), [&] { return mine() != s.statuses.end() || s.closed; }) ||
      mine() == s.statuses.end()) {
    std::cout << "no STATUS came back\n";
    return false;
  }
  const auto it = mine();
  std::cout << it->second << "\n";
  s.statuses.erase(it);
  return true;
}

struct Client {
  igtl::ClientSocket* sock;
  Shared& s;
  Path& path;
  const isotouch::engine::Volume& base;
  char** argv;
  int argc;
  int i;
  Clock::time_point started = Clock::now();  // what `at` counts from
  std::string arg() { return i < argc ? argv[i++] : ""; }
  double num() { return std::atof(arg().c_str()); }
  bool action(const std::string& a);
};

// The mean of the newest 10 Force transforms once they have settled: at least 300 ms after
// the call, and their spread (largest distance from their mean) within 2 % of the mean's
// size or 5 mN; after 3 s unsettled, the figures as they are and false. The forces follow the
// last move's end through the display stream's filter, so a fixed wait read them mid-rise.
bool print_settled_force(Shared& s, std::chrono::steady_clock::time_point started) {
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::lock_guard<std::mutex> lock(s.mu);
    double f[3] = {0, 0, 0}, spread = 0;
    for (const auto& v : s.forces)
      for (int k = 0; k < 3; ++k) f[k] += v[std::size_t(k)] / double(s.forces.size());
    for (const auto& v : s.forces) spread = std::max(spread, std::hypot(v[0] - f[0], v[1] - f[1], v[2] - f[2]));
    const double mag = std::hypot(f[0], f[1], f[2]);
    const bool settled = s.forces.size() == 10 && spread <= std::max(0.02 * mag, 0.005);
    if (waited < 0.3 || (!settled && waited < 3.0)) continue;
    std::cout << "force " << f[0] << " " << f[1] << " " << f[2] << " " << mag << " N, " << s.forces_received
              << " received, spread " << spread << " N, " << (settled ? "settled" : "NOT settled") << " after "
              << waited << " s, from " << std::chrono::duration<double>(t0 - started).count() << " to "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() << " s\n";
    return settled;
  }
}

bool Client::action(const std::string& a) {
  if (a == "move") {
    double to[3] = {num(), num(), num()};
    const double secs = num();
    const auto now = Clock::now();
    double here[3];
    path.at(now, here);
    {
      std::lock_guard<std::mutex> lock(path.mu);
      for (int k = 0; k < 3; ++k) path.from[k] = path.started ? here[k] : to[k], path.to[k] = to[k];
      path.t0 = now;
      path.t1 = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(secs));
      path.started = true;
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(secs));
    return true;
  }
  if (a == "at") {
    const double at = num(), now = std::chrono::duration<double>(Clock::now() - started).count();
    if (now > at) return std::cout << "at " << at << ": already " << now << " s\n", false;
    return std::this_thread::sleep_for(std::chrono::duration<double>(at - now)), true;
  }
  if (a == "pause") {
    const double secs = num();
    {
      std::lock_guard<std::mutex> lock(path.mu);
      path.paused_until = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(secs));
    }
    return std::this_thread::sleep_for(std::chrono::duration<double>(secs)), true;
  }
  if (a == "points") {
    std::lock_guard<std::mutex> lock(s.mu);
    std::cout << "points HIP " << s.hips << " Proxy " << s.proxies << ", off: HIP " << s.hips_off << " Proxy "
              << s.proxies_off << ", last HIP " << s.last_hip[0] << " " << s.last_hip[1] << " " << s.last_hip[2] << "\n";
    return true;
  }
  if (a == "register") {
    const std::string name = arg();
    igtl::Matrix4x4 m;
    igtl::IdentityMatrix(m);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) m[r][c] = float(num());
    igtl::TransformMessage::Pointer t = igtl::TransformMessage::New();
    t->SetDeviceName(name.c_str());
    t->SetMatrix(m);
    send(sock, t);
    return wait_status(s, name);
  }
  if (a == "wait") return std::this_thread::sleep_for(std::chrono::duration<double>(num())), true;
  if (a == "cmd") {
    igtl::StringMessage::Pointer m = igtl::StringMessage::New();
    m->SetDeviceName("CMD");
    m->SetString(arg().c_str());
    send(sock, m);
    return wait_status(s, "CMD");
  }
  if (a == "force") return print_settled_force(s, started);
  if (a == "hz") {
    const double hz = num();
    if (!(hz > 0)) return false;
    stream_period_us = long(1e6 / hz);
    return true;
  }
  if (a == "peak") {
    std::lock_guard<std::mutex> lock(s.mu);
    const double last = s.forces.empty() ? 0 : std::hypot(s.forces.back()[0], s.forces.back()[1], s.forces.back()[2]);
    std::cout << "peak |F| " << s.peak_force << " N of " << s.forces_received << " received, last |F| " << last << " N\n";
    return true;
  }
  if (a == "images") {
    const double quiet = num();
    std::unique_lock<std::mutex> lock(s.mu);
    for (int seen = -1; seen != s.images && !s.closed;) {
      seen = s.images;
      s.cv.wait_for(lock, std::chrono::duration<double>(quiet), [&] { return s.images != seen || s.closed; });
    }
    std::cout << "images " << s.images << "\n";
    return true;
  }
  if (a == "compare") {
    const std::string file = arg();
    const isotouch::engine::Volume f = isotouch::io::load_volume(file);
    std::lock_guard<std::mutex> lock(s.mu);
    std::size_t count = 0;
    if (f.voxels.size() == s.copy.voxels.size())
      for (std::size_t k = 0; k < f.voxels.size(); ++k) count += f.voxels[k] != s.copy.voxels[k];
    else
      count = f.voxels.size();
    std::cout << "compare " << file << ": " << count << " voxels differ, geometry " << (s.geometry_ok ? "ok" : "off") << "\n";
    return true;
  }
  if (a == "labelmeta") {
    igtl::LabelMetaMessage::Pointer m = igtl::LabelMetaMessage::New();
    m->SetDeviceName("Labels");
    igtl::LabelMetaElement::Pointer e = igtl::LabelMetaElement::New();
    e->SetName("skull");
    e->SetDeviceName(arg().c_str());
    e->SetLabel(1);
    m->AddLabelMetaElement(e);
    send(sock, m);
    return true;
  }
  if (a == "lbmeta") {
    igtl::LabelMetaMessage::Pointer m = igtl::LabelMetaMessage::New();
    m->SetDeviceName("Labels");
    const std::string image = arg();
    const int n = int(num());
    for (int i = 0; i < n; ++i) {
      igtl::LabelMetaElement::Pointer e = igtl::LabelMetaElement::New();
      e->SetName(arg().c_str());
      e->SetDeviceName(image.c_str());
      e->SetLabel(igtlUint8(num()));
      const int r = int(num()), g = int(num()), b = int(num());
      e->SetRGBA(igtlUint8(r), igtlUint8(g), igtlUint8(b), 255);
      m->AddLabelMetaElement(e);
    }
    send(sock, m);
    return true;
  }
  if (a == "labelmap") {
    const std::string name = arg();
    const double dx = num();
    std::vector<double> t(std::size_t(std::max(0.0, num())));
    for (double& v : t) v = num();
    isotouch::engine::Volume l = base;
    for (float& v : l.voxels) v = float(std::count_if(t.begin(), t.end(), [&](double x) { return x <= v; }));
    std::vector<std::size_t> counts(t.size() + 1, 0);
    for (const float v : l.voxels) ++counts[std::size_t(v)];
    std::cout << "labelmap " << name << ": voxels";
    for (const std::size_t c : counts) std::cout << " " << c;
    std::cout << "\n";
    l.grid.origin_m.x -= dx * 1e-3;  // R is -x in LPS
    const std::vector<std::uint8_t> b = isotouch::test::image_of(l, igtl::ImageMessage::ENDIAN_LITTLE, name.c_str());
    {
      std::lock_guard<std::mutex> lock(send_mu);
      sock->Send(b.data(), int(b.size()));
    }
    return wait_status(s, name);
  }
  if (a == "unchanged") {
    const std::string file = arg();
    const double lo = num();
    const isotouch::engine::Volume f = isotouch::io::load_volume(file);
    if (f.voxels.size() != base.voxels.size()) return std::cout << "unchanged " << file << ": another size\n", false;
    std::size_t above = 0, below = 0;
    for (std::size_t k = 0; k < f.voxels.size(); ++k)
      if (f.voxels[k] != base.voxels[k]) ++(base.voxels[k] >= lo ? above : below);
    std::cout << "unchanged " << file << ": " << above << " voxels differ where BASE >= " << lo << ", " << below
              << " below\n";
    return true;
  }
  if (a == "rebase") {
    std::lock_guard<std::mutex> lock(s.mu);
    s.copy = base;
    return true;
  }
  if (a == "ramp" || a == "checker") {
    const std::string name = arg();
    int dims[3];
    for (int& d : dims) d = int(num());
    const bool checker = a == "checker";
    igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
    float sp[3] = {1, 1, 1};
    m->SetDimensions(dims);
    m->SetSpacing(sp);
    m->SetScalarType(checker ? igtl::ImageMessage::TYPE_INT16 : igtl::ImageMessage::TYPE_UINT8);
    m->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
    m->SetDeviceName(name.c_str());
    m->AllocateScalars();
    const std::size_t nx = std::size_t(dims[0]), ny = std::size_t(dims[1]);
    const std::size_t n = nx * ny * std::size_t(dims[2]);
    if (checker) {  // 0 and 2000 in 5-voxel cubes: surfaces through every brick
      auto* out = static_cast<std::int16_t*>(m->GetScalarPointer());
      for (std::size_t k = 0; k < n; ++k)
        out[k] = std::int16_t(((k % nx) / 5 + (k / nx % ny) / 5 + k / (nx * ny) / 5) % 2 * 2000);
    } else {
      auto* out = static_cast<std::uint8_t*>(m->GetScalarPointer());
      for (std::size_t k = 0; k < n; ++k) out[k] = std::uint8_t(k % nx % 256);
    }
    send(sock, m);
    return wait_status(s, name, 90);  // its session is built first (a large one: seconds)
  }
  if (a == "ball") {
    const std::string name = arg();
    const int n = int(num());
    const double r1 = num(), r2 = num();
    igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
    int dims[3] = {n, n, n};
    float sp[3] = {1, 1, 1};
    m->SetDimensions(dims);
    m->SetSpacing(sp);
    m->SetScalarType(igtl::ImageMessage::TYPE_INT16);
    m->SetEndian(igtl::ImageMessage::ENDIAN_LITTLE);  // written in this (x86) host's order
    m->SetCoordinateSystem(igtl::ImageMessage::COORDINATE_RAS);
    m->SetDeviceName(name.c_str());
    m->AllocateScalars();
    auto* out = static_cast<std::int16_t*>(m->GetScalarPointer());
    const double c = (n - 1) / 2.0;
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const double r = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c));
          *out++ = std::int16_t(r <= r1 ? 1000 : r <= r2 ? 40 : -1024);
        }
    send(sock, m);
    return wait_status(s, name);
  }
  if (a == "statuses") {
    std::this_thread::sleep_for(std::chrono::duration<double>(num()));
    std::lock_guard<std::mutex> lock(s.mu);
    for (; !s.statuses.empty(); s.statuses.pop_front()) std::cout << s.statuses.front().second << "\n";
    return true;
  }
  if (a == "first") {
    const double secs = num();
    std::unique_lock<std::mutex> lock(s.mu);
    s.cv.wait_until(lock, s.connected + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(secs)),
                    [&] { return s.first_force.has_value() || s.closed; });
    if (!s.first_force) return std::cout << "no transform within " << secs << " s\n", false;
    std::cout << "first transform " << std::chrono::duration<double>(*s.first_force - s.connected).count()
              << " s after connecting\n";
    return true;
  }
  if (a == "mark") {
    std::lock_guard<std::mutex> lock(s.mu);
    s.force_times.clear();
    return true;
  }
  if (a == "gaps") {
    std::lock_guard<std::mutex> lock(s.mu);
    std::vector<double> ms;
    for (std::size_t k = 1; k < s.force_times.size(); ++k)
      ms.push_back(std::chrono::duration<double, std::milli>(s.force_times[k] - s.force_times[k - 1]).count());
    std::cout << "gaps " << s.force_times.size() << " transforms, " << percentiles(ms) << "\n";
    return s.force_times.size() > 1;
  }
  if (a == "cmds") {
    const int n = int(num());
    const std::string text = arg();
    {
      std::lock_guard<std::mutex> lock(s.mu);
      s.cmds_answered.clear();
    }
    std::vector<Clock::time_point> sent;
    const auto t0 = Clock::now();
    for (int k = 0; k < n; ++k) {  // one every 20 ms, answered or not (as a UI sends them)
      std::this_thread::sleep_until(t0 + std::chrono::milliseconds(20 * k));
      igtl::StringMessage::Pointer m = igtl::StringMessage::New();
      m->SetDeviceName("CMDS");
      m->SetString(text.c_str());
      sent.push_back(Clock::now());
      send(sock, m);
    }
    std::unique_lock<std::mutex> lock(s.mu);
    s.cv.wait_for(lock, std::chrono::seconds(15), [&] { return s.cmds_answered.size() >= sent.size() || s.closed; });
    if (s.cmds_answered.size() < sent.size())
      return std::cout << "cmds " << s.cmds_answered.size() << " of " << n << " answered\n", false;
    std::vector<double> ms;  // answered in the order sent
    for (std::size_t k = 0; k < sent.size(); ++k)
      ms.push_back(std::chrono::duration<double, std::milli>(s.cmds_answered[k] - sent[k]).count());
    std::cout << "cmds " << n << " answered, " << percentiles(ms) << "\n";
    return true;
  }
  if (a == "noread") {
    std::lock_guard<std::mutex> lock(s.mu);
    s.noread = true;
    return true;
  }
  if (a == "closed") {
    const double secs = num();
    std::unique_lock<std::mutex> lock(s.mu);
    s.noread = false;  // a closed connection is seen by reading it
    s.cv.notify_all();
    if (s.cv.wait_for(lock, std::chrono::duration<double>(secs), [&] { return s.closed; }))
      std::cout << "closed after " << std::chrono::duration<double>(s.closed_at - s.connected).count() << " s\n";
    else
      std::cout << "open after " << secs << " s\n";
    return true;
  }
  if (a == "refusal") {
    const double secs = num();
    std::unique_lock<std::mutex> lock(s.mu);
    if (!s.cv.wait_for(lock, std::chrono::duration<double>(secs), [&] { return s.forces_at_refusal >= 0 || s.closed; }) ||
        s.forces_at_refusal < 0)
      return std::cout << "no refusal within " << secs << " s\n", false;
    s.cv.wait_for(lock, std::chrono::milliseconds(300), [&] { return s.closed; });
    std::cout << "refusal: held |F| " << s.held_at_refusal << " N at the STATUS, " << s.forces_at_refusal
              << " Forces before it; ";
    if (s.after_refusal)
      std::cout << "first Force after it |F| " << s.after_refusal->first << " N, "
                << std::chrono::duration<double, std::milli>(s.after_refusal->second - s.refused_at).count() << " ms later\n";
    else
      std::cout << "none after it\n";
    return true;
  }
  if (a == "image") {
    const std::string name = arg();
    const std::vector<std::uint8_t> b = isotouch::test::image_of(base, igtl::ImageMessage::ENDIAN_LITTLE, name.c_str());
    {
      std::lock_guard<std::mutex> lock(send_mu);
      sock->Send(b.data(), int(b.size()));
    }
    return wait_status(s, name);
  }
  std::cout << "unknown action '" << a << "'\n";
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::cerr << "usage: igtl_session_client HOST PORT BASE ACTION...\n";
    return 2;
  }
  std::signal(SIGPIPE, SIG_IGN);  // a server that dropped this client: the sends fail, the process goes on
  Shared s;
  const isotouch::engine::Volume base = isotouch::io::load_volume(argv[3]);
  s.copy = base;
  igtl::ClientSocket::Pointer sock = igtl::ClientSocket::New();
  if (sock->ConnectToServer(argv[1], std::atoi(argv[2])) != 0) {
    std::cerr << "igtl_session_client: cannot connect to " << argv[1] << ":" << argv[2] << "\n";
    return 1;
  }
  s.connected = Clock::now();
  Path path;
  std::atomic<bool> done{false};
  std::thread reader([&] { read_loop(sock, s); });
  std::thread streamer([&] { stream_loop(sock, path, s, done); });
  Client c{sock, s, path, base, argv, argc, 4};
  bool ok = true;
  while (ok && c.i < argc) ok = c.action(c.arg());
  done = true;
  streamer.join();
  {
    std::lock_guard<std::mutex> lock(s.mu);
    s.noread = false;  // the reader sees the close
    s.cv.notify_all();
  }
  sock->CloseSocket();
  reader.join();
  return ok ? 0 : 1;
}
