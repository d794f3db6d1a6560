#!/usr/bin/env bash
# An `isotouch run` output folder is complete or plainly marked:
#  1. SIGINT while a run works: exit 130, summary.json "status": "interrupted" naming the
#     stage, the earlier run's report.md gone, a user's own file kept;
#  2. a second run into a folder whose lock is held: refused, naming the folder;
#  3. a run to completion: summary.json "status": "complete", the lock released.
# usage: cli_run_folder.sh ISOTOUCH SCENE OUT
set -u
exe=$1 scene=$2 out=$3
fail() { echo "FAIL: $*"; exit 1; }
# Waits (at most 30 s) until summary.json says the run in the folder is running.
wait_running() {
  for _ in $(seq 1 600); do
    grep -q '"running"' "$out/summary.json" 2>/dev/null && return 0
    sleep 0.05
  done
  return 1
}
rm -rf "$out"; mkdir -p "$out"
echo "earlier run's report" > "$out/report.md"
echo '{"status": "complete"}' > "$out/summary.json"
echo "the user's own file" > "$out/notes.txt"

"$exe" run "$scene" --out "$out" --quiet > "$out.log" 2>&1 &
pid=$!
wait_running || fail "summary.json never said running"
kill -INT "$pid"
wait "$pid"; rc=$?
cat "$out.log"
[ "$rc" -eq 130 ] || fail "exit $rc after SIGINT, expected 130"
grep -q '"status": "interrupted"' "$out/summary.json" || fail "summary.json does not say interrupted"
grep -q '"stage": ' "$out/summary.json" || fail "summary.json does not name the stage"
[ ! -e "$out/report.md" ] || fail "the earlier run's report.md is still there beside the new run's files"
[ -e "$out/notes.txt" ] || fail "a file that is not a run output was removed"
ls "$out" | grep -q '\.tmp-' && fail "a temp file was left behind"

flock "$out/.isotouch-run.lock" "$exe" run "$scene" --out "$out" --quiet > "$out.log" 2>&1; rc=$?
cat "$out.log"
[ "$rc" -ne 0 ] || fail "a second run into a locked folder exited 0"
grep -q "another isotouch run.*is writing this folder" "$out.log" || fail "no clear message for the locked folder"
grep -q '"status": "interrupted"' "$out/summary.json" || fail "the refused run touched summary.json"

"$exe" run "$scene" --out "$out" --quiet > "$out.log" 2>&1 || { cat "$out.log"; fail "the run after the lock was released failed"; }
grep -q '"status": "complete"' "$out/summary.json" || fail "a finished run's summary.json does not say complete"
[ -e "$out/report.md" ] || fail "no report.md after a complete run"
# SIGTERM: exit 143, interrupted.
"$exe" run "$scene" --out "$out" --quiet > "$out.log" 2>&1 &
pid=$!
wait_running || fail "summary.json never said running"
kill -TERM "$pid"
wait "$pid"; rc=$?
[ "$rc" -eq 143 ] || fail "exit $rc after SIGTERM, expected 143"
grep -q '"signal": "SIGTERM"' "$out/summary.json" || fail "summary.json does not name SIGTERM"

# A run that fails inside (a volume whose data file is truncated): "failed" with the error,
# the exit code non-zero.
printf 'ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\nElementType = MET_SHORT\nElementDataFile = bad.raw\n' > "$out.bad.mhd"
head -c 100 /dev/zero > "$out.bad.raw"
mv "$out.bad.raw" "$(dirname "$out")/bad.raw"
printf '{"name": "bad", "volume": {"path": "%s"}, "isovalue": 1}' "$out.bad.mhd" > "$out.bad.json"
"$exe" run "$out.bad.json" --out "$out" --quiet > "$out.log" 2>&1; rc=$?
cat "$out.log"
[ "$rc" -ne 0 ] || fail "a failed run exited 0"
if grep -q '"status": "failed"' "$out/summary.json"; then
  grep -q '"error": ".*bad.mhd' "$out/summary.json" || fail "summary.json does not name the error"
else
  # the scene loader may refuse the volume before the folder is touched: then the earlier summary stays
  grep -q '"signal": "SIGTERM"' "$out/summary.json" || fail "summary.json neither failed nor untouched"
fi
echo "PASS run folder: interrupted, locked and complete runs"
