"""Spheres from arrays, pyopenvdb grids and files; import without pyopenvdb."""

import os
import re

import numpy as np
import pytest

import pyopenvdb as vdb

import pqdc
from conftest import enclosed_volume, outward_fraction, run_python, sphere_distance


def test_import_in_a_fresh_process_without_pyopenvdb():
    # pyopenvdb made unimportable: pqdc must import, mesh an array and
    # reject foreign objects with TypeError, never loading pyopenvdb.
    r = run_python(
        "import sys\n"
        "sys.modules['pyopenvdb'] = None\n"
        "import numpy as np, pqdc\n"
        "m = pqdc.extract(np.linspace(-1, 1, 1000).reshape(10, 10, 10))\n"
        "assert len(m.faces) > 0\n"
        "try:\n"
        "    pqdc.extract(object())\n"
        "except TypeError as e:\n"
        "    print('TypeError', e)\n"
        "assert sys.modules['pyopenvdb'] is None\n"
        "print('ok')\n")
    assert r.returncode == 0, r.stderr
    assert "ok" in r.stdout and "TypeError pqdc.extract: cannot mesh a builtins.object" in r.stdout


def test_sphere_from_array():
    centre, radius = np.array([31.5, 30.25, 32.75]), 21.3
    v = sphere_distance((64, 64, 66), centre, radius)
    m = pqdc.extract(v)
    d = np.linalg.norm(m.vertices - centre, axis=1) - radius
    assert len(m.vertices) > 5000
    assert np.abs(d).max() < 0.02  # voxels
    assert outward_fraction(m.vertices, m.faces, centre) == 1.0
    radial = (m.vertices - centre) / np.linalg.norm(m.vertices - centre, axis=1)[:, None]
    assert np.einsum("ij,ij->i", m.vertex_normals, radial).min() > 0.999
    assert np.allclose(np.linalg.norm(m.vertex_normals, axis=1), 1.0)
    assert np.abs(m.values).max() < 0.05  # trilinear interpolation of a distance
    s = m.stats
    assert s["vertices"] == len(m.vertices) and s["triangles"] == len(m.faces)
    assert s["source"] == "array" and s["interior"] == "below" and s["mode"] == "uniform"


def test_sphere_from_pyopenvdb_grid():
    centre, radius = np.array([1.0, -2.0, 0.5]), 7.0
    grid = vdb.createLevelSetSphere(radius=radius, center=tuple(centre), voxelSize=0.25)
    grid.name = "ball"
    m = pqdc.extract(grid)
    d = np.linalg.norm(m.vertices - centre, axis=1) - radius
    assert np.abs(d).max() < 0.01 * 0.25 * 4  # a hundredth of a voxel, with slack x4
    assert outward_fraction(m.vertices, m.faces, centre) == 1.0
    radial = (m.vertices - centre) / np.linalg.norm(m.vertices - centre, axis=1)[:, None]
    assert np.einsum("ij,ij->i", m.vertex_normals, radial).min() > 0.999
    assert m.stats["source"] == "grid" and m.stats["grid"] == "ball"
    # The grid object is still usable afterwards (reference handled under the GIL).
    assert grid.activeVoxelCount() > 0


def test_fog_grid_interior_auto_is_above():
    fog = vdb.FloatGrid(background=0.0)  # density: 2 inside, 0 outside, 1 on the sphere
    fog.copyFromArray(np.clip(-sphere_distance((40, 40, 40), (20, 20, 20), 12.0), -1, 1) + 1)
    fog.gridClass = vdb.GridClass.FOG_VOLUME
    m = pqdc.extract(fog, isovalue=1.0)
    assert m.stats["interior"] == "above"
    assert outward_fraction(m.vertices, m.faces, np.array([20.0, 20, 20])) == 1.0


def test_mirrored_grid_transform_keeps_outward_winding():
    grid = vdb.FloatGrid(background=3.0)
    grid.copyFromArray(sphere_distance((30, 30, 30), (15, 14, 16), 9.0))
    grid.transform = vdb.createLinearTransform([[-0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 0.5, 0], [1, 2, 3, 1]])
    m = pqdc.extract(grid)
    centre = np.array([1 - 7.5, 2 + 7.0, 3 + 8.0])
    d = np.linalg.norm(m.vertices - centre, axis=1) - 4.5
    assert np.abs(d).max() < 0.05 * 0.5  # a twentieth of a voxel
    assert outward_fraction(m.vertices, m.faces, centre) == 1.0
    radial = (m.vertices - centre) / np.linalg.norm(m.vertices - centre, axis=1)[:, None]
    assert np.einsum("ij,ij->i", m.vertex_normals, radial).min() > 0.999


def test_file_source_and_grid_name(source_dir, tmp_path):
    path = f"{source_dir}/volumes/sphere.vdb"
    m = pqdc.extract(path)
    assert len(m.faces) > 1000 and m.stats["source"] == "file"
    named = pqdc.extract(path, grid=m.stats["grid"])
    assert np.array_equal(named.vertices, m.vertices)
    out = tmp_path / "sphere.obj"
    m.write(out)
    lines = out.read_text().splitlines()
    assert sum(1 for l in lines if l.startswith("v ")) == len(m.vertices)
    assert sum(1 for l in lines if l.startswith("f ")) == len(m.faces)


def test_dtypes_and_orders_give_the_same_mesh():
    base = np.round(sphere_distance((24, 26, 28), (11.5, 12.2, 13.1), 8.3, dtype=np.float64) * 16)
    ref = pqdc.extract(base.astype(np.float32), isovalue=0.5)
    for dtype in (np.float16, np.float64, np.int16, np.int32, np.int64):
        for order in ("C", "F"):
            m = pqdc.extract(np.asarray(base.astype(dtype), order=order), isovalue=0.5)
            assert np.array_equal(m.vertices, ref.vertices), (dtype, order)
            assert np.array_equal(m.faces, ref.faces), (dtype, order)
    sliced = np.zeros((48, 26, 56), np.float32)
    sliced[::2, :, ::2] = base
    m = pqdc.extract(sliced[::2, :, ::2], isovalue=0.5)
    assert np.array_equal(m.vertices, ref.vertices)
    # Negative strides: the mirrored view meshes like a mirrored copy.
    flipped = base.astype(np.float32)[::-1, :, ::-1]
    m = pqdc.extract(flipped, isovalue=0.5)
    c = pqdc.extract(np.ascontiguousarray(flipped), isovalue=0.5)
    assert np.array_equal(m.vertices, c.vertices) and np.array_equal(m.faces, c.faces)


def test_zyx_axes_transposes_the_array():
    v = sphere_distance((20, 24, 28), (9.5, 11.0, 13.5), 7.0)
    m = pqdc.extract(v)
    t = pqdc.extract(np.ascontiguousarray(v.transpose(2, 1, 0)), axes="zyx")
    assert np.array_equal(m.vertices, t.vertices) and np.array_equal(m.faces, t.faces)


def test_quads_and_triangles():
    v = sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0)
    q = pqdc.extract(v, faces="quads")
    t = pqdc.extract(v)
    assert q.faces.shape == (0, 3) and q.quads.shape[1] == 4 and len(q.quads) * 2 == len(t.faces)
    assert q.triangles().shape == (2 * len(q.quads), 3)
    assert outward_fraction(q.vertices, q.triangles(), np.array([11.5] * 3)) == 1.0


def test_adaptive_has_fewer_faces_and_stays_on_the_sphere():
    centre, radius = np.array([31.5] * 3), 24.0
    v = sphere_distance((64, 64, 64), centre, radius)
    u = pqdc.extract(v)
    a = pqdc.extract(v, adaptive=True, max_error=0.1)
    assert a.stats["mode"] == "adaptive" and len(a.faces) < len(u.faces) / 3
    assert np.abs(np.linalg.norm(a.vertices - centre, axis=1) - radius).max() < 0.15
    # Large faces and a few slivers: judge the winding by the enclosed volume.
    assert enclosed_volume(a.vertices, a.faces) == pytest.approx(4 / 3 * np.pi * radius**3, rel=0.01)


def test_thread_count_does_not_change_the_mesh():
    rng = np.random.default_rng(3)
    v = rng.standard_normal((40, 40, 40)).astype(np.float32)
    one = pqdc.extract(v, threads=1)
    two = pqdc.extract(v, threads=2)
    assert np.array_equal(one.vertices, two.vertices) and np.array_equal(one.faces, two.faces)


def test_sigma_n_auto_is_the_default_and_chosen_from_the_noise():
    v = sphere_distance((20, 20, 20), (9.3, 9.6, 9.9), 6.0)
    assert pqdc.SIGMA_N_AUTO == "auto"
    auto = pqdc.extract(v, sigma_n="auto")
    assert np.array_equal(auto.vertices, pqdc.extract(v).vertices)
    # A clean distance field: sigma_n 0.1 with sharp gradients, no denoising.
    assert auto.stats["sigma_n"] == 0.1 and auto.stats["gradient"] == "sharp"
    assert auto.stats["noise_voxels"] < 0.05 and auto.stats["denoise_radius"] == 0
    assert np.array_equal(auto.vertices, pqdc.extract(v, sigma_n=0.1, normals="sharp").vertices)
    noisy = v + np.random.default_rng(5).normal(0.0, 0.3, v.shape).astype(np.float32)
    n = pqdc.extract(noisy)
    assert abs(n.stats["noise_voxels"] - 0.3) < 0.06
    assert n.stats["sigma_n"] == 0.25 and n.stats["denoise_radius"] == 1
    assert not np.array_equal(pqdc.extract(v, sigma_n=0).vertices, pqdc.extract(v, sigma_n=0.1).vertices)


def test_version_is_the_projects(source_dir):
    # One version: CMake's project() call reaches the module (it was typed twice).
    with open(os.path.join(source_dir, "CMakeLists.txt")) as f:
        declared = re.search(r"project\(pqdc VERSION (\d+\.\d+\.\d+)", f.read()).group(1)
    assert pqdc.__version__ == declared
