"""Run folders (`isotouch run --out DIR`) read into numpy arrays and plain dicts."""
import json
import os

import numpy as np

_POINTS = ("hip", "vhip", "f", "hand")


def read_trace_csv(path):
    """trace.csv as a dict of arrays: every column by its name ('t_s', 'hip_x_m', 'contact', ...;
    points in the volume's physical frame [m], forces [N]) and, for each point column triple,
    an (N, 3) array ('hip', 'vhip', 'f': hip_x_m, hip_y_m, hip_z_m -> hip).
    Raises ValueError naming the file when it is not an isotouch trace.csv."""
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    if header[:2] != ["t_s", "hip_x_m"]:
        raise ValueError(f"{path}: not an isotouch trace.csv (header 't_s,hip_x_m,...' expected)")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[1] != len(header):
        raise ValueError(f"{path}: {data.shape[1]} columns, the header names {len(header)}")
    out = {name: data[:, i] for i, name in enumerate(header)}
    for p in _POINTS:
        cols = [c for c in header if c.startswith(p + "_") and c[len(p) + 1 : len(p) + 2] in "xyz" and c.count("_") == 2]
        cols = sorted(cols, key=lambda c: c[len(p) + 1])
        if len(cols) == 3:
            out[p] = np.stack([out[c] for c in cols], axis=1)
    return out


def read_run_folder(path):
    """A run folder as a dict: 'summary' (summary.json), 'trace' (read_trace_csv, if written),
    'report' (report.md's text, if written), 'files' (the names in the folder)."""
    out = {"path": path, "files": sorted(os.listdir(path))}
    with open(os.path.join(path, "summary.json"), encoding="utf-8") as f:
        out["summary"] = json.load(f)
    trace = os.path.join(path, "trace.csv")
    if os.path.exists(trace):
        out["trace"] = read_trace_csv(trace)
    report = os.path.join(path, "report.md")
    if os.path.exists(report):
        with open(report, encoding="utf-8") as f:
            out["report"] = f.read()
    return out
