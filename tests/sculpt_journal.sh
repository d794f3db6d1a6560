#!/usr/bin/env bash
# The edit journal through a kill -9 (issue 62): the sculpting app, scripted on the simulated
# clock under Xvfb, carves three strokes and undoes one, saves (Ctrl+S: the volume at the
# kill, written by the app itself) and is killed with SIGKILL while it waits. Its journal
# ($XDG_STATE_HOME/isotouch/sculpt-CRC.journal) then holds the edits; a start with
# --restore ask and no terminal does not restore them (its save is the unedited volume) and
# keeps them as JOURNAL.unrestored; put back and started with --restore yes, the app says
# "restore N edits from HH:MM?", applies them, and its save equals the one before the kill
# byte for byte; that clean exit deletes the journal.
# Usage: sculpt_journal.sh SCULPT_BIN SOURCE_DIR OUT_DIR. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 src=$2 out=$3
command -v xvfb-run >/dev/null || { echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"; exit 77; }
rm -rf "$out"; mkdir -p "$out"
fail() { echo "FAIL: $*"; exit 1; }
export XDG_STATE_HOME="$out/state"
common=(--size 320 --no-overlay --no-slices --sim-clock --no-sched-fifo --no-display-off-servo-cpu)
stroke='{"after_frames": 2, "press": "left"}, {"after_frames": 8, "release": "left"}, {"wait": "edits", "timeout_s": 60}'
cat > "$out/edits.json" <<EOF
{"events": [
  {"cursor": [0.5, 0.45]},
  {"tool": "carve", "radius_mm": 8, "strength": 0.5},
  {"wait": "contact", "timeout_s": 60},
  {"scroll": 2},
  $stroke,
  {"cursor": [0.56, 0.45]}, {"wait": "contact", "timeout_s": 60}, $stroke,
  {"after_frames": 3, "key": "z", "mods": ["ctrl"]}, {"wait": "edits", "timeout_s": 60},
  {"cursor": [0.46, 0.5]}, {"wait": "contact", "timeout_s": 60}, $stroke,
  {"key": "s", "mods": ["ctrl"]},
  {"after_frames": 1000000, "quit": true}
]}
EOF
echo '{"events": [{"after_frames": 2, "key": "s", "mods": ["ctrl"]}, {"after_frames": 2, "quit": true}]}' > "$out/save.json"

# 1. Sculpt, save, kill -9 while it waits.
export bin src out
xvfb-run -a -s "-screen 0 640x480x24" bash -c '
  "$bin" "$src/scenes/head.json" '"${common[*]}"' --script "$out/edits.json" --save "$out/before-kill.nrrd" \
    > "$out/killed.txt" 2>&1 &
  app=$!
  for _ in $(seq 1 1800); do grep -q "^sculpt   saved " "$out/killed.txt" && break; sleep 0.1; done
  kill -KILL "$app"; wait "$app"; echo "rc $?" > "$out/killed-rc.txt"
' || true
cat "$out/killed.txt" "$out/killed-rc.txt"
grep -q "^rc 137" "$out/killed-rc.txt" || fail "the app was not killed by SIGKILL"
grep -q "^sculpt   saved $out/before-kill.nrrd" "$out/killed.txt" || fail "the app did not save before the kill"
journals=("$out"/state/isotouch/sculpt-*.journal)
[ "${#journals[@]}" -eq 1 ] && [ -f "${journals[0]}" ] || fail "no journal left in $out/state/isotouch after the kill"
journal=${journals[0]}
edits=$(grep -c '^{"edit"' "$journal" || true)
undos=$(grep -c '^{"edit":"undo"' "$journal" || true)
[ "$edits" -gt 6 ] && [ "$undos" -eq 1 ] || fail "the journal holds $edits edits, $undos undos: the check says little"

# 2. --restore ask without a terminal: not restored, kept aside.
xvfb-run -a -s "-screen 0 640x480x24" "$bin" "$src/scenes/head.json" "${common[@]}" --restore ask \
  --script "$out/save.json" --save "$out/unrestored.nrrd" < /dev/null > "$out/ask.txt" 2>&1 || { cat "$out/ask.txt"; fail "exit $?"; }
cat "$out/ask.txt"
grep -q "^journal  restore $edits edits from [0-9][0-9]:[0-9][0-9]?" "$out/ask.txt" || fail "the question was not asked"
grep -q "^journal  not restored (no terminal to ask" "$out/ask.txt" || fail "restored without an answer"
cmp -s "$out/unrestored.nrrd" "$out/before-kill.nrrd" && fail "the unrestored volume equals the sculpted one: the edits changed nothing"
[ -f "$journal.unrestored" ] || fail "the journal not restored was not kept as $journal.unrestored"
[ ! -e "$journal" ] || fail "the clean exit did not delete $journal"

# 3. Put back, --restore yes: the volume at the kill, byte for byte.
mv "$journal.unrestored" "$journal"
xvfb-run -a -s "-screen 0 640x480x24" "$bin" "$src/scenes/head.json" "${common[@]}" --restore yes \
  --script "$out/save.json" --save "$out/restored.nrrd" > "$out/restored.txt" 2>&1 || { cat "$out/restored.txt"; fail "exit $?"; }
cat "$out/restored.txt"
grep -q "^journal  restoring $edits edits from $journal" "$out/restored.txt" || fail "the $edits edits were not restored"
cmp "$out/restored.nrrd" "$out/before-kill.nrrd" || fail "the restored volume differs from the one saved before the kill"
[ ! -e "$journal" ] || fail "the clean exit did not delete $journal"
echo "PASS sculpt journal: $edits edits ($undos undo) restored after kill -9, the volume byte for byte"
