#!/usr/bin/env bash
# Ctrl+C on `isotouch run` (the chest scene: engine set-up, servo, then outputs that take
# seconds: trace.csv, plots, the picture):
#  1. two SIGINTs at once (an impatient Ctrl+C Ctrl+C): exit 130, and summary.json says
#     "interrupted", never "running";
#  2. one SIGINT while the run's picture is drawn (the plots are written, surface.png is
#     not: one GPU submission, seconds to tens of seconds on lavapipe): exit 130 within
#     LIMIT_S seconds, summary.json "interrupted" at an outputs stage. Prints the time.
# usage: cli_run_interrupt.sh ISOTOUCH SCENE OUT [LIMIT_S (default 2)]
set -u
exe=$1 scene=$2 out=$3 limit=${4:-2}
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"

# Waits (at most 120 s) until the regex matches a line of FILE.
wait_for() { timeout 120 bash -c 'until grep -Eq "$2" "$1" 2>/dev/null; do sleep 0.05; done' _ "$1" "$2"; }

# 1. Twice, as soon as the folder says "running".
"$exe" run "$scene" --out "$out/twice" --quiet > "$out/twice.log" 2>&1 &
pid=$!
wait_for "$out/twice/summary.json" '"status": "running"' || fail "the run never marked its folder"
kill -INT "$pid"; sleep 0.3; kill -INT "$pid"  # apart: two pending SIGINTs merge into one
wait "$pid"; rc=$?
cat "$out/twice.log" "$out/twice/summary.json"
[ "$rc" -eq 130 ] || fail "exit $rc after two SIGINTs, expected 130"
grep -q '"status": "interrupted"' "$out/twice/summary.json" || fail "summary.json after two SIGINTs is not \"interrupted\""
ls "$out/twice" | grep -q "last-words" && fail "a temporary file was left: $(ls "$out/twice")"

# 2. Once, while the picture is drawn: the plots are in place, surface.png is not yet.
"$exe" run "$scene" --out "$out/once" --quiet > "$out/once.log" 2>&1 &
pid=$!
for _ in $(seq 1 2400); do [ -f "$out/once/tick_time.png" ] && break; sleep 0.05; done
[ -f "$out/once/tick_time.png" ] || { kill -KILL "$pid"; fail "the run never wrote its plots"; }
sleep 0.2
[ -f "$out/once/surface.png" ] && fail "the picture was drawn within 0.2 s: nothing to interrupt"
t0=$(date +%s.%N)
kill -INT "$pid"
wait "$pid"; rc=$?
t1=$(date +%s.%N)
cat "$out/once.log" "$out/once/summary.json"
took=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')
echo "one SIGINT during the outputs stage: stopped in $took s (limit $limit s)"
[ "$rc" -eq 130 ] || fail "exit $rc after SIGINT, expected 130"
grep -q '"status": "interrupted"' "$out/once/summary.json" || fail "summary.json after SIGINT is not \"interrupted\""
grep -q '"stage": "outputs' "$out/once/summary.json" || fail "summary.json does not name an outputs stage"
awk -v t="$took" -v l="$limit" 'BEGIN { exit !(t <= l) }' || fail "one SIGINT took $took s to stop the outputs stage (limit $limit s)"
echo "PASS run interrupt"
