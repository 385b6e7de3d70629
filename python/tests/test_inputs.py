"""Issue 12's inputs from Python: the interior rule on grids, warnings, bbox."""

import numpy as np

import pyopenvdb as vdb

import pqdc
from conftest import enclosed_volume, sphere_distance


def _radial(n, f, background):
    r = np.sqrt(((np.indices((n, n, n)) - (n - 1) / 2.0) ** 2).sum(axis=0))
    g = vdb.FloatGrid(background=background)
    g.copyFromArray(f(r).astype(np.float32), tolerance=0.0)
    return g


def test_ct_grid_of_unknown_class_comes_out_outward_and_says_why():
    g = _radial(28, lambda r: 1000.0 * np.tanh((8.0 - r) / 1.5), -1000.0)
    m = pqdc.extract(g, isovalue=300)
    assert enclosed_volume(m.vertices, m.faces) > 0
    assert m.stats["interior"] == "above"
    assert "background -1000 is below the isovalue 300" in m.stats["interior_reason"]
    assert m.stats["warnings"] == []


def test_fog_volume_at_its_background_is_warned_about():
    g = _radial(28, lambda r: np.clip((9.0 - r) / 2.0, 0.0, 1.0), 0.0)
    g.gridClass = vdb.GridClass.FOG_VOLUME
    m = pqdc.extract(g, isovalue=0.0)
    assert len(m.stats["warnings"]) == 1
    assert "equals the background" in m.stats["warnings"][0]
    assert pqdc.extract(g, isovalue=0.5).stats["warnings"] == []


def test_bbox_in_world_units_cuts_an_array_mesh_open():
    spacing = (0.5, 1.0, 2.0)
    v = sphere_distance((64, 32, 16), (16.0, 16.0, 16.0), 10.0, spacing)
    full = pqdc.extract(v, spacing=spacing)
    part = pqdc.extract(v, spacing=spacing, bbox=(-100, -100, -100, 16.0, 100, 100))
    assert 0.3 * len(full.faces) < len(part.faces) < 0.7 * len(full.faces)
    assert part.vertices[:, 0].max() <= 16.0 + 0.25 + 1e-9  # half a cell along x
    kept = {tuple(p) for p in full.vertices}
    assert all(tuple(p) in kept for p in part.vertices)


def test_an_empty_mesh_says_why():
    # A binary mask at the default isovalue 0 (its smallest value) gave an
    # empty mesh with no warning; so did an isovalue beyond the data.
    mask = np.zeros((16, 16, 16), bool)
    mask[4:12, 4:12, 4:12] = True
    m = pqdc.extract(mask)
    assert len(m.vertices) == 0
    assert "e.g. isovalue=0.5" in m.stats["warnings"][0]
    assert len(pqdc.extract(mask, isovalue=0.5, interior="above").vertices) > 0
    ramp = np.linspace(0, 100, 16**3).reshape(16, 16, 16)
    (warning,) = pqdc.extract(ramp, isovalue=1000).stats["warnings"]
    assert "the isovalue 1000 is outside that range; choose an isovalue inside it" in warning
    # A surface only in the border cells: the value range was blamed
    # ("never change sign"), though the isovalue is crossed.
    tiny = np.zeros((2, 2, 2), np.float32)
    tiny[0, 0, 0] = 1
    m = pqdc.extract(tiny, isovalue=0.5, interior="above")
    assert len(m.vertices) == 0
    (warning,) = m.stats["warnings"]
    assert "crossed on 3 lattice edges, but each lies on the array's border" in warning
    assert "np.pad(a, 1, mode='edge')" in warning
    assert len(pqdc.extract(np.pad(tiny, 1, mode="edge"), isovalue=0.5, interior="above").vertices) > 0
    # A sphere cut by the array's border: open, and now said (warnings were empty).
    cut = sphere_distance((16, 16, 16), (2.0, 8.0, 8.0), 6.0)
    m = pqdc.extract(cut)
    assert m.stats["boundary_crossings"] > 0
    assert any("the mesh is open where the surface reaches the array's border" in w for w in m.stats["warnings"])
    assert pqdc.extract(sphere_distance((16, 16, 16), (8.0, 8.0, 8.0), 5.0)).stats["warnings"] == []
    # A constant array suggested "e.g. isovalue=3", the isovalue just given.
    (warning,) = pqdc.extract(np.full((8, 8, 8), 3.0, np.float32), isovalue=3.0).stats["warnings"]
    assert "every value is 3, so no isovalue crosses it" in warning


def test_density_array_with_the_default_interior_is_warned_inside_out():
    # A density blob (high inside, low all around): the default for arrays is
    # inside below, so the mesh encloses the low values and faces into the
    # blob. It used to say nothing.
    density = -sphere_distance((24, 24, 24), (12.0, 12.0, 12.0), 7.0)
    m = pqdc.extract(density)
    assert enclosed_volume(m.vertices, m.faces) < 0
    (warning,) = m.stats["warnings"]
    assert "the mesh is inside out" in warning and "interior='above'" in warning
    right = pqdc.extract(density, interior="above")
    assert enclosed_volume(right.vertices, right.faces) > 0 and right.stats["warnings"] == []
    assert pqdc.extract(density, interior="below").stats["warnings"] == []  # asked for: not second-guessed
    # A distance array (border above) and one whose border is partly above say nothing.
    assert pqdc.extract(-density).stats["warnings"] == []
    half = density.copy()
    half[0] = 10.0
    assert not any("inside out" in w for w in pqdc.extract(half).stats["warnings"])


def test_a_mask_at_its_extreme_value_is_warned():
    # A 0/1 mask at isovalue 0 with inside above (or 1 with inside below) is
    # meshed through the voxels at that value next to the object, half a
    # voxel outside the level between 0 and 1. It used to say nothing.
    mask = np.zeros((20, 20, 20), np.uint8)
    mask[5:15, 5:15, 5:15] = 1
    m = pqdc.extract(mask, isovalue=0, interior="above")
    assert np.allclose(np.asarray(m.vertices).min(axis=0), 4.0, atol=1e-3)  # the 0 voxels at 4, not 4.5
    (warning,) = m.stats["warnings"]
    assert "the array's smallest value" in warning and "isovalue=0.5" in warning
    (warning,) = pqdc.extract(mask.astype(np.float32), isovalue=1, interior="below").stats["warnings"]
    assert "the array's largest value" in warning and "isovalue=0.5" in warning
    # Between the values, or at the extreme on the inside's own end (which
    # gives an empty mesh, explained as before), no such warning.
    assert pqdc.extract(mask, isovalue=0.5, interior="above").stats["warnings"] == []
    assert not any("runs through the voxels" in w
                   for w in pqdc.extract(mask, isovalue=1, interior="above").stats["warnings"])
    # NaN values do not hide the extreme.
    with_nan = mask.astype(np.float32)
    with_nan[0, 0, 0] = np.nan
    assert any("the array's smallest value" in w
               for w in pqdc.extract(with_nan, isovalue=0, interior="above").stats["warnings"])


def test_a_file_of_several_grids_says_which_it_meshed(tmp_path):
    # The CLI logs the pick; Python said nothing.
    a = _radial(20, lambda r: r - 6.0, 3.0)
    a.name = "b_sdf"
    b = _radial(20, lambda r: r - 4.0, 3.0)
    b.name = "a_sdf"
    path = str(tmp_path / "two.vdb")
    vdb.write(path, grids=[a, b])
    m = pqdc.extract(path)
    assert m.stats["grid"] == "a_sdf"
    (warning,) = m.stats["warnings"]
    assert "has several scalar grids ('a_sdf', 'b_sdf'); meshed 'a_sdf'" in warning and "grid=NAME" in warning
    assert pqdc.extract(path, grid="b_sdf").stats["warnings"] == []
    streamed = pqdc.extract_to_file(path, str(tmp_path / "out.ply"))
    assert any("meshed 'a_sdf'" in w for w in streamed["warnings"])
