#!/usr/bin/env bash
# `isotouch run SCENE --live --haptic openhaptics|forcedimension` against the test doubles of
# libHD.so and libdhd.so (ISOTOUCH_HD_LIBRARY / ISOTOUCH_DHD_LIBRARY), whose device follows the
# scene's scripted hand (run --hand-path):
#  1. the live run feels the skull (ticks with force, exit 0), and the forces the double
#     RECEIVED, in its SDK's units and frame, are the servo's (compare_forces.py);
#  2. the double's device vanishes at 1.5 s: every force after the first frame that found it
#     gone is an exact zero, the run counts disconnected ticks, names the SDK's error, exits 5;
#  4. `isotouch devices --check openhaptics` (below 3): "n" renders nothing (every force the
#     double received is zero); "y" renders the soft wall: the double, pushed down by its
#     hand, receives forces up (HD +y) of at most 1 N, then an exact zero;
#  3. without the SDK: one clear message naming what was searched, exit 1; `isotouch devices`
#     says found / not found with the override variable, and the devices the doubles show.
# usage: cli_run_live_sdk.sh ISOTOUCH SCENE HD_DOUBLE DHD_DOUBLE COMPARE_PY OUT
set -u
exe=$1 scene=$2 hd=$3 dhd=$4 compare=$5 out=$6
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
"$exe" run "$scene" --hand-path "$out/hand.csv" > "$out/path.log" 2>&1 || { cat "$out/path.log"; fail "--hand-path"; }

# kind PREFIX LIBVAR LIB FRAME ERROR: one kind, steps 1 and 2.
check_kind() {
  local kind=$1 prefix=$2 libvar=$3 lib=$4 frame=$5 error=$6
  env "$libvar=$lib" "${prefix}_PATH=$out/hand.csv" "${prefix}_LOG=$out/$kind.csv" \
    "$exe" run "$scene" --live --haptic "$kind" --record "$out/$kind.rec" --quiet > "$out/$kind.log" 2>&1; rc=$?
  cat "$out/$kind.log"
  [ "$rc" -eq 0 ] || fail "$kind: run --live exited $rc"
  line=$(grep '^device .*ticks with force' "$out/$kind.log") || fail "$kind: no device summary"
  forced=$(echo "$line" | sed -E 's/.*: ([0-9]+) ticks with force.*/\1/')
  fmax=$(echo "$line" | sed -E 's/.*max \|F\| ([0-9.]+) N.*/\1/')
  [ "$forced" -ge 300 ] || fail "$kind: only $forced ticks with force: the skull was not felt"
  awk -v f="$fmax" 'BEGIN { exit !(f > 0.5 && f <= 3.3) }' || fail "$kind: max |F| $fmax N"
  python3 "$compare" "$out/$kind.csv" "$out/$kind.rec" "$frame" "$fmax" || fail "$kind: the double did not receive the servo's forces"

  env "$libvar=$lib" "${prefix}_PATH=$out/hand.csv" "${prefix}_LOG=$out/${kind}_gone.csv" "${prefix}_VANISH_AT=1.5" \
    "$exe" run "$scene" --live --haptic "$kind" --quiet > "$out/${kind}_gone.log" 2>&1; rc=$?
  cat "$out/${kind}_gone.log"
  [ "$rc" -eq 5 ] || fail "$kind: a vanished device: exit $rc, expected 5"
  grep -Eq "disconnected [1-9][0-9]*," "$out/${kind}_gone.log" || fail "$kind: no disconnected ticks counted"
  grep -q "$error" "$out/${kind}_gone.log" || fail "$kind: the SDK's error ($error) is not named"
  awk -F, 'NR > 1 && $6 == 1 { n++; if (n > 1 && ($2 != 0 || $3 != 0 || $4 != 0)) bad++ }
           END { print n + 0, "forces sent to the vanished device,", bad + 0, "not zero after the first"; exit !(n > 100 && bad == 0) }' \
    "$out/${kind}_gone.csv" || fail "$kind: force after the device vanished"
}
check_kind openhaptics HD_DOUBLE ISOTOUCH_HD_LIBRARY "$hd" hd "HD_COMM_ERROR"
check_kind forcedimension DHD_DOUBLE ISOTOUCH_DHD_LIBRARY "$dhd" fd "dhdGetPosition failed: communication error"

# 3. Without the SDK.
ISOTOUCH_HD_LIBRARY=/nonexistent/libHD.so "$exe" run "$scene" --live --haptic openhaptics --quiet > "$out/nosdk.log" 2>&1; rc=$?
cat "$out/nosdk.log"
[ "$rc" -eq 1 ] || fail "openhaptics without the SDK: exit $rc, expected 1"
[ "$(grep -c 'error' "$out/nosdk.log")" -eq 1 ] || fail "not one error line"
grep -q 'OpenHaptics HD library not found (searched: \$ISOTOUCH_HD_LIBRARY=/nonexistent/libHD.so; /nonexistent/libHD.so: ' "$out/nosdk.log" ||
  fail "the message does not name what was searched"
env -u ISOTOUCH_HD_LIBRARY "$exe" run "$scene" --live --haptic openhaptics --quiet > "$out/nosdk2.log" 2>&1; rc=$?
if [ "$rc" -eq 1 ]; then
  grep -q 'searched: \$ISOTOUCH_HD_LIBRARY unset; libHD.so: ' "$out/nosdk2.log" || fail "the default search is not named"
fi
"$exe" run "$scene" --live --haptic "forcedimension:x" > "$out/bad.log" 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q "the index 'x' is not a device number" "$out/bad.log" || { cat "$out/bad.log"; fail "bad index: exit $rc"; }
ISOTOUCH_HD_LIBRARY=/nonexistent/libHD.so ISOTOUCH_DHD_LIBRARY=/nonexistent/libdhd.so "$exe" devices > "$out/devices.log" 2>&1
cat "$out/devices.log"
[ "$(grep -c 'SDK not found (searched: \$ISOTOUCH_D\?HD_LIBRARY=/nonexistent/' "$out/devices.log")" -eq 2 ] || fail "devices: not found for both SDKs"
ISOTOUCH_HD_LIBRARY=$hd ISOTOUCH_DHD_LIBRARY=$dhd "$exe" devices > "$out/devices2.log" 2>&1
cat "$out/devices2.log"
grep -q "override: ISOTOUCH_HD_LIBRARY" "$out/devices2.log" && grep -q "override: ISOTOUCH_DHD_LIBRARY" "$out/devices2.log" || fail "devices: override variables not named"
grep -q "default device: PHANToM (test double), serial DOUBLE-1" "$out/devices2.log" || fail "devices: the HD double's device not listed"
grep -q "0: delta.3 (system type 63)" "$out/devices2.log" || fail "devices: the dhd double's device not listed"
# 4. devices --check: a hand that rests 1.2 s, then goes 40 mm down over 1.5 s (device frame).
awk 'BEGIN { print "t_s,x_m,y_m,z_m"; for (k = 0; k <= 4000; k++) { t = k / 1000; z = t < 1.2 ? 0 : (t < 2.7 ? -0.04 * (t - 1.2) / 1.5 : -0.04); printf "%.3f,0,0,%.6f\n", t, z } }' > "$out/down.csv"
echo n | ISOTOUCH_HD_LIBRARY=$hd HD_DOUBLE_PATH=$out/down.csv HD_DOUBLE_LOG=$out/check_n.csv \
  "$exe" devices --check openhaptics --seconds 1 > "$out/check_n.log" 2>&1; rc=$?
cat "$out/check_n.log"
[ "$rc" -eq 0 ] && grep -q "no force rendered" "$out/check_n.log" || fail "check, answered n: exit $rc"
grep -q "pose (0.0, 0.0, 0.0) mm" "$out/check_n.log" || fail "check: the resting pose is not printed"
awk -F, 'NR > 1 && ($2 != 0 || $3 != 0 || $4 != 0) { bad++ } END { exit bad > 0 }' "$out/check_n.csv" || fail "check, answered n: a force was sent"
echo y | ISOTOUCH_HD_LIBRARY=$hd HD_DOUBLE_PATH=$out/down.csv HD_DOUBLE_LOG=$out/check_y.csv \
  "$exe" devices --check openhaptics --seconds 1 --wall-seconds 2.5 > "$out/check_y.log" 2>&1; rc=$?
cat "$out/check_y.log"
[ "$rc" -eq 0 ] && grep -q "^wall " "$out/check_y.log" || fail "check, answered y: exit $rc"
awk -F, 'NR > 1 { if ($2 != 0 || $4 != 0 || $3 < 0 || $3 > 1.0 + 1e-9) bad++; if ($3 > max) max = $3; if ($1 < 1.0 && $3 != 0) early++; last = $3 }
         END { print "wall: max", max, "N up, bad", bad + 0, "early", early + 0, "last", last; exit !(bad == 0 && early == 0 && max > 0.5 && last == 0) }' \
  "$out/check_y.csv" || fail "check, answered y: the wall's forces (up only, <= 1 N, none while reading, zero at the end)"
echo "PASS run --live --haptic openhaptics, forcedimension"
