"""pqdc.skimage.marching_cubes against skimage.measure.marching_cubes, and
anisotropic spacing against the analytic surface."""

import numpy as np
import pytest
import skimage.measure
from scipy.spatial import cKDTree

import pqdc
import pqdc.skimage
from conftest import outward_fraction


def ellipsoid_density(shape, spacing, centre, axes):
    """Bright ellipsoid (1 inside, 0 outside, 0.5 on the surface), blurred
    over about one world unit (a CT-like edge); sampled at index * spacing."""
    grids = np.meshgrid(*(np.arange(n) * s for n, s in zip(shape, spacing)), indexing="ij", sparse=True)
    q = sum(((g - c) / a) ** 2 for g, c, a in zip(grids, centre, axes))
    # Approximate distance: (sqrt(q) - 1) * min axis; logistic of it.
    return (1 / (1 + np.exp((np.sqrt(q) - 1) * min(axes)))).astype(np.float32)


def ellipsoid_residual(points, centre, axes):
    """First-order distance of points to the ellipsoid surface."""
    p = (points - centre) / axes
    f = np.sqrt((p**2).sum(1)) - 1
    grad = p / axes / np.sqrt((p**2).sum(1))[:, None]
    return f / np.linalg.norm(grad, axis=1)


SPACING = (0.5, 1.0, 2.0)
CENTRE, AXES = np.array([16.0, 17.0, 18.0]), np.array([10.0, 12.0, 11.0])
VOLUME = ellipsoid_density((64, 34, 18), SPACING, CENTRE, AXES)


def test_matches_skimage_conventions():
    ours = pqdc.skimage.marching_cubes(VOLUME, 0.5, spacing=SPACING)
    theirs = skimage.measure.marching_cubes(VOLUME, 0.5, spacing=SPACING)
    for a, b in zip(ours, theirs):
        assert a.dtype == b.dtype and a.ndim == b.ndim and a.shape[1:] == b.shape[1:]
    unit = [pqdc.skimage.marching_cubes(VOLUME, 0.5), skimage.measure.marching_cubes(VOLUME, 0.5)]
    assert [a.dtype for a in unit[0]] == [b.dtype for b in unit[1]]  # float32 vertices without spacing
    verts, faces, normals, values = ours
    sk_verts, sk_faces, sk_normals, _ = theirs
    # Same surface in the same axis order: every vertex near skimage's mesh.
    dist, nearest = cKDTree(sk_verts).query(verts)
    assert dist.max() < 0.6 * max(SPACING)
    # Normals point the same way (skimage's are not corrected for spacing).
    assert np.einsum("ij,ij->i", normals, sk_normals[nearest]).min() > 0.5
    # Same winding: face normals agree with vertex normals in both.
    def winding(v, f, n):
        a, b, c = (v[f[:, i]].astype(np.float64) for i in range(3))
        return np.mean(np.einsum("ij,ij->i", np.cross(b - a, c - a), n[f[:, 0]]) > 0)
    assert winding(verts, faces, normals) == winding(sk_verts, sk_faces, sk_normals)
    assert winding(verts, faces, normals) in (0.0, 1.0)
    assert np.abs(values - 0.5).max() < 0.1


@pytest.mark.parametrize("direction", ["descent", "ascent"])
def test_gradient_direction_winding_as_skimage(direction):
    ours = pqdc.skimage.marching_cubes(VOLUME, 0.5, gradient_direction=direction)
    theirs = skimage.measure.marching_cubes(VOLUME, 0.5, gradient_direction=direction)
    c = np.array(VOLUME.shape) / 2
    assert outward_fraction(ours[0], ours[1], c) == outward_fraction(theirs[0], theirs[1], c)
    assert outward_fraction(ours[0], ours[1], c) in (0.0, 1.0)
    radial = ours[0] - c
    assert np.all(np.einsum("ij,ij->i", ours[2], radial) > 0)  # down the gradient: outwards


def test_anisotropic_spacing_against_the_analytic_surface():
    m = pqdc.extract(VOLUME, isovalue=0.5, interior="above", spacing=SPACING, origin=(1.0, -2.0, 3.0))
    r = ellipsoid_residual(m.vertices - [1.0, -2.0, 3.0], CENTRE, AXES)
    sk = skimage.measure.marching_cubes(VOLUME, 0.5, spacing=SPACING)[0]
    r_sk = ellipsoid_residual(sk, CENTRE, AXES)
    # Within 1/20 of the coarsest voxel; marching cubes' vertices lie on the
    # interpolated isosurface, dual contouring's within the cell (here 12%
    # further from the analytic surface on average).
    assert np.abs(r).max() < 0.05 * max(SPACING)
    assert np.sqrt(np.mean(r**2)) <= 1.25 * np.sqrt(np.mean(r_sk**2))
    assert outward_fraction(m.vertices, m.faces, CENTRE + [1.0, -2.0, 3.0]) == 1.0
    # Normals are covectors: parallel to the ellipsoid's world gradient.
    p = m.vertices - [1.0, -2.0, 3.0] - CENTRE
    g = p / AXES**2
    g /= np.linalg.norm(g, axis=1)[:, None]
    assert np.einsum("ij,ij->i", m.vertex_normals, g).min() > 0.99


def test_level_none_step_size_mask_and_degenerate():
    verts, faces, _, _ = pqdc.skimage.marching_cubes(VOLUME)  # level: middle of the range
    assert len(faces) > 100
    coarse = pqdc.skimage.marching_cubes(VOLUME, 0.5, step_size=2)[0]
    assert 2 * len(coarse) < len(verts)
    mask = np.zeros(VOLUME.shape, bool)
    mask[:32] = True
    half = pqdc.skimage.marching_cubes(VOLUME, 0.5, mask=mask)[0]
    # As skimage: the cubes whose last corner (x+1, y+1, z+1) is in the mask.
    theirs = skimage.measure.marching_cubes(VOLUME, 0.5, mask=mask)[0]
    assert theirs[:, 0].max() == 31 and len(half) < len(verts)
    assert 30 < half[:, 0].max() <= 31
    v, f, n, val = pqdc.skimage.marching_cubes(VOLUME, 0.5, allow_degenerate=False)
    a, b, c = (v[f[:, i]] for i in range(3))
    assert np.linalg.norm(np.cross(b - a, c - a), axis=1).min() > 0
    assert len(v) == len(n) == len(val) and f.max() < len(v)


def test_errors_are_skimages():
    with pytest.raises(ValueError, match="within volume data range"):
        pqdc.skimage.marching_cubes(VOLUME, 2.0)
    with pytest.raises(ValueError, match="3D numpy array"):
        pqdc.skimage.marching_cubes(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="gradient_direction"):
        pqdc.skimage.marching_cubes(VOLUME, 0.5, gradient_direction="up")
    with pytest.raises(RuntimeError, match="No surface found"):
        pqdc.skimage.marching_cubes(np.zeros((8, 8, 8), np.float32), 0.0)
    with pytest.raises(RuntimeError, match="No surface found"):
        pqdc.skimage.marching_cubes(VOLUME, 0.5, step_size=100)  # no cube left
    with pytest.raises(RuntimeError, match="No surface found"):
        pqdc.skimage.marching_cubes(np.full((5, 5, 5), np.nan))
    with pytest.raises(ValueError, match="spacing. must be three positive"):
        pqdc.skimage.marching_cubes(VOLUME, 0.5, spacing=(1, 0, 1))


def test_any_dtype_numpy_converts_is_taken():
    v, f, _, _ = pqdc.skimage.marching_cubes(VOLUME, 0.5)
    for dtype in (">f4", np.longdouble):
        w, g, _, _ = pqdc.skimage.marching_cubes(VOLUME.astype(dtype), 0.5)
        assert len(w) == len(v) and len(g) == len(f)


def test_reachable_after_import_pqdc():
    assert pqdc.skimage.marching_cubes is not None


def test_docstring_says_dual_contouring():
    assert "DUAL CONTOURING, not marching cubes" in pqdc.skimage.marching_cubes.__doc__
