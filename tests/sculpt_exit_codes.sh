#!/usr/bin/env bash
# isotouch-sculpt's exit codes for what goes wrong in a session (docs/exit-codes.md):
#  1. a scripted save (Ctrl+S) and export (Ctrl+E) into a folder that does not exist: the
#     window says so and the session goes on, and the process exits 6, not 0;
#  2. the haptic device (an isotouch-devemu process) SIGKILLed while the window runs: the
#     device's disconnected ticks are counted and the process exits 5 (as run --live), not 0.
# Usage: sculpt_exit_codes.sh SCULPT_BIN ISOTOUCH_BIN DEVEMU_BIN SOURCE_DIR OUT_DIR. Exit 77 without xvfb-run.
set -u
bin=$1 iso=$2 emu=$3 src=$4 out=$5
fail() { echo "FAIL: $*"; exit 1; }
command -v xvfb-run >/dev/null || { echo "SKIP: xvfb-run is not installed"; exit 77; }
rm -rf "$out"; mkdir -p "$out"
scene=$src/scenes/head.json
# The app's own exit code, written by the shell xvfb-run starts (xvfb-run's own may differ).
app_rc() { sed -n 's/^app exit \([0-9]*\)$/\1/p' "$1"; }

xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --size 128 --script "$src/tests/sculpt/save-fails.json" \
  --save "$out/no-such-folder/x.vdb" --export "$out/no-such-folder/x.stl" > "$out/save.log" 2>&1
rc=$(app_rc "$out/save.log")
cat "$out/save.log"
grep -q "save failed: .*no-such-folder/x.vdb" "$out/save.log" || fail "no 'save failed' line naming the file"
grep -q "export failed: .*no-such-folder/x.stl" "$out/save.log" || fail "no 'export failed' line naming the file"
[ "$rc" = 6 ] || fail "a failed scripted save: exit $rc, expected 6"

sock=$out/dev.sock
"$iso" run "$scene" --hand-path "$out/hand.csv" > "$out/path.log" 2>&1 || { cat "$out/path.log"; fail "--hand-path failed"; }
"$emu" --socket "$sock" --path "$out/hand.csv" --seconds 120 > "$out/emu.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --size 128 --haptic "emu:$sock" \
  --script "$src/tests/sculpt/run-long.json" > "$out/lost.log" 2>&1 &
app=$!
# Killed once the window's session is connected (a connected peer on the socket) and has run 1 s.
for _ in $(seq 1 600); do ss -x state connected 2>/dev/null | grep -q "$sock" && break; sleep 0.05; done
sleep 1
kill -KILL "$emu_pid"; wait "$emu_pid" 2>/dev/null
wait "$app"
rc=$(app_rc "$out/lost.log")
cat "$out/lost.log"
grep -Eq "^device   emu:.*disconnected [1-9]" "$out/lost.log" || fail "no disconnected ticks counted"
[ "$rc" = 5 ] || fail "the device lost mid-session: exit $rc, expected 5"
echo "PASS sculpt exit codes"
