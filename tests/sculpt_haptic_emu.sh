#!/usr/bin/env bash
# isotouch-sculpt --haptic emu:SOCKET under Xvfb: the window's probe is an isotouch-devemu
# process playing the head scene's scripted hand (isotouch run --hand-path), so the person's
# hand is the emulator's. Checks: the window opened the device (its line in the log), the
# emulator received forces and felt the skull (its max |F| of the order of the simulated
# run's 2 N), no disconnected, fault or refused tick; a bad spec or a missing socket: exit 1.
# Usage: sculpt_haptic_emu.sh SCULPT_BIN ISOTOUCH_BIN DEVEMU_BIN SOURCE_DIR OUT_DIR. Exit 77 without xvfb-run.
set -u
bin=$1 iso=$2 emu=$3 src=$4 out=$5
fail() { echo "FAIL: $*"; exit 1; }
command -v xvfb-run >/dev/null || { echo "SKIP: xvfb-run is not installed"; exit 77; }
rm -rf "$out"; mkdir -p "$out"
sock=$out/dev.sock
scene=$src/scenes/head.json

# The app's own exit code, written by the shell xvfb-run starts: xvfb-run itself may exit 5
# when its clean-up races a client that quits at once ("problem while cleaning up").
app_rc() { sed -n 's/^app exit \([0-9]*\)$/\1/p' "$1"; }
xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --haptic sim > "$out/bad.log" 2>&1; rc=$(app_rc "$out/bad.log")
[ "$rc" = 1 ] && grep -q "sim needs the scene's scripted hand" "$out/bad.log" || { cat "$out/bad.log"; fail "--haptic sim: exit $rc"; }
xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --haptic "emu:$out/none.sock" > "$out/bad.log" 2>&1
rc=$(app_rc "$out/bad.log")
[ "$rc" = 1 ] && grep -q "none.sock: cannot connect" "$out/bad.log" || { cat "$out/bad.log"; fail "missing socket: exit $rc"; }

"$iso" run "$scene" --hand-path "$out/hand.csv" > "$out/path.log" 2>&1 || { cat "$out/path.log"; fail "--hand-path failed"; }
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 120 > "$out/emu.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
# The hand reaches the skull 0.6 s into its path and pushes past 0.5 N 0.1 s later (the
# simulated run): the window runs until the probe is in contact, then 200 frames more (a
# frame is 3-300 ms here: 0.6-60 s), not a fixed number of frames from the start.
xvfb-run -a -s "-screen 0 640x480x24" "$bin" "$scene" --haptic "emu:$sock" --script "$src/tests/sculpt/haptic-emu.json" \
  --size 256 --stats > "$out/sculpt.log" 2>&1; rc=$?
kill -TERM "$emu_pid" 2>/dev/null; wait "$emu_pid"
cat "$out/sculpt.log" "$out/emu.log"
[ "$rc" -eq 0 ] || fail "isotouch-sculpt --haptic emu exited $rc"
grep -q "^device   emu:$sock" "$out/sculpt.log" || fail "the window did not report the device"
grep -q "wait for contact timed out" "$out/sculpt.log" && fail "the probe never touched the skull"
grep -Eq "^device   .*disconnected 0, fault 0, refused 0" "$out/sculpt.log" || fail "device faults in a clean run"
grep -Eq "^link     [1-9][0-9]* reports" "$out/sculpt.log" || fail "no input reports read"
fmax=$(sed -nE 's/.*max \|F\| ([0-9.e+-]+) N.*/\1/p' "$out/emu.log")
[ -n "$fmax" ] || fail "the emulator printed no max force"
# Felt through the window, and never beyond the scene's 3.3 N force limit (plus the
# protocol's fixed-point rounding): a stalled servo lets the hand push in up to the clamp.
awk -v f="$fmax" 'BEGIN { exit !(f > 0.5 && f <= 3.31) }' || fail "the emulator's max |F| $fmax N: not felt through the window, or beyond the 3.3 N limit"
# The servo's passivity stage, as the stats panel shows it (servo::describe): the hand that
# pressed the skull put energy into the port.
pin=$(sed -n 's/^stats    passivity [a-z ]* ([a-z]* clock): in \([-0-9.e+]*\) mJ, out [-0-9.e+]* mJ, .*/\1/p' "$out/sculpt.log" | head -1)
[ -n "$pin" ] || fail "no passivity line among the stats"
awk -v e="$pin" 'BEGIN { exit !(e > 0) }' || fail "the passivity observer saw $pin mJ put in by a hand that pressed the skull"
echo "PASS sculpt --haptic emu (passivity: $pin mJ in)"
