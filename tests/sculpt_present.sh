#!/usr/bin/env bash
# What the X server shows in the sculpting window, read back from the server (--window-shot),
# for both ways a frame reaches the screen: X shared memory (--present shm, the default on a
# CPU device) and the Vulkan swapchain (--present swapchain). Under Xvfb with validation on.
# Checks: without panels the window holds the ray caster's picture (--screenshot) pixel for
# pixel, both ways (a swapped channel, a row pitch, a shifted row fails it); with the panels
# (a build with Dear ImGui, SCULPT_EXPECT_OVERLAY=1) the window differs from the picture where
# they are drawn, and the two ways agree within 1 per channel (the shared-memory path blends
# the panels' layer on the host); with the slice views the window holds the screenshot both
# ways, their inset over the right of the picture only; --present shm on a display without MIT-SHM fails naming it, and auto falls
# back to the swapchain saying why.
# Usage: sculpt_present.sh SCULPT_BIN SOURCE_DIR [OUT_DIR]. Exit 77 (skipped) without xvfb-run.
set -euo pipefail
bin=$1 src=$2
out=${3:-$(mktemp -d)}
if ! command -v xvfb-run >/dev/null; then
  echo "SKIP: xvfb-run is not installed (Debian: xvfb xauth)"
  exit 77
fi
mkdir -p "$out"
scene="$src/tests/sculpt/head-sculpt.json"
run() {  # run NAME XVFB_ARGS SCULPT_ARGS...: one short session, its log in $out/NAME.txt
  local name=$1 xargs=$2
  shift 2
  rm -f "$out/$name.png" "$out/$name-window.png"
  set +e
  xvfb-run -a -s "-screen 0 1280x1024x24 $xargs" "$bin" "$scene" --size "${size:-320}" --frames 4 --sim-clock --validation \
    --screenshot "$out/$name.png" --window-shot "$out/$name-window.png" "$@" > "$out/$name.txt" 2>&1
  local rc=$?
  set -e
  echo "$rc"
}
compare() {  # compare A B: "equal" or the count of differing pixels (RGB)
  python3 -c '
import sys
sys.path.insert(0, sys.argv[3])
from png_check import read_png
w1, h1, a = read_png(sys.argv[1])
w2, h2, b = read_png(sys.argv[2])
if (w1, h1) != (w2, h2):
    print(f"sizes {w1}x{h1} and {w2}x{h2}")
    sys.exit(0)
n = sum(1 for p, q in zip(a, b) if p != q)
print("equal" if n == 0 else f"{n} of {w1 * h1} pixels differ")
' "$1" "$2" "$src/tests/sculpt"
}
for p in shm swapchain; do
  rc=$(run "$p" "" --present "$p" --no-overlay --no-slices)
  [ "$rc" = 0 ] || { cat "$out/$p.txt"; echo "FAIL: --present $p exited $rc"; exit 1; }
  want="X11 shared memory"
  [ "$p" = swapchain ] && want="mailbox\|immediate\|fifo"
  grep -q "present mode \($want\)$" "$out/$p.txt" || { grep 'present mode' "$out/$p.txt"; echo "FAIL: --present $p did not present that way"; exit 1; }
  r=$(compare "$out/$p.png" "$out/$p-window.png")
  [ "$r" = equal ] || { echo "FAIL: --present $p: the window does not hold the picture: $r"; exit 1; }
  echo "--present $p: the X server's window holds the ray caster's picture pixel for pixel"
done
# The slice views' inset (their column at the window's right edge; in the screenshots too), no
# panels: the window holds the screenshot pixel for pixel both ways, and the screenshot differs
# from the run without them only on the right.
for p in shm swapchain; do
  rc=$(run "slices-$p" "" --present "$p" --no-overlay)
  [ "$rc" = 0 ] || { cat "$out/slices-$p.txt"; echo "FAIL: the slice views' run (--present $p) exited $rc"; exit 1; }
  r=$(compare "$out/slices-$p.png" "$out/slices-$p-window.png")
  [ "$r" = equal ] || { echo "FAIL: --present $p with the slice views: the window does not hold the picture: $r"; exit 1; }
done
r=$(python3 -c '
import sys
sys.path.insert(0, sys.argv[3])
from png_check import read_png
w, h, a = read_png(sys.argv[1])
_, _, b = read_png(sys.argv[2])
diff = [i for i, (p, q) in enumerate(zip(a, b)) if p != q]
print(len(diff), sum(1 for i in diff if i % w < w // 2))
' "$out/shm.png" "$out/slices-shm.png" "$src/tests/sculpt")
read -r nslice nleft <<< "$r"
[ "$nslice" -gt 0 ] && [ "$nleft" = 0 ] ||
  { echo "FAIL: the slice views changed $nslice pixels of the picture, $nleft in the left half (want some, none there)"; exit 1; }
echo "the slice views' inset: the window holds it both ways ($nslice pixels over the picture's right side)"
if [ "${SCULPT_EXPECT_OVERLAY:-0}" = 1 ]; then
  # At 800 x 600 the panels (at the left edge, a few hundred pixels wide) leave the right
  # quarter to the picture: the window differs from the picture, but not there.
  for p in shm swapchain; do
    rc=$(size=800 run panels "" --present "$p" --no-slices --stats)
    [ "$rc" = 0 ] || { cat "$out/panels.txt"; echo "FAIL: the panels' run (--present $p) exited $rc"; exit 1; }
    if [ "$p" = shm ]; then  # the host composed the frames: the panels came from their layer
      grep -q "^stats    overlay .*, their layer drawn anew in [1-9][0-9]*$" "$out/panels.txt" ||
        { grep "^stats    overlay" "$out/panels.txt"; echo "FAIL: --present shm did not draw the panels' layer"; exit 1; }
    fi
    r=$(python3 -c '
import sys
sys.path.insert(0, sys.argv[3])
from png_check import read_png
w, h, a = read_png(sys.argv[1])
_, _, b = read_png(sys.argv[2])
diff = [i for i, (p, q) in enumerate(zip(a, b)) if p != q]
right = [i for i in diff if i % w >= 3 * w // 4]
print(f"{len(diff)} {len(right)} {w * h}")
' "$out/panels.png" "$out/panels-window.png" "$src/tests/sculpt")
    read -r ndiff nright ntotal <<< "$r"
    [ "$ndiff" -gt 0 ] && [ "$nright" = 0 ] ||
      { echo "FAIL: --present $p with the panels: $ndiff of $ntotal pixels differ from the picture, $nright in the right quarter (want some, none there)"; exit 1; }
    echo "--present $p with the panels: $ndiff of $ntotal pixels differ from the picture, none in the right quarter"
    cp "$out/panels-window.png" "$out/panels-$p-window.png"
  done
  # The shared-memory path blends the panels' own layer (drawn only when they change) over
  # the picture on the host; the swapchain path draws them over the picture with ImGui's
  # pipeline: the same window but for the 8-bit rounding (--sim-clock: the same panels).
  r=$(python3 -c '
import sys
sys.path.insert(0, sys.argv[3])
from png_check import read_png
w, h, a = read_png(sys.argv[1])
_, _, b = read_png(sys.argv[2])
d = [max(abs(x - y) for x, y in zip(p, q)) for p, q in zip(a, b)]
print(f"{sum(1 for m in d if m > 1)} {max(d)}")
' "$out/panels-shm-window.png" "$out/panels-swapchain-window.png" "$src/tests/sculpt")
  read -r nbig maxd <<< "$r"
  [ "$nbig" = 0 ] || { echo "FAIL: the panels through shared memory and through the swapchain differ by more than 1 in $nbig pixels (max $maxd)"; exit 1; }
  echo "the panels through shared memory (a layer blended on the host) and through the swapchain: within $maxd per channel"
fi
# A display without MIT-SHM: shm refused by name, auto falls back to the swapchain.
rc=$(run noshm "-extension MIT-SHM" --present shm --no-overlay --no-slices)
[ "$rc" = 1 ] && grep -q "cannot present through X shared memory: the X server offers no MIT-SHM" "$out/noshm.txt" ||
  { cat "$out/noshm.txt"; echo "FAIL: --present shm without MIT-SHM: exit $rc"; exit 1; }
rc=$(run fallback "-extension MIT-SHM" --no-overlay --no-slices)
[ "$rc" = 0 ] && grep -q "X shared memory not used (the X server offers no MIT-SHM): the swapchain" "$out/fallback.txt" ||
  { cat "$out/fallback.txt"; echo "FAIL: auto without MIT-SHM: exit $rc"; exit 1; }
r=$(compare "$out/fallback.png" "$out/fallback-window.png")
[ "$r" = equal ] || { echo "FAIL: the fallback's window does not hold the picture: $r"; exit 1; }
echo "without MIT-SHM: shm refused by name, auto presents through the swapchain"
echo "PASS sculpt present"
