"""What a sweep tells its user while and after it runs: progress lines, failed tasks, the
plot's legend, the task time without scene preparation, distributed's log after a lost worker.
Judged by what was printed, what the files hold and a clock outside the task."""
import json
import logging
import re
import subprocess
import sys
import time

from isotouch import sweep as sw

SPEC = {"scenes": ["sphere"], "methods": [{"algorithm": "hri", "n": [1, 5], "options": "linear/samples"},
                                          {"algorithm": "avila"}], "timing_replays": 1}


def test_progress_lines_count_done_and_failed_and_estimate_the_rest(tmp_path):
    spec = dict(SPEC, scenes=["sphere", "missing.json"])
    lines = []
    sweep = sw.check_sweep(spec, base=tmp_path)
    try:
        sw.run_sweep(sweep, tmp_path / "out", client=None, log=lambda s, **k: lines.append(s), progress_s=0)
        raise AssertionError("a failed task must not end in success")
    except sw.SweepTaskError as e:
        assert "3 of 6 tasks failed" in str(e)
    progress = [ln for ln in lines if re.match(r"sweep: \d+/6 tasks done", ln)]
    assert len(progress) == 6, lines
    assert re.fullmatch(r"sweep: 6/6 tasks done, 3 failed, \S+ elapsed, about 0s left", progress[-1]), progress[-1]
    first = re.match(r"sweep: 1/6 tasks done, 0 failed, (\S+) elapsed, about (\S+) left", progress[0])
    assert first, progress[0]
    failed = [ln for ln in lines if "failed: " in ln]
    assert len(failed) == 3 and all("missing.json" in ln for ln in failed), failed
    assert len(sw.read_results(tmp_path / "out/results.csv")) == 3  # the others' rows written


def test_progress_estimate_is_elapsed_per_task_times_tasks_left():
    now = [100.0]
    lines = []
    p = sw.Progress(10, lambda s, **k: lines.append(s), every_s=60, clock=lambda: now[0])
    for t in (10.0, 20.0, 30.0, 40.0):  # 4 tasks in 40 s: 6 left, about 60 s
        now[0] = 100.0 + t
        p.step()
    assert lines == []  # not yet a minute
    now[0] = 100.0 + 62.0
    p.step(failed=True)  # 5 in 62 s: 62 s left
    assert lines == ["sweep: 5/10 tasks done, 1 failed, 1m02s elapsed, about 1m02s left"]


def test_the_cli_exits_1_when_a_task_failed(tmp_path):
    path = tmp_path / "sweep.json"
    path.write_text(json.dumps(dict(SPEC, scenes=["missing.json"], methods=[{"algorithm": "avila"}])))
    p = subprocess.run([sys.executable, "-m", "isotouch.sweep", str(path), "--serial", "--out", str(tmp_path / "o"),
                        "--progress-s", "0"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 1, p.stderr
    assert "sweep: 1/1 tasks done, 1 failed" in p.stdout and "1 of 1 tasks failed" in p.stderr


def test_the_plot_labels_each_configuration(tmp_path):
    rows = sw.run_sweep(sw.check_sweep(SPEC), tmp_path / "out", client=None, log=lambda *a, **k: None)
    sw.plot_error_vs_time(rows, tmp_path / "plot.svg")
    svg = (tmp_path / "plot.svg").read_text()
    for label in ("HRI n=1 linear/samples", "HRI n=5 linear/samples", "Avila-Sobierajski"):
        assert label in svg, label


def test_task_s_is_the_measurement_without_scene_preparation():
    sw._SCENES.clear()
    task = sw.make_tasks(sw.check_sweep(dict(SPEC, scenes=["knot"], methods=[{"algorithm": "avila"}])))[0]
    t0 = time.perf_counter()
    row = sw.run_task(task)
    wall = time.perf_counter() - t0
    assert row["prepare_s"] > 0
    assert row["task_s"] + row["prepare_s"] <= wall, (row["task_s"], row["prepare_s"], wall)


def test_a_recovered_gather_is_one_warning_that_says_what_happened():
    sw.quiet_recovered_gathers()
    seen = []
    handler = logging.Handler()
    handler.emit = seen.append
    for name, emit in (("distributed.scheduler", lambda lg: lg.exception(
            "Couldn't gather keys %s state: %s workers: %s", {"isotouch-sweep-abc": []}, ["memory"], ["tcp://x:1"])),
                       ("distributed.client", lambda lg: lg.warning(
                           "Couldn't gather %s keys, rescheduling %s", 1, ["isotouch-sweep-abc"]))):
        lg = logging.getLogger(name)
        lg.addHandler(handler)
        try:
            try:
                raise OSError("worker gone")
            except OSError:
                emit(lg)
        finally:
            lg.removeHandler(handler)
    assert len(seen) == 2
    for r in seen:
        assert r.levelno == logging.WARNING and r.exc_info is None
        text = r.getMessage()
        assert "a worker was lost" in text and "nothing is lost" in text and "isotouch-sweep-abc" in text, text
    other = []
    handler.emit = other.append
    lg = logging.getLogger("distributed.scheduler")
    lg.addHandler(handler)
    lg.error("something else")
    lg.removeHandler(handler)
    assert other[0].levelno == logging.ERROR  # any other error stays one
