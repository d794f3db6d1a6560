#!/usr/bin/env bash
# `isotouch serve`'s edit journal through a kill -9 (issue 62): a client carves two strokes
# into the head and undoes the second, saves (`save carved.mha`: the volume at the kill,
# written by serve itself), and serve is killed with SIGKILL. Its journal
# ($XDG_STATE_HOME/isotouch/serve-CRC.journal) holds the edits and the undo; serve started
# again restores them by default ("restore N edits from HH:MM?" and what was done in the
# log): its `save restored.mha` equals carved.mha byte for byte and differs from the head
# (the client's comparison); stopped by SIGTERM, it deletes the journal. The same for a
# session on a client's IMAGE: restored when the same IMAGE is sent to the next serve.
# (A session an `isovalue V` rebuilt: see the last part.)
# Where the first press carved nothing because it never pressed (no brush of its stroke over
# the carve's force threshold: the client's stream went stale under load and the renderer, reset with the
# probe in the bone, rightly felt nothing from inside), the restore's comparison with the head
# says nothing: not judged, "SKIP serve journal", exit 77 (ctest: skipped).
# The client's first message is the tool command: its answer says the server reads this client
# (a serve still starting would take the poses queued in the socket at once, the probe already
# in the bone, and the renderer rightly feels no contact from inside).
# Usage: cli_serve_journal.sh ISOTOUCH SCENE CLIENT OUT_DIR HEAD_MHD
set -u
source "$(dirname "$0")/serve_port.sh"
exe=$1; scene=$2; client=$3; out=$4; head=$5
rm -rf "$out"; mkdir -p "$out"
export XDG_STATE_HOME="$out/state"
# On failure: the logs' ends, and each journal left as its edits in order (runs of a kind
# counted: which strokes the server made of the client's presses).
fail() {
  echo "FAIL serve journal: $*"
  for f in "$out"/*.log; do echo "--- $f"; tail -n 30 "$f"; done
  for j in "$out"/state/isotouch/*.journal; do
    [[ -f $j ]] && echo "--- $j: $(grep -o '^{"edit":"[a-z_]*"' "$j" | sed 's/.*:"//; s/"//' | uniq -c | tr -s ' \n' ' ')"
  done
  exit 1
}
# RAS [mm]: outside the skull and 2.6 voxels into it (as cli_serve_session.sh), at slice z 11
# and 7 slices further (z 18).
trap 'kill -KILL $(jobs -p) 2>/dev/null' EXIT  # a failed part leaves no serve running
# serve_n N HZ: the Nth serve of the head (log serveN.log), edited images sent at HZ.
serve_n() { start_serve "$out/serve$1.log" "$scene" --port 0 --stream Stylus --save-dir "$out" --image-hz "$2"; }
out_p="-9.6 -102.4 121.5"; in_p="-37.12 -102.4 121.5"; out_q="-9.6 -102.4 110.5"; in_q="-37.12 -102.4 110.5"

serve_n 1 0 || fail "serve never said it was listening"
timeout 90 "$client" 127.0.0.1 "$port" "$head" cmd "tool carve 4 300" move $out_p 0.3 move $in_p 0.5 \
  cmd apply wait 0.6 cmd stop cmd "save first.mha" move $out_q 0.3 move $in_q 0.5 cmd apply wait 0.6 cmd stop \
  cmd "save both.mha" cmd undo cmd "save carved.mha" \
  >"$out/client1.log" 2>&1 || fail "the first client failed (exit $?)"
kill -KILL $pid; wait $pid; rc=$?
[[ $rc == 137 ]] || fail "serve exited $rc, not killed"
grep -q "save carved.mha: wrote" "$out/client1.log" || fail "carved.mha was not written"
journal=$(ls "$out"/state/isotouch/serve-*.journal 2>/dev/null)
[[ -f $journal ]] || fail "no journal left after the kill"
edits=$(grep -c '^{"edit"' "$journal"); brushes=$(grep -c '^{"edit":"brush"' "$journal"); undos=$(grep -c '^{"edit":"undo"' "$journal")
(( brushes > 0 && undos == 1 )) || fail "the journal holds $brushes brushes and $undos undos: the check says little"
# One stroke per press (apply ... stop): a carve breaking through under the still probe loses
# contact for a moment and goes on with the same stroke (the undo takes back the whole press).
strokes=$(grep -c '^{"edit":"begin_stroke"' "$journal")
(( strokes == 2 )) || fail "the journal holds $strokes strokes for the client's 2 presses"
cmp -s "$out/first.mha" "$out/carved.mha" || fail "the undo did not give the first stroke back"
# The first stroke's largest brush force over the carve's threshold [N] (its brushes before
# its end_stroke; the carve removes at rate x max(0, |F| - threshold)): 0 when it never pressed.
first_force=$(python3 -c '
import json, sys
top = 0.0
for line in open(sys.argv[1]):
    if line.startswith("{\"edit\""):
        e = json.loads(line)
        if e["edit"] == "end_stroke": break
        if e["edit"] == "brush":
            b = e["brush"]
            top = max(top, b.get("force_n", 0.0) - b.get("force_threshold_n", 0.0))
print(top)' "$journal")
cmp -s "$out/both.mha" "$out/carved.mha" && fail "the second stroke changed nothing: the undo says little"

serve_n 2 4 || fail "serve did not start again"
timeout 90 "$client" 127.0.0.1 "$port" "$head" cmd "save restored.mha" compare "$out/restored.mha" \
  >"$out/client2.log" 2>&1 || fail "the second client failed (exit $?)"
kill -TERM $pid; wait $pid; rc=$?
[[ $rc == 143 ]] || fail "serve exited $rc after SIGTERM, not 143"
grep -q "^journal  restore $edits edits from [0-9][0-9]:[0-9][0-9]?" "$out/serve2.log" || fail "the restore was not offered for $edits edits"
grep -q "^journal  restoring $edits edits from $journal" "$out/serve2.log" || fail "the $edits edits were not restored"
cmp "$out/restored.mha" "$out/carved.mha" || fail "restored.mha differs from carved.mha (the volume at the kill)"
carved=$(sed -n "s|^compare $out/restored.mha: \([0-9]*\) voxels differ.*|\1|p" "$out/client2.log")
if (( ${carved:-0} < 10 )); then
  if [[ $first_force == 0.0 ]] && ! cmp -s "$out/both.mha" "$out/carved.mha"; then
    echo "SKIP serve journal: the first press never pressed (no brush of its stroke over the carve's threshold; the second carved): the restore's comparison with the head says nothing"
    exit 77
  fi
  fail "the restored volume differs from the head in ${carved:-no} voxels (the first press's largest force over the threshold $first_force N)"
fi
[[ ! -e $journal ]] || fail "the journal was not deleted when serve stopped"
echo "ok serve journal: $edits edits ($brushes brushes, 1 undo) restored after kill -9, byte for byte ($carved voxels carved)"

# A session on a client's IMAGE (Slicer's way) keeps its edits through a kill -9 too: the
# journal of the IMAGE's volume is restored when the same IMAGE is sent to the next serve.
serve_n 3 0 || fail "serve did not start a third time"
# The same IMAGE sent again mid-session starts its session and journal afresh (one file).
timeout 90 "$client" 127.0.0.1 "$port" "$head" ball Ball 48 15 20 move 0 0 24 0.4 move 0 0 13 0.6 \
  cmd "tool carve 4 300" cmd apply wait 0.6 cmd stop ball Ball 48 15 20 move 0 0 24 0.4 move 0 0 13 0.6 \
  cmd apply wait 0.6 cmd stop cmd "save ballcarved.mha" \
  >"$out/client3.log" 2>&1 || fail "the IMAGE client failed (exit $?)"
(( $(grep -c "volume taken" "$out/client3.log") == 2 )) || fail "the IMAGE was not taken twice"
kill -KILL $pid; wait $pid
grep -q "save ballcarved.mha: wrote" "$out/client3.log" || fail "ballcarved.mha was not written"
left=( "$out"/state/isotouch/serve-*.journal )
(( ${#left[@]} == 1 )) && [[ -f ${left[0]} ]] || fail "not one journal left after the kill: ${left[*]}"
ball_journal=${left[0]}
ball_edits=$(grep -c '^{"edit"' "$ball_journal"); ball_brushes=$(grep -c '^{"edit":"brush"' "$ball_journal")
(( ball_brushes > 0 )) || fail "the IMAGE session's journal holds no brush: the check says little"
grep -q "igtl:Ball" "$ball_journal" || fail "the journal does not name the IMAGE it belongs to"
serve_n 4 0 || fail "serve did not start a fourth time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ball Ball 48 15 20 cmd "save ballrestored.mha" \
  >"$out/client4.log" 2>&1 || fail "the second IMAGE client failed (exit $?)"
kill -TERM $pid; wait $pid
grep -q "^journal  restoring $ball_edits edits from $ball_journal" "$out/serve4.log" ||
  fail "the IMAGE session's $ball_edits edits were not restored when the IMAGE came again"
cmp "$out/ballrestored.mha" "$out/ballcarved.mha" || fail "ballrestored.mha differs from ballcarved.mha (the volume at the kill)"
[[ ! -e $ball_journal ]] || fail "the IMAGE session's journal was not deleted when serve stopped"
echo "ok serve journal: an IMAGE session's $ball_edits edits restored after kill -9 when the IMAGE came again, byte for byte"

# An `isovalue V` rebuilds the session on its edited volume (the undo history starts afresh):
# its edits, before and after the change, go on being journaled in the IMAGE's journal, and
# the next serve given the same IMAGE restores the session at V. A stroke carved at the
# image's own isovalue (300 HU: bone), `isovalue -500` (the tissue's surface), an undo (the
# rebuilt session has nothing to undo: a restore that undid the first stroke would differ),
# a second stroke on another side; then kill -9.
serve_n 5 0 || fail "serve did not start a fifth time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ball Ball 48 15 20 move 0 0 24 0.4 move 0 0 13 0.6 \
  cmd "tool carve 4 300" cmd apply wait 0.6 cmd stop cmd "save isofirst.mha" cmd "isovalue -500" cmd undo \
  move 24 0 0 0.4 move 13 0 0 0.6 cmd apply wait 0.6 cmd stop cmd "save isocarved.mha" \
  >"$out/client5.log" 2>&1 || fail "the isovalue client failed (exit $?)"
kill -KILL $pid; wait $pid
grep -q "isovalue -500: done" "$out/client5.log" || fail "the isovalue -500 was not taken"
grep -q "save isocarved.mha: wrote" "$out/client5.log" || fail "isocarved.mha was not written"
cmp -s "$out/isofirst.mha" "$out/isocarved.mha" && fail "nothing was carved after the isovalue: the check says little"
left=( "$out"/state/isotouch/serve-*.journal )
(( ${#left[@]} == 1 )) && [[ -f ${left[0]} ]] || fail "not one journal left after the kill past an isovalue: ${left[*]}"
iso_journal=${left[0]}
[[ $iso_journal == "$ball_journal" ]] || fail "the journal is not the IMAGE's ($iso_journal, not $ball_journal)"
iso_edits=$(grep -c '^{"edit"' "$iso_journal"); iso_undos=$(grep -c '^{"edit":"undo"' "$iso_journal")
head -n 1 "$iso_journal" | grep -q '"isovalue":{"tau":-500' || fail "the journal's header does not hold the isovalue -500"
(( iso_undos == 1 )) || fail "the journal holds $iso_undos undos, not the one after the isovalue"
serve_n 6 0 || fail "serve did not start a sixth time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" ball Ball 48 15 20 cmd "save isorestored.mha" \
  >"$out/client6.log" 2>&1 || fail "the client after the isovalue's kill failed (exit $?)"
kill -TERM $pid; wait $pid
grep -q "^journal  restoring $iso_edits edits from $iso_journal" "$out/serve6.log" ||
  fail "the $iso_edits edits around the isovalue were not restored when the IMAGE came again"
grep -q "volume taken: 48 x 48 x 48; isovalue -500 " "$out/client6.log" ||
  fail "the restored session does not run at the isovalue -500 (the client was told: $(grep 'volume taken' "$out/client6.log"))"
cmp "$out/isorestored.mha" "$out/isocarved.mha" || fail "isorestored.mha differs from isocarved.mha (the volume at the kill)"
[[ ! -e $iso_journal ]] || fail "the journal was not deleted when serve stopped"
echo "ok serve journal: the IMAGE session's $iso_edits edits across an isovalue change restored at -500, byte for byte"

# The same for the scene's volume: a stroke at the scene's 1150, `isovalue 500`, an undo and a
# stroke after it, kill -9; the next serve of the scene restores the session at 500 (not the
# scene's 1150), every edit.
serve_n 7 0 || fail "serve did not start a seventh time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" cmd "tool carve 4 300" move $out_p 0.3 move $in_p 0.5 \
  cmd apply wait 0.6 cmd stop cmd "save scenefirst.mha" cmd "isovalue 500" cmd undo \
  move $out_q 0.3 move $in_q 0.5 cmd apply wait 0.6 cmd stop cmd "save scenecarved.mha" \
  >"$out/client7.log" 2>&1 || fail "the scene's isovalue client failed (exit $?)"
kill -KILL $pid; wait $pid
grep -q "isovalue 500: done" "$out/client7.log" || fail "the isovalue 500 was not taken"
grep -q "save scenecarved.mha: wrote" "$out/client7.log" || fail "scenecarved.mha was not written"
cmp -s "$out/scenefirst.mha" "$out/scenecarved.mha" && fail "nothing was carved after the scene's isovalue: the check says little"
[[ -f $journal ]] || fail "no journal of the scene's volume left after the kill past an isovalue"
scene_edits=$(grep -c '^{"edit"' "$journal")
head -n 1 "$journal" | grep -q '"isovalue":{"tau":500' || fail "the scene journal's header does not hold the isovalue 500"
serve_n 8 0 || fail "serve did not start an eighth time"
timeout 90 "$client" 127.0.0.1 "$port" "$head" cmd "save scenerestored.mha" >"$out/client8.log" 2>&1 ||
  fail "the client after the scene's kill failed (exit $?)"
kill -TERM $pid; wait $pid
grep -q "^journal  restoring $scene_edits edits from $journal" "$out/serve8.log" ||
  fail "the scene's $scene_edits edits around the isovalue were not restored"
grep -q "^journal  restored $scene_edits edits at isovalue 500 (inside above)" "$out/serve8.log" ||
  fail "the restored scene session was not built at the isovalue 500"
cmp "$out/scenerestored.mha" "$out/scenecarved.mha" || fail "scenerestored.mha differs from scenecarved.mha (the volume at the kill)"
[[ ! -e $journal ]] || fail "the scene's journal was not deleted when serve stopped"
echo "PASS serve journal: the sessions' edits restored after kill -9, byte for byte ($edits and $ball_edits edits; $iso_edits on an IMAGE and $scene_edits on the scene across an isovalue change)"
