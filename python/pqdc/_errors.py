"""Exceptions raised by pqdc (the C++ library's error kinds, as Python classes).

Each also derives from the built-in exception a caller would naturally catch:
option and input problems are ValueErrors, a failed write is an OSError, a job
that would not fit in memory is a MemoryError. Wrong argument types raise the
built-in TypeError (flag() is the check shared by every True/False option).
"""

import numpy as np


class Error(Exception):
    """Base class of every error pqdc raises on purpose."""


class OptionError(Error, ValueError):
    """An option value is out of range or options conflict."""


class InputError(Error, ValueError):
    """The source cannot be meshed: a missing or unreadable file, an unknown
    grid name, a vector grid, an array that is not 3-D..."""


class WriteError(Error, OSError):
    """Writing a mesh file failed (permissions, missing directory, disk full)."""


class ResourceError(Error, MemoryError):
    """The job would need more memory than allowed (raised before allocating)."""


class CancelledError(Error):
    """The progress callback returned False."""


def double_precision(precision):
    """True for "double", False for "float" (the precision a mesh is checked
    and stored at); pqdc.OptionError otherwise."""
    if precision not in ("float", "double"):
        raise OptionError(f"precision must be 'float' or 'double', got {precision!r}")
    return precision == "double"


def flag(name, value, where):
    """A True/False option, numpy.bool_ too; a string such as "no" is refused
    (TypeError from `where`), not taken as true."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{where}: {name} must be True or False, got {type(value).__name__}")
    return bool(value)
