"""The options of pqdc.decimate() and pqdc.Mesh.decimate(), checked into the
C++ request. A module of their own: pqdc.Mesh needs them, and pqdc.decimate()
needs pqdc.Mesh."""

import math
import numbers

from . import _pqdc
from ._errors import OptionError, double_precision

_METRICS = ("triangle", "plane", "curvature")


def _number(name, value, *, positive=False, allow_none=False):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"pqdc.decimate: {name} must be a number{' or None' if allow_none else ''}, "
                        f"got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (positive and v == 0):
        raise OptionError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {value}")
    return v


def _count(name, value, unit, none_means, most=2**63 - 1):
    """None, or an integer in [1, most]."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"pqdc.decimate: {name} must be an integer or None, got {type(value).__name__}")
    if value < 1:
        raise OptionError(f"{name} must be at least 1 {unit} (or None for {none_means}), got {value}")
    if value > most:  # beyond the C++ field: pybind11 would say only "incompatible function arguments"
        raise OptionError(f"{name} must be at most {most} {unit}s (or None for {none_means}), got {value}")
    return int(value)


def request(*, target_ratio=None, target_faces=None, max_distance=None, metric="triangle", sigma_position="auto",
            sigma_normal=0.05, voxel_size=None, threads=None, progress=None, memory_limit=None, precision="float",
            **unknown):
    """The C++ request from pqdc.decimate()'s keyword options (their
    defaults are these), checked: TypeError or pqdc.OptionError naming the
    option."""
    if unknown:
        raise TypeError(f"pqdc.decimate: unknown option {', '.join(map(repr, unknown))} (see help(pqdc.decimate); "
                        f"faces and normals are for pqdc.decimate() with arrays)")
    r = _pqdc.DecimateRequest()
    ratio = _number("target_ratio", target_ratio, allow_none=True)
    if ratio is not None:
        if not 0 < ratio <= 1:
            raise OptionError(f"target_ratio must be in (0, 1] (the fraction of triangles to keep), got {target_ratio}")
        r.target_ratio = ratio
    faces = _count("target_faces", target_faces, "triangle", "no face target")
    if faces is not None:
        r.target_faces = faces
    distance = _number("max_distance", max_distance, positive=True, allow_none=True)
    if distance is not None:
        r.max_distance = distance
    if ratio is None and faces is None and distance is None:
        raise OptionError("decimate needs a target: target_ratio, target_faces or max_distance (voxels), "
                          "alone or combined (it stops at the first one reached)")
    if metric not in _METRICS:
        raise OptionError(f"metric must be one of {', '.join(repr(m) for m in _METRICS)}, got {metric!r}")
    r.metric = metric
    if isinstance(sigma_position, str):
        if sigma_position != "auto":
            raise OptionError(f"sigma_position must be a number > 0 (voxels) or 'auto', got {sigma_position!r}")
        r.sigma_position = _pqdc.SIGMA_POSITION_AUTO_VALUE
    else:
        r.sigma_position = _number("sigma_position", sigma_position, positive=True)
    r.sigma_normal = _number("sigma_normal", sigma_normal, positive=True)
    size = _number("voxel_size", voxel_size, positive=True, allow_none=True)
    if size is not None:
        r.voxel_size = size
    r.threads = _count("threads", threads, "thread", "all cores", 4096) or 0
    r.memory_limit = _count("memory_limit", memory_limit, "byte", "80% of physical memory") or 0
    if progress is not None and not callable(progress):
        raise TypeError(f"pqdc.decimate: progress must be callable or None, got {type(progress).__name__}")
    r.progress = progress
    r.double_precision = double_precision(precision)
    return r
