#!/usr/bin/env bash
# isotouch-devemu --sine-mm A: the hand moves +-A mm along z, so the pose read over the link
# (`isotouch devices --check emu:SOCKET`, force off) stays within +-(A + 1) mm and spans at
# least A mm (a sine read as metres, or not at all, fails).
# usage: cli_devemu_sine.sh ISOTOUCH DEVEMU OUT
set -u
exe=$1 emu=$2 out=$3
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
sock=$out/dev.sock
amp=5
"$emu" --socket "$sock" --rate 1000 --sine-mm $amp --sine-hz 0.7 --seconds 10 > "$out/emu.log" 2>&1 &
emu_pid=$!
for _ in $(seq 1 100); do [ -S "$sock" ] && break; sleep 0.05; done
echo n | "$exe" devices --check "emu:$sock" --seconds 3 > "$out/check.log" 2>&1
kill -TERM "$emu_pid" 2>/dev/null; wait "$emu_pid" 2>/dev/null
cat "$out/check.log"
# "  pose (x, y, z) mm ...": every z within +-(amp + 1) mm; the range of z at least amp mm.
zs=$(sed -n 's/^  pose ([^,]*, [^,]*, \([-0-9.]*\)) mm.*/\1/p' "$out/check.log")
[ -n "$zs" ] || fail "no pose read"
echo "$zs" | awk -v a=$amp 'BEGIN{lo=1e30; hi=-1e30}
  {if ($1 < lo) lo = $1; if ($1 > hi) hi = $1}
  END{printf "z from %.1f to %.1f mm (amplitude %d mm)\n", lo, hi, a;
      exit !(lo >= -(a + 1) && hi <= a + 1 && hi - lo >= a)}' || fail "the pose left +-$((amp + 1)) mm or did not move"
echo "PASS devemu --sine-mm in mm"
