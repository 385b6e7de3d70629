"""Every user error is a clear exception of the documented class."""

import os

import numpy as np
import pyopenvdb as vdb
import pytest

import pqdc
from conftest import sphere_distance

BALL = sphere_distance((16, 16, 16), (7.5, 7.5, 7.5), 5.0)


def test_class_hierarchy():
    assert issubclass(pqdc.OptionError, pqdc.Error) and issubclass(pqdc.OptionError, ValueError)
    assert issubclass(pqdc.InputError, pqdc.Error) and issubclass(pqdc.InputError, ValueError)
    assert issubclass(pqdc.WriteError, pqdc.Error) and issubclass(pqdc.WriteError, OSError)
    assert issubclass(pqdc.ResourceError, pqdc.Error) and issubclass(pqdc.ResourceError, MemoryError)
    assert issubclass(pqdc.CancelledError, pqdc.Error)
    assert not issubclass(pqdc.CancelledError, ValueError)


def test_missing_file():
    with pytest.raises(pqdc.InputError, match=r"cannot open 'no/such\.vdb'.*No such file"):
        pqdc.extract("no/such.vdb")


def test_not_a_vdb_file(tmp_path):
    p = tmp_path / "junk.vdb"
    p.write_bytes(b"not a volume")
    with pytest.raises(pqdc.InputError, match="junk.vdb"):
        pqdc.extract(p)


def test_two_grids_of_one_name_are_refused(tmp_path):
    # OpenVDB warned and the first was meshed; the CLI refuses it too.
    grids = []
    for radius in (5.0, 6.0):
        g = vdb.createLevelSetSphere(radius=radius)
        g.name = "s"
        grids.append(g)
    path = str(tmp_path / "dup.vdb")
    vdb.write(path, grids=grids)
    for grid in ("s", None):
        with pytest.raises(pqdc.InputError, match="has 2 grids named 's'; pqdc reads grids by name"):
            pqdc.extract(path, grid=grid)


def test_unknown_grid_name_lists_the_grids(source_dir):
    with pytest.raises(pqdc.InputError, match="nope"):
        pqdc.extract(os.path.join(source_dir, "volumes", "sphere.vdb"), grid="nope")


def test_messages_name_the_python_arguments(source_dir):
    # The library's messages name C++ fields and CLI options; Python callers read their keywords.
    with pytest.raises(pqdc.OptionError, match=r"^max_error must be >= 0") as e:
        pqdc.extract(BALL, adaptive=True, max_error=-1)
    with pytest.raises(pqdc.OptionError, match=r"^bbox must be finite"):
        pqdc.extract(BALL, bbox=(10, 10, 10, 0, 0, 0))
    with pytest.raises(pqdc.InputError, match=r"choose one with grid=NAME\)"):
        pqdc.extract(os.path.join(source_dir, "volumes", "fandisk.vdb"), grid="nope")
    assert "--" not in str(e.value) and "::" not in str(e.value)


def test_none():
    with pytest.raises(TypeError, match="source is None; pass a 3-D numpy array"):
        pqdc.extract(None)


def test_vec3_grid():
    g = vdb.Vec3SGrid()
    g.name = "velocity"
    with pytest.raises(pqdc.InputError, match="grid 'velocity' holds vec3s values; pqdc meshes scalar.*a component"):
        pqdc.extract(g)
    # A mask is told how to mesh it, not to take a component.
    b = vdb.BoolGrid()
    b.name = "inside"
    with pytest.raises(pqdc.InputError, match="holds bool values.*for a mask, convert it to a float grid"):
        pqdc.extract(b)


def test_two_dimensional_array():
    with pytest.raises(pqdc.InputError, match=r"expected a 3-D array, got a 2-D array of shape \(4, 5\)"):
        pqdc.extract(np.zeros((4, 5)))


def test_too_thin_array():
    with pytest.raises(pqdc.InputError, match=r"shape \(1, 5, 5\); every axis needs at least 2"):
        pqdc.extract(np.zeros((1, 5, 5)))


@pytest.mark.parametrize("source", [[[[0.0]]], 3.0, object()])
def test_wrong_source_type(source):
    with pytest.raises(TypeError, match="cannot mesh a"):
        pqdc.extract(source)


def test_unsupported_dtype():
    with pytest.raises(TypeError, match="dtype complex64 are not supported"):
        pqdc.extract(np.zeros((4, 4, 4), np.complex64))


@pytest.mark.parametrize("options,message", [
    ({"interior": "inside"}, "interior must be one of 'auto', 'below', 'above', got 'inside'"),
    ({"faces": "hexagons"}, "faces must be one of"),
    ({"normals": "smooth"}, "normals must be one of"),
    ({"sigma_n": -1.0}, "sigma_n must be >= 0"),
    ({"sigma_n": "best"}, "sigma_n must be a number >= 0, inf or 'auto'"),
    ({"isovalue": float("nan")}, "isovalue must be a finite number"),
    ({"spacing": (1, 0, 1)}, "spacing must be three positive finite voxel sizes"),
    ({"spacing": (1, 1)}, "spacing must have three entries"),
    ({"origin": (0, float("inf"), 0)}, "origin must be three finite numbers"),
    ({"axes": "yxz"}, "axes must be 'xyz'"),
    ({"threads": 0}, "threads must be at least 1"),
    ({"memory_limit": -5}, "memory_limit must be at least 1"),
    ({"adaptive": True, "max_cell_size": 3}, "max_cell_size"),
    ({"adaptive": True, "max_error": -1}, "max_error"),
    ({"grid": "density"}, "grid names a grid in a .vdb file"),
])
def test_option_errors(options, message):
    with pytest.raises(pqdc.OptionError, match=message):
        pqdc.extract(BALL, **options)


@pytest.mark.parametrize("options", [{"isovalue": "0"}, {"sigma_n": None}, {"threads": 1.5},
                                     {"progress": 3}, {"interior": 1}, {"spacing": "abc"},
                                     {"mask": [[[True]]]}])
def test_option_type_errors(options):
    with pytest.raises(TypeError, match="pqdc.extract: "):
        pqdc.extract(BALL, **options)


def test_array_options_on_a_grid():
    g = vdb.createLevelSetSphere(radius=3.0)
    with pytest.raises(pqdc.OptionError, match="spacing only apply to numpy arrays"):
        pqdc.extract(g, spacing=2.0)
    with pytest.raises(pqdc.OptionError, match="a numpy mask has no placement"):
        pqdc.extract(g, mask=np.ones((2, 2, 2), bool))


def test_mask_errors():
    with pytest.raises(pqdc.InputError, match=r"mask has shape \(4, 4, 4\) but the array has shape \(16, 16, 16\)"):
        pqdc.extract(BALL, mask=np.ones((4, 4, 4), bool))
    with pytest.raises(TypeError, match="a numpy mask must be bool or numeric"):
        pqdc.extract(BALL, mask=np.ones(BALL.shape, object))
    with pytest.raises(TypeError, match="mask must be a numpy array .* got int"):
        pqdc.extract(BALL, mask=3)
    with pytest.raises(TypeError, match="a file mask is a path or \\(path, grid name\\)"):
        pqdc.extract(BALL, mask=("a.vdb", 3))
    with pytest.raises(pqdc.OptionError, match="invert_mask=True inverts a mask: pass mask= too"):
        pqdc.extract(BALL, invert_mask=True)
    with pytest.raises(TypeError, match="invert_mask must be True or False"):
        pqdc.extract(BALL, mask=np.ones(BALL.shape, bool), invert_mask=1)


def test_flags_are_booleans():
    # bool("no") is True: a string turned adaptive mode on without a word.
    for name in ("adaptive", "sparse"):
        with pytest.raises(TypeError, match=f"{name} must be True or False, got str"):
            pqdc.extract(BALL, **{name: "no"})
    assert len(pqdc.extract(BALL, adaptive=np.bool_(False)).faces) > 0
    # Every flag alike: invert_mask took only bool, Mesh.write's normals took anything.
    assert len(pqdc.extract(BALL, mask=BALL < 0, invert_mask=np.bool_(True)).faces) > 0
    with pytest.raises(TypeError, match="normals must be True or False, got str"):
        pqdc.extract(BALL).write("never-written.ply", normals="no")


def test_integers_beyond_the_fields_are_named():
    # They reached pybind11, which said "incompatible function arguments".
    with pytest.raises(pqdc.OptionError, match="threads must be at most 4096"):
        pqdc.extract(BALL, threads=2**70)
    with pytest.raises(pqdc.OptionError, match="memory_limit must be at most"):
        pqdc.extract(BALL, memory_limit=2**80)
    with pytest.raises(pqdc.OptionError, match=r"max_cell_size must be a power of two in \[1, 4096\]"):
        pqdc.extract(BALL, adaptive=True, max_cell_size=2**40)
    m = pqdc.extract(BALL)
    with pytest.raises(pqdc.OptionError, match="target_faces must be at most"):
        m.decimate(target_faces=2**70)


def test_write_error_leaves_no_file(tmp_path):
    m = pqdc.extract(BALL)
    with pytest.raises(pqdc.WriteError, match="cannot write") as e:
        m.write(tmp_path / "missing-dir" / "ball.obj")
    assert isinstance(e.value, OSError)
    with pytest.raises(pqdc.OptionError, match="ball.xyz"):
        m.write(tmp_path / "ball.xyz")
    assert list(tmp_path.iterdir()) == []


def test_resource_error_before_allocating():
    big = sphere_distance((64, 64, 64), (31.5, 31.5, 31.5), 25.0)
    with pytest.raises(pqdc.ResourceError, match="memory_limit") as e:
        pqdc.extract(big, memory_limit=100_000)
    assert isinstance(e.value, MemoryError)


def test_cancelled_error():
    with pytest.raises(pqdc.CancelledError, match="cancelled by the caller"):
        pqdc.extract(BALL, progress=lambda fraction: False)
    # numpy's False (what `elapsed < limit` gives) cancels too; None and 0 go on.
    with pytest.raises(pqdc.CancelledError):
        pqdc.extract(BALL, progress=lambda fraction: np.float64(fraction) > 2)
    assert len(pqdc.extract(BALL, progress=lambda fraction: None).faces) > 0
