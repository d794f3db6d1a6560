#!/usr/bin/env bash
# `isotouch run SCENE --live --haptic emu:SOCKET` against an isotouch-devemu process:
#  1. the emulator's hand plays the scene's scripted hand (run --hand-path): the live run
#     feels the skull (ticks with force, a force of the order of the simulated run's), no
#     disconnect, fault or refused report, exit 0; the emulator received the forces;
#  2. the emulator SIGKILLed mid-run: the run reports disconnected ticks and exits 5;
#     the emulator closing its link and listening again 0.3 s later, with --record: the
#     recording holds the outage's ticks (held) and the renderer's reset after it, and
#     replays IDENTICAL (a replay that ticked through the outage or did not reset differs);
#  3. bad --haptic specs: a clear message and exit 1; the Polhem's ID (mbed's default) is
#     refused unless the user names it (--haptic polhem:...);
#  4. isotouch-devemu --polhem (a polhem_v3 or polhem_v1 unit) driven by --haptic
#     polhem:emu:SOCKET[,config=v1|v3]: its own configuration (v3 by default, as upstream's
#     USB example) feels the skull, says which kinematics and their source; the other one
#     is faulted (exit 5) with no current reaching the unit and names the right config.
# usage: cli_run_live_emu.sh ISOTOUCH DEVEMU SCENE OUT
set -u
exe=$1 emu=$2 scene=$3 out=$4
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
sock=$out/dev.sock

"$exe" run "$scene" --hand-path "$out/hand.csv" > "$out/path.log" 2>&1; rc=$?
[ "$rc" -eq 0 ] || { cat "$out/path.log"; fail "--hand-path exited $rc"; }
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 20 > "$out/emu.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
"$exe" run "$scene" --live --haptic "emu:$sock" --quiet > "$out/run.log" 2>&1; rc=$?
cat "$out/run.log"
kill -TERM "$emu_pid"; wait "$emu_pid"
cat "$out/emu.log"
[ "$rc" -eq 0 ] || fail "run --live --haptic emu exited $rc"
line=$(grep '^device .*ticks with force' "$out/run.log") || fail "no device summary"
forced=$(echo "$line" | sed -E 's/.*: ([0-9]+) ticks with force.*/\1/')
fmax=$(echo "$line" | sed -E 's/.*max \|F\| ([0-9.]+) N.*/\1/')
[ "$forced" -ge 300 ] || fail "only $forced ticks with force: the skull was not felt"
# Felt (well above zero) and never beyond the device limit of the scene (3.3 N); a loaded
# machine that stalls the servo lets the hand push deeper, up to the clamp.
awk -v f="$fmax" 'BEGIN { exit !(f > 0.5 && f <= 3.3) }' || fail "max |F| $fmax N: not felt, or beyond the 3.3 N limit"
echo "$line" | grep -q "disconnected 0, fault 0, refused 0" || fail "device faults in a clean run"
grep -q "outputs received" "$out/emu.log" || fail "the emulator printed no summary"

# 2. The emulator killed mid-run: zero force, counted, exit 5.
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 20 > "$out/emu2.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
( sleep 1.5; kill -KILL "$emu_pid" ) &
"$exe" run "$scene" --live --haptic "emu:$sock" --quiet > "$out/run2.log" 2>&1; rc=$?
wait
cat "$out/run2.log"
[ "$rc" -eq 5 ] || fail "a killed emulator: exit $rc, expected 5"
grep -Eq "disconnected [1-9][0-9]*," "$out/run2.log" || fail "no disconnected ticks counted"
grep -q "link down" "$out/run2.log" || fail "the log does not say the link went down"

# 2b. An outage and a reconnection, recorded and replayed. The outage's times count from the
# run's connection: the run's start-up (1.2 s and more on one loaded core) is not in them.
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 20 --disconnect-at 1.2 --reconnect-after 0.3 --faults-from-connection \
  > "$out/emu3.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
"$exe" run "$scene" --live --haptic "emu:$sock" --record "$out/outage.rec" --quiet > "$out/run3.log" 2>&1; rc=$?
kill -TERM "$emu_pid" 2>/dev/null; wait "$emu_pid"
cat "$out/run3.log"
grep -q "1 reconnects" "$out/run3.log" || fail "the link did not come back after the emulator's outage"
[ -f "$out/outage.rec" ] || fail "no recording of the outage run (exit $rc)"
held=$(grep -c '"held":true' "$out/outage.rec"); resets=$(grep -c '"reset":true' "$out/outage.rec")
[ "$held" -ge 100 ] || fail "only $held held ticks recorded across a 0.3 s outage"
[ "$resets" -ge 1 ] || fail "no renderer reset recorded after the outage"
"$exe" replay "$out/outage.rec" --quiet > "$out/replay3.log" 2>&1; rc=$?
cat "$out/replay3.log"
[ "$rc" -eq 0 ] && grep -q "^IDENTICAL" "$out/replay3.log" || fail "the outage recording does not replay identically (exit $rc)"

# 3. Bad specs.
"$exe" run "$scene" --live --haptic "bogus:1" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "unknown kind 'bogus'" "$out/bad.log" || { cat "$out/bad.log"; fail "bogus kind: exit $rc"; }
"$exe" run "$scene" --live --haptic "emu:$out/none.sock" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "none.sock: cannot connect" "$out/bad.log" || { cat "$out/bad.log"; fail "missing socket: exit $rc"; }
"$exe" run "$scene" --live --haptic "hid:zz:1" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "vendor ID 'zz' is not a hex USB ID" "$out/bad.log" || { cat "$out/bad.log"; fail "bad hid spec: exit $rc"; }
# The Polhem's ID is mbed's default: refused unless named; named, it is opened as a Polhem.
"$exe" run "$scene" --live --haptic "hid:1234:0006" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "1234:0006 is the mbed HID library's default USB ID.*--haptic polhem:1234:0006" "$out/bad.log" ||
  { cat "$out/bad.log"; fail "hid:1234:0006 not refused: exit $rc"; }
"$exe" run "$scene" --live --haptic "polhem:1234:0006" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "hid:1234:0006: cannot open the HID device" "$out/bad.log" ||
  { cat "$out/bad.log"; fail "polhem:1234:0006 without a device: exit $rc"; }
"$exe" run "$scene" --live --haptic "polhem:emu:$sock,config=v2" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "config 'v2' is neither v1 nor v3" "$out/bad.log" || { cat "$out/bad.log"; fail "config=v2: exit $rc"; }
"$emu" --socket "$sock" --polhem --polhem-config v2 > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 2 ] || { cat "$out/bad.log"; fail "isotouch-devemu --polhem-config v2: exit $rc, expected 2"; }

# 4. The Polhem over the emulator. polhem_run UNIT SPEC_OPTIONS NAME: the emulator's unit
# of configuration UNIT (v1, v3) plays the scene's hand; the run's exit status is echoed.
polhem_run() {
  "$emu" --socket "$sock" --polhem --polhem-config "$1" --path "$out/hand.csv" --seconds 20 > "$out/emu_$3.log" 2>&1 &
  local pid=$!
  for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
  "$exe" run "$scene" --live --haptic "polhem:emu:$sock$2" --quiet > "$out/run_$3.log" 2>&1; local rc=$?
  kill -TERM "$pid"; wait "$pid"
  cat "$out/run_$3.log" "$out/emu_$3.log" >&2
  echo "$rc"
}
source_line="forsslund/hfabapi @aadabaa82ce9 (2023-04-05)"
for unit in v3 v1; do
  spec=""; [ "$unit" = v1 ] && spec=",config=v1"
  rc=$(polhem_run "$unit" "$spec" "$unit")
  [ "$rc" -eq 0 ] || fail "a polhem_$unit unit driven as one: exit $rc"
  log=$out/run_$unit.log
  grep -q "kinematics polhem_$unit.*from $source_line" "$log" || fail "polhem_$unit: the active kinematics and their source are not printed"
  [ "$unit" = v1 ] || grep -q "kinematics polhem_v3 (the default" "$log" || fail "v3 is not the default"
  line=$(grep '^device .*ticks with force' "$log") || fail "polhem_$unit: no device summary"
  forced=$(echo "$line" | sed -E 's/.*: ([0-9]+) ticks with force.*/\1/')
  [ "$forced" -ge 300 ] || fail "polhem_$unit: only $forced ticks with force: the skull was not felt"
  echo "$line" | grep -q "disconnected 0, fault 0, refused 0" || fail "polhem_$unit: device faults in a clean run"
  grep -q "Polhem: [1-9][0-9]* calibration commands (0 lost), calibrated" "$out/emu_$unit.log" || fail "polhem_$unit: not calibrated"
  fmax=$(sed -nE 's/.*max \|F\| ([0-9.e+-]+) N$/\1/p' "$out/emu_$unit.log")
  awk -v f="$fmax" 'BEGIN { exit !(f > 0.5) }' || fail "polhem_$unit: the unit made $fmax N of the currents it received"
done
for unit in v3 v1; do
  host=v1; [ "$unit" = v1 ] && host=v3
  rc=$(polhem_run "$unit" ",config=$host" "mismatch_$unit")
  log=$out/run_mismatch_$unit.log
  [ "$rc" -eq 5 ] || fail "a polhem_$unit unit driven as polhem_$host: exit $rc, expected 5"
  grep -q "the unit is not a polhem_$host (a polhem_$unit? --haptic polhem:...,config=$unit)" "$log" ||
    fail "a polhem_$unit unit driven as polhem_$host: the mismatch is not named"
  grep -q "max |F| 0 N$" "$out/emu_mismatch_$unit.log" || fail "a polhem_$unit unit driven as polhem_$host received current"
done
# `isotouch devices --check` of a v3 unit as polhem_v1: the pose is refused and the check says why.
"$emu" --socket "$sock" --polhem --hold 0,0,0 --seconds 20 > "$out/emu_check.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
echo n | "$exe" devices --check "polhem:emu:$sock,config=v1" --seconds 0.5 > "$out/check.log" 2>&1; rc=$?
kill -TERM "$emu_pid"; wait "$emu_pid"
cat "$out/check.log"
[ "$rc" -eq 1 ] && grep -q "^check: .*the unit is not a polhem_v1 (a polhem_v3? --haptic polhem:...,config=v3)" "$out/check.log" ||
  fail "devices --check of a v3 unit as polhem_v1: exit $rc, or the reason is not given"
# 5. A v1 device whose capabilities declare no watchdog (0 ms: its last force stays on if
# isotouch stops sending) is refused, naming the field that drives it anyway; with that field
# the same device is driven.
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 20 --watchdog-ms 0 > "$out/emu_nowd.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
"$exe" run "$scene" --live --haptic "emu:$sock" --quiet > "$out/run_nowd.log" 2>&1; rc=$?
cat "$out/run_nowd.log"
[ "$rc" -ne 0 ] || fail "a device without a watchdog was driven (exit 0)"
grep -q "has no watchdog (0 ms in its capabilities).*refused (the scene's device.allow_no_watchdog: true drives it anyway)" \
  "$out/run_nowd.log" || fail "the refusal of a device without a watchdog does not name device.allow_no_watchdog"
kill -TERM "$emu_pid"; wait "$emu_pid"
grep -q "max |F| 0 N" "$out/emu_nowd.log" || fail "a refused device received force"
python3 - "$scene" "$out/allow_nowd.json" <<'PY'
import json, os, sys
s = json.load(open(sys.argv[1]))
base = os.path.dirname(os.path.abspath(sys.argv[1]))
v = s["volume"]
if "path" in v and not os.path.isabs(v["path"]): v["path"] = os.path.join(base, v["path"])
s.setdefault("device", {})["allow_no_watchdog"] = True
json.dump(s, open(sys.argv[2], "w"))
PY
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 20 --watchdog-ms 0 > "$out/emu_allow.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
"$exe" run "$out/allow_nowd.json" --live --haptic "emu:$sock" --quiet --out "$out/allow_nowd" > "$out/run_allow.log" 2>&1; rc=$?
kill -TERM "$emu_pid"; wait "$emu_pid"
cat "$out/run_allow.log"
[ "$rc" -eq 0 ] || fail "device.allow_no_watchdog: true, the device was still refused (exit $rc)"
# 6. `devices --check`'s safety drill on the v1 emulator (a device with a writer thread): the
# step held to the rate limit, the stall taking the force off and the ramp back, each "held".
"$emu" --socket "$sock" --hold 0,0,0 --seconds 20 > "$out/emu_drill.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
printf 'y\ny\n' | "$exe" devices --check "emu:$sock" --seconds 0.3 --wall-seconds 0.3 > "$out/drill.log" 2>&1; rc=$?
kill -TERM "$emu_pid"; wait "$emu_pid"
cat "$out/drill.log"
[ "$rc" -eq 0 ] || fail "devices --check's safety drill exited $rc"
[ "$(grep -c '^drill .*: held$' "$out/drill.log")" -eq 3 ] || fail "the safety drill did not print three rules held"
grep -Eq "^drill .*the device took the force off \([1-9][0-9]* stall\(s\)\)" "$out/drill.log" || fail "the drill's stall did not take the force off"
echo "PASS run --live --haptic emu"
