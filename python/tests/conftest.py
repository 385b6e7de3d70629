"""Shared fields for the pqdc Python tests (run with PYTHONPATH=<build>/python)."""

import os
import subprocess
import sys

import numpy as np
import pytest


def sphere_distance(shape, centre, radius, spacing=(1.0, 1.0, 1.0), dtype=np.float32):
    """Signed distance to a sphere sampled at index * spacing (inside negative)."""
    axes = [np.arange(n) * s - c for n, s, c in zip(shape, spacing, centre)]
    x, y, z = np.meshgrid(*axes, indexing="ij", sparse=True)
    return (np.sqrt(x * x + y * y + z * z) - radius).astype(dtype)


def outward_fraction(vertices, faces, centre):
    """Fraction of triangles whose right-hand normal points away from centre."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    return float(np.mean(np.einsum("ij,ij->i", n, (a + b + c) / 3 - centre) > 0))


def enclosed_volume(vertices, faces):
    """Signed volume by the divergence theorem: positive for outward winding."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def run_python(code, env_extra=None, timeout=120):
    """Runs code in a fresh /usr/bin/python3 with this run's PYTHONPATH."""
    env = dict(os.environ)
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          timeout=timeout)


@pytest.fixture(scope="session")
def source_dir():
    d = os.environ.get("PQDC_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
    return os.path.abspath(d)
