"""pqdc.extract(): the one entry point for arrays, pyopenvdb grids and files."""

import numbers
import os

import numpy as np

from . import _pqdc
from ._errors import OptionError, double_precision, flag
from ._mesh import Mesh

#: The value of sigma_n that asks pqdc to choose it from the volume's
#: estimated noise (the default; C++ pqdc::sigma_n_auto).
SIGMA_N_AUTO = "auto"

_SOURCE_HELP = "pass a 3-D numpy array, a pyopenvdb FloatGrid or DoubleGrid, or the path of a .vdb file"


def _real(name, value):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"pqdc.extract: {name} must be a number, got {type(value).__name__}")
    return float(value)


def _string(name, value):
    if not isinstance(value, str):
        raise TypeError(f"pqdc.extract: {name} must be a string, got {type(value).__name__}")
    return value


def _flag(name, value):
    return flag(name, value, "pqdc.extract")


def _count(name, value, what, most=2**63 - 1):
    if value is None:
        return 0
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"pqdc.extract: {name} must be an integer or None, got {type(value).__name__}")
    if value < 1:
        raise OptionError(f"{name} must be at least 1 {what} (or None), got {value}")
    if value > most:  # beyond the C++ field: pybind11 would say only "incompatible function arguments"
        raise OptionError(f"{name} must be at most {most} {what}s (or None), got {value}")
    return int(value)


def _triple(name, value):
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return (float(value),) * 3
    try:
        items = tuple(value)
    except TypeError:
        raise TypeError(f"pqdc.extract: {name} must be a number or three numbers (x, y, z), "
                        f"got {type(value).__name__}") from None
    if len(items) != 3:
        raise OptionError(f"{name} must have three entries (x, y, z), got {len(items)}")
    return tuple(_real(f"{name}[{i}]", v) for i, v in enumerate(items))


def _request(isovalue, sigma_n, interior, faces, normals, denoise, containment, adaptive, max_error,
             max_cell_size, threads, progress, memory_limit):
    r = _pqdc.Request()
    r.isovalue = _real("isovalue", isovalue)
    if isinstance(sigma_n, str):
        if sigma_n != "auto":
            raise OptionError(f"sigma_n must be a number >= 0, inf or 'auto', got '{sigma_n}'")
        r.sigma_n = _pqdc.SIGMA_N_AUTO_VALUE
    else:
        r.sigma_n = _real("sigma_n", sigma_n)
        if not r.sigma_n >= 0:
            raise OptionError(f"sigma_n must be >= 0 (or inf for the mass point, or 'auto'), got {r.sigma_n}")
    r.interior = _string("interior", interior)
    r.faces = _string("faces", faces)
    r.normals = _string("normals", normals)
    r.denoise = _string("denoise", denoise)
    r.containment = _string("containment", containment)
    r.adaptive = _flag("adaptive", adaptive)
    r.max_error = _real("max_error", max_error)
    if isinstance(max_cell_size, bool) or not isinstance(max_cell_size, numbers.Integral):
        raise TypeError(f"pqdc.extract: max_cell_size must be an integer, got {type(max_cell_size).__name__}")
    if not -2**31 <= max_cell_size < 2**31:
        raise OptionError(f"max_cell_size must be a power of two in [1, 4096] voxels, got {max_cell_size}")
    r.max_cell_size = int(max_cell_size)
    r.threads = _count("threads", threads, "thread", 4096)
    r.memory_limit = _count("memory_limit", memory_limit, "byte")
    if progress is not None and not callable(progress):
        raise TypeError(f"pqdc.extract: progress must be callable or None, got {type(progress).__name__}")
    r.progress = progress
    return r


def _min_component(r, min_component):
    r.min_component = _real("min_component", min_component)
    if not r.min_component >= 0:
        raise OptionError(f"min_component is a size in voxels, >= 0 (0 keeps every component), "
                          f"got {r.min_component}")


def _bbox(r, bbox, caller):
    """r.bbox from the world-space box (xmin, ymin, zmin, xmax, ymax, zmax), or nothing for None."""
    if bbox is None:
        return
    try:
        items = tuple(bbox)
    except TypeError:
        raise TypeError(f"pqdc.{caller}: bbox must be six numbers, got {type(bbox).__name__}") from None
    if len(items) != 6:
        raise OptionError(f"bbox must be six numbers (xmin, ymin, zmin, xmax, ymax, zmax), got {len(items)}")
    r.bbox = [_real(f"bbox[{i}]", v) for i, v in enumerate(items)]


def extract(source, *, isovalue=0.0, sigma_n="auto", spacing=None, origin=None, axes="xyz",
            mask=None, invert_mask=False, interior="auto", faces="triangles", normals="auto", denoise="auto",
            containment="clamp", grid=None, adaptive=False, max_error=0.1, max_cell_size=64, threads=None,
            progress=None, memory_limit=None, sparse=True, bbox=None, min_component=0.0, precision="float"):
    """Mesh the isosurface ``value == isovalue`` of a volume by dual contouring.

    source
        * a 3-D numpy array of a float (16 to 64 bits), integer or bool dtype in
          native byte order (``a.astype(a.dtype.newbyteorder("="))`` converts
          one), C or F order or any strides. ``axes="xyz"`` (default): the first numpy axis is x, as in
          pyopenvdb's ``copyFromArray``; ``axes="zyx"``: an image stack
          ``volume[slice, row, column]``, i.e. the last axis is x. Values are
          stored as float32 when that is exact (float16/32, 8/16-bit integers,
          bool), else as float64.
        * a pyopenvdb ``FloatGrid`` (or DoubleGrid); the grid's transform places
          the mesh. Do not modify the grid while it is being meshed.
        * a path (str or os.PathLike) of a .vdb file; ``grid`` names the grid,
          default the file's first float or double grid.

    Options (defaults as in the ``pqdc`` CLI and the C++ ExtractOptions):

    isovalue
        The surface level, in the volume's value units. Default 0.
    sigma_n
        Normal noise of the probabilistic quadrics, a fraction of the unit
        normal in [0, inf]: 0 classical quadrics (sharpest, noisiest), inf the
        mass point (smoothest). ``"auto"`` (default): chosen from the volume's
        estimated noise (0.1 on clean data, 0.25 on noisy data; the estimate
        and the choice are in ``mesh.stats``).
    spacing, origin (arrays only)
        Voxel size and the position of voxel (0, 0, 0), both in world (x, y, z)
        order (also with ``axes="zyx"``); a single number means the same along
        every axis. Anisotropic voxels are meshed in index space and the
        vertices mapped; normals are mapped as covectors, so they stay
        perpendicular to the surface.
    mask, invert_mask
        Mesh only the cells whose minimum-corner voxel is in the mask (the
        CLI's ``--mask``; the mesh is open where the surface leaves the mask
        and equals the whole volume's mesh inside it):

        * a numpy array of the source array's shape (same axis order), bool or
          numeric (nonzero counts), for array sources;
        * a pyopenvdb grid (BoolGrid, FloatGrid...): its active voxels, or the
          inside (value < 0) of a level set, placed by its own transform in
          world space (arrays: after spacing and origin);
        * the path of a .vdb file, or ``(path, grid_name)``: that grid, as the
          CLI's ``--mask FILE.vdb:GRID`` (default the file's first bool, mask,
          float, double or int32 grid).

        ``invert_mask=True`` meshes where the mask does not hold instead (the
        two split the cells exactly; a face needs all four cells around its
        edge, so the one band of faces whose cells straddle the seam is in
        neither mesh).
    interior
        ``"auto"``: inside is below the isovalue for arrays (pass ``"above"``
        for density and CT arrays); grids and files follow the C++ rule: level
        sets below, fog volumes above, other grids the side their background
        (inactive) value is not on, then the side their active region's
        boundary is not on (``mesh.stats["interior_reason"]`` says which).
        ``"below"`` or ``"above"`` force a side.
    bbox
        ``(xmin, ymin, zmin, xmax, ymax, zmax)`` in world units (arrays: after
        spacing and origin): only cells whose centre lies in the box are
        meshed, so the mesh is open at the box and equals the whole volume's
        mesh inside it. Default None (everything).
    faces
        ``"triangles"`` (each quad split along its better diagonal) or ``"quads"``.
    normals, denoise, containment
        Hermite normals of grid crossings (``"auto"``, ``"central"``,
        ``"sharp"`` or ``"least_squares"``), denoising (``"auto"``: on when the
        estimated noise is at least 0.08 voxel, ``"on"``, ``"off"``) and vertex
        placement (``"clamp"`` to the cell or ``"unconstrained"``).
    adaptive, max_error, max_cell_size
        Octree dual marching cubes: merge cells while the collapse error stays
        below ``max_error`` voxels, up to ``max_cell_size`` voxels.
    threads
        Worker threads (None: all cores). The mesh is the same for any count.
        The limit is process-wide while the extraction runs.
    progress
        ``callable(fraction)`` called from the calling thread with the GIL held,
        between chunks of each stage (uniform: about 1/64 of it; adaptive: a
        fixed number of blocks, cells or leaves, tens of milliseconds on one
        thread); returning False cancels (``pqdc.CancelledError``); an
        exception it raises propagates unchanged. Ctrl-C (KeyboardInterrupt)
        cancels at the same points, with or without a callback.
    memory_limit
        Bytes the job may use (checked before allocating; ``pqdc.ResourceError``
        above it). None: 80% of physical memory.
    min_component
        Remove the mesh's components whose bounding-box diagonal is below this
        many voxels (the shortest voxel side; arrays: the shortest spacing),
        as the CLI's ``--min-component``. 3.5 removes the islands noise makes
        and keeps droplets of radius 1 voxel and more. Default 0 keeps
        everything. ``mesh.stats`` counts what went (``components_*``).
    precision
        ``"float"`` (default) or ``"double"``: how the mesh will be stored.
        The self-intersection repair makes the vertices rounded to it free
        of intersections, as the CLI's ``--precision`` does for its file, so
        ``mesh.write(path)`` (which stores at this precision by default)
        writes the CLI's bytes. With ``"float"`` the float64 ``vertices``
        themselves are not checked; pass ``"double"`` to use them as they are
        (e.g. in float64 geometry code). For arrays with ``spacing`` or
        ``origin`` the check is made in index space, before the vertices are
        placed.
    sparse (arrays only)
        True: only 8^3 blocks within 3 voxels of the isovalue are stored voxel
        by voxel. False stores every voxel (a reference: same mesh, more memory).

    Returns a :class:`pqdc.Mesh`. Faces are wound counter-clockwise seen from
    outside in the returned coordinates; ``mesh.vertex_normals`` point outside.
    The GIL is released while the volume is converted and meshed.
    """
    r = _request(isovalue, sigma_n, interior, faces, normals, denoise, containment, adaptive, max_error,
                 max_cell_size, threads, progress, memory_limit)
    _bbox(r, bbox, "extract")
    _min_component(r, min_component)
    r.double_precision = double_precision(precision)
    if source is None:
        raise TypeError(f"pqdc.extract: source is None; {_SOURCE_HELP}")
    if isinstance(source, np.ndarray):
        if grid is not None:
            raise OptionError("grid names a grid in a .vdb file; it does not apply to a numpy array")
        array_mask = _mask(r, mask, invert_mask)
        mesh = Mesh(_pqdc.extract_array(source, array_mask, _array_request(r, spacing, origin, axes, sparse)))
        if len(mesh.vertices) == 0 and mask is None and bbox is None and not min_component:
            # The sparse grid holds no voxels where nothing crosses: the
            # array itself says why.
            mesh = Mesh(mesh._data, [_explain_empty_array(source, isovalue, mesh.stats)])
        elif mask is None and bbox is None:
            open_crossings = mesh.stats.get("boundary_crossings", 0)
            if open_crossings:
                # The CLI's summary says "open where ..."; an array's caller
                # reads the warnings (an object cut by the array's border).
                mesh = Mesh(mesh._data, mesh.stats["warnings"] + [
                    f"the mesh is open where the surface reaches the array's border or NaN values "
                    f"({open_crossings} crossings lack a cell); pad the array, e.g. np.pad(a, 1, mode='edge'), "
                    f"for a closed mesh"])
        if interior == "auto" and len(mesh.vertices) and _border_below(source, isovalue):
            mesh = Mesh(mesh._data, mesh.stats["warnings"] + [
                f"the mesh is inside out: for arrays inside is below the isovalue (interior='auto'), and all "
                f"of the array's border lies below {isovalue:g}, so the mesh encloses the low values around "
                f"the object and its normals point into it; for a density or CT array pass interior='above'"])
        if len(mesh.vertices):
            extreme = _isovalue_at_extreme(source, isovalue, mesh.stats["interior"])
            if extreme:
                mesh = Mesh(mesh._data, mesh.stats["warnings"] + [extreme])
        return mesh
    array_only = {"spacing": spacing, "origin": origin}
    given = [k for k, v in array_only.items() if v is not None] + (["axes"] if axes != "xyz" else [])
    if given:
        raise OptionError(f"{', '.join(given)} only apply to numpy arrays; a grid or .vdb file carries "
                          f"its own transform")
    if isinstance(mask, np.ndarray):
        raise OptionError("a numpy mask has no placement, so it applies to numpy array sources only; "
                          "for a grid or .vdb file pass the mask as a pyopenvdb grid or (path, grid name)")
    _mask(r, mask, invert_mask)
    if isinstance(source, (str, bytes, os.PathLike)):
        path = os.fsdecode(os.fspath(source))
        if grid is not None and not isinstance(grid, str):
            raise TypeError(f"pqdc.extract: grid must be a grid name (str), got {type(grid).__name__}")
        return Mesh(_pqdc.extract_file(path, grid or "", r))
    if grid is not None:
        raise OptionError("grid names a grid in a .vdb file; it does not apply to a grid object")
    data = _pqdc.extract_grid(source, r)
    if data is None:
        raise TypeError(f"pqdc.extract: cannot mesh a {type(source).__module__}.{type(source).__name__}; "
                        f"{_SOURCE_HELP}")
    return Mesh(data)


def _border_below(array, isovalue):
    """Whether every value on the array's six faces that is not NaN lies
    below the isovalue (and there is one): a density or CT array meshed
    with inside below."""
    if array.ndim != 3 or array.size == 0:
        return False
    found = False
    for face in (array[0], array[-1], array[:, 0], array[:, -1], array[:, :, 0], array[:, :, -1]):
        values = np.asarray(face, dtype=np.float64)
        values = values[~np.isnan(values)]
        if values.size:
            if values.max() >= isovalue:
                return False
            found = True
    return found


def _isovalue_at_extreme(array, isovalue, inside):
    """A warning when the isovalue is the array's value at the far end from
    the inside (its smallest with inside above, its largest with inside
    below), else None. The voxels at that value then lie on the surface:
    a 0/1 mask at isovalue 0 with interior='above' is meshed through the 0
    voxels next to the object, half a voxel outside the level between the
    two values. One pass over the array, small beside the meshing."""
    if array.size == 0 or inside not in ("above", "below"):
        return None
    values = np.asarray(array)
    lo = float(np.fmin.reduce(values, axis=None))  # fmin/fmax skip NaN
    hi = float(np.fmax.reduce(values, axis=None))
    at = lo if inside == "above" else hi
    if isovalue != at or not lo < hi:
        return None
    which = "smallest" if inside == "above" else "largest"
    return (f"the isovalue {isovalue:g} is the array's {which} value and the inside is {inside} it, so the surface "
            f"runs through the voxels at exactly {isovalue:g} next to the object, half a voxel outside the level "
            f"between two values; for a mask or label volume choose a level between two of its values, e.g. "
            f"isovalue={0.5 * (lo + hi):g}")


def _explain_empty_array(array, isovalue, stats):
    """Why an array gave no surface: crossings without the cells a face
    needs, else its value range against the isovalue."""
    crossings = stats.get("crossing_edges", 0)
    if crossings and stats.get("boundary_crossings", 0) == crossings:
        return (f"no surface in the array: the isovalue {isovalue:g} is crossed on {crossings} lattice edges, but "
                f"each lies on the array's border or next to NaN values, where a face lacks the cells beyond "
                f"(a face needs the four cells around its edge); pad the array, e.g. np.pad(a, 1, mode='edge'); "
                f"the mesh is empty")
    values = array[np.isfinite(array)] if array.dtype.kind == "f" else array
    if values.size == 0:
        return "no surface in the array: all its values are NaN or infinite; the mesh is empty"
    lo, hi = float(values.min()), float(values.max())
    if lo == hi:
        return (f"no surface in the array: every value is {lo:g}, so no isovalue crosses it; the mesh is "
                f"empty")
    if isovalue < lo or isovalue > hi:
        return (f"no surface in the array: its values lie in [{lo:g}, {hi:g}] and the isovalue {isovalue:g} is "
                f"outside that range; choose an isovalue inside it (the mesh is empty)")
    text = (f"no surface in the array: its values [{lo:g}, {hi:g}] never change sign across the isovalue "
            f"{isovalue:g} between neighbouring voxels")
    if isovalue in (lo, hi):  # a mask or label volume at one of its values
        text += (f"; the isovalue is the {'smallest' if isovalue == lo else 'largest'} value, so no voxel lies "
                 f"beyond it: for a mask or label volume choose a level between two of its values, e.g. "
                 f"isovalue={(lo + hi) / 2 if lo < hi else lo:g}")
    return text + "; the mesh is empty"


def _mask(r, mask, invert_mask):
    """Puts a grid or file mask into the request; returns a numpy mask as bool (or None)."""
    invert_mask = _flag("invert_mask", invert_mask)
    r.invert_mask = invert_mask
    if mask is None:
        if invert_mask:
            raise OptionError("invert_mask=True inverts a mask: pass mask= too")
        return None
    if isinstance(mask, np.ndarray):
        if mask.dtype.kind not in "biuf":
            raise TypeError(f"pqdc.extract: a numpy mask must be bool or numeric (nonzero counts), "
                            f"got dtype {mask.dtype}")
        return mask if mask.dtype == np.bool_ else mask != 0
    if isinstance(mask, (str, bytes, os.PathLike)):
        r.mask_path = os.fsdecode(os.fspath(mask))
    elif isinstance(mask, tuple):
        if len(mask) != 2 or not isinstance(mask[0], (str, bytes, os.PathLike)) or not isinstance(mask[1], str):
            raise TypeError("pqdc.extract: a file mask is a path or (path, grid name), got a tuple of "
                            + ", ".join(type(m).__name__ for m in mask))
        r.mask_path, r.mask_grid_name = os.fsdecode(os.fspath(mask[0])), mask[1]
    else:
        r.mask_grid = mask  # a pyopenvdb grid; anything else is a TypeError from the C++ side
    return None


def _array_request(r, spacing, origin, axes, sparse):
    if axes not in ("xyz", "zyx"):
        raise OptionError(f"axes must be 'xyz' (first numpy axis is x) or 'zyx' (image stacks), got {axes!r}")
    r.zyx = axes == "zyx"
    r.spacing = _triple("spacing", 1.0 if spacing is None else spacing)
    r.origin = _triple("origin", 0.0 if origin is None else origin)
    r.sparse = _flag("sparse", sparse)
    return r


def extract_to_file(source, path, *, grid=None, isovalue=0.0, sigma_n="auto", interior="auto", bbox=None,
                    mask=None, invert_mask=False, faces="triangles", normals="auto", denoise="auto",
                    containment="clamp", threads=None, progress=None, memory_limit=None, brick_size=256,
                    brick_runs=None, precision="float", min_component=0.0):
    """Mesh a .vdb file or a brick store brick by brick and stream the mesh
    into ``path``: for volumes, and meshes, larger than memory.

    The file holds the bytes ``pqdc SOURCE -o PATH --out-of-core`` writes
    with the same options, and the bytes ``extract(SOURCE, ...).write(PATH)``
    writes at float precision: the output depends on neither brick_size nor
    brick_runs. Memory holds the volume's topology (for a brick store made by
    ``pqdc-bricks split``, only its candidate list and a cache of its files),
    the bricks in flight and a bit per output vertex; the mesh waits in
    scratch files next to ``path`` (about 40 bytes per vertex) and is never
    whole in memory. Uniform mode only (adaptive mode is not streamed).

    source
        The path of a .vdb file (``grid`` names the grid, default the file's
        first float or double grid) or of a brick store directory.
    path
        The output: .obj, .ply, .off or .stl, written atomically.
    isovalue, sigma_n, interior, bbox, mask, invert_mask, faces, normals, denoise, containment,
    threads, progress, memory_limit, min_component
        As for :func:`extract` (``mask`` as a pyopenvdb grid, a .vdb path or
        (path, grid name)).
    brick_size
        Voxels per brick: a power of two from 128 to 4096. Larger bricks hold
        more memory and repeat less work at their edges.
    brick_runs
        Runs of bricks meshed at once, each on its own thread (None: the
        threads available, at most 4, fewer when memory is short).
    precision
        ``"float"`` (default) or ``"double"``: the vertices' precision in PLY,
        OBJ and OFF (STL is always float).

    Returns the run's statistics, the dict ``Mesh.stats`` gives, with the
    counts written (``points_written``, ``triangles_written``,
    ``quads_written``).
    """
    r = _request(isovalue, sigma_n, interior, faces, normals, denoise, containment, False, 0.1, 64, threads,
                 progress, memory_limit)
    _bbox(r, bbox, "extract_to_file")
    _min_component(r, min_component)
    if not isinstance(source, (str, bytes, os.PathLike)):
        raise TypeError(f"pqdc.extract_to_file: source must be the path of a .vdb file or a brick store, got "
                        f"{type(source).__name__} (mesh arrays and grid objects with pqdc.extract)")
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise TypeError(f"pqdc.extract_to_file: path must be the output file's path, got {type(path).__name__}")
    if grid is not None and not isinstance(grid, str):
        raise TypeError(f"pqdc.extract_to_file: grid must be a grid name (str), got {type(grid).__name__}")
    if isinstance(mask, np.ndarray):
        raise OptionError("a numpy mask has no placement; for a file pass the mask as a pyopenvdb grid or "
                          "(path, grid name)")
    _mask(r, mask, invert_mask)
    if isinstance(brick_size, bool) or not isinstance(brick_size, numbers.Integral):
        raise TypeError(f"pqdc.extract_to_file: brick_size must be an integer, got {type(brick_size).__name__}")
    r.double_precision = double_precision(precision)  # the file's too
    s = _pqdc.StreamRequest()
    s.output = os.fsdecode(os.fspath(path))
    s.brick_size = int(brick_size)
    s.brick_runs = _count("brick_runs", brick_runs, "run", most=64)
    return Mesh(_pqdc.extract_file_to(os.fsdecode(os.fspath(source)), grid or "", r, s)).stats


def split_to_store(source, store, *, grid=None, brick_size=256, progress=None):
    """Write a .vdb file's grid as a brick store: one small .vdb file per
    brick plus an index, in the new directory ``store`` (what ``pqdc-bricks
    split`` writes). The source is read one brick at a time. Mesh the store
    with :func:`extract_to_file`; it gives the source's bytes.

    ``progress``: None or ``callable(fraction)``, called between bricks;
    returning False stops the split with :class:`pqdc.CancelledError`, as Ctrl-C
    does with KeyboardInterrupt. Either way the files written so far are
    removed (and ``store`` itself, if the split made it).

    Returns ``{"bricks": files written, "leaves": leaf nodes in them}``.
    """
    for name, value in (("source", source), ("store", store)):
        if not isinstance(value, (str, bytes, os.PathLike)):
            raise TypeError(f"pqdc.split_to_store: {name} must be a path, got {type(value).__name__}")
    if grid is not None and not isinstance(grid, str):
        raise TypeError(f"pqdc.split_to_store: grid must be a grid name (str), got {type(grid).__name__}")
    if isinstance(brick_size, bool) or not isinstance(brick_size, numbers.Integral):
        raise TypeError(f"pqdc.split_to_store: brick_size must be an integer, got {type(brick_size).__name__}")
    if progress is not None and not callable(progress):
        raise TypeError(f"pqdc.split_to_store: progress must be callable or None, got {type(progress).__name__}")
    bricks, leaves = _pqdc.split_file(os.fsdecode(os.fspath(source)), grid or "", os.fsdecode(os.fspath(store)),
                                      int(brick_size), progress)
    return {"bricks": bricks, "leaves": leaves}
