"""isotouch from Python: volumes as numpy arrays, the engine, offline rendering (HRI and the
two baselines), scenes, live sessions, recordings and run folders.

Frames: index (x, y, z) continuous voxel coordinates; grid-world [m] = origin + spacing * index,
the frame renderers, strokes and brushes use; physical [m] = origin + D (spacing * index), the
file's frame (trace.csv). Arrays of voxels are (nz, ny, nx), x fastest, as SimpleITK's.
Errors: isotouch.VolumeError, SceneError, RecordingError (subclasses of isotouch.Error, a
RuntimeError) carry the command line's messages; bad arguments raise ValueError.
isotouch.UnitsWarning (a UserWarning): a spacing or origin that looks like the other unit.
LiveSession.stop() raises isotouch.ServoAbandoned (an Error) when the servo thread was left
stuck in the renderer: the force is off, and the session is never freed (that thread may
still read its renderer, snapshots and device).
"""
import sys as _sys

try:
    import numpy as _np
except ImportError:  # an interpreter other than the build's (same ABI): use the build's numpy
    from . import _build

    if f"{_sys.version_info.major}.{_sys.version_info.minor}" != _build.PYTHON_VERSION or not _build.NUMPY_SITE:
        raise
    _sys.path.append(_build.NUMPY_SITE)
    import numpy as _np  # noqa: F401

from ._isotouch import (  # noqa: F401
    BaselineParams,
    Error,
    Field,
    HriParams,
    InsideIs,
    Intersection,
    LiveSession,
    NormalSource,
    Pass,
    Realtime,
    RecordingError,
    SceneError,
    ServoAbandoned,
    StrokeScene,
    SurfaceFriction,
    UnitsWarning,
    Variant,
    Volume,
    VolumeError,
    __version__,
    check_all,
    cpp_ns_per_tick,
    load_recording,
    load_volume,
    measure_stroke,
    render,
    run_passes,
    run_scene,
    scene_passes,
    scene_setup,
    stroke_scene,
)
from .engine import check  # noqa: F401
from .files import read_run_folder, read_trace_csv  # noqa: F401
