"""mask= and invert_mask= for every source: numpy masks (array sources),
pyopenvdb grids and .vdb files, all as ExtractOptions::region."""

import numpy as np
import pyopenvdb as vdb
import pytest

import pqdc
from conftest import sphere_distance

SHAPE, CENTRE, RADIUS = (40, 40, 40), (19.5, 20.2, 18.9), 13.0
SPACING, ORIGIN = (0.5, 0.75, 1.25), (3.0, -2.0, 1.0)
CUT = 24  # the mask holds voxels with z < CUT


def ball():
    return sphere_distance(SHAPE, CENTRE, RADIUS)


def numpy_mask(dtype=bool):
    m = np.zeros(SHAPE, dtype)
    m[:, :, :CUT] = 1
    return m


def placed_bool_grid(spacing=SPACING, origin=ORIGIN):
    """The numpy mask as a BoolGrid whose transform places it like the array."""
    g = vdb.BoolGrid()
    g.fill((0, 0, 0), (SHAPE[0] - 1, SHAPE[1] - 1, CUT - 1), True, active=True)
    m = np.diag([*spacing, 1.0])
    m[3, :3] = origin
    g.transform = vdb.createLinearTransform(m.tolist())
    g.name = "half"
    return g


def rows(a):
    return {tuple(r) for r in np.asarray(a)}


def assert_part_of(part, whole):
    """The masked mesh is the whole one inside the mask: its vertices are whole's."""
    assert 0 < len(part.faces) < len(whole.faces)
    assert rows(part.vertices) <= rows(whole.vertices)


def assert_split(inside, outside, whole):
    """A mask and its inverse split the cells, so the vertices, exactly; the
    faces are the whole mesh's but those joining cells on both sides."""
    a, b = rows(inside.vertices), rows(outside.vertices)
    assert not a & b and a | b == rows(whole.vertices)
    side = np.array([tuple(v) in a for v in whole.vertices])[whole.faces]
    across = np.count_nonzero(side.any(axis=1) & ~side.all(axis=1))
    assert across > 0 and len(inside.faces) + len(outside.faces) + across == len(whole.faces)


def test_numpy_mask_keeps_the_whole_mesh_inside_it():
    whole = pqdc.extract(ball())
    part = pqdc.extract(ball(), mask=numpy_mask())
    assert_part_of(part, whole)
    assert part.vertices[:, 2].max() <= CUT  # cells whose minimum corner is in the mask
    assert part.vertices[:, 2].max() > CUT - 1


@pytest.mark.parametrize("dtype", [np.uint8, np.int32, np.float32])
def test_numeric_numpy_mask_counts_nonzero(dtype):
    m = numpy_mask(dtype) * dtype(7)
    a = pqdc.extract(ball(), mask=m)
    b = pqdc.extract(ball(), mask=numpy_mask())
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_numpy_mask_follows_the_axes_option():
    v = ball()
    a = pqdc.extract(v, mask=numpy_mask())
    b = pqdc.extract(np.ascontiguousarray(v.transpose(2, 1, 0)), axes="zyx",
                     mask=np.ascontiguousarray(numpy_mask().transpose(2, 1, 0)))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


@pytest.mark.parametrize("adaptive", [False, True])
def test_mask_and_inverted_mask_split_the_surface(adaptive):
    whole = pqdc.extract(ball(), adaptive=adaptive)
    inside = pqdc.extract(ball(), mask=numpy_mask(), adaptive=adaptive)
    outside = pqdc.extract(ball(), mask=numpy_mask(), invert_mask=True, adaptive=adaptive)
    assert inside.vertices[:, 2].max() <= CUT and outside.vertices[:, 2].min() >= CUT - 1
    if not adaptive:  # uniform cells split exactly; adaptive merges differ near the cut
        assert_split(inside, outside, whole)


def test_pyopenvdb_mask_on_a_placed_array_equals_the_numpy_mask():
    # The grid lives in world space: with the array's spacing and origin in
    # its transform it selects the same voxels as the numpy mask.
    a = pqdc.extract(ball(), spacing=SPACING, origin=ORIGIN, mask=numpy_mask())
    b = pqdc.extract(ball(), spacing=SPACING, origin=ORIGIN, mask=placed_bool_grid())
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    # Unplaced (unit voxels at the origin) it selects other voxels.
    c = pqdc.extract(ball(), spacing=SPACING, origin=ORIGIN, mask=placed_bool_grid((1, 1, 1), (0, 0, 0)))
    assert not np.array_equal(a.faces, c.faces) or len(a.vertices) != len(c.vertices)


def level_set():
    g = vdb.createLevelSetSphere(radius=6.0, voxelSize=0.5)
    g.name = "sphere"
    return g


def half_space_mask():
    """World z < 1 on a 0.5 grid, as a BoolGrid."""
    g = vdb.BoolGrid()
    g.fill((-20, -20, -20), (20, 20, 1), True, active=True)
    g.transform = vdb.createLinearTransform(voxelSize=0.5)
    g.name = "half"
    return g


def test_pyopenvdb_mask_on_a_pyopenvdb_grid():
    whole = pqdc.extract(level_set())
    part = pqdc.extract(level_set(), mask=half_space_mask())
    rest = pqdc.extract(level_set(), mask=half_space_mask(), invert_mask=True)
    assert_part_of(part, whole)
    assert part.vertices[:, 2].max() <= 1.0 + 1e-9 and rest.vertices[:, 2].min() >= 0.5 - 1e-9
    assert_split(part, rest, whole)


def test_file_masks_as_path_or_path_and_grid(tmp_path):
    both = str(tmp_path / "both.vdb")
    only = str(tmp_path / "mask.vdb")
    vdb.write(both, grids=[level_set(), half_space_mask()])
    vdb.write(only, grids=[half_space_mask()])
    expected = pqdc.extract(level_set(), mask=half_space_mask())
    for source in (level_set(), both):
        for mask in ((both, "half"), only):
            got = pqdc.extract(source, grid="sphere" if source is both else None, mask=mask)
            assert np.array_equal(got.vertices, expected.vertices) and np.array_equal(got.faces, expected.faces)
    # A file mask on an array source is placed by spacing and origin, like a grid.
    placed = str(tmp_path / "placed.vdb")
    vdb.write(placed, grids=[placed_bool_grid()])
    a = pqdc.extract(ball(), spacing=SPACING, origin=ORIGIN, mask=numpy_mask())
    b = pqdc.extract(ball(), spacing=SPACING, origin=ORIGIN, mask=(placed, "half"))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_mask_errors_name_what_is_wrong(tmp_path):
    with pytest.raises(pqdc.InputError, match=r"mask has shape \(40, 40, 39\) but the array has shape \(40, 40, 40\)"):
        pqdc.extract(ball(), mask=np.ones((40, 40, 39), bool))
    missing = str(tmp_path / "missing.vdb")
    with pytest.raises(pqdc.InputError, match="missing.vdb"):
        pqdc.extract(ball(), mask=missing)
    f = str(tmp_path / "m.vdb")
    vdb.write(f, grids=[half_space_mask()])
    with pytest.raises(pqdc.InputError, match="'nope'.*half"):
        pqdc.extract(level_set(), mask=(f, "nope"))
    with pytest.raises(pqdc.InputError, match="vec3s"):
        pqdc.extract(level_set(), mask=vdb.Vec3SGrid())
    with pytest.raises(TypeError, match="pqdc.extract: mask must be a numpy array .*got list"):
        pqdc.extract(level_set(), mask=[1, 2, 3])
