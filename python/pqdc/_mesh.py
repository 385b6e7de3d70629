"""pqdc.Mesh: numpy views of a mesh the C++ library produced."""

import os
import warnings

import numpy as np

from . import _pqdc
from ._decimate_options import request
from ._errors import double_precision, flag


def read_mesh(path):
    """A :class:`pqdc.Mesh` from a mesh file: .obj, .ply (ASCII or binary),
    .off or .stl (binary; corners at the same position become one vertex),
    by extension. Polygons of more than four corners become triangle fans.
    The file's vertex normals (PLY nx/ny/nz, one OBJ vn per v) become
    ``vertex_normals``; there are no ``values``. For example
    ``pqdc.read_mesh("scan.ply").decimate(target_ratio=0.1).write("out.ply")``.
    pqdc.InputError names the file and what is wrong with it."""
    return Mesh(_pqdc.read_mesh_file(os.fsdecode(os.fspath(path))))


def _restore_mesh(state, warnings):
    """A pickled Mesh back (Mesh.__reduce__)."""
    data = _pqdc.MeshData.__new__(_pqdc.MeshData)
    data.__setstate__(state)
    return Mesh(data, warnings)


class Mesh:
    """A polygon mesh from :func:`pqdc.extract`.

    The arrays are read-only, zero-copy views of the C++ result; each keeps
    the result alive, so they stay valid after the Mesh, the source array or
    grid are deleted. Copy them (``np.array(mesh.vertices)``) to edit.

    Faces are wound counter-clockwise seen from outside (right-hand normal
    pointing out of the interior), in the returned coordinates.
    """

    __slots__ = ("_data", "_warnings")

    def __init__(self, data, warnings=None):
        self._data = data
        self._warnings = warnings  # replaces stats["warnings"] when the Python layer knows better

    def __reduce__(self):
        # Every pickle protocol: 0 and 1 refused a class with __slots__ and no
        # __getstate__, and cannot rebuild the C++ object by themselves.
        return (_restore_mesh, (self._data.__getstate__(), self._warnings))

    @property
    def vertices(self):
        """(N, 3) float64 world positions."""
        return self._data.vertices

    @property
    def faces(self):
        """(M, 3) int32 triangles. With faces="quads" the uniform mode's
        faces are all quads (this is empty); adaptive mode's are quads and
        triangles (both arrays): use ``triangles()`` for all faces as
        triangles."""
        return self._data.triangles

    @property
    def quads(self):
        """(K, 4) int32 quads (empty unless extracted with faces="quads";
        see ``faces``)."""
        return self._data.quads

    @property
    def vertex_normals(self):
        """(N, 3) float64 unit outward normals: the field's gradient sampled at
        each vertex (trilinear over the corners' central differences), mapped
        to world space as covectors. Zero where the gradient vanishes.

        Sampled on first access (with the GIL released) from the grid the
        mesh came from, which the Mesh keeps alive until then: the converted
        array, the .vdb file's grid or a reference to the pyopenvdb grid
        (do not modify that grid before reading the normals)."""
        return self._data.normals

    @property
    def values(self):
        """(N,) float64 field value at each vertex (trilinear); close to the
        isovalue, not equal to it (dual contouring places vertices at quadric
        minimizers)."""
        return self._data.values

    @property
    def stats(self):
        """dict: counts (vertices, triangles, active cells, clamped vertices,
        dense blocks of an array's conversion...), seconds per stage, and the
        resolved mode, interior and source."""
        stats = self._data.stats
        if self._warnings is not None:
            stats["warnings"] = list(self._warnings)
        return stats

    def triangles(self):
        """(M', 3) int32: the triangles, with each quad split as 0-1-2, 0-2-3."""
        q = self.quads
        if len(q) == 0:
            return self.faces
        split = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        return np.concatenate([self.faces, split])

    def decimate(self, **options):
        """A decimated copy (:func:`pqdc.decimate` with this mesh; same
        options, e.g. ``mesh.decimate(target_ratio=0.1)``)."""
        return Mesh(self._data.decimate(request(**options)))

    def write(self, path, precision=None, normals=False):
        """Write .obj, .ply (binary), .off or .stl, chosen by extension,
        atomically (pqdc.WriteError on failure, no partial file). Vertices
        are stored as float32 (``precision="float"``, what most readers
        take, as the CLI's default) or float64 (``"double"``: the vertices
        read back exactly); STL is always float32. The default (None) is the
        precision the mesh was made intersection-free at (``precision=`` of
        :func:`pqdc.extract` and :func:`pqdc.decimate`; "float" for a mesh
        read from a file); another one warns (RuntimeWarning), since
        rounding can make nearly touching faces cross. ``normals=True`` adds
        ``vertex_normals`` (PLY nx/ny/nz, OBJ vn; OFF and STL have none:
        pqdc.OptionError)."""
        checked = self._data.checked_precision
        if precision is None:
            precision = checked or "float"
        as_double = double_precision(precision)
        if checked and precision != checked:
            warnings.warn(f"pqdc.Mesh.write: this mesh was made free of self-intersections at {checked} "
                          f"precision; stored at {precision} precision its faces may cross where they nearly "
                          f"touch (pass precision={checked!r}, or make it with precision={precision!r})",
                          RuntimeWarning, stacklevel=2)
        self._data.write(os.fsdecode(os.fspath(path)), as_double, flag("normals", normals, "pqdc.Mesh.write"))

    def to_trimesh(self, **kwargs):
        """A trimesh.Trimesh (copies; quads split into triangles, keeping
        their winding). Needs trimesh (not in Debian 12: pip install trimesh)."""
        trimesh = _lazy_import("to_trimesh", "trimesh", "pip install trimesh; Debian 12 has no package")
        return trimesh.Trimesh(vertices=np.array(self.vertices), faces=np.array(self.triangles()),
                               vertex_normals=np.array(self.vertex_normals), process=False, **kwargs)

    def to_pyvista(self):
        """A pyvista.PolyData (copies) with the triangles, then the quads, as
        they are (adaptive quad meshes have both). Needs pyvista (not in
        Debian 12: pip install pyvista)."""
        pv = _lazy_import("to_pyvista", "pyvista", "pip install pyvista; Debian 12 has no package")
        cells = [np.hstack([np.full((len(f), 1), f.shape[1], dtype=np.int64), f.astype(np.int64)]).ravel()
                 for f in (self.faces, self.quads)]
        poly = pv.PolyData(np.array(self.vertices), np.concatenate(cells))
        poly.point_data["Normals"] = np.array(self.vertex_normals)
        return poly

    def to_open3d(self):
        """An open3d.geometry.TriangleMesh (copies; quads split into
        triangles, keeping their winding) with the vertex normals. Needs
        open3d (Debian 12: apt-get install python3-open3d)."""
        o3d = _lazy_import("to_open3d", "open3d", "apt-get install python3-open3d, or pip install open3d")
        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(self.vertices)),
                                      o3d.utility.Vector3iVector(np.array(self.triangles(), dtype=np.int32)))
        m.vertex_normals = o3d.utility.Vector3dVector(np.array(self.vertex_normals))
        return m

    def __repr__(self):
        return (f"pqdc.Mesh({len(self.vertices)} vertices, {len(self.faces)} triangles, "
                f"{len(self.quads)} quads)")


def _lazy_import(method, module, how):
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise ImportError(f"pqdc.Mesh.{method}() needs the '{module}' module, which is not installed "
                          f"({how}); mesh.write(path) saves a file any of them reads") from e
