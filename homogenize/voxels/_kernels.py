"""Every numba kernel of ``homogenize``, and nothing else.

Rules (STYLE.md): contiguous arrays in, caller-allocated output, no defaults, short;
``cache=True``; no ``fastmath``. Each kernel has a test against a plain-numpy/scipy reference on a
small input (tests/homogenize/test_fem_kernels.py). Python wrappers (in _assembly.py, cell.py) check
shapes and allocate.

Determinism: every parallel loop writes disjoint outputs and each output is a sequential sum in a
fixed order, so results do not depend on the number of threads.

Each kernel is written once as a plain function and compiled twice: ``name`` (parallel over
``prange``) and ``name_serial`` (``prange`` runs as ``range``). Launching a parallel region costs
tens of microseconds -- far more on a loaded machine, where a thread may wait for a time slice --
so wrappers use the parallel variant only for large loops (:data:`PARALLEL_MIN_ROWS`).
"""
from __future__ import annotations


import numba as nb
import numpy as np

from micro.common.jit import parallel_and_serial

PARALLEL_MIN_ROWS = 50_000


@nb.njit(cache=True, inline="always")
def _block_acc(M, r0, c0, R, C, x, q, y, p, k, sign, tr):
    """y[p, r, m] += sign * sum_c A[r, c] x[q, c, m] for the R x C block A of the 2-D matrix M at
    (r0, c0) (``tr`` False: A[r, c] = M[r0 + r, c0 + c]) or of its transpose (``tr`` True:
    A[r, c] = M[r0 + c, c0 + r], read in place, no transposed copy), and the k columns m. 3x3
    blocks (the voxel grid's) are read once into scalars (measured 1.3-1.5x over one loop per
    matrix entry); other block sizes (the 6-mode aggregates of smoothed aggregation) read each
    entry once and apply it to all k columns (the column loop innermost), except for one column,
    where a scalar sum per row is faster (both measured on random 3x6, 6x6 and 6x3 block
    products at k = 7 and k = 1, session 8)."""
    if R == 3 and C == 3:
        if tr:
            a00, a01, a02 = sign * M[r0, c0], sign * M[r0 + 1, c0], sign * M[r0 + 2, c0]
            a10, a11, a12 = sign * M[r0, c0 + 1], sign * M[r0 + 1, c0 + 1], sign * M[r0 + 2, c0 + 1]
            a20, a21, a22 = sign * M[r0, c0 + 2], sign * M[r0 + 1, c0 + 2], sign * M[r0 + 2, c0 + 2]
        else:
            a00, a01, a02 = sign * M[r0, c0], sign * M[r0, c0 + 1], sign * M[r0, c0 + 2]
            a10, a11, a12 = sign * M[r0 + 1, c0], sign * M[r0 + 1, c0 + 1], sign * M[r0 + 1, c0 + 2]
            a20, a21, a22 = sign * M[r0 + 2, c0], sign * M[r0 + 2, c0 + 1], sign * M[r0 + 2, c0 + 2]
        for m in range(k):
            x0 = x[q, 0, m]
            x1 = x[q, 1, m]
            x2 = x[q, 2, m]
            y[p, 0, m] += a00 * x0 + a01 * x1 + a02 * x2
            y[p, 1, m] += a10 * x0 + a11 * x1 + a12 * x2
            y[p, 2, m] += a20 * x0 + a21 * x1 + a22 * x2
    elif k == 1:
        for r in range(R):
            acc = 0.0
            for c in range(C):
                acc += (M[r0 + c, c0 + r] if tr else M[r0 + r, c0 + c]) * x[q, c, 0]
            y[p, r, 0] += sign * acc
    else:
        for r in range(R):
            for c in range(C):
                a = sign * (M[r0 + c, c0 + r] if tr else M[r0 + r, c0 + c])
                for m in range(k):
                    y[p, r, m] += a * x[q, c, m]


@nb.njit(cache=True, inline="always")
def block_acc(M, r0, c0, R, C, x, q, y, p, k, sign):
    """The block product of :func:`_block_acc` with the block as stored (the one block product
    of the BSR kernels here and of the matrix-free operator, homogenize.solvers._matfree)."""
    _block_acc(M, r0, c0, R, C, x, q, y, p, k, sign, False)


def _bsr_matmat(indptr, indices, data, x, y):
    """y = A x for a block-sparse row matrix and k right-hand sides at once.

    data (nnzb, R, C); x (ncolblocks, C, k); y (nrowblocks, R, k). Each matrix block is read once
    for all k columns (k columns cost far less than k products).
    Parallel over block rows (disjoint writes); scipy's BSR product runs on one core.
    """
    nb_rows = indptr.shape[0] - 1
    R = data.shape[1]
    C = data.shape[2]
    k = x.shape[2]
    for p in nb.prange(nb_rows):
        for r in range(R):
            for m in range(k):
                y[p, r, m] = 0.0
        for s in range(indptr[p], indptr[p + 1]):
            block_acc(data[s], 0, 0, R, C, x, indices[s], y, p, k, 1.0)


def _bsr_transposed_matmat(indptr, indices, perm, data, x, y):
    """y = A^T x for the BSR matrix A of blocks ``data`` (nnzb, C, R) without a transposed copy
    of its blocks: (indptr, indices) is the sorted BSR pattern of A^T and ``perm[s]`` the block
    of A that is block s of A^T (read transposed). The same sums in the same order as
    :func:`bsr_matmat` on the explicitly transposed matrix. x (ncolblocks, C, k); y
    (nrowblocks, R, k) with R, C the block shape of A^T."""
    nb_rows = indptr.shape[0] - 1
    R = data.shape[2]
    C = data.shape[1]
    k = x.shape[2]
    for p in nb.prange(nb_rows):
        for r in range(R):
            for m in range(k):
                y[p, r, m] = 0.0
        for s in range(indptr[p], indptr[p + 1]):
            # the stored block read transposed in place (no transposed copy of A)
            _block_acc(data[perm[s]], 0, 0, R, C, x, indices[s], y, p, k, 1.0, True)


def _bsr_residual(indptr, indices, data, x, b, out):
    """out = b - A x (same layout as :func:`bsr_matmat`)."""
    nb_rows = indptr.shape[0] - 1
    R = data.shape[1]
    C = data.shape[2]
    k = x.shape[2]
    for p in nb.prange(nb_rows):
        for r in range(R):
            for m in range(k):
                out[p, r, m] = b[p, r, m]
        for s in range(indptr[p], indptr[p + 1]):
            block_acc(data[s], 0, 0, R, C, x, indices[s], out, p, k, -1.0)


def _bsr_gauss_seidel_colour(indptr, indices, data, dinv, rows, x, b, tmp):
    """One block Gauss-Seidel update of the block rows ``rows``, in place in x (k columns).

    ``dinv`` (nrows, R, R) holds the inverse diagonal blocks; ``tmp`` (nrows, R, k) is scratch
    (row p writes only tmp[p]). The rows of one colour must not be coupled to each other, so they
    are updated in parallel exactly as a sequential sweep in any order would.
    """
    R = data.shape[1]
    k = x.shape[2]
    for t in nb.prange(rows.shape[0]):
        p = rows[t]
        for r in range(R):
            for m in range(k):
                tmp[p, r, m] = b[p, r, m]
        for s in range(indptr[p], indptr[p + 1]):
            q = indices[s]
            if q != p:
                block_acc(data[s], 0, 0, R, R, x, q, tmp, p, k, -1.0)
        for r in range(R):
            for m in range(k):
                acc = 0.0
                for c in range(R):
                    acc += dinv[p, r, c] * tmp[p, c, m]
                x[p, r, m] = acc


def _greedy_colouring(indptr, indices, colour, mark):
    """Greedy colouring of the block graph: rows in order, each the smallest colour none of its
    coupled rows has. ``colour`` (nrows,) out; ``mark`` (nrows + 1,) scratch, filled with -1."""
    n = indptr.shape[0] - 1
    for p in range(n):
        for s in range(indptr[p], indptr[p + 1]):
            q = indices[s]
            if q < p:
                mark[colour[q]] = p
        c = 0
        while mark[c] == p:
            c += 1
        colour[p] = c


def _typed_stencil_blocks(n, rows, etype, Ktab, tab, axis_order, indices, data):
    """Block rows ``rows`` (int64) of the periodic stiffness of an element-type field in sorted
    27-block BSR order; row t of the output is node rows[t].

    etype (n^3,) int32: every voxel's index into Ktab (T, 24, 24) (flat voxel index
    i + n (j + n k), DOF 3 a + c of corner a = ax + 2 ay + 4 az); tab (8, 27) neighbour corner of
    corner a at offset slot s = (dx+1) + 3 (dy+1) + 9 (dz+1) (-1: outside the voxel); axis_order
    (3, 3): the offsets (-1, 0, 1) of one axis in increasing order of the wrapped neighbour index,
    row 0 for coordinate 0, row 1 inside, row 2 for coordinate n - 1 (z-major flat indices then
    sort as z, y, x: no per-row sort needed). Writes indices (27 len(rows),) and data
    (27 len(rows), 3, 3). Block of node p at slot s = sum_a Ktab[type of the voxel with corner a
    at p][3 a:, 3 tab[a, s]:]. Serves the assembled solver (one type per (lambda, mu) pair,
    homogenize.voxels._assembly.assemble_bsr) and the matrix-free levels' assembled rows
    (homogenize.solvers._matfree.typed_rows_bsr).
    """
    for t in nb.prange(rows.shape[0]):
        p = rows[t]
        i = p % n
        j = (p // n) % n
        k = p // (n * n)
        ri = 0 if i == 0 else (2 if i == n - 1 else 1)
        rj = 0 if j == 0 else (2 if j == n - 1 else 1)
        rk = 0 if k == 0 else (2 if k == n - 1 else 1)
        out = 27 * t
        for oz in range(3):
            dz = axis_order[rk, oz]
            for oy in range(3):
                dy = axis_order[rj, oy]
                for ox in range(3):
                    dx = axis_order[ri, ox]
                    s = (dx + 1) + 3 * (dy + 1) + 9 * (dz + 1)
                    indices[out] = (i + dx + n) % n + n * (((j + dy + n) % n)
                                                           + n * ((k + dz + n) % n))
                    for r in range(3):
                        for c in range(3):
                            data[out, r, c] = 0.0
                    for a in range(8):
                        bb = tab[a, s]
                        if bb >= 0:
                            ax = a & 1
                            ay = (a >> 1) & 1
                            az = (a >> 2) & 1
                            v = (i - ax + n) % n + n * (((j - ay + n) % n) + n * ((k - az + n) % n))
                            e = etype[v]
                            for r in range(3):
                                for c in range(3):
                                    data[out, r, c] += Ktab[e, 3 * a + r, 3 * bb + c]
                    out += 1


def _axpy_cols(X, P, alpha):
    """X[:, j] += alpha[j] P[:, j], in place (X, P (n, k) C-contiguous)."""
    n, k = X.shape
    for i in nb.prange(n):
        for j in range(k):
            X[i, j] += alpha[j] * P[i, j]


def _xpby_cols(P, Z, beta):
    """P[:, j] = Z[:, j] + beta[j] P[:, j], in place."""
    n, k = P.shape
    for i in nb.prange(n):
        for j in range(k):
            P[i, j] = Z[i, j] + beta[j] * P[i, j]


def _coldot(A, B, out):
    """out[j] = sum_i A[i, j] B[i, j] (sequential sum per column: deterministic)."""
    n, k = A.shape
    for j in range(k):
        out[j] = 0.0
    for i in range(n):
        for j in range(k):
            out[j] += A[i, j] * B[i, j]


# coupled block CG (homogenize.solvers.coupled_block_cg): (n, k) blocks, k x k coefficients. The
# reductions sum each chunk of ``chunk`` rows sequentially into its own slot; the caller adds the
# slots in order, so the result does not depend on the number of threads.

def _gram_parts(A, B, chunk, out):
    """out[c, i, j] = sum over the rows r of chunk c (rows c chunk .. (c + 1) chunk - 1) of
    A[r, i] B[r, j]; out (ceil(n / chunk), ka, kb)."""
    n, ka = A.shape
    kb = B.shape[1]
    for c in nb.prange(out.shape[0]):
        for i in range(ka):
            for j in range(kb):
                out[c, i, j] = 0.0
        for r in range(c * chunk, min(n, (c + 1) * chunk)):
            for i in range(ka):
                a = A[r, i]
                for j in range(kb):
                    out[c, i, j] += a * B[r, j]


def _colsq_parts(A, chunk, out):
    """out[c, j] = sum over the rows r of chunk c of A[r, j]^2; out (ceil(n / chunk), k)."""
    n, k = A.shape
    for c in nb.prange(out.shape[0]):
        for j in range(k):
            out[c, j] = 0.0
        for r in range(c * chunk, min(n, (c + 1) * chunk)):
            for j in range(k):
                out[c, j] += A[r, j] * A[r, j]


def _block_step(X, R, P, Q, alpha):
    """X += P alpha, R -= Q alpha, in place (X, R (n, ka); P, Q (n, kp); alpha (kp, ka))."""
    n, kp = P.shape
    ka = X.shape[1]
    for r in nb.prange(n):
        for j in range(ka):
            sx = 0.0
            sr = 0.0
            for i in range(kp):
                sx += P[r, i] * alpha[i, j]
                sr += Q[r, i] * alpha[i, j]
            X[r, j] += sx
            R[r, j] -= sr


def _block_directions(P, Z, beta, chunk, out):
    """out = Z + P beta (P (n, kp), Z and out (n, ka), beta (kp, ka)); out may be P itself
    (ka <= kp: each row of P is read before it is written). Rows in chunks of ``chunk`` (one
    scratch row per chunk)."""
    n, kp = P.shape
    ka = Z.shape[1]
    for c in nb.prange((n + chunk - 1) // chunk):
        row = np.empty(kp)
        for r in range(c * chunk, min(n, (c + 1) * chunk)):
            for i in range(kp):
                row[i] = P[r, i]
            for j in range(ka):
                s = Z[r, j]
                for i in range(kp):
                    s += row[i] * beta[i, j]
                out[r, j] = s


def _zero_rows(X):
    """X[:] = 0 (X (n, k) C-contiguous), parallel over rows: a new block's pages are first
    touched, so faulted in, by every thread (numpy's zeros_like fills them on one)."""
    n, k = X.shape
    for i in nb.prange(n):
        for j in range(k):
            X[i, j] = 0.0


def _csr_gather_matmat(indptr, indices, data, rows, Y, out):
    """out = A Y[rows] for a CSR A (m x len(rows)) without the gathered copy: out[i, :] =
    sum_s data[s] Y[rows[indices[s]], :] over row i's entries in order (out (m, k))."""
    k = Y.shape[1]
    for i in nb.prange(indptr.shape[0] - 1):
        for j in range(k):
            out[i, j] = 0.0
        for s in range(indptr[i], indptr[i + 1]):
            a = data[s]
            q = rows[indices[s]]
            for j in range(k):
                out[i, j] += a * Y[q, j]


def _csr_scatter_matmat(indptr, indices, data, C, rows, X, sign):
    """X[rows[i], :] += sign (A C)[i, :] for a CSR A (len(rows) x m), C (m, k); ``rows``
    distinct (each row of X written by one iteration). Row i's product summed over its entries
    in order, then added."""
    k = C.shape[1]
    for i in nb.prange(indptr.shape[0] - 1):
        p = rows[i]
        for j in range(k):
            acc = 0.0
            for s in range(indptr[i], indptr[i + 1]):
                acc += data[s] * C[indices[s], j]
            X[p, j] += sign * acc


bsr_matmat, bsr_matmat_serial = parallel_and_serial(_bsr_matmat)
bsr_transposed_matmat, bsr_transposed_matmat_serial = parallel_and_serial(_bsr_transposed_matmat)
bsr_residual, bsr_residual_serial = parallel_and_serial(_bsr_residual)
bsr_gauss_seidel_colour, bsr_gauss_seidel_colour_serial = parallel_and_serial(_bsr_gauss_seidel_colour)
greedy_colouring = nb.njit(cache=True)(_greedy_colouring)
typed_stencil_blocks, typed_stencil_blocks_serial = parallel_and_serial(_typed_stencil_blocks)
axpy_cols, _ = parallel_and_serial(_axpy_cols)
xpby_cols, _ = parallel_and_serial(_xpby_cols)
coldot = nb.njit(cache=True)(_coldot)
gram_parts, _ = parallel_and_serial(_gram_parts)
colsq_parts, _ = parallel_and_serial(_colsq_parts)
block_step, _ = parallel_and_serial(_block_step)
block_directions, _ = parallel_and_serial(_block_directions)
zero_rows, zero_rows_serial = parallel_and_serial(_zero_rows)
csr_gather_matmat, csr_gather_matmat_serial = parallel_and_serial(_csr_gather_matmat)
csr_scatter_matmat, csr_scatter_matmat_serial = parallel_and_serial(_csr_scatter_matmat)
