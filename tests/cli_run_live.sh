#!/usr/bin/env bash
# `isotouch run SCENE --live`: the scene in real time on the live session's threads.
#  1. --record F, to the end: exit 0, F complete (end record), no F.part left; replay F:
#     every force, VHIP and snapshot version identical;
#  2. SIGKILL mid-way: F.part remains, replay of F.part is identical up to its last chunk
#     and says the file has no end record; replay F names F.part;
#  3. SIGINT mid-way: exit 130, the recording complete and replayable, no F.part.
#  --out DIR (runs 1 and 3): trace.csv with a row per tick, report.md, summary.json
#     "complete" with its "live" section (run 1), "interrupted" (run 3), "failed" (a
#     device that cannot be opened).
# usage: cli_run_live.sh ISOTOUCH SCENE OUT
set -u
exe=$1 scene=$2 out=$3
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
rec=$out/live.rec

"$exe" run "$scene" --live --record "$rec" --out "$out/folder" --quiet > "$out/run.log" 2>&1; rc=$?
[ "$rc" -eq 0 ] || { cat "$out/run.log"; fail "run --live exited $rc"; }
cat "$out/run.log"
# --out: what the live session ran, in the folder (the servo's tick count against the rows).
ticks=$(sed -n 's/^live     \([0-9]*\) ticks in.*/\1/p' "$out/run.log")
rows=$(( $(wc -l < "$out/folder/trace.csv") - 1 ))
[ "${ticks:-0}" -gt 1000 ] && [ "$rows" -gt $(( ticks - 50 )) ] && [ "$rows" -le "$ticks" ] ||
  fail "--out: trace.csv has $rows rows for ${ticks:-?} servo ticks"
grep -q '"status": "complete"' "$out/folder/summary.json" || fail "--out: summary.json not complete"
grep -q '"live": {' "$out/folder/summary.json" || fail "--out: summary.json has no live section"
# The servo's passivity stage observed the simulated hand (the scene leaves the controller
# off): its net energy out is the work of the forces written over the motion, worked out here
# from the recording (device frame = world less the volume's centre at workspace_scale 1):
# sum over ticks of sent(k) . (hip(k+1) - hip(k)), a held tick's force being zero.
python3 - "$out/folder/summary.json" "$rec" <<'PY' || fail "--out: summary.json's live.passivity is not the observer's"
import json, math, sys
p = json.load(open(sys.argv[1]))["live"]["passivity"]
assert p["status"] == "run" and p["control"] is False and p["active_ticks"] == 0, p
assert p["clock"] in ("device", "servo") and p["restarts"] == 0, p
assert all(math.isfinite(p[k]) for k in ("energy_in_j", "energy_out_j", "dissipated_j")), p
assert p["energy_in_j"] > 0 and p["energy_out_j"] > 0, p  # the probe pressed and was pushed back
ticks = [t for t in map(json.loads, open(sys.argv[2])) if "k" in t]
work = scale = 0.0
for a, b in zip(ticks, ticks[1:]):
    w = sum(f * (y - x) for f, x, y in zip(a.get("sent", [0, 0, 0]), a["hip"], b["hip"]))
    work, scale = work + w, scale + abs(w)
net = p["energy_out_j"] - p["energy_in_j"]
print(f"live.passivity: net energy out {net:.9g} J, the recording's work {work:.9g} J (sum |w| {scale:.3g} J)")
assert abs(net - work) <= 1e-6 * scale, (net, work, scale)
PY
[ -s "$out/folder/report.md" ] || fail "--out: no report.md"
[ -f "$rec" ] || fail "no recording"
[ ! -e "$rec.part" ] || fail "$rec.part left after a clean stop"
tail -n 1 "$rec" | grep -q '"end":true' || fail "the recording has no end record"
grep -q '"format_version":3' "$rec" || fail "not a format 3 recording"
grep -q '"edit":"brush"' "$rec" || fail "the live drill recorded no brush"
"$exe" replay "$rec" --quiet > "$out/replay.log" 2>&1; rc=$?
cat "$out/replay.log"
[ "$rc" -eq 0 ] || fail "replay of the live recording exited $rc"
grep -q "^IDENTICAL" "$out/replay.log" || fail "replay not identical"

# Waits (at most 30 s) until FILE has at least 1000 tick lines.
wait_ticks() {
  for _ in $(seq 1 600); do
    local n
    n=$(grep -c '"k":' "$1" 2>/dev/null)  # (no file: empty; no line: 0 and exit 1)
    [ "${n:-0}" -ge 1000 ] && return 0
    sleep 0.05
  done
  return 1
}
rm -f "$rec" "$rec.part"
"$exe" run "$scene" --live --record "$rec" --quiet > "$out/kill.log" 2>&1 &
pid=$!
wait_ticks "$rec.part" || fail "the live recording did not stream ticks into $rec.part"
kill -KILL "$pid"; wait "$pid" 2>/dev/null
[ -f "$rec.part" ] || fail "no $rec.part after SIGKILL"
[ ! -e "$rec" ] || fail "$rec exists after SIGKILL (it must only appear complete)"
"$exe" replay "$rec.part" --quiet > "$out/replay-part.log" 2>&1; rc=$?
cat "$out/replay-part.log"
[ "$rc" -eq 0 ] || fail "replay of the killed session's $rec.part exited $rc"
grep -q "no end record" "$out/replay-part.log" || fail "replay did not say the file was cut"
grep -q "^IDENTICAL" "$out/replay-part.log" || fail "replay of $rec.part not identical"
"$exe" replay "$rec" --quiet > "$out/replay-missing.log" 2>&1 && fail "replay of a missing recording exited 0"
grep -q "live.rec.part exists" "$out/replay-missing.log" || { cat "$out/replay-missing.log"; fail "replay of F did not point at F.part"; }

rm -f "$rec" "$rec.part"
"$exe" run "$scene" --live --record "$rec" --out "$out/int-folder" --quiet > "$out/int.log" 2>&1 &
pid=$!
wait_ticks "$rec.part" || fail "no ticks streamed before SIGINT"
kill -INT "$pid"; wait "$pid"; rc=$?
cat "$out/int.log"
[ "$rc" -eq 130 ] || fail "exit $rc after SIGINT, expected 130"
grep -q '"status": "interrupted"' "$out/int-folder/summary.json" || fail "--out: summary.json after SIGINT not interrupted"
[ "$(wc -l < "$out/int-folder/trace.csv")" -gt 1000 ] || fail "--out: no trace.csv after SIGINT"
[ ! -e "$rec.part" ] || fail "$rec.part left after SIGINT"
tail -n 1 "$rec" | grep -q '"end":true' || fail "the recording after SIGINT has no end record"
"$exe" replay "$rec" --quiet > "$out/replay-int.log" 2>&1 || { cat "$out/replay-int.log"; fail "replay after SIGINT failed"; }
grep -q "^IDENTICAL" "$out/replay-int.log" || fail "replay after SIGINT not identical"
# --out with a device that cannot be opened: summary.json says "failed" with the error.
"$exe" run "$scene" --live --haptic "emu:$out/none.sock" --out "$out/failed" --quiet > "$out/failed.log" 2>&1 &&
  fail "a missing device exited 0"
grep -q '"status": "failed"' "$out/failed/summary.json" || { cat "$out/failed.log"; fail "--out: summary.json after a failed start is not \"failed\""; }
echo "PASS run --live"
