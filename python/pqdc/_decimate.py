"""pqdc.decimate(): fewer triangles at bounded error, for a pqdc.Mesh or mesh arrays."""

import numpy as np

from . import _pqdc
from ._decimate_options import request
from ._errors import OptionError
from ._mesh import Mesh


def decimate(mesh, faces=None, *, normals=None, target_ratio=None, target_faces=None, max_distance=None,
             metric="triangle", sigma_position="auto", sigma_normal=0.05, voxel_size=None, threads=None,
             progress=None, memory_limit=None, precision="float"):
    """Collapse edges to the minimizer of summed probabilistic quadrics
    (the C++ ``pqdc::decimate``; the CLI's ``pqdc-decimate``).

    mesh, faces
        A :class:`pqdc.Mesh` (faces None), or the arrays of any triangle or
        quad mesh: vertices ``(N, 3)`` of a real dtype and faces ``(M, 3)``
        or ``(M, 4)`` of an integer dtype (e.g. skimage's marching cubes).
    normals
        With arrays: optional vertex normals ``(N, 3)``, carried over to the
        result's ``vertex_normals`` (interpolated from the input's where a
        vertex moved; see the C++ ``pqdc::decimate``).
    target_ratio, target_faces, max_distance
        Stop at this fraction of the input's triangles (quads count as two),
        at this many triangles, or before any vertex would move farther than
        ``max_distance`` voxels from the input surface. At least one; with
        several, decimation stops at the first one reached.
    metric
        ``"triangle"`` (probabilistic triangle quadrics, the default),
        ``"plane"`` (probabilistic plane quadrics) or ``"curvature"``.
    sigma_position, sigma_normal
        Positional noise of the vertices in voxels (``"auto"``: estimated
        from the mesh) and normal noise of the plane metric (dimensionless).
    voxel_size
        World units per voxel, the unit of the lengths above. Default: the
        shortest voxel side of the grid or array the mesh was extracted from;
        for arrays, the mean edge length.
    threads
        Worker threads (None: all cores). The result is the same for any count.
    progress
        ``callable(fraction)`` called from the calling thread with the GIL
        held before each pass and within it, between its stages and slices
        of its checks (fractions of the faces to remove, never falling,
        ending at 1);
        returning False cancels (``pqdc.CancelledError``), an exception it
        raises propagates unchanged. Ctrl-C cancels at the same points.
    memory_limit
        Bytes the decimation may use (about 300 per input triangle, checked
        before it starts; ``pqdc.ResourceError`` above it). None: 80% of
        physical memory.
    precision
        ``"float"`` (default) or ``"double"``: how the result will be
        stored. No collapse creates an intersection in the vertices rounded
        to it, and ``Mesh.write`` stores at this precision by default (as
        ``pqdc-decimate`` checks at its output's precision).

    Returns a new :class:`pqdc.Mesh` of triangles. Closed manifold input
    stays closed and manifold with the same genus, and no self-intersection
    is created. Its ``stats`` are the source mesh's (with ``vertices``,
    ``triangles`` and ``quads`` counting this mesh) plus ``decimate_*``
    entries. Its vertex normals are sampled from the source mesh's grid at
    the new positions while the source holds its grid; otherwise (a mesh
    read from a file with normals, a source whose normals were read first,
    arrays with ``normals``) the source's normals are carried over, and
    without them there are none. The GIL is released while decimating. A cancelled
    call leaves no result and the source mesh unchanged.
    """
    r = request(target_ratio=target_ratio, target_faces=target_faces, max_distance=max_distance, metric=metric,
                sigma_position=sigma_position, sigma_normal=sigma_normal, voxel_size=voxel_size, threads=threads,
                progress=progress, memory_limit=memory_limit, precision=precision)
    if isinstance(mesh, Mesh):
        if faces is not None or normals is not None:
            raise OptionError("faces and normals are for a mesh given as arrays; a pqdc.Mesh brings its own")
        return Mesh(mesh._data.decimate(r))
    if faces is None:
        raise TypeError(f"pqdc.decimate: pass a pqdc.Mesh, or vertices and faces arrays; got "
                        f"{type(mesh).__name__} and no faces")
    vertices, faces = np.asarray(mesh), np.asarray(faces)
    if vertices.dtype.kind not in "fiu":
        raise TypeError(f"pqdc.decimate: vertices must be a real array, got dtype {vertices.dtype}")
    if faces.dtype.kind not in "iu":
        raise TypeError(f"pqdc.decimate: faces must be an integer array, got dtype {faces.dtype}")
    if normals is None:
        normals = np.zeros((0, 3))
    normals = np.asarray(normals)
    if normals.dtype.kind not in "fiu":
        raise TypeError(f"pqdc.decimate: normals must be a real array, got dtype {normals.dtype}")
    return Mesh(_pqdc.decimate_arrays(vertices, faces, normals, r))
