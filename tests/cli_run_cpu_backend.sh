#!/usr/bin/env bash
# The CPU backend where no Vulkan device exists: with no driver to load and no device asked
# for, `isotouch run` says so, runs the engine, brushes and pictures on the CPU and gives
# the Vulkan run's trace (every column but tick_ns), edited volume and pictures bit for
# bit; a device asked for by name that does not open is an error, not a silent fallback.
# usage: cli_run_cpu_backend.sh ISOTOUCH SCENE OUT
set -u
exe=$1 scene=$2 out=$3
fail() { echo "FAIL: $*"; exit 1; }
# trace.csv without its tick_ns column (the only one that depends on the machine's speed).
no_tick_ns() {
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == "tick_ns") c = i }
           { line = ""; for (i = 1; i <= NF; ++i) if (i != c) line = line (line == "" ? "" : ",") $i; print line }' "$1"
}
rm -rf "$out"; mkdir -p "$out"
unset ISOTOUCH_DEVICE VK_DRIVER_FILES VK_ADD_DRIVER_FILES
# No driver for the loader to find (the older and the newer variable).
nodriver() { VK_ICD_FILENAMES=/nonexistent-icd.json VK_DRIVER_FILES=/nonexistent-icd.json "$@"; }
"$exe" run "$scene" --out "$out/vulkan" --quiet --record "$out/vulkan.rec" > "$out/vulkan.log" 2>&1 ||
  { cat "$out/vulkan.log"; fail "the Vulkan run failed"; }
nodriver "$exe" run "$scene" --out "$out/cpu" --quiet > "$out/cpu.log" 2>&1; rc=$?
cat "$out/cpu.log"
[ "$rc" -eq 0 ] || fail "the run without a Vulkan driver exited $rc"
grep -q "^device   none: no Vulkan device" "$out/cpu.log" || fail "the log does not say there is no Vulkan device"
grep -q "run_sparse_cpu (CPU backend" "$out/cpu.log" || fail "the engine did not run on the CPU backend"
grep -q "brushes on the CPU" "$out/cpu.log" || fail "the brushes did not run on the CPU"
grep -q "engine device | CPU backend" "$out/cpu/report.md" || fail "report.md does not name the CPU backend"
cmp <(no_tick_ns "$out/vulkan/trace.csv") <(no_tick_ns "$out/cpu/trace.csv") || fail "trace.csv differs from the Vulkan run's"
for f in drilled.nrrd surface.png after.png section_after.png drill.png; do
  [ -s "$out/cpu/$f" ] || fail "$f not written"
  cmp -s "$out/vulkan/$f" "$out/cpu/$f" || fail "$f differs from the Vulkan run's"
done
nodriver "$exe" replay "$out/vulkan.rec" > "$out/replay.log" 2>&1; rc=$?
cat "$out/replay.log"
[ "$rc" -eq 0 ] && grep -q "^IDENTICAL" "$out/replay.log" || fail "the replay without a Vulkan driver is not identical (exit $rc)"
ISOTOUCH_DEVICE=cpu "$exe" run "$scene" --out "$out/env" --quiet > "$out/env.log" 2>&1 || { cat "$out/env.log"; fail "ISOTOUCH_DEVICE=cpu failed"; }
grep -q "^device   none: device cpu asked for" "$out/env.log" || { cat "$out/env.log"; fail "ISOTOUCH_DEVICE=cpu did not take the CPU backend"; }
nodriver "$exe" run "$scene" --device llvmpipe --out "$out/asked" --quiet > "$out/asked.log" 2>&1; rc=$?
cat "$out/asked.log"
[ "$rc" -ne 0 ] || fail "a device asked for by name that does not open exited 0"
grep -q "Vulkan: " "$out/asked.log" || fail "no Vulkan error for the device asked for"
echo "PASS CPU backend"
