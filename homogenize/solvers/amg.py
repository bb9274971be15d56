"""Smoothed-aggregation AMG and its block V-cycle, for many right-hand sides at once.

The cell problems of one RVE share their matrix: six unit strains plus the magnetic load. The
products with the matrix are memory-bound (the 64^3 stiffness is ~0.5 GB of 3 x 3 blocks), so every
operation here acts on a block of ``k`` columns, stored as a C-contiguous ``(n_dof, k)`` array:
each matrix block is read once for all columns.

* :func:`smoothed_aggregation` -- the project's one pyamg smoothed-aggregation setup
  (:class:`homogenize.solvers.AMGOptions`, the repeatable smoother :data:`SA_SMOOTH`), with the
  near-null space of :func:`rigid_body_modes`.
* :class:`BSROp` -- ``A X`` and ``B - A X`` with the parallel numba kernels.
* :class:`BlockVCycle` -- a symmetric V-cycle on a pyamg smoothed-aggregation hierarchy. Every
  level is smoothed by multicolour block Gauss-Seidel (the periodic voxel grid has 8 natural
  colours; coarse levels are coloured greedily), so each colour is updated in parallel with the
  same result for any number of threads. Pre-smoothing runs the colours forward, post-smoothing
  backward: the V-cycle is a symmetric positive definite operator, as CG requires.
"""
from __future__ import annotations

import types
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
import pyamg
import scipy.sparse as sp

from homogenize.voxels import _kernels as kn
from micro.common.validate import InputError
from scipy.linalg import cho_factor, cho_solve
from scipy.sparse.linalg import splu

from homogenize.solvers.options import AMGOptions

__all__ = ["BSROp", "BlockVCycle", "zeros_block", "grid_colours", "greedy_colours", "SA_SMOOTH",
           "smoothed_aggregation", "rigid_body_modes", "grid_node_coordinates"]

#: the prolongation smoother of every pyamg smoothed-aggregation hierarchy of the project: damped
#: Jacobi weighted by its local (Gershgorin) bound. pyamg's default weighting scales it by a
#: spectral-radius estimate that starts from ``np.random.rand``: two setups of one matrix then
#: differ at the solver tolerance, and the setup draws from numpy's global generator
#: (tests/homogenize/test_cell_solver.py checks both)
SA_SMOOTH = ("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"})


def smoothed_aggregation(A, B, options: AMGOptions = AMGOptions()):
    """pyamg smoothed-aggregation hierarchy of ``A`` with the near-null space ``B`` (columns:
    :func:`rigid_body_modes`) and the prolongation smoother :data:`SA_SMOOTH`: the only place
    the project sets one up.

    A : sparse (n, n) -- symmetric positive (semi)definite; B : ndarray (n, m);
    options : :class:`homogenize.solvers.AMGOptions` (``max_coarse`` must be set).
    Returns the pyamg ``MultilevelSolver``.
    """
    if not isinstance(options, AMGOptions):
        raise InputError(f"options must be an AMGOptions, got {options!r}")
    if options.max_coarse is None:
        raise InputError("AMGOptions.max_coarse must be set for a setup (None: the caller's "
                         "own size rule, applied with AMGOptions.replace)")
    kw = dict(symmetry=options.symmetry, max_coarse=options.max_coarse, smooth=SA_SMOOTH)
    if options.strength_theta is not None:
        kw["strength"] = ("symmetric", {"theta": options.strength_theta})
    if not options.improve_candidates:
        kw["improve_candidates"] = None
    if options.coarse_solver is not None:
        kw["coarse_solver"] = options.coarse_solver
    if options.keep:
        kw["keep"] = True
    return pyamg.smoothed_aggregation_solver(A, B=B, **kw)


def grid_node_coordinates(n: int, wrap=(0, 0, 0)) -> np.ndarray:
    """Coordinates of the nodes of the periodic n^3 voxel grid (node ``i + n (j + n k)``) for
    :func:`rigid_body_modes`, shape (n^3, 3): centred in the cell and divided by the cell's
    edge, so all six modes have comparable magnitude (AMG orthonormalises them per aggregate).

    wrap : (x, y, z) node layers where the coordinates jump by one cell (node i gets the
        coordinates of node i - wrap): a rotation mode jumps there, so the layer should cut no
        stiff particle (:func:`homogenize.cell.cut`'s wrap planes).
    """
    k, j, i = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    x = (np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1) - 0.5 * (n - 1)) / n
    if any(wrap):
        x = np.roll(x.reshape(n, n, n, 3), shift=tuple(wrap)[::-1],
                    axis=(0, 1, 2)).reshape(-1, 3)
    return x


def rigid_body_modes(coords, components=None) -> np.ndarray:
    """Rigid-body modes of elasticity (the near-null space of smoothed aggregation, the
    deflation space of a stiff particle): translations, then rotations ``e_k x r`` (about x:
    ``(0, -z, y)``; about y: ``(z, 0, -x)``; about z: ``(-y, x, 0)``; in 2D ``(-y, x)``).

    coords : ndarray, shape (m, d), d = 3 or 2 -- positions relative to the rotation centre (in
        whatever length scale the modes should have)
    components : None or int array (m,) -- None: ``coords`` are nodes with d unknowns each
        (interleaved), result (d m, modes); else the displacement component (0..d-1) of every
        unknown at position ``coords[t]``, result (m, modes).
    Returns 6 modes in 3D, 3 in 2D.
    """
    x = np.asarray(coords, dtype=np.float64)
    m, d = x.shape
    if d not in (2, 3):
        raise InputError(f"coords must have shape (m, 2) or (m, 3), got {x.shape}")
    if d == 2:
        rot = ((2, 0, 1, -1), (2, 1, 0, +1))
    else:
        # (mode, component, coordinate, sign)
        rot = ((3, 1, 2, -1), (3, 2, 1, +1), (4, 0, 2, +1), (4, 2, 0, -1),
               (5, 0, 1, -1), (5, 1, 0, +1))
    nm = 3 if d == 2 else 6
    if components is None:
        B = np.zeros((m, d, nm))
        for c in range(d):
            B[:, c, c] = 1.0
        for mode, comp, coord, sign in rot:
            B[:, comp, mode] = x[:, coord] if sign > 0 else -x[:, coord]
        return B.reshape(d * m, nm)
    comp = np.asarray(components)
    if comp.shape != (m,):
        raise InputError(f"components must have shape ({m},), got {comp.shape}")
    B = np.zeros((m, nm))
    for c in range(d):
        B[comp == c, c] = 1.0
    for mode, c, coord, sign in rot:
        sel = comp == c
        B[sel, mode] = x[sel, coord] if sign > 0 else -x[sel, coord]
    return B


def zeros_block(B) -> np.ndarray:
    """``np.zeros_like(B)`` for a (n, k) float64 block, zeroed in parallel when large: the
    V-cycle's new correction block is first touched there, and numpy's serial fill (page
    faults included) took 8 s of a 277 s solve at 128^3 on one thread and 13 s on two
    (cProfile; results/bench/threads.md)."""
    if B.ndim != 2 or B.shape[0] < kn.PARALLEL_MIN_ROWS:
        return np.zeros_like(B)
    X = np.empty(B.shape)
    kn.zero_rows(X)
    return X


def _bsr(A, blocksize=None):
    if not (sp.isspmatrix_bsr(A) or isinstance(A, sp.bsr_array)) or (
            blocksize is not None and A.blocksize != blocksize):
        A = sp.bsr_matrix(A, blocksize=blocksize)
    A.sort_indices()
    return A


class BSROp:
    """``A @ X`` for X of shape (n, k) (or (n,)) with the parallel BSR kernel."""

    def __init__(self, A, blocksize=None):
        A = _bsr(A, blocksize)
        self.indptr = np.ascontiguousarray(A.indptr)
        self.indices = np.ascontiguousarray(A.indices)
        self.data = np.ascontiguousarray(A.data, dtype=np.float64)
        self.R, self.C = A.blocksize
        self.shape = A.shape
        # parallel when the product is large enough to pay for starting the threads
        par = self.data.size >= 200_000 and self.indptr.size - 1 >= 8
        self._mm = kn.bsr_matmat if par else kn.bsr_matmat_serial
        self._res = kn.bsr_residual if par else kn.bsr_residual_serial

    def _cols(self, X):
        X = np.ascontiguousarray(X, dtype=np.float64)
        return X, (X.shape[1] if X.ndim == 2 else 1)

    def __matmul__(self, X):
        X, k = self._cols(X)
        Y = np.empty((self.shape[0], k))
        self._mm(self.indptr, self.indices, self.data, X.reshape(-1, self.C, k),
                 Y.reshape(-1, self.R, k))
        return Y if X.ndim == 2 else Y[:, 0]

    __call__ = __matmul__

    def residual(self, X, B):
        X, k = self._cols(X)
        B = np.ascontiguousarray(B, dtype=np.float64)
        out = np.empty((self.shape[0], k))
        self._res(self.indptr, self.indices, self.data, X.reshape(-1, self.C, k),
                  B.reshape(-1, self.R, k), out.reshape(-1, self.R, k))
        return out if X.ndim == 2 else out[:, 0]


class TransposedBSROp:
    """``A^T @ X`` for a :class:`BSROp` A, reading A's blocks transposed (no copy of them: only
    the pattern of A^T, 8 B per block; the products are those of ``BSROp`` of the explicit
    transpose, bit for bit)."""

    def __init__(self, A: BSROp):
        nbr = A.indptr.size - 1
        ncb = A.shape[1] // A.C
        rows = np.repeat(np.arange(nbr, dtype=np.int64), np.diff(A.indptr))
        cols = np.asarray(A.indices, dtype=np.int64)
        order = np.lexsort((rows, cols))             # by block column, then block row
        idx = np.int32 if max(nbr, ncb, order.size) < 2 ** 31 else np.int64
        self.indptr = np.zeros(ncb + 1, dtype=idx)
        np.cumsum(np.bincount(cols, minlength=ncb), out=self.indptr[1:])
        self.indices = np.ascontiguousarray(rows[order], dtype=idx)
        self.perm = np.ascontiguousarray(order, dtype=idx)
        del rows, cols, order
        self.data = A.data
        self.R, self.C = A.C, A.R
        self.shape = (A.shape[1], A.shape[0])
        par = self.data.size >= 200_000 and self.indptr.size - 1 >= 8
        self._mm = kn.bsr_transposed_matmat if par else kn.bsr_transposed_matmat_serial

    def __matmul__(self, X):
        X = np.ascontiguousarray(X, dtype=np.float64)
        k = X.shape[1] if X.ndim == 2 else 1
        Y = np.empty((self.shape[0], k))
        self._mm(self.indptr, self.indices, self.perm, self.data, X.reshape(-1, self.C, k),
                 Y.reshape(-1, self.R, k))
        return Y if X.ndim == 2 else Y[:, 0]

    __call__ = __matmul__


def grid_colours(n: int) -> list[np.ndarray]:
    """Node sets of the periodic n^3 grid none of whose members share a voxel.

    Per axis the colour is ``i mod 2``, and the last layer gets a third colour when n is odd (it
    touches both layer 0 and layer n - 2 through the periodic wrap). 8 colours for even n.
    """
    c1 = np.arange(n) % 2
    if n % 2:
        c1[-1] = 2
    k, j, i = np.meshgrid(c1, c1, c1, indexing="ij")
    col = (i + 3 * j + 9 * k).ravel()
    return [np.flatnonzero(col == c).astype(np.int64) for c in np.unique(col)]


def greedy_colours(op: BSROp) -> list[np.ndarray]:
    """Colour classes of the block-row graph of a square BSR operator (no two coupled rows share
    a colour)."""
    n = op.indptr.size - 1
    colour = np.zeros(n, dtype=np.int64)
    mark = np.full(n + 1, -1, dtype=np.int64)
    kn.greedy_colouring(op.indptr, op.indices, colour, mark)
    return [np.flatnonzero(colour == c).astype(np.int64) for c in range(colour.max() + 1)]


#: blocks per task of :func:`_block_inverse` on several threads
_INVERSE_CHUNK = 65536


def _block_inverse(diag: np.ndarray) -> np.ndarray:
    """Inverses of the diagonal blocks (m, R, R) for Gauss-Seidel; a (nearly) singular block --
    a coarse direction no fine vector reaches, from a rank-deficient rigid-body fit on a small
    aggregate next to cut composite voxels -- gets its symmetric pseudo-inverse, so the sweep
    leaves that null direction alone.

    Many blocks: chunks of :data:`_INVERSE_CHUNK` on numba's number of threads (numpy's linalg
    loops release the GIL; every block is inverted on its own, so the result is bitwise that of
    one call: 2.1e6 blocks at 128^3, 2.1 s on one thread, 1.2 s on two)."""
    m = diag.shape[0]
    threads = numba.get_num_threads()
    if m < 2 * _INVERSE_CHUNK or threads < 2:
        return _block_inverse_serial(diag)
    out = np.empty_like(diag)

    def part(start):
        sl = slice(start, min(m, start + _INVERSE_CHUNK))
        out[sl] = _block_inverse_serial(diag[sl])
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(part, range(0, m, _INVERSE_CHUNK)))
    return out


def _block_inverse_serial(diag: np.ndarray) -> np.ndarray:
    ev = np.linalg.eigvalsh(diag)
    bad = ev[:, 0] <= 1e-12 * np.abs(ev[:, -1:]).max(axis=1)
    out = np.empty_like(diag)
    ok = ~bad
    out[ok] = np.linalg.inv(diag[ok])
    if bad.any():
        out[bad] = np.linalg.pinv(diag[bad], rcond=1e-12, hermitian=True)
    return out


class _Level:
    def __init__(self, A, colours, P=None):
        self.A = BSROp(A)
        R = self.A.R
        ip, ind, data = self.A.indptr, self.A.indices, self.A.data
        rows = np.repeat(np.arange(ip.size - 1), np.diff(ip))
        diag = data[ind == rows]
        if diag.shape[0] != ip.size - 1:
            raise ValueError("every block row needs its diagonal block")
        self.dinv = np.ascontiguousarray(_block_inverse(diag))
        self.colours = colours if colours is not None else greedy_colours(self.A)
        self.R_blk = R
        # parallel sweeps when a colour holds enough work to pay for starting the threads
        # (per colour: the greedy colours of a coarse level range from one row to hundreds, and
        # the large ones pay: 128^3 bench RVE, the level below the 64^3 grid, 1.0x on 2 threads
        # with every colour serial)
        blocks_per_row = ind.size / max(ip.size - 1, 1)
        self._gs = [kn.bsr_gauss_seidel_colour if c.size * blocks_per_row * R * R >= 100_000
                    else kn.bsr_gauss_seidel_colour_serial for c in self.colours]
        if P is not None:
            P = _bsr(P)
            self.P = BSROp(P)
            # the restriction P^T reads P's blocks transposed (no second copy of them)
            self.Rop = TransposedBSROp(self.P)
        self._tmp = {}
        self._op = None

    def use_operator(self, op):
        """Smooth and take residuals with ``op`` (a :class:`homogenize.solvers._matfree.MatFreeOperator`
        of this level's matrix, the same colours) instead of the assembled blocks, and drop
        those: a geometric coarse grid handed to smoothed aggregation keeps only its transfer."""
        self._op = op
        self.A = types.SimpleNamespace(shape=self.A.shape, residual=op.residual)
        self.dinv = None

    def smooth(self, X, B, order, from_zero: bool = False):
        """Gauss-Seidel over the colour classes ``order`` in place in X; ``from_zero``: X is
        zero on entry (the V-cycle's pre-smoothing), which the matrix-free operator exploits."""
        if self._op is not None:
            cols = [self.colours[c] for c in order]
            if from_zero:
                self._op.gauss_seidel_from_zero(X, B, cols)
            else:
                self._op.gauss_seidel(X, B, cols)
            return
        k = X.shape[1]
        tmp = self._tmp.get(k)
        if tmp is None:
            tmp = self._tmp[k] = np.empty((self.A.shape[0] // self.R_blk, self.R_blk, k))
        Xv, Bv = X.reshape(-1, self.R_blk, k), B.reshape(-1, self.R_blk, k)
        a = self.A
        for c in order:
            self._gs[c](a.indptr, a.indices, a.data, self.dinv, self.colours[c], Xv, Bv, tmp)


def _fix_null_rows(A):
    """Coarsest matrix with empty rows (zero diagonal: coarse directions no fine vector
    reaches, from rank-deficient rigid-body candidates on small aggregates) given the mean
    diagonal, so it can be factorized; the restriction never feeds those rows."""
    A = sp.csr_matrix(A)
    d = A.diagonal()
    null = np.flatnonzero(np.abs(d) <= 1e-14 * np.abs(d).max())
    if null.size:
        A = A + sp.csr_matrix((np.full(null.size, float(np.mean(np.abs(d)))), (null, null)),
                              shape=A.shape)
    return A


def _shifted_cholesky(A: np.ndarray):
    """Cholesky factor of a symmetric positive (semi)definite A. The coarsest smoothed-
    aggregation matrix can be exactly singular (measured: 2 eigenvalues of 1e-20 relative among
    3090 at 24^3 with composite voxels -- rank-deficient rigid-body candidates on small
    aggregates give null coarse directions that the restriction never reaches); then a diagonal
    shift of 1e-12, 1e-10, ... of the mean diagonal. The V-cycle stays a symmetric positive
    definite preconditioner and CG converges to ``tol`` as before."""
    d = float(np.mean(np.diag(A)))
    for shift in (0.0, 1e-12, 1e-10, 1e-8, 1e-6):
        try:
            return cho_factor(A + shift * d * np.eye(A.shape[0]) if shift else A)
        except np.linalg.LinAlgError:
            continue
    raise np.linalg.LinAlgError("coarse AMG matrix is not positive definite (shift up to 1e-6)")


class BlockVCycle:
    """Symmetric V-cycle for a block of right-hand sides, on a pyamg smoothed-aggregation hierarchy.

    ``sweeps`` Gauss-Seidel passes over the colours before (forward) and after (backward) the
    coarse correction on every level but the coarsest, which is solved exactly (dense Cholesky up
    to 4000 unknowns, sparse LU beyond).
    ``fine_colours``: colour classes of the finest level (default: greedy).
    """

    def __init__(self, ml, *, fine_colours=None, sweeps: int = 1):
        lv = ml.levels
        self.levels = [_Level(lv[i].A, fine_colours if i == 0 else None, lv[i].P)
                       for i in range(len(lv) - 1)]
        Ac = _fix_null_rows(lv[-1].A)
        if Ac.shape[0] <= 4000:
            # the coarsest matrix of smoothed aggregation is nearly dense: dense Cholesky (LAPACK,
            # multithreaded) beats sparse LU, and one solve handles all columns
            fac = _shifted_cholesky(Ac.toarray())
            self.coarse_solve = lambda B: cho_solve(fac, B)
        else:
            self.coarse_solve = splu(sp.csc_matrix(Ac)).solve
        self.sweeps = int(sweeps)
        self.shape = lv[0].A.shape

    def _cycle(self, i, B):
        if i == len(self.levels):
            return self.coarse_solve(np.asarray(B))
        L = self.levels[i]
        X = zeros_block(B)
        nc = len(L.colours)
        fwd, bwd = list(range(nc)), list(range(nc - 1, -1, -1))
        L.smooth(X, B, fwd * self.sweeps, from_zero=True)
        cB = L.Rop @ L.A.residual(X, B)
        X += L.P @ self._cycle(i + 1, cB)
        L.smooth(X, B, bwd * self.sweeps)
        return X

    def __matmul__(self, B):
        B = np.ascontiguousarray(B, dtype=np.float64)
        one = B.ndim == 1
        X = self._cycle(0, B[:, None] if one else B)
        return X[:, 0] if one else X

    __call__ = __matmul__


