"""Mesh.to_open3d() with the real package (python3-open3d); to_trimesh() and
to_pyvista() (not in Debian 12) through stand-in modules that record what
they are given; the message when a package is missing."""

import sys
import types

import numpy as np
import pytest

import pqdc
from conftest import enclosed_volume, run_python, sphere_distance

CENTRE, RADIUS = (19.5, 19.5, 19.5), 14.0


def sphere(**options):
    return pqdc.extract(sphere_distance((40, 40, 40), CENTRE, RADIUS), **options)


def mixed_mesh():
    # Adaptive quads: quads where both halves of a loop survive, triangles elsewhere.
    m = sphere(faces="quads", adaptive=True)
    assert len(m.faces) > 0 and len(m.quads) > 0
    return m


def open3d_or_skip():
    return pytest.importorskip("open3d", reason="python3-open3d is not installed (scripts/install-deps.sh installs it)")


@pytest.mark.parametrize("options", [{}, {"faces": "quads"}, {"adaptive": True}, {"faces": "quads", "adaptive": True}],
                         ids=["triangles", "quads", "adaptive", "adaptive-quads"])
def test_to_open3d_is_the_same_closed_outward_surface(options):
    o3d = open3d_or_skip()
    m = sphere(**options)
    o = m.to_open3d()
    assert isinstance(o, o3d.geometry.TriangleMesh)
    vertices, triangles = np.asarray(o.vertices), np.asarray(o.triangles)
    assert vertices.dtype == np.float64 and triangles.dtype == np.int32
    assert np.array_equal(vertices, m.vertices)
    assert len(triangles) == len(m.faces) + 2 * len(m.quads)
    assert np.array_equal(triangles, m.triangles())
    assert o.has_vertex_normals() and np.array_equal(np.asarray(o.vertex_normals), m.vertex_normals)
    # Open3D's own checks of the topology.
    assert o.is_watertight() and o.is_edge_manifold(allow_boundary_edges=False) and o.is_vertex_manifold()
    assert o.is_orientable()
    assert o.get_volume() == pytest.approx(4 / 3 * np.pi * RADIUS ** 3, rel=0.01)
    # Outward: a positive signed volume, and Open3D's face normals (from the
    # winding) point away from the centre (adaptive meshes: all but a few
    # slivers folded at merged cells, 54 of 3962 here, as in test_basic.py).
    assert enclosed_volume(vertices, triangles) == pytest.approx(4 / 3 * np.pi * RADIUS ** 3, rel=0.01)
    o.compute_triangle_normals()
    centres = vertices[triangles].mean(axis=1) - np.array(CENTRE)
    outward = np.mean(np.einsum("ij,ij->i", np.asarray(o.triangle_normals), centres) > 0)
    assert outward > 0.97 if options.get("adaptive") else outward == 1.0
    # Copies: editing the Open3D mesh leaves pqdc's (read-only) arrays alone.
    np.asarray(o.vertices)[0] += 1.0
    assert not np.array_equal(np.asarray(o.vertices)[0], m.vertices[0])


def test_to_open3d_in_a_fresh_process_after_pqdc():
    # Both link TBB and Eigen: importing open3d after pqdc (and pyopenvdb) must work.
    open3d_or_skip()
    r = run_python("import numpy as np, pyopenvdb, pqdc, open3d\n"
                   "m = pqdc.extract(pyopenvdb.createLevelSetSphere(radius=4.0, voxelSize=0.5))\n"
                   "print(m.to_open3d().is_watertight())")
    assert r.returncode == 0 and r.stdout.strip() == "True", r.stderr


class Recorder:
    """Stand-in class: keeps its constructor's arguments."""
    made = []

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs
        self.point_data = {}
        Recorder.made.append(self)


@pytest.fixture
def recorder():
    Recorder.made = []
    return Recorder


def split_cells(cells):
    """[n, i1..in, n, ...] to a list of index tuples."""
    out, i = [], 0
    while i < len(cells):
        n = int(cells[i])
        out.append(tuple(int(x) for x in cells[i + 1:i + 1 + n]))
        i += 1 + n
    return out


@pytest.mark.parametrize("options", [{}, {"faces": "quads"}], ids=["triangles", "quads"])
def test_to_pyvista_faces_layout(monkeypatch, recorder, options):
    monkeypatch.setitem(sys.modules, "pyvista", types.SimpleNamespace(PolyData=recorder))
    m = sphere(**options)
    poly = m.to_pyvista()
    assert recorder.made == [poly]
    points, cells = poly.args
    assert points.dtype == np.float64 and points.flags.writeable and np.array_equal(points, m.vertices)
    assert cells.dtype == np.int64 and cells.ndim == 1
    n = 4 if options else 3
    rows = cells.reshape(-1, n + 1)
    assert np.all(rows[:, 0] == n)
    assert np.array_equal(rows[:, 1:], m.quads if options else m.faces)
    assert np.array_equal(poly.point_data["Normals"], m.vertex_normals)


def test_to_pyvista_keeps_triangles_and_quads_of_a_mixed_mesh(monkeypatch, recorder):
    monkeypatch.setitem(sys.modules, "pyvista", types.SimpleNamespace(PolyData=recorder))
    m = mixed_mesh()
    faces = split_cells(m.to_pyvista().args[1])
    assert faces == [tuple(f) for f in m.faces] + [tuple(q) for q in m.quads]


def test_to_trimesh_passes_copies(monkeypatch, recorder):
    monkeypatch.setitem(sys.modules, "trimesh", types.SimpleNamespace(Trimesh=recorder))
    m = mixed_mesh()
    t = m.to_trimesh()
    kw = t.kwargs
    assert np.array_equal(kw["vertices"], m.vertices) and kw["vertices"].flags.writeable
    assert kw["faces"].shape == (len(m.faces) + 2 * len(m.quads), 3)
    assert np.array_equal(kw["faces"], m.triangles())
    # The split keeps the quads' winding: the closed surface still encloses positive volume.
    assert enclosed_volume(kw["vertices"], kw["faces"]) == pytest.approx(4 / 3 * np.pi * RADIUS ** 3, rel=0.02)
    assert np.array_equal(kw["vertex_normals"], m.vertex_normals) and kw["process"] is False


@pytest.mark.parametrize("method,module,hint", [("to_trimesh", "trimesh", "pip install trimesh"),
                                                ("to_pyvista", "pyvista", "pip install pyvista"),
                                                ("to_open3d", "open3d", "apt-get install python3-open3d")])
def test_a_missing_package_is_named_with_how_to_install_it(monkeypatch, method, module, hint):
    monkeypatch.setitem(sys.modules, module, None)  # as if not installed
    m = sphere()
    with pytest.raises(ImportError, match=f"Mesh.{method}\\(\\) needs the '{module}' module") as e:
        getattr(m, method)()
    assert hint in str(e.value)


def test_import_does_not_load_conversion_modules():
    r = run_python("import sys, pqdc; print(sorted(m for m in ('trimesh', 'pyvista', 'open3d', 'skimage') "
                   "if m in sys.modules))")
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stderr
