"""Zero-copy views and their lifetime (conversions: test_conversions.py)."""

import gc
import sys

import numpy as np
import pyopenvdb as vdb
import pytest

import pqdc
from conftest import sphere_distance


def owner_chain(a):
    while isinstance(a, np.ndarray):
        a = a.base
    return a


def test_views_are_zero_copy_and_read_only():
    m = pqdc.extract(sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0))
    v1, v2 = m.vertices, m.vertices
    assert v1.dtype == np.float64 and v1.shape[1] == 3 and v1.flags.c_contiguous
    assert v1.__array_interface__["data"][0] == v2.__array_interface__["data"][0]  # same C++ buffer
    assert m.faces.dtype == np.int32 and m.quads.dtype == np.int32
    assert type(owner_chain(v1)).__name__ == "MeshData"
    assert owner_chain(v1) is owner_chain(m.faces) is owner_chain(m.vertex_normals)
    for a in (v1, m.faces, m.quads, m.vertex_normals, m.values):
        assert not a.flags.writeable
        with pytest.raises(ValueError):
            a[...] = 0


def test_views_outlive_mesh_and_source():
    volume = sphere_distance((32, 32, 32), (15.5, 15.5, 15.5), 11.0)
    m = pqdc.extract(volume)
    vertices, faces, normals = m.vertices, m.faces, m.vertex_normals
    expected = (vertices.copy(), faces.copy(), normals.copy())
    del m, volume
    gc.collect()
    junk = [np.full(len(expected[0]) * 3, 7.0) for _ in range(20)]  # reuse freed memory if any
    assert np.array_equal(vertices, expected[0])
    assert np.array_equal(faces, expected[1])
    assert np.array_equal(normals, expected[2])
    assert len(junk) == 20


def test_views_outlive_a_pyopenvdb_grid():
    grid = vdb.createLevelSetSphere(radius=5.0, voxelSize=0.5)
    m = pqdc.extract(grid)
    vertices = m.vertices
    expected = vertices.copy()
    del grid, m
    gc.collect()
    assert np.array_equal(vertices, expected)


def test_empty_mesh():
    m = pqdc.extract(np.ones((8, 8, 8), np.float32))
    assert m.vertices.shape == (0, 3) and m.faces.shape == (0, 3) and m.quads.shape == (0, 4)
    assert m.vertex_normals.shape == (0, 3) and m.values.shape == (0,)


def test_normals_are_sampled_lazily_and_then_release_the_grid():
    grid = vdb.createLevelSetSphere(radius=5.0, voxelSize=0.5)
    before = sys.getrefcount(grid)
    m = pqdc.extract(grid)
    assert sys.getrefcount(grid) == before + 1  # kept for the normals
    assert "seconds_normals" not in m.stats
    n = m.vertex_normals
    assert sys.getrefcount(grid) == before  # dropped once sampled
    assert "seconds_normals" in m.stats
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert m.vertex_normals.__array_interface__["data"][0] == n.__array_interface__["data"][0]


def test_normals_after_the_grid_object_is_gone():
    grid = vdb.createLevelSetSphere(radius=5.0, voxelSize=0.5)
    m = pqdc.extract(grid)
    del grid
    gc.collect()
    radial = m.vertices / np.linalg.norm(m.vertices, axis=1)[:, None]
    assert np.einsum("ij,ij->i", m.vertex_normals, radial).min() > 0.99


def test_infinite_values_lie_beyond_the_finite_ones():
    # np.log of an image with zeros: -inf. The surface passes next to the
    # finite voxels (the limit of ever lower values), with outward normals.
    a = np.ones((6, 6, 6), np.float32)
    a[0] = -np.inf
    m = pqdc.extract(a)
    assert np.allclose(m.vertices[:, 0], 1.0, atol=1e-3)
    assert np.allclose(m.vertex_normals, [1.0, 0.0, 0.0], atol=1e-6)


def test_a_mesh_pickles_with_its_arrays_fields_and_stats(tmp_path):
    # multiprocessing, joblib and dask pickle results ("cannot pickle
    # 'pqdc._pqdc.MeshData' object" before).
    import pickle

    m = pqdc.extract(sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0), faces="quads")
    r = pickle.loads(pickle.dumps(m))
    for name in ("vertices", "faces", "quads", "vertex_normals", "values"):
        assert np.array_equal(getattr(r, name), getattr(m, name)), name
    assert len(r.quads) > 100
    assert r.stats == m.stats
    r.write(tmp_path / "r.ply")
    m.write(tmp_path / "m.ply")
    assert (tmp_path / "r.ply").read_bytes() == (tmp_path / "m.ply").read_bytes()
    assert np.array_equal(r.decimate(target_ratio=0.5).vertices, m.decimate(target_ratio=0.5).vertices)
    # Every protocol (0 and 1 refused the class), and the precision the mesh
    # was checked at travels: a double-checked copy writes double as well.
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        assert np.array_equal(pickle.loads(pickle.dumps(m, protocol=protocol)).vertices, m.vertices), protocol
    md = pqdc.extract(sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0), precision="double")
    pickle.loads(pickle.dumps(md)).write(tmp_path / "rd.ply")
    md.write(tmp_path / "md.ply")
    assert (tmp_path / "rd.ply").read_bytes() == (tmp_path / "md.ply").read_bytes()
    # A mesh without vertex fields keeps saying why after the trip.
    d = pqdc.decimate(np.array(m.vertices), np.array(m.triangles()), target_ratio=0.5)
    with pytest.raises(pqdc.InputError, match="no field to sample vertex normals"):
        pickle.loads(pickle.dumps(d)).vertex_normals
    with pytest.raises(pqdc.InputError, match="not a pickled pqdc.Mesh"):
        type(m._data).__new__(type(m._data)).__setstate__((7,))
