"""Multigrid and conjugate gradients for many right-hand sides at once.

The cell problems of one RVE share their matrix: six unit strains plus the magnetic load. The
products with the matrix are memory-bound (the 64^3 stiffness is ~0.5 GB of 3 x 3 blocks), so every
operation here acts on a block of ``k`` columns, stored as a C-contiguous ``(n_dof, k)`` array:
each matrix block is read once for all columns.

* :class:`BSROp` -- ``A X`` and ``B - A X`` with the parallel numba kernels.
* :class:`BlockVCycle` -- a symmetric V-cycle on a pyamg smoothed-aggregation hierarchy. Every
  level is smoothed by multicolour block Gauss-Seidel (the periodic voxel grid has 8 natural
  colours; coarse levels are coloured greedily), so each colour is updated in parallel with the
  same result for any number of threads. Pre-smoothing runs the colours forward, post-smoothing
  backward: the V-cycle is a symmetric positive definite operator, as CG requires.
* :func:`block_cg` -- preconditioned CG run in lock-step on all columns (each column has its own
  step lengths: mathematically k independent CG solves), in place, optionally deflated
  (:class:`Deflation`); converged columns leave the block. Used by every cell solver.
* :func:`coupled_block_cg` -- the block CG proper (O'Leary 1980): one Krylov space for all
  columns (or for groups of them), breakdown-free; the matrix-free cell solver's default.
"""
from __future__ import annotations

import types

import numpy as np
import scipy.sparse as sp

from . import _kernels as kn
from scipy.linalg import cho_factor, cho_solve
from scipy.sparse.linalg import splu

__all__ = ["BSROp", "BlockVCycle", "Deflation", "block_cg", "coupled_block_cg", "grid_colours",
           "greedy_colours", "SA_SMOOTH"]

#: the prolongation smoother of every pyamg smoothed-aggregation hierarchy of the project: damped
#: Jacobi weighted by its local (Gershgorin) bound. pyamg's default weighting scales it by a
#: spectral-radius estimate that starts from ``np.random.rand``: two setups of one matrix then
#: differ at the solver tolerance, and the setup draws from numpy's global generator
#: (tests/homogenize/test_cell_solver.py checks both)
SA_SMOOTH = ("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"})


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


def _block_inverse(diag: np.ndarray) -> np.ndarray:
    """Inverses of the diagonal blocks (m, R, R) for Gauss-Seidel; a (nearly) singular block --
    a coarse direction no fine vector reaches, from a rank-deficient rigid-body fit on a small
    aggregate next to cut composite voxels -- gets its symmetric pseudo-inverse, so the sweep
    leaves that null direction alone."""
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
        blocks_per_row = ind.size / max(ip.size - 1, 1)
        par = min(c.size for c in self.colours) * blocks_per_row * R * R >= 100_000
        self._gs = kn.bsr_gauss_seidel_colour if par else kn.bsr_gauss_seidel_colour_serial
        if P is not None:
            P = _bsr(P)
            self.P = BSROp(P)
            self.Rop = BSROp(P.T.tobsr(blocksize=(P.blocksize[1], P.blocksize[0])))
        self._tmp = {}
        self._op = None

    def use_operator(self, op):
        """Smooth and take residuals with ``op`` (a :class:`homogenize._matfree.MatFreeOperator`
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
            self._gs(a.indptr, a.indices, a.data, self.dinv, self.colours[c], Xv, Bv, tmp)


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
        X = np.zeros_like(B)
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


class Deflation:
    """The deflation space Z (n, m) of the stiff particles' rigid modes with ``KZ = K Z`` and the
    factorized ``E = Z^T K Z`` (``Esolve``); products touch only the rows where Z or KZ are
    nonzero."""

    def __init__(self, Z, KZ, Esolve):
        Z, KZ = sp.csr_matrix(Z), sp.csr_matrix(KZ)
        self.zr = np.flatnonzero(np.diff(Z.indptr))
        self.kr = np.flatnonzero(np.diff(KZ.indptr))
        self.Z, self.KZ = Z[self.zr], KZ[self.kr]          # the nonzero rows only
        self.ZT, self.KZT = self.Z.T.tocsr(), self.KZ.T.tocsr()
        self.Es = Esolve

    def coefficients(self, Y, on_K: bool):
        """E^-1 Z^T Y (``on_K=False``) or E^-1 (KZ)^T Y."""
        if on_K:
            return self.Es(np.asarray(self.KZT @ Y[self.kr]))
        return self.Es(np.asarray(self.ZT @ Y[self.zr]))

    def start(self, F):
        """The start ``Z E^-1 Z^T F`` (dense, the shape of F)."""
        X = np.zeros(F.shape)
        X[self.zr] = self.Z @ self.coefficients(F, False)
        return X

    def project(self, Y):
        """Y -= Z E^-1 (KZ)^T Y, in place: K-orthogonal to the deflation space."""
        Y[self.zr] -= self.Z @ self.coefficients(Y, True)

    def correct(self, X, R):
        """X += Z c, R -= K Z c with c = E^-1 Z^T R, in place."""
        c = self.coefficients(R, False)
        X[self.zr] += self.Z @ c
        R[self.kr] -= self.KZ @ c


def _own(Y, R):
    """Y as a C-contiguous float64 array that does not share memory with R (updated in place)."""
    Y = np.ascontiguousarray(Y, dtype=np.float64)
    return Y.copy() if np.shares_memory(Y, R) else Y


def _dots(A, B):
    out = np.empty(A.shape[1])
    kn.coldot(A, B, out)
    return out


def _cg_start(A, F, tol, deflation):
    """The start of both block CGs: X (the deflated start or zero), the active residual block,
    the histories and the active columns. Returns (X, Xa, R, hist, idx, fa, tols): ``Xa`` is X
    itself when every column is active (one block less memory), else a copy of the active
    columns; columns converged at the start stay in X; ``fa`` the active columns' load norms."""
    F = np.ascontiguousarray(F, dtype=np.float64)
    n, k = F.shape
    fn = np.linalg.norm(F, axis=0)
    fn[fn == 0.0] = 1.0
    tols = np.broadcast_to(np.asarray(tol, dtype=np.float64), (k,))
    if deflation is not None:
        X = deflation.start(F)
        R = A.residual(X, F) if hasattr(A, "residual") else F - A(X)
    else:
        X = np.zeros((n, k))
        R = F.copy()
    del F
    hist = [[float(v)] for v in np.linalg.norm(R, axis=0) / fn]
    idx = np.flatnonzero([h[0] > t for h, t in zip(hist, tols)])
    if 0 < idx.size < k:
        Xa = np.ascontiguousarray(X[:, idx])
        R = np.ascontiguousarray(R[:, idx])
    else:
        Xa = X
    return X, Xa, R, hist, idx, fn[idx], tols


def _record_step(hist, idx, res, tols, k, it, callback):
    """Append the active columns' relative residuals ``res`` to their histories, report
    progress; returns which active columns have converged."""
    for c, v in zip(idx, res):
        hist[c].append(float(v))
    done = res <= tols[idx]
    if callback is not None:
        callback(it, k - idx.size + int(done.sum()), float(res.max()))
    return done


def block_cg(A, M, F, *, tol, maxiter: int, deflation: Deflation | None = None,
             callback=None):
    """Preconditioned CG on the k columns of F at once, with in-place updates (X, R, P, the
    product A P and the preconditioned residual are the only vectors).

    A, M : callables mapping an (n, k) array to an (n, k) array (the matrix and the
        preconditioner, both symmetric positive definite on the space CG works in); A may offer
        ``A.residual(X, B)`` (= B - A X without a temporary)
    F : ndarray (n, k) -- right-hand sides
    tol : float or sequence of k floats -- relative residual ||f - A x|| / ||f|| at which a
        column stops (one value for all columns, or one per column)
    deflation : :class:`Deflation` or None -- deflated CG: start ``Z E^-1 Z^T F``, projection of
        the preconditioned residual, and the correction ``X += Z c, R -= K Z c`` of the residual
        after every step. Deflated CG keeps ``Z^T R = 0`` only in exact arithmetic; the round-off
        that builds up there when the load acts mostly on the deflated modes (particle forces
        move the particles rigidly) grows until CG diverges below ~1e-9; the correction removes it.
    callback : callable or None -- ``callback(iteration, n_converged, worst_residual)`` after
        every step (progress reporting)

    Returns ``(X, histories)``: the solutions and, per column, the list of relative residuals
    (first entry: the start). Each column follows exactly the recursion of a single-vector CG
    (its own step lengths); converged columns leave the block.
    """
    k = F.shape[1]
    X, Xa, R, hist, idx, fa, tols = _cg_start(A, F, tol, deflation)
    if idx.size == 0:
        return X, hist
    P = _own(M(R), R)
    rz = _dots(R, P)
    if deflation is not None:
        deflation.project(P)
    it = 0
    while idx.size and it < maxiter:
        Q = _own(A(P), P)
        alpha = rz / _dots(P, Q)
        kn.axpy_cols(Xa, P, alpha)
        kn.axpy_cols(R, Q, -alpha)
        del Q
        if deflation is not None:
            deflation.correct(Xa, R)
        it += 1
        done = _record_step(hist, idx, np.linalg.norm(R, axis=0) / fa, tols, k, it, callback)
        if done.any():                  # converged columns leave the block
            X[:, idx[done]] = Xa[:, done]
            keep = ~done
            idx, fa, rz = idx[keep], fa[keep], rz[keep]
            if idx.size == 0:
                break
            # one at a time, so that only one old block is alive next to its copy
            Xa = np.ascontiguousarray(Xa[:, keep])
            R = np.ascontiguousarray(R[:, keep])
            P = np.ascontiguousarray(P[:, keep])
        Z = _own(M(R), R)
        rz_new = _dots(R, Z)
        if deflation is not None:
            deflation.project(Z)
        kn.xpby_cols(P, Z, rz_new / rz)
        del Z
        rz = rz_new
    if idx.size:
        X[:, idx] = Xa
    return X, hist


#: rows per partial sum of the coupled block CG's reductions (homogenize._kernels.gram_parts):
#: fixed, so the sums do not depend on the number of threads
CG_CHUNK = 8192
#: directions of the block whose A-norm Gram matrix, scaled to unit diagonal, has an eigenvalue
#: below this are dropped from the step (linearly dependent directions: coupled_block_cg)
RANK_TOL = 1e-10


def _gram(A, B):
    """A^T B (deterministic: fixed chunks of CG_CHUNK rows, added in order)."""
    n = A.shape[0]
    parts = np.empty(((n + CG_CHUNK - 1) // CG_CHUNK, A.shape[1], B.shape[1]))
    kn.gram_parts(A, B, CG_CHUNK, parts)
    return parts.sum(axis=0)


def _colnorms(A):
    n = A.shape[0]
    parts = np.empty(((n + CG_CHUNK - 1) // CG_CHUNK, A.shape[1]))
    kn.colsq_parts(A, CG_CHUNK, parts)
    return np.sqrt(parts.sum(axis=0))


def _pinv_spd(G):
    """Pseudo-inverse of the symmetric positive semi-definite Gram matrix G = P^T A P, dropping
    the directions that are linearly dependent after scaling G to unit diagonal (eigenvalue
    below RANK_TOL)."""
    G = 0.5 * (G + G.T)
    d = np.sqrt(np.abs(np.diag(G)))
    d[d == 0.0] = 1.0
    w, V = np.linalg.eigh(G / np.outer(d, d))
    keep = w > RANK_TOL * max(float(w.max()), 0.0)
    Vk = V[:, keep] / d[:, None]
    return (Vk / w[keep]) @ Vk.T


def _group_pinv(G, groups):
    """Block-diagonal pseudo-inverse of G: :func:`_pinv_spd` of each group's diagonal block (the
    couplings between groups are ignored)."""
    out = np.zeros_like(G)
    for g in np.unique(groups):
        sel = np.flatnonzero(groups == g)
        out[np.ix_(sel, sel)] = _pinv_spd(G[np.ix_(sel, sel)])
    return out


def coupled_block_cg(A, M, F, *, tol, maxiter: int, deflation: Deflation | None = None,
                     callback=None, groups=None):
    """Block preconditioned CG (O'Leary, Linear Algebra Appl. 29, 1980) on the k columns of F:
    every column's step is taken in the span of ALL the block's search directions, so each
    column sees a Krylov space k times larger per iteration (the outlying eigenvalues a weak
    preconditioner leaves are found by the whole block). Same arguments and return value as
    :func:`block_cg`; converged columns leave the block (their residual is orthogonal to every
    direction so far, so the rest keep the short recurrence); directions that become linearly
    dependent are dropped from the step through a rank-revealing pseudo-inverse of the block's
    Gram matrix (:data:`RANK_TOL`), so the iteration does not break down (as in the
    breakdown-free block CG of Ji & Li, Comput. Math. Appl. 73, 2017).

    Per iteration: one product ``A P`` and one preconditioner application on the block, and the
    k x k coefficients alpha = (P^T A P)^+ P^T R and beta = -(P^T A P)^+ (A P)^T Z, with
    ``Z = M R`` (projected when deflated). Vectors: X, R, P, A P and Z (A P is kept until beta is
    formed: one block more than :func:`block_cg` while the preconditioner runs).

    groups : None (all columns coupled) or one label per column: columns are coupled only within
        their group (every group is its own block CG; all share the products with A and M).
        One group per column is :func:`block_cg`'s independent recursion.
    """
    k = F.shape[1]
    X, Xa, R, hist, idx, fa, tols = _cg_start(A, F, tol, deflation)
    del F
    if idx.size == 0:
        return X, hist
    labels = np.zeros(k, dtype=np.int64) if groups is None else np.asarray(groups)
    if labels.shape != (k,):
        raise ValueError(f"groups needs one label per column ({k}), got {labels.shape}")
    P = _own(M(R), R)
    if deflation is not None:
        deflation.project(P)
    it = 0
    while idx.size and it < maxiter:
        g = labels[idx]                 # the group of every active column and its direction
        same = g[:, None] == g[None, :]
        Q = _own(A(P), P)
        Gi = _group_pinv(_gram(P, Q), g)
        alpha = np.ascontiguousarray(Gi @ (_gram(P, R) * same))
        kn.block_step(Xa, R, P, Q, alpha)
        if deflation is not None:
            deflation.correct(Xa, R)
        it += 1
        done = _record_step(hist, idx, _colnorms(R) / fa, tols, k, it, callback)
        if done.any():                  # converged columns leave the block
            X[:, idx[done]] = Xa[:, done]
            keep = ~done
            idx, fa = idx[keep], fa[keep]
            if idx.size == 0:
                break
            Xa = np.ascontiguousarray(Xa[:, keep])
            R = np.ascontiguousarray(R[:, keep])
        Z = _own(M(R), R)
        if deflation is not None:
            deflation.project(Z)
        beta = np.ascontiguousarray(-(Gi @ (_gram(Q, Z) * (g[:, None] == labels[idx][None, :]))))
        del Q
        if Z.shape[1] == P.shape[1]:
            kn.block_directions(P, Z, beta, CG_CHUNK, P)
        else:
            Pn = np.empty_like(Z)
            kn.block_directions(P, Z, beta, CG_CHUNK, Pn)
            P = Pn
            del Pn
        del Z
    if idx.size:
        X[:, idx] = Xa
    return X, hist
