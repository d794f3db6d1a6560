"""The engine's GPU chain against its CPU reference from Python (what `isotouch check` does)."""
import numpy as np

from . import _isotouch


def _ulps(a, b):
    """|a - b| in units in the last place of float32 (ordered integer distance)."""
    ia = a.view(np.int32).astype(np.int64)
    ib = b.view(np.int32).astype(np.int64)
    ia = np.where(ia < 0, -(1 << 31) - ia, ia)  # sign-magnitude -> two's complement order
    ib = np.where(ib < 0, -(1 << 31) - ib, ib)
    return np.abs(ia - ib)


def check(volume, passes=None, device=""):
    """Run `passes` (default: the gradient) on the Vulkan device `device` ('' the default) and on
    the one-thread CPU reference; compare every output value.

    Returns a dict: 'gpu' and 'cpu' (run_passes' dicts), and per output ('samples': value and
    gradient, (nz, ny, nx, 4); 'field': the filtered voxels) 'max_abs', 'max_ulp',
    'differing' (count of values not bit-identical), 'nonfinite' (NaN/Inf in the GPU output),
    and 'identical' (every output bit for bit the same). On lavapipe (a CPU Vulkan device)
    the outputs are bit-identical.
    """
    gpu = _isotouch.run_passes(volume, passes, device)
    cpu = _isotouch.run_passes(volume, passes, "cpu")
    out = {"gpu": gpu, "cpu": cpu, "device": gpu["device"], "outputs": {}}
    identical = True
    for key in ("samples", "field"):
        if key not in cpu:
            continue
        g = gpu[key].samples if key == "samples" else gpu[key]
        c = cpu[key].samples if key == "samples" else cpu[key]
        g = np.ascontiguousarray(g, dtype=np.float32)
        c = np.ascontiguousarray(c, dtype=np.float32)
        ulp = _ulps(g, c)
        same = g.view(np.int32) == c.view(np.int32)
        figures = {
            "max_abs": float(np.nanmax(np.abs(g.astype(np.float64) - c))) if g.size else 0.0,
            "max_ulp": int(ulp.max()) if ulp.size else 0,
            "differing": int((~same).sum()),
            "nonfinite": int((~np.isfinite(g)).sum()),
        }
        identical = identical and figures["differing"] == 0
        out["outputs"][key] = figures
    out["identical"] = identical
    return out
