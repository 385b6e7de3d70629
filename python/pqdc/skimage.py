"""A drop-in for ``skimage.measure.marching_cubes`` backed by pqdc.

    from pqdc.skimage import marching_cubes   # instead of skimage.measure
    verts, faces, normals, values = marching_cubes(volume, 0.5, spacing=(2, 1, 1))
"""

import numpy as np

from ._api import extract


def marching_cubes(volume, level=None, *, spacing=(1.0, 1.0, 1.0), gradient_direction="descent",
                   step_size=1, allow_degenerate=True, method="lewiner", mask=None, sigma_n="auto"):
    """Isosurface of a 3-D array, with skimage.measure.marching_cubes' signature
    and return values -- computed by DUAL CONTOURING, not marching cubes.

    pqdc places one vertex per crossed cell at the minimizer of the cell's
    probabilistic plane quadrics: sharp features are kept, the mesh has about
    as many vertices as marching cubes' (one per cell instead of one per
    crossed edge) and they lie close to, not exactly on, the interpolated
    isosurface. The conventions are skimage's:

    * ``verts`` (V, 3) in numpy axis order, scaled by ``spacing`` (one entry
      per numpy axis): float32, or float64 when spacing is not (1, 1, 1); ``faces`` (F, 3) int32; ``normals`` (V, 3)
      float32 unit vectors pointing down the gradient (towards lower values),
      for either gradient_direction; ``values`` (V,) float32, the volume
      interpolated at each vertex (about ``level``; skimage's values are
      taken from the data around each vertex differently).
    * ``gradient_direction='descent'`` (objects brighter than their
      surroundings) or ``'ascent'`` decides the winding exactly as skimage
      does; ``step_size`` subsamples the volume; ``mask`` (bool, the volume's
      shape) limits the surface to the cubes skimage keeps: those whose last
      corner (x+1, y+1, z+1 in steps) is in the mask.
    * ``level`` defaults to the middle of the data range; a level outside it,
      a non-3-D volume and an empty result (also a ``step_size`` larger than
      the volume, an all-NaN volume) raise what skimage raises. Any dtype
      numpy can convert to float64 is taken (big-endian, long double).

    Differences: ``method`` is accepted and ignored (there is one method);
    normals are mapped as covectors when ``spacing`` is anisotropic (skimage
    leaves them in index space); ``spacing`` must be positive (skimage also
    takes zero and negative); a surface that leaves the volume ends at the
    centers of the outermost cells, half a voxel inside the border (dual
    vertices), where skimage's reaches the border; ``sigma_n`` is pqdc's
    quadric noise option (see pqdc.extract).
    """
    if not isinstance(volume, np.ndarray) or volume.ndim != 3:
        raise ValueError("Input volume should be a 3D numpy array.")
    if min(volume.shape) < 2:
        raise ValueError("Input array must be at least 2x2x2.")
    if method not in ("lewiner", "lorensen", "_lorensen"):
        raise ValueError("method should be one of 'lewiner', 'lorensen' or '_lorensen'.")
    if gradient_direction not in ("descent", "ascent"):
        raise ValueError(f"Incorrect input {gradient_direction} in `gradient_direction`, see docstring.")
    if not volume.dtype.isnative or (volume.dtype.kind == "f" and volume.dtype.itemsize > 8):
        volume = volume.astype(np.float64)
    if volume.dtype.kind == "f" and np.isnan(volume).all():
        raise RuntimeError("No surface found at the given iso value.")
    low, high = float(np.nanmin(volume)), float(np.nanmax(volume))
    if level is None:
        level = 0.5 * (low + high)
    else:
        level = float(level)
        if level < low or level > high:
            raise ValueError("Surface level must be within volume data range.")
    if len(spacing) != 3:
        raise ValueError("`spacing` must consist of three floats.")
    if not all(float(s) > 0 and np.isfinite(float(s)) for s in spacing):
        raise ValueError(f"`spacing` must be three positive finite numbers, one per numpy axis "
                         f"(pqdc needs a voxel size), got {tuple(spacing)}.")
    step_size = int(step_size)
    if step_size < 1:
        raise ValueError("step_size must be at least one.")
    if mask is not None and mask.shape != volume.shape:
        raise ValueError("volume and mask must have the same shape.")

    step = slice(None, None, step_size)
    if min(len(range(n)[step]) for n in volume.shape) < 2:  # no cube left
        raise RuntimeError("No surface found at the given iso value.")
    spacing = tuple(float(s) * step_size for s in spacing)
    # Inside "below" for descent: pqdc winds counter-clockwise seen from the
    # outside, i.e. towards higher values, which is skimage's descent winding.
    interior = "below" if gradient_direction == "descent" else "above"
    # skimage returns float32 vertices, promoted to float64 when it scales them by spacing:
    # the repair keeps them apart at the precision returned.
    unit = all(s == step_size for s in spacing)
    mesh = extract(volume[step, step, step], isovalue=level, sigma_n=sigma_n, spacing=spacing,
                   mask=None if mask is None else _cube_mask(mask[step, step, step]), interior=interior,
                   precision="float" if unit else "double")
    if len(mesh.vertices) == 0:
        raise RuntimeError("No surface found at the given iso value.")
    verts = mesh.vertices.astype(np.float32 if unit else np.float64)
    faces = np.array(mesh.faces, dtype=np.int32)
    outward = mesh.vertex_normals
    normals = (-outward if interior == "below" else outward).astype(np.float32)
    values = mesh.values.astype(np.float32)
    if not allow_degenerate:
        verts, faces, normals, values = _drop_degenerate(verts, faces, normals, values)
    return verts, faces, normals, values


def _drop_degenerate(verts, faces, normals, values):
    """Faces with a repeated or coincident corner, then unreferenced vertices."""
    a, b, c = (verts[faces[:, i]] for i in range(3))
    area = np.linalg.norm(np.cross(b.astype(np.float64) - a, c.astype(np.float64) - a), axis=1)
    faces = faces[area > 0]
    used = np.zeros(len(verts), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used, dtype=np.int64) - 1
    return verts[used], remap[faces].astype(np.int32), normals[used], values[used]


def _cube_mask(mask):
    """skimage tests a cube's mask at its last corner; pqdc.extract at its first."""
    shifted = np.zeros(mask.shape, bool)
    shifted[:-1, :-1, :-1] = np.asarray(mask, bool)[1:, 1:, 1:]
    return shifted
