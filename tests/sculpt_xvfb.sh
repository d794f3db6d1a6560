#!/usr/bin/env bash
# The sculpting window as a person would use it, under Xvfb with Vulkan validation on: open
# the head CT, orbit, move the probe onto the skull, carve, undo (tests/sculpt/carve.json).
# Checks (tests/sculpt/png_check.py): the surface and the probe are drawn, the carve changed
# the pixels around the brush, undo restored the picture exactly; no validation message,
# exit 0; dropped files: errors keep the old volume, a good one opens; Ctrl+S and Ctrl+E write the .vdb and the STL; a resize recreates the swapchain; the session's recording replays in `isotouch replay`.
# The carve runs on the simulated clock (--sim-clock) twice: the same recording and screenshots
# byte for byte. An undo in the frame the isovalue changes is in the volume the new session
# carries (both clocks). A dropped file that never finishes loading (a FIFO) does not keep the
# window from closing.
# With SCULPT_EXPECT_OVERLAY=1 (a build with Dear ImGui): the panels were set up and drawn
# (the screenshots are the ray caster's picture, without them), built anew in fewer frames
# than they were drawn in, and through X shared memory their layer drawn anew in fewer
# frames than showed it; --no-overlay draws none.
# Usage: sculpt_xvfb.sh SCULPT_BIN ISOTOUCH_BIN SOURCE_DIR [OUT_DIR]. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 iso=$2 src=$3
out=${4:-$(mktemp -d)}
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth); the sculpting window cannot be tested headless"
  exit 77
fi
mkdir -p "$out"
carve_run() {  # carve_run DIR: the carve script on the simulated clock, into DIR
  mkdir -p "$1"
  rm -f "$1"/{probe,before,carved,undone,last}.png "$1"/session.rec "$1"/sculpted.vdb "$1"/sculpted.stl
  xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/tests/sculpt/head-sculpt.json" --script "$src/tests/sculpt/carve.json" \
    --screenshot "$1/last.png" --record "$1/session.rec" --save "$1/sculpted.vdb" --export "$1/sculpted.stl" --size 512 \
    --validation --stats --sim-clock
}
set +e
carve_run "$out" 2>&1 | tee "$out/log.txt"
rc=${PIPESTATUS[0]}
set -e
if [ "$rc" -ne 0 ]; then echo "FAIL: isotouch-sculpt exited $rc"; exit 1; fi
grep -q "^sculpt   simulated clock: 33 servo ticks" "$out/log.txt" || { echo "FAIL: --sim-clock did not run the simulated clock"; exit 1; }
# Again: the simulated clock gives the same recording and screenshots, byte for byte.
set +e
carve_run "$out/again" > "$out/again.txt" 2>&1
rc=$?
set -e
if [ "$rc" -ne 0 ]; then cat "$out/again.txt"; echo "FAIL: isotouch-sculpt exited $rc (second run)"; exit 1; fi
for f in probe.png before.png carved.png undone.png last.png session.rec; do
  cmp -s "$out/$f" "$out/again/$f" || { echo "FAIL: $f differs between two runs on the simulated clock"; exit 1; }
done
echo "simulated clock: the recording and 5 screenshots are the same in two runs"
if grep -q "timed out\|ended before" "$out/log.txt"; then echo "FAIL: the script did not run its course"; exit 1; fi
if [ "${SCULPT_EXPECT_OVERLAY:-0}" = 1 ]; then
  grep -q "^overlay  Dear ImGui [0-9.]*$" "$out/log.txt" || { echo "FAIL: the Dear ImGui overlay was not set up"; exit 1; }
  grep -q "^stats    overlay Dear ImGui [0-9.]* drawn in [1-9][0-9]* of " "$out/log.txt" ||
    { echo "FAIL: the Dear ImGui overlay was not drawn"; exit 1; }
  # The panels are drawn every frame but built anew only when what they show changes (their
  # figures every 15 frames, the H key, the resize) and in the two frames after.
  read -r drawn built layer < <(sed -n 's/^stats    overlay Dear ImGui [0-9.]* drawn in \([0-9]*\) of [0-9]* frames, built anew in \([0-9]*\)\(, their layer drawn anew in \([0-9]*\)\)\{0,1\}$/\1 \2 \4/p' "$out/log.txt")
  [ -n "${built:-}" ] && [ "$built" -gt 0 ] && [ "$built" -lt "$drawn" ] ||
    { echo "FAIL: the panels were built anew in ${built:-?} frames, not fewer than the ${drawn:-?} that drew them (a build every frame)"; exit 1; }
  # Through X shared memory (the default here) the panels' layer is drawn anew only when the
  # drawing changed (a build, a remade window), not in every frame that shows it.
  if grep -q "present mode X11 shared memory$" "$out/log.txt"; then
    [ -n "${layer:-}" ] && [ "$layer" -gt 0 ] && [ "$layer" -lt "$drawn" ] ||
      { echo "FAIL: the panels' layer was drawn anew in ${layer:-no} frames of the ${drawn} that showed it"; exit 1; }
  fi
fi
# Ctrl+S and Ctrl+E after the carve: the edited volume as .vdb, its isosurface as STL.
for f in sculpted.vdb sculpted.stl; do
  [ -s "$out/$f" ] || { echo "FAIL: $f was not written"; exit 1; }
done
if grep -q "save failed\|export failed" "$out/log.txt"; then echo "FAIL: save or export failed"; exit 1; fi
# The window was resized at the end: the swapchain was recreated and the last frame has the new size.
grep -q "swapchain recreated [1-9]" "$out/log.txt" || { echo "FAIL: the resize did not recreate the swapchain"; exit 1; }
python3 - "$out/last.png" <<'PY' || { echo "FAIL: last.png does not have the resized window's size"; exit 1; }
import struct, sys
w, h = struct.unpack(">II", open(sys.argv[1], "rb").read()[16:24])
print(f"last.png: {w}x{h}")
sys.exit(0 if (w, h) == (400, 300) else 1)
PY
python3 "$src/tests/sculpt/png_check.py" "$out" 0.5 0.45 || { echo "FAIL: screenshots"; exit 1; }
# Dropped files (tests/sculpt/drop.json): a scene that is not one and a missing volume show
# their error and the head stays; the chest's DICOM series folder loads on a background thread
# while the head session goes on drawing, then opens in a new session (the head's isovalue).
set +e
xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/scenes/head.json" --script "$src/tests/sculpt/drop.json" \
  --frames 10 --size 320 --validation --no-overlay > "$out/drop.txt" 2>&1
rc=$?
set -e
cat "$out/drop.txt"
if [ "$rc" -ne 0 ]; then echo "FAIL: isotouch-sculpt with dropped files exited $rc"; exit 1; fi
[ "$(grep -c "cannot open .*(keeping head)" "$out/drop.txt")" -eq 2 ] || { echo "FAIL: a bad drop did not keep the old volume"; exit 1; }
grep -q "^sculpt   opening .*dicom-5mm (loaded in [0-9.]* s, [1-9][0-9]* frames drawn meanwhile)" "$out/drop.txt" ||
  { echo "FAIL: the dropped series did not load while the session went on drawing"; exit 1; }
grep -q "^sculpt   sculpt: 512x512x64 voxels" "$out/drop.txt" || { echo "FAIL: the dropped chest series did not open"; exit 1; }
if grep -q "^overlay  " "$out/drop.txt"; then echo "FAIL: --no-overlay still set up the overlay"; exit 1; fi
# A pinned servo (SCHED_FIFO granted, two CPUs or more) has the X server kept off its CPU.
if [ "$(nproc)" -ge 2 ] && ! grep -q "SCHED_FIFO .* refused\|pinning to CPU .* refused" "$out/drop.txt"; then
  grep -q "^servo    display server Xvfb (pid [0-9]*, [0-9]* threads\?) kept off CPU [0-9]*, the servo's" "$out/drop.txt" ||
    { echo "FAIL: the X server was not kept off the servo's CPU"; exit 1; }
fi
# The isovalue slider (tests/sculpt/iso.json): let go at 500 HU, the session restarts there
# with the volume as edited; the skin (500) covers more pixels than the skull (1150), and the
# probe finds contact on the new surface, so the servo follows the new isovalue too.
mkdir -p "$out/iso"
rm -f "$out"/iso/*.png
set +e
xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/scenes/head.json" --script "$src/tests/sculpt/iso.json" \
  --screenshot "$out/iso/last.png" --size 320 --validation --no-overlay > "$out/iso.txt" 2>&1
rc=$?
set -e
cat "$out/iso.txt"
if [ "$rc" -ne 0 ]; then echo "FAIL: isotouch-sculpt with an isovalue change exited $rc"; exit 1; fi
if grep -q "timed out\|ended before" "$out/iso.txt"; then echo "FAIL: the isovalue script did not run its course"; exit 1; fi
grep -q "^sculpt   isovalue 500: the session restarts" "$out/iso.txt" || { echo "FAIL: the isovalue change did not restart the session"; exit 1; }
grep -q "^sculpt   head: 64x64x93 voxels, isovalue 500," "$out/iso.txt" || { echo "FAIL: the restarted session is not at isovalue 500"; exit 1; }
python3 - "$src/tests/sculpt/png_check.py" "$out/iso" <<'PY' || { echo "FAIL: the picture did not follow the isovalue"; exit 1; }
import collections, importlib.util, sys
spec = importlib.util.spec_from_file_location("png_check", sys.argv[1])
m = importlib.util.module_from_spec(spec)
spec.loader.exec_module(m)
lit = {}
for n in ("iso-before", "iso-after"):
    w, h, px = m.read_png(f"{sys.argv[2]}/{n}.png")
    bg = collections.Counter(px).most_common(1)[0][0]
    lit[n] = sum(p != bg for p in px) / len(px)
print(f"lit pixels: skull (1150) {lit['iso-before']:.1%}, skin (500) {lit['iso-after']:.1%}")
sys.exit(0 if lit["iso-after"] > 1.1 * lit["iso-before"] else 1)
PY
# Ctrl+Z in the frame the isovalue changes (tests/sculpt/iso-undo.json): the undo is applied
# before the new session takes the volume, so after going back to 1150 the picture is the one
# before the carve, exactly (simulated clock: always; real time: the restart waits for it).
# In real time a run was seen (once, in a full suite at -j2) whose carved screenshot equalled
# the one before, its script waits all met: the cause was not found. Such a run says nothing
# about the undo, so it is tried again (at most 3 runs), and said so.
for clock in --sim-clock --real-time; do
  d="$out/iso-undo$clock"
  mkdir -p "$d"
  tries=1; [ "$clock" = --real-time ] && tries=3
  for try in $(seq 1 "$tries"); do
    rm -f "$d"/*.png
    set +e
    xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/scenes/head.json" --script "$src/tests/sculpt/iso-undo.json" \
      --screenshot "$d/last.png" --size 320 --validation --no-overlay $([ "$clock" = --sim-clock ] && echo --sim-clock) > "$d/log.txt" 2>&1
    rc=$?
    set -e
    if [ "$rc" -ne 0 ]; then cat "$d/log.txt"; echo "FAIL: isotouch-sculpt (iso-undo $clock) exited $rc"; exit 1; fi
    if grep -q "timed out\|ended before" "$d/log.txt"; then cat "$d/log.txt"; echo "FAIL: the iso-undo script did not run its course ($clock)"; exit 1; fi
    ! cmp -s "$d/iso-undo-before.png" "$d/iso-undo-carved.png" && break
    cat "$d/log.txt"
    [ "$try" -lt "$tries" ] || { echo "FAIL: the carve changed nothing ($clock, $tries runs): the check says little"; exit 1; }
    echo "note: the carve changed nothing in run $try ($clock): run again"
  done
  cmp -s "$d/iso-undo-before.png" "$d/iso-undo-after.png" ||
    { echo "FAIL: the undo in the isovalue's frame was lost in the restart ($clock)"; exit 1; }
done
echo "iso-undo: the undo in the isovalue's frame is in the restarted volume (both clocks)"
# A dropped FIFO named as a volume (.mhd) is refused at once, before open(), naming it; the
# head stays. A dropped file whose reader blocks (a FIFO named as a scene, .json: open() waits
# for a writer that never comes): quitting abandons the load instead of waiting for it, and
# exits 0.
rm -f "$out/slow.json" "$out/fifo.mhd"
mkfifo "$out/slow.json" "$out/fifo.mhd"
printf '{"events": [{"drop": "%s"}, {"after_frames": 3, "drop": "%s"}, {"after_frames": 3, "quit": true}]}\n' \
  "$out/fifo.mhd" "$out/slow.json" > "$out/drop-slow.json"
set +e
timeout 120 xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/scenes/head.json" --script "$out/drop-slow.json" \
  --size 320 --no-overlay > "$out/drop-slow.txt" 2>&1
rc=$?
set -e
cat "$out/drop-slow.txt"
# A reader still blocked (the app waited and was killed): a writer releases it.
[ "$rc" -eq 124 ] && timeout 5 bash -c ": > '$out/slow.json'; : > '$out/fifo.mhd'"
rm -f "$out/slow.json" "$out/fifo.mhd"
if [ "$rc" -ne 0 ]; then echo "FAIL: quitting while a file loads exited $rc (124: it waited for the load)"; exit 1; fi
grep -q "cannot open .*fifo.mhd: not a regular file (a FIFO): a volume is read from a regular file.*(keeping head)" "$out/drop-slow.txt" ||
  { echo "FAIL: the dropped FIFO was not refused, named, at once"; exit 1; }
grep -q "^sculpt   abandoned loading .*slow.json (still reading after" "$out/drop-slow.txt" ||
  { echo "FAIL: the blocked load was not abandoned"; exit 1; }
set +e
"$iso" replay "$out/session.rec" --quiet > "$out/replay.log" 2>&1
rc=$?
set -e
cat "$out/replay.log"
if [ "$rc" -ne 0 ] || ! grep -q "^IDENTICAL" "$out/replay.log"; then echo "FAIL: the recording does not replay identically"; exit 1; fi
echo "PASS sculpt: screenshots in $out"
