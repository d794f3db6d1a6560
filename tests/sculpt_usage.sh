#!/usr/bin/env bash
# isotouch-sculpt's usage errors, before any window opens (no display needed): each exits 2
# (docs/exit-codes.md) and says how to do it right.
#  1. --record with a volume: a recording names its scene, so the message names
#     `isotouch run VOLUME --out DIR`, which writes DIR/scene.json;
#  2. --mesh-units other than mm or m.
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
echo "PASS sculpt usage errors"
