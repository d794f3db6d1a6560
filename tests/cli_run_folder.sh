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
rm -rf "$out"; mkdir -p "$out"
echo "earlier run's report" > "$out/report.md"
echo '{"status": "complete"}' > "$out/summary.json"
echo "the user's own file" > "$out/notes.txt"

"$exe" run "$scene" --out "$out" --quiet > "$out.log" 2>&1 &
pid=$!
for _ in $(seq 1 600); do
  grep -q '"running"' "$out/summary.json" 2>/dev/null && break
  sleep 0.05
done
grep -q '"running"' "$out/summary.json" || fail "summary.json never said running"
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
echo "PASS run folder: interrupted, locked and complete runs"
