#!/usr/bin/env bash
# isotouch-sculpt's usage errors, before any window opens (no display needed): each exits 2
# (docs/exit-codes.md) and says how to do it right.
#  1. --record with a volume: a recording names its scene, so the message names
#     `isotouch run VOLUME --out DIR`, which writes DIR/scene.json;
#  2. --mesh-units other than mm or m;
#  3. --size that is not W or WxH within 64-4096 a side and 4096x3072 pixels: the message
#     names --size, the value and what is wrong; with xvfb-run, --size 320x180 and --size 320
#     open windows of 320x180 and 320x240 (the last frame's PNG).
# Usage: sculpt_usage.sh SCULPT_BIN SOURCE_DIR OUT_DIR
set -u
bin=$1 src=$2 out=$3
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
vol=$src/data/ct-head-headsq/headsq_64x64x93_int16.mhd

"$bin" "$vol" --record "$out/x.rec" > "$out/record.log" 2>&1
rc=$?
cat "$out/record.log"
[ "$rc" = 2 ] || fail "--record with a volume: exit $rc, expected 2 (usage)"
grep -q -- "--record.*needs a scene file" "$out/record.log" || fail "no line saying --record needs a scene"
grep -q "isotouch run $vol --out out/headsq_64x64x93_int16\` writes out/headsq_64x64x93_int16/scene.json" \
  "$out/record.log" || fail "the message does not name 'isotouch run VOLUME --out DIR' and its scene.json"
[ -e "$out/x.rec" ] && fail "a recording was started"

"$bin" "$vol" --mesh-units cm > "$out/units.log" 2>&1
rc=$?
cat "$out/units.log"
[ "$rc" = 2 ] || fail "--mesh-units cm: exit $rc, expected 2 (usage)"
grep -q -- "--mesh-units: must be mm or m, got cm" "$out/units.log" || fail "the error does not name --mesh-units and the value"
size_error() {  # size_error VALUE [WHY]: the message names --size, the value as given and WHY
  "$bin" "$vol" --size "$1" > "$out/size.log" 2>&1
  local rc=$? want="got '$1'${2:+: $2}"
  cat "$out/size.log"
  [ "$rc" = 2 ] || fail "--size $1: exit $rc, expected 2 (usage)"
  grep -F -- "--size: must be W (height 3/4 of it) or WxH in pixels," "$out/size.log" | grep -F -- "$want" |
    grep -q -- "'${2:+: $2}\$" || fail "--size $1: the error does not name --size, the value and what is wrong ($want)"
}
size_error 1920x
size_error x1080
size_error '1920*1080'
size_error 1920x1080x2
size_error -640
size_error 640.5
size_error 32x480 "width 32 outside 64 to 4096"
size_error 1920x40 "height 40 outside 48 to 4096"
size_error 4096x4096 "16777216 pixels, more than 4096x3072 = 12582912"
size_error 63 "width 63 outside 64 to 4096"
if command -v xvfb-run >/dev/null; then
  for size in 320x180 320; do
    XDG_STATE_HOME=$out/state xvfb-run -a "$bin" "$src/tests/sculpt/head-sculpt.json" --size $size --frames 3 --no-slices --no-overlay --no-journal \
      --screenshot "$out/size-$size.png" > "$out/size-$size.log" 2>&1 || { cat "$out/size-$size.log"; fail "--size $size: exit $?"; }
    got=$(python3 -c 'import struct, sys; print("%dx%d" % struct.unpack(">II", open(sys.argv[1], "rb").read()[16:24]))' "$out/size-$size.png")
    want=$([ $size = 320 ] && echo 320x240 || echo $size)
    [ "$got" = "$want" ] || fail "--size $size: the last frame is $got, expected $want"
    echo "--size $size: a $got window"
  done
else
  echo "(no xvfb-run: the window sizes not checked)"
fi
echo "PASS sculpt usage errors"
