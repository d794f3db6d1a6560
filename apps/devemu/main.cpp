// isotouch-devemu - the firmware side of isotouch protocol v1 (or, with --polhem, of the
// Polhem's USB reports) as a separate process: a point mass pulled by a simulated hand (or a
// scripted path) on its own clock at 1 to 8 kHz, serving `isotouch ... --haptic emu:SOCKET`
// (--polhem: `--haptic polhem:emu:SOCKET`) over a Unix-domain socket, with injectable
// faults. Prints what it sent, received and measured when it stops.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <iostream>

#include "isotouch/apps/cli_common.h"
#include "isotouch/sim/device_emulator.h"

namespace {
isotouch::sim::DeviceEmulator* g_emu = nullptr;
extern "C" void on_signal(int) {
  if (g_emu) g_emu->stop();  // an atomic store
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5))];
}
}  // namespace

int main(int argc, char** argv) {
  using namespace isotouch;
  CLI::App cli{
      "isotouch-devemu: a simulated haptic device speaking isotouch protocol v1 (docs/hid-protocol.md), or with\n"
      "--polhem the Polhem's USB reports, over a Unix-domain socket, for `isotouch run SCENE --live --haptic\n"
      "emu:SOCKET` (--polhem: `--haptic polhem:emu:SOCKET[,config=v1|v3]`) and tests without hardware.\n\n"
      "Example:\n"
      "  isotouch-devemu --socket /tmp/dev.sock --rate 1000 --path hand.csv --drop 0.01\n"
      "  isotouch-devemu --socket /tmp/dev.sock --polhem --polhem-config v1   (--haptic polhem:emu:/tmp/dev.sock,config=v1)\n\n"
      "Exit status (docs/exit-codes.md): 0 stopped (--seconds or SIGINT / SIGTERM); 1 error (the socket, the\n"
      "path file); 2 usage error.\n"};
  app::common_options(cli);
  sim::EmuConfig c;
  c.caps.name = "devemu";
  c.caps.buttons = 1;
  c.caps.position_resolution_m = 1e-6;
  double half_mm = 150, max_force = 10, watchdog_ms = 50;
  std::vector<double> hold{0, 0, 0};
  std::string path_csv;
  cli.add_option("--socket", c.socket_path, "Unix-domain socket to listen on (a stale socket there is replaced; any other file is refused)")->required();
  cli.add_option("--rate", c.rate_hz, "Report rate [Hz]")->capture_default_str()->check(CLI::Range(1.0, 8000.0));
  cli.add_option("--seconds", c.seconds, "Run this long, 0 = until SIGINT/SIGTERM")->capture_default_str()->check(CLI::NonNegativeNumber);
  cli.add_option("--path", path_csv, "Hand path CSV: header, then t_s,x_m,y_m,z_m rows (device frame), from each connection, looped (isotouch run SCENE --hand-path FILE writes one)");
  cli.add_option("--hold", hold, "Without --path: the hand holds this point x,y,z [m]")->delimiter(',')->expected(3);
  double sine_mm = 0;  // [mm] on the command line; the emulator takes metres
  cli.add_option("--sine-mm", sine_mm, "Without --path: the hand moves +-this many mm along z")->check(CLI::NonNegativeNumber);
  cli.add_option("--sine-hz", c.sine_hz, "... at this frequency [Hz]")->capture_default_str()->check(CLI::PositiveNumber);
  cli.add_option("--mass", c.device.mass_kg, "End-effector mass [kg]")->capture_default_str()->check(CLI::PositiveNumber);
  cli.add_option("--hand-stiffness", c.device.hand_stiffness_n_per_m, "Hand spring [N/m]")->capture_default_str()->check(CLI::NonNegativeNumber);
  cli.add_option("--hand-damping", c.device.hand_damping_n_s_per_m, "Hand damper [N s/m]")->capture_default_str()->check(CLI::NonNegativeNumber);
  cli.add_option("--max-force", max_force, "Maximum force, also the actuator's saturation [N]")->capture_default_str()->check(CLI::PositiveNumber);
  cli.add_option("--workspace-mm", half_mm, "Workspace: a cube of +-this many mm")->capture_default_str()->check(CLI::PositiveNumber);
  cli.add_option("--watchdog-ms", watchdog_ms, "No output report this long: the force is zeroed (0: off)")->capture_default_str()->check(CLI::NonNegativeNumber);
  bool polhem = false;
  std::string polhem_config = "v3";
  cli.add_flag("--polhem", polhem,
               "Speak the Polhem's 14-byte USB reports instead (lock-step, calibration request, 0.5 s firmware watchdog; "
               "for --haptic polhem:emu:SOCKET); its limits replace --max-force, --workspace-mm and --watchdog-ms");
  cli.add_option("--polhem-config", polhem_config, "With --polhem: the unit's kinematics, v1 or v3")
      ->capture_default_str()->check(CLI::IsMember({"v1", "v3"}));
  cli.add_option("--polhem-lose-calibrations", c.polhem_lose_calibrations,
                 "With --polhem: the first N calibration commands are lost (the firmware keeps only its last queued report)")
      ->check(CLI::NonNegativeNumber);
  cli.add_flag("--polhem-power-up", c.polhem_power_up,
               "With --polhem: start as the firmware powers up (info 0, counters 0 where the handle starts); "
               "it asks for calibration only once the switch is pressed (--polhem-switch-at)");
  cli.add_option("--polhem-switch-at", c.polhem_switch_at_s,
                 "With --polhem-power-up: the handle is pressed into the calibration switch at this time [s since start]");
  bool fifo = true;
  cli.add_flag("--fifo,!--no-fifo", fifo, "Run the device clock under SCHED_FIFO priority 75 when allowed (default on)");
  auto* faults = cli.add_option_group("Faults", "Probabilities are per input report; times are [s] since start");
  sim::EmuFaults& f = c.faults;
  faults->add_option("--drop", f.drop, "Probability a report is dropped")->check(CLI::Range(0.0, 1.0));
  faults->add_option("--duplicate", f.duplicate, "Probability a report is sent twice")->check(CLI::Range(0.0, 1.0));
  faults->add_option("--reorder", f.reorder, "Probability a report is swapped with the next")->check(CLI::Range(0.0, 1.0));
  faults->add_option("--garbage", f.garbage, "Probability random bytes are sent instead")->check(CLI::Range(0.0, 1.0));
  faults->add_option("--delay", f.delay, "Probability a report is delayed by --delay-ms")->check(CLI::Range(0.0, 1.0));
  faults->add_option("--delay-ms", f.delay_ms, "Delay of a delayed report [ms]")->capture_default_str()->check(CLI::NonNegativeNumber);
  faults->add_option("--freeze-at", f.freeze_at_s, "Stop reporting (the link stays up) at this time [s]");
  faults->add_option("--freeze-for", f.freeze_for_s, "... for this long [s]")->check(CLI::NonNegativeNumber);
  faults->add_option("--disconnect-at", f.disconnect_at_s, "Close the connection and the socket at this time [s]");
  faults->add_option("--reconnect-after", f.reconnect_after_s, "... and listen again this much later [s]");
  faults->add_flag("--faults-from-connection", f.from_first_connection,
                   "Fault times count from the host's first connection, not from the start");
  faults->add_option("--seed", f.seed, "Random seed of the faults")->capture_default_str();
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app::parse_exit(cli, e);
  }

  c.caps.workspace_min_m = core::Vec3{-half_mm, -half_mm, -half_mm} * 1e-3;
  c.caps.workspace_max_m = core::Vec3{half_mm, half_mm, half_mm} * 1e-3;
  c.caps.max_force_n = max_force;
  c.device.force_max_n = max_force;
  c.caps.native_rate_hz = c.rate_hz;
  c.caps.watchdog_s = watchdog_ms * 1e-3;
  c.hold_m = core::Vec3{hold[0], hold[1], hold[2]};
  c.sine_amplitude_m = sine_mm * 1e-3;
  c.fifo_priority = fifo ? 75 : 0;
  c.polhem = polhem;
  servo::hid::polhem::parse_config(polhem_config, c.polhem_config);  // checked by the option
  try {
    if (!path_csv.empty()) c.path = sim::load_path_csv(path_csv);
    sim::DeviceEmulator emu(c);
    emu.listen();
    g_emu = &emu;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    std::cout << "devemu   listening on " << c.socket_path << " at " << c.rate_hz << " Hz";
    if (polhem)
      std::cout << " as a Polhem, kinematics " << servo::hid::polhem::config_name(c.polhem_config) << " (from "
                << servo::hid::polhem::kConfigSource << ")";
    std::cout << std::endl;
    const sim::EmuStats s = emu.run();
    g_emu = nullptr;
    std::cout << "devemu   " << s.connections << " connections, " << s.reports_sent << " reports sent, "
              << s.outputs_received << " outputs received (" << s.outputs_refused << " refused), dropped "
              << s.dropped << ", duplicated " << s.duplicated << ", reordered " << s.reordered << ", garbled "
              << s.garbled << ", delayed " << s.delayed << ", watchdog trips " << s.watchdog_trips
              << ", max |F| " << s.max_force_n << " N\n";
    if (s.outputs_received > 0)
      std::cout << "devemu   last output: enable " << (s.last_enable ? 1 : 0) << ", |F| " << s.last_force_n << " N\n";
    if (polhem)
      std::cout << "devemu   Polhem: " << s.calibrations << " calibration commands (" << s.calibrations_lost
                << " lost), " << (s.calibrated_ns ? "calibrated" : "never calibrated") << ", " << s.switch_presses
                << " switch presses, " << s.currents_while_uncalibrated << " current commands while uncalibrated\n";
    if (!s.latency_us.empty())
      std::cout << "devemu   report-to-force [us]: p50 " << percentile(s.latency_us, 0.5) << ", p99 "
                << percentile(s.latency_us, 0.99) << ", max " << percentile(s.latency_us, 1.0) << "\n";
    return exit_code::kOk;
  } catch (const std::exception& e) {
    std::cerr << "isotouch-devemu: error: " << e.what() << "\n";
    return exit_code::kError;
  }
}
