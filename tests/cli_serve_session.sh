#!/usr/bin/env bash
# `isotouch serve` driven the way 3D Slicer drives a session, by igtl_session_client (built on
# the OpenIGTLink library's messages), the tool held 2.6 voxels into the skull from outside:
#   1. the force follows the STRING isovalue: about 1.5 N at 1150 (bone), zero at 1900 (only
#      the densest voxel, deeper than the tool, is inside), the force limit 3.3 N at 500;
#   2. bad commands (not a number, an unknown tool, an isovalue outside the volume's range,
#      an unknown command, a save name with a folder or of no volume format) each answered with a STATUS naming the
#      command and value; the next command is served;
#   3. carve (tool, apply, stop): the edited IMAGEs the client received, applied to the head,
#      equal the file `save` wrote, and differ from the head; undo gives the head back voxel
#      for voxel; redo the carved file again; every IMAGE in the head's place;
#   4. an IMAGE named by a LABELMETA holding values it does not name (the head), or with
#      "label" in its name and no LABELMETA, refused with a STATUS; a
#      scalar image taken, and a save right after it writes that image (not the session it
#      replaces, and not refused while the sessions change over);
#   5. a save that cannot write (its name is a folder) answered with STATUS 11; serve ends by
#      itself with exit 6 (a save failed, the session went on) and no servo faults.
# "PASS serve session" is printed once, last, after every check.
# Usage: cli_serve_session.sh ISOTOUCH SCENE CLIENT OUT_DIR HEAD_MHD
set -u
source "$(dirname "$0")/serve_port.sh"
exe=$1; scene=$2; client=$3; out=$4; head=$5
[[ $out == */cli_serve_session ]] || { echo "FAIL serve session: OUT_DIR must end in /cli_serve_session: $out"; exit 1; }
rm -rf "$out"; mkdir -p "$out/blocked.mha"  # a folder where `save blocked.mha` would write: it cannot
fail() { echo "FAIL serve session: $*"; echo "--- client.log"; cat "$out/client.log"; echo "--- serve.log"; tail -n 30 "$out/serve.log"; exit 1; }
"$exe" serve "$scene" --port 0 --stream Stylus --save-dir "$out" --image-hz 4 --seconds 16 >"$out/serve.log" 2>&1 &
serve_pid=$!
port=$(wait_port "$out/serve.log" $serve_pid)
[[ -n $port ]] || fail "serve never said it was listening"
# RAS [mm]: outside the skull (voxel x 3) and 2.6 voxels into it (x 11.6), row y 32, slice z 11
# (the head's header: LPS = (0, 0, 138) mm + (3.2 x, 3.2 y, -1.5 z) mm).
out_p="-9.6 -102.4 121.5"; in_p="-37.12 -102.4 121.5"
press="move $out_p 0.3 move $in_p 0.5 force"
# shellcheck disable=SC2086
timeout 90 "$client" 127.0.0.1 "$port" "$head" \
  $press cmd "isovalue 1900" $press cmd "isovalue 500" $press cmd "isovalue 1150" $press \
  cmd "isovalue abc" cmd "tool hammer 3" cmd "isovalue 99999" cmd "sculpt 3" cmd "save ../x.mha" cmd "save x.txt" cmd "tool carve 0" \
  cmd "tool carve 4 300" cmd apply wait 0.6 cmd stop cmd "save carved.mha" images 1 \
  compare "$out/carved.mha" compare "$head" \
  cmd undo images 1 compare "$head" cmd redo images 1 compare "$out/carved.mha" \
  labelmeta Seg image Seg image HeadLabelMap image Head2 cmd "save taken.mha" rebase compare "$out/taken.mha" \
  cmd "save blocked.mha" >"$out/client.log" 2>&1 ||
  fail "the client failed (exit $?)"
wait $serve_pid
rc=$?
[[ $rc == 6 ]] || fail "serve exited $rc, not 6 (a save command could not write)"
grep -q " 0 faults" "$out/serve.log" || fail "servo faults"
python3 - "$out" <<'PY' || exit 1
import re, sys
out = sys.argv[1]
log = open(f"{out}/client.log").read().splitlines()
def fail(msg):
    print("FAIL serve session:", msg); print("\n".join(log)); sys.exit(1)
forces = [float(l.split()[4]) for l in log if l.startswith("force ")]
if len(forces) != 4: fail(f"{len(forces)} force readings, not 4")
f1150, f1900, f500, f1150b = forces
if not 0.8 < f1150 < 2.5: fail(f"|F| {f1150} N at isovalue 1150, not the ~1.5 N of 2.6 voxels into bone")
if f1900 != 0: fail(f"|F| {f1900} N at isovalue 1900, where the tool is outside")
if abs(f500 - 3.3) > 0.01: fail(f"|F| {f500} N at isovalue 500, not the force limit 3.3 N")
if abs(f1150b - f1150) > 0.05: fail(f"|F| {f1150b} N back at 1150, not the {f1150} N of before")
status = [l for l in log if l.startswith("STATUS")]
want = [("code 1: isovalue 1900: done",), ("code 1: isovalue 500: done",), ("code 1: isovalue 1150: done",),
        ("code 10: isovalue 'abc': not a number",), ("code 10: tool kind 'hammer'",),
        ("code 10: isovalue 99999: outside the volume's value range",), ("code 12: unknown command 'sculpt'",),
        ("code 10: save name '../x.mha'",), ("code 10: save name 'x.txt': not a format",), ("code 10: tool radius '0'",),
        ("code 1: tool carve 4 300: done",), ("code 1: apply: done",), ("code 1: stop: done",),
        ("code 1: save carved.mha: wrote",), ("code 1: undo: done",), ("code 1: redo: done",),
        ("code 10: ", "igtl:Seg: label value ", "is no label of the LBMETA"), ("code 10: ", "label map"),
        ("code 1: volume taken: 64 x 64 x 93",), ("code 1: save taken.mha: wrote",), ("code 11: save blocked.mha: ",)]
if len(status) != len(want): fail(f"{len(status)} STATUS answers, not {len(want)}")
for got, w in zip(status, want):
    if not all(p in got for p in w): fail(f"STATUS '{got}' does not say {w}")
cmp = [l for l in log if l.startswith("compare ")]
def differ(i): return int(re.search(r": (\d+) voxels differ", cmp[i]).group(1))
if len(cmp) != 5: fail(f"{len(cmp)} comparisons, not 5")
if differ(0) != 0: fail("the received edits differ from the saved file: " + cmp[0])
if differ(1) < 10: fail("carving changed fewer than 10 voxels: " + cmp[1])
if differ(2) != 0: fail("after undo the received volume is not the head: " + cmp[2])
if differ(3) != 0: fail("after redo the received volume is not the saved file: " + cmp[3])
if differ(4) != 0: fail("a save after an IMAGE did not write that IMAGE: " + cmp[4])
if any("geometry ok" not in l for l in cmp): fail("an edited IMAGE not in the head's place: " + "; ".join(cmp))
images = [int(l.split()[1]) for l in log if l.startswith("images ")]
if not (images[0] >= 1 and images[1] > images[0] and images[2] > images[1]): fail(f"edited IMAGEs received: {images}")
serve = open(f"{out}/serve.log").read()
if "sent as a sub-volume" not in serve: fail("no edited sub-volume in the server's log")
print(f"session ok: |F| {f1150:.2f} / {f1900:.2f} / {f500:.2f} N at isovalues 1150 / 1900 / 500; "
      f"{differ(1)} voxels carved, equal to the saved file through {images[-1]} IMAGEs; undo and redo exact")
PY
echo "PASS serve session"
