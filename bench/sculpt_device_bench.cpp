#include "isotouch/bench/sculpt_device_bench.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <thread>

#include "isotouch/bench/sculpt_big_bench.h"
#include "isotouch/bench/servo_bench.h"
#include "isotouch/eval/stats.h"

extern char** environ;

namespace isotouch::bench {

namespace fs = std::filesystem;

bool misses_within(long missed, long ticks, long ref_missed, long ref_ticks) {
  if (ticks < kMinVerdictTicks || ref_ticks < kMinVerdictTicks || missed < 0 || ref_missed < 0) return false;
  const double ref = double(ref_missed) * double(ticks) / double(ref_ticks);
  return double(missed) <= ref + 3 * std::sqrt(ref);
}

namespace {
std::string fixed(double x, int digits = 1) {
  if (!std::isfinite(x)) return "n/a";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << x;
  return s.str();
}
}  // namespace

std::string ratio_verdict(double device_ms, double mouse_ms, double limit) {
  const bool ok = std::isfinite(device_ms) && std::isfinite(mouse_ms) && device_ms > 0 && mouse_ms > 0;
  const double r = ok ? device_ms / mouse_ms : NAN;
  return "device / mouse = " + fixed(r, 2) + ": <= " + fixed(limit, 2) + " " + (ok && r <= limit ? "PASS" : "FAIL");
}

namespace {
const char* kWhole = "frames drawn whole (first, camera or style changed)";
const char* kReused = "frames reusing the last picture (only the probe and the edits drawn again)";
const char* kAll = "frame time";

/// An isotouch-devemu process: its CPU time [s] read from /proc while it runs.
class Emulator {
 public:
  Emulator(const std::string& exe, const std::string& socket) : socket_(socket) {
    std::error_code ec;
    fs::remove(socket, ec);
    std::vector<std::string> args = {exe, "--socket", socket, "--rate", "1000", "--sine-mm", "5"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, exe.c_str(), &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
    t0_ = std::chrono::steady_clock::now();
    for (int i = 0; i < 200 && pid_ > 0 && !fs::exists(socket_); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ~Emulator() { stop(); }
  bool ok() const { return pid_ > 0 && fs::exists(socket_); }
  /// Stops it: its CPU time [s] and its wall time [s] since it started.
  void stop() {
    if (pid_ <= 0) return;
    cpu_s_ = cpu_now();
    wall_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    ::kill(pid_, SIGTERM);
    while (::waitpid(pid_, nullptr, 0) < 0 && errno == EINTR) {
    }
    pid_ = -1;
  }
  double cpu_s() const { return cpu_s_; }
  double wall_s() const { return wall_s_; }

 private:
  /// utime + stime of /proc/PID/stat (fields 14 and 15) [s].
  double cpu_now() const {
    std::ifstream f("/proc/" + std::to_string(pid_) + "/stat");
    std::string s((std::istreambuf_iterator<char>(f)), {});
    const auto paren = s.rfind(')');
    if (paren == std::string::npos) return NAN;
    std::istringstream in(s.substr(paren + 2));
    std::string field;
    double ut = NAN, st = NAN;
    for (int i = 3; i <= 15 && in >> field; ++i) {
      if (i == 14) ut = std::stod(field);
      if (i == 15) st = std::stod(field);
    }
    return (ut + st) / double(::sysconf(_SC_CLK_TCK));
  }
  std::string socket_;
  pid_t pid_ = -1;
  std::chrono::steady_clock::time_point t0_;
  double cpu_s_ = NAN, wall_s_ = NAN;
};

/// One mode's runs pooled.
struct Mode {
  std::string name;
  int runs = 0;
  long ticks = 0, missed = 0;
  std::vector<double> all, whole, reused;  // each run's median [ms]
  double app_cpu_s = 0, app_wall_s = 0, emu_cpu_s = 0, emu_wall_s = 0;
  std::string error;
  double median(const std::vector<double>& v) const { return v.empty() ? NAN : eval::median(v); }
};

std::string exe_beside(const std::string& given, const char* name) {
  if (!given.empty()) return given;
  return (fs::read_symlink("/proc/self/exe").parent_path() / name).string();
}

std::string resolve(const std::string& rel) {
  if (fs::exists(rel)) return rel;
  return (fs::path(ISOTOUCH_SOURCE_DIR) / rel).string();
}

/// Runs isotouch-sculpt --bench with `args` (after the scene) beside a fresh emulator on
/// `socket`, min_runs times and until the mode has min_ticks servo ticks (max_runs at most);
/// `haptic`: the --haptic value or "".
Mode run_mode(const SculptDeviceOptions& o, const std::string& name, const std::string& scene,
              const std::string& socket, const std::string& haptic, std::ostream& progress) {
  Mode m;
  m.name = name;
  const std::string emu_exe = exe_beside(o.devemu_exe, "isotouch-devemu");
  while (m.error.empty() && (m.runs < o.min_runs || (m.ticks < o.min_ticks && m.runs < o.max_runs))) {
    Emulator emu(emu_exe, socket);
    if (!emu.ok()) {
      m.error = "isotouch-devemu (" + emu_exe + ") did not start listening on " + socket;
      break;
    }
    std::vector<std::string> args = {scene};
    if (!haptic.empty()) args.insert(args.end(), {"--haptic", haptic});
    progress << "[bench sculpt-device] " << name << ": isotouch-sculpt " << scene << " --bench"
             << (haptic.empty() ? "" : " --haptic " + haptic) << "\n" << std::flush;
    const ChildRun r = run_sculpt_bench(o.sculpt_exe, args, o.width, o.device);
    emu.stop();
    const ServoLine servo = parse_sculpt_servo(r.out);
    const auto st = parse_sculpt_stats(r.out);
    if (!r.started || r.exit_code != 0 || servo.ticks <= 0 || !st.count(kAll)) {
      m.error = "isotouch-sculpt did not complete (" + (r.started ? "exit code " + std::to_string(r.exit_code) : r.error) +
                (servo.ticks <= 0 ? ", no servo line" : "") + "); its last output:\n" +
                r.out.substr(r.out.size() > 1500 ? r.out.size() - 1500 : 0);
      break;
    }
    ++m.runs;
    m.ticks += servo.ticks, m.missed += servo.missed;
    for (auto [what, v] : {std::pair{kAll, &m.all}, {kWhole, &m.whole}, {kReused, &m.reused}})
      if (st.count(what) && std::isfinite(st.at(what).median)) v->push_back(st.at(what).median);
    m.app_cpu_s += r.cpu_s, m.app_wall_s += r.wall_ms / 1e3;
    m.emu_cpu_s += emu.cpu_s(), m.emu_wall_s += emu.wall_s();
  }
  return m;
}

void print_modes(const std::vector<Mode>& modes, std::ostream& out) {
  out << "| mode | runs | servo ticks | missed | frames median ms | drawn whole median ms | reusing median ms | "
         "app CPU (sculpt + Xvfb), % of one core | emulator CPU, % of one core |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const Mode& m : modes)
    out << "| " << m.name << " | " << m.runs << " | " << m.ticks << " | " << m.missed << " | " << fixed(m.median(m.all))
        << " | " << fixed(m.median(m.whole)) << " | " << fixed(m.median(m.reused)) << " | "
        << fixed(100 * m.app_cpu_s / m.app_wall_s) << " | " << fixed(100 * m.emu_cpu_s / m.emu_wall_s) << " |\n";
  out << "(medians: the median of each run's median)\n";
}

void print_verdicts(const Mode& mouse, const Mode& dev, bool same_path, std::ostream& out) {
  out << "verdict: " << dev.name << ": frames drawn whole " << ratio_verdict(dev.median(dev.whole), mouse.median(mouse.whole))
      << "\n";
  if (same_path)
    out << "verdict: " << dev.name << ": all frames " << ratio_verdict(dev.median(dev.all), mouse.median(mouse.all)) << "\n";
  else
    out << "note:    " << dev.name << ": all frames " << fixed(dev.median(dev.all)) << " ms against " << fixed(mouse.median(mouse.all))
        << " ms: not compared (its hand follows the emulator's sine, not the bench's cursor: another mix of frames)\n";
  const double ref = mouse.ticks > 0 ? double(mouse.missed) * double(dev.ticks) / double(mouse.ticks) : NAN;
  out << "verdict: " << dev.name << ": servo missed " << dev.missed << " of " << dev.ticks << " ticks against the mouse's "
      << mouse.missed << " of " << mouse.ticks << " (" << fixed(ref) << " at this many ticks; needs <= ref + 3 sqrt(ref) = "
      << fixed(ref + 3 * std::sqrt(ref)) << (std::min(dev.ticks, mouse.ticks) < kMinVerdictTicks ? ", fewer than 20,000 ticks: not a pass" : "")
      << "): " << (misses_within(dev.missed, dev.ticks, mouse.missed, mouse.ticks) ? "PASS" : "FAIL") << "\n";
}

/// The three modes on one scene; false when a run did not complete.
bool bench_scene(const SculptDeviceOptions& o, const std::string& scene, const fs::path& dir, std::ostream& out,
                 std::ostream& progress) {
  out << "\n## " << scene << "\n\n";
  const std::string idle = (dir / "idle.sock").string(), emu = (dir / "emu.sock").string();
  const std::string rec = (dir / (fs::path(scene).stem().string() + "-mouse.rec")).string();
  // The recording (c) plays: a mouse run of its own, so that (a) is not timed recording.
  {
    std::vector<std::string> args = {scene, "--record", rec};
    progress << "[bench sculpt-device] recording the mouse bench's hand into " << rec << "\n" << std::flush;
    const ChildRun r = run_sculpt_bench(o.sculpt_exe, args, o.width, o.device);
    if (!r.started || r.exit_code != 0 || !fs::exists(rec)) {
      out << "the recording run did not complete (exit code " << r.exit_code << "): " << r.error << "\n";
      return false;
    }
  }
  std::vector<Mode> modes;
  modes.push_back(run_mode(o, "(a) mouse, emulator idle beside it", scene, idle, "", progress));
  modes.push_back(run_mode(o, "(b) emu: isotouch-devemu --sine-mm 5", scene, emu, "emu:" + emu, progress));
  modes.push_back(run_mode(o, "(c) playback of (a)'s recording", scene, idle, "playback:" + rec, progress));
  print_modes(modes, out);
  bool ok = true;
  for (const Mode& m : modes)
    if (!m.error.empty()) out << m.name << ": " << m.error << "\n", ok = false;
  if (!ok) return false;
  print_verdicts(modes[0], modes[1], false, out);
  print_verdicts(modes[0], modes[2], true, out);
  return true;
}
}  // namespace

int run_bench_sculpt_device(const SculptDeviceOptions& o, std::ostream& out, std::ostream& progress) {
  out << "# bench sculpt-device\n\nload average before: " << load_average() << "\n" << cpu_model() << "\n";
  std::string tmpl = (fs::temp_directory_path() / "isotouch-sculpt-device-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr) {
    out << "bench sculpt-device: could not make a temporary folder from " << tmpl << "\n";
    return 1;
  }
  bool ok = true;
  for (const std::string& scene : o.scenes) {
    try {
      ok = bench_scene(o, resolve(scene), tmpl, out, progress) && ok;
    } catch (const std::exception& e) {
      out << "bench sculpt-device: " << scene << ": " << e.what() << "\n";
      ok = false;
    }
  }
  std::error_code ec;
  fs::remove_all(tmpl, ec);
  out << "\nload average after: " << load_average() << "\n";
  return ok ? 0 : 1;
}

}  // namespace isotouch::bench
