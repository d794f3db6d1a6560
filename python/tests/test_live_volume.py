"""A live session on a volume made in Python (no scene file): an isotouch.Volume or a numpy
array, the isovalue given as tau. The scripted hand of 'sim' must press on the isosurface the
array holds: a sphere of known centre and radius, checked from the geometry, not the renderer."""
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import isotouch

N, SPACING, RADIUS = 48, 1e-3, 15e-3  # voxels per axis, [m], [m]


def sphere_array():
    """(nz, ny, nx) float32: RADIUS - distance to the box's centre [m]; tau = 0 is the sphere."""
    i = np.arange(N) * SPACING
    z, y, x = np.meshgrid(i, i, i, indexing="ij")
    c = (N - 1) * SPACING / 2
    return (RADIUS - np.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2)).astype(np.float32)


def pressed_points(live):
    """The VHIPs [m, grid-world] of the ticks seen in contact with a force, every 10th tick or so
    over the whole script: the loop stops on the servo's ticks (what the simulated hand moves
    on), not on the wall clock, which runs ahead of them on a loaded machine."""
    points = []
    while True:
        o = live.observe()
        if o["contact"] and np.linalg.norm(o["force"]) > 0:
            points.append(o["vhip"])
        if o["tick"] + 1 >= live.script_ticks:
            return np.array(points)
        live.wait_ticks(o["tick"] + 11)


def assert_on_sphere(points):
    assert len(points) > 5, "the scripted hand never pressed on the sphere"
    c = (N - 1) * SPACING / 2
    r = np.linalg.norm(points - c, axis=1)
    np.testing.assert_allclose(r, RADIUS, atol=SPACING)  # the proxy stays on the surface, within a voxel


@pytest.mark.parametrize("how", ["array", "volume"])
def test_a_live_session_on_a_python_volume_presses_on_its_isosurface(how):
    a = sphere_array()
    if how == "array":
        live = isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=0.0, haptic="sim")
    else:
        live = isotouch.LiveSession(isotouch.Volume(a, spacing=(SPACING,) * 3), tau=0.0, haptic="sim")
    with live:
        assert live.duration_s > 0
        points = pressed_points(live)
    assert live.stats()["faults"] == 0
    assert_on_sphere(points)


def test_the_isovalue_from_params_with_its_renderer():
    p = isotouch.HriParams(tau=0.0, stiffness_n_per_m=300.0)
    with isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3, params=p) as live:
        points = pressed_points(live)
    assert_on_sphere(points)


def test_a_renderer_given_as_params_gets_the_scene_files_checks():
    a = sphere_array()
    with pytest.raises(ValueError, match=r"stiffness_n_per_m: 100000, must be at most the stability bound"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, params=isotouch.HriParams(tau=0.0, stiffness_n_per_m=1e5))
    with pytest.raises(ValueError, match=r"tau: nan given, must be a finite isovalue"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=float("nan"))
    with pytest.raises(ValueError, match=r"force_limit_n: .*must be in \(0, 1000\] N"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, params=isotouch.HriParams(tau=0.0, force_limit_n=5000.0))


def test_a_volume_without_an_isovalue_is_refused_not_run_at_zero():
    with pytest.raises(ValueError, match=r"tau: no isovalue given .*a Volume does not carry one"):
        isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3)
    with pytest.raises(ValueError, match="tau: no isovalue given"):
        isotouch.LiveSession(isotouch.Volume(sphere_array(), spacing=(SPACING,) * 3))


def test_argument_errors_name_the_argument(root, tmp_path):
    a = sphere_array()
    with pytest.raises(ValueError, match=r"tau: 1 given, but params.tau is 0"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=1.0, params=isotouch.HriParams(tau=0.0))
    p = isotouch.HriParams(tau=0.0)
    p.velocity_cutoff_hz = 150.0  # no scene key carries it: a replay would render otherwise
    with pytest.raises(ValueError, match="record: params.velocity_cutoff_hz 150 cannot be recorded"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, params=p, record=str(tmp_path / "x.rec"))
    assert os.listdir(tmp_path) == []
    paper_tool = isotouch.HriParams(tau=0.0)
    paper_tool.variant = isotouch.Variant.paper
    paper_tool.tool_radius_m = 0.002  # the paper variant renders a point: the scene's parser refuses it
    with pytest.raises(ValueError, match=r"record: params cannot be recorded as a scene's servo section: .*radius_mm"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, params=paper_tool, record=str(tmp_path / "x.rec"))
    assert os.listdir(tmp_path) == []
    with pytest.raises(ValueError, match="tau: the scene .* gives its own isovalue"):
        isotouch.LiveSession(str(root / "scenes/sphere.json"), tau=0.0)
    with pytest.raises(RuntimeError, match=r"isovalue.*outside the finite data range"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=1.0)
    with pytest.raises(ValueError, match=r"spacing\[1\] is -1"):
        isotouch.LiveSession(a, spacing=(SPACING, -1.0, SPACING), tau=0.0)


def test_the_script_is_waited_for_on_the_servos_ticks():
    """wait_ticks returns once the servo has run the ticks asked for, whatever the wall clock
    says: the script's whole length is seen by the simulated hand."""
    with isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3, tau=0.0) as live:
        assert live.script_ticks == int(np.ceil(live.duration_s * 1000))  # the default scene's 1 kHz servo
        live.wait_ticks(live.script_ticks)
        assert live.observe()["tick"] + 1 >= live.script_ticks
    with pytest.raises(TimeoutError, match=r"wait_ticks: 0 of 10 ticks run after timeout_s"):
        isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3, tau=0.0).wait_ticks(10, timeout_s=0.05)


def test_an_array_is_named_in_memory_and_nothing_is_written_in_the_working_folder(tmp_path, monkeypatch):
    """A numpy array has no file: its scene and errors name it as in memory, never as a file
    of the working folder; a session on it writes nothing there."""
    monkeypatch.chdir(tmp_path)
    a = sphere_array()
    assert isotouch.Volume(a, spacing=(SPACING,) * 3).path == "memory:numpy array"
    with isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=0.0) as live:
        live.wait_ticks(100)
    with pytest.raises(RuntimeError, match=r"outside the finite data range .* of memory:numpy array: there is no isosurface"):
        isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=1.0)
    assert sorted(os.listdir(tmp_path)) == []


PEAK_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import isotouch

    def status(field):
        for line in open("/proc/self/status"):
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024

    n = 256
    i = np.arange(n, dtype=np.float32) - 128
    r2 = i[None, :] ** 2 + i[:, None] ** 2
    base = status("VmRSS")
    a = np.empty((n, n, n), np.float32)
    for k in range(n):  # slice by slice: no full-size temporaries
        a[k] = 100.0 - np.sqrt(r2 + i[k] ** 2)
    given = a if sys.argv[1] == "array" else isotouch.Volume(a, spacing=(1e-3,) * 3)
    live = isotouch.LiveSession(given, spacing=(1e-3,) * 3, tau=0.0) if sys.argv[1] == "array" else \\
        isotouch.LiveSession(given, tau=0.0)
    print((status("VmHWM") - base) / a.nbytes)
""")


def peak_in_arrays(how):
    """The peak RSS (VmHWM) of a fresh process making a 256^3 float32 array and a LiveSession
    on it (`how`: the array itself, or an isotouch.Volume made from it), above the RSS before
    the array, in units of the array's size."""
    p = subprocess.run([sys.executable, "-c", PEAK_SCRIPT, how], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    return float(p.stdout.split()[-1])


def test_a_session_on_an_array_makes_one_copy_fewer_than_on_a_volume():
    """The array is copied once into the session's volume and moved from there (the session
    edits its own copy); a Volume the caller keeps needs one copy more. Measured: the array
    path's peak was the Volume path's (both 11.4 x the array) before the move. The rest of the
    peak is not copies: the engine's dense truth field (16 B a voxel) and the first snapshot."""
    on_array, on_volume = peak_in_arrays("array"), peak_in_arrays("volume")
    print(f"peak above the RSS before a 256^3 float32 array: LiveSession(array) {on_array:.2f} x the array, "
          f"LiveSession(Volume(array)) {on_volume:.2f} x")
    assert on_array <= on_volume - 0.5


def test_a_recorded_session_on_an_array_replays_bit_for_bit(cli, tmp_path):
    """record= on an array: the volume (RECORD.nrrd) and its scene (RECORD.scene.json) are
    written beside the recording, which carries that scene; `isotouch replay` replays it bit
    for bit, and the volume it reads holds the array's voxels."""
    rec = tmp_path / "array.rec"
    a = sphere_array()
    with isotouch.LiveSession(a, spacing=(SPACING,) * 3, tau=0.0, record=str(rec)) as live:
        live.wait_ticks(live.script_ticks)
    assert sorted(os.listdir(tmp_path)) == ["array.rec", "array.rec.nrrd", "array.rec.scene.json"]
    r = isotouch.load_recording(str(rec))
    assert r["complete"] and len(r["ticks"]["t"]) == live.stats()["ticks"] >= live.script_ticks
    assert r["scene_path"] == str(tmp_path / "array.rec.scene.json")
    np.testing.assert_array_equal(isotouch.load_volume(str(tmp_path / "array.rec.nrrd")).array, a)
    with open(tmp_path / "array.rec.scene.json") as f:
        description = json.load(f)["description"]
    assert ": isovalue 0 (inside above), chosen by the program (LiveSession's tau); the probe" in description, description
    p = subprocess.run([cli, "replay", str(rec)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "IDENTICAL: every force, VHIP and snapshot version equals the recorded one bit for bit" in p.stdout, p.stdout


def test_a_recorded_session_with_params_replays_bit_for_bit(cli, tmp_path):
    """record= with params=: the renderer's parameters are the scene's servo section (read
    back equal, or refused), so `isotouch replay` renders the same forces bit for bit."""
    rec = tmp_path / "params.rec"
    p = isotouch.HriParams(tau=0.0, stiffness_n_per_m=500.0, plane_update_period=3)
    p.intersection_steps = 6
    with isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3, params=p, record=str(rec)) as live:
        live.wait_ticks(live.script_ticks)
    with open(tmp_path / "params.rec.scene.json") as f:
        servo = json.load(f)["servo"]
    assert (servo["stiffness_n_per_m"], servo["plane_update_period"], servo["intersection_steps"]) == (500.0, 3, 6), servo
    r = subprocess.run([cli, "replay", str(rec)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "IDENTICAL: every force, VHIP and snapshot version equals the recorded one bit for bit" in r.stdout, r.stdout


def test_record_never_replaces_a_file_beside_it(tmp_path):
    """record= writes RECORD.nrrd and RECORD.scene.json: where one already exists (the user's
    own ct.nrrd for record="ct") the session is refused naming it, and the file is kept."""
    rec = tmp_path / "ct"
    own = tmp_path / "ct.nrrd"
    own.write_bytes(b"the user's own scan")
    with pytest.raises(ValueError, match="ct.nrrd exists"):
        isotouch.LiveSession(sphere_array(), spacing=(SPACING,) * 3, tau=0.0, record=str(rec))
    assert own.read_bytes() == b"the user's own scan"
    assert sorted(os.listdir(tmp_path)) == ["ct.nrrd"]
