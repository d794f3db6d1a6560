#!/usr/bin/env bash
# SIGTERM to the sculpting window under Xvfb: the frame loop ends, the session stops, the
# app exits 143 and says so, and the X server, kept off the servo's CPU while the window
# was open, has its own CPU set back (read from the kernel with taskset before, during and
# after). Needs a pinned servo (SCHED_FIFO granted, two CPUs or more): skipped (77) without
# it, and without xvfb-run.
# Usage: sculpt_sigterm.sh SCULPT_BIN SOURCE_DIR OUT_DIR
set -u
bin=$1 src=$2 out=$3
command -v xvfb-run >/dev/null || { echo "SKIP: xvfb-run is not installed"; exit 77; }
[ "$(nproc)" -ge 2 ] || { echo "SKIP: one CPU: nothing to keep the X server off"; exit 77; }
rm -rf "$out"; mkdir -p "$out"
export bin src out
xvfb-run -a -s "-screen 0 640x480x24" bash -c '
  x=$(pgrep -n -x Xvfb)
  before=$(taskset -p "$x" | sed "s/.*: //")
  "$bin" "$src/scenes/head.json" --frames 0 --size 320 --no-overlay > "$out/log.txt" 2>&1 &
  app=$!
  for _ in $(seq 1 600); do grep -q "^servo    display server\|^sculpt   sculpt:" "$out/log.txt" && break; sleep 0.1; done
  sleep 0.5
  during=$(taskset -p "$x" | sed "s/.*: //")
  kill -TERM "$app"; wait "$app"; rc=$?
  after=$(taskset -p "$x" | sed "s/.*: //")
  echo "xvfb $x before $before during $during after $after rc $rc" > "$out/result.txt"
'
cat "$out/log.txt"; cat "$out/result.txt"
if grep -q "SCHED_FIFO .* refused\|pinning to CPU .* refused" "$out/log.txt"; then echo "SKIP: the servo was not pinned"; exit 77; fi
read -r _ x _ before _ during _ after _ rc < "$out/result.txt"
grep -q "^servo    display server Xvfb (pid $x, " "$out/log.txt" || { echo "FAIL: the log does not name Xvfb $x as kept off the servo's CPU"; exit 1; }
[ "$during" != "$before" ] || { echo "FAIL: Xvfb's CPU set was not changed while the window was open ($before)"; exit 1; }
[ "$rc" -eq 143 ] || { echo "FAIL: exit $rc after SIGTERM, expected 143"; exit 1; }
grep -q "^sculpt   stopped by signal 15" "$out/log.txt" || { echo "FAIL: the app did not say it stopped on the signal"; exit 1; }
[ "$after" = "$before" ] || { echo "FAIL: Xvfb's CPU set is $after after SIGTERM, $before before"; exit 1; }
echo "PASS sculpt SIGTERM: Xvfb $before -> $during -> $after, exit $rc"
