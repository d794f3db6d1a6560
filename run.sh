#!/usr/bin/env bash
# isotouch - the README's two commands.
#   ./run.sh [SCENE] [--out DIR] [...]  install what is missing, build, run `isotouch run`
#                                       (no arguments: scenes/head.json, scenes/drill-skull.json, then
#                                       scenes/drill-burr.json; output: out/head/, out/drill-skull/, out/drill-burr/)
#   ./run.sh test [ctest args]          install what is missing, build, run the test suite
#                                       (release build, then the servo under ThreadSanitizer)
# Debian 12. Needs root or sudo only when packages are missing.
set -euo pipefail
cd "$(dirname "$0")"

PACKAGES=(
  build-essential cmake ninja-build pkg-config zlib1g-dev ccache
  libvulkan-dev glslang-tools mesa-vulkan-drivers vulkan-validationlayers
  libinsighttoolkit5-dev libteem-dev
  nlohmann-json3-dev libcli11-dev libgtest-dev
  gnuplot-nox
  libopenvdb-dev libboost-iostreams-dev libtbb-dev
  libpng-dev libassimp-dev
  libhidapi-dev
  libopenigtlink-dev openigtlink-examples
  libglfw3-dev libx11-dev libxext-dev libxrandr-dev libimgui-dev xvfb xauth procps python3
  pybind11-dev python3-dev python3-numpy python3-pytest python3-matplotlib
  python3-dask python3-distributed
)
# `./run.sh test` also builds the libFuzzer targets with clang.
if [[ "${1:-}" == "test" ]]; then PACKAGES+=(clang-14 libclang-rt-14-dev); fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "run.sh: installing missing Debian packages: ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# ccache: a rebuild (and tests/mutants.sh's copy of the tree, under the same base directory)
# takes unchanged files from the cache.
if command -v ccache >/dev/null; then
  export CMAKE_CXX_COMPILER_LAUNCHER=${CMAKE_CXX_COMPILER_LAUNCHER:-ccache}
  export CMAKE_C_COMPILER_LAUNCHER=${CMAKE_C_COMPILER_LAUNCHER:-ccache}
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD}
fi
echo "run.sh: configuring and building (cmake preset 'release' -> build/)"
cmake --preset release >build-configure.log 2>&1 || { cat build-configure.log; exit 1; }
rm -f build-configure.log
if [[ "${1:-}" == "test" ]]; then
  cmake --build --preset release -j"$(nproc)"
else
  # The main job's program first (build/bin/isotouch): the scenes run as soon as it is built;
  # the other programs (isotouch-sculpt, isotouch-devemu) are built after them. The tests, the
  # benchmarks' helpers and the fuzzers are built by `./run.sh test`.
  cmake --build --preset release -j"$(nproc)" --target isotouch
fi

if [[ "${1:-}" == "test" ]]; then
  shift
  # The safety tests (label `safety`: what a device or peer receives when something fails) run
  # once: one that passes only on a retry has failed. The rest: a test that fails is run once
  # more before it counts as failed (--repeat until-pass:2): the real-time tests time the
  # servo and the emulated device in wall-clock periods, and this VM loses the CPU for
  # milliseconds now and then; a defect fails both runs.
  status=0
  ctest --preset release -j"$(nproc)" -L safety "$@" || status=1
  ctest --preset release -j"$(nproc)" -LE safety --repeat until-pass:2 "$@" || status=1
  [ "$status" = 0 ] || { echo "run.sh: tests FAILED (release build)"; exit 1; }
  # What needs no Vulkan again under ThreadSanitizer: servo thread, live session (edit thread
  # publishing live-field snapshots to the servo thread), threaded CPU chains, queues.
  echo "run.sh: ThreadSanitizer build of the servo, session and CPU engine (cmake preset 'tsan' -> build-tsan/)"
  cmake --preset tsan >build-configure.log 2>&1 || { cat build-configure.log; exit 1; }
  rm -f build-configure.log
  cmake --build --preset tsan -j"$(nproc)"
  ctest --preset tsan -j"$(nproc)" -L safety "$@" || status=1
  ctest --preset tsan -j"$(nproc)" -LE safety --repeat until-pass:2 "$@" || status=1
  [ "$status" = 0 ] || { echo "run.sh: tests FAILED (ThreadSanitizer build)"; exit 1; }
  # Every parser of ours under libFuzzer (ASan + UBSan) for a few seconds on its corpus: a
  # crash, a sanitizer report or a broken invariant fails the suite (the input is kept in
  # build-fuzz/crash-*). Longer runs: see tests/CMakeLists.txt.
  echo "run.sh: libFuzzer targets (cmake preset 'fuzz' -> build-fuzz/), ${ISOTOUCH_FUZZ_SECONDS:-10} s each"
  cmake --preset fuzz >build-configure.log 2>&1 || { cat build-configure.log; exit 1; }
  rm -f build-configure.log
  cmake --build --preset fuzz -j"$(nproc)"
  # scene, recording, hid_report, igtl and seg_nrrd: libFuzzer (clang); volume and vdb: a mutation loop built by GCC in
  # build/ (Debian's ITK headers refuse clang).
  for t in scene recording hid_report igtl seg_nrrd volume vdb; do
    bin=build-fuzz/bin/fuzz_$t
    [[ $t == volume || $t == vdb ]] && bin=build/bin/fuzz_$t
    mkdir -p "build-fuzz/corpus_$t"
    if ! ASAN_OPTIONS=detect_leaks=0 "$bin" "build-fuzz/corpus_$t" "tests/fuzz/corpus_$t" -max_total_time="${ISOTOUCH_FUZZ_SECONDS:-10}" \
        -timeout=30 -rss_limit_mb=4096 -artifact_prefix=build-fuzz/ -print_final_stats=1 >"build-fuzz/fuzz_$t.log" 2>&1; then
      tail -n 60 "build-fuzz/fuzz_$t.log"
      echo "run.sh: fuzz_$t FAILED (log: build-fuzz/fuzz_$t.log)"
      exit 1
    fi
    echo "run.sh: fuzz_$t: $(grep -E '^stat::number_of_executed_units' "build-fuzz/fuzz_$t.log" | awk '{print $2}') inputs, no failure"
  done
  exit 0
fi
if (($# == 0)); then
  # The main job: touch the skull of the head CT, drill through it with the point tool, then
  # with the burr as a sphere (its hole the burr's size).
  build/bin/isotouch run scenes/head.json
  build/bin/isotouch run scenes/drill-skull.json
  build/bin/isotouch run scenes/drill-burr.json
else
  build/bin/isotouch run "$@"
fi
echo "run.sh: building the other programs (isotouch-sculpt, isotouch-devemu)"
exec cmake --build --preset release -j"$(nproc)" --target programs
