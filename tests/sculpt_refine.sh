#!/usr/bin/env bash
# A view that stops after moving frames drawn at a lower scale is refined to full resolution
# over the next frames, a band of rows each, and the frame after the last band reuses the
# bands' picture (docs/user-guide.md, frame budget). Under Xvfb, wall clock (the budget needs
# it), a budget of 2 ms so that the orbit's frames are drawn at the smallest scale: the log
# must show one refinement started and finished, at least two band frames, and the frame
# after it reusing the picture; with --frame-budget-ms 0 none. The script quits 260 frames
# after the orbit: a band holds at least one row, so the 240 rows are refined by then
# whatever the bands cost.
# Usage: sculpt_refine.sh SCULPT_BIN SOURCE_DIR [OUT_DIR]. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 src=$2
out=${3:-$(mktemp -d)}
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"
  exit 77
fi
mkdir -p "$out"
run() {  # run NAME BUDGET_MS
  set +e
  xvfb-run -a "$bin" "$src/tests/sculpt/head-sculpt.json" --size 320 --no-slices --stats \
    --script "$src/tests/sculpt/orbit-still.json" --frame-budget-ms "$2" > "$out/$1.txt" 2>&1
  local rc=$?
  set -e
  [ "$rc" = 0 ] || { cat "$out/$1.txt"; echo "FAIL: isotouch-sculpt --frame-budget-ms $2 exited $rc"; exit 1; }
}
figures() {  # figures NAME: "started finished reused bands"
  python3 - "$out/$1.txt" <<'PY'
import re, sys
log = open(sys.argv[1]).read()
m = re.search(r"^stats    still views refined over frames: (\d+) started, (\d+) finished, (\d+) followed by", log, re.M)
b = re.search(r"^stats      frames refining a still view \(a band of rows each\): n (\d+),", log, re.M)
if not m:
    sys.exit("FAIL: no 'still views refined' line in " + sys.argv[1])
print(m.group(1), m.group(2), m.group(3), b.group(1) if b else 0)
PY
}
run budget 2
read -r started finished reused bands <<< "$(figures budget)"
echo "budget 2 ms: $started started, $finished finished, $reused reused, $bands band frames"
[ "$started" -ge 1 ] && [ "$finished" = "$started" ] && [ "$reused" = "$finished" ] && [ "$bands" -ge 2 ] ||
  { grep -E "^stats" "$out/budget.txt"; echo "FAIL: the still view was not refined over frames and reused"; exit 1; }
run none 0
read -r started finished reused bands <<< "$(figures none)"
[ "$started" = 0 ] && [ "$bands" = 0 ] || { echo "FAIL: refined without a frame budget ($started, $bands band frames)"; exit 1; }
echo "PASS sculpt still refinement"
