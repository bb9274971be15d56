"""Krylov drivers for many right-hand sides at once, optionally deflated.

* :func:`block_cg` -- preconditioned CG run in lock-step on all columns (each column has its own
  step lengths: mathematically k independent CG solves), in place, optionally deflated
  (:class:`Deflation`); converged columns leave the block. Used by every cell solver.
* :func:`coupled_block_cg` -- the block CG proper (O'Leary 1980): one Krylov space for all
  columns (or for groups of them), breakdown-free; the matrix-free cell solver's default.

Blocks are C-contiguous ``(n_dof, k)`` arrays (see :mod:`homogenize.solvers.amg`); the column
reductions and updates are the numba kernels of :mod:`homogenize.voxels._kernels`.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from homogenize.voxels import _kernels as kn

__all__ = ["Deflation", "block_cg", "coupled_block_cg", "CG_CHUNK", "RANK_TOL"]


class Deflation:
    """The deflation space Z (n, m) of the stiff particles' rigid modes with ``KZ = K Z`` and the
    factorized ``E = Z^T K Z`` (``Esolve``); products touch only the rows where Z or KZ are
    nonzero, with the row-parallel CSR kernels of :mod:`homogenize.voxels._kernels` on (n, k)
    blocks (each output row a sum in the order of its entries, as scipy's product, so the
    same numbers for any number of threads; scipy's serial products for anything else)."""

    def __init__(self, Z, KZ, Esolve):
        Z, KZ = sp.csr_matrix(Z), sp.csr_matrix(KZ)
        self.zr = np.flatnonzero(np.diff(Z.indptr))
        self.kr = np.flatnonzero(np.diff(KZ.indptr))
        self.Z, self.KZ = Z[self.zr], KZ[self.kr]          # the nonzero rows only
        self.ZT, self.KZT = self.Z.T.tocsr(), self.KZ.T.tocsr()
        for A in (self.Z, self.KZ, self.ZT, self.KZT):
            A.sort_indices()
        self.Es = Esolve
        self._par = max(self.Z.nnz, self.KZ.nnz) >= 20 * kn.PARALLEL_MIN_ROWS

    @staticmethod
    def _block(Y) -> bool:
        return (isinstance(Y, np.ndarray) and Y.ndim == 2 and Y.dtype == np.float64
                and Y.flags.c_contiguous)

    def _gather(self, A, rows, Y):
        """A @ Y[rows] (A: Z^T or (KZ)^T)."""
        if not self._block(Y):
            return np.asarray(A @ Y[rows])
        out = np.empty((A.shape[0], Y.shape[1]))
        (kn.csr_gather_matmat if self._par else kn.csr_gather_matmat_serial)(
            A.indptr, A.indices, A.data, rows, Y, out)
        return out

    def _scatter(self, A, c, rows, X, sign: float):
        """X[rows] += sign A @ c, in place (A: Z or KZ)."""
        c = np.ascontiguousarray(c, dtype=np.float64)
        if not self._block(X) or c.ndim != 2:
            X[rows] += sign * (A @ c)
            return
        (kn.csr_scatter_matmat if self._par else kn.csr_scatter_matmat_serial)(
            A.indptr, A.indices, A.data, c, rows, X, sign)

    def coefficients(self, Y, on_K: bool):
        """E^-1 Z^T Y (``on_K=False``) or E^-1 (KZ)^T Y."""
        if on_K:
            return self.Es(self._gather(self.KZT, self.kr, Y))
        return self.Es(self._gather(self.ZT, self.zr, Y))

    def start(self, F):
        """The start ``Z E^-1 Z^T F`` (dense, the shape of F)."""
        X = np.zeros(F.shape)
        self._scatter(self.Z, self.coefficients(F, False), self.zr, X, 1.0)
        return X

    def project(self, Y):
        """Y -= Z E^-1 (KZ)^T Y, in place: K-orthogonal to the deflation space."""
        self._scatter(self.Z, self.coefficients(Y, True), self.zr, Y, -1.0)

    def correct(self, X, R):
        """X += Z c, R -= K Z c with c = E^-1 Z^T R, in place."""
        c = self.coefficients(R, False)
        self._scatter(self.Z, c, self.zr, X, 1.0)
        self._scatter(self.KZ, c, self.kr, R, -1.0)


def _own(Y, R):
    """Y as a C-contiguous float64 array that does not share memory with R (updated in place)."""
    Y = np.ascontiguousarray(Y, dtype=np.float64)
    return Y.copy() if np.shares_memory(Y, R) else Y


def _dots(A, B):
    out = np.empty(A.shape[1])
    kn.coldot(A, B, out)
    return out


def _cg_start(A, F, tol, deflation, x0=None):
    """The start of both block CGs: X (the deflated start, zero, or the initial guess ``x0``
    (n, k) with the deflation's correction ``X = x0 + Z E^-1 Z^T (F - A x0)``), the active
    residual block, the histories and the active columns. Returns (X, Xa, R, hist, idx, fa,
    tols): ``Xa`` is X itself when every column is active (one block less memory), else a copy
    of the active columns; columns converged at the start stay in X; ``fa`` the active
    columns' load norms."""
    F = np.ascontiguousarray(F, dtype=np.float64)
    n, k = F.shape
    fn = _colnorms(F)
    fn[fn == 0.0] = 1.0
    tols = np.broadcast_to(np.asarray(tol, dtype=np.float64), (k,))
    if x0 is not None:
        X = np.array(x0, dtype=np.float64, order="C")      # a copy: x0 is not changed
        if X.shape != F.shape:
            raise ValueError(f"x0 must have the shape of F {F.shape}, got {X.shape}")
        R = A.residual(X, F) if hasattr(A, "residual") else F - A(X)
        if deflation is not None:
            deflation.correct(X, R)
    elif deflation is not None:
        X = deflation.start(F)
        R = A.residual(X, F) if hasattr(A, "residual") else F - A(X)
    else:
        X = np.zeros((n, k))
        R = F.copy()
    del F
    hist = [[float(v)] for v in _colnorms(R) / fn]
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
             callback=None, x0=None):
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
    x0 : ndarray (n, k) or None -- initial guess (warm start; None: zero, or the deflated start);
        the relative residual stays ``||f - A x|| / ||f||``, so a good guess saves iterations and
        a column already converged at the start takes none

    Returns ``(X, histories)``: the solutions and, per column, the list of relative residuals
    (first entry: the start). Each column follows exactly the recursion of a single-vector CG
    (its own step lengths); converged columns leave the block.
    """
    k = F.shape[1]
    X, Xa, R, hist, idx, fa, tols = _cg_start(A, F, tol, deflation, x0)
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
        done = _record_step(hist, idx, _colnorms(R) / fa, tols, k, it, callback)
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


#: rows per partial sum of the coupled block CG's reductions (homogenize.voxels._kernels.gram_parts):
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
                     callback=None, groups=None, x0=None):
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
    formed: one block more than :func:`block_cg` while the preconditioner runs); the converged
    columns of X are kept one by one beside the active block and the (n, k) solution is
    assembled at the end, once R, P and A P are freed.

    groups : None (all columns coupled) or one label per column: columns are coupled only within
        their group (every group is its own block CG; all share the products with A and M).
        One group per column is :func:`block_cg`'s independent recursion.
    """
    n, k = F.shape
    X, Xa, R, hist, idx, fa, tols = _cg_start(A, F, tol, deflation, x0)
    del F
    if idx.size == 0:
        return X, hist
    # the converged columns, one (n,) array each, and Xa the active ones: no (n, k) block of all
    # columns next to the active block while the CG runs (assembled at the end)
    done_cols = {int(c): X[:, c].copy() for c in range(k) if c not in set(idx.tolist())}
    del X
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
            for j in np.flatnonzero(done):
                done_cols[int(idx[j])] = Xa[:, j].copy()
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
    R = P = Q = None                    # (freed before the solution block is assembled)
    X = np.empty((n, k))
    for c in list(done_cols):
        X[:, c] = done_cols.pop(c)
    if idx.size:
        X[:, idx] = Xa
    return X, hist


# ------------------------------------------------------------------------------------------------
# the steps of the drivers by public names, for variants of them passed in as
# SolverOptions.krylov (results/cell/magnetic_column_experiments.py); the drivers above are the
# only users inside the library
# ------------------------------------------------------------------------------------------------

#: (X, Xa, R, hist, idx, fa, tols) = cg_start(A, F, tol, deflation): the start of both drivers
cg_start = _cg_start
#: own(Y, R): Y as a C-contiguous float64 array that shares no memory with R
own = _own
#: gram(A, B) = A^T B, deterministic (fixed chunks of CG_CHUNK rows, added in order)
gram = _gram
#: colnorms(A): the column 2-norms, deterministic as :func:`gram`
colnorms = _colnorms
#: group_pinv(G, groups): block-diagonal pseudo-inverse of the Gram matrix G per column group
group_pinv = _group_pinv
#: done = record_step(hist, idx, res, tols, k, it, callback): append the active columns'
#: relative residuals, report progress, return which active columns converged
record_step = _record_step
#: block_step(X, R, P, Q, alpha): X += P alpha, R -= Q alpha, in place (numba)
block_step = kn.block_step
#: block_directions(P, Z, beta, chunk, out): out = Z + P beta (numba; out may be P)
block_directions = kn.block_directions

__all__ += ["cg_start", "own", "gram", "colnorms", "group_pinv", "record_step", "block_step",
            "block_directions"]
