"""min_component: pqdc.extract and pqdc.extract_to_file remove small
components as the CLI's --min-component does, in the shortest voxel side."""

import numpy as np
import pytest

import pyopenvdb as vdb

import pqdc
from conftest import sphere_distance

SHAPE = (64, 40, 40)
BIG = ((20.0, 20.0, 20.0), 10.0)       # diagonal about 2 sqrt(3) 10 = 35 voxels
DROPLET = ((45.3, 20.2, 20.4), 0.9)    # three inside lattice points: about 3 voxels across


def two_spheres():
    return np.minimum(sphere_distance(SHAPE, *BIG), sphere_distance(SHAPE, *DROPLET))


def test_an_array_loses_its_droplet_and_keeps_the_sphere():
    whole = pqdc.extract(two_spheres())
    assert whole.stats["components_found"] == 0  # no filter asked for
    # None, as the CLI's --stats writes null, where no component was removed or kept.
    assert whole.stats["components_largest_removed_diagonal_voxels"] is None
    assert whole.stats["components_smallest_kept_diagonal_voxels"] is None
    assert whole.vertices[:, 0].max() > 44  # the droplet is meshed
    kept = pqdc.extract(two_spheres(), min_component=5)
    s = kept.stats
    assert s["components_found"] == 2 and s["components_removed"] == 1
    assert s["components_removed_vertices"] == len(whole.vertices) - len(kept.vertices) > 0
    assert s["components_removed_faces"] == len(whole.faces) - len(kept.faces) > 0
    assert s["vertices"] == len(kept.vertices) and s["triangles"] == len(kept.faces)
    assert 0 < s["components_largest_removed_diagonal_voxels"] < 5 < s["components_smallest_kept_diagonal_voxels"]
    assert kept.vertices[:, 0].max() < 31  # only the big sphere is left
    # The same in adaptive mode.
    adaptive = pqdc.extract(two_spheres(), min_component=5, adaptive=True)
    assert adaptive.stats["components_removed"] == 1 and adaptive.vertices[:, 0].max() < 31


def test_an_arrays_islands_are_measured_in_world_units():
    # Slices 4 apart stretch the droplet to about 7 voxels (of the shortest
    # spacing, 1) along z: it is no island of 5 voxels any more. Measured in
    # index space (3 voxels across) it would have been removed.
    stretched = pqdc.extract(two_spheres(), spacing=(1, 1, 4), min_component=5)
    assert stretched.stats["components_found"] == 2 and stretched.stats["components_removed"] == 0
    assert 5 < stretched.stats["components_smallest_kept_diagonal_voxels"] < 14
    assert stretched.stats["components_largest_removed_diagonal_voxels"] is None
    # Scaling every axis alike changes nothing: voxels are the unit.
    scaled = pqdc.extract(two_spheres(), spacing=0.25, min_component=5)
    assert scaled.stats["components_removed"] == 1


def test_a_file_streams_the_in_core_bytes(tmp_path):
    grid = vdb.FloatGrid(background=3.0)
    grid.copyFromArray(np.clip(two_spheres(), -3, 3), tolerance=0.0)
    grid.gridClass = vdb.GridClass.LEVEL_SET
    grid.name = "two"
    vdb.write(str(tmp_path / "two.vdb"), grids=[grid])
    source = str(tmp_path / "two.vdb")
    in_core = pqdc.extract(source, min_component=5)
    assert in_core.stats["components_removed"] == 1
    in_core.write(str(tmp_path / "in_core.ply"))
    stats = pqdc.extract_to_file(source, tmp_path / "streamed.ply", min_component=5, brick_size=128, brick_runs=2)
    assert (tmp_path / "streamed.ply").read_bytes() == (tmp_path / "in_core.ply").read_bytes()
    assert stats["points_written"] == len(in_core.vertices)
    assert stats["components_removed"] == 1


@pytest.mark.parametrize("value, error, message", [
    (-1, pqdc.OptionError, "min_component is a size in voxels, >= 0"),
    (float("nan"), pqdc.OptionError, "min_component is a size in voxels, >= 0"),
    ("3.5", TypeError, "min_component must be a number"),
    (True, TypeError, "min_component must be a number"),
])
def test_bad_values_are_refused(value, error, message, tmp_path):
    with pytest.raises(error, match=message):
        pqdc.extract(two_spheres(), min_component=value)
    with pytest.raises(error, match=message):
        pqdc.extract_to_file("missing.vdb", tmp_path / "out.ply", min_component=value)
    assert not (tmp_path / "out.ply").exists()
