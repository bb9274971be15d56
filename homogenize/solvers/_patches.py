"""Particle patches: an exact local solve per particle in the fine level of the geometric V-cycle.

Each particle gets one patch: the fine-grid nodes within ``r + shell`` voxels of its centre
(periodic; the pinned node left out). The patch's principal submatrix of the pinned stiffness K,
assembled from the matrix-free operator's own stencil rows, is factorized once (LAPACK Cholesky,
the lower factor kept packed: (3 m)(3 m + 1) / 2 doubles for m nodes). In the V-cycle the patches
are solved after the fine pre-smoothing (``forward``) and again before the post-smoothing
(``backward``, the same colours in reverse): multiplicative Schwarz, so the cycle stays
symmetric. Every particle then sits whole inside a subdomain with an exact solve -- the particle,
its matrix shell and the rigid motion of the one against the other -- the setting in which
overlapping Schwarz methods are robust to the contrast of the inclusions (Graham, Lechner &
Scheichl, Numer. Math. 106, 2007). Measured in results/cell/README.md ("Particle patches").

Patches whose nodes are stencil neighbours of each other get different colours (greedy, in
particle order); the patches of one colour touch disjoint rows and read disjoint unknowns, so they
are solved in parallel and the result does not depend on the number of threads. A colour's
patches go to the threads in groups of about equal work (largest first to the least loaded
group, :meth:`ParticlePatches._groups`): their costs span two orders of magnitude.
"""
from __future__ import annotations

import numpy as np
import numba as nb
from threadpoolctl import threadpool_limits

from homogenize.voxels._budget import PATCH_BYTES_PER_NODE
from micro.common.jit import parallel_and_serial
from micro.box import PeriodicBox

from homogenize.voxels._kernels import block_acc

__all__ = ["ParticlePatches", "patch_nodes", "patch_colours", "patch_factor_bytes",
           "select_patches", "MAX_NODES", "BYTES_PER_NODE"]

#: a particle whose patch has more nodes than this gets none: its factor would take
#: 8 (3 m)^2 / 2 B (36 MB at 1000 nodes), and a particle that large against the grid is resolved
#: well enough for the multigrid alone (the 64^3 bench RVE, particles of ~2.5 voxels mean radius,
#: gains no iterations from its patches: results/cell/README.md)
MAX_NODES = 1000
#: the packed factors of all patches together take at most this many bytes per grid node
#: (smallest patches first; the matrix-free memory estimate of homogenize.voxels._budget, which owns
#: the number, counts it in full)
BYTES_PER_NODE = PATCH_BYTES_PER_NODE
#: storage of the factors (the solves compute in float64 either way)
FACTOR_DTYPE = np.float32


def patch_nodes(centers_vox, radii_vox, n: int, shell_voxels: float, pin: int = -1):
    """Per particle: the sorted fine nodes (index ``i + n (j + n k)``, position (i, j, k) voxels)
    within ``r + shell_voxels`` of its centre (periodic), the pinned node left out.
    Returns ``(ptr, nodes)`` (CSR: patch q holds ``nodes[ptr[q]:ptr[q + 1]]``)."""
    parts = []
    for c, r in zip(np.asarray(centers_vox, dtype=float), np.asarray(radii_vox, dtype=float)):
        R = r + shell_voxels
        lo, hi = np.floor(c - R).astype(np.int64), np.ceil(c + R).astype(np.int64)
        I, J, K = np.meshgrid(*[np.arange(lo[d], hi[d] + 1) for d in range(3)], indexing="ij")
        m = (I - c[0]) ** 2 + (J - c[1]) ** 2 + (K - c[2]) ** 2 <= R * R
        nodes = np.unique((I[m] % n) + n * ((J[m] % n) + n * (K[m] % n))).astype(np.int64)
        parts.append(nodes[nodes != pin])
    ptr = np.zeros(len(parts) + 1, dtype=np.int64)
    ptr[1:] = np.cumsum([p.size for p in parts])
    return ptr, (np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64))


def patch_colours(centers_vox, reach_vox, n: int) -> np.ndarray:
    """Greedy colour per patch (in particle order) such that two patches of one colour have no
    pair of nodes that are stencil neighbours: nodes within ``reach`` of their centres, so two
    patches can couple only if their centres are closer than ``reach_a + reach_b + sqrt(3)``
    (periodic distance in voxels) -- every such pair gets different colours (conservative)."""
    box = PeriodicBox(float(n))
    c = box.wrap(centers_vox)
    reach = np.asarray(reach_vox, dtype=float)
    P = c.shape[0]
    colour = np.full(P, -1, dtype=np.int64)
    if P == 0:
        return colour
    cut = 2.0 * float(reach.max()) + np.sqrt(3.0) + 1e-9
    i, j, dist = box.pairs_within(c, cut)
    close = dist <= reach[i] + reach[j] + np.sqrt(3.0) + 1e-9
    nbrs = [[] for _ in range(P)]
    for a, b in zip(i[close], j[close]):
        nbrs[a].append(b)
        nbrs[b].append(a)
    for q in range(P):
        used = {int(colour[o]) for o in nbrs[q] if colour[o] >= 0}
        col = 0
        while col in used:
            col += 1
        colour[q] = col
    return colour


def select_patches(ptr, n_nodes: int, max_nodes: int | None = None,
                   bytes_per_node: float | None = None) -> np.ndarray:
    """The patches kept (sorted indices): at most ``max_nodes`` nodes each (and at least one),
    taken smallest first (ties in particle order) while their packed factors stay within
    ``bytes_per_node * n_nodes`` bytes (None: :data:`MAX_NODES`, :data:`BYTES_PER_NODE`)."""
    max_nodes = MAX_NODES if max_nodes is None else max_nodes
    bytes_per_node = BYTES_PER_NODE if bytes_per_node is None else bytes_per_node
    m = np.diff(np.asarray(ptr, dtype=np.int64))
    m3 = 3 * m
    cost = np.dtype(FACTOR_DTYPE).itemsize * (m3 * (m3 + 1) // 2)
    order = np.lexsort((np.arange(m.size), m))
    order = order[(m[order] > 0) & (m[order] <= max_nodes)]
    fits = np.cumsum(cost[order]) <= bytes_per_node * n_nodes
    return np.sort(order[fits])


def patch_factor_bytes(ptr) -> int:
    """Memory of the packed Cholesky factors [bytes]: (3 m)(3 m + 1) / 2 entries of
    :data:`FACTOR_DTYPE` per patch."""
    m3 = 3 * np.diff(np.asarray(ptr, dtype=np.int64))
    return int(np.dtype(FACTOR_DTYPE).itemsize * (m3 * (m3 + 1) // 2).sum())


# ------------------------------------------------------------------------------------------------
# numba kernels
# ------------------------------------------------------------------------------------------------

@nb.njit(cache=True, fastmath=True, inline="always")
def _dot(L, base, y, a):
    """sum_{b < a} L[base + b] y[b] (reassociated: vectorized; the same machine code in every
    call, so the result does not depend on the thread that runs it)."""
    acc = 0.0
    for bb in range(a):
        acc += L[base + bb] * y[bb]
    return acc


@nb.njit(cache=True, fastmath=True, inline="always")
def _dot4(L, base, y0, y1, y2, y3, a):
    """:func:`_dot` of four vectors with one read of the factor's row."""
    s0 = s1 = s2 = s3 = 0.0
    for bb in range(a):
        lv = L[base + bb]
        s0 += lv * y0[bb]
        s1 += lv * y1[bb]
        s2 += lv * y2[bb]
        s3 += lv * y3[bb]
    return s0, s1, s2, s3


@nb.njit(cache=True, fastmath=True, inline="always")
def _dot8(L, base, Y, a):
    """:func:`_dot` of the eight rows of Y with one read of the factor's row."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    for bb in range(a):
        lv = L[base + bb]
        s0 += lv * Y[0, bb]
        s1 += lv * Y[1, bb]
        s2 += lv * Y[2, bb]
        s3 += lv * Y[3, bb]
        s4 += lv * Y[4, bb]
        s5 += lv * Y[5, bb]
        s6 += lv * Y[6, bb]
        s7 += lv * Y[7, bb]
    return s0, s1, s2, s3, s4, s5, s6, s7


@nb.njit(cache=True, fastmath=True, inline="always")
def _axpy8(L, base, Y, a):
    """:func:`_axpy` of the eight rows of Y, x = Y[:, a], with one read of the factor's row."""
    x0, x1, x2, x3 = Y[0, a], Y[1, a], Y[2, a], Y[3, a]
    x4, x5, x6, x7 = Y[4, a], Y[5, a], Y[6, a], Y[7, a]
    for bb in range(a):
        lv = L[base + bb]
        Y[0, bb] -= lv * x0
        Y[1, bb] -= lv * x1
        Y[2, bb] -= lv * x2
        Y[3, bb] -= lv * x3
        Y[4, bb] -= lv * x4
        Y[5, bb] -= lv * x5
        Y[6, bb] -= lv * x6
        Y[7, bb] -= lv * x7


@nb.njit(cache=True, fastmath=True, inline="always")
def _axpy4(L, base, y0, y1, y2, y3, a, x0, x1, x2, x3):
    """:func:`_axpy` of four vectors with one read of the factor's row."""
    for bb in range(a):
        lv = L[base + bb]
        y0[bb] -= lv * x0
        y1[bb] -= lv * x1
        y2[bb] -= lv * x2
        y3[bb] -= lv * x3


@nb.njit(cache=True, fastmath=True, inline="always")
def _axpy(L, base, y, a, x):
    """y[b] -= L[base + b] x for b < a."""
    for bb in range(a):
        y[bb] -= L[base + bb] * x


@nb.njit(cache=True, inline="always")
def _neighbour(n, p, s):
    """The grid node in stencil slot s = (dx+1) + 3 (dy+1) + 9 (dz+1) of node p (periodic)."""
    i = p % n
    j = (p // n) % n
    kk = p // (n * n)
    return (((i + s % 3 - 1 + n) % n)
            + n * (((j + (s // 3) % 3 - 1 + n) % n) + n * ((kk + s // 9 - 1 + n) % n)))


@nb.njit(cache=True)
def _patch_residual(n, nodes, stype, S, pin, u, b, r):
    """r[t] = b_p - (K u)_p for the nodes p = nodes[t] of one patch (pinned operator; the pinned
    node is never a patch node). u, b: (N, 3, k); r: (m, 3, k)."""
    k = u.shape[2]
    for t in range(nodes.shape[0]):
        p = nodes[t]
        for c in range(3):
            for m in range(k):
                r[t, c, m] = 0.0
        ty = stype[p]
        for s in range(27):
            q = _neighbour(n, p, s)
            if q == pin:
                continue
            block_acc(S[ty, s], 0, 0, 3, 3, u, q, r, t, k, 1.0)
        for c in range(3):
            for m in range(k):
                r[t, c, m] = b[p, c, m] - r[t, c, m]


def _factorize(n, ptr, nodes, stype, S, pin, fptr, L):
    """Assemble every patch's principal submatrix K[nodes, nodes] (3 m x 3 m, DOF 3 t + c) from
    the stencil rows, factorize it (Cholesky, lower) and store the factor packed by rows
    (entry (a, b), b <= a, at fptr[q] + a (a + 1) / 2 + b). Parallel over patches."""
    for q in nb.prange(ptr.shape[0] - 1):
        a0 = ptr[q]
        m = ptr[q + 1] - a0
        if m == 0:
            continue
        pn = nodes[a0:a0 + m]
        A = np.zeros((3 * m, 3 * m))
        for t in range(m):
            p = pn[t]
            ty = stype[p]
            for s in range(27):
                g = _neighbour(n, p, s)
                if g == pin:
                    continue
                loc = np.searchsorted(pn, g)
                if loc < m and pn[loc] == g:
                    for r in range(3):
                        for c in range(3):
                            A[3 * t + r, 3 * loc + c] += S[ty, s, r, c]
        C = np.linalg.cholesky(A)
        off = fptr[q]
        for a in range(3 * m):
            base = off + a * (a + 1) // 2
            for bb in range(a + 1):
                L[base + bb] = C[a, bb]


@nb.njit(cache=True)
def _solve_patch(n, q, ptr, nodes, stype, S, pin, fptr, L, u, b):
    """u[patch q] += K_q^-1 (b - K u)[patch q], with its packed Cholesky factor."""
    k = u.shape[2]
    a0 = ptr[q]
    m = ptr[q + 1] - a0
    if m > 0:
        pn = nodes[a0:a0 + m]
        r = np.empty((m, 3, k))
        _patch_residual(n, pn, stype, S, pin, u, b, r)
        # the columns one after another (rows of y contiguous): dot products and axpys of
        # contiguous vectors, the packed factor read by rows in both solves
        # padded with zero columns to a multiple of four (a zero column stays zero): four
        # columns per read of the factor's row, the vectorized form
        wd = 1 if k == 1 else (4 if k <= 4 else 8)
        kp = wd * ((k + wd - 1) // wd)
        y = np.zeros((kp, 3 * m))
        for t in range(m):
            for c in range(3):
                for mm in range(k):
                    y[mm, 3 * t + c] = r[t, c, mm]
        off = fptr[q]
        for a in range(3 * m):                  # L y' = y
            base = off + a * (a + 1) // 2
            d = L[base + a]
            mm = 0
            while wd == 8 and mm + 8 <= kp:
                s0, s1, s2, s3, s4, s5, s6, s7 = _dot8(L, base, y[mm:mm + 8], a)
                y[mm, a] = (y[mm, a] - s0) / d
                y[mm + 1, a] = (y[mm + 1, a] - s1) / d
                y[mm + 2, a] = (y[mm + 2, a] - s2) / d
                y[mm + 3, a] = (y[mm + 3, a] - s3) / d
                y[mm + 4, a] = (y[mm + 4, a] - s4) / d
                y[mm + 5, a] = (y[mm + 5, a] - s5) / d
                y[mm + 6, a] = (y[mm + 6, a] - s6) / d
                y[mm + 7, a] = (y[mm + 7, a] - s7) / d
                mm += 8
            while mm + 4 <= kp:
                s0, s1, s2, s3 = _dot4(L, base, y[mm], y[mm + 1], y[mm + 2], y[mm + 3], a)
                y[mm, a] = (y[mm, a] - s0) / d
                y[mm + 1, a] = (y[mm + 1, a] - s1) / d
                y[mm + 2, a] = (y[mm + 2, a] - s2) / d
                y[mm + 3, a] = (y[mm + 3, a] - s3) / d
                mm += 4
            while mm < kp:
                y[mm, a] = (y[mm, a] - _dot(L, base, y[mm], a)) / d
                mm += 1
        for a in range(3 * m - 1, -1, -1):      # L^T x = y', column-oriented
            base = off + a * (a + 1) // 2
            d = L[base + a]
            mm = 0
            while wd == 8 and mm + 8 <= kp:
                for c in range(8):
                    y[mm + c, a] /= d
                _axpy8(L, base, y[mm:mm + 8], a)
                mm += 8
            while mm + 4 <= kp:
                x0, x1, x2, x3 = y[mm, a] / d, y[mm + 1, a] / d, y[mm + 2, a] / d, y[mm + 3, a] / d
                y[mm, a], y[mm + 1, a], y[mm + 2, a], y[mm + 3, a] = x0, x1, x2, x3
                _axpy4(L, base, y[mm], y[mm + 1], y[mm + 2], y[mm + 3], a, x0, x1, x2, x3)
                mm += 4
            while mm < kp:
                x = y[mm, a] / d
                y[mm, a] = x
                _axpy(L, base, y[mm], a, x)
                mm += 1
        for t in range(m):
            p = pn[t]
            for c in range(3):
                for mm in range(k):
                    u[p, c, mm] += y[mm, 3 * t + c]


def _solve_colour(n, which, bounds, ptr, nodes, stype, S, pin, fptr, L, u, b):
    """One colour of the multiplicative Schwarz sweep: every patch q in ``which`` (patches that
    do not couple) by :func:`_solve_patch`. Parallel over the groups ``which[bounds[g]:bounds[g +
    1]]``, one per thread (:meth:`ParticlePatches._groups`): the patches of a colour are
    independent, so the grouping does not change the numbers."""
    for g in nb.prange(bounds.shape[0] - 1):
        for w in range(bounds[g], bounds[g + 1]):
            _solve_patch(n, which[w], ptr, nodes, stype, S, pin, fptr, L, u, b)


factorize, factorize_serial = parallel_and_serial(_factorize)
solve_colour, solve_colour_serial = parallel_and_serial(_solve_colour)


class ParticlePatches:
    """The particle patches of one matrix-free fine operator (:class:`homogenize.solvers._matfree.
    MatFreeOperator`): ``forward(X, B)`` / ``backward(X, B)`` apply one multiplicative Schwarz
    sweep over them in place in X (colours in order / in reverse).

    centers_vox (P, 3), radii_vox (P,): the particles in voxel units (node (i, j, k) at (i, j, k));
    shell_voxels: the matrix shell around each particle included in its patch; max_nodes,
    bytes_per_node: which patches are kept (:func:`select_patches`; ``particles`` holds the
    indices of the particles that have one)."""

    def __init__(self, op, centers_vox, radii_vox, shell_voxels: float,
                 max_nodes: int | None = None, bytes_per_node: float | None = None):
        n = op.n
        self.shell_voxels = float(shell_voxels)
        centers_vox = np.asarray(centers_vox, dtype=float).reshape(-1, 3)
        radii_vox = np.asarray(radii_vox, dtype=float).reshape(-1)
        ptr, nodes = patch_nodes(centers_vox, radii_vox, n, self.shell_voxels, op.pin)
        self.particles = select_patches(ptr, n ** 3, max_nodes, bytes_per_node)
        self.n_particles = radii_vox.size
        parts = [nodes[ptr[q]:ptr[q + 1]] for q in self.particles]
        self.ptr = np.zeros(len(parts) + 1, dtype=np.int64)
        self.ptr[1:] = np.cumsum([p.size for p in parts])
        self.nodes = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
        del ptr, nodes, parts
        colour = patch_colours(centers_vox[self.particles],
                               radii_vox[self.particles] + self.shell_voxels, n)
        self.colours = [np.flatnonzero(colour == c).astype(np.int64)
                        for c in range(int(colour.max()) + 1 if colour.size else 0)]
        m3 = 3 * np.diff(self.ptr)
        self.fptr = np.zeros(m3.size + 1, dtype=np.int64)
        self.fptr[1:] = np.cumsum(m3 * (m3 + 1) // 2)
        self.L = np.empty(int(self.fptr[-1]), dtype=FACTOR_DTYPE)
        self.op = op
        big = op.n ** 3 >= 4096
        self._fact = factorize if big else factorize_serial
        self._solve = solve_colour if big else solve_colour_serial
        self._grouped = {}
        # one BLAS thread per factorization: the patches are factorized in numba's parallel
        # loop, and OpenBLAS threads started inside each of its threads oversubscribe the cores
        # (48^3, 100 particles, on a loaded 2-core machine: 15-46 s without the limit, 0.7-1.2 s
        # with it; the factors are bitwise the same)
        with threadpool_limits(limits=1, user_api="blas"):
            self._fact(n, self.ptr, self.nodes, op.stype, op.S, op.pin, self.fptr, self.L)

    @property
    def nbytes(self) -> int:
        return int(self.L.nbytes + self.nodes.nbytes + self.ptr.nbytes + self.fptr.nbytes)

    @property
    def node_share(self) -> float:
        """Patch nodes over grid nodes (a node in two patches counts twice)."""
        return float(self.nodes.size / self.op.n ** 3)

    def _groups(self, threads: int) -> list:
        """Per colour ``(which, bounds)``: its patches split into ``threads`` groups of about
        equal work, largest first to the least loaded group (LPT; work of a patch: its factor's
        entries, read twice, and its residual's 27 blocks per node). numba splits a parallel
        loop into equal contiguous ranges of iterations, so a loop over the patches themselves
        gave one thread the large particles (the RVE places them first): 1.1x on 2 threads at
        128^3 (800 particles), against ~2x over these groups (results/bench/threads.md)."""
        got = self._grouped.get(threads)
        if got is None:
            m = np.diff(self.ptr)
            work = (3 * m) * (3 * m + 1) + 243 * m
            got = []
            for col in self.colours:
                load = np.zeros(threads)
                members = [[] for _ in range(threads)]
                for q in col[np.argsort(-work[col], kind="stable")]:
                    g = int(np.argmin(load))
                    members[g].append(q)
                    load[g] += work[q]
                bounds = np.zeros(threads + 1, dtype=np.int64)
                bounds[1:] = np.cumsum([len(x) for x in members])
                which = np.array([q for x in members for q in x], dtype=np.int64)
                got.append((which, bounds))
            self._grouped[threads] = got
        return got

    def _sweep(self, X, B, order):
        op = self.op
        k = X.shape[1]
        u, b = X.reshape(-1, 3, k), B.reshape(-1, 3, k)
        groups = self._groups(nb.get_num_threads() if self._solve is solve_colour else 1)
        for c in order:
            which, bounds = groups[c]
            self._solve(op.n, which, bounds, self.ptr, self.nodes, op.stype, op.S, op.pin,
                        self.fptr, self.L, u, b)

    def forward(self, X, B):
        self._sweep(X, B, range(len(self.colours)))

    def backward(self, X, B):
        self._sweep(X, B, range(len(self.colours) - 1, -1, -1))
