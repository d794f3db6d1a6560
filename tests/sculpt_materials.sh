#!/usr/bin/env bash
# The sculpting app on a labelled scene (scenes/drill-tooth-labels.json: enamel, dentin and
# the critical pulp): a carve of 40 mm at the probe's contact (tests/sculpt/carve-critical.json,
# --point-probe: the brush reaches 40 mm into the tooth) is saved (Ctrl+S, --save NRRD); the
# saved volume, compared voxel by voxel with the scene's volume as loaded over the scene's
# labels (critical_voxels_check), has no critical voxel changed while voxels next to the pulp
# were removed (the brush reached it), and the log says the app cuts by material. The edited
# label map saved beside it (sculpted.seg.nrrd, 3D Slicer's form), read back by the scene's
# material names, holds the scene's labels with every removed voxel 0.
# Usage: sculpt_materials.sh SCULPT_BIN CHECK_BIN SOURCE_DIR OUT_DIR. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 check=$2 src=$3 out=$4
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"
  exit 77
fi
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"
mkdir -p "$out"
scene="$src/scenes/drill-tooth-labels.json"
set +e
timeout 300 xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$scene" --script "$src/tests/sculpt/carve-critical.json" \
  --save "$out/sculpted.nrrd" --size 320 --no-overlay --sim-clock --point-probe > "$out/log.txt" 2>&1
rc=$?
set -e
cat "$out/log.txt"
[ "$rc" -eq 0 ] || fail "isotouch-sculpt exited $rc"
grep -q "^sculpt   cuts by material (.*pulp (critical: never changed)" "$out/log.txt" || fail "the log does not say the app cuts by material"
[ -f "$out/sculpted.nrrd" ] || fail "nothing was saved"
[ -f "$out/sculpted.seg.nrrd" ] || fail "no edited label map beside the saved volume"
grep -q "^sculpt   saved $out/sculpted.nrrd and its label map $out/sculpted.seg.nrrd" "$out/log.txt" || fail "the log does not say the label map was saved"
line=$("$check" "$scene" "$out/sculpted.nrrd" "$out/sculpted.seg.nrrd") || fail "critical_voxels_check failed"
echo "$line"
read -r _ crit _ next _ changed _ removed _ wrong <<< "$line"
[ "$removed" -gt 0 ] || fail "no labelled voxel was removed: the label map check says little"
[ "$wrong" -eq 0 ] || fail "$wrong voxels of the saved label map are not the scene's labels with the removed ones 0"
[ "$changed" -gt 0 ] || fail "the carve changed nothing: the check says little"
[ "$next" -gt 0 ] || fail "no voxel next to the pulp was removed: the carve did not reach it, the check says little"
[ "$crit" -eq 0 ] || fail "$crit critical (pulp) voxels changed"
echo "PASS sculpt materials: $changed voxels carved, $next of them next to the pulp, no pulp voxel changed; label map: $removed removed voxels 0, the rest the scene's"
