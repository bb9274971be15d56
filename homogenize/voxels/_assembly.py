"""Voxel assembly of periodic 3D linear elasticity with trilinear (Q1) hexahedra.

The grid is an ``n x n x n`` periodic array of cubic voxels of edge ``h``. Node ``(i, j, k)`` has
index ``p = i + n (j + n k)``; voxel ``(i, j, k)`` has its 8 corners at ``(i + ax, j + ay, k + az)
mod n`` with local corner ``a = ax + 2 ay + 4 az``. Because the node index is taken modulo ``n``,
the displacement fluctuation is periodic by construction and no constraint equations are needed.

Every voxel has isotropic material ``(lambda_e, mu_e)``, so its 24 x 24 element matrix is
``lambda_e K_lam + mu_e K_mu`` with two reference matrices computed ONCE by scikit-fem. Row ``p`` of
the global matrix couples node ``p`` to its 27 neighbours ``p + d``; the 3 x 3 block for offset ``d``
is ``sum_a lambda(p - a) K_lam[a, a + d] + mu(p - a) K_mu[a, a + d]`` (the voxel whose corner ``a``
is node ``p``), i.e. one dense product ``(N, 16) @ (16, 27 * 9)`` -- BLAS speed, no scatter, no
duplicate summation. The result is a 3 x 3 block-sparse (BSR) matrix with sorted indices, the
natural format for smoothed-aggregation AMG of elasticity.
"""
from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementHex1, ElementVector, MeshHex
from skfem.helpers import ddot, sym_grad, trace
from homogenize.voxels import _kernels as kn

__all__ = ["CORNERS", "OFFSETS", "reference_matrices", "node_coefficients", "assemble_bsr",
           "affine_load", "body_force_load", "element_mean_strain"]

# local corner a -> (ax, ay, az)
CORNERS = np.array([[a & 1, (a >> 1) & 1, (a >> 2) & 1] for a in range(8)], dtype=np.int64)
# the 27 neighbour offsets d in {-1, 0, 1}^3, x fastest
OFFSETS = np.array([[dx, dy, dz] for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)],
                   dtype=np.int64)
# Voigt order 11, 22, 33, 23, 13, 12
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


@functools.lru_cache(maxsize=2)
def _unit_reference_matrices(sri: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """K_lam, K_mu (24 x 24, DOF 3 a + c) of the unit cube from scikit-fem.

    ``sri``: selective reduced integration -- the volumetric (lambda) term with the one-point
    rule, the deviatoric term with the full 2 x 2 x 2 rule (Hughes 1980). Without it the Q1 hex
    locks volumetrically near incompressibility (PDMS: nu = 0.45, and rigid particles force an
    almost isochoric flow around them), which inflates the stiffening by a large factor.
    """

    mesh = MeshHex()   # the unit cube, one element
    basis = Basis(mesh, ElementVector(ElementHex1()))
    # one-point rule: the centre of the reference cube [0, 1]^3, weight 1
    one_point = (np.full((3, 1), 0.5), np.ones(1))
    basis_lam = Basis(mesh, ElementVector(ElementHex1()), quadrature=one_point) if sri else basis

    @BilinearForm
    def lam_form(u, v, w):
        return trace(sym_grad(u)) * trace(sym_grad(v))

    @BilinearForm
    def mu_form(u, v, w):
        return 2.0 * ddot(sym_grad(u), sym_grad(v))

    # skfem vertex order -> our corner order
    verts = np.rint(mesh.p.T).astype(np.int64)
    vid = verts[:, 0] + 2 * verts[:, 1] + 4 * verts[:, 2]
    perm = np.empty(24, dtype=np.int64)
    for v, a in enumerate(vid):
        perm[3 * a:3 * a + 3] = basis.nodal_dofs[:, v]
    out = []
    for form, b in ((lam_form, basis_lam), (mu_form, basis)):
        K = form.assemble(b).toarray()
        out.append(np.ascontiguousarray(K[np.ix_(perm, perm)]))
    return out[0], out[1]


SRI = True   # module default; tests compare both integrations


def reference_matrices(h: float, sri: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Element matrices of a cube of edge ``h`` for unit lambda and unit mu (K scales with h in 3D)."""
    Kl, Km = _unit_reference_matrices(SRI if sri is None else bool(sri))
    return Kl * h, Km * h


# per axis, the offsets (-1, 0, 1) sorted by the wrapped neighbour index: coordinate 0 (its -1
# neighbour wraps to n - 1), inside, coordinate n - 1 (its +1 neighbour wraps to 0)
_AXIS_ORDER = np.array([[0, 1, -1], [-1, 0, 1], [1, -1, 0]], dtype=np.int64)


@functools.lru_cache(maxsize=4)
def _stencil_tables() -> np.ndarray:
    """(8, 27) table: neighbour corner b = a + d, or -1 if outside the voxel."""
    tab = -np.ones((8, 27), dtype=np.int64)
    for a in range(8):
        for s, d in enumerate(OFFSETS):
            pb = CORNERS[a] + d
            if np.all((pb >= 0) & (pb <= 1)):
                tab[a, s] = pb[0] + 2 * pb[1] + 4 * pb[2]
    return tab


def node_coefficients(field: np.ndarray) -> np.ndarray:
    """For each node p and corner a, the value of a voxel field at the voxel whose corner a is p.

    field : ndarray, shape (n, n, n) indexed [k, j, i]. Returns (N, 8) with N = n^3.
    """
    n = field.shape[0]
    out = np.empty((n ** 3, 8), dtype=np.float64)
    for a, (ax, ay, az) in enumerate(CORNERS):
        out[:, a] = np.roll(field, shift=(az, ay, ax), axis=(0, 1, 2)).ravel()
    return out


@functools.lru_cache(maxsize=4)
def _pattern(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted BSR pattern of the periodic 27-point stencil: (indptr, indices, slot permutation)."""
    k, j, i = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    cols = np.empty((n ** 3, 27), dtype=np.int64)
    for s, (dx, dy, dz) in enumerate(OFFSETS):
        cols[:, s] = (i + dx) % n + n * (((j + dy) % n) + n * ((k + dz) % n))
    # interior rows are already sorted (offsets run z-major); only rows on the faces wrap
    rows = np.flatnonzero(np.any(np.diff(cols, axis=1) < 0, axis=1))
    order = np.argsort(cols[rows], axis=1, kind="stable")
    cols[rows] = np.take_along_axis(cols[rows], order, axis=1)
    idx_dtype = np.int32 if 27 * n ** 3 < 2 ** 31 else np.int64
    indptr = np.arange(0, 27 * n ** 3 + 1, 27, dtype=idx_dtype)
    for arr in (cols, order, rows):
        arr.setflags(write=False)
    return indptr, cols.ravel().astype(idx_dtype), (rows, order)


def _stencil_blocks(h: float) -> np.ndarray:
    """(16, 27, 3, 3): blocks K[a, a + d] of the unit-lambda (first 8) and unit-mu element matrix."""
    Kl, Km = reference_matrices(h)
    tab = _stencil_tables()
    G = np.zeros((16, 27, 3, 3))
    for a in range(8):
        for s in range(27):
            b = tab[a, s]
            if b >= 0:
                G[a, s] = Kl[3 * a:3 * a + 3, 3 * b:3 * b + 3]
                G[8 + a, s] = Km[3 * a:3 * a + 3, 3 * b:3 * b + 3]
    return G


def voxel_types(lam: np.ndarray, mu: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """The voxels of the fields ``lam``, ``mu`` (n, n, n) [Pa] as element types: ``etype``
    (n^3,) int32 indexes ``Ktab`` (T, 24, 24), one element matrix ``lambda K_lam + mu K_mu`` per
    distinct (lambda, mu) pair (a phase field has two or three)."""
    Kl, Km = reference_matrices(h)
    pairs, inv = np.unique(np.stack([np.ravel(lam), np.ravel(mu)], axis=1), axis=0,
                           return_inverse=True)
    Ktab = np.stack([la * Kl + m * Km for la, m in pairs])
    return np.ascontiguousarray(inv.reshape(-1), dtype=np.int32), Ktab


def assemble_bsr(lam: np.ndarray, mu: np.ndarray, h: float, *, method: str = "numba"
                 ) -> sp.bsr_matrix:
    """Global periodic stiffness matrix, 3 x 3 BSR with sorted indices, DOF ``3 p + c``.

    lam, mu : ndarray, shape (n, n, n) -- Lame parameters per voxel [Pa], indexed [k, j, i]
    h : float -- voxel edge [m]
    method : {"numba", "blas"} -- "numba": one parallel pass writing every row's 27 blocks in
        sorted column order (:func:`homogenize.voxels._kernels.typed_stencil_blocks` on the
        :func:`voxel_types` of the fields); "blas": the
        reference path, one dense product ``(N, 16) @ (16, 243)`` then a reordering of the rows
        that wrap. Both give the same matrix up to the summation order (round-off).
    """
    n = lam.shape[0]
    if n < 3:
        raise ValueError("the periodic 27-point stencil needs n >= 3")
    if method not in ("numba", "blas"):
        raise ValueError(f"method must be 'numba' or 'blas', got {method!r}")
    if method == "numba":
        etype, Ktab = voxel_types(lam, mu, h)
        kern = (kn.typed_stencil_blocks if n ** 3 >= kn.PARALLEL_MIN_ROWS
                else kn.typed_stencil_blocks_serial)
        idx_dtype = np.int32 if 27 * n ** 3 < 2 ** 31 else np.int64
        indices = np.empty(27 * n ** 3, dtype=idx_dtype)
        data = np.empty((27 * n ** 3, 3, 3))
        kern(n, np.arange(n ** 3, dtype=np.int64), etype, Ktab, _stencil_tables(), _AXIS_ORDER,
             indices, data)
        indptr = np.arange(0, 27 * n ** 3 + 1, 27, dtype=idx_dtype)
        A = sp.bsr_matrix((data, indices, indptr),
                          shape=(3 * n ** 3, 3 * n ** 3))
        A.has_sorted_indices = True
        return A
    G = _stencil_blocks(h)
    X = np.concatenate([node_coefficients(lam), node_coefficients(mu)], axis=1)
    data = (X @ G.reshape(16, 243)).reshape(n ** 3, 27, 3, 3)
    del X
    indptr, indices, (rows, order) = _pattern(n)
    # reorder the 27 slots of the wrapping rows to sorted column order
    data[rows] = np.take_along_axis(data[rows], order[:, :, None, None], axis=1)
    A = sp.bsr_matrix((data.reshape(-1, 3, 3), indices, indptr), shape=(3 * n ** 3, 3 * n ** 3))
    A.has_sorted_indices = True
    return A


def _corner_coords(h: float) -> np.ndarray:
    return h * CORNERS.astype(np.float64)


def affine_load(lam: np.ndarray, mu: np.ndarray, h: float, E: np.ndarray) -> np.ndarray:
    """Right-hand side ``-K (E x)`` of the fluctuation problem for mean strain ``E`` (3 x 3).

    Returns the nodal force vector, shape (3 N,) [N].
    """
    Kl, Km = reference_matrices(h)
    ue = (_corner_coords(h) @ E.T).ravel()           # affine displacement at the 8 corners
    gl = -(Kl @ ue).reshape(8, 3)
    gm = -(Km @ ue).reshape(8, 3)
    X = np.concatenate([node_coefficients(lam), node_coefficients(mu)], axis=1)
    return (X @ np.concatenate([gl, gm], axis=0)).ravel()


def body_force_load(b: np.ndarray, h: float) -> np.ndarray:
    """Consistent nodal loads of a body force constant in each voxel.

    b : ndarray, shape (n, n, n, 3) -- force density per voxel [N/m^3], indexed [k, j, i, c]
    Returns shape (3 N,) [N]: each corner of a cube receives exactly V_e / 8 of its force.
    """
    n = b.shape[0]
    out = np.zeros((n ** 3, 3))
    for ax, ay, az in CORNERS:
        out += np.roll(b, shift=(az, ay, ax), axis=(0, 1, 2)).reshape(-1, 3)
    return (out * (h ** 3 / 8.0)).ravel()


def element_mean_strain(w: np.ndarray, n: int, h: float) -> np.ndarray:
    """Volume-averaged strain in every voxel of a periodic nodal field.

    w : ndarray, shape (3 N,) -- nodal displacement [m]. Returns (n, n, n, 3, 3).
    The mean gradient of a Q1 field over a cube is exact: ``(1 / 4h) sum_a w_a (x) s_a`` with
    ``s_a = 2 corner_a - 1``.
    """
    W = w.reshape(n, n, n, 3)
    grad = np.zeros((n, n, n, 3, 3))
    for ax, ay, az in CORNERS:
        s = 2.0 * np.array([ax, ay, az], dtype=np.float64) - 1.0
        wa = np.roll(W, shift=(-az, -ay, -ax), axis=(0, 1, 2))
        grad += wa[..., :, None] * s[None, None, None, None, :]
    grad /= 4.0 * h
    return 0.5 * (grad + np.swapaxes(grad, -1, -2))


def element_stress(lam: np.ndarray, mu: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Voxel stress ``lambda tr(eps) I + 2 mu eps`` [Pa], shape (n, n, n, 3, 3)."""
    tr = np.trace(eps, axis1=-2, axis2=-1)
    sig = 2.0 * mu[..., None, None] * eps
    for c in range(3):
        sig[..., c, c] += lam * tr
    return sig


# ------------------------------------------------------------------------------------------------
# composite voxels: anisotropic element matrices, laminate stiffness, scatter into the BSR matrix
# ------------------------------------------------------------------------------------------------

def voigt_tensor4(C: np.ndarray) -> np.ndarray:
    """(..., 6, 6) Voigt stiffness (engineering shear) -> (..., 3, 3, 3, 3) tensor ``C_ijkl``."""
    C = np.asarray(C, dtype=np.float64)
    T = np.empty(C.shape[:-2] + (3, 3, 3, 3))
    for a, (i, j) in enumerate(VOIGT):
        for b, (k, l) in enumerate(VOIGT):
            v = C[..., a, b]
            T[..., i, j, k, l] = T[..., j, i, k, l] = T[..., i, j, l, k] = T[..., j, i, l, k] = v
    return T


def isotropic_voigt(lam, mu) -> np.ndarray:
    """(..., 6, 6) isotropic stiffness, Voigt order 11, 22, 33, 23, 13, 12, engineering shear."""
    lam, mu = np.broadcast_arrays(np.asarray(lam, dtype=np.float64), np.asarray(mu, np.float64))
    C = np.zeros(lam.shape + (6, 6))
    C[..., :3, :3] = lam[..., None, None]
    for a in range(3):
        C[..., a, a] += 2.0 * mu
        C[..., 3 + a, 3 + a] = mu
    return C


def laminate_voigt(C1: np.ndarray, C2: np.ndarray, f1, normal) -> np.ndarray:
    """Stiffness of a rank-one laminate of two phases with interface normal ``normal``.

    C1, C2 : ndarray, shape (6, 6) or (m, 6, 6) -- phase stiffnesses (Voigt, engineering shear) [Pa]
    f1 : ndarray, shape (m,) -- volume fraction of phase 1 [1]
    normal : ndarray, shape (m, 3) -- unit laminate normal [1]
    Returns (m, 6, 6) [Pa].

    Phase strains ``eps_1 = E + sym(a_1 (x) n)``, ``eps_2 = E + sym(a_2 (x) n)`` with
    ``f1 a_1 + f2 a_2 = 0`` (compatible jumps, mean strain E) and continuous traction
    ``sigma_1 n = sigma_2 n``: with ``a_1 = f2 d``, ``a_2 = -f1 d`` and the acoustic tensors
    ``A_i = n . C_i . n``, ``(f2 A_1 + f1 A_2) d = (C_2 - C_1) : E . n`` and the mean stress is
    ``<C> : E + f1 f2 (C_1 - C_2) : sym(d (x) n)`` -- tangential strains mix by Voigt, normal
    tractions by Reuss (Kabel, Merkert & Schneider 2015).
    """
    nrm = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    f1 = np.asarray(f1, dtype=np.float64).reshape(-1)
    m = nrm.shape[0]
    f2 = 1.0 - f1
    T1 = np.broadcast_to(voigt_tensor4(C1), (m, 3, 3, 3, 3))
    T2 = np.broadcast_to(voigt_tensor4(C2), (m, 3, 3, 3, 3))
    A1 = np.einsum("mjlkq,ml,mq->mjk", T1, nrm, nrm)
    A2 = np.einsum("mjlkq,ml,mq->mjk", T2, nrm, nrm)
    A = f2[:, None, None] * A1 + f1[:, None, None] * A2
    Tm = f1[:, None, None, None, None] * T1 + f2[:, None, None, None, None] * T2
    dT = T1 - T2
    out = np.empty((m, 6, 6))
    for b in range(6):
        E = np.zeros((3, 3))
        i, j = VOIGT[b]
        E[i, j] = E[j, i] = 1.0 if i == j else 0.5          # engineering shear strain 1
        rhs = -np.einsum("mjlkq,kq,ml->mj", dT, E, nrm)     # (C2 - C1) : E . n
        d = np.linalg.solve(A, rhs[..., None])[..., 0]
        sdn = 0.5 * (d[:, :, None] * nrm[:, None, :] + nrm[:, :, None] * d[:, None, :])
        sig = (np.einsum("mijkl,kl->mij", Tm, E)
               + (f1 * f2)[:, None, None] * np.einsum("mijkl,mkl->mij", dT, sdn))
        for a, (p, q) in enumerate(VOIGT):
            out[:, a, b] = sig[:, p, q]
    return out


@functools.lru_cache(maxsize=1)
def _unit_strain_operators() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Strain-displacement matrices of the unit Q1 cube: (B at the 8 Gauss points (8, 6, 24),
    Gauss weights (8,), B at the centre (6, 24)); engineering shear, DOF ``3 a + c``."""
    g = 0.5 + np.array([-1.0, 1.0]) / (2.0 * np.sqrt(3.0))
    pts = np.array([[x, y, z] for z in g for y in g for x in g])

    def B_at(p):
        B = np.zeros((6, 24))
        for a, (ax, ay, az) in enumerate(CORNERS):
            fx = (p[0] if ax else 1.0 - p[0], p[1] if ay else 1.0 - p[1],
                  p[2] if az else 1.0 - p[2])
            sx = (1.0 if ax else -1.0, 1.0 if ay else -1.0, 1.0 if az else -1.0)
            dN = np.array([sx[0] * fx[1] * fx[2], fx[0] * sx[1] * fx[2], fx[0] * fx[1] * sx[2]])
            for c in range(3):
                B[c, 3 * a + c] = dN[c]
            for v, (i, j) in enumerate(VOIGT[3:]):
                B[3 + v, 3 * a + i] += dN[j]
                B[3 + v, 3 * a + j] += dN[i]
        return B

    Bq = np.stack([B_at(p) for p in pts])
    return Bq, np.full(8, 1.0 / 8.0), B_at(np.full(3, 0.5))


@functools.lru_cache(maxsize=1)
def _voigt_element_basis() -> tuple[np.ndarray, np.ndarray]:
    """(R (6, 6, 24, 24), V (24, 24)): ``R[i, j] = sum_q w_q B_q[i]^T B_q[j]`` of the unit cube,
    so the fully integrated element matrix of a stiffness C is ``sum_ij C_ij R[i, j]``, and the
    one-point volumetric matrix ``V = b^T b`` with ``b = m^T B(centre)``."""
    Bq, w, B0 = _unit_strain_operators()
    R = np.einsum("q,qia,qjb->ijab", w, Bq, Bq)
    b = B0[:3].sum(axis=0)
    return R, np.outer(b, b)


def anisotropic_element_matrices(C: np.ndarray, h: float) -> np.ndarray:
    """Element matrices (m, 24, 24) of cubes of edge ``h`` with stiffness C (m, 6, 6) [Pa].

    The same selective reduced integration as the isotropic element (:func:`reference_matrices`):
    a volumetric part ``lambda* m (x) m`` on the one-point rule, the rest ``C - lambda* m (x) m``
    on the 2x2x2 rule, with ``lambda* = K_R - 2 G_R / 3`` from the Reuss bulk and shear moduli of
    C (for an isotropic C exactly its lambda, so the element equals ``lambda K_lam + mu K_mu``),
    clipped to ``[0, K_R)``: ``C - lambda* m (x) m`` stays positive definite (no hourglass mode).
    """
    C = np.asarray(C, dtype=np.float64).reshape(-1, 6, 6)
    S = np.linalg.inv(C)
    KR = 1.0 / (S[:, 0, 0] + S[:, 1, 1] + S[:, 2, 2]
                + 2.0 * (S[:, 0, 1] + S[:, 0, 2] + S[:, 1, 2]))
    GR = 15.0 / (4.0 * (S[:, 0, 0] + S[:, 1, 1] + S[:, 2, 2])
                 - 4.0 * (S[:, 0, 1] + S[:, 0, 2] + S[:, 1, 2])
                 + 3.0 * (S[:, 3, 3] + S[:, 4, 4] + S[:, 5, 5]))
    lam = np.clip(KR - 2.0 * GR / 3.0, 0.0, None) if SRI else np.zeros_like(KR)
    Cf = C.copy()
    Cf[:, :3, :3] -= lam[:, None, None]
    R, V = _voigt_element_basis()
    K = np.einsum("mij,ijab->mab", Cf, R, optimize=True) + lam[:, None, None] * V[None]
    return K * h


def _block_positions(n: int, vox: np.ndarray) -> np.ndarray:
    """(m, 8, 8) positions in the sorted 27-block rows of :func:`assemble_bsr` of the blocks
    (corner a, corner b) of voxels ``vox`` (flat index ``i + n (j + n k)``)."""
    _, indices, _ = _pattern(n)
    rowcols = indices.reshape(-1, 27)
    k, rem = np.divmod(vox, n * n)
    j, i = np.divmod(rem, n)
    nodes = np.stack([(i + ax) % n + n * (((j + ay) % n) + n * ((k + az) % n))
                      for ax, ay, az in CORNERS], axis=1)                 # (m, 8)
    P = np.repeat(nodes, 8, axis=1)                                       # row node (a major)
    Q = np.tile(nodes, (1, 8))                                            # column node
    rank = (rowcols[P] < Q[..., None]).sum(axis=-1)
    return (27 * P + rank).reshape(-1, 8, 8), nodes


def add_voxel_matrices(K: sp.bsr_matrix, n: int, vox: np.ndarray, Ke: np.ndarray) -> None:
    """K += the element matrices Ke (m, 24, 24) of voxels ``vox`` (m,), in place (sorted BSR)."""
    pos, _ = _block_positions(n, np.asarray(vox, dtype=np.int64))
    blocks = Ke.reshape(-1, 8, 3, 8, 3).transpose(0, 1, 3, 2, 4)         # (m, a, b, 3, 3)
    np.add.at(K.data, pos.ravel(), blocks.reshape(-1, 3, 3))


def voxel_matrix_load(n: int, vox: np.ndarray, Ke: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """Nodal vector (3 n^3,) of ``-Ke @ ue`` summed over voxels ``vox``; ue (24,) the same element
    displacement for all (an affine field)."""
    k, rem = np.divmod(np.asarray(vox, dtype=np.int64), n * n)
    j, i = np.divmod(rem, n)
    g = -(Ke @ ue).reshape(-1, 8, 3)
    out = np.zeros((n ** 3, 3))
    for a, (ax, ay, az) in enumerate(CORNERS):
        node = (i + ax) % n + n * (((j + ay) % n) + n * ((k + az) % n))
        np.add.at(out, node, g[:, a])
    return out.ravel()

