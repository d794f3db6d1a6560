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

Then a model of a 1,000-scan study on N workers, from the measured task times of the shipped
CTs (--model-scans) under the report's configurations and the scheduler overheads above.

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
    lasts min_task_s. Each task runs serially twice, with 20 and with 200 replays: the
    difference is the cost of 180 replays, the rest of the task (scene preparation, playback,
    error figures) is what the shorter run took beyond its replays. A 10 % margin covers the
    drift between this probe and the timed runs."""
    lo, hi = 20, 200
    rows = {}
    for replays in (lo, hi):
        probe = sw.check_sweep({"scenes": scenes, "methods": METHODS, "timing_replays": replays})
        for t in sw.make_tasks(probe):
            sw.run_task(t)  # warm: the scene's preparation and caches are not the replays' cost
            rows[(t["scene"], t["algorithm"], t["n"], replays)] = sw.run_task(t)["task_s"]
    need = {}
    for (scene, alg, n, replays), task_s in rows.items():
        if replays != lo:
            continue
        per_replay = max((rows[(scene, alg, n, hi)] - task_s) / (hi - lo), 1e-9)
        fixed = max(task_s - lo * per_replay, 0.0)
        m = (alg, n)
        need[m] = max(need.get(m, 1), math.ceil(1.1 * max(min_task_s - fixed, 0.0) / per_replay))
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
    ap.add_argument("--model-scans", nargs="*", default=["head", "chest"],
                    help="scans whose measured tasks model a 1,000-scan study (none: no model)")
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
    print("\n| run | wall [s] | tasks/s | vs serial |\n|---|---|---|---|")
    for name, wall in (("serial", serial_s), ("1 worker", one_s), ("2 workers", two_s)):
        print(f"| {name} | {wall:.2f} | {n / wall:.3f} | {serial_s / wall:.3f} |")
    eff = (n / two_s) / (2 * n / serial_s)
    per_task = (one_s - one_busy) / n
    print(f"\nscheduler overhead per task: {per_task * 1e3:.1f} ms (1-worker wall less its tasks' "
          f"time), {noop * 1e3:.2f} ms round trip of an empty task ({a.noop_tasks} of them)")
    print(f"figures equal in the three runs (time columns aside): {same}")
    print(f"load average after the sweeps: {load()}")
    print(f"verdict: 2-worker efficiency {eff:.3f} against serial: "
          f"{'meets' if eff >= TARGET else 'below'} the target {TARGET}", flush=True)
    if a.model_scans:
        study_model(a.model_scans, noop, max(per_task, 0.0))
    print(f"load average after: {load()}")
    return 0 if same else 1


def hms(s):
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min" if s >= 3600 else (
        f"{s / 60:.1f} min" if s >= 60 else f"{s:.0f} s")


def study_model(scans, o_empty, o_task, study=1000, workers=(1, 2, 32, 128)):
    """Serially, each scan under the report's configurations (python/sweeps/report.json's
    methods and timing replays): t = the scan's tasks' time less its preparation p. A study of
    `study` such scans on N workers then takes about study x (t + k o) / N for k tasks per scan
    at a scheduler overhead o per task, plus between study x p / N (a worker runs all of a
    scan's tasks) and study x p (every worker prepares every scan)."""
    spec = {"scenes": scans, "methods": METHODS, "timing_replays": 5}
    per_scan = {}
    for t in sw.make_tasks(sw.check_sweep(spec)):
        row = sw.run_task(t)
        d = per_scan.setdefault(t["scene"], {"tasks": 0, "s": 0.0, "p": 0.0})
        d["tasks"] += 1
        d["s"] += row["task_s"] - row["prepare_s"]
        d["p"] += row["prepare_s"]
    print(f"\nA {study:,}-scan study, modelled from these scans' tasks (the report's configurations, "
          "measured serially in this run):\n\n| scan | tasks | tasks' time t [s] | preparation p [s] |\n|---|---|---|---|")
    for scan, d in per_scan.items():
        print(f"| {scan} | {d['tasks']} | {d['s']:.2f} | {d['p']:.2f} |")
    k = max(d["tasks"] for d in per_scan.values())
    t = sum(d["s"] for d in per_scan.values()) / len(per_scan)
    p = max(d["p"] for d in per_scan.values())
    print(f"\nT(N) = {study} x (t + {k} o) / N with the mean t = {t:.2f} s; preparation adds between "
          f"{study} p / N and {study} p (largest p = {p:.2f} s).\n")
    print(f"| workers N | T(N), o = {o_empty * 1e3:.1f} ms (empty task) | T(N), o = {o_task * 1e3:.1f} ms "
          "(per task, 1 worker) | preparation added, at most |\n|---|---|---|---|")
    for nw in workers:
        print(f"| {nw} | {hms(study * (t + k * o_empty) / nw)} | {hms(study * (t + k * o_task) / nw)} | {hms(study * p)} |")


def sw_figures(rows):
    return {r["key"]: tuple(r[c] for c in sw.FIGURES) for r in rows}


if __name__ == "__main__":
    sys.exit(main())
