"""The one helper that compiles a numba kernel as a parallel and a serial variant, and the one
that keeps BLAS on one thread while numba's kernels use the cores."""
from __future__ import annotations

import functools
import threading
import types

import numba as nb
from threadpoolctl import threadpool_limits

__all__ = ["parallel_and_serial", "one_blas_thread"]


def one_blas_thread(f):
    """Run ``f`` with BLAS/LAPACK limited to one thread (restored after): for solvers whose
    parallel work is in numba kernels and whose BLAS calls are small. OpenBLAS's threads keep
    spinning for a while after each call and take a core from numba's: the PME dipole solve at
    N = 1e5 on 2 numba threads took 23-25 s with them, 21-23 s without; the cell solve's
    V-cycle 1.63x over one thread with them, 1.89x without (results/bench/threads.md).

    Only in the main thread: the limit is process-wide, so two threads (Dask's threaded workers)
    would set and restore it under each other, and the BLAS thread count a solve sees -- which
    can change the last bits of a multithreaded LAPACK result -- would depend on their timing
    (a table of two threaded workers then differed from one worker's:
    tests/homogenize/test_relax_batch.py). Other threads leave BLAS as it is."""
    @functools.wraps(f)
    def run(*args, **kwargs):
        if threading.current_thread() is not threading.main_thread():
            return f(*args, **kwargs)
        with threadpool_limits(limits=1, user_api="blas"):
            return f(*args, **kwargs)
    return run


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
