"""pqdc: isosurfaces of numpy volumes, pyopenvdb grids and .vdb files by dual
contouring with probabilistic plane quadrics.

    import numpy as np, pqdc
    mesh = pqdc.extract(volume, isovalue=300, interior="above", spacing=(0.7, 0.7, 2.5))
    mesh.vertices, mesh.faces, mesh.vertex_normals   # numpy views of the C++ mesh
    mesh.write("bone.ply")

See pqdc.extract() for the options and pqdc.skimage.marching_cubes() for a
drop-in replacement of skimage.measure.marching_cubes. Volumes or meshes
larger than memory: pqdc.extract_to_file("big.vdb", "big.ply") meshes brick
by brick and streams the mesh into the file (also for pqdc-bricks stores).
Fewer triangles at bounded error: mesh.decimate(target_ratio=0.1), also for
files: pqdc.read_mesh("scan.ply").decimate(target_ratio=0.1).write("out.ply").
"""

from ._errors import (CancelledError, Error, InputError, OptionError,
                      ResourceError, WriteError)
from ._mesh import Mesh, read_mesh
from ._api import SIGMA_N_AUTO, extract, extract_to_file, split_to_store
from ._decimate import decimate
from . import skimage  # pqdc.skimage.marching_cubes without a separate import
from ._pqdc import __version__  # the library's version (the top CMakeLists.txt's project())

__all__ = ["extract", "extract_to_file", "decimate", "read_mesh", "split_to_store", "Mesh", "SIGMA_N_AUTO", "Error", "OptionError", "InputError",
           "WriteError", "ResourceError", "CancelledError"]
