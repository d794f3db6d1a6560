#!/usr/bin/env bash
# `isotouch serve`'s memory budget for the IMAGEs of every client (issue 62), judged on the
# STATUS answers igtl_session_client got:
#   1. with --memory-mib 600 (a budget of 450 MiB), a peer (python, raw OpenIGTLink) sends the
#      message and image headers of a 512 x 512 x 44 uint8 IMAGE (11 MiB of voxels, about
#      407 MiB with its session: it fits) and then its voxels a byte at a time: while it
#      arrives, a 128^3 uint8 IMAGE (its session about 74 MiB) from another client is refused
#      with code 11 naming the need, the budget (450 MiB) and what the arriving one counts in
#      flight; once the peer has gone, the same IMAGE is taken;
#   1b. on the same server, a peer sends a 512 x 512 x 1600 uint8 IMAGE (400 MiB of voxels) whole:
#      its header alone is over the budget, so it is refused with code 11 and its voxels are
#      read and dropped, never held: the server's peak memory (VmHWM) grows by under 100 MiB
#      (reading it whole would take 400 MiB, its library copy 400 more) and the log counts
#      nothing arriving for it;
#   2. where the machine's memory is unknown (the fault seam ISOTOUCH_SERVE_TEST_FAULT
#      "budget:NAME": io::memory_budget_bytes read as 0 for the image NAME) and no
#      --memory-mib, a 512 x 512 x 400 uint8 IMAGE (about 3.6 GiB with its session) is refused
#      against the default of 4096 MiB (a budget of 3072 MiB), named as such; a 128^3 one is
#      taken after it. ("prepare:Huge" makes a wrongly taken Huge fail fast, not build 3.6 GiB.)
#   3. an IMAGE the main thread took counts until its session runs ("taken:A" holds it 5 s
#      after the take): a second one sent meanwhile is refused with code 11 (two do not fit).
# "PASS serve budget" is printed once, last.
# Usage: cli_serve_budget.sh ISOTOUCH SCENE CLIENT OUT_DIR HEAD_MHD
set -u
source "$(dirname "$0")/serve_port.sh"
exe=$1; scene=$2; client=$3; out=$4; head=$5
rm -rf "$out"; mkdir -p "$out"
export XDG_STATE_HOME="$out/state"
fail() { echo "FAIL serve budget: $*"; for f in "$out"/*.log; do echo "--- $f"; tail -n 20 "$f"; done; exit 1; }
holder=""
trap 'kill -KILL $(jobs -p) 2>/dev/null' EXIT  # the holder, and any serve a failed part left

start_serve "$out/serve1.log" "$scene" --port 0 --stream Stylus --image-hz 0 --memory-mib 600 ||
  fail "serve never said it was listening"
# The peer: an IGTL header announcing the IMAGE's body, its 72-byte image header, then one
# voxel byte every 0.2 s (serve drops a client silent 2 s inside a message) for at most 60 s.
python3 - "$port" >"$out/holder.log" 2>&1 <<'PY' &
import socket, struct, sys, time
dims = (512, 512, 44)
voxels = dims[0] * dims[1] * dims[2]
body = 72 + voxels
head = struct.pack(">H12s20sQQQ", 1, b"IMAGE", b"Held", 0, body, 0)
image = struct.pack(">HBBBB3H12f3H3H", 1, 1, 3, 2, 1, *dims, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, *dims)
assert len(head) == 58 and len(image) == 72
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(head + image)
print(f"held {body} bytes announced", flush=True)
end = time.time() + 60
while time.time() < end:
    s.sendall(b"\0")
    time.sleep(0.2)
PY
holder=$!
for _ in $(seq 300); do
  grep -q "image    'Held': 512 x 512 x 44 arriving, [0-9]* bytes" "$out/serve1.log" && break
  kill -0 $holder 2>/dev/null || break
  sleep 0.1
done
held=$(sed -n "s/^.*image    'Held': 512 x 512 x 44 arriving, \([0-9]*\) bytes.*/\1/p" "$out/serve1.log")
[[ -n $held ]] || fail "serve never counted the peer's IMAGE"
held_mib=$(( held >> 20 ))
timeout 60 "$client" 127.0.0.1 "$port" "$head" ramp Mid 128 128 128 >"$out/client1.log" 2>&1 ||
  fail "the first client failed (exit $?)"
kill $holder; wait $holder 2>/dev/null; holder=""
for _ in $(seq 100); do  # the peer's IMAGE is dropped once its connection ends
  grep -q "IMAGE 'Held': IMAGE body truncated" "$out/serve1.log" && break
  sleep 0.1
done
grep -q "IMAGE 'Held': IMAGE body truncated" "$out/serve1.log" || fail "serve did not drop the peer's IMAGE"
timeout 60 "$client" 127.0.0.1 "$port" "$head" ramp Mid 128 128 128 >"$out/client2.log" 2>&1 ||
  fail "the second client failed (exit $?)"
refused=$(grep "STATUS" "$out/client1.log")
[[ $refused == "STATUS code 11: igtl:Mid: not taken: 128 x 128 x 128 voxels need "* ]] ||
  fail "the IMAGE beside the one arriving was not refused with code 11: $refused"
[[ $refused == *"more than the budget of 450 MiB (3/4 of the 600 MiB"* ]] || fail "the STATUS does not name the budget: $refused"
[[ $refused == *" $held_mib MiB in flight"* ]] || fail "the STATUS does not name the arriving IMAGE's $held_mib MiB in flight: $refused"
need=$(sed -n 's/.* voxels need \([0-9]*\) MiB,.*/\1/p' <<<"$refused")
(( need > 450 && need < 600 )) || fail "the need of $need MiB is not the ~490 MiB of the image, the head and the $held_mib MiB"
grep -q "STATUS code 1: volume taken: 128 x 128 x 128" "$out/client2.log" ||
  fail "the same IMAGE was not taken once the peer had gone: $(grep STATUS "$out/client2.log")"
echo "ok serve budget: a 128^3 IMAGE refused beside $held_mib MiB arriving ($need MiB needed, 450 MiB budget), taken after"

# 1b. An IMAGE over the budget by its header alone: refused, its voxels never held.
hwm() { sed -n 's/^VmHWM: *\([0-9]*\) kB/\1/p' "/proc/$pid/status"; }
hwm_before=$(hwm)
timeout 120 python3 - "$port" >"$out/big.log" 2>&1 <<'PY' || fail "the peer sending the 400 MiB IMAGE failed: $(cat "$out/big.log")"
import socket, struct, sys
dims = (512, 512, 1600)
voxels = dims[0] * dims[1] * dims[2]
head = struct.pack(">H12s20sQQQ", 1, b"IMAGE", b"Big", 0, 72 + voxels, 0)
image = struct.pack(">HBBBB3H12f3H3H", 1, 1, 3, 2, 1, *dims, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, *dims)
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.settimeout(90)
s.sendall(head + image)
chunk = bytes(1 << 20)
for _ in range(voxels >> 20):
    s.sendall(chunk)
def read(n):
    b = b""
    while len(b) < n:
        got = s.recv(n - len(b))
        if not got:
            sys.exit("closed before a STATUS")
        b += got
    return b
while True:
    h = read(58)
    kind, name, size = h[2:14].rstrip(b"\0"), h[14:34].rstrip(b"\0"), struct.unpack(">Q", h[42:50])[0]
    body = read(size)
    if kind == b"STATUS" and name == b"Big":
        print("STATUS code %d: %s" % (struct.unpack(">H", body[:2])[0], body[30:].split(b"\0")[0].decode()))
        break
PY
hwm_after=$(hwm)
big=$(grep STATUS "$out/big.log")
[[ $big == "STATUS code 11: igtl:Big: not taken: 512 x 512 x 1600 voxels need "* ]] ||
  fail "the 400 MiB IMAGE over the budget was not refused with code 11: $big"
grep -q "image    'Big': .* arriving" "$out/serve1.log" && fail "serve counted the IMAGE its header refused"
grown=$(( (hwm_after - hwm_before) >> 10 ))
(( grown < 100 )) || fail "serve's peak memory grew $grown MiB while it refused a 400 MiB IMAGE (VmHWM $hwm_before -> $hwm_after kB)"
echo "ok serve budget: a 400 MiB IMAGE over the budget refused at its header; serve's peak memory grew $grown MiB"
kill -TERM $pid; wait $pid

ISOTOUCH_SERVE_TEST_FAULT="budget:Huge,prepare:Huge" start_serve "$out/serve2.log" "$scene" --port 0 --stream Stylus \
  --image-hz 0 || fail "serve did not start again"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ramp Huge 512 512 400 ramp Mid 128 128 128 >"$out/client3.log" 2>&1 ||
  fail "the third client failed (exit $?)"
kill -TERM $pid; wait $pid
huge=$(grep "STATUS.*Huge" "$out/client3.log")
[[ $huge == "STATUS code 11: igtl:Huge: not taken: 512 x 512 x 400 voxels need "* ]] ||
  fail "the large IMAGE was not refused with code 11 where the memory is unknown: $huge"
[[ $huge == *"more than the budget of 3072 MiB (3/4 of the 4096 MiB of memory this server may use, a default: this machine's memory is unknown)"* ]] ||
  fail "the STATUS does not name the default budget: $huge"
grep -q "STATUS code 1: volume taken: 128 x 128 x 128" "$out/client3.log" ||
  fail "serve did not take an IMAGE after the refusal: $(grep STATUS "$out/client3.log")"
echo "ok serve budget: an unknown memory takes the 4096 MiB default"

# 3. An IMAGE taken by the main thread counts from the take until its session runs: with
#    --memory-mib 160 (a budget of 120 MiB) and the head's running session (~13 MiB), one
#    128^3 uint8 IMAGE fits (~74 MiB with its session), two do not. "taken:A" holds A 5 s
#    between the take and its build (the window where it counted nowhere): B, sent then, is
#    refused with code 11 naming A's ~72 MiB in flight; A is taken.
ISOTOUCH_SERVE_TEST_FAULT="taken:A" \
  "$exe" serve "$scene" --port 0 --stream Stylus --image-hz 0 --memory-mib 160 >"$out/serve3.log" 2>&1 &
pid=$!
port=$(wait_port "$out/serve3.log" $pid)
[[ -n $port ]] || fail "serve did not start a third time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ramp A 128 128 128 >"$out/client4.log" 2>&1 &
a=$!
for _ in $(seq 300); do grep -q "test     'A' taken, held 5 s" "$out/serve3.log" && break; sleep 0.05; done
grep -q "test     'A' taken, held 5 s" "$out/serve3.log" || fail "A was never taken"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ramp B 128 128 128 >"$out/client5.log" 2>&1 ||
  fail "client B failed (exit $?)"
wait $a || fail "client A failed (exit $?)"
kill -TERM $pid; wait $pid
b=$(grep "STATUS" "$out/client5.log")
[[ $b == "STATUS code 11: igtl:B: not taken: 128 x 128 x 128 voxels need "* ]] ||
  fail "the IMAGE sent while A was taken but not yet built was not refused with code 11: $b"
flight=$(sed -n 's/.* MiB the running session, \([0-9]*\) MiB in flight.*/\1/p' <<<"$b")
(( flight >= 72 )) || fail "B's refusal counts $flight MiB in flight, not A's 72 MiB session: $b"
grep -q "STATUS code 1: volume taken: 128 x 128 x 128" "$out/client4.log" || fail "A was not taken: $(cat "$out/client4.log")"
echo "ok serve budget: an IMAGE sent while another was taken and not yet built refused ($flight MiB in flight)"
echo "PASS serve budget: every client's IMAGEs in flight counted against the one budget; an unknown memory takes the 4096 MiB default"
