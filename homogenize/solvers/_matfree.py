"""Matrix-free periodic voxel stiffness and a geometric multigrid preconditioner for it.

The stiffness of the periodic Q1 voxel grid (:mod:`homogenize.voxels._assembly`) is held as ELEMENT
TYPES: ``etype`` (n^3,) gives every voxel an index into a table ``Ktab`` (T, 24, 24) of element
matrices (DOF ``3 a + c``, corner ``a = ax + 2 ay + 4 az``). The isotropic phases share one
matrix each (``lambda K_lam + mu K_mu``); every cut (composite) voxel has its own. The first
``n_shared`` types are the shared ones.

``K u`` is a gather over nodes (each node sums its 27-block stencil row: parallel over nodes, no
write races), for k right-hand sides at once (``u`` of shape (N, 3, k)). A node whose 8 voxels
all have the same shared type uses that type's stencil; every other node has its own row,
assembled once from its 8 element matrices (:func:`node_stencils`), so the operator keeps no
element matrices: 243 multiply-adds per column and node everywhere.

Multigrid: trilinear prolongation from the (n/2)^3 grid. The Galerkin coarse operator ``P^T K P``
is built element by element: a coarse voxel's matrix is ``sum_c P_c^T K_child(c) P_c`` over its 8
children ``c`` with ``P_c`` fixed per child position, so a coarse voxel whose children all share
one type gets a shared coarse type, and the fine matrix is never assembled. The coarsest
geometric level is assembled as 3x3 BSR and handed to pyamg smoothed aggregation
(:class:`homogenize.solvers.BlockVCycle`). Every matrix-free level is smoothed by 8-colour block
Gauss-Seidel (forward before, backward after the coarse correction: a symmetric V-cycle).

Rigid translations: one node is pinned (its row and column replaced by ``scale * I``), the same
way as the assembled solver in :mod:`homogenize.cell.problem`; the pinned node of each coarser level is
the coarse node at the same position (the pin has even coordinates on every level).
"""
from __future__ import annotations

import numpy as np
import numba as nb
import scipy.sparse as sp

from micro.common.jit import parallel_and_serial

from homogenize.voxels import _assembly as asm
from homogenize.voxels import _kernels as kn
from homogenize.voxels._kernels import block_acc
from homogenize.solvers.amg import zeros_block

__all__ = ["ElementField", "element_field", "MatFreeOperator", "coarsen", "GeometricVCycle",
           "child_prolongations", "prolongation_matrix", "typed_bsr"]

# per node-neighbour slot s = (dx+1) + 3 (dy+1) + 9 (dz+1): for corner a, the corner b = a + d of
# the same voxel, or -1
_TAB = asm._stencil_tables()


# ------------------------------------------------------------------------------------------------
# numba kernels (contiguous arrays in, caller-allocated output, cache=True)
# ------------------------------------------------------------------------------------------------

def _node_op(n, nodes, stype, S, pin, pin_scale, u, b, dinv, out, mode):
    """For the nodes ``nodes`` (int64), with ``(K u)_p`` the matrix-free product (pinned node
    ``pin``: row and column replaced by ``pin_scale I``):

    mode 0: out[t] = (K u)_p;  mode 1: out[t] = b_p - (K u)_p  (p = nodes[t]);
    mode 2: one block Gauss-Seidel update in place, u[p] += dinv[p] (b_p - (K u)_p); out is
    scratch of len(nodes) rows. The nodes of one Gauss-Seidel call must not share a voxel.
    mode 3: mode 2 for the first forward sweep of an even grid from u = 0 over the 8 parity
    colours in order (colour c = (i & 1) + 2 (j & 1) + 4 (kk & 1)): only the neighbours of a
    lower colour are nonzero yet, so the blocks of the others (and the node's own) are skipped
    -- the same sums as mode 2 without its products with exact zeros (13 of 27 blocks on
    average).
    u, b: (N, 3, k); out: (len(nodes), 3, k); stype (N,) int32: every node's row in the stencil
    table S (T, 27, 3, 3) (block of neighbour slot s = (dx+1) + 3 (dy+1) + 9 (dz+1)).

    Loop shape (measured, 64^3, 2 threads: 1.3-1.5x over one multiply-add loop per matrix
    entry): every 3x3 block is read once into scalars and applied to all k columns; a node away
    from the grid faces reaches its 27 neighbours by fixed offsets (no wrapping).
    """
    k = u.shape[2]
    offs = np.empty(27, dtype=np.int64)
    flip = np.empty(27, dtype=np.int64)     # the parity colour bits a neighbour slot flips
    for s in range(27):
        offs[s] = (s % 3 - 1) + n * ((s // 3) % 3 - 1) + n * n * (s // 9 - 1)
        flip[s] = (s % 3 != 1) + 2 * ((s // 3) % 3 != 1) + 4 * (s // 9 != 1)
    for t in nb.prange(nodes.shape[0]):
        p = nodes[t]
        i = p % n
        j = (p // n) % n
        kk = p // (n * n)
        for r in range(3):
            for m in range(k):
                out[t, r, m] = 0.0
        if p == pin:
            for r in range(3):
                for m in range(k):
                    out[t, r, m] = pin_scale * u[p, r, m]
        else:
            ty = stype[p]
            inner = 0 < i < n - 1 and 0 < j < n - 1 and 0 < kk < n - 1
            col = (i & 1) + 2 * (j & 1) + 4 * (kk & 1)
            for s in range(27):
                if mode == 3 and (col ^ flip[s]) >= col:
                    continue
                if inner:
                    q = p + offs[s]
                else:
                    sx, sy, sz = s % 3 - 1, (s // 3) % 3 - 1, s // 9 - 1
                    q = ((i + sx + n) % n) + n * (((j + sy + n) % n) + n * ((kk + sz + n) % n))
                if q == pin:
                    continue
                block_acc(S[ty, s], 0, 0, 3, 3, u, q, out, t, k, 1.0)
        if mode == 1:
            for r in range(3):
                for m in range(k):
                    out[t, r, m] = b[p, r, m] - out[t, r, m]
        elif mode >= 2:
            for r in range(3):
                for m in range(k):
                    out[t, r, m] = b[p, r, m] - out[t, r, m]
            for r in range(3):
                for m in range(k):
                    acc = 0.0
                    for c in range(3):
                        acc += dinv[p, r, c] * out[t, c, m]
                    u[p, r, m] += acc


def _diag_blocks(n, etype, Ktab, out):
    """out (N, 3, 3): the 3x3 diagonal block of every node, summed over its 8 voxels."""
    for p in nb.prange(n * n * n):
        i = p % n
        j = (p // n) % n
        kk = p // (n * n)
        for r in range(3):
            for c in range(3):
                out[p, r, c] = 0.0
        for ca in range(8):
            ax = ca & 1
            ay = (ca >> 1) & 1
            az = (ca >> 2) & 1
            v = (i - ax + n) % n + n * (((j - ay + n) % n) + n * ((kk - az + n) % n))
            e = etype[v]
            for r in range(3):
                for c in range(3):
                    out[p, r, c] += Ktab[e, 3 * ca + r, 3 * ca + c]


def _prolong_add(nc, xc, x):
    """x += P xc: trilinear interpolation from the periodic nc^3 grid to the (2 nc)^3 grid.
    xc (nc^3, 3, k), x ((2 nc)^3, 3, k)."""
    n = 2 * nc
    k = x.shape[2]
    for p in nb.prange(n * n * n):
        i = p % n
        j = (p // n) % n
        kk = p // (n * n)
        ni = 1 if i % 2 == 0 else 2
        nj = 1 if j % 2 == 0 else 2
        nk = 1 if kk % 2 == 0 else 2
        for a in range(nk):
            K = (kk // 2 + a) % nc
            wk = 1.0 if nk == 1 else 0.5
            for bj in range(nj):
                J = (j // 2 + bj) % nc
                wj = 1.0 if nj == 1 else 0.5
                for ci in range(ni):
                    I = (i // 2 + ci) % nc
                    w = wk * wj * (1.0 if ni == 1 else 0.5)
                    q = I + nc * (J + nc * K)
                    for r in range(3):
                        for m in range(k):
                            x[p, r, m] += w * xc[q, r, m]


def _restrict_planes(nc, x, z0, nz, xc, K0, K1):
    """xc = P^T x (full weighting, the transpose of :func:`_prolong_add`) for the coarse planes
    K0 <= K < K1 only, from the fine planes z0, z0 + 1, ..., z0 + nz - 1 (mod 2 nc) held in x
    ((nz (2 nc)^2, 3, k)); those must include 2 K0 - 1 ... 2 K1 - 1."""
    n = 2 * nc
    k = x.shape[2]
    m = nc * nc
    for t in nb.prange((K1 - K0) * m):
        q = K0 * m + t
        I = q % nc
        J = (q // nc) % nc
        K = q // m
        for r in range(3):
            for mm in range(k):
                xc[q, r, mm] = 0.0
        for dz in range(-1, 2):
            wz = 1.0 if dz == 0 else 0.5
            fk = ((2 * K + dz + n) % n - z0 + n) % n
            for dy in range(-1, 2):
                wy = 1.0 if dy == 0 else 0.5
                fj = (2 * J + dy + n) % n
                for dx in range(-1, 2):
                    w = wz * wy * (1.0 if dx == 0 else 0.5)
                    fi = (2 * I + dx + n) % n
                    p = fi + n * (fj + n * fk)
                    for r in range(3):
                        for mm in range(k):
                            xc[q, r, mm] += w * x[p, r, mm]


node_op, node_op_serial = parallel_and_serial(_node_op)
diag_blocks, _ = parallel_and_serial(_diag_blocks)
prolong_add, _ = parallel_and_serial(_prolong_add)
restrict_planes, _ = parallel_and_serial(_restrict_planes)


def restrict(nc, x, xc):
    """xc = P^T x (full weighting), the transpose of :func:`prolong_add`: the plane kernel
    over every coarse plane from the whole fine grid (one kernel, the same sums in the same
    order)."""
    restrict_planes(nc, x, 0, 2 * nc, xc, 0, nc)


# ------------------------------------------------------------------------------------------------
# element types
# ------------------------------------------------------------------------------------------------

class ElementField:
    """Element matrices of a periodic n^3 voxel grid by type (see the module docstring)."""

    def __init__(self, n: int, etype: np.ndarray, Ktab: np.ndarray, n_shared: int):
        self.n = int(n)
        self.etype = np.ascontiguousarray(etype, dtype=np.int32).reshape(-1)
        self.Ktab = np.ascontiguousarray(Ktab, dtype=np.float64)
        self.n_shared = int(n_shared)
        if self.etype.size != self.n ** 3:
            raise ValueError("etype must have n^3 entries")

    @property
    def nbytes(self) -> int:
        return int(self.etype.nbytes + self.Ktab.nbytes)

    def voxel_matrices(self, vox) -> np.ndarray:
        return self.Ktab[self.etype[np.asarray(vox)]]


def element_field(lam, mu, h: float, composite=None) -> ElementField:
    """Element types of the isotropic fields ``lam``, ``mu`` (n, n, n) [Pa] plus the cut voxels of
    a :class:`homogenize.cell.problem._Composite` (their matrix: the isotropic base plus the same
    difference the assembled solver adds, so both operators agree to round-off)."""
    n = lam.shape[0]
    inv, shared = asm.voxel_types(lam, mu, h)
    T0 = len(shared)
    if composite is None or composite.vox.size == 0:
        return ElementField(n, inv, shared, T0)
    Ktab = np.empty((T0 + composite.vox.size, 24, 24))
    Ktab[:T0] = shared
    for sl, dK in composite._chunks():
        vox = composite.vox[sl]
        Ktab[T0 + sl.start:T0 + sl.start + vox.size] = shared[inv[vox]] + dK
    etype = inv.copy()
    etype[composite.vox] = T0 + np.arange(composite.vox.size, dtype=np.int32)
    return ElementField(n, etype, Ktab, T0)


def _shared_stencils(field: ElementField) -> np.ndarray:
    """(n_shared, 27, 3, 3): the 27-block row of a node all of whose voxels have one shared type."""
    S = np.zeros((max(field.n_shared, 1), 27, 3, 3))
    for t in range(field.n_shared):
        K = field.Ktab[t]
        for a in range(8):
            for s in range(27):
                b = _TAB[a, s]
                if b >= 0:
                    S[t, s] += K[3 * a:3 * a + 3, 3 * b:3 * b + 3]
    return S


def _node_types(field: ElementField) -> np.ndarray:
    """(N,) int32: the shared type of all 8 voxels around each node, or -1."""
    n = field.n
    e = field.etype.reshape(n, n, n)
    first = e.copy()
    same = np.ones((n, n, n), dtype=bool)
    for ax, ay, az in asm.CORNERS:
        same &= np.roll(e, shift=(az, ay, ax), axis=(0, 1, 2)) == first
    out = np.where(same & (first < field.n_shared), first, -1)
    return np.ascontiguousarray(out.reshape(-1), dtype=np.int32)


#: the offsets (-1, 0, 1) of every axis in slot order: with it the assembly kernel
#: (:func:`homogenize.voxels._kernels.typed_stencil_blocks`) writes a node's 27 blocks by slot
#: s = (dx+1) + 3 (dy+1) + 9 (dz+1) (its sorted BSR order differs at the grid faces)
_SLOT_ORDER = np.array([[-1, 0, 1]] * 3, dtype=np.int64)


def node_stencils(field: ElementField) -> tuple[np.ndarray, np.ndarray, int]:
    """Every node's 27-block stencil row as an index into a table: ``(stype, S, n_own)`` with
    ``stype`` (N,) int32, ``S`` (T, 27, 3, 3) and the number of nodes with their own row. A node
    whose 8 voxels share one shared type points to that type's stencil (the first
    ``max(n_shared, 1)`` rows); every other node (next to a cut voxel or a phase boundary) has
    its own row, assembled from its 8 element matrices. Against the 8 x 8 blocks of the element
    matrices the product then reads 27 blocks per node everywhere (measured at 64^3, bench RVE,
    11 % own rows: product and Gauss-Seidel sweep ~1.4x faster), and the table of own rows is
    about as large as the cut voxels' element matrices."""
    n = field.n
    ntype = _node_types(field)
    own = np.flatnonzero(ntype < 0)
    ns = max(field.n_shared, 1)
    S = np.empty((ns + own.size, 27, 3, 3))
    S[:ns] = _shared_stencils(field)
    if own.size:
        scratch = np.empty(27 * own.size, dtype=np.int32 if n ** 3 < 2 ** 31 else np.int64)
        kern = (kn.typed_stencil_blocks if own.size >= kn.PARALLEL_MIN_ROWS
                else kn.typed_stencil_blocks_serial)
        kern(n, own, field.etype, field.Ktab, _TAB, _SLOT_ORDER, scratch,
             S[ns:].reshape(-1, 3, 3))
    stype = ntype
    stype[own] = ns + np.arange(own.size, dtype=np.int32)
    return stype, S, int(own.size)


# ------------------------------------------------------------------------------------------------
# the operator
# ------------------------------------------------------------------------------------------------

class MatFreeOperator:
    """``K u`` of an :class:`ElementField` (pinned node ``pin`` with diagonal ``scale I``; the
    scale defaults to the mean diagonal entry, as in :class:`homogenize.cell.problem._CellSolver`).
    Vectors: (3 N, k) arrays, C-contiguous, float64."""

    def __init__(self, field: ElementField, pin: int = -1, pin_scale: float | None = None):
        self.n = field.n
        N = self.n ** 3
        self.shape = (3 * N, 3 * N)
        self.stype, self.S, n_own = node_stencils(field)   # no element matrices kept
        #: share of the nodes with their own stencil row
        self.own_share = n_own / N
        #: the nodes with their own stencil row (next to a cut voxel or a phase boundary) have
        #: stype >= n_shared_rows
        self.n_shared_rows = self.S.shape[0] - n_own
        D = np.empty((N, 3, 3))
        diag_blocks(self.n, field.etype, field.Ktab, D)
        self.mean_diag = float(np.mean(np.einsum("pii->pi", D)))
        self.pin = int(pin)
        self.pin_scale = self.mean_diag if pin_scale is None else float(pin_scale)
        if self.pin >= 0:
            D[self.pin] = self.pin_scale * np.eye(3)
        #: the diagonal blocks (N, 3, 3); None once :attr:`dinv` has been formed (the sweeps need
        #: only the inverses: one array of 72 B per node less)
        self.diag = D
        self._dinv = None
        self._op = node_op if N >= 4096 else node_op_serial
        self._all = np.arange(N, dtype=np.int64)
        self._tmp = {}

    @property
    def dinv(self) -> np.ndarray:
        if self._dinv is None:
            from homogenize.solvers.amg import _block_inverse
            self._dinv = np.ascontiguousarray(_block_inverse(self.diag))
            self.diag = None
        return self._dinv

    def _run(self, nodes, X, B, out, mode):
        k = X.shape[-1]
        self._op(self.n, nodes, self.stype, self.S, self.pin, self.pin_scale,
                 X.reshape(-1, 3, k), B.reshape(-1, 3, k),
                 self.dinv if mode >= 2 or self.diag is None else self.diag,
                 out.reshape(-1, 3, k), mode)          # (modes 0 and 1 do not read it)

    def node_residual(self, nodes, X, B, out) -> None:
        """``out[t] = (B - K X)`` at the grid nodes ``nodes[t]`` (int64), ``out`` of shape
        (len(nodes), 3, k) for X, B of shape (3 n^3, k), C-contiguous float64."""
        self._run(nodes, X, B, out, 1)

    def __matmul__(self, X):
        X = np.ascontiguousarray(X, dtype=np.float64)
        one = X.ndim == 1
        X2 = X[:, None] if one else X
        Y = np.empty_like(X2)
        self._run(self._all, X2, X2, Y, 0)
        return Y[:, 0] if one else Y

    __call__ = __matmul__

    def residual(self, X, B):
        X = np.ascontiguousarray(X, dtype=np.float64)
        B = np.ascontiguousarray(B, dtype=np.float64)
        out = np.empty_like(X)
        self._run(self._all, X, B, out, 1)
        return out

    def _scratch(self, k, colours=None, rows=None):
        """Scratch of ``rows`` nodes (default: the largest colour class in ``colours``) for k
        columns: a view of one flat buffer kept for every k (the block loses columns as they
        converge)."""
        rows = max(c.size for c in colours) if rows is None else int(rows)
        size = rows * 3 * k
        flat = self._tmp.get("flat")
        if flat is None or flat.size < size:
            flat = self._tmp["flat"] = np.empty(size)
        return flat[:size].reshape(rows, 3, k)

    def restricted_residual(self, X, B, Rc, planes: int | None = None):
        """``Rc = P^T (B - K X)`` (full weighting, :func:`restrict`) onto the (n/2)^3 grid, the
        residual taken by slabs of fine planes (``planes`` coarse planes at a time, default
        n/16) so that no fine residual block is held: the same numbers as restricting
        :meth:`residual` (each fine node's residual and each coarse sum as there). A slab's last
        fine plane is the next one's first (kept, not computed again)."""
        n, k = self.n, X.shape[1]
        nc = n // 2
        step = max(2, nc // 8) if planes is None else max(1, int(planes))
        step = min(step, nc)
        X = np.ascontiguousarray(X, dtype=np.float64)
        B = np.ascontiguousarray(B, dtype=np.float64)
        m = n * n
        plane = np.arange(m, dtype=np.int64)
        rc = Rc.reshape(-1, 3, k)
        buf = self._scratch(k, rows=(2 * step + 1) * m)
        last = 0
        for K0 in range(0, nc, step):
            K1 = min(nc, K0 + step)
            z0 = (2 * K0 - 1) % n
            nz = min(2 * (K1 - K0) + 1, n)
            if K0 == 0 or nz == n:
                first = 0                               # every plane of the slab computed
            else:                                       # the previous slab's last plane
                buf[:m] = buf[last * m:(last + 1) * m]
                first = 1
            nodes = (((z0 + np.arange(first, nz, dtype=np.int64)) % n)[:, None] * m
                     + plane[None, :]).reshape(-1)
            self.node_residual(nodes, X, B, buf[first * m:nz * m])
            restrict_planes(nc, buf[:nz * m], z0, nz, rc, K0, K1)
            last = nz - 1

    def gauss_seidel(self, X, B, colours):
        """Block Gauss-Seidel sweeps over the node colour classes ``colours``, in place in X."""
        tmp = self._scratch(X.shape[1], colours)
        for c in colours:
            self._run(c, X, B, tmp, 2)

    def gauss_seidel_from_zero(self, X, B, colours):
        """``gauss_seidel(X, B, colours)`` for X = 0 (checked by the caller: the V-cycle's
        pre-smoothing). On an even grid whose first 8 classes of ``colours`` are the parity
        colours in order (:func:`grid_colours`), that first sweep skips the neighbours that are
        still zero (same result to the last bit, ~half the work of a sweep)."""
        n = self.n

        def parity(p):
            return (p % n) % 2 + 2 * ((p // n) % n % 2) + 4 * ((p // (n * n)) % 2)
        if n % 2 or len(colours) < 8 or any(c.size and parity(int(c[0])) != i
                                            for i, c in enumerate(colours[:8])):
            return self.gauss_seidel(X, B, colours)
        tmp = self._scratch(X.shape[1], colours[:8])
        for c in colours[:8]:
            self._run(c, X, B, tmp, 3)
        if len(colours) > 8:
            self.gauss_seidel(X, B, colours[8:])

    def interface_nodes(self, halo: int = 1) -> np.ndarray:
        """(N,) bool: the nodes with their own stencil row (next to a cut voxel or a phase
        boundary), grown by ``halo`` nodes in every direction (periodic)."""
        n = self.n
        m = (self.stype >= self.n_shared_rows).reshape(n, n, n)
        for _ in range(int(halo)):
            for ax in range(3):
                m = m | np.roll(m, 1, ax) | np.roll(m, -1, ax)
        return m.reshape(-1)

    def release(self):
        self._tmp.clear()


def typed_rows_bsr(field: ElementField, rows) -> sp.bsr_matrix:
    """Block rows ``rows`` of the (unpinned) assembled matrix of an element field: 3x3 BSR of
    shape (3 len(rows), 3 N), sorted indices."""
    n = field.n
    N = n ** 3
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    m = rows.size
    idx_dtype = np.int32 if 27 * max(m, N) < 2 ** 31 else np.int64
    indices = np.empty(27 * m, dtype=idx_dtype)
    data = np.empty((27 * m, 3, 3))
    kern = (kn.typed_stencil_blocks if m >= kn.PARALLEL_MIN_ROWS
            else kn.typed_stencil_blocks_serial)
    kern(n, rows, field.etype, field.Ktab, _TAB, asm._AXIS_ORDER, indices, data)
    indptr = np.arange(0, 27 * m + 1, 27, dtype=idx_dtype)
    A = sp.bsr_matrix((data, indices, indptr), shape=(3 * m, 3 * N))
    A.has_sorted_indices = True
    return A


def typed_bsr(field: ElementField, pin: int = -1, pin_scale: float | None = None) -> sp.bsr_matrix:
    """The assembled periodic matrix of an element field: 3x3 BSR with sorted indices (pinned
    like :class:`MatFreeOperator` when ``pin >= 0``)."""
    A = typed_rows_bsr(field, np.arange(field.n ** 3, dtype=np.int64))
    if pin >= 0:
        if pin_scale is None:
            pin_scale = float(np.mean(A.diagonal()))
        ptr, ind = A.indptr, A.indices
        A.data[ind == pin] = 0.0
        A.data[ptr[pin]:ptr[pin + 1]] = 0.0
        row = np.arange(ptr[pin], ptr[pin + 1])
        A.data[row[ind[row] == pin][0]] = pin_scale * np.eye(3)
    return A


# ------------------------------------------------------------------------------------------------
# geometric coarsening
# ------------------------------------------------------------------------------------------------

def stiffness_times_sparse(field: ElementField, Z: sp.spmatrix, pin: int = -1,
                           chunk: int = 32768) -> sp.csr_matrix:
    """``K Z`` for a sparse Z (3 N, m) (the deflation space of the stiff particles) without the
    whole matrix: only the block rows of nodes within one node of Z's support are assembled,
    ``chunk`` block rows at a time (each row of the product is its own sum, so the result does
    not depend on the chunks; at most 27 x 72 B x chunk of rows alive at once).
    With ``pin >= 0`` the pinned row is zero (Z must vanish at the pinned node)."""
    n = field.n
    N = n ** 3
    Z = sp.csr_matrix(Z)
    support = np.zeros(N, dtype=bool)
    support[np.flatnonzero(np.diff(Z.indptr)) // 3] = True
    s3 = support.reshape(n, n, n)
    near = np.zeros_like(s3)
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                near |= np.roll(s3, shift=(dz, dy, dx), axis=(0, 1, 2))
    rows = np.flatnonzero(near.reshape(-1))
    if pin >= 0:
        rows = rows[rows != pin]
    parts = []
    for s in range(0, rows.size, int(chunk)):
        r = rows[s:s + int(chunk)]
        out = (sp.csr_matrix(typed_rows_bsr(field, r)) @ Z).tocoo()
        r3 = np.repeat(3 * r, 3) + np.tile(np.arange(3), r.size)
        parts.append((out.data, r3[out.row], out.col))
        del out
    if not parts:
        return sp.csr_matrix((3 * N, Z.shape[1]))
    data, ri, ci = (np.concatenate(a) for a in zip(*parts))
    del parts
    return sp.csr_matrix((data, (ri, ci)), shape=(3 * N, Z.shape[1]))


def child_prolongations() -> np.ndarray:
    """(8, 24, 24): ``P_c`` for child position c = cx + 2 cy + 4 cz of a coarse voxel: the
    trilinear interpolation of the coarse voxel's 8 corners at the child's 8 corners, x I_3."""
    P = np.zeros((8, 8, 8))
    for c, (cx, cy, cz) in enumerate(asm.CORNERS):
        for b, (bx, by, bz) in enumerate(asm.CORNERS):
            x = np.array([cx + bx, cy + by, cz + bz]) / 2.0
            for A, corner in enumerate(asm.CORNERS):
                P[c, b, A] = np.prod(np.where(corner == 1, x, 1.0 - x))
    return np.einsum("cbA,ij->cbiAj", P, np.eye(3)).reshape(8, 24, 24)


def prolongation_matrix(nc: int) -> sp.csr_matrix:
    """The global trilinear prolongation from the periodic nc^3 to the (2 nc)^3 grid, 3 DOF per
    node (for tests; the solver uses :func:`prolong_add` / :func:`restrict`)."""
    n = 2 * nc
    rows, cols, vals = [], [], []
    for i in range(n):
        if i % 2 == 0:
            rows.append(i); cols.append(i // 2); vals.append(1.0)
        else:
            rows += [i, i]; cols += [i // 2, (i // 2 + 1) % nc]; vals += [0.5, 0.5]
    p = sp.csr_matrix((vals, (rows, cols)), shape=(n, nc))
    return sp.kron(sp.kron(sp.kron(p, p), p), sp.identity(3)).tocsr()


def coarsen(field: ElementField, chunk: int = 4096) -> ElementField:
    """Galerkin coarse element field ``P^T K P`` on the (n/2)^3 grid, element by element.

    A coarse voxel whose 8 children all have the same shared type t gets the shared coarse type t
    (``sum_c P_c^T K_t P_c``, computed once); every other coarse voxel its own matrix.
    """
    n = field.n
    if n % 2:
        raise ValueError("geometric coarsening needs an even number of voxels per edge")
    nc = n // 2
    e = field.etype.reshape(n, n, n)
    kids = np.stack([e[cz::2, cy::2, cx::2].reshape(-1) for cx, cy, cz in asm.CORNERS], axis=1)
    Pc = child_prolongations()
    uniform = np.all(kids == kids[:, :1], axis=1) & (kids[:, 0] < field.n_shared)
    ns = field.n_shared
    shared = np.einsum("cia,tij,cjb->tab", Pc, field.Ktab[:ns], Pc, optimize=True)
    own = np.flatnonzero(~uniform)
    Ktab = np.empty((ns + own.size, 24, 24))
    Ktab[:ns] = shared
    for s in range(0, own.size, chunk):
        sl = own[s:s + chunk]
        acc = np.zeros((sl.size, 24, 24))
        for c in range(8):
            Kc = field.Ktab[kids[sl, c]]
            acc += Pc[c].T @ Kc @ Pc[c]
        Ktab[ns + s:ns + s + sl.size] = acc
    etype = np.where(uniform, kids[:, 0], 0).astype(np.int32)
    etype[own] = ns + np.arange(own.size, dtype=np.int32)
    return ElementField(nc, etype, Ktab, ns)


def grid_colours(n: int) -> list[np.ndarray]:
    from homogenize.solvers.amg import grid_colours as gc
    return gc(n)


class _AMGSummary:
    """Levels and operator complexity of a pyamg hierarchy, without its matrices."""

    def __init__(self, ml):
        self.levels = [None] * len(ml.levels)
        self._complexity = float(ml.operator_complexity())
        self.shapes = [lv.A.shape[0] for lv in ml.levels]

    def operator_complexity(self) -> float:
        return self._complexity


class _GeoLevel:
    def __init__(self, op: MatFreeOperator, interface_sweeps: int, interface_halo: int):
        self.op = op
        self.n = op.n
        self.colours = grid_colours(op.n)
        # the colour classes restricted to the interface nodes (GeometricVCycle: local sweeps)
        if interface_sweeps > 0:
            mask = op.interface_nodes(interface_halo)
            self.interface_colours = [c[mask[c]] for c in self.colours]
            self.interface_share = float(mask.mean())
        else:
            self.interface_colours, self.interface_share = [], 0.0


class GeometricVCycle:
    """Symmetric V-cycle: matrix-free levels (8-colour block Gauss-Seidel, trilinear transfer)
    down to a grid of at most ``assembled_max`` voxels per edge (at least one matrix-free level:
    the fine one), then the assembled Galerkin matrix of that grid with a pyamg smoothed-
    aggregation V-cycle (:class:`homogenize.solvers.BlockVCycle`).

    field : fine ElementField; pin : pinned fine node (even coordinates on every matrix-free
    level); pin_scale : its diagonal; amg_options : :class:`homogenize.solvers.AMGOptions` of
    the coarse hierarchy (``max_coarse`` None: up to 600 blocks, below);
    coarse : "amg" (default) or "lu": the assembled grid solved exactly by a sparse LU (small
    grids only: it tells whether the geometric levels or the AMG below them limit convergence);
    sweeps : Gauss-Seidel sweeps per side over all nodes; interface_sweeps : further sweeps per
    side over the interface nodes only (those with their own stencil row, next to a cut voxel or
    a phase boundary, grown by ``interface_halo`` nodes): extra sweeps confined to where the
    error the trilinear coarse grid cannot take is ("local relaxation", as Brandt & Livne,
    Multigrid Techniques, 2nd ed. 2011, use it near singularities).
    patches : None or a :class:`homogenize.solvers._patches.ParticlePatches` of the fine operator: its
    forward sweep after the fine pre-smoothing, its backward sweep before the fine post-smoothing.
    Pre-smoothing: the full sweeps, then the interface ones (then the patches); post-smoothing: the
    same in reverse order and colours, so the cycle stays symmetric.
    """

    def __init__(self, field: ElementField, *, pin: int, pin_scale: float, h: float,
                 amg_options, assembled_max: int = 64, fine_op: MatFreeOperator | None = None,
                 sweeps: int = 1, coarse: str = "amg", interface_sweeps: int = 0,
                 interface_halo: int = 1, patches=None):
        from homogenize.solvers.amg import BlockVCycle, grid_node_coordinates, rigid_body_modes, smoothed_aggregation
        if coarse not in ("amg", "lu"):
            raise ValueError(f"coarse must be 'amg' or 'lu', got {coarse!r}")
        self.levels = []
        self.sweeps = int(sweeps)
        self.patches = patches
        f, p = field, pin
        op = fine_op if fine_op is not None else MatFreeOperator(f, p, pin_scale)
        self.interface_sweeps = int(interface_sweeps)
        geo = dict(interface_sweeps=self.interface_sweeps, interface_halo=int(interface_halo))
        self.levels.append(_GeoLevel(op, **geo))
        self.field_bytes = [f.nbytes]
        while True:
            n = f.n
            ii, jj, kk = p % n, (p // n) % n, p // (n * n)
            if ii % 2 or jj % 2 or kk % 2:
                raise ValueError("the pinned node needs even coordinates on every level")
            nc = n // 2
            pc = ii // 2 + nc * (jj // 2 + nc * (kk // 2))
            f = coarsen(f)
            self.field_bytes.append(f.nbytes)
            p = pc
            if nc <= assembled_max or nc % 2 or nc < 8:
                break
            # the coarse level's own pin scale: its mean diagonal (the preconditioner only needs
            # an SPD operator; the Galerkin operator of the unpinned matrix with the pin replaced)
            self.levels.append(_GeoLevel(MatFreeOperator(f, p, None), **geo))
        cop = MatFreeOperator(f, p, None) if coarse == "amg" else None
        Ac = typed_bsr(f, pin=p, pin_scale=cop.pin_scale if cop is not None else None)
        if coarse == "lu":              # diagnostics: the two-grid method with an exact coarse solve
            from scipy.sparse.linalg import splu
            lu = splu(sp.csc_matrix(Ac))
            self.coarse = lambda B: lu.solve(np.asarray(B))
            self.ml = None
        else:
            B = rigid_body_modes(grid_node_coordinates(f.n))
            # pyamg counts max_coarse in blocks, and its coarse levels have 6 unknowns per
            # aggregate (the rigid modes): at most 600 blocks (3600 unknowns) on the coarsest AMG
            # level, which BlockVCycle then factorizes densely (the sparse LU of a 7188-unknown,
            # nearly dense coarsest matrix took 10 s to set up at 32^3)
            opts = amg_options
            if opts.max_coarse is None:
                opts = opts.replace(max_coarse=max(50, min(600, Ac.shape[0] // 120)))
            ml = smoothed_aggregation(Ac, B, opts)
            del B
            self.coarse = BlockVCycle(ml, fine_colours=grid_colours(f.n))
            # its finest level is this geometric grid: smoothed and residuals taken matrix-free
            # (same matrix to round-off, same time: measured on the 64^3 bench RVE's 32^3 grid)
            # so that its assembled blocks (27 x 72 B per node: 0.5 GB for the 64^3 grid under a
            # 128^3 cell) are freed once pyamg's setup has them
            if self.coarse.levels:
                self.coarse.levels[0].use_operator(cop)
            # keep what the V-cycle uses (its own copies of A and P per level), not pyamg's R, B
            self.ml = _AMGSummary(ml)
            del ml
        self.coarse_n = f.n
        self.coarse_op = cop
        del Ac, f
        self.shape = self.levels[0].op.shape
        # the smoothers' inverse diagonal blocks now (set-up work: formed on first use they
        # fell into the first V-cycle, 1.7 s of the solve at 128^3)
        for L in self.levels:
            L.op.dinv
        if cop is not None:
            cop.dinv

    def cycle(self, level: int, B):
        """One V-cycle from ``level`` down (0: the fine grid, the whole cycle; ``len(levels)``:
        the coarse solve alone) on the C-contiguous block B (3 n_level^3, k); returns X."""
        return self._cycle(level, B)

    def _cycle(self, i, B):
        if i == len(self.levels):
            return self.coarse(B)
        L = self.levels[i]
        k = B.shape[1]
        X = zeros_block(B)
        nc = len(L.colours)
        fwd = ([L.colours[c] for c in range(nc)] * self.sweeps
               + L.interface_colours * self.interface_sweeps)
        bwd = fwd[::-1]
        L.op.gauss_seidel_from_zero(X, B, fwd)
        if i == 0 and self.patches is not None:
            self.patches.forward(X, B)
        ncg = L.n // 2
        Rc = np.empty((3 * ncg ** 3, k))
        L.op.restricted_residual(X, B, Rc)      # no fine residual block
        Xc = np.ascontiguousarray(self._cycle(i + 1, Rc))
        del Rc
        prolong_add(ncg, Xc.reshape(-1, 3, k), X.reshape(-1, 3, k))
        del Xc
        if i == 0 and self.patches is not None:
            self.patches.backward(X, B)
        L.op.gauss_seidel(X, B, bwd)
        return X

    def __matmul__(self, B):
        B = np.ascontiguousarray(B, dtype=np.float64)
        one = B.ndim == 1
        X = self._cycle(0, B[:, None] if one else B)
        return X[:, 0] if one else X

    __call__ = __matmul__

    def release(self):
        for L in self.levels:
            L.op.release()
        if self.coarse_op is not None:
            self.coarse_op.release()


