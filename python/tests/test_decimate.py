"""pqdc.decimate() and pqdc.Mesh.decimate(): the C++ decimation from Python."""

import numpy as np
import pytest

import pqdc
from conftest import enclosed_volume, outward_fraction, sphere_distance

SPACING = (0.5, 0.75, 1.0)   # world units per voxel along x, y, z
CENTRE = (12.0, 12.0, 12.0)  # world
RADIUS = 8.0                 # world


@pytest.fixture(scope="module")
def sphere():
    shape = tuple(int(np.ceil(24.0 / s)) for s in SPACING)
    return pqdc.extract(sphere_distance(shape, CENTRE, RADIUS, spacing=SPACING), spacing=SPACING)


def edge_uses(faces):
    """How many triangles use each undirected edge."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return counts


def test_keeps_a_closed_outward_sphere(sphere):
    d = sphere.decimate(target_ratio=0.1)
    n_in = len(sphere.faces)
    assert len(d.quads) == 0 and 0 < len(d.faces) <= 0.1 * n_in
    assert d.stats["decimate_input_triangles"] == n_in
    assert d.stats["decimate_output_triangles"] == len(d.faces) == d.stats["triangles"]
    assert d.stats["vertices"] == len(d.vertices) and sphere.stats["triangles"] == n_in
    assert d.stats["decimate_collapses"] > 0
    assert np.all(edge_uses(d.faces) == 2)  # closed and edge-manifold
    assert outward_fraction(d.vertices, d.faces, np.array(CENTRE)) == 1.0
    v = enclosed_volume(d.vertices, d.faces)
    assert v == pytest.approx(4 / 3 * np.pi * RADIUS**3, rel=0.03)
    # Every face stays used and every vertex is used.
    assert len(np.unique(d.faces)) == len(d.vertices)


def test_lengths_are_in_the_source_voxels(sphere):
    d = sphere.decimate(target_ratio=0.2, max_distance=0.25)
    assert d.stats["decimate_voxel_size"] == min(SPACING)
    r = np.linalg.norm(d.vertices - np.array(CENTRE), axis=1)
    r_in = np.linalg.norm(sphere.vertices - np.array(CENTRE), axis=1)
    # Each vertex within 0.25 voxel of the input surface, whose own distance to the sphere is at most input_dev.
    input_dev = np.abs(r_in - RADIUS).max()
    assert np.abs(r - RADIUS).max() <= 0.25 * min(SPACING) + input_dev + 1e-9


def test_normals_come_from_the_source_grid():
    volume = sphere_distance((32, 32, 32), (15.5, 15.5, 15.5), 11.0)
    d = pqdc.extract(volume).decimate(target_ratio=0.1)
    radial = d.vertices - 15.5
    r = np.linalg.norm(radial, axis=1)
    radial /= r[:, None]
    assert d.vertex_normals.shape == d.vertices.shape
    assert np.einsum("ij,ij->i", d.vertex_normals, radial).min() > 0.99
    # The grid's value at the new positions (the decimated vertices leave the surface a little).
    assert np.abs(d.values - (r - 11.0)).max() < 0.05  # trilinear error of a curved field


def test_normals_read_before_decimating_are_carried_over(tmp_path):
    m = pqdc.extract(sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0))
    m.vertex_normals  # releases the grid
    d = m.decimate(target_ratio=0.5)
    assert len(d.faces) <= len(m.faces) // 2
    radial = d.vertices - 11.5
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    assert np.einsum("ij,ij->i", d.vertex_normals, radial).min() > 0.99
    with pytest.raises(pqdc.InputError, match="vertex values of a decimated.*call decimate\\(\\) before reading"):
        d.values
    # Written with them, and read back.
    d.write(tmp_path / "d.ply", normals=True)
    back = pqdc.read_mesh(tmp_path / "d.ply")
    assert np.allclose(back.vertex_normals, d.vertex_normals, atol=1e-6)
    d.write(tmp_path / "d.obj", normals=True)
    assert "vn " in (tmp_path / "d.obj").read_text()
    d.write(tmp_path / "plain.ply")
    with pytest.raises(pqdc.InputError, match="no field to sample vertex normals"):
        pqdc.read_mesh(tmp_path / "plain.ply").vertex_normals
    with pytest.raises(pqdc.OptionError, match="holds no vertex normals"):
        d.write(tmp_path / "d.stl", normals=True)
    assert not (tmp_path / "d.stl").exists()


def test_arrays_match_the_mesh_path_and_any_thread_count(sphere):
    a = sphere.decimate(target_ratio=0.1, threads=1)
    b = pqdc.decimate(np.array(sphere.vertices), np.array(sphere.faces), target_ratio=0.1,
                      voxel_size=min(SPACING), threads=2)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    with pytest.raises(pqdc.InputError, match="pass normals= to carry"):
        b.vertex_normals
    # With normals: carried over (radial on the sphere), the geometry unchanged.
    radial_in = np.array(sphere.vertices) - np.array(CENTRE)
    radial_in /= np.linalg.norm(radial_in, axis=1)[:, None]
    c = pqdc.decimate(np.array(sphere.vertices), np.array(sphere.faces), normals=radial_in, target_ratio=0.1,
                      voxel_size=min(SPACING), threads=2)
    assert np.array_equal(c.vertices, b.vertices) and np.array_equal(c.faces, b.faces)
    radial = c.vertices - np.array(CENTRE)
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    assert np.einsum("ij,ij->i", c.vertex_normals, radial).min() > 0.999
    with pytest.raises(pqdc.InputError, match="no field to sample vertex values"):
        c.values
    with pytest.raises(pqdc.OptionError, match=r"normals must have the vertices' shape \(\d+, 3\), got \(4, 3\)"):
        pqdc.decimate(np.array(sphere.vertices), np.array(sphere.faces), normals=radial_in[:4], target_ratio=0.1)
    with pytest.raises(pqdc.OptionError, match="faces and normals are for a mesh given as arrays"):
        pqdc.decimate(sphere, normals=radial_in, target_ratio=0.1)


def test_quads_and_other_dtypes():
    volume = sphere_distance((24, 24, 24), (11.5, 11.5, 11.5), 8.0)
    q = pqdc.extract(volume, faces="quads")
    d = pqdc.decimate(q.vertices.astype(np.float32), q.quads.astype(np.uint32), target_faces=400)
    assert len(d.quads) == 0 and len(d.faces) <= 400
    assert d.stats["decimate_input_triangles"] == 2 * len(q.quads)
    assert np.all(edge_uses(d.faces) == 2)


@pytest.mark.parametrize("options, error, message", [
    ({}, pqdc.OptionError, "needs a target"),
    ({"target_ratio": 0}, pqdc.OptionError, "target_ratio must be in"),
    ({"target_ratio": 1.5}, pqdc.OptionError, "target_ratio must be in"),
    ({"target_faces": 0}, pqdc.OptionError, "target_faces must be at least 1"),
    ({"target_faces": 2.5}, TypeError, "target_faces must be an integer"),
    ({"max_distance": -1}, pqdc.OptionError, "max_distance must be"),
    ({"target_ratio": 0.5, "metric": "qem"}, pqdc.OptionError, "metric must be one of"),
    ({"target_ratio": 0.5, "sigma_position": "high"}, pqdc.OptionError, "sigma_position must be"),
    ({"target_ratio": 0.5, "sigma_position": 0}, pqdc.OptionError, "sigma_position must be"),
    ({"target_ratio": 0.5, "voxel_size": float("nan")}, pqdc.OptionError, "voxel_size must be"),
    ({"target_ratio": 0.5, "threads": 0}, pqdc.OptionError, "threads must be at least 1"),
])
def test_bad_options_name_the_option(sphere, options, error, message):
    with pytest.raises(error, match=message):
        sphere.decimate(**options)


def test_mesh_decimate_names_an_unknown_option(sphere):
    with pytest.raises(TypeError, match="unknown option 'normals'"):
        sphere.decimate(target_ratio=0.5, normals=np.zeros((len(sphere.vertices), 3)))
    with pytest.raises(TypeError, match="unknown option 'target_ration'"):
        sphere.decimate(target_ration=0.5)


def test_bad_arrays_are_refused(sphere):
    v, f = np.array(sphere.vertices), np.array(sphere.faces)
    with pytest.raises(pqdc.InputError, match="refers to vertex -1"):
        pqdc.decimate(v, np.where(f == 0, -1, f), target_ratio=0.5)
    with pytest.raises(pqdc.InputError, match=f"there are {len(v)} vertices"):
        pqdc.decimate(v, f + len(v), target_ratio=0.5)
    with pytest.raises(TypeError, match="faces must be an integer array"):
        pqdc.decimate(v, f.astype(float), target_ratio=0.5)
    with pytest.raises(pqdc.OptionError, match="vertices must have shape"):
        pqdc.decimate(v[:, :2], f, target_ratio=0.5)
    with pytest.raises(pqdc.OptionError, match="faces must have shape"):
        pqdc.decimate(v, f[:, :2], target_ratio=0.5)
    with pytest.raises(TypeError, match="pass a pqdc.Mesh"):
        pqdc.decimate(v, target_ratio=0.5)
    with pytest.raises(pqdc.OptionError, match="brings its own"):
        pqdc.decimate(sphere, f, target_ratio=0.5)
    bad = v.copy()
    bad[f[0, 0]] = np.nan
    with pytest.raises(pqdc.InputError):
        pqdc.decimate(bad, f, target_ratio=0.5)


def test_progress_and_cancel(sphere):
    seen = []
    d = sphere.decimate(target_ratio=0.1, progress=lambda f: seen.append(f))
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen) and len(seen) > 2
    assert np.array_equal(d.faces, sphere.decimate(target_ratio=0.1).faces)
    with pytest.raises(pqdc.CancelledError):
        sphere.decimate(target_ratio=0.1, progress=lambda f: f < 0.3)

    class Stop(Exception):
        pass

    def boom(f):
        if f > 0:
            raise Stop()

    with pytest.raises(Stop):
        sphere.decimate(target_ratio=0.1, progress=boom)
    with pytest.raises(TypeError, match="progress must be callable"):
        sphere.decimate(target_ratio=0.1, progress=3)


def test_memory_limit(sphere):
    n = len(sphere.faces)
    with pytest.raises(pqdc.ResourceError, match=f"{n} triangles would need about"):
        sphere.decimate(target_ratio=0.1, memory_limit=n * 300 - 1)
    assert len(sphere.decimate(target_ratio=0.1, memory_limit=n * 300).faces) <= n // 10
    with pytest.raises(pqdc.OptionError, match="memory_limit must be at least 1 byte"):
        sphere.decimate(target_ratio=0.1, memory_limit=0)


def test_read_mesh_files(tmp_path, sphere):
    path = tmp_path / "sphere.ply"
    with pytest.warns(RuntimeWarning, match="at float precision"):  # checked at float, stored at double
        sphere.write(path, precision="double")  # read back exactly
    r = pqdc.read_mesh(path)
    assert np.array_equal(r.vertices, sphere.vertices) and np.array_equal(r.faces, sphere.faces)
    sphere.write(tmp_path / "float.ply")  # float32 by default, as the CLI
    f = pqdc.read_mesh(tmp_path / "float.ply")
    assert np.array_equal(f.vertices, sphere.vertices.astype(np.float32).astype(np.float64))
    with pytest.raises(pqdc.OptionError, match="precision must be"):
        sphere.write(tmp_path / "x.ply", precision="half")
    assert r.stats["triangles"] == len(sphere.faces) and r.stats["source"] == str(path)
    with pytest.raises(pqdc.InputError, match="no field to sample vertex normals or values"):
        r.vertex_normals
    d = r.decimate(target_ratio=0.1, voxel_size=min(SPACING))
    assert np.array_equal(d.faces, sphere.decimate(target_ratio=0.1).faces)  # same lengths, same mesh
    with pytest.raises(pqdc.InputError, match="came from arrays or a file"):
        d.vertex_normals
    # A file with normals: the decimated mesh has them, interpolated from the file's.
    fresh = pqdc.extract(sphere_distance(tuple(int(np.ceil(24.0 / s)) for s in SPACING), CENTRE, RADIUS,
                                         spacing=SPACING), spacing=SPACING, precision="double")
    fresh.write(tmp_path / "shaded.ply", normals=True)  # at double, as made
    shaded = pqdc.read_mesh(tmp_path / "shaded.ply")
    ds = shaded.decimate(target_ratio=0.1, voxel_size=min(SPACING))
    assert np.array_equal(ds.faces, d.faces)  # the normals do not steer the decimation
    radial = ds.vertices - np.array(CENTRE)
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    assert np.einsum("ij,ij->i", ds.vertex_normals, radial).min() > 0.99
    with pytest.raises(pqdc.InputError, match="came from arrays or a file"):
        ds.values

    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n" + "vn 0 0 1\n" * 4 + "f 1//1 2//2 3//3 4//4\n")
    q = pqdc.read_mesh(str(obj))
    assert q.quads.tolist() == [[0, 1, 2, 3]] and len(q.faces) == 0
    assert np.array_equal(q.vertex_normals, np.tile([0.0, 0.0, 1.0], (4, 1)))
    with pytest.raises(pqdc.InputError, match="no field to sample vertex values"):
        q.values

    with pytest.raises(pqdc.InputError, match="absent.ply"):
        pqdc.read_mesh(tmp_path / "absent.ply")
    with pytest.raises(pqdc.Error, match="mesh.xyz"):
        pqdc.read_mesh(tmp_path / "mesh.xyz")
