#!/usr/bin/env bash
# What the sculpting app reads and writes, as a person would name it:
# - --save and --export write the format their name asks for (.nrrd for 3D Slicer, .obj); a
#   name of no format they write is refused before a window opens, naming it, nothing written;
# - a FIFO named as the volume is refused at once (open() would wait for a writer);
# - a session on a scene without an "edits" section (scenes/head.json's copy) recorded with
#   --record replays identically in `isotouch replay`, also after the scene file is gone.
# Usage: sculpt_files.sh SCULPT_BIN ISOTOUCH_BIN SOURCE_DIR OUT_DIR. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 iso=$2 src=$3 out=$4
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"
  exit 77
fi
rm -rf "$out"
mkdir -p "$out/scene"
fail() { echo "FAIL: $*"; exit 1; }
# Names of no format: refused before anything runs, exit non-zero, the path named.
echo kept > "$out/kept.xyz"
for args in "--save $out/kept.xyz" "--export $out/kept.xyz" "--save $out/y.mhd"; do
  set +e
  timeout 60 "$bin" "$src/scenes/head.json" $args --frames 1 > "$out/bad.txt" 2>&1
  rc=$?
  set -e
  cat "$out/bad.txt"
  [ "$rc" -ne 0 ] && [ "$rc" -ne 124 ] || fail "$args: exit $rc"
  opt=${args%% *} path=${args#* }
  grep -q -- "$opt $path: the name must end in " "$out/bad.txt" || fail "$args: the name is not refused"
done
[ "$(cat "$out/kept.xyz")" = kept ] && [ ! -e "$out/y.mhd" ] || fail "a refused name was written"
# A FIFO as the volume.
mkfifo "$out/f.mhd"
set +e
timeout 60 "$bin" "$out/f.mhd" --iso 1 --frames 1 > "$out/fifo.txt" 2>&1
rc=$?
set -e
[ "$rc" -eq 124 ] && timeout 5 bash -c ": > '$out/f.mhd'"
cat "$out/fifo.txt"
[ "$rc" -ne 0 ] && [ "$rc" -ne 124 ] || fail "a FIFO volume: exit $rc (124: it blocked in open())"
grep -q "f.mhd: not a regular file (a FIFO): a volume is read from a regular file" "$out/fifo.txt" || fail "the FIFO is not named"
# The head scene, no "edits" section, its volume named relative to the scene's folder.
sed "s#\"../data/#\"$src/data/#" "$src/scenes/head.json" > "$out/scene/head.json"
grep -q '"edits"' "$out/scene/head.json" && fail "the scene has an edits section: the check says little"
set +e
xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$out/scene/head.json" --script "$src/tests/sculpt/carve.json" \
  --screenshot "$out/last.png" --record "$out/session.rec" --save "$out/sculpted.nrrd" --export "$out/sculpted.obj" \
  --size 320 --no-overlay --sim-clock > "$out/log.txt" 2>&1
rc=$?
set -e
cat "$out/log.txt"
[ "$rc" -eq 0 ] || fail "isotouch-sculpt exited $rc"
grep -q "save failed\|export failed" "$out/log.txt" && fail "save or export failed"
[ "$(head -c 4 "$out/sculpted.nrrd")" = NRRD ] || fail "sculpted.nrrd is not NRRD: $(head -c 16 "$out/sculpted.nrrd" | od -c | head -1)"
grep -q "^v " "$out/sculpted.obj" && grep -q "^f " "$out/sculpted.obj" || fail "sculpted.obj is not OBJ text"
"$iso" check "$out/sculpted.nrrd" > "$out/check.txt" 2>&1 || { cat "$out/check.txt"; fail "isotouch check cannot read sculpted.nrrd"; }
grep -q "^recorded .*session.rec (replay: isotouch replay " "$out/log.txt" || fail "no recording was said"
edits=$(grep -c '^{"edit"' "$out/session.rec" || true)
[ "$edits" -gt 0 ] || fail "the recording holds no edit: the check says little"
rm "$out/scene/head.json"  # the scene file is gone: the recording carries its text
set +e
"$iso" replay "$out/session.rec" --quiet > "$out/replay.log" 2>&1
rc=$?
set -e
cat "$out/replay.log"
[ "$rc" -eq 0 ] && grep -q "^IDENTICAL" "$out/replay.log" || fail "the recording ($edits edits) does not replay identically (exit $rc)"
echo "PASS sculpt files: $edits edits replayed; sculpted.nrrd and sculpted.obj in $out"
