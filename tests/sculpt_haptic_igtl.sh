#!/usr/bin/env bash
# isotouch-sculpt --haptic igtl:HOST:PORT under Xvfb, against igtl_plus_peer (a PLUS-like
# OpenIGTLink server built on the library, the one tests/cli_haptic_igtl.sh uses): the
# window's probe is the peer's stylus. Truth from the peer's side (the Force TRANSFORMs it
# received) and the app's exit code:
#   1. at 500 Hz: the stylus moved 2.6 voxels into the skull gets forces pushing it back out
#      (-x), never past the scene's 3.3 N; when the stream stops while the window goes on, the
#      next force the peer gets is an exact zero, within the stale timeout (3 stream periods)
#      and 100 ms for a loaded machine, and no force other than zero after it; SIGTERM then
#      ends the window (exit 143);
#   2. at 50 Hz the head's 800 N/m is above the link's bound (simulated, sim::link_k_max:
#      about 140 N/m without and 260 N/m with the peer's passivity controller):
#      refused, exit 1, naming both bounds and how to allow it; with --allow-unstable-stiffness
#      the window runs (exit 0), warning.
# "PASS sculpt --haptic igtl" is printed once, last, after every check.
# Usage: sculpt_haptic_igtl.sh SCULPT_BIN PEER SOURCE_DIR OUT_DIR. Exit 77 without xvfb-run.
set -u
bin=$1 peer=$2 src=$3 out=$4
command -v xvfb-run >/dev/null || { echo "SKIP: xvfb-run is not installed"; exit 77; }
[[ $out == */sculpt_haptic_igtl ]] || { echo "FAIL: OUT_DIR must end in /sculpt_haptic_igtl: $out"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
fail() { echo "FAIL sculpt --haptic igtl: $*"; for f in "$out"/*.log; do echo "--- $f"; tail -n 20 "$f"; done; exit 1; }
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
scene=$src/scenes/head.json
# The peer NAME RATE STREAM_S: device frame [mm] (cli_haptic_igtl.sh's path): outside the skull
# until 1.6 s (the device measures the rate for 1 s), in 0.5 s to 2.6 voxels into it; then silent.
start_peer() {
  port=$(free_port)
  "$peer" "$port" "$2" "$3" 1.6 0.5 30 -91.2 1.6 -52.5 -63.68 1.6 -52.5 >"$out/$1.peer.log" 2>&1 &
  peer_pid=$!
  for _ in $(seq 100); do grep -q listening "$out/$1.peer.log" && break; sleep 0.05; done
}
stop_peer() { kill "$peer_pid" 2>/dev/null; wait "$peer_pid" 2>/dev/null; }

# 1. Contact, then the stream stops; the window goes on until SIGTERM, 1 s after the stop.
# Once more if the contact was lost before the stream stopped (igtl_peer_check.py).
for _ in 1 2; do
  start_peer fast 500 6
  export bin scene port src out
  xvfb-run -a -s "-screen 0 640x480x24" bash -c '
    "$bin" "$scene" --haptic "igtl:127.0.0.1:$port" --script "$src/tests/sculpt/haptic-igtl.json" --size 256 --stats \
      > "$out/fast.log" 2>&1 &
    app=$!
    for _ in $(seq 1 900); do grep -q "^stopped" "$out/fast.peer.log" && break; kill -0 $app 2>/dev/null || break; sleep 0.1; done
    sleep 1
    kill -TERM $app; wait $app; echo $? > "$out/fast.rc"'
  stop_peer
  python3 "$(dirname "$0")/igtl_peer_check.py" "$out/fast.peer.log" && break
  echo "note: the contact was lost before the stream stopped; once more"
done
[[ $(cat "$out/fast.rc") == 143 ]] || fail "the window exited $(cat "$out/fast.rc") on SIGTERM, not 143"
grep -q "^device   igtl:127.0.0.1:$port (.* Hz measured" "$out/fast.log" || fail "the window did not report the device and its rate"
grep -q "wait for contact timed out" "$out/fast.log" && fail "the probe never touched the skull"
python3 - "$out" "$(dirname "$0")" <<'PY' || exit 1
import sys
out = sys.argv[1]
sys.path.insert(0, sys.argv[2])
from igtl_peer_check import check_peer_forces, norm
def fail(msg):
    print("FAIL sculpt --haptic igtl:", msg); sys.exit(1)
during, pushing, late = check_peer_forces(f"{out}/fast.peer.log", 2.6, 0.5, 200, 500, fail)
print(f"sculpt igtl ok: {len(pushing)} of {len(during)} forces above 0.5 N (max {max(norm(f) for f in during):.2f} N); "
      f"zero {late * 1e3:.1f} ms after the stream stopped")
PY

# 2. A 50 Hz stream: refused, then allowed.
app_rc() { sed -n 's/^app exit \([0-9]*\)$/\1/p' "$1"; }
start_peer slow 50 4
xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --haptic "igtl:127.0.0.1:$port" \
  --script "$src/tests/sculpt/quit.json" --size 256 > "$out/slow.log" 2>&1
stop_peer
[[ $(app_rc "$out/slow.log") == 1 ]] || fail "the 50 Hz stream against K 800 N/m: exit $(app_rc "$out/slow.log"), not 1"
grep -qE "servo.stiffness_n_per_m 800 is above the bound [0-9.]+ N/m without the passivity controller at the peer's end \([0-9.]+ N/m without it, [0-9.]+ N/m with it\)" \
  "$out/slow.log" || fail "the refusal does not name both bounds"
grep -q -- "--allow-unstable-stiffness" "$out/slow.log" || fail "the refusal does not say how to allow it"
start_peer allowed 50 6
xvfb-run -a sh -c '"$@"; echo "app exit $?"' sh "$bin" "$scene" --haptic "igtl:127.0.0.1:$port" --allow-unstable-stiffness \
  --script "$src/tests/sculpt/quit.json" --size 256 > "$out/allowed.log" 2>&1
stop_peer
[[ $(app_rc "$out/allowed.log") == 0 ]] || fail "--allow-unstable-stiffness: exit $(app_rc "$out/allowed.log"), not 0"
grep -q "K is above the bound (allowed)" "$out/allowed.log" || fail "--allow-unstable-stiffness did not warn"
echo "PASS sculpt --haptic igtl"
