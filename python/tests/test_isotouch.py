"""The isotouch Python module against what lies outside it: the files' headers, the command
line's own outputs and messages, the recordings the CLI writes, a second Python thread."""
import gc
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import isotouch


def mhd_field(path, name):
    """A MetaImage header field as numbers, read from the file's text (not through isotouch)."""
    with open(path, encoding="ascii") as f:
        for line in f:
            key, _, value = line.partition("=")
            if key.strip() == name:
                return [float(v) for v in value.split()]
    raise KeyError(name)


def cli_error(cli, *args):
    """The message the command line prints for a fault (after 'isotouch: error: ')."""
    p = subprocess.run([cli, *args], capture_output=True, text=True, timeout=120)
    assert p.returncode != 0, p.stdout
    m = re.search(r"isotouch: error: (.*)", p.stderr)
    assert m, p.stderr
    return m.group(1).strip()


# ---- volumes ----


def test_load_volume_shape_units_and_layout(head_path):
    v = isotouch.load_volume(head_path)
    nx, ny, nz = mhd_field(head_path, "DimSize")
    assert v.array.shape == (nz, ny, nx)
    assert v.array.dtype == np.float32 and v.array.flags["C_CONTIGUOUS"]
    spacing_mm = mhd_field(head_path, "ElementSpacing")
    assert v.spacing == pytest.approx([s * 1e-3 for s in spacing_mm])  # metres
    # x fastest: voxel (x=1, y=0, z=0) is the second value of the raw file
    raw = np.fromfile(head_path.replace(".mhd", ".raw"), dtype="<i2").reshape(int(nz), int(ny), int(nx))
    np.testing.assert_array_equal(v.array, raw.astype(np.float32))


def test_array_is_a_view_writes_reach_the_engine(head_path):
    v = isotouch.load_volume(head_path)
    a = v.array
    assert a.__array_interface__["data"][0] == v.array.__array_interface__["data"][0]
    crc_before = v.crc32()
    a[40, 30, 20] = 12345.0
    assert v.array[40, 30, 20] == 12345.0
    assert v.crc32() != crc_before  # the C++ side's bytes changed
    samples = isotouch.run_passes(v, device="cpu")["samples"]
    assert samples.value[40, 30, 20] == 12345.0  # the engine read the written voxel


def test_volume_from_numpy_round_trip():
    arr = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    v = isotouch.Volume(arr, spacing=(1e-3, 2e-3, 3e-3), origin=(0.1, 0.2, 0.3))
    assert v.dims == (6, 5, 4) and v.shape == (4, 5, 6)
    np.testing.assert_array_equal(v.array, arr)
    assert v.spacing == (1e-3, 2e-3, 3e-3) and v.origin == (0.1, 0.2, 0.3)
    np.testing.assert_array_equal(v.direction, np.eye(3))
    # grid-world of index (1, 2, 3) = origin + spacing * index
    np.testing.assert_allclose(v.index_to_world([[1, 2, 3]]), [[0.101, 0.204, 0.309]])


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: isotouch.Volume(np.zeros((4, 5, 6)), (1e-3,) * 3), "dtype float64"),
        (lambda: isotouch.Volume(np.zeros((6, 5, 4), np.float32).transpose(), (1e-3,) * 3), "not C-contiguous"),
        (lambda: isotouch.Volume(np.zeros((4, 5), np.float32), (1e-3,) * 3), "2 dimensions"),
        (lambda: isotouch.Volume(np.zeros((4, 5, 6), np.float32), (1e-3, float("nan"), 1e-3)), r"spacing\[1\] is nan"),
        (lambda: isotouch.Volume(np.zeros((4, 5, 6), np.float32), (1e-3, -1.0, 1e-3)), r"spacing\[1\] is -1"),
        (lambda: isotouch.Volume(np.zeros((4, 5, 6), np.float32), (1e-3,) * 3, direction=np.ones((3, 3))), "direction"),
    ],
)
def test_bad_arrays_are_value_errors(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_load_errors_carry_the_cli_message(cli, tmp_path):
    bad = tmp_path / "bad.mhd"
    bad.write_text("ObjectType = Image\nNDims = 3\nDimSize = -64 64 93\nElementType = MET_SHORT\n"
                   "ElementSpacing = 1 1 1\nElementDataFile = x.raw\n")
    for path in (str(bad), str(tmp_path / "missing.nrrd")):
        with pytest.raises(isotouch.VolumeError) as e:
            isotouch.load_volume(path)
        assert str(e.value) == cli_error(cli, "check", path)
    assert "field 'DimSize' = -64 64 93" in cli_error(cli, "check", str(bad))  # file, field, value


def test_scene_and_recording_errors(cli, tmp_path):
    scene = tmp_path / "bad.json"
    scene.write_text('{"name": "x", "volume": {"synthetic": "sphere", "dims": [8, 8, 8], "spacing_m": 0.001, '
                     '"radius_vox": 3}, "isovalue": 0, "servo": {"stiffness_n_per_m": -3}}')
    with pytest.raises(isotouch.SceneError) as e:
        isotouch.run_scene(str(scene), str(tmp_path / "out"))
    assert str(e.value) == cli_error(cli, "run", str(scene), "--out", str(tmp_path / "out2"))
    assert "stiffness_n_per_m" in str(e.value)
    with pytest.raises(isotouch.SceneError) as e:
        isotouch.LiveSession(str(scene))
    assert "stiffness_n_per_m" in str(e.value) and str(scene) in str(e.value)
    rec = tmp_path / "garbage.rec"
    rec.write_text("not json\n")
    with pytest.raises(isotouch.RecordingError, match="garbage.rec"):
        isotouch.load_recording(str(rec))


# ---- scenes: the CLI's own outputs ----


def trace_rows(path):
    """trace.csv's lines without the wall-time column tick_ns (the only column a rerun changes)."""
    with open(path, encoding="ascii") as f:
        lines = f.read().splitlines()
    assert lines[0].endswith(",tick_ns")
    return [line.rsplit(",", 1)[0] for line in lines]


def test_scene_run_gives_the_cli_trace_bit_for_bit(cli, root, tmp_path):
    scene = str(root / "scenes/sphere.json")
    subprocess.run([cli, "run", scene, "--out", str(tmp_path / "cli"), "--device", "cpu", "--quiet"],
                   check=True, capture_output=True, timeout=600)
    isotouch.run_scene(scene, str(tmp_path / "py"), device="cpu")
    assert trace_rows(tmp_path / "py/trace.csv") == trace_rows(tmp_path / "cli/trace.csv")
    run = isotouch.read_run_folder(str(tmp_path / "py"))
    assert run["summary"]["status"] == "complete"
    assert run["trace"]["hip"].shape == (len(trace_rows(tmp_path / "cli/trace.csv")) - 1, 3)


def test_offline_render_reproduces_a_cli_recording(cli, root, tmp_path):
    """The forces `isotouch run --record` wrote, rendered again from Python over the recorded HIPs."""
    scene = str(root / "scenes/sphere.json")
    rec = str(tmp_path / "sphere.rec")
    subprocess.run([cli, "run", scene, "--out", str(tmp_path / "out"), "--device", "cpu", "--quiet",
                    "--record", rec], check=True, capture_output=True, timeout=600)
    r = isotouch.load_recording(rec)
    setup = isotouch.scene_setup(scene, device="cpu")
    ticks = r["ticks"]
    assert r["format_version"] == 3 and len(ticks["t"]) > 1000
    out = isotouch.render(setup["field"], ticks["hip"], "hri", setup["hri"])
    np.testing.assert_array_equal(out["force"], ticks["force"])  # bit for bit
    np.testing.assert_array_equal(out["vhip"], ticks["vhip"])
    assert out["contact"].sum() > 100


# ---- offline rendering ----


@pytest.fixture(scope="module")
def sphere_stroke():
    return isotouch.stroke_scene("sphere", device="cpu")


def test_render_three_algorithms(sphere_stroke):
    s = sphere_stroke
    hip = s.hip
    for algo, params in (("hri", s.table1_hri_params()), ("hri", s.table1_hri_params(isotouch.Variant.paper)),
                         ("avila", s.table1_baseline_params()), ("blezek", s.table1_baseline_params())):
        out = isotouch.render(s.field, hip, algo, params)
        assert out["force"].shape == (len(hip), 3) and out["contact"].dtype == np.bool_
        assert np.isfinite(out["force"]).all() and not out["fault"].any()
        # the sphere's truth: in contact the force points away from the centre (outward)
        c = out["contact"]
        assert c.sum() > 50, algo
        centre = np.array(s.field.origin) + (np.array(s.field.dims) - 1) / 2 * np.array(s.field.spacing)
        radial = hip[c] - centre
        assert (np.einsum("ij,ij->i", out["force"][c], radial) > 0).mean() > 0.99, algo
    assert isotouch.render(s.field, hip, "hri", s.table1_hri_params())["plane_update"].sum() > 0


def test_render_argument_errors(sphere_stroke):
    s = sphere_stroke
    with pytest.raises(ValueError, match="algorithm"):
        isotouch.render(s.field, s.hip, "nope")
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        isotouch.render(s.field, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="hip"):
        isotouch.render(s.field, np.zeros((5, 3, 1)))
    with pytest.raises(ValueError, match=r"points: row 2 is not finite"):
        isotouch.Volume(np.zeros((2, 2, 2), np.float32), (1e-3,) * 3).to_physical([[0, 0, 0]] * 2 + [[0, np.inf, 0]])


def test_render_answers_a_nan_hip_as_the_servo_does(sphere_stroke):
    """A non-finite HIP is a fault tick (zero force), never a NaN force."""
    s = sphere_stroke
    out0 = isotouch.render(s.field, s.hip, "hri", s.table1_hri_params())
    k = int(np.flatnonzero(out0["contact"])[50])  # a tick in contact
    bad = s.hip.copy()
    bad[k, 1] = np.nan
    for algo, params in (("hri", s.table1_hri_params()), ("avila", s.table1_baseline_params()),
                         ("blezek", s.table1_baseline_params())):
        out = isotouch.render(s.field, bad, algo, params)
        assert out["fault"][k] and not out["fault"][:k].any(), algo
        assert np.array_equal(out["force"][k], [0.0, 0.0, 0.0]) and np.isfinite(out["force"]).all(), algo


def test_render_releases_the_gil(sphere_stroke):
    """A second Python thread keeps running while one render call is in C++."""
    s = sphere_stroke
    reps = max(1, int(3_000_000 / len(s.hip)))
    hip = np.concatenate([s.hip, s.hip[::-1]] * reps)
    stamps = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            stamps.append(time.perf_counter())

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.05)
    t0 = time.perf_counter()
    isotouch.render(s.field, hip, "hri", s.table1_hri_params())
    t1 = time.perf_counter()
    stop.set()
    t.join()
    assert t1 - t0 > 0.2, "the call is too short to show anything"
    lo, hi = t0 + 0.1 * (t1 - t0), t1 - 0.1 * (t1 - t0)
    inside = sum(lo < x < hi for x in stamps)
    assert inside > 1000, f"the other thread ran {inside} times during the middle 80 % of a {t1 - t0:.2f} s call"


# ---- engine ----


def test_check_gpu_against_cpu(head_path):
    v = isotouch.load_volume(head_path)
    r = isotouch.check(v, [isotouch.Pass.gaussian(1.0), isotouch.Pass.gradient()], device="")
    assert r["gpu"]["device"] != r["cpu"]["device"]
    assert set(r["outputs"]) == {"field", "samples"}  # the Gaussian's output and the samples
    assert r["outputs"]["samples"]["nonfinite"] == 0 and r["outputs"]["field"]["nonfinite"] == 0
    if "llvmpipe" in r["device"] or "lavapipe" in r["device"].lower():
        assert r["identical"], r["outputs"]  # a CPU Vulkan device: the same float operations
    else:
        assert r["outputs"]["samples"]["max_ulp"] <= 64


def test_a_scenes_passes_on_gpu_and_cpu(root, tmp_path):
    d = json.loads((root / "scenes/sphere.json").read_text())
    d.setdefault("engine", {})["passes"] = [{"gaussian": {"sigma_mm": 1.5}}, {"closing": {"radius_mm": 1}}, "gradient"]
    scene = tmp_path / "sphere.json"
    scene.write_text(json.dumps(d))
    passes = isotouch.scene_passes(str(scene))
    assert [p.label for p in passes] == ["gaussian(sigma 1.5 mm)", "closing(radius 1 mm)", "gradient"]
    vol = isotouch.scene_setup(str(scene))["volume"]
    r = isotouch.check(vol, passes, device="")
    assert r["outputs"]["samples"]["nonfinite"] == 0 and r["outputs"]["field"]["nonfinite"] == 0
    # the filtered field is not the raw volume: the passes ran
    assert not np.array_equal(r["cpu"]["field"], vol.array)


def test_check_all_is_the_cli_report(head_path):
    rc, text = isotouch.check_all(volume_path=head_path)
    assert rc == 0 and "gradient" in text


# ---- live ----


def test_live_session_edits_undo_and_recording(root, tmp_path):
    rec = str(tmp_path / "live.rec")
    with isotouch.LiveSession(str(root / "scenes/sphere.json"), haptic="sim", record=rec) as live:
        live.wait_ticks(300)
        centre = live.observe()["vhip"]
        assert live.begin_stroke() and live.brush("carve", centre, radius_m=3e-3) and live.end_stroke()
        live.wait_ticks(500)
        assert live.undo()
        live.wait_ticks(700)
        running = live.stats()
    stats = live.stats()
    assert running["ticks"] > 100 and stats["ticks"] >= running["ticks"]
    assert stats["edits_applied"] == 4 and stats["faults"] == 0
    r = isotouch.load_recording(rec)
    assert r["complete"] and len(r["ticks"]["t"]) == stats["ticks"]
    assert r["edits"]["kind"] == ["begin_stroke", "brush", "end_stroke", "undo"]
    assert r["edits"]["brush"][1] == "carve"
    np.testing.assert_allclose(r["edits"]["centre"][1], centre)
    with pytest.raises(ValueError, match="kind"):
        live.brush("paint", centre)

def test_edits_after_stop_are_refused_not_accepted(root, tmp_path):
    """An edit after stop() can never be applied: it raises, and the session's counters show none."""
    live = isotouch.LiveSession(str(root / "scenes/sphere.json"), haptic="sim")
    live.start()
    live.wait_ticks(100)
    centre = live.observe()["vhip"]
    live.stop()
    before = live.stats()["edits_requested"]
    with pytest.raises(RuntimeError, match="brush: the session is stopped"):
        live.brush("carve", centre)
    with pytest.raises(RuntimeError, match="undo: the session is stopped"):
        live.undo()
    assert live.stats()["edits_requested"] == before


def test_the_zero_sent_at_stop_is_the_recordings_last_tick(cli, root, tmp_path):
    """The device is left with an exact zero: the recording's last tick says so (held: the
    renderer not ticked, force 0), and the recording still replays bit for bit."""
    rec = str(tmp_path / "stop.rec")
    with isotouch.LiveSession(str(root / "scenes/sphere.json"), haptic="sim", record=rec) as live:
        while not live.observe()["contact"] and live.observe()["tick"] + 1 < live.script_ticks:
            live.wait_ticks(live.observe()["tick"] + 11)
        assert live.observe()["contact"], "the script never touched the sphere"
    r = isotouch.load_recording(rec)
    ticks = r["ticks"]
    assert r["complete"] and len(ticks["t"]) == live.stats()["ticks"]
    assert np.linalg.norm(ticks["force"][-2]) > 0  # stopped while pressing
    assert ticks["held"][-1]
    assert np.array_equal(ticks["force"][-1], [0.0, 0.0, 0.0])
    p = subprocess.run([cli, "replay", rec, "--quiet"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr


def test_live_session_on_a_playback_device(root, tmp_path):
    """A trace.csv whose HIPs no scripted hand would reach: the session is given those."""
    k = np.arange(3000)
    hip = np.stack([0.005 + 1e-5 * k, np.full(k.shape, 0.007), np.full(k.shape, 0.011)], axis=1)
    rows = np.column_stack([k * 1e-3, hip, hip, np.zeros((len(k), 6))])
    trace = tmp_path / "trace.csv"
    np.savetxt(trace, rows, delimiter=",", fmt="%.9g", comments="",
               header="t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m,vhip_y_m,vhip_z_m,f_x_n,f_y_n,f_z_n,contact,"
                      "plane_update,tick_ns")
    with isotouch.LiveSession(str(root / "scenes/sphere.json"), haptic=f"playback:{trace}") as pb:
        pb.wait_ticks(300)
        seen = pb.observe()
    assert seen["tick"] > 100
    assert np.min(np.linalg.norm(hip - np.array(seen["hip"]), axis=1)) < 1e-9


def test_live_session_on_the_device_emulator(cli, root, tmp_path):
    """The head scene's hand played by isotouch-devemu; what the emulator received is the truth."""
    emu = os.environ.get("ISOTOUCH_DEVEMU")
    assert emu, "ISOTOUCH_DEVEMU is not set (ctest sets it)"
    scene, hand, sock = str(root / "scenes/head.json"), str(tmp_path / "hand.csv"), str(tmp_path / "dev.sock")
    subprocess.run([cli, "run", scene, "--hand-path", hand], check=True, capture_output=True, timeout=300)
    dev = subprocess.Popen([emu, "--socket", sock, "--path", hand, "--seconds", "30"], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(200):
            if os.path.exists(sock):
                break
            time.sleep(0.05)
        with isotouch.LiveSession(scene, haptic="emu:" + sock) as live:
            live.wait_ticks(live.script_ticks)
        stats = live.stats()
    finally:
        dev.send_signal(signal.SIGTERM)
        log = dev.communicate(timeout=60)[0]
    m = re.search(r"(\d+) outputs received \((\d+) refused\).*max \|F\| ([\d.]+) N", log)
    assert m, log
    received, refused, fmax = int(m.group(1)), int(m.group(2)), float(m.group(3))
    assert stats["ticks"] > 1000 and stats["faults"] == 0
    assert received > 1000 and refused == 0
    assert 0.5 < fmax <= 3.3, f"max |F| the emulator received: {fmax} N"


def test_a_live_session_dropped_while_running_is_stopped_and_freed(root, tmp_path):
    """Neither stop() nor a with block: dropping the object stops the session (the recording
    completed) and, no servo thread having been abandoned in the renderer, frees it: its device
    closes the link, so the emulator (one host at a time) serves the next session. A session
    whose servo thread was abandoned is never freed instead (stop() raises ServoAbandoned):
    test_a_stuck_renderer_is_abandoned_with_the_force_off_and_the_session_kept."""
    emu = os.environ.get("ISOTOUCH_DEVEMU")
    assert emu, "ISOTOUCH_DEVEMU is not set (ctest sets it)"
    scene, sock, rec = str(root / "scenes/sphere.json"), str(tmp_path / "dev.sock"), str(tmp_path / "dropped.rec")
    dev = subprocess.Popen([emu, "--socket", sock, "--seconds", "30"], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(200):
            if os.path.exists(sock):
                break
            time.sleep(0.05)
        first = isotouch.LiveSession(scene, haptic="emu:" + sock, record=rec)
        first.start()
        first.wait_ticks(300)
        del first
        gc.collect()
        r = isotouch.load_recording(rec)
        assert r["complete"] and len(r["ticks"]["t"]) > 100
        with isotouch.LiveSession(scene, haptic="emu:" + sock) as second:
            second.wait_ticks(300)
        stats = second.stats()
    finally:
        dev.send_signal(signal.SIGTERM)
        log = dev.communicate(timeout=60)[0]
    assert stats["ticks"] > 100 and stats["faults"] == 0
    m = re.search(r"(\d+) connections", log)
    assert m and int(m.group(1)) == 2, log
    assert issubclass(isotouch.ServoAbandoned, isotouch.Error)



@pytest.mark.parametrize("how", ["stop", "with"])
def test_a_stuck_renderer_is_abandoned_with_the_force_off_and_the_session_kept(root, tmp_path, how):
    """A renderer that stops returning (the test seam ISOTOUCH_PY_TEST_STUCK_AT_TICK, in a
    child process): stop(), or leaving the with block, raises ServoAbandoned; the session is
    never freed under the stuck thread (the seam aborts the process if it is), the
    interpreter exits 0, and the emulator's last output received is a disabled zero after
    forces in contact."""
    emu = os.environ.get("ISOTOUCH_DEVEMU")
    assert emu, "ISOTOUCH_DEVEMU is not set (ctest sets it)"
    scene, sock = str(root / "scenes/sphere.json"), str(tmp_path / "dev.sock")
    # The hand 2 mm outside the sphere's top (radius 20 mm about the device origin), +-5 mm: in contact half the time.
    dev = subprocess.Popen([emu, "--socket", sock, "--hold", "0,0,0.022", "--sine-mm", "5", "--seconds", "60"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    script = textwrap.dedent(f"""
        import gc, sys, time, isotouch
        def until_stuck(live):  # the seam's tick is 1000: the servo thread stays inside the renderer from there
            give_up = time.monotonic() + 30
            while live.stats()["ticks"] < 999:
                if time.monotonic() > give_up:
                    sys.exit("the servo never reached tick 999")
                live.wait(0.05)
            live.wait(0.1)
        try:
            if {how!r} == "stop":
                live = isotouch.LiveSession({scene!r}, haptic={"emu:" + sock!r})
                live.start()
                until_stuck(live)
                live.stop()
            else:
                with isotouch.LiveSession({scene!r}, haptic={"emu:" + sock!r}) as live:
                    until_stuck(live)
            print("returned")
        except isotouch.ServoAbandoned as e:
            print("raised:", e)
        live.stop()  # idempotent: the abandonment was raised once
        del live
        gc.collect()
        print("dropped")
    """)
    try:
        for _ in range(200):
            if os.path.exists(sock):
                break
            time.sleep(0.05)
        env = dict(os.environ, ISOTOUCH_PY_TEST_STUCK_AT_TICK="1000")
        r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    finally:
        dev.send_signal(signal.SIGTERM)
        log = dev.communicate(timeout=60)[0]
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "raised: live session: servo thread: the renderer has not returned" in r.stdout, out
    assert r.stdout.rstrip().endswith("dropped"), out
    fmax = float(re.search(r"max \|F\| ([\d.e+-]+) N", log).group(1))
    assert fmax > 0.5, f"no force in contact before the renderer stuck: {log}"
    assert re.search(r"last output: enable 0, \|F\| 0 N", log), log


def test_ctrl_c_stops_a_live_session_cleanly(root, tmp_path):
    rec = tmp_path / "interrupted.rec"
    script = textwrap.dedent(f"""
        import os, signal, threading, isotouch
        live = isotouch.LiveSession({str(root / 'scenes/sphere.json')!r}, record={str(rec)!r})
        live.start()
        threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        try:
            live.wait(30)
        except KeyboardInterrupt:
            print("interrupted", live.stats()["ticks"])
    """)
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    assert time.monotonic() - t0 < 25
    ticks = int(re.search(r"interrupted (\d+)", p.stdout).group(1))
    r = isotouch.load_recording(str(rec))  # complete: stop() wrote the end record
    assert r["complete"] and len(r["ticks"]["t"]) == ticks > 0
    assert not (tmp_path / "interrupted.rec.part").exists()


# ---- the offline benchmark ----


def test_bench_offline_prints_both_figures_and_a_verdict(root):
    p = subprocess.run([sys.executable, str(root / "python/bench_offline.py"), "--scenes", "sphere",
                        "--algorithms", "avila", "--calls", "20", "--min-ticks", "10000"],
                       capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    row = re.search(r"sphere\s+avila\s+(\d+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)", p.stdout)
    assert row, p.stdout
    ticks, cpp, py, ratio = int(row.group(1)), *map(float, row.group(2, 3, 4))
    assert ticks >= 10000 and cpp > 0 and py > 0
    assert ratio == pytest.approx(py / cpp, rel=0.01)  # the printed verdict follows from the figures
    assert re.search(r"verdict: Python within 10 % of C\+\+ on \d+ of 1", p.stdout)
    assert "scheduling of the timed calls: " in p.stdout


# ---- installed ----


def test_import_from_an_installed_prefix(tmp_path, head_path):
    build = os.environ.get("ISOTOUCH_BUILD_DIR")
    assert build, "ISOTOUCH_BUILD_DIR is not set (ctest sets it)"
    prefix = tmp_path / "prefix"
    subprocess.run(["cmake", "--install", build, "--prefix", str(prefix)], check=True, capture_output=True,
                   timeout=600)
    site = prefix / "lib/python3/dist-packages"
    assert (site / "isotouch/__init__.py").exists()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(site)
    p = subprocess.run([sys.executable, "-c", "import isotouch; print(isotouch.__file__); "
                        f"print(isotouch.load_volume({head_path!r}).array.shape)"],
                       capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines() == [str(site / "isotouch/__init__.py"), "(93, 64, 64)"]
