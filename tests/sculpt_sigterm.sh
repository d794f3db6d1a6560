#!/usr/bin/env bash
# Signals to the sculpting window under Xvfb. SIGTERM and SIGHUP: the frame loop ends, the
# session stops, the app exits 128 + the signal and says so. Each of these and SIGKILL (the
# app's guard process does it then): the X server, kept off the servo's CPU while the window
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
for sig in TERM HUP KILL; do
  export sig
  xvfb-run -a -s "-screen 0 640x480x24" bash -c '
    x=$(pgrep -n -x Xvfb)
    before=$(taskset -p "$x" | sed "s/.*: //")
    "$bin" "$src/scenes/head.json" --frames 0 --size 320 --no-overlay > "$out/log-$sig.txt" 2>&1 &
    app=$!
    for _ in $(seq 1 600); do grep -q "^servo    display server\|^sculpt   sculpt:" "$out/log-$sig.txt" && break; sleep 0.1; done
    sleep 0.5
    during=$(taskset -p "$x" | sed "s/.*: //")
    kill -"$sig" "$app"; wait "$app"; rc=$?
    # (after SIGKILL the guard acts once the kernel has closed the dead app'"'"'s pipe: beside
    # other tests under ctest -j2 that took more than 5 s once, so up to 30 s)
    for _ in $(seq 1 300); do after=$(taskset -p "$x" | sed "s/.*: //"); [ "$after" = "$before" ] && break; sleep 0.1; done
    echo "xvfb $x before $before during $during after $after rc $rc" > "$out/result-$sig.txt"
  '
  cat "$out/log-$sig.txt"; cat "$out/result-$sig.txt"
  if grep -q "SCHED_FIFO .* refused\|pinning to CPU .* refused" "$out/log-$sig.txt"; then echo "SKIP: the servo was not pinned"; exit 77; fi
  read -r _ x _ before _ during _ after _ rc < "$out/result-$sig.txt"
  num=$(kill -l "$sig")
  grep -q "^servo    display server Xvfb (pid $x, " "$out/log-$sig.txt" || { echo "FAIL: the log does not name Xvfb $x as kept off the servo's CPU"; exit 1; }
  [ "$during" != "$before" ] || { echo "FAIL: Xvfb's CPU set was not changed while the window was open ($before)"; exit 1; }
  [ "$rc" -eq $((128 + num)) ] || { echo "FAIL: exit $rc after SIG$sig, expected $((128 + num))"; exit 1; }
  if [ "$sig" != KILL ]; then
    grep -q "^sculpt   stopped by signal $num" "$out/log-$sig.txt" || { echo "FAIL: the app did not say it stopped on SIG$sig"; exit 1; }
  fi
  [ "$after" = "$before" ] || { echo "FAIL: Xvfb's CPU set is $after after SIG$sig, $before before"; exit 1; }
  echo "sculpt SIG$sig: Xvfb $before -> $during -> $after, exit $rc"
done
echo "PASS sculpt SIGTERM, SIGHUP, SIGKILL: the X server's CPU set given back each time"
