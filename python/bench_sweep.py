#!/usr/bin/env python3
"""bench sweep: the same error-against-time sweep serially in this process, then on a
LocalCluster of 1 and of 2 single-threaded worker processes; tasks per second of each, and
efficiency = tasks/s on 2 workers / (2 x tasks/s serial) (target >= 0.8).

Every process runs one compute thread (LP_NUM_THREADS=1; the tasks replay strokes on one
thread). The timing replays per task are calibrated so the shortest task takes at least
--min-task-s. The scheduler's overhead per task is measured two ways: the 1-worker sweep's wall
time less the time its tasks report, per task; and the round trip of --noop-tasks empty tasks
on the 1-worker cluster. Load averages before and after are printed: other work on the machine
takes cores from the workers. Wall times exclude starting the cluster (the workers are
started and have imported isotouch before the clock starts); scene preparation is included.

    PYTHONPATH=build/python python3 python/bench_sweep.py [--scenes sphere box knot three-spheres]
"""
import argparse
import math
import os
import sys
import tempfile
import time

os.environ["LP_NUM_THREADS"] = "1"  # before any worker starts: they inherit it
# Run as a script, this folder comes first on sys.path and its isotouch/ (the sources, without
# the extension) would hide the built package on PYTHONPATH.
if sys.path and os.path.abspath(sys.path[0]) == os.path.dirname(os.path.abspath(__file__)):
    sys.path.pop(0)
from isotouch import sweep as sw  # noqa: E402

TARGET = 0.8
METHODS = [{"algorithm": "hri", "n": [1, 5, 20]}, {"algorithm": "avila"}, {"algorithm": "blezek"}]


def load():
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def calibrate(scenes, min_task_s):
    """The methods with timing replays per method such that its cheapest task (over the scenes)
    lasts min_task_s: one task of each with 50 replays, serially; a replay costs its mean tick
    x the stroke's ticks, the rest of the task (playback, error figures) is its time less the
    replays'."""
    probe = sw.check_sweep({"scenes": scenes, "methods": METHODS, "timing_replays": 50})
    need = {}
    for t in sw.make_tasks(probe):
        row = sw.run_task(t)
        per_replay = row["tick_ns_mean"] * row["ticks"] * 1e-9
        fixed = max(row["task_s"] - 50 * per_replay, 0.0)
        m = (t["algorithm"], t["n"])
        need[m] = max(need.get(m, 1), math.ceil(max(min_task_s - fixed, 0.0) / per_replay))
    methods = []
    for m in METHODS:
        for n in m.get("n", [1]):
            methods.append(dict(m, n=n, timing_replays=need[(m["algorithm"], n)]) if "n" in m
                           else dict(m, timing_replays=need[(m["algorithm"], 1)]))
    return methods


def timed_sweep(sweep, out, client):
    t0 = time.perf_counter()
    rows = sw.run_sweep(sweep, out, client, log=lambda *a, **k: None)
    return time.perf_counter() - t0, rows


def _noop(i):
    return i


def noop_overhead(client, n):
    """Wall time per empty task submitted and gathered through the scheduler [s]."""
    client.gather(client.map(_noop, range(10), pure=False))  # warm
    t0 = time.perf_counter()
    client.gather(client.map(_noop, range(n), pure=False))
    return (time.perf_counter() - t0) / n


def on_cluster(sweep, out, workers, noop_tasks):
    client, cluster = sw.connect(local_workers=workers)
    try:
        client.wait_for_workers(workers)
        client.run(lambda: __import__("isotouch.sweep"))  # imported before the clock starts
        wall, rows = timed_sweep(sweep, out, client)
        noop = noop_overhead(client, noop_tasks) if noop_tasks else None
        return wall, rows, noop
    finally:
        client.close()
        cluster.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["sphere", "box", "knot", "three-spheres"])
    ap.add_argument("--min-task-s", type=float, default=0.5)
    ap.add_argument("--noop-tasks", type=int, default=500)
    a = ap.parse_args()
    print(f"bench sweep: load average before: {load()}; {os.cpu_count()} cores; LP_NUM_THREADS=1", flush=True)
    methods = calibrate(a.scenes, a.min_task_s)
    sweep = sw.check_sweep({"scenes": a.scenes, "methods": methods})
    n = len(sw.make_tasks(sweep))
    print(f"{n} tasks ({len(a.scenes)} scenes x {len(methods)} configurations); timing replays: "
          + ", ".join(f"{m['algorithm']}{' n=%d' % m['n'] if 'n' in m else ''} {m['timing_replays']}" for m in methods),
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        serial_s, serial_rows = timed_sweep(sweep, f"{tmp}/serial", None)
        print(f"serial: {serial_s:.1f} s; load {load()}", flush=True)
        one_s, one_rows, noop = on_cluster(sweep, f"{tmp}/one", 1, a.noop_tasks)
        print(f"1 worker: {one_s:.1f} s; load {load()}", flush=True)
        two_s, two_rows, _ = on_cluster(sweep, f"{tmp}/two", 2, 0)
    task_s = [float(r["task_s"]) for r in serial_rows]
    one_busy = sum(float(r["task_s"]) for r in one_rows)
    same = sw_figures(serial_rows) == sw_figures(one_rows) == sw_figures(two_rows)
    print(f"task time (serial): min {min(task_s):.3f} s ({'at least' if min(task_s) >= a.min_task_s else 'below'} "
          f"{a.min_task_s} s), mean {sum(task_s) / n:.3f} s, max {max(task_s):.3f} s")
    print(f"{'run':<12} {'wall [s]':>9} {'tasks/s':>9} {'vs serial':>10}")
    for name, wall in (("serial", serial_s), ("1 worker", one_s), ("2 workers", two_s)):
        print(f"{name:<12} {wall:>9.2f} {n / wall:>9.3f} {serial_s / wall:>10.3f}")
    eff = (n / two_s) / (2 * n / serial_s)
    print(f"scheduler overhead per task: {(one_s - one_busy) / n * 1e3:.1f} ms (1-worker wall less its tasks' "
          f"time), {noop * 1e3:.2f} ms round trip of an empty task ({a.noop_tasks} of them)")
    print(f"figures equal in the three runs (time columns aside): {same}")
    print(f"load average after: {load()}")
    print(f"verdict: 2-worker efficiency {eff:.3f} against serial: "
          f"{'meets' if eff >= TARGET else 'below'} the target {TARGET}")
    return 0 if same else 1


def sw_figures(rows):
    return {r["key"]: tuple(r[c] for c in sw.FIGURES) for r in rows}


if __name__ == "__main__":
    sys.exit(main())
