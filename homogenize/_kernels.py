"""Every numba kernel of ``homogenize``, and nothing else.

Rules (STYLE.md): contiguous arrays in, caller-allocated output, no defaults, short;
``cache=True``; no ``fastmath``. Each kernel has a test against a plain-numpy/scipy reference on a
small input (tests/homogenize/test_kernels.py). Python wrappers (in _assembly.py, cell.py) check
shapes and allocate.

Determinism: every parallel loop writes disjoint outputs and each output is a sequential sum in a
fixed order, so results do not depend on the number of threads.

Each kernel is written once as a plain function and compiled twice: ``name`` (parallel over
``prange``) and ``name_serial`` (``prange`` runs as ``range``). Launching a parallel region costs
tens of microseconds -- far more on a loaded machine, where a thread may wait for a time slice --
so wrappers use the parallel variant only for large loops (:data:`PARALLEL_MIN_ROWS`).
"""
from __future__ import annotations

import types

import numba as nb
import numpy as np

PARALLEL_MIN_ROWS = 50_000


def _both(f):
    """Compile ``f`` as a parallel and a serial kernel (same source).

    The serial one is compiled from a renamed copy of the function: numba's on-disk cache is keyed
    by the function's qualified name, not by the ``parallel`` flag, so the two variants would
    otherwise load each other's machine code.
    """
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__,
                           f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    return nb.njit(cache=True, parallel=True)(f), nb.njit(cache=True)(g)


def _bsr_matvec(indptr, indices, data, x, y):
    """y = A x for a block-sparse row matrix: data (nnzb, R, C), x (ncolblocks, C), y (nrowblocks, R).

    Parallel over block rows (disjoint writes); scipy's bsr_matvec is single-threaded.
    """
    nb_rows = indptr.shape[0] - 1
    R = data.shape[1]
    C = data.shape[2]
    for p in nb.prange(nb_rows):
        for r in range(R):
            y[p, r] = 0.0
        for s in range(indptr[p], indptr[p + 1]):
            q = indices[s]
            for r in range(R):
                acc = 0.0
                for c in range(C):
                    acc += data[s, r, c] * x[q, c]
                y[p, r] += acc


def _bsr_residual(indptr, indices, data, x, b, out):
    """out = b - A x (same layout as :func:`bsr_matvec`)."""
    nb_rows = indptr.shape[0] - 1
    R = data.shape[1]
    C = data.shape[2]
    for p in nb.prange(nb_rows):
        for r in range(R):
            out[p, r] = b[p, r]
        for s in range(indptr[p], indptr[p + 1]):
            q = indices[s]
            for r in range(R):
                acc = 0.0
                for c in range(C):
                    acc += data[s, r, c] * x[q, c]
                out[p, r] -= acc


def _bsr3_gauss_seidel_color(indptr, indices, data, dinv, rows, x, b):
    """One block Gauss-Seidel update of the block rows ``rows`` (3 x 3 blocks), in place in x.

    ``dinv`` (nrows, 3, 3) holds the inverse diagonal blocks. The rows of one colour must not be
    coupled to each other, so they are updated in parallel exactly as a sequential sweep would.
    """
    for t in nb.prange(rows.shape[0]):
        p = rows[t]
        r0 = b[p, 0]
        r1 = b[p, 1]
        r2 = b[p, 2]
        for s in range(indptr[p], indptr[p + 1]):
            q = indices[s]
            if q != p:
                r0 -= data[s, 0, 0] * x[q, 0] + data[s, 0, 1] * x[q, 1] + data[s, 0, 2] * x[q, 2]
                r1 -= data[s, 1, 0] * x[q, 0] + data[s, 1, 1] * x[q, 1] + data[s, 1, 2] * x[q, 2]
                r2 -= data[s, 2, 0] * x[q, 0] + data[s, 2, 1] * x[q, 1] + data[s, 2, 2] * x[q, 2]
        x[p, 0] = dinv[p, 0, 0] * r0 + dinv[p, 0, 1] * r1 + dinv[p, 0, 2] * r2
        x[p, 1] = dinv[p, 1, 0] * r0 + dinv[p, 1, 1] * r1 + dinv[p, 1, 2] * r2
        x[p, 2] = dinv[p, 2, 0] * r0 + dinv[p, 2, 1] * r1 + dinv[p, 2, 2] * r2


def _voxel_stencil_blocks(n, lam, mu, tab, Gl, Gm, indices, data):
    """Rows of the periodic voxel stiffness matrix in sorted BSR order.

    lam, mu (n^3,) per voxel (flat index i + n (j + n k)); tab (8, 27) neighbour corner of corner
    a at offset slot s (-1: outside); Gl, Gm (8, 27, 3, 3) element blocks K[a, a + d] for unit
    lambda / mu. Writes indices (27 n^3,) and data (27 n^3, 3, 3).
    Block of node p at offset slot s = sum_a lam(voxel with corner a at p) Gl[a, s] + mu Gm[a, s].
    """
    N = n * n * n
    for p in nb.prange(N):
        i = p % n
        j = (p // n) % n
        k = p // (n * n)
        cols = np.empty(27, dtype=np.int64)
        for s in range(27):
            dx = s % 3 - 1
            dy = (s // 3) % 3 - 1
            dz = s // 9 - 1
            cols[s] = (i + dx) % n + n * (((j + dy) % n) + n * ((k + dz) % n))
        order = np.argsort(cols)
        for r in range(27):
            s = order[r]
            out = 27 * p + r
            indices[out] = cols[s]
            for c in range(9):
                data[out, c // 3, c % 3] = 0.0
            for a in range(8):
                if tab[a, s] >= 0:
                    ax = a & 1
                    ay = (a >> 1) & 1
                    az = (a >> 2) & 1
                    v = (i - ax) % n + n * (((j - ay) % n) + n * ((k - az) % n))
                    la = lam[v]
                    ma = mu[v]
                    for c in range(9):
                        data[out, c // 3, c % 3] += la * Gl[a, s, c // 3, c % 3] + \
                            ma * Gm[a, s, c // 3, c % 3]


bsr_matvec, bsr_matvec_serial = _both(_bsr_matvec)
bsr_residual, bsr_residual_serial = _both(_bsr_residual)
bsr3_gauss_seidel_color, bsr3_gauss_seidel_color_serial = _both(_bsr3_gauss_seidel_color)
voxel_stencil_blocks, voxel_stencil_blocks_serial = _both(_voxel_stencil_blocks)
