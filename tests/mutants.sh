#!/usr/bin/env bash
# tests/mutants.sh - breaks each safety-guarding source line once and shows that the tests
# guarding it fail. Not run by ctest: it rebuilds a copy of the tree per mutation; .ci/run
# runs every mutation after the suite (--shard splits them over several runs, if ever needed).
#
# usage: tests/mutants.sh [-k] [--shard K/N] [NAME_REGEX]
#   NAME_REGEX  run only the mutations whose name matches (grep -E)
#   --shard K/N run only the mutations whose index i has i % N == K (K in 0..N-1): N runs with
#               K = 0..N-1 cover every line; the selected names are printed first
#   -k          keep the copy (build-mutants/) afterwards, for a faster next run
#
# The working tree (tracked and untracked, not ignored files) is copied to build-mutants/src
# (ignored by git; under the same ccache base_dir as the tree, so unchanged files come from
# the cache). The tree itself is never modified, also not on Ctrl-C. The copy is built once
# and every test named below is run unmutated first: if one fails there, nothing is judged.
# Then per mutation: the text is replaced in the copy, only the named target is rebuilt,
# its test run with the named filter, the file restored. Prints one line per mutation:
#   KILLED    the test failed in both of two runs (the failing tests are named)
#   SURVIVED  the test passed with the line broken: the line is not guarded
#   FLAKY     it failed in one run of two only: a safety test that passes on a retry has failed
#   ERROR     the text was not found exactly once, or the mutant did not build
# Exit status: 0 all killed; 1 some survived; 2 some errors (or the unmutated run failed).
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
keep=0 shard=""
while [ $# -gt 0 ]; do
  case "$1" in
    -k) keep=1; shift ;;
    --shard) shard=$2; shift 2 ;;
    *) break ;;
  esac
done
only=${1:-}

# ---- The mutations ----
# m NAME WHERE OLD NEW TARGET FILTER
#   WHERE   a file, or a folder whose one file (*.cpp, *.h) holding OLD is meant: lines that
#           move between files (a split) are still found by their content
#   OLD     the exact text to replace; it must occur exactly once (use $'...\n...' to take in
#           a neighbouring line where the text alone occurs twice)
#   NEW     its replacement ("" deletes it)
#   TARGET  the build target whose test must fail; FILTER its --gtest_filter. A FILTER
#           "ctest:NAME" runs the ctest test NAME instead (a cli_*.sh test judged on what a
#           peer or a file got), TARGET then the targets it runs, space-separated
names=() wheres=() olds=() news=() targets=() filters=()
m() { names+=("$1"); wheres+=("$2"); olds+=("$3"); news+=("$4"); targets+=("$5"); filters+=("$6"); }

S=servo/servo_thread.cpp T=test_servo_thread F='ServoSafety.*'
m servo-bad-tick-zero       $S 'device_.write_force_n({});  // within this tick' '' $T "$F"
m servo-stale-judged        $S 'if (d.received_ns != 0 && t - d.received_ns > stale_ns) return DeviceStatus::kStale;' '' $T "$F"
m servo-refused-position    $S 'if (!caps.contains(d.position_m)) {' 'if (false) {' $T "$F"
m servo-ramp-factor         $S 'double ramp = ramp_ns > 0 ? std::min(1.0, double(t - ramp_start) / ramp_ns) : 1.0;' \
                               'double ramp = 1.0;' $T "$F"
m servo-ramp-reconnect      $S 'if (first || d.connection != connection) ramp_start = -1;' '' $T "$F"
m servo-ramp-after-outage   $S $'restart_ns) {\n          ramp_start = -1;' 'restart_ns) {' $T "$F"
m servo-paused-zero         $S $'} else if (paused) {\n        device_.write_force_n({});' '} else if (paused) {' $T "$F"
m servo-stop-zero           $S 'device_.write_force_n({});  // leave the device with no force' '' $T "$F"
# stop() turns the force off itself: on its own it matters where the loop never reaches its
# end (a renderer that never returns); in a normal stop the loop's last lines do it first.
m servo-stop-disable        $S $'    device_.enable_force(false, 0);\n  }\n  unlock_servo_memory();' $'  }\n  unlock_servo_memory();' \
  $T 'ServoThread.StopGivesUp*'
m servo-device-force-off    $S 'if ((d.force_off || d.watchdog_tripped) && ramp_start >= 0) ramp_start = t;' '' \
  $T 'ServoSafety.AfterTheDeviceWatchdogTripped*'
m servo-late-restart        $S 'ramp_start = -1;  // the next tick starts the ramp' '' \
  $T 'ServoThread.ADeviceThatTookTheForceOff*'

# The force gate every force passes (servo/force_gate.cpp), judged on what the device received.
G=servo/force_gate.cpp
m gate-peak-at-2x           $G 'if (m > lim_.peak_n) f = f * (lim_.peak_n / m), m = lim_.peak_n, flags |= kGatePeak;' \
                               'if (m > 2 * lim_.peak_n) f = f * (lim_.peak_n / m), m = lim_.peak_n, flags |= kGatePeak;' $T "$F"
m gate-rate-off             $G 'if (c > allowed) f = last_ + change * (allowed / c), flags |= kGateRate;' '' \
  $T 'ServoSafety.AStepDemand*'
m gate-nonfinite-zero       $G 'if (!all_finite(f)) f = {}, flags |= kGateNonFinite;' '' $T 'ServoSafety.ANonFinite*'
m backend-step-every-kind   $G 'if (c > allowed) f = last_ + change * (allowed / c), flags |= kGateRate;' '' test_backend_faults '*_Step'
m backend-nan-every-kind    $G 'if (!all_finite(f)) f = {}, flags |= kGateNonFinite;' '' test_backend_faults '*_NaN'
m backend-gap-every-kind    $S 'if (d.received_ns != 0 && t - d.received_ns > stale_ns) return DeviceStatus::kStale;' '' \
  test_backend_faults '*_PoseGap'
m gate-continuous-off       $G 'if (const double cap = continuous_cap(dt_s); m > cap) f = f * (cap / m), flags |= kGateContinuous;' '' \
  test_force_gate 'ForceGate.*'
m gate-scene-limit          $G 'l.peak_n = std::min(limit_or_inf(scene_limit_n), limit_or_inf(caps.max_force_n));' \
                               'l.peak_n = limit_or_inf(caps.max_force_n);' $T 'ServoSafety.TheScenesLimit*'
m gate-zero-on-bad-tick     $S $'device_.write_force_n({});  // within this tick\n        gate_.zero(gate_dt);' \
                               'device_.write_force_n({});  // within this tick' $T 'ServoSafety.AStepDemand*'
m servo-exact-zero-at-once  $S 'if (ramp_start < 0 || ramp == 0 || rec.out.fault) {' 'if (ramp_start < 0) {' \
  $T 'ServoSafety.AFaultOrTheDevices*'
m servo-faster-than-device  $S 'if (caps_.output_rate_hz > 0 && cfg_.rate_hz > caps_.output_rate_hz * 1.001)' 'if (false)' \
  $T 'ServoSafety.AServoFaster*'

# The device side's stall rule (servo/stall_rule.cpp), on a simulated clock and on the wire of
# every backend with a thread of its own, and the emulator that checks it.
R=servo/stall_rule.cpp E=sim/device_emulator.cpp
m stall-counted             $R 'if (on && was_on_ && stalled) {' 'if (false) {' test_stall_rule 'StallRule.*'
m stall-off                 $R 'if (o.stalls != stalls_.load(std::memory_order_relaxed)) on = false;' '' test_stall_rule 'StallRule.*'
m stall-no-jump-back        $R 'if (stalls != stalls_seen_) f = Vec3{};  // the first write after a stall: no jump back' '' \
  test_stall_rule 'StallRule.*'
m stall-half-period         $R 'std::max(stall_s - p / 2, p)' 'std::max(stall_s, p)' test_stall_rule 'StallRule.*'
m writer-stall-counted      $R 'if (on && was_on_ && stalled) {' 'if (false) {' test_report_device 'ReportDevice.AServoThatStops*'
m writer-stall-on-the-wire  $R 'if (on && was_on_ && stalled) {' 'if (false) {' \
  test_device_emu 'DeviceEmu.AStalledServo*:DeviceEmu.ARendererThatNeverReturns*'
m backend-stall-every-kind  $R 'if (on && was_on_ && stalled) {' 'if (false) {' test_backend_faults '*_Stall'
m sdk-nonfinite-backstop    $R 'Vec3 f = ok ? force_n : Vec3{};' 'Vec3 f = force_n;' test_sdk_devices 'OpenHaptics.ANonFinite*'
m emu-watchdog              $E 'enabled_ = false, force_n_ = {}, watchdog_tripped_ = true;' '' \
  test_device_emu 'DeviceEmu.AFrozenWriterTripsTheDevicesWatchdog'
m emu-output-log            $E 'log_[logged_ % log_.size()] = ReceivedOutput{now, force_n, enable, answers};' '' \
  test_device_emu 'DeviceEmu.*'

# The vendor SDK backends against their doubles (what the library received).
OH=servo/openhaptics_device.cpp FD=servo/forcedimension_device.cpp
m hd-disable-at-close       $OH 'api_.hdDisable(hd::kForceOutput);' '' test_sdk_devices 'OpenHaptics.CloseDisables*'
m hd-calibration-gate       $OH 'const bool zero = closing_.load() || !on || down_ || !calibrated;' \
                               'const bool zero = closing_.load() || !on || down_;' test_sdk_devices 'OpenHaptics.NoForceUntil*'
m hd-calibration-update     $OH 'api_.hdUpdateCalibration(cal_style_);' '' test_sdk_devices 'OpenHaptics.ACalibrationThatNeeds*'
m hd-continuous-force       $OH '    c.max_continuous_force_n = v;' '    ;' test_sdk_devices 'OpenHaptics.ContinuousForce*'
m fd-watchdog               $FD 'if (api_.dhdSetWatchdog((unsigned char)units, id_) < 0) return note_error("dhdSetWatchdog");' \
                               'return;' test_sdk_devices 'ForceDimension.OpenSets*'

m fd-reopen                 $FD '  if (down_) reopen(now, force_on);' '' test_sdk_devices 'ForceDimension.Vanished*'
# A force-off by the firmware (its watchdog, the force button) read from dhdGetStatus: held
# off until the servo's force is an exact zero; not turned on again by isotouch unless its
# watchdog turned it off.
m fd-status-read            $FD 'if (periods_.load(std::memory_order_relaxed) % status_every_ == 0) read_status(force_on);' '' \
  test_sdk_devices 'ForceDimension.AFirmwareWatchdogTrip*'
m fd-watchdog-flag          $FD 'r.watchdog_tripped = fw_off_ && fw_off_cause_ == dhd::kForceOffWatchdog;' '' \
  test_sdk_devices 'ForceDimension.AFirmwareWatchdogTrip*'
m fd-back-from-zero         $FD 'if (servo_zero && (fw_off_cause_ == dhd::kForceOffWatchdog || fw_on_)) fw_off_ = false;' \
                               'if (fw_off_cause_ == dhd::kForceOffWatchdog || fw_on_) fw_off_ = false;' \
  test_sdk_devices 'ForceDimension.AFirmwareWatchdogTrip*'
m fd-user-turns-forces-on   $FD 'if (servo_zero && (fw_off_cause_ == dhd::kForceOffWatchdog || fw_on_)) fw_off_ = false;' \
                               'if (servo_zero) fw_off_ = false;' test_sdk_devices 'ForceDimension.ForcesTurnedOff*'
# Not calibrated yet: zero force, counted apart from faults (run --live does not exit 5).
m hd-uncalibrated-not-fault $OH 'if (!calibrated) r.status = DeviceStatus::kUncalibrated;' \
                               'if (!calibrated) r.status = DeviceStatus::kFault;' test_sdk_devices 'OpenHaptics.CalibratedAfter*'
m servo-uncalibrated-count  servo/servo_thread.cpp \
                               'else if (s == DeviceStatus::kUncalibrated) uncalibrated_.fetch_add(1, std::memory_order_relaxed);' '' \
  test_sdk_devices 'OpenHaptics.CalibratedAfter*'

# What the report devices put on the wire: forces rounded toward zero (v1), the Polhem's
# currents scaled as one vector and none before isotouch's own calibration is acknowledged.
HR=servo/hid_report.cpp DP=servo/device_protocols.cpp
m v1-force-toward-zero      $HR 'const double q = std::trunc(v / unit);' 'const double q = std::round(v / unit);' \
  test_hid_report 'HidReport.AnEncoded*'
m polhem-scale-vector       $HR '  for (double& v : a) v *= s;' '' test_hid_report 'Polhem.CurrentsOverTheCap*'
m polhem-calibration-gate   $DP 'const bool on = enable && !faulted_.load() && calibrated_.load();' \
                               'const bool on = enable && !faulted_.load();' test_hid_report 'Polhem.ProtocolSendsNoCurrent*'
m polhem-own-command        $DP 'if (in.info == 0 && commanded_) calibrated_.store(true), commanded_ = false;' \
                               'if (in.info == 0) calibrated_.store(true), commanded_ = false;' \
  test_device_emu 'DeviceEmuPolhem.FromPowerUp*'
m polhem-uncalibrated-not-fault $DP $'    r.status = DeviceStatus::kUncalibrated;\n    r.force_off = true;' \
                               $'    r.status = DeviceStatus::kFault;\n    r.force_off = true;' \
  test_device_emu 'DeviceEmuPolhem.FromPowerUp*'
m polhem-refusal-cleared    servo/report_device.cpp '      unnote(link_->name() + ": " + fault_noted_);' '' \
  test_device_emu 'DeviceEmuPolhem.FromPowerUp*'

# The OpenIGTLink link: the zero at a stall and however the process ends (what the peer got).
IG=service/igtl_reply_rule.cpp X=servo/exit_zero.cpp
m igtl-stall-zero-at-once   $IG '  if (look.stalled_now) {' '  if (false) {' \
  test_igtl_device 'ServiceIgtlDevice.AStalledServo*'
m igtl-stale-stream-zero    $IG '    const bool send = !zero_sent_;' '    const bool send = false;' \
  test_igtl_device 'ServiceIgtlDevice.ForcesAnswerPoses*'
m igtl-rule-stall-zero      $IG '  if (look.stalled_now) {' '  if (false) {' test_igtl_reply_rule 'IgtlReplyRule.*'
m igtl-rule-stale-once      $IG '    const bool send = !zero_sent_;' '    const bool send = true;' test_igtl_reply_rule 'IgtlReplyRule.*'
m igtl-rule-stale-late      $IG '  if (t - pose_received_ns > stale_ns_) {' '  if (t - pose_received_ns > 2 * stale_ns_) {' \
  test_igtl_reply_rule 'IgtlReplyRule.*'
m igtl-rule-frozen-writer   $IG '  return !away;' '  return true;' test_igtl_reply_rule 'IgtlReplyRule.*'
m igtl-rule-never-twice     $IG ' && !skipped_;' ';' test_igtl_reply_rule 'IgtlReplyRule.*'
m igtl-rule-answers         $IG 'look.answers < pose_sequence' 'look.last_write_ns < pose_received_ns' \
  test_igtl_reply_rule 'IgtlReplyRule.*'
m exit-zero-on-crash        $X $'extern "C" void on_fatal_signal(int sig) {\n  send_exit_zeros(2000);' \
                               'extern "C" void on_fatal_signal(int sig) {' test_igtl_device 'ServiceIgtlDevice.ACrashOr*'
# A registered tracker's force goes back in the tracker's frame: R^T f, not the image's f.
m registration-force-back   service/registration.h \
  $'    return {r[0] * f.x + r[3] * f.y + r[6] * f.z, r[1] * f.x + r[4] * f.y + r[7] * f.z,\n            r[2] * f.x + r[5] * f.y + r[8] * f.z};' \
  '    return f;' test_service 'ServiceDevice.ARotatedRegistration*'
m exit-zero-sealed          $X $'  if (g_sealed.load()) {\n    s.busy.store(0);\n    return false;' \
                               $'  if (false) {\n    s.busy.store(0);\n    return false;' test_exit_zero 'ExitZero.*'
m exit-zero-alt-stack       $X '    a.sa_flags = SA_NODEFER | SA_ONSTACK;' '    a.sa_flags = SA_NODEFER;' test_exit_zero 'ExitZero.AStackOverflow*'
m exit-zero-not-mid-send    $X '    if (s.busy.load() != 0) {  // inside a send that does not end: the stream cannot take a zero' \
                               '    if (false) {' test_exit_zero 'ExitZero.*'

# A process ended for a stuck servo sends each link its zero before _Exit (what the peer got).
m live-stuck-exit-zero      session/live_session.cpp '  servo::send_exit_zeros(5000);  // a link'"'"'s peer (PLUS) holds the last force it got (exit_zero.h)' \
                               '' test_live_session 'LiveSession.AServoStuckEnd*'
# A v1 report device without a watchdog is refused unless the scene allows it.
m run-no-watchdog-refused   run/haptic_device.cpp 'if (d.report && !(d.io->caps().watchdog_s > 0) && !scene.allow_no_watchdog)' \
                               'if (false)' 'isotouch isotouch-devemu' 'ctest:cli_run_live_emu'
# A link's device limit (device.link_max_force_n) is the gate's clamp: what the peer got.
m igtl-link-max-force       service/igtl_device.cpp '  c.max_force_n = o_.max_force_n;  // the peer'"'"'s device, as the scene declares it' \
                               '' 'isotouch igtl_plus_peer' 'ctest:cli_haptic_igtl'
# serve's stream renders at the identity map: no 1 / workspace_scale in its force.
m serve-stream-unscaled     service/serve.cpp '  if (!echo_device_) so.hri.world_per_device = 1.0;' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# A pose the servo never read is counted when a newer one replaces it, a pose it read is not.
m device-overtaken-unread   service/transform_device.cpp 'read_sequence_.load(std::memory_order_relaxed) < p.sequence' 'true' \
                               test_service 'ServiceDevice.EachPoseNeverReadIsCountedOnce'
# A stream client dropped by an exception in its thread is left a zero before its connection closes.
m serve-dropped-zero        service/serve.cpp '  if (dropped) leave_stream_zero(c, "its connection closed");' '  (void)dropped;' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# serve's stream is clamped to the link's limit (device.link_max_force_n), not only the scene's:
# the caps the gate reads, and serve setting them from the scene.
m serve-link-max-force      service/transform_device.h '    c.max_force_n = max_force_n_;' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
m serve-link-max-force-set  service/serve.cpp '    device_.set_max_force_n(scene_.link_max_force_n);' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# serve's stream: the stiffness bound at its measured rate (as igtl:'s), a slower stream refused.
m serve-stream-k-bound      service/serve.cpp '  if (!j.over) {' '  if (true) {' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# ... the link's simulated bound (as igtl:'s), not Colgate-Schenkel's: K 600 over 100 Hz refused (part 11).
m serve-stream-link-bound   service/serve.cpp '  if (!j.over) {' '  if (!(k > j.colgate_n_per_m)) {' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# ... with the peer's controller when the scene says it runs one: K 600 over 100 Hz served (part 11).
m serve-stream-peer-pc      run/haptic_device.cpp '          scene.device, scene.link_round_trip_s, scene.link_passivity_control};' \
                               '          scene.device, scene.link_round_trip_s, false};' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# The stream's rate is judged at every pose over its latest 16, not once: a stream that slows is refused.
m serve-stream-rolling      service/serve.cpp '  if (c.stream_gap_count + 1 < kRatePoses) return true;' '  if (c.stream_gap_count + 1 != kRatePoses) return true;' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# ... over the bound at 16 judgements in a row: a moment's slowdown is not refused (part 10).
m serve-stream-hysteresis   service/serve.cpp '  if (++c.stream_over < kRatePoses) return true;' '  ++c.stream_over;' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# An IMAGE over the memory budget by its header alone is refused before its voxels are read.
m serve-budget-header       service/serve.cpp '  if (std::string why = memory_refusal(device, size, 0); !why.empty()) return {std::move(why), nullptr, 0};' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_budget'
# A still view whose frame is over the budget without its band still refines in bands of the margin.
m refine-bands-margin       engine/refine_bands.cpp '  if (band_cost(first, 1 - first) > room) room = band_cost(0, 0) + (1 - target_) * budget_ms_;' '' \
                               test_refine_bands 'RefineBands.*'
# A stream refused in contact: its client is sent a zero before the STATUS (part 9b).
m serve-refused-zero        service/serve.cpp '    if (stream_from_ == c.conn) stream_from_.reset();' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_truth'
# Once learned, the period moves at most 1/64 / 16 of it per interval: one late arrival does
# not stop the next ticks following and waiting.
m input-period-clamp        servo/input_phase.cpp 'std::clamp(d - period_ns_, -period_ns_ / 64, period_ns_ / 64)' 'd - period_ns_' \
                               test_input_phase 'InputWaitUntil.TwoLatePosesInARowAreBothRendered'
# A servo tick waits for its late input instead of letting the next one overtake it.
m servo-input-wait          servo/input_phase.cpp '  if (in.due_ns > t_ns || t_ns - in.due_ns > period_ns) return -1;' '  return -1;' \
                               test_input_phase 'InputWaitUntil.*'
m servo-input-wait-call     servo/servo_thread.cpp '    if (cfg_.follow_input_phase) t = wait_for_input(t, next, period);' '' \
                               test_servo_thread 'ServoThread.ATickWaitsForALatePoseInsteadOfLeavingItToTheNext'
# A pose the servo answered after a newer one came is still answered (its own force and stamp).
m serve-reply-overtaken     service/stream_replies.h '    return other && servo_answered.sequence == l.answers ? servo_answered : newest;' '    return newest;' \
                               test_stream_replies 'StreamReplies.APoseTheServoAnsweredIsAnsweredThoughANewerOneCame'
# The stream's age is the newest pose's, not that of an older pose the servo answered late.
m serve-reply-stale-newest   service/stream_replies.h 'std::max(p.received_ns, newest.received_ns)' 'p.received_ns' \
                               test_igtl_reply_rule 'IgtlReplyRule.ServesReplyToAnOlderPoseJudgesStalenessByTheNewest'
# A reply waits (bounded) for another send to the same client instead of being dropped.
m socket-busy-wait          service/igtl_socket.cpp '    if (std::chrono::steady_clock::now() >= until) return Sent::kBusy;' '    return Sent::kBusy;' \
                               test_service 'ServiceSocket.ADroppableSendWaitsForAnotherSendUnderWayWithinItsBusyWait'
# serve's command thread: no burst of missed tool ticks, a stroke through a moment out of contact.
m serve-tool-no-burst       service/tool_ticks.cpp '  return (now > due + period ? now : due) + period;' '  return due + period;' \
                               test_tool_ticks 'ToolTicks.*'
m serve-stroke-gap          service/tool_ticks.cpp '  if (apart_s_ + 1e-9 < kStrokeGapS) return false;' '' \
                               test_tool_ticks 'ToolTicks.*'
# A journal whose rewrite failed writes nothing more (its file stays the session before the change).
m journal-restart-fails-quiet io/journal.cpp '    impl_->error = e.what();  // appends are dropped from now on, not queued for no writer' '    (void)e;' \
                               test_journal 'Journal.*'
# serve's edit journal through an `isovalue V` (issue 62): it goes on for the rebuilt session, and
# a restore drops the undo history where the session was rebuilt (cli_serve_journal's last part).
m serve-journal-isovalue    service/serve.cpp $'  if (journal_.journal)\n    carry = ' $'  if (false)\n    carry = ' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_journal'
m journal-history-restart   io/journal_offer.cpp '++next) es.sculptor().drop_history();' '++next) {}' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_journal'
# serve's one memory budget (issue 62): other clients' IMAGEs in flight counted, and an
# unknown memory's default (cli_serve_budget; its fault seam keeps a wrongly taken image small).
m serve-budget-in-flight    service/serve.cpp '  in_flight += held > own_held_bytes ? held - own_held_bytes : 0;' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_budget'
m serve-budget-default      service/serve.cpp '  if (by_default) have = kUnknownMemoryBytes;' '  if (by_default) return "";' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_budget'
# An IMAGE the main thread took counts until its session runs (cli_serve_budget part 3).
m serve-budget-taken        service/serve.cpp '      if (v) building.emplace(' '      if (false) building.emplace(' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_budget'

# serve's TRANSFORM stream replies (`serve --reply-force`): what its client got.
SR=service/stream_replies.cpp T=test_stream_replies
m stream-stall-zero         $SR '    const IgtlReply r = poll.step(p, newest, l, now);' \
                               '    IgtlReply r = poll.step(p, newest, l, now); if (r.why == IgtlReply::Why::kStall) r.send = false;' $T 'StreamReplies.AStalledServo*'
m stream-stale-zero         $SR '    const IgtlReply r = poll.step(p, newest, l, now);' \
                               '    IgtlReply r = poll.step(p, newest, l, now); if (r.why == IgtlReply::Why::kStale) r.send = false;' $T 'StreamReplies.AStaleStream*'
m stream-stale-late         $SR 'StreamReplyPoll poll(std::int64_t(o_.stale_s * 1e9));' \
                               'StreamReplyPoll poll(std::int64_t(o_.stale_s * 2e9));' $T 'StreamReplies.AStaleStream*'
m stream-switch-zero        $SR '    fenced->send(zero_msg);  // blocking: the zero is not dropped' '' $T 'StreamReplies.AClientThatStops*'
m stream-exit-zero          $SR '        exit_zero = std::make_unique<ExitZeroFence>(to->fd(), zero_msg);' '' $T 'StreamReplies.ACrashOr*'

# HRI's own limits, wherever in servo/ the line now lives.
H=servo T=test_hri F='Hri.*'
m hri-limit-robust-at-2x    $H '} else if (mag > params_.force_limit_n) {' '} else if (mag > 2 * params_.force_limit_n) {' $T "$F"
m hri-limit-quick-at-2x     $H 'if (!(mag < params_.force_limit_n)) return quick_contact_limited(' \
                               'if (!(mag < 2 * params_.force_limit_n)) return quick_contact_limited(' $T "$F"
m hri-limit-paper-at-2x     $H $'} else {\n    out.saturated = saturate(force, params_.force_limit_n);' \
                               $'} else {\n    out.saturated = saturate(force, 2 * params_.force_limit_n);' $T "$F"
m hri-nonfinite-robust      $H $'if (!std::isfinite(mag)) {\n    force = {};' $'if (false) {\n    force = {};' $T "$F"
m hri-nonfinite-paper       $H 'if (!std::isfinite(norm(force))) {' 'if (false) {' $T "$F"
m hri-reach-robust-at-2x    $H 'const bool absurd = sane && dot(from_centre, from_centre) > params_.max_reach_m * params_.max_reach_m;' \
                               'const bool absurd = sane && dot(from_centre, from_centre) > 4 * params_.max_reach_m * params_.max_reach_m;' $T "$F"
m hri-reach-quick-at-2x     $H 'if (!(dot(from_centre, from_centre) <= params_.max_reach_m * params_.max_reach_m))' \
                               'if (!(dot(from_centre, from_centre) <= 4 * params_.max_reach_m * params_.max_reach_m))' $T "$F"
m hri-reach-paper-at-2x     $H 'const bool absurd = finite(hip) && norm(hip - field.grid().centre_m()) > params_.max_reach_m;' \
                               'const bool absurd = finite(hip) && norm(hip - field.grid().centre_m()) > 2 * params_.max_reach_m;' $T "$F"
m hri-speed-robust-at-2x    $H 'return dot(moved, moved) > max_move * max_move;' 'return dot(moved, moved) > 4 * max_move * max_move;' $T "$F"
m hri-speed-quick-at-2x     $H 'if (dot(moved, moved) > max_move * max_move) return tick_robust_full(' \
                               'if (dot(moved, moved) > 4 * max_move * max_move) return tick_robust_full(' $T "$F"
m core-saturate-at-2x       core/vec3.h 'if (!(m > limit)) return false;' 'if (!(m > 2 * limit)) return false;' $T "$F"
m hri-edit-ease-off         $H 'if (edited && !out.fault) {' 'if (false) {' test_hri_edit 'HriEdit.*'
m hri-edit-resaturate       $H $'if (sent > params_.force_limit_n) {\n    out.saturated = saturate(force, params_.force_limit_n);' \
                               $'if (sent > params_.force_limit_n) {\n    out.saturated = saturate(force, 2 * params_.force_limit_n);' \
                               test_hri_edit 'HriEdit.*'
m hri-edit-ease-half-period $H 'const Vec3 offset = edit_ease_from_ * (edit_ease_left_s_ / params_.edit_period_s);' \
                               'const Vec3 offset = edit_ease_from_ * std::max(0.0, 2 * edit_ease_left_s_ / params_.edit_period_s - 1);' \
                               test_hri_edit 'HriEdit.*'
m hri-release-fade-contact  $H $'out.penetration_m = 0;\n    ++release_fade_ticks_;' \
                               $'out.penetration_m = 0;\n    out.contact = true;\n    ++release_fade_ticks_;' \
                               $T 'HriRecovery.AReleaseByAPlaneUpdate*'

# The point's thin-feature hold (hold_entry_side): each rule alone lets a scan-like ridge wrap
# below 0.9 of the limit; the held plane's point lowered to a face falling away under the
# stroke (short of the middle, the wall as thick as at entry) lets a plate's hold end with no
# release step, and never where the material under the face thins (a crest's corner).
R=test_hri_ridges G='HriRidges.*'
m hri-hold-faces-entry      $H 'if (!entry_held_ && dot(entry_n_, hip - held.p) < 0.0) kept.n = entry_n_;' '' $R "$G"
m hri-hold-stays            $H '!entry_held_ && dot(plane_.n, entry_n_) >= kCos;' 'dot(plane_.n, entry_n_) >= kCos;' $R "$G"
m hri-hold-pressed-round    $H '(entry_held_ || pressed_round ||' '(entry_held_ ||' $R "$G"
# The turn the iteration made is held inside the entry cone too, and a HIP past the middle at
# its deepest since entry_n_ was set holds the side after a stroke took it short of the middle
# (each fails its HriEntrySide case; HriRidges seeds 23/28/29 and 13/17 wrapped at 0.4-0.7).
m hri-hold-carried-in-cone  $H 'if (in_cone && !carried) return;' 'if (in_cone) return;' test_hri_entry_side 'HriEntrySide.*'
m hri-hold-deep-past        $H ' || deep_past()))' '))' test_hri_entry_side 'HriEntrySide.*'
# Inside the cone the carry counts from the proxy the entry plane gave, not from the VHIP of
# the plane before (its step onto a followed face on the engine block's metal held that face
# through the lift: 1001 lift ticks pulled inward, up to 0.90 N).
m hri-hold-carried-from-proxy $H 'const Vec3 proxy_then = in_cone ? entry_proxy_ : entry_vhip_;' 'const Vec3 proxy_then = entry_vhip_;' \
                               isotouch 'ctest:cli_run_engine_lift'
m hri-hold-face-lowered     $H '(!past_middle(field, hip, kept.n, kept_depth, voxel) && as_thick_as_entry(q))' \
                               'false' test_hri_falling_plate 'HriFallingPlate.*'
m hri-hold-face-thick       $H '&& as_thick_as_entry(q))))' ')))' $R "$G"
# The face search's reach: the HIP's depth along the normal kept (entry_n_ after a turn undone),
# not along the held one (a held point to the side: the proxy went up past depth + voxel).
m hri-hold-reach-kept       $H 'face_along(field, hip, kept.n, kept_depth + voxel, voxel, q)' \
                               'face_along(field, hip, kept.n, depth + voxel, voxel, q)' test_hri_entry_side 'HriEntrySide.*'
# The pressed-round rule only on a thin feature (its far face within the depth and two of the
# smallest voxels): on convex bulk material (the sphere's run) it held a 20 deg plane round the
# side and the force turned 60 deg at the lift.
m hri-hold-round-thin       $H 'face_along(field, hip, entry_n_ * -1.0, far_reach, voxel, far_face);' \
                               '(face_along(field, hip, entry_n_ * -1.0, far_reach, voxel, far_face) || true);' \
                               isotouch 'ctest:cli_run_sphere'
# Thin also where the feature is at most twice limit / K thick (its middle within the press the
# limit allows): with two voxels alone, 2-3-voxel ridges on 1 x 1 x 3 mm voxels wrapped at 0.7.
m hri-hold-round-limit      $H 'std::max(depth + 2.0 * voxel, thin_wall - depth)' 'depth + 2.0 * voxel' $R "$G"

# The time-domain passivity controller at the device end of a delayed link (port_passivity)
# and the link the simulation puts in front of it (delayed_link).
P=servo/port_passivity.cpp
m passivity-damping         $P '      f += damp;' '' test_linked_contact 'LinkedContact.*'
# (cli_haptic_igtl_delay, the same line through `run --haptic igtl:` against a PLUS-like peer,
# is not run here: run once, it failed in each of the last two fresh-clone runs on this machine
# (a disturbed press not resting at the window's end; cause not found), though it passed 5 of 5
# in the kept build; it runs in ./run.sh test, where a failure is retried once.)
m passivity-device-clock    $P 'capped ? alpha_max_ / period : excess' 'capped ? alpha_max_ / 1e-3 : excess' \
                               test_port_passivity 'PortPassivity.*'
m passivity-energy-in       $P '    e_in_ += std::max(-w, 0.0);' '' test_port_passivity 'PortPassivity.*'
m passivity-reported-alpha  $P '      alpha_ = per_m * period;' '      alpha_ = per_m * 1e-3;' test_port_passivity 'PortPassivity.*'
m passivity-stalled-clock   $P $'  if (started_) {\n    dx = x - prev_x_;' $'  if (moving) {\n    dx = x - prev_x_;' \
                               test_port_passivity 'PortPassivity.*'
m passivity-infinite-time   $P '!std::isfinite(t)' '!(t == t)' test_port_passivity 'PortPassivity.*'
# The same controller on the servo's live output stage: the gate is given the demand with
# the damping added (a stiff wall above the Colgate bound, through the real servo thread).
m passivity-live-stage      servo/servo_thread.cpp 'rec.force_sent_n = gate_.step(damped, gate_dt, gated);' \
                               'rec.force_sent_n = gate_.step(rec.out.force_n * ramp, gate_dt, gated);' \
                               test_live_passivity 'LivePassivity.*'
m passivity-clip-dissipated $P '    damp = damp * scale;' '' test_port_passivity 'PortPassivity.*'
m passivity-force-limit     $P '  core::require_positive("PortPassivity", "force_limit_n", force_limit_n, "N");' '' \
                               test_port_passivity 'PortPassivity.*'
# The live stage's review rules, judged on what the test-double device received, what
# summary.json holds and what the recording loads (issue 67).
L=servo/live_passivity.cpp S=servo/servo_thread.cpp
m passivity-hold-period     $P '  min_period_s_ = std::max(kMinPeriodS, hold_period_s);' '  min_period_s_ = kMinPeriodS;' \
                               test_live_passivity 'LivePassivity.TheDampingCapIsTakenOverTheHoldPeriod*'
m passivity-clock-zero      $L '  if (device_time_us == 0) return true;  // a reset device, or one without a clock now' '' \
                               test_live_passivity 'LivePassivity.ADeviceClockResetToZero*'
m passivity-clock-jump      $L '  return std::int64_t(step) * 1000 > servo_ns - last_ns_ + kClockJumpNs;' '  return false;' \
                               test_live_passivity 'LivePassivity.ABackwardOrJumpingClock*'
m passivity-reconnect       $S '      if (!first && d.connection != connection) passivity_.restart();  // a new device: no old books' '' \
                               test_live_passivity 'LivePassivity.ABackwardOrJumpingClock*'
m passivity-skipped-ticks   $S '          passivity_.skip(t, d.device_time_us, d.position_m);  // the held force'"'"'s work is booked' '' \
                               test_live_passivity 'LivePassivity.TicksThatSkipTheStage*'
m passivity-nan-tick        $L $'    pc_.observe(t, x_m);\n    return demand_n;' '    return demand_n;' \
                               test_live_passivity 'LivePassivity.TicksThatSkipTheStage*'
m passivity-gate-clamp      servo/force_gate.cpp 'if (m > lim_.peak_n) f = f * (lim_.peak_n / m), m = lim_.peak_n, flags |= kGatePeak;' '' \
                               test_live_passivity 'LivePassivity.TheGateClamps*'
m passivity-not-run         run/run_report.cpp '  if (!stats) return {{"status", "not run"}, {"note", "no servo thread: nothing was observed"}};' '' \
                               test_run_job 'RunJob.LivePassivityWithoutAServoThread*'
m record-held-pt            io/record.cpp '  if (t.held) throw RecordingError(w.at("pt") + ": a held tick has no passivity stage, got " + num(pt) + " s");' '' \
                               test_record 'Record.PassivityClock*'
m link-delay                sim/delayed_link.h 'one_way_s_(0.5 * p.round_trip_delay_s)' 'one_way_s_(0.0)' \
                               test_linked_contact 'DelayLine.*:LinkedContact.*'
m link-arrival-slack        sim/delayed_link.h 'arrive_s <= t_s + kArrivalSlackS' 'arrive_s <= t_s' \
                               test_linked_contact 'DelayLine.*:LinkedContact.*'
m link-whole-ticks          sim/linked_contact.cpp 'whole >= 1 && std::abs(ticks - whole) <= 1e-9 * whole' 'whole >= 1' \
                               test_linked_contact 'DelayLine.*:LinkedContact.*'
# A link's stiffness bound (sim::link_k_max): the search with the device end's controller, at
# the measured rate as it is; the igtl check takes the bound with it only when the peer runs it,
# and refuses above the bound.
m link-kmax-controller      sim/linked_contact.cpp '    base.passivity_controller = pc;' '    base.passivity_controller = false;' \
                               test_linked_contact 'LinkKMax.*'
m link-kmax-measured-rate   sim/linked_contact.cpp '    base.device_period_s = period / std::max(1.0, std::round(period / 1e-3));' '    (void)0;' \
                               test_linked_contact 'LinkKMax.*'
m igtl-link-bound-peer-pc   service/igtl_device.cpp \
                               'j.limit_n_per_m = loop.peer_passivity_control ? j.bound.k_max_with_pc_n_per_m : j.bound.k_max_n_per_m;' \
                               'j.limit_n_per_m = j.bound.k_max_with_pc_n_per_m;' test_igtl_device 'ServiceIgtlDevice.TheStiffnessBound*'
m igtl-link-bound-refused   service/igtl_device.cpp 'j.over = loop.stiffness_n_per_m > j.limit_n_per_m;' 'j.over = false;' \
                               test_igtl_device 'ServiceIgtlDevice.TheStiffnessBound*'

# Per-material drilling: a critical structure is never removed, and each material takes its own rate.
C=session/brush_cpu.cpp
m cut-critical-never-removed $C 'if (cc.critical[mat]) continue;  // a critical structure is never changed' '' \
                               test_material_cut 'MaterialCut.*'
m cut-material-rate          $C 'if (b.kind == BrushKind::kDrill && m.rate >= 0) c.amount[i] = float(m.rate * b.dt_s * excess);' '' \
                               test_material_cut 'MaterialCut.*'
# A v1 device's report rate bounds the servo's; a scene over a device's stiffness is refused.
m v1-output-rate             servo/device_protocols.cpp 'caps.output_rate_hz = caps.native_rate_hz;' '' \
                               test_device_emu 'DeviceEmu.AServoFasterThanTheDeclaredReportRateIsRefused'
m check-caps-stiffness       run/haptic_device.cpp \
  'over("servo.stiffness_n_per_m", hri.stiffness_n_per_m, "maximum stiffness", caps.max_stiffness_n_per_m);' '' \
                               test_device_refusals 'DeviceRefusals.*'
m cut-material-density-scale $C 'if (m.density_scale > 0) c.inv_dens[i] = float(1.0 / m.density_scale);' '' \
                               test_material_cut 'MaterialCut.*'
# The distance transform takes each axis's own spacing (an oblique shape on three spacings).
m cut-edt-axis-spacing       materials/critical_distance.cpp 'envelope_1d(&sq[k * sz + j * sy], nx, sx, grid.spacing_m.x, f, v, z)' \
                               'envelope_1d(&sq[k * sz + j * sy], nx, sx, grid.spacing_m.y, f, v, z)' \
                               test_material_cut 'MaterialCut.*'
# The margin warning watches the brush that cuts each tick (a timeline brush's own centre and radius).
m cut-margin-cutting-brush   run/edit_driver.cpp 'if (removes(b)) cutters_.push_back({b.centre_m, b.radius_m});' '' \
                               test_material_margin_run 'MaterialMarginRun.*'
# Each critical material has its own distance field (not the union of them all).
m cut-margin-per-material    run/scene_setup.cpp 'only[i + 1] = true;' \
                               'for (std::size_t j = 0; j < lv.materials.size(); ++j) only[j + 1] = lv.materials[j].critical;' \
                               test_material_margin_run 'MaterialMarginRun.*'
# The run log promises the margin warning only where it runs (with edits).
m cut-margin-log-with-edits  run/scene_setup.cpp 'if (!s.critical.empty() && scene.edits.present)' 'if (!s.critical.empty())' \
                               test_material_margin_run 'MaterialMarginRun.*'
# serve's label map (issue 66): on the session volume's grid, every value named by its LBMETA,
# the LBMETA's values kept, a scene material of the same name lending its fields.
L=service/label_map.cpp
m label-map-origin           $L 'if (!(std::abs(lo - fo) <= kLabelOriginTolerance * smallest))' 'if (false)' \
                               test_serve_labels 'ServeLabels.*'
m label-map-unknown-value    $L ' && (v == 0.f || table[std::size_t(v)] != 0);' ';' \
                               test_serve_labels 'ServeLabels.*'
m label-map-scene-fields     $L '      m = *same;' '' test_serve_labels 'ServeLabels.*'
m label-meta-value           service/igtl_message.cpp '      entry.label = int(e->GetLabel());' '' \
                               test_serve_labels 'ServeLabels.*'
# ... and serve's drill then cuts by it: the client's critical bone is never carved.
m serve-label-map-cut        service/serve.cpp '    s->parts->edits().sculptor().set_material_cut(run::material_cut(*p.labels));' '' \
                               'isotouch igtl_session_client' 'ctest:cli_serve_labels'

# ---- The run ----
work=$root/build-mutants
copy=$work/src
cleanup() { [ "$keep" = 1 ] || rm -rf "$work"; }
trap cleanup EXIT
trap 'echo "interrupted"; exit 130' INT TERM HUP
mkdir -p "$copy"
# The working tree as it is (deleted files left out), over whatever an older kept copy held:
# only the files whose content differs are copied, stamped now, so that an object built from a
# mutated file of a kept copy is rebuilt (the tree's own older time stamp would hide it).
git -C "$root" ls-files -z -co --exclude-standard | python3 -c '
import filecmp, os, shutil, sys
root, copy = sys.argv[1:3]
for f in sys.stdin.buffer.read().decode().split("\0"):
    src, dst = os.path.join(root, f), os.path.join(copy, f)
    if not f or not os.path.isfile(src) or (os.path.isfile(dst) and filecmp.cmp(src, dst, shallow=False)):
        continue
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    shutil.copy(src, dst)
' "$root" "$copy" || { echo "ERROR: cannot copy the tree"; exit 2; }

export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$root}  # the copy's files hit the tree's cache entries
export CMAKE_CXX_COMPILER_LAUNCHER=${CMAKE_CXX_COMPILER_LAUNCHER:-ccache}
export CMAKE_C_COMPILER_LAUNCHER=${CMAKE_C_COMPILER_LAUNCHER:-ccache}
jobs=${MUTANTS_JOBS:-2}
(cd "$copy" && cmake --preset release > "$work/configure.log" 2>&1) ||
  { tail -20 "$work/configure.log"; echo "ERROR: configure failed"; exit 2; }

selected=()
for i in "${!names[@]}"; do
  if [ -n "$shard" ] && [ $((i % ${shard#*/})) != "${shard%/*}" ]; then continue; fi
  [ -z "$only" ] || echo "${names[$i]}" | grep -qE "$only" && selected+=("$i")
done
[ "${#selected[@]}" -gt 0 ] || { echo "no mutation matches '$only'${shard:+ in shard $shard}"; exit 2; }
[ -z "$shard" ] || echo "shard $shard of ${#names[@]} mutations: $(for i in "${selected[@]}"; do printf '%s ' "${names[$i]}"; done)"

# apply WHERE OLD [NEW]: the one file under WHERE holding OLD exactly once, relative to the
# copy, on stdout (else the reason on stderr, exit 1); with NEW, OLD replaced by NEW there.
apply() {
  python3 - "$copy" "$@" <<'EOF'
import os, sys
copy, where, old = sys.argv[1:4]
new = sys.argv[4] if len(sys.argv) > 4 else None
base = os.path.join(copy, where)
files = [base] if os.path.isfile(base) else [
    os.path.join(d, f) for d, _, fs in os.walk(base) for f in sorted(fs) if f.endswith((".cpp", ".h"))]
hits = [(f, open(f).read()) for f in files]
hits = [(f, s) for f, s in hits if old in s]
if len(hits) != 1 or hits[0][1].count(old) != 1:
    where_found = ", ".join(f"{os.path.relpath(f, copy)} x{s.count(old)}" for f, s in hits) or "nowhere"
    sys.exit(f"the text occurs in {where_found} under {where}, not exactly once")
f, s = hits[0]
if new is not None:
    open(f, "w").write(s.replace(old, new))
print(os.path.relpath(f, copy))
EOF
}

# shellcheck disable=SC2086
build() { (cd "$copy" && cmake --build --preset release -j"$jobs" --target $1) > "$work/build.log" 2>&1; }
# Runs TARGET's tests with FILTER (5 minutes at most); the failing tests' names on stdout.
run_test() {
  if [[ $2 == ctest:* ]]; then
    timeout 300 ctest --test-dir "$copy/build" -R "^${2#ctest:}\$" --output-on-failure > "$work/test.log" 2>&1
    local rc=$?
    grep -q "tests passed, 0 tests failed out of 1" "$work/test.log" && return 0
    echo "${2#ctest:}"
    return $(( rc ? rc : 1 ))
  fi
  timeout 300 "$copy/build/bin/$1" --gtest_filter="$2" > "$work/test.log" 2>&1
  local rc=$?
  sed -n 's/^\[  FAILED  \] \([A-Za-z0-9_]*\.[A-Za-z0-9_./]*\).*/\1/p' "$work/test.log" | sort -u | tr '\n' ' '
  [ "$rc" = 124 ] && echo "(timed out)"
  return $rc
}

# The unmutated copy: every target builds and every test passes.
declare -A seen=()
for i in "${selected[@]}"; do
  key="${targets[$i]} ${filters[$i]}"
  [ -n "${seen[$key]:-}" ] && continue
  seen[$key]=1
  build "${targets[$i]}" || { tail -30 "$work/build.log"; echo "ERROR: ${targets[$i]} does not build unmutated"; exit 2; }
  failed=$(run_test "${targets[$i]}" "${filters[$i]}") ||
    { tail -30 "$work/test.log"; echo "ERROR: ${targets[$i]} --gtest_filter='${filters[$i]}' fails unmutated: $failed"; exit 2; }
done
echo "unmutated: ${#seen[@]} test runs pass; ${#selected[@]} mutations"

killed=0 survived=0 errors=0 flaky=0
for i in "${selected[@]}"; do
  name=${names[$i]} target=${targets[$i]} filter=${filters[$i]}
  tmp=$work/pristine
  # Where the text is, before touching it (the copy's file is restored from this).
  if ! file=$(apply "${wheres[$i]}" "${olds[$i]}" 2> "$work/apply.log"); then
    printf '%-9s %-26s %s\n' ERROR "$name" "$(cat "$work/apply.log")"; errors=$((errors + 1)); continue
  fi
  cp -p "$copy/$file" "$tmp"
  apply "${wheres[$i]}" "${olds[$i]}" "${news[$i]}" > /dev/null 2>&1
  if ! build "$target"; then
    printf '%-9s %-26s %s\n' ERROR "$name" "$file: the mutant does not build (see $work/build.log)"
    errors=$((errors + 1))
  elif failed=$(run_test "$target" "$filter"); then
    printf '%-9s %-26s %s\n' SURVIVED "$name" "$file: $target --gtest_filter='$filter' passes"
    survived=$((survived + 1))
  elif run_test "$target" "$filter" > /dev/null; then  # the second run must fail too
    printf '%-9s %-26s %s\n' FLAKY "$name" "$file: $target failed once ($failed), then passed"
    flaky=$((flaky + 1))
  else
    printf '%-9s %-26s %s\n' KILLED "$name" "$file: $target: $failed"
    killed=$((killed + 1))
  fi
  cp -p "$tmp" "$copy/$file"
  touch "$copy/$file"  # rebuilt unmutated next time (ccache: from the cache)
done
echo "$((killed + survived + flaky + errors)) mutations: $killed killed, $survived survived, $flaky flaky, $errors errors"
[ "$errors" = 0 ] || exit 2
[ "$survived" = 0 ] && [ "$flaky" = 0 ] || exit 1
exit 0
