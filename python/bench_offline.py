#!/usr/bin/env python3
"""Offline rendering from Python against the same C++ loop: per-tick cost of isotouch.render()
timed in Python around the call (the HIP array's conversion in, the result arrays out),
beside eval::median_ns_per_tick (what `isotouch bench table1` times) on the same scene, stroke,
algorithm and parameters, measured in the same run, interleaved call by call.

The stroke is the scene's recorded one (`bench table1`'s), run forward then backward until it
has at least --min-ticks ticks (a continuous path: no jump where it turns).
Verdict: Python's median per-tick cost at most 10 % above the C++ median.

    PYTHONPATH=build/python python3 python/bench_offline.py [--scenes head chest] [--calls 21]
"""
import argparse
import os
import statistics
import sys
import time

import numpy as np

# Run as a script, this folder comes first on sys.path and its isotouch/ (the sources, without
# the extension) would hide the built package on PYTHONPATH.
if sys.path and os.path.abspath(sys.path[0]) == os.path.dirname(os.path.abspath(__file__)):
    sys.path.pop(0)
import isotouch  # noqa: E402

ALGORITHMS = ("hri", "hri-paper", "avila", "blezek")
TARGET = 1.10  # Python / C++ per-tick cost


def stroke(scene, min_ticks):
    """The recorded stroke forward, backward, forward ... until min_ticks ticks."""
    parts, n = [], 0
    forward = True
    while n < min_ticks:
        parts.append(scene.hip if forward else scene.hip[::-1])
        n += len(scene.hip)
        forward = not forward
    return np.ascontiguousarray(np.concatenate(parts))


def params(scene, algorithm):
    if algorithm == "hri":
        return "hri", scene.table1_hri_params()
    if algorithm == "hri-paper":
        return "hri", scene.table1_hri_params(isotouch.Variant.paper)
    return algorithm, scene.table1_baseline_params()


def measure(scene, algorithm, hip, calls):
    """(C++ ns per tick, Python ns per tick): medians of `calls` rounds, each one C++ replay and
    one Python call, after one warm-up of each."""
    name, p = params(scene, algorithm)
    isotouch.render(scene.field, hip, name, p)
    isotouch.cpp_ns_per_tick(scene.field, hip, name, p, warmup=1, repetitions=1)
    cpp, py = [], []
    for _ in range(calls):
        cpp.append(isotouch.cpp_ns_per_tick(scene.field, hip, name, p, warmup=0, repetitions=1))
        t0 = time.perf_counter_ns()
        isotouch.render(scene.field, hip, name, p)
        py.append((time.perf_counter_ns() - t0) / len(hip))
    return statistics.median(cpp), statistics.median(py)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["sphere", "knot", "head", "chest"])
    ap.add_argument("--algorithms", nargs="+", default=list(ALGORITHMS), choices=ALGORITHMS)
    ap.add_argument("--calls", type=int, default=41, help="timed calls per algorithm (>= 20)")
    ap.add_argument("--min-ticks", type=int, default=10000, help="ticks per call (>= 10,000)")
    ap.add_argument("--device", default="cpu", help="samples from the CPU reference or a Vulkan device")
    ap.add_argument("--no-realtime", action="store_true",
                    help="time under the default scheduler (default: SCHED_FIFO on one CPU, as bench table1)")
    a = ap.parse_args(argv)
    if a.calls < 20 or a.min_ticks < 10000:
        ap.error("--calls must be >= 20 and --min-ticks >= 10000")
    print(f"bench_offline: isotouch {isotouch.__version__}, Python {sys.version.split()[0]}, "
          f"numpy {np.__version__}; {os.cpu_count()} CPUs; load average (1/5/15 min) "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"per tick: median of {a.calls} calls; C++ = eval::median_ns_per_tick (bench table1's loop), "
          "Python = time.perf_counter around isotouch.render (conversions included)\n")
    print(f"{'scene':<8} {'algorithm':<10} {'ticks':>7} {'C++ [ns]':>10} {'Python [ns]':>12} {'Py/C++':>7}")
    met, rows = 0, 0
    worst = (0.0, "")
    granted = "default scheduler, unpinned (--no-realtime)"
    for name in a.scenes:
        scene = isotouch.stroke_scene(name, device=a.device)  # prepared unpinned (its threads)
        hip = stroke(scene, a.min_ticks)
        for algorithm in a.algorithms:
            if a.no_realtime:
                cpp, py = measure(scene, algorithm, hip, a.calls)
            else:
                with isotouch.Realtime("bench_offline") as rt:
                    granted = rt.granted
                    cpp, py = measure(scene, algorithm, hip, a.calls)
            ratio = py / cpp
            rows += 1
            met += ratio <= TARGET
            worst = max(worst, (ratio, f"{name} {algorithm}"))
            print(f"{name:<8} {algorithm:<10} {len(hip):>7} {cpp:>10.1f} {py:>12.1f} {ratio:>7.3f}")
    print(f"\nverdict: Python within 10 % of C++ on {met} of {rows} (worst: {worst[1]} {worst[0]:.3f}); "
          f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"scheduling of the timed calls: {granted}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
