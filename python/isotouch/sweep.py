"""Error-against-time sweeps on a Dask cluster: `python3 -m isotouch.sweep SWEEP.json`.

A sweep file names stroke scenes (those of `isotouch report`: sphere, box, three-spheres, knot,
head, chest, or scene JSON paths), methods (HRI with plane-update periods n and options, the
paper's HRI, Avila-Sobierajski, Blezek-Robb) with parameter grids, and repetitions. Each
(scene, configuration, repetition) is one task: the scene's recorded stroke replayed through
the renderer and measured exactly as `isotouch report` does (isotouch.measure_stroke), a pure
function of its inputs but for the time columns. Tasks run on a Dask client (a LocalCluster of
single-threaded worker processes, a scheduler address, or a scheduler file) or serially in this
process; each worker prepares a scene once and keeps it.

Results: OUT/results.csv, one row per task keyed by a hash of the task, appended one whole line
at a time as tasks finish, so a sweep stopped (Ctrl-C, a lost machine) and started again skips
what is written; OUT/summary.md, a table per method and configuration; OUT/error_vs_time.png,
surface error against mean tick time per scene, every method (as `isotouch report` draws it).
"""
import argparse
import csv
import hashlib
import io
import itertools
import json
import logging
import os
import pathlib
import socket
import sys
import time

FORMAT = "isotouch-sweep-2"  # part of every task's key: a change to what a task measures changes it
ALGORITHMS = {"hri": "HRI", "hri-paper": "HRI-paper", "avila": "Avila-Sobierajski", "blezek": "Blezek-Robb"}
HRI_ALGORITHMS = ("hri", "hri-paper")
# Grid parameters per algorithm family, each with its meaning (the renderers' fields).
GRID_KEYS = {
    "stiffness_n_per_m": "K, device space [N/m]",
    "damping_n_s_per_m": "B, device space [N s/m]",
    "force_limit_n": "force clamp [N]",
}
HRI_GRID_KEYS = dict(GRID_KEYS, tool_radius_m="spherical tool radius [m] (0: a point)",
                     friction_mu_s="static friction coefficient", friction_mu_d="dynamic friction coefficient")
METHOD_KEYS = {"algorithm", "n", "options", "grid", "timing_replays"}
TOP_KEYS = {"scenes", "methods", "repetitions", "timing_replays", "figures", "isovalues"}
EXACT_SHAPES = ("sphere", "box", "three-spheres", "knot")  # truth fixed to their own isovalue

# What a task measured (equal between runs of the same task) and what it took (not).
FIGURES = ["ticks", "contact_ticks", "surface_err_rms_m", "angle_err_rms_deg", "force_err_rms_n",
           "max_force_step_n", "max_force_step_slide_n", "pop_throughs", "voxel_m"]
TIMES = ["tick_ns_mean", "tick_ns_p99", "task_s", "prepare_s", "host", "cpu", "worker_pid"]
IDENTITY = ["key", "scene", "isovalue", "algorithm", "n", "options", "params", "rep"]
# The figures a sweep file can ask for (`figures`): the summary's columns for each, as
# (header, cell(rows)). results.csv always holds every figure: one task computes them all at
# once, and one file layout keeps a restarted sweep's rows comparable.
SUMMARY_FIGURES = {
    "surface_error": [("surface RMS [voxel] mean / max",
                       lambda rs: f"{_mean(_surface_voxels(rs)):.3g} / {max(_surface_voxels(rs)):.3g}")],
    "angle_error": [("normal angle RMS [deg] mean", lambda rs: f"{_mean([_f(r, 'angle_err_rms_deg') for r in rs]):.3g}")],
    "force_error": [("force err RMS [N] mean", lambda rs: f"{_mean([_f(r, 'force_err_rms_n') for r in rs]):.3g}")],
    "force_steps": [("max force step [N]", lambda rs: f"{max(_f(r, 'max_force_step_n') for r in rs):.3g}"),
                    ("max step sliding [N]", lambda rs: f"{max(_f(r, 'max_force_step_slide_n') for r in rs):.3g}")],
    "pop_throughs": [("pop-throughs", lambda rs: f"{sum(int(r['pop_throughs']) for r in rs)}")],
    "contact_fraction": [("contact fraction mean",
                          lambda rs: f"{_mean([_f(r, 'contact_ticks') / max(_f(r, 'ticks'), 1) for r in rs]):.3g}")],
    "tick_time": [("mean tick [ns] median", lambda rs: f"{_median([_f(r, 'tick_ns_mean') for r in rs]):.4g}"),
                  ("tick p99 [ns] median", lambda rs: f"{_median([_f(r, 'tick_ns_p99') for r in rs]):.4g}")],
}
DEFAULT_FIGURES = ["surface_error", "force_error", "force_steps", "pop_throughs", "tick_time"]
COLUMNS = IDENTITY + FIGURES + TIMES


class SweepError(ValueError):
    """A bad sweep file or results file: the message names the file, the field and the value."""


# ---------------------------------------------------------------------------------------------
# The sweep file


def _fail(path, field, value, why):
    raise SweepError(f"{path}: {field}: {json.dumps(value)}: {why}")


def _int_list(path, field, value, least):
    vals = value if isinstance(value, list) else [value]
    if not vals or any(isinstance(v, bool) or not isinstance(v, int) or v < least for v in vals):
        _fail(path, field, value, f"must be an integer >= {least} or a non-empty list of them")
    return vals


def _positive_int(path, field, value):
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        _fail(path, field, value, "must be an integer >= 1")
    return value


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")


def _options(path, field, value):
    """HRI options as `isotouch report` names them: INTERSECTION/NORMAL[/shading][/recoveryNms]."""
    vals = value if isinstance(value, list) else [value]
    if not vals:
        _fail(path, field, value, "must be a non-empty list")
    for o in vals:
        if not isinstance(o, str) or _hri_option_error(o):
            _fail(path, field, o, _hri_option_error(o) if isinstance(o, str) else "must be a string")
    return vals


def _hri_option_error(option):
    parts = option.split("/")
    if len(parts) < 2:
        return "must be INTERSECTION/NORMAL[/shading][/recoveryNms], e.g. linear/samples or secant4/central"
    inter, normal, extras = parts[0], parts[1], parts[2:]
    if not (inter == "linear" or _counted(inter, "secant") or _counted(inter, "bisect")):
        return f"intersection '{inter}': linear, secantK or bisectK (K steps >= 1)"
    if normal not in ("samples", "central", "exact"):
        return f"normal '{normal}': samples, central or exact"
    for e in extras:
        if e != "shading" and not (e.startswith("recovery") and e.endswith("ms") and _counted(e[:-2], "recovery")):
            return f"'{e}': shading or recoveryNms (N milliseconds)"
    return None


def _counted(token, prefix):
    rest = token[len(prefix):]
    return token.startswith(prefix) and rest.isdigit() and int(rest) >= 1


def _grid(path, field, value, algorithm):
    allowed = HRI_GRID_KEYS if algorithm in HRI_ALGORITHMS else GRID_KEYS
    if not isinstance(value, dict):
        _fail(path, field, value, "must be an object of parameter: [values]")
    for k, vals in value.items():
        if k not in allowed:
            _fail(path, f"{field}.{k}", vals, f"not a parameter of {algorithm}; one of {', '.join(sorted(allowed))}")
        vals = vals if isinstance(vals, list) else [vals]
        if not vals or not all(_number(v) and v >= 0 for v in vals):
            _fail(path, f"{field}.{k}", value[k], "must be a finite number >= 0 or a non-empty list of them")
    return {k: (v if isinstance(v, list) else [v]) for k, v in sorted(value.items())}


def _method(path, i, m):
    field = f"methods[{i}]"
    if not isinstance(m, dict):
        _fail(path, field, m, "must be an object with 'algorithm'")
    for k in m:
        if k not in METHOD_KEYS:
            _fail(path, f"{field}.{k}", m[k], f"unknown field; one of {', '.join(sorted(METHOD_KEYS))}")
    alg = m.get("algorithm")
    if alg not in ALGORITHMS:
        _fail(path, f"{field}.algorithm", alg, f"must be one of {', '.join(ALGORITHMS)}")
    hri = alg in HRI_ALGORITHMS
    for k in ("n", "options"):
        if k in m and not hri:
            _fail(path, f"{field}.{k}", m[k], f"HRI only; {alg} has no {k}")
    ns = _int_list(path, f"{field}.n", m.get("n", 1), 1)
    opts = _options(path, f"{field}.options", m.get("options", "linear/samples" if alg == "hri" else "linear/central"))
    grid = _grid(path, f"{field}.grid", m.get("grid", {}), alg)
    replays = _positive_int(path, f"{field}.timing_replays", m["timing_replays"]) if "timing_replays" in m else None
    return {"algorithm": alg, "n": ns if hri else [1], "options": opts if hri else [""], "grid": grid,
            "timing_replays": replays}


def load_sweep(path):
    """The sweep file at `path`, checked: a dict of scenes, methods, repetitions, timing_replays.
    Scene paths ending in .json are taken relative to the sweep file. Raises SweepError."""
    path = str(path)
    try:
        with open(path, encoding="utf-8") as f:
            spec = json.load(f)
    except OSError as e:
        raise SweepError(f"{path}: cannot read: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise SweepError(f"{path}: not JSON: line {e.lineno} column {e.colno}: {e.msg}") from None
    return check_sweep(spec, path, pathlib.Path(path).resolve().parent)


def check_sweep(spec, path="(sweep)", base="."):
    """A sweep given as a dict, checked as load_sweep checks a file (`path` names it in errors;
    scene JSON paths are relative to `base`)."""
    if not isinstance(spec, dict):
        _fail(path, "(top level)", spec, "must be an object with scenes and methods")
    for k in spec:
        if k not in TOP_KEYS:
            _fail(path, k, spec[k], f"unknown field; one of {', '.join(sorted(TOP_KEYS))}")
    scenes = spec.get("scenes")
    if not isinstance(scenes, list) or not scenes or not all(isinstance(s, str) and s for s in scenes):
        _fail(path, "scenes", scenes, "must be a non-empty list of scene names or scene JSON paths")
    if len(set(scenes)) != len(scenes):
        _fail(path, "scenes", scenes, "names a scene twice")
    methods = spec.get("methods")
    if not isinstance(methods, list) or not methods:
        _fail(path, "methods", methods, "must be a non-empty list of methods")
    base = pathlib.Path(base)
    figures = spec.get("figures", DEFAULT_FIGURES)
    if (not isinstance(figures, list) or not figures or len(set(map(str, figures))) != len(figures)
            or not all(f in SUMMARY_FIGURES for f in figures)):
        _fail(path, "figures", figures, f"must be a non-empty list of distinct names from {', '.join(SUMMARY_FIGURES)}")
    return {
        "isovalues": _isovalues(path, spec.get("isovalues", {}), scenes),
        "scenes": scenes,
        "scene_paths": {s: (str(base / s) if s.endswith(".json") else s) for s in scenes},
        "methods": [_method(path, i, m) for i, m in enumerate(methods)],
        "repetitions": _positive_int(path, "repetitions", spec.get("repetitions", 1)),
        "timing_replays": _positive_int(path, "timing_replays", spec.get("timing_replays", 5)),
        "figures": figures,
    }


def _isovalues(path, value, scenes):
    """{scene: [isovalue, ...]} for scene files measured at other isovalues than their own."""
    if not isinstance(value, dict):
        _fail(path, "isovalues", value, "must be an object: scene -> list of isovalues")
    for scene, taus in value.items():
        field = f"isovalues.{scene}"
        if scene not in scenes:
            _fail(path, field, taus, "not one of the sweep's scenes")
        if scene in EXACT_SHAPES:
            _fail(path, field, taus, "an exact shape's truth is its own isovalue; only scene files (head, chest, "
                                     "a scene JSON) take others")
        if (not isinstance(taus, list) or not taus or not all(_number(t) for t in taus)
                or len(set(taus)) != len(taus)):
            _fail(path, field, taus, "must be a non-empty list of distinct finite numbers (volume units)")
    return {k: [float(t) for t in v] for k, v in value.items()}


def task_key(task):
    """A hash of what a task computes (scene, isovalue when not the scene's own, algorithm, n,
    options, params, rep, replays)."""
    ident = {k: task[k] for k in ("scene", "algorithm", "n", "options", "params", "rep", "timing_replays")}
    if task["isovalue"] != "":
        ident["isovalue"] = task["isovalue"]
    blob = json.dumps([FORMAT, ident], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def make_tasks(sweep):
    """One task per (scene, configuration, repetition), in a fixed order."""
    tasks = []
    for scene, iso in ((sc, t) for sc in sweep["scenes"] for t in sweep["isovalues"].get(sc, [""])):
        for m in sweep["methods"]:
            grid_keys = list(m["grid"])
            for n, opt, values in itertools.product(m["n"], m["options"], itertools.product(*m["grid"].values())):
                for rep in range(sweep["repetitions"]):
                    t = {"scene": scene, "isovalue": iso, "scene_path": sweep["scene_paths"][scene],
                         "algorithm": m["algorithm"],
                         "n": n, "options": opt, "params": dict(zip(grid_keys, values)), "rep": rep,
                         "timing_replays": m["timing_replays"] or sweep["timing_replays"]}
                    t["key"] = task_key(t)
                    tasks.append(t)
    return tasks


def config_label(row):
    """The configuration a row belongs to, scene and repetition aside."""
    label = ALGORITHMS[row["algorithm"]]
    if row["algorithm"] in HRI_ALGORITHMS:
        label += f" n={row['n']} {row['options']}"
    params = row["params"] if isinstance(row["params"], dict) else json.loads(row["params"] or "{}")
    iso = f" isovalue={row['isovalue']}" if row.get("isovalue", "") != "" else ""
    return label + "".join(f" {k}={v}" for k, v in sorted(params.items())) + iso


# ---------------------------------------------------------------------------------------------
# One task (runs on a worker)

_SCENES = {}  # scene path -> StrokeScene, kept for the life of the worker process
_HOST = {}


def _host():
    if not _HOST:
        cpu = "unknown"
        try:
            with open("/proc/cpuinfo", encoding="utf-8") as f:
                cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
        except OSError:
            pass
        _HOST.update(host=socket.gethostname(), cpu=cpu)
    return _HOST


def _scene(path, isovalue=""):
    """The prepared scene (at `isovalue` unless "": the scene's own) and the seconds this call
    spent preparing it (0 when cached)."""
    import isotouch

    if (path, isovalue) in _SCENES:
        return _SCENES[(path, isovalue)], 0.0
    t0 = time.perf_counter()
    _SCENES[(path, isovalue)] = isotouch.stroke_scene(path, tau=None if isovalue == "" else isovalue)
    return _SCENES[(path, isovalue)], time.perf_counter() - t0


def _apply_option(p, option):
    import isotouch

    inter, normal, *extras = option.split("/")
    if inter.startswith("secant"):
        p.intersection, p.intersection_steps = isotouch.Intersection.secant, int(inter[6:])
    elif inter.startswith("bisect"):
        p.intersection, p.intersection_steps = isotouch.Intersection.bisection, int(inter[6:])
    else:
        p.intersection = isotouch.Intersection.linear
    p.normal = {"samples": isotouch.NormalSource.samples, "central": isotouch.NormalSource.central,
                "exact": isotouch.NormalSource.trilinear_exact}[normal]
    for e in extras:
        if e == "shading":
            p.force_shading = True
        else:
            p.recovery_time_s = int(e[len("recovery"):-2]) / 1000.0


def renderer_params(scene, task):
    """The renderer parameters of a task, as `isotouch report` builds them: HRI from the scene's
    reference parameters at period n with the task's options; the baselines from the scene's tau,
    inside and K, no damping, a 1 kN clamp; then the task's grid values."""
    import isotouch

    if task["algorithm"] in HRI_ALGORITHMS:
        p = scene.reference_params()
        p.plane_update_period = task["n"]
        _apply_option(p, task["options"])
        if task["algorithm"] == "hri-paper":
            p.variant = isotouch.Variant.paper
    else:
        p = isotouch.BaselineParams()
        p.tau, p.inside, p.stiffness_n_per_m = scene.tau, scene.inside, scene.stiffness_n_per_m
        p.damping_n_s_per_m, p.rate_hz, p.force_limit_n = 0.0, scene.rate_hz, 1e3
    for k, v in task["params"].items():
        if k.startswith("friction_"):
            fr = p.friction
            setattr(fr, k[len("friction_"):], float(v))
            p.friction = fr
        else:
            setattr(p, k, float(v))
    return p


def run_task(task):
    """One task: the row it writes (IDENTITY + FIGURES + TIMES). The same function runs serially
    and on Dask workers; every column but TIMES depends on the task alone."""
    import isotouch

    scene, prepare_s = _scene(task["scene_path"], task["isovalue"])
    t0 = time.perf_counter()  # task_s: the measurement alone; preparing the scene is prepare_s
    algorithm = "hri" if task["algorithm"] in HRI_ALGORITHMS else task["algorithm"]
    figures = isotouch.measure_stroke(scene, algorithm, renderer_params(scene, task), task["timing_replays"])
    row = {k: task[k] for k in IDENTITY}
    row["params"] = json.dumps(task["params"], sort_keys=True)
    row.update({k: figures[k] for k in FIGURES if k in figures})
    row["voxel_m"] = scene.voxel_m
    row.update(tick_ns_mean=figures["tick_ns_mean"], tick_ns_p99=figures["tick_ns_p99"],
               task_s=time.perf_counter() - t0, prepare_s=prepare_s, worker_pid=os.getpid(), **_host())
    return row


# ---------------------------------------------------------------------------------------------
# The results file


def _csv_line(values):
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(values)
    return buf.getvalue()


def _format(v):
    return repr(v) if isinstance(v, float) else v  # repr: every digit, so a re-read row is equal


class Results:
    """OUT/results.csv: the header written once (temporary file, then rename), then one
    os.write of a whole line per row on an O_APPEND descriptor, fsync'd. A line cut short by a
    crash (no newline) is dropped when the file is opened again."""

    def __init__(self, path):
        self.path = pathlib.Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not self.path.exists():
            tmp = self.path.with_name(self.path.name + ".tmp")
            tmp.write_text(_csv_line(COLUMNS), encoding="utf-8")
            os.replace(tmp, self.path)
        self._drop_partial_line()
        self.rows = read_results(self.path)
        self.fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)

    def _drop_partial_line(self):
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            with open(self.path, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)

    def keys(self):
        return {r["key"] for r in self.rows}

    def append(self, row):
        line = _csv_line([_format(row[c]) for c in COLUMNS]).encode()
        os.write(self.fd, line)
        os.fsync(self.fd)
        self.rows.append({c: str(_format(row[c])) for c in COLUMNS})

    def close(self):
        os.close(self.fd)


def read_results(path):
    """The rows of a results file as dicts of strings; SweepError if its header is not ours."""
    with open(path, encoding="utf-8", newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header != COLUMNS:
            raise SweepError(f"{path}: header: {json.dumps(header)}: not an isotouch sweep results file "
                             f"of this version (expected {','.join(COLUMNS)})")
        return [dict(zip(COLUMNS, r)) for r in reader if r]


# ---------------------------------------------------------------------------------------------
# Summary and plot


def _f(row, k):
    return float(row[k])


def _mean(xs):
    return sum(xs) / len(xs)


def _median(xs):
    xs = sorted(xs)
    return xs[len(xs) // 2]


def _surface_voxels(rs):
    return [_f(r, "surface_err_rms_m") / _f(r, "voxel_m") for r in rs]


def summary_markdown(rows, figures=DEFAULT_FIGURES):
    """One line per method and configuration over its scenes and repetitions: the columns of
    `figures` (SUMMARY_FIGURES' names), then the mean task time."""
    groups = {}
    for r in rows:
        groups.setdefault(config_label(r), []).append(r)
    cols = [c for f in figures for c in SUMMARY_FIGURES[f]] + [("task [s] mean", lambda rs: f"{_mean([_f(r, 'task_s') for r in rs]):.3g}")]
    out = ["| configuration | tasks | scenes | " + " | ".join(h for h, _ in cols) + " |",
           "|---|---|---|" + "---|" * len(cols)]
    for label in sorted(groups):
        rs = groups[label]
        out.append(f"| {label} | {len(rs)} | {len({r['scene'] for r in rs})} | " + " | ".join(c(rs) for _, c in cols) + " |")
    return "\n".join(out) + "\n"


def plot_error_vs_time(rows, path):
    """Surface error RMS [voxel] against mean tick [ns], log axes, a panel per scene, a series
    per configuration (config_label: HRI's n, options and grid values apart), its label in the
    legend: a colour family per algorithm, a shade and a marker per configuration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    matplotlib.rcParams["svg.fonttype"] = "none"  # an .svg keeps its labels as text
    scenes = list(dict.fromkeys((r["scene"], r["isovalue"]) for r in rows))
    configs = sorted({_plot_label(r) for r in rows})
    style = _series_styles(configs, {c: r["algorithm"] for r in rows for c in [_plot_label(r)]})
    cols = min(3, len(scenes))
    lines = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(lines, cols, figsize=(5.2 * cols, 3.8 * lines), squeeze=False)
    for ax, (scene, iso) in zip(axes.flat, scenes):
        for label in configs:
            pts = [(_f(r, "tick_ns_mean"), _f(r, "surface_err_rms_m") / _f(r, "voxel_m"))
                   for r in rows if (r["scene"], r["isovalue"]) == (scene, iso) and _plot_label(r) == label]
            pts = [(x, y) for x, y in pts if x > 0 and y > 0]  # log axes
            if pts:
                ax.scatter(*zip(*pts), s=16, label=label, **style[label])
        title = scene + (f" at isovalue {iso}" if iso != "" else "")
        ax.set(xscale="log", yscale="log", title=title, xlabel="mean tick [ns]", ylabel="surface error RMS [voxel]")
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_label(row):
    """config_label without the isovalue (each isovalue has its own panel)."""
    return config_label(dict(row, isovalue=""))


def _series_styles(labels, algorithm_of):
    """{label: scatter style}: the algorithm's colour map (HRI blues, HRI-paper purples, Avila
    reds, Blezek greens), shades spread over its configurations, markers cycling."""
    import matplotlib

    maps = {"hri": "Blues", "hri-paper": "Purples", "avila": "Reds", "blezek": "Greens"}
    markers = "osD^v<>pXh*"
    out = {}
    for alg, cmap in maps.items():
        mine = [lb for lb in labels if algorithm_of[lb] == alg]
        for i, lb in enumerate(mine):
            shade = 0.85 if len(mine) == 1 else 0.45 + 0.5 * i / (len(mine) - 1)
            out[lb] = {"color": matplotlib.colormaps[cmap](shade), "marker": markers[i % len(markers)]}
    return out


# ---------------------------------------------------------------------------------------------
# Running


class SweepTaskError(RuntimeError):
    """Tasks raised: the others' rows are written; the message names how many and why."""


def run_sweep(sweep, out_dir, client=None, log=print, progress_s=30.0):
    """Runs the tasks of `sweep` (load_sweep's dict) not yet in OUT/results.csv, on `client`
    (a dask.distributed Client) or, when None, serially in this process; then writes the summary
    and the plot. Says how far it is (tasks done, failed, the time left estimated from the
    tasks finished so far) at most every `progress_s` seconds [s] and when the last finishes.
    Returns the results' rows (dicts of strings). A task that raises is logged and counted;
    the rest run, and then SweepTaskError names how many failed (run again to retry them)."""
    out = pathlib.Path(out_dir)
    tasks = make_tasks(sweep)
    results = Results(out / "results.csv")
    failures = []
    try:
        done = results.keys()
        todo = [t for t in tasks if t["key"] not in done]
        log(f"sweep: {len(tasks)} tasks; {len(tasks) - len(todo)} already in {results.path}: skipped; "
            f"{len(todo)} to run on {'this process' if client is None else _describe(client)}", flush=True)
        progress = Progress(len(todo), log, progress_s)
        for task, row, error in _rows(todo, client):
            if error is None:
                results.append(row)
            else:
                failures.append(task)
                log(f"sweep: task {task['key']} ({task['scene']}, {config_label(task)}, rep {task['rep']}) failed: "
                    f"{type(error).__name__}: {error}", flush=True)
            progress.step(failed=error is not None)
    finally:
        results.close()
    rows = [r for r in results.rows if r["key"] in {t["key"] for t in tasks}]
    figures = sweep.get("figures", DEFAULT_FIGURES)
    (out / "summary.md").write_text(summary_markdown(rows, figures), encoding="utf-8")
    wrote = "summary.md"
    if rows and "surface_error" in figures and "tick_time" in figures:
        plot_error_vs_time(rows, out / "error_vs_time.png")
        wrote += ", error_vs_time.png"
    else:
        (out / "error_vs_time.png").unlink(missing_ok=True)
    log(f"sweep: {len(rows)} rows in {results.path}; {wrote} in {out}", flush=True)
    if failures:
        raise SweepTaskError(f"{len(failures)} of {len(todo)} tasks failed (each said above); "
                             f"their rows are not in {results.path}: run again to retry them")
    return rows


class Progress:
    """`sweep: 120/333 tasks done, 1 failed, 1m40s elapsed, about 3m05s left` at most every
    `every_s` seconds and after the last task; the time left is the elapsed time per finished
    task times the tasks left (tasks in flight at the start count as not yet begun)."""

    def __init__(self, total, log, every_s, clock=time.monotonic):
        self.total, self.log, self.every_s, self.clock = total, log, every_s, clock
        self.done = self.failed = 0
        self.start = self.last = clock()

    def step(self, failed=False):
        self.done += 1
        self.failed += failed
        now = self.clock()
        if now - self.last >= self.every_s or self.done == self.total:
            self.last = now
            self.log(self.line(now), flush=True)

    def line(self, now):
        elapsed = now - self.start
        left = elapsed / self.done * (self.total - self.done)
        return (f"sweep: {self.done}/{self.total} tasks done, {self.failed} failed, {_duration(elapsed)} elapsed, "
                f"about {_duration(left)} left")


def _duration(seconds):
    m, s = divmod(int(round(seconds)), 60)
    h, m = divmod(m, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else f"{m}m{s:02d}s" if m else f"{s}s"


def _rows(todo, client):
    """(task, row, None) or (task, None, exception) for each task of `todo` as it finishes
    (serially, or through Dask: a task lost with its worker is rescheduled on another by the
    scheduler, so each key yields exactly once)."""
    if client is None:
        for t in todo:
            try:
                yield t, run_task(t), None
            except Exception as e:  # noqa: BLE001 - counted and said; Ctrl-C still stops the sweep
                yield t, None, e
        return
    from dask.distributed import as_completed

    quiet_recovered_gathers()
    futures = client.map(run_task, todo, key=[f"isotouch-sweep-{t['key']}" for t in todo], pure=True)
    task_of = {f.key: t for f, t in zip(futures, todo)}
    try:
        for fut in as_completed(futures):
            if fut.status == "error":
                yield task_of[fut.key], None, fut.exception()
            elif fut.status == "cancelled":  # a task the cluster gave up on is a failed task, not the sweep's end
                yield task_of[fut.key], None, RuntimeError(f"task {task_of[fut.key]['key']} was cancelled by the cluster")
            else:
                yield task_of[fut.key], fut.result(), None
    finally:
        client.cancel(futures)


class _RecoveredGather(logging.Filter):
    """distributed's "Couldn't gather keys" (an ERROR with a traceback from the scheduler, a
    WARNING from the client) after a worker died holding finished results: the scheduler
    computes those tasks again elsewhere, so nothing is lost. Said as one WARNING that says so."""

    def filter(self, record):
        if "Couldn't gather" not in str(record.msg):
            return True
        args = record.args if isinstance(record.args, tuple) else ()  # a dict of named args: no keys to quote
        keys = args[0] if args and "keys %s" in str(record.msg) else args[-1] if args else ""
        record.msg = ("sweep: a worker was lost holding finished task results (%s); the scheduler runs those "
                      "tasks again on the other workers and nothing is lost (distributed: Couldn't gather keys)")
        record.args = (keys,)
        record.levelno, record.levelname = logging.WARNING, "WARNING"
        record.exc_info = record.exc_text = None
        return True


def quiet_recovered_gathers():
    """Installs _RecoveredGather on distributed's scheduler and client loggers (once)."""
    for name in ("distributed.scheduler", "distributed.client"):
        lg = logging.getLogger(name)
        if not any(isinstance(f, _RecoveredGather) for f in lg.filters):
            lg.addFilter(_RecoveredGather())


def _describe(client):
    workers = client.scheduler_info().get("workers", {})
    return f"{len(workers)} Dask workers ({client.scheduler.address})"


def connect(local_workers=None, scheduler=None, scheduler_file=None):
    """A Dask client, and the LocalCluster it owns (None when it joins a running scheduler)."""
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="30s"), None
    if scheduler_file:
        return Client(scheduler_file=scheduler_file, timeout="30s"), None
    n = local_workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster


def main(argv=None):
    ap = argparse.ArgumentParser(prog=os.environ.get("ISOTOUCH_SWEEP_PROG", "python3 -m isotouch.sweep"),
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("sweep", help="the sweep file (JSON)")
    ap.add_argument("--out", default="sweep-out", help="results folder (default: sweep-out)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--local-workers", type=int, metavar="N",
                       help="a LocalCluster of N single-threaded worker processes (default: the machine's cores)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler")
    where.add_argument("--scheduler-file", metavar="FILE", help="the scheduler's address from its scheduler file")
    where.add_argument("--serial", action="store_true", help="every task in this process (the serial reference)")
    ap.add_argument("--progress-s", type=float, default=30.0, metavar="S",
                    help="a progress line (done, failed, time left) at most every S seconds (default 30)")
    args = ap.parse_args(argv)
    if args.progress_s < 0:
        ap.error(f"--progress-s: {args.progress_s}: must be >= 0")
    if args.local_workers is not None and args.local_workers < 1:
        ap.error(f"--local-workers: {args.local_workers}: must be >= 1")
    try:
        sweep = load_sweep(args.sweep)
    except SweepError as e:
        print(f"sweep: {e}", file=sys.stderr)
        return 2
    client = cluster = None
    try:
        if not args.serial:
            client, cluster = connect(args.local_workers, args.scheduler, args.scheduler_file)
        run_sweep(sweep, args.out, client, progress_s=args.progress_s)
        return 0
    except SweepTaskError as e:
        print(f"sweep: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        rows = read_results(pathlib.Path(args.out) / "results.csv")
        print(f"sweep: interrupted; {len(rows)} of {len(make_tasks(sweep))} tasks written in "
              f"{pathlib.Path(args.out) / 'results.csv'}; run again to finish", file=sys.stderr, flush=True)
        return 130
    except SweepError as e:
        print(f"sweep: {e}", file=sys.stderr)
        return 2
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


if __name__ == "__main__":
    # Through the imported module, so Dask pickles isotouch.sweep.run_task by reference.
    import importlib

    sys.exit(importlib.import_module("isotouch.sweep").main())
