#!/usr/bin/env bash
# `isotouch serve` takes a client's label map IMAGE with its LBMETA (as 3D Slicer sends a
# segmentation's labelmap) as the session's materials (issue 66), driven by
# igtl_session_client; the scene is the head with a "materials" section whose critical
# "bone" labels no voxel of the head (so only the client's labels can make bone critical):
#   1. a label map 3 mm off the head's grid: STATUS 10 naming the origin and both values;
#   2. a label map holding a value (3) its LBMETA does not name: STATUS 10 naming the value;
#   3. a good one (tissue = 1 where the head is >= 300, bone = 2 where >= 1150): STATUS 1
#      naming each material's label, colour (the LBMETA's RGB) and voxel count (the client's
#      own count of what it sent), bone critical
#      (the scene's material of that name lends it its fields);
#   4. carving into the skull then removes tissue but no voxel of the client's bone: the saved
#      volume against the head, voxel for voxel.
# "PASS serve labels" is printed once, last, after every check.
# Usage: cli_serve_labels.sh ISOTOUCH SCENE CLIENT OUT_DIR HEAD_MHD
set -u
source "$(dirname "$0")/serve_port.sh"
exe=$1; scene=$2; client=$3; out=$4; head=$5
[[ $out == */cli_serve_labels ]] || { echo "FAIL serve labels: OUT_DIR must end in /cli_serve_labels: $out"; exit 1; }
rm -rf "$out"; mkdir -p "$out"
export XDG_STATE_HOME="$out/state"
fail() { echo "FAIL serve labels: $*"; echo "--- client.log"; cat "$out/client.log"; echo "--- serve.log"; tail -n 30 "$out/serve.log"; exit 1; }
python3 - "$scene" "$head" "$out/labels.json" <<'PY' || exit 1
import json, sys
s = json.load(open(sys.argv[1]))
s["volume"]["path"] = sys.argv[2]
s["materials"] = {"list": [{"name": "bone", "range": [90000, 100000], "critical": True, "margin_mm": 1.0}]}
json.dump(s, open(sys.argv[3], "w"), indent=1)
PY
"$exe" serve "$out/labels.json" --port 0 --stream Stylus --save-dir "$out" --seconds 14 >"$out/serve.log" 2>&1 &
serve_pid=$!
port=$(wait_port "$out/serve.log" $serve_pid)
[[ -n $port ]] || fail "serve never said it was listening"
# RAS [mm]: outside the skull and 2.6 voxels into it (as cli_serve_session.sh).
out_p="-9.6 -102.4 121.5"; in_p="-37.12 -102.4 121.5"
# shellcheck disable=SC2086
timeout 90 "$client" 127.0.0.1 "$port" "$head" \
  lbmeta Seg 2 tissue 1 255 0 0 bone 2 230 220 200 \
  labelmap Seg 3 2 300 1150 labelmap Seg 0 3 300 1150 1500 labelmap Seg 0 2 300 1150 \
  move $out_p 0.3 move $in_p 0.5 cmd "tool carve 4 300" cmd apply wait 0.6 cmd stop cmd "save cut.mha" \
  unchanged "$out/cut.mha" 1150 >"$out/client.log" 2>&1 ||
  fail "the client failed (exit $?)"
wait $serve_pid
rc=$?
[[ $rc == 0 ]] || fail "serve exited $rc, not 0"
python3 - "$out" "$head" <<'PY' || exit 1
import re, sys
out = sys.argv[1]
log = open(f"{out}/client.log").read().splitlines()
def fail(msg):
    print("FAIL serve labels:", msg); print("\n".join(log)); sys.exit(1)
status = [l for l in log if l.startswith("STATUS")]
if len(status) != 7: fail(f"{len(status)} STATUS answers, not 7")
grid, value, taken = status[:3]
# 1. the origin along x (LPS) 3 mm off: both values named
m = re.search(r"code 10: .*origin along x is (-?[0-9.e+-]+) mm \(LPS\), the volume's (-?[0-9.e+-]+) mm", grid)
if not m: fail(f"the label map off the grid was not refused naming the origin: {grid}")
if abs(abs(float(m.group(1)) - float(m.group(2))) - 3.0) > 1e-3: fail(f"the origins named are not 3 mm apart: {grid}")
# 2. the value its LBMETA does not name
if not re.search(r"code 10: .*label value 3 .*is no label of the LBMETA", value): fail(f"value 3 not refused: {value}")
# 3. taken, with the LBMETA's names, values and colours; bone critical (the scene's)
if "code 1: label map taken: 2 materials:" not in taken: fail(f"the good label map not taken: {taken}")
t = re.search(r"tissue \(label 1, colour #ff0000, (\d+) voxels\)", taken)
b = re.search(r"bone \(label 2, colour #e6dcc8, (\d+) voxels, critical\)", taken)
if not (t and b): fail(f"names, values, colours or critical not as the LBMETA and scene say: {taken}")
sent = [l for l in log if l.startswith("labelmap Seg: voxels")]
if len(sent) != 3: fail(f"{len(sent)} label maps sent, not 3")
counts = [int(x) for x in sent[2].split()[3:]]  # the good one's voxels of value 0, 1, 2, counted by the client
if [int(t.group(1)), int(b.group(1))] != counts[1:]: fail(f"the voxels named {taken} are not the {counts[1:]} sent")
if not all("code 1:" in s for s in status[3:]): fail(f"a command failed: {status[3:]}")
# 4. the carve removed tissue, never the client's bone (the head's voxels >= 1150)
u = re.search(r"unchanged .*: (\d+) voxels differ where BASE >= 1150, (\d+) below", "\n".join(log))
if not u: fail("no comparison")
if int(u.group(1)) != 0: fail(f"{u.group(1)} bone voxels (critical) were removed")
if int(u.group(2)) < 1: fail("the carve removed nothing at all: the test shows nothing")
serve = open(f"{out}/serve.log").read()
if "materials client" not in serve or "from label map IMAGE 'Seg'" not in serve: fail("no materials line in the log")
if "images taken 0, label maps taken 1, refused 2 messages" not in serve: fail("the served line does not count 1 label map taken, 2 refused")
print(f"labels ok: tissue {t.group(1)} and bone {b.group(1)} voxels; carving changed {u.group(2)} voxels, no bone")
PY
echo "PASS serve labels"
