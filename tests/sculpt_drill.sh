#!/usr/bin/env bash
# The sculpting app's scripted drill (tests/sculpt/drill.json on scenes/sphere.json, a solid
# ball of 1 mm voxels, on the simulated clock): a drill brush of radius 3 mm is felt as the
# spherical tool of 3 mm, the brush cuts 3 mm plus at most half a voxel, the burr drills a
# channel and comes out of it cleanly. Asserted on what the app printed (its log file):
# - the tool the servo renders while drilling (the radius the servo thread applied) is the
#   brush's, and the cutting brush's margin is at most half a voxel;
# - the channel, measured on the edited volume (eval::measure_channel), is open to at least
#   90 % of the burr's radius and no wider than the cutting brush, over at least 5 slices;
# - the lift (the hand pulled 20 mm back out along the channel) touched the channel's walls
#   and never pulled the burr into the hole by more than 5 % of the force limit
#   (lift_max_inward_force_n <= 0.165 N at 3.3 N);
# - --point-probe feels the point and cuts the brush's own radius (no margin); --help names it.
# Usage: sculpt_drill.sh SCULPT_BIN SOURCE_DIR OUT_DIR. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 src=$2 out=$3
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"
  exit 77
fi
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"
mkdir -p "$out/burr" "$out/point"
"$bin" --help > "$out/help.txt" 2>&1 || true
grep -q -- "--point-probe" "$out/help.txt" || fail "--help does not name --point-probe"
drill_run() {  # drill_run DIR [ARGS...]
  local dir=$1
  shift
  set +e
  timeout 300 xvfb-run -a -s "-screen 0 1280x1024x24" "$bin" "$src/scenes/sphere.json" --script "$src/tests/sculpt/drill.json" \
    --screenshot "$dir/last.png" --size 320 --no-overlay --sim-clock --stats "$@" > "$dir/log.txt" 2>&1
  local rc=$?
  set -e
  grep -v "^stats    " "$dir/log.txt"
  [ "$rc" -eq 0 ] || fail "isotouch-sculpt exited $rc ($dir/log.txt)"
}
# "drill    burr radius B mm, cutting brush C mm (margin M mm, V voxel); ..."
field() {  # field FILE SED-EXPRESSION: the first line's match
  sed -n "$2" "$1" | head -1
}
drill_run "$out/burr"
log="$out/burr/log.txt"
grep -q "^sculpt   tool felt as a sphere of the carve or drill brush's radius" "$log" || fail "the tool is not felt as a sphere"
burr=$(field "$log" 's/^drill    burr radius \([0-9.]*\) mm, .*/\1/p')
cut=$(field "$log" 's/^drill    burr radius [0-9.]* mm, cutting brush \([0-9.]*\) mm .*/\1/p')
margin_vox=$(field "$log" 's/^drill    .*(margin [-0-9.]* mm, \([-0-9.]*\) voxel).*/\1/p')
open=$(field "$log" 's/^drill    channel: narrowest open radius \([0-9.]*\) mm .*/\1/p')
slices=$(field "$log" 's/^drill    channel: .* mm along the path, \([0-9]*\) slices$/\1/p')
contact=$(field "$log" 's/^drill    lift: [0-9]* ticks after the button came up, \([0-9]*\) in contact.*/\1/p')
inward=$(field "$log" 's/^drill    lift: .*lift_max_inward_force_n \([0-9.]*\) N .*/\1/p')
echo "burr $burr mm, brush $cut mm (margin $margin_vox voxel), channel $open mm over $slices slices; lift: $contact contact ticks, max inward $inward N"
[ -n "$burr" ] && [ -n "$cut" ] && [ -n "$margin_vox" ] && [ -n "$open" ] && [ -n "$slices" ] && [ -n "$contact" ] && [ -n "$inward" ] ||
  fail "the drill's figures are missing from $log"
awk -v b="$burr" 'BEGIN { exit !(b == 3.0) }' || fail "the servo felt a burr of $burr mm, not the brush's 3 mm"
awk -v m="$margin_vox" 'BEGIN { exit !(m >= 0 && m <= 0.5) }' || fail "the cutting brush's margin is $margin_vox voxel (at most 0.5)"
awk -v o="$open" -v b="$burr" -v c="$cut" 'BEGIN { exit !(o >= 0.9 * b && o <= c) }' ||
  fail "the channel's narrowest open radius $open mm is not within [0.9 x $burr, $cut] mm"
[ "$slices" -ge 5 ] || fail "the channel was measured over $slices slices: the drill hardly went in"
[ "$contact" -gt 0 ] || fail "the lift never touched the channel: the check says little"
awk -v f="$inward" 'BEGIN { exit !(f <= 0.165) }' || fail "the lift pulled the burr into the hole with $inward N (> 0.165 N, 5 % of 3.3 N)"
# The point, for comparison: felt as the point, the brush its own radius.
drill_run "$out/point" --point-probe
plog="$out/point/log.txt"
grep -q "^sculpt   tool felt as the point (--point-probe)" "$plog" || fail "--point-probe does not feel the point"
grep -q "^drill    burr radius 3.000 mm, cutting brush 3.000 mm (margin 0.000 mm" "$plog" || fail "--point-probe's brush is not its own radius"
echo "PASS sculpt drill: burr $burr mm, channel $open mm, lift max inward $inward N"
