"""The one helper that compiles a numba kernel as a parallel and a serial variant."""
from __future__ import annotations

import types

import numba as nb

__all__ = ["parallel_and_serial"]


def parallel_and_serial(f):
    """Compile ``f`` twice from the same source: ``(parallel, serial)`` (``prange`` runs as
    ``range`` in the serial one).

    The serial variant is compiled from a renamed copy (``<name>_serial``): numba's on-disk cache
    is keyed by the function's qualified name, not by the ``parallel`` flag, so two variants of
    one name would load each other's machine code (a cached serial build made the "parallel"
    direct dipole kernel run on one thread).
    """
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__,
                           f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    return nb.njit(cache=True, parallel=True)(f), nb.njit(cache=True)(g)
