"""Sweeps on Dask (isotouch.sweep): 2 scenes x 2 methods. What is checked is what the results
file holds and what the command printed, against the serial reference run in one process."""
import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from isotouch import sweep as sw

pytest.importorskip("distributed")

# Tasks of about a second each (timing replays), so a worker can be caught holding one.
SPEC = {
    "scenes": ["sphere", "box"],
    "methods": [{"algorithm": "hri", "n": 5, "options": "linear/samples"}, {"algorithm": "avila"}],
    "timing_replays": 5000,
}


def write_spec(tmp_path, spec=SPEC, name="sweep.json"):
    path = tmp_path / name
    path.write_text(json.dumps(spec))
    return path


def run_cli(*args, timeout=240):
    return subprocess.run([sys.executable, "-m", "isotouch.sweep", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


def rows_of(out_dir):
    with open(out_dir / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def figures(rows):
    """key -> the columns that must not depend on where or when a task ran."""
    return {r["key"]: {c: r[c] for c in sw.IDENTITY + sw.FIGURES} for r in rows}


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The serial reference: every task in this process, the same task function."""
    tmp = tmp_path_factory.mktemp("serial")
    rows = sw.run_sweep(sw.load_sweep(write_spec(tmp)), tmp / "out", client=None, log=lambda *a, **k: None)
    assert len(rows) == 4
    return figures(rows_of(tmp / "out"))


def test_a_process_prepares_a_scene_once():
    tasks = sw.make_tasks(sw.check_sweep(dict(SPEC, scenes=["three-spheres"], timing_replays=1)))
    first, second = (sw.run_task(t) for t in tasks)
    assert first["prepare_s"] > 0 and second["prepare_s"] == 0
    assert first["surface_err_rms_m"] != second["surface_err_rms_m"]  # two methods, one scene


def test_two_local_workers_give_the_serial_figures(tmp_path, serial):
    r = run_cli(write_spec(tmp_path), "--local-workers", "2", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    assert "4 tasks; 0 already in" in r.stdout and "2 Dask workers" in r.stdout
    rows = rows_of(tmp_path / "out")
    assert figures(rows) == serial
    assert all(float(r["surface_err_rms_m"]) > 0 and int(r["contact_ticks"]) > 0 for r in rows)
    # Each worker prepared each scene it ran once: one row per (worker, scene) carries the time.
    for pid, scene in {(r["worker_pid"], r["scene"]) for r in rows}:
        prepared = [r for r in rows if (r["worker_pid"], r["scene"]) == (pid, scene) and float(r["prepare_s"]) > 0]
        assert len(prepared) == 1
    assert len({r["worker_pid"] for r in rows}) == 2
    assert {r["host"] for r in rows} and all(r["cpu"] for r in rows)
    table = (tmp_path / "out/summary.md").read_text().splitlines()
    assert [ln.split(" | ")[0] for ln in table[2:]] == ["| Avila-Sobierajski", "| HRI n=5 linear/samples"]
    assert (tmp_path / "out/error_vs_time.png").stat().st_size > 1000


def _kill_a_busy_worker(client, killed, stop):
    """SIGKILLs the first worker seen executing a task; records (pid, task key)."""
    def executing(dask_worker):
        state = getattr(dask_worker, "state", dask_worker)
        return [ts.key for ts in state.executing]

    while not stop.is_set():
        for addr, keys in client.processing().items():
            if not keys:
                continue
            running = client.run(executing, workers=[addr]).get(addr, [])
            if running:
                pid = client.run(os.getpid, workers=[addr])[addr]
                os.kill(pid, signal.SIGKILL)
                killed.append((pid, running[0]))
                return
        time.sleep(0.05)


def test_a_worker_killed_mid_task_loses_nothing(tmp_path, serial):
    client, cluster = sw.connect(local_workers=2)
    killed, stop = [], threading.Event()
    try:
        killer = threading.Thread(target=_kill_a_busy_worker, args=(client, killed, stop), daemon=True)
        killer.start()
        sw.run_sweep(sw.load_sweep(write_spec(tmp_path)), tmp_path / "out", client, log=lambda *a, **k: None)
        stop.set()
        killer.join(10)
    finally:
        client.close()
        cluster.close()
    assert killed, "no worker was seen holding a task"
    pid, dask_key = killed[0]
    rows = rows_of(tmp_path / "out")
    keys = [r["key"] for r in rows]
    assert len(rows) == 4 and len(set(keys)) == 4
    assert figures(rows) == serial
    # The task the killed worker held was written by another process.
    lost = next(r for r in rows if dask_key == f"isotouch-sweep-{r['key']}")
    assert lost["worker_pid"] != str(pid)


def test_interrupt_and_restart_skips_the_written_tasks(tmp_path, serial):
    spec = write_spec(tmp_path)
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "isotouch.sweep", str(spec), "--local-workers", "1", "--out", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not ((out / "results.csv").exists() and len(rows_of(out)) >= 1):
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    written = len(rows_of(out))
    assert p.returncode == 130, err
    assert 1 <= written < 4, "the sweep finished before it was interrupted"
    assert f"interrupted; {written} of 4 tasks written" in err

    r = run_cli(spec, "--local-workers", "1", "--out", out)
    assert r.returncode == 0, r.stderr
    assert f"4 tasks; {written} already in" in r.stdout and f"{4 - written} to run" in r.stdout
    rows = rows_of(out)
    assert len(rows) == 4 and len({r["key"] for r in rows}) == 4
    assert figures(rows) == serial


@pytest.mark.parametrize("spec, field, value", [
    ({"scenes": [], "methods": [{"algorithm": "hri"}]}, "scenes", "[]"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri", "n": [0]}]}, "methods[0].n", "[0]"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "avila", "n": 5}]}, "methods[0].n", "5"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri", "options": "secant/x"}]}, "methods[0].options",
     '"secant/x"'),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri", "grid": {"tool_radius_m": [-1]}}]},
     "methods[0].grid.tool_radius_m", "[-1]"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "blezek", "grid": {"tool_radius_m": [0.001]}}]},
     "methods[0].grid.tool_radius_m", "[0.001]"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "cheese"}]}, "methods[0].algorithm", '"cheese"'),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri"}], "repetitions": 0}, "repetitions", "0"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri"}], "colour": 1}, "colour", "1"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri"}], "figures": ["smell"]}, "figures", '["smell"]'),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri"}], "figures": []}, "figures", "[]"),
    ({"scenes": ["sphere"], "methods": [{"algorithm": "hri"}], "isovalues": {"sphere": [0.4]}}, "isovalues.sphere",
     "[0.4]"),
    ({"scenes": ["head"], "methods": [{"algorithm": "hri"}], "isovalues": {"chest": [300]}}, "isovalues.chest", "[300]"),
    ({"scenes": ["head"], "methods": [{"algorithm": "hri"}], "isovalues": {"head": ["bone"]}}, "isovalues.head",
     '["bone"]'),
    ({"scenes": ["head"], "methods": [{"algorithm": "hri"}], "isovalues": [1150]}, "isovalues", "[1150]"),
])
def test_a_bad_sweep_file_is_one_clear_error(tmp_path, spec, field, value):
    path = write_spec(tmp_path, spec)
    r = run_cli(path, "--serial", "--out", tmp_path / "out", timeout=60)
    assert r.returncode == 2
    assert r.stderr.startswith(f"sweep: {path}: {field}: {value}: "), r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def test_the_figures_asked_for_are_the_summarys_columns(tmp_path):
    """The summary holds the figures the file names, in its order, each computed here again
    from results.csv; without the error or the time there is no error-against-time plot."""
    spec = {"scenes": ["sphere"], "methods": [{"algorithm": "blezek"}], "timing_replays": 1,
            "figures": ["contact_fraction", "pop_throughs"]}
    r = run_cli(write_spec(tmp_path, spec), "--serial", "--out", tmp_path / "out", timeout=120)
    assert r.returncode == 0, r.stderr
    table = (tmp_path / "out/summary.md").read_text().splitlines()
    assert table[0] == "| configuration | tasks | scenes | contact fraction mean | pop-throughs | task [s] mean |"
    (row,) = rows_of(tmp_path / "out")
    cells = [c.strip() for c in table[2].strip("|").split("|")]
    assert cells[:3] == ["Blezek-Robb", "1", "1"]
    assert float(cells[3]) == pytest.approx(int(row["contact_ticks"]) / int(row["ticks"]), rel=2e-3)
    assert 0 < float(cells[3]) < 1 and cells[4] == row["pop_throughs"]
    assert not (tmp_path / "out/error_vs_time.png").exists()
    assert "surface_err_rms_m" in row and "tick_ns_mean" in row  # the file keeps every figure


def test_a_scene_file_measured_at_other_isovalues(tmp_path):
    """The head at its own isovalue named explicitly gives the figures of the head as it is
    (stroke and reference re-made at that isovalue: the same ones); at another isovalue the
    stroke and its truth are those of another surface; each isovalue its own row and key."""
    spec = {"scenes": ["head"], "methods": [{"algorithm": "blezek"}], "timing_replays": 1,
            "isovalues": {"head": [1150, 1600]}}
    r = run_cli(write_spec(tmp_path, spec), "--serial", "--out", tmp_path / "iso", timeout=120)
    assert r.returncode == 0, r.stderr
    base = dict(spec)
    del base["isovalues"]
    r = run_cli(write_spec(tmp_path, base, "own.json"), "--serial", "--out", tmp_path / "own", timeout=120)
    assert r.returncode == 0, r.stderr
    (own,) = rows_of(tmp_path / "own")
    at = {float(r["isovalue"]): r for r in rows_of(tmp_path / "iso")}
    assert set(at) == {1150.0, 1600.0} and own["isovalue"] == ""
    assert len({own["key"], at[1150.0]["key"], at[1600.0]["key"]}) == 3
    same = [c for c in sw.FIGURES]
    assert {c: at[1150.0][c] for c in same} == {c: own[c] for c in same}
    assert at[1600.0]["contact_ticks"] != own["contact_ticks"] or at[1600.0]["surface_err_rms_m"] != own["surface_err_rms_m"]
    table = (tmp_path / "iso/summary.md").read_text()
    assert "Blezek-Robb isovalue=1150.0" in table and "Blezek-Robb isovalue=1600.0" in table


def test_the_isotouch_command_runs_the_same_sweep(tmp_path, serial):
    """`isotouch sweep` finds the module beside its own build (no PYTHONPATH) and hands every
    argument on: the serial reference's figures; a bad file is the same one-line error."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([os.environ["ISOTOUCH_BIN"], "sweep", str(write_spec(tmp_path)), "--serial", "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, env=env, timeout=240)
    assert r.returncode == 0, r.stderr
    assert figures(rows_of(tmp_path / "out")) == serial
    bad = write_spec(tmp_path, {"scenes": []}, "bad.json")
    r = subprocess.run([os.environ["ISOTOUCH_BIN"], "sweep", str(bad), "--serial"], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 2 and r.stderr == f"sweep: {bad}: scenes: []: must be a non-empty list of scene names or scene JSON paths\n"
    r = subprocess.run([os.environ["ISOTOUCH_BIN"], "sweep", "--help"], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("usage: isotouch sweep")


def test_a_broken_sweep_file_names_line_and_column(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"scenes": ["sphere"],\n "methods": [}')
    r = run_cli(path, "--serial", timeout=60)
    assert r.returncode == 2 and r.stderr.startswith(f"sweep: {path}: not JSON: line 2 column"), r.stderr


def test_a_line_cut_short_is_dropped_and_its_task_run_again(tmp_path, serial):
    spec = write_spec(tmp_path)
    out = tmp_path / "out"
    sw.run_sweep(sw.load_sweep(spec), out, client=None, log=lambda *a, **k: None)
    data = (out / "results.csv").read_bytes()
    cut = data[: data.rstrip(b"\n").rfind(b"\n") + 40]  # the last row cut 39 bytes in, as a crash leaves it
    (out / "results.csv").write_bytes(cut)
    r = run_cli(spec, "--serial", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "4 tasks; 3 already in" in r.stdout
    rows = rows_of(out)
    assert len(rows) == 4 and figures(rows) == serial


def slurm_script(root):
    return root / "python/slurm_sweep.sh"


def test_the_slurm_script_parses_and_its_dry_run_prints_what_it_starts(root, tmp_path):
    script = slurm_script(root)
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    env = dict(os.environ, SLURM_NTASKS="5")
    r = subprocess.run([str(script), "--dry-run", "s.json", "/shared/out"], capture_output=True, text=True, env=env,
                       timeout=30)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        "mkdir -p /shared/out",
        "rm -f /shared/out/scheduler.json",
        "srun --ntasks=1 --nodes=1 --cpus-per-task=1 dask-scheduler --scheduler-file /shared/out/scheduler.json "
        "--no-dashboard &",
        "srun --ntasks=4 --cpus-per-task=1 dask-worker --scheduler-file /shared/out/scheduler.json --nworkers 1 "
        "--nthreads 1 --no-dashboard &",
        "python3 -m isotouch.sweep s.json --scheduler-file /shared/out/scheduler.json --out /shared/out",
    ]
    assert not (tmp_path / "out").exists()
    bad = subprocess.run([str(script), "--dry-run"], capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "usage" in bad.stderr


def test_the_slurm_script_runs_a_sweep_through_srun(root, tmp_path, serial):
    """A stand-in srun (runs its command once, here) and this interpreter as python3: the
    script's scheduler, worker and sweep for real."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "srun").write_text('#!/bin/bash\nwhile [[ "$1" == --* ]]; do shift; done\nexec "$@"\n')
    (bin_dir / "srun").chmod(0o755)
    (bin_dir / "python3").symlink_to(sys.executable)
    env = dict(os.environ, SLURM_NTASKS="2", PATH=f"{bin_dir}:/usr/bin:{os.environ['PATH']}",
               ISOTOUCH_PYTHONPATH=os.environ["PYTHONPATH"])
    out = tmp_path / "out"
    r = subprocess.run([str(slurm_script(root)), str(write_spec(tmp_path)), str(out)], capture_output=True, text=True,
                       env=env, timeout=180)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "4 tasks; 0 already in" in r.stdout
    assert figures(rows_of(out)) == serial
