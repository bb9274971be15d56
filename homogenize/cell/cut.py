"""Nitsche cut voxels: a voxel discretization of the periodic cell whose interface error is second
order (results/cell/README.md, "Why composite voxels are first order, and a cut-voxel
discretization that is second order"; the experiments: results/cell/cut_cell_experiments.py).

The grid is the project's periodic Q1 voxel grid (:mod:`homogenize.voxels._assembly`: node
``i + n (j + n k)``, selectively reduced integration in the voxels that no interface cuts). The
geometry is a nodal level set ``phi`` (< 0: particle, > 0: matrix). A voxel is CUT when its corner
values change sign. Its 6 Kuhn tetrahedra (all along the main diagonal, so that the faces match
between voxels) are split exactly by the plane of the linear interpolant of ``phi``: the discrete
interface is made of planar facets, O(h^2) from a smooth surface.

Every cut voxel carries two Q1 copies of the displacement, one per phase, each integrated over
its phase's part of the voxel (Hansbo & Hansbo 2002). The copies are glued on the facets by a
symmetric Nitsche method:

* contrast-robust weights ``w_i = (V_i / E_i) / sum_j (V_j / E_j)`` (Annavarapu, Hautefeuille &
  Dolbow 2012), ``V_i`` the volume of phase ``i`` in the voxel;
* a penalty ``safety * sum_i w_i^2 lambda_i`` per voxel, ``lambda_i`` the largest eigenvalue of
  the traction energy on the facets against the copy's bulk energy (the coercivity bound,
  computed per voxel);
* the volumetric term of each copy acts on its mean divergence over its part (B-bar, the cut
  voxel's analogue of the one-point volumetric rule of the whole voxels; with the full rule the
  cut layer locks at nu = 0.45).

A node's own phase uses the node's standard unknowns; the other phase's copy at that node is an
extra unknown. One cut voxel therefore has ONE particle copy: two particles whose particle corners
meet in one voxel would be glued, and :func:`homogenize_cut` refuses them.

What is known (results/cell/cut_cell_experiments.json): exact on a tilted Fe/PDMS laminate; on
one dilute Fe sphere (phi 0.01) the error of the shear coefficient against the curved-P2 limit
2.3408 is +12.8 % at 4.3 voxels per diameter and +0.94 % at 16, observed order 1.98 +- 0.02;
Richardson at order 2 on two resolutions agrees with the P2 limit within 0.12 %. At the
project's usual resolutions (4-8 voxels per diameter) composite voxels
(:func:`homogenize.cell.problem.homogenize_rve`) are the more accurate; the cut voxels are the
reference for convergence studies.

Solver: the assembled matrix (whole voxels from :func:`homogenize.voxels._assembly.assemble_bsr`, cut
voxels added as 48 x 48 blocks), pyamg smoothed aggregation with the rigid-body modes on both
copies (local smoother weights: reproducible), CG per load case, without particle deflation (30-60
iterations at Fe/PDMS contrast). C_eff comes from the energy of the solutions in the
variational form (error quadratic in the CG error, as in :mod:`homogenize.cell.problem`). Elastic load
cases only (no magnetic body force). Cost, measured on 2 cores: the element setup of the cut
voxels (a Python loop in :func:`cut_pieces`) ~5 ms per cut voxel; one dilute sphere, one load
case: 1.3 s at 16^3 (96 cut voxels), 12 s at 30^3 (300 cut voxels, mostly the AMG setup and
CG on 0.1 M unknowns); the 12^3 tilted laminate (864 cut voxels), six cases: 9 s.

Lengths inside this module are in box units (the cell is ``[0, 1)^3``, voxel edge ``1 / n``);
C_eff is independent of the length scale, so the public functions take metres and return Pa.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from micro.common.validate import ConvergenceError, InputError, check_range
from micro.materials import FE, PDMS, ElasticMaterial, elastic
from micro.box import PeriodicBox

from homogenize.voxels import _assembly as asm
from homogenize.solvers import AMGOptions, grid_node_coordinates, rigid_body_modes, smoothed_aggregation
from homogenize.voxels._budget import check_memory, cut_cell_bytes as memory_estimate_bytes
from homogenize.cell.problem import CASES, CELL_RANGES, isotropic_projection, voigt_to_tensor
from homogenize.voxels.mesh import _as_geometry

__all__ = ["CutResult", "homogenize_cut", "homogenize_level_set", "discrete_volume",
           "volume_matched_radius", "sphere_fn", "nodal_phi", "nitsche_matrices", "cut_pieces",
           "split_tet", "tet_negative_volume", "tet_rule", "tri_rule", "q1",
           "memory_estimate_bytes", "check_cut_memory", "isotropic_element_matrices",
           "side_integrals", "cut_cell_problem"]

_CORN = asm.CORNERS.astype(float)       # local corner a = x + 2 y + 4 z -> (x, y, z)
#: the 6 Kuhn tetrahedra of the unit cube as corner indices (6, 4): all share the main diagonal
#: 0 -> 7, so the triangulations of neighbouring voxels match on their common faces
_KUHN = np.array([[0] + [sum(1 << d for d in perm[:k + 1]) for k in range(3)]
                  for perm in itertools.permutations(range(3))])


@dataclass(frozen=True, eq=False)
class CutResult:
    """Result of :func:`homogenize_cut` / :func:`homogenize_level_set`. Units: Pa; lengths in m.

    Attributes
    ----------
    C_eff_Pa : ndarray, shape (6, 6) -- effective stiffness [Pa], Voigt order 11, 22, 33, 23, 13,
        12, engineering shear, symmetric. Only the rows and columns of the solved ``cases`` are
        filled; the other entries are NaN.
    E_eff_Pa, nu_eff : float or None -- isotropic projection of C_eff
        (:func:`homogenize.cell.problem.isotropic_projection`) [Pa], [1]; None unless all 6 cases are
        solved
    phi_discrete : float -- particle volume fraction of the discrete geometry (the Kuhn-linear
        interpolant of the level set) [1]
    radius_scale : float or None -- common factor applied to all radii (volume matching; 1.0
        without it); None for a level set given directly
    iterations : dict -- CG iterations per load case ("e11", ..., "g12"); 0 for a load that
        vanishes by symmetry
    penalty_h_over_E_matrix : tuple of 3 floats, or None -- (min, median, max) over the cut voxels
        of the Nitsche penalty times the voxel edge over the matrix Young's modulus [1]; None
        without cut voxels
    n_dof : int -- unknowns (3 per node plus 3 per node of a cut voxel for the other phase)
    n_cut_voxels : int -- voxels crossed by the interface
    settings : dict -- method ("nitsche-cut"), tol, safety, volume_matched, voxels, cases
    """

    C_eff_Pa: np.ndarray
    E_eff_Pa: float | None
    nu_eff: float | None
    phi_discrete: float
    radius_scale: float | None
    iterations: dict
    penalty_h_over_E_matrix: tuple | None
    n_dof: int
    n_cut_voxels: int
    settings: dict


# ------------------------------------------------------------------------------------------------
# geometry and quadrature (voxel or box units)
# ------------------------------------------------------------------------------------------------

def _gauss01(q):
    x, w = np.polynomial.legendre.leggauss(q)
    return 0.5 * (x + 1.0), 0.5 * w


def tet_rule(q):
    """Collapsed (Duffy) Gauss-Legendre rule on a tetrahedron, exact for polynomials of degree
    2 q - 3 (the Jacobian a^2 b of the collapse is in the weights, not in the Gauss rule).

    The cut voxels use q = 3 (degree 3) for products of Q1 gradients (degree 4); the exact rule
    (q = 4) changes the dilute sphere's coefficient by 1e-5 relative at 4.3 and 5.9 voxels per
    diameter (measured), far below the discretization error.

    Parameters
    ----------
    q : int -- Gauss points per direction (>= 2)

    Returns
    -------
    lam : ndarray, shape (q^3, 4) -- barycentric coordinates of the points [1]
    w : ndarray, shape (q^3,) -- weights as fractions of the tetrahedron's volume (sum 1) [1]
    """
    x, w = _gauss01(q)
    a, b, c = (g.ravel() for g in np.meshgrid(x, x, x, indexing="ij"))
    wa, wb, wc = (g.ravel() for g in np.meshgrid(w, w, w, indexing="ij"))
    lam = np.stack([1 - a, a * (1 - b), a * b * (1 - c), a * b * c], axis=1)
    return lam, wa * wb * wc * a ** 2 * b * 6.0


def tri_rule(q):
    """Collapsed Gauss-Legendre rule on a triangle, exact for polynomials of degree 2 q - 2.

    Returns barycentric points, shape (q^2, 3) [1], and weights as fractions of the area,
    shape (q^2,) [1].
    """
    x, w = _gauss01(q)
    a, b = (g.ravel() for g in np.meshgrid(x, x, indexing="ij"))
    wa, wb = (g.ravel() for g in np.meshgrid(w, w, indexing="ij"))
    return np.stack([1 - a, a * (1 - b), a * b], axis=1), wa * wb * a * 2.0


def split_tet(P, phi):
    """Split a tetrahedron by the zero plane of the linear interpolant of ``phi``.

    Parameters
    ----------
    P : ndarray, shape (4, 3) -- vertices [any length unit]
    phi : ndarray, shape (4,) -- level set at the vertices, none exactly zero [same unit]

    Returns
    -------
    parts : list of (ndarray (4, 3), int) -- sub-tetrahedra and their sign (-1: phi < 0)
    faces : list of ndarray (3, 3) -- interface triangles (none if the sign does not change)
    normal : ndarray, shape (3,), or None -- unit normal of the plane towards phi > 0
    """
    neg = phi < 0
    k = int(neg.sum())
    if k in (0, 4):
        return [(P, -1 if k == 4 else 1)], [], None
    g = np.linalg.solve(P[1:] - P[0], phi[1:] - phi[0])

    def cut(i, j):
        return P[i] + phi[i] / (phi[i] - phi[j]) * (P[j] - P[i])

    def prism(T1, T2):
        return [np.array([T1[0], T1[1], T1[2], T2[0]]), np.array([T1[1], T1[2], T2[0], T2[1]]),
                np.array([T1[2], T2[0], T2[1], T2[2]])]
    if k in (1, 3):
        lone_sign = -1 if k == 1 else 1
        a = int(np.flatnonzero(neg if k == 1 else ~neg)[0])
        others = [i for i in range(4) if i != a]
        cp = [cut(a, o) for o in others]
        parts = [(np.array([P[a]] + cp), lone_sign)]
        parts += [(t, -lone_sign) for t in prism(cp, [P[o] for o in others])]
        return parts, [np.array(cp)], g / np.linalg.norm(g)
    a, b = np.flatnonzero(neg)
    c, d = np.flatnonzero(~neg)
    pac, pad, pbc, pbd = cut(a, c), cut(a, d), cut(b, c), cut(b, d)
    parts = [(t, -1) for t in prism([P[a], pac, pad], [P[b], pbc, pbd])]
    parts += [(t, 1) for t in prism([P[c], pac, pbc], [P[d], pad, pbd])]
    return parts, [np.array([pac, pad, pbd]), np.array([pac, pbd, pbc])], g / np.linalg.norm(g)


def q1(xi):
    """Trilinear shape functions of the unit cube.

    Parameters
    ----------
    xi : ndarray, shape (..., 3) -- points in the cube [voxel units]

    Returns
    -------
    N : ndarray, shape (..., 8) -- values, corner ``a = x + 2 y + 4 z`` [1]
    dN : ndarray, shape (..., 8, 3) -- gradients d N / d xi [1 / voxel]
    """
    x, y, z = xi[..., 0, None], xi[..., 1, None], xi[..., 2, None]
    cx, cy, cz = _CORN[:, 0], _CORN[:, 1], _CORN[:, 2]
    fx = cx * x + (1 - cx) * (1 - x)
    fy = cy * y + (1 - cy) * (1 - y)
    fz = cz * z + (1 - cz) * (1 - z)
    dN = np.stack([(2 * cx - 1) * fy * fz, fx * (2 * cy - 1) * fz, fx * fy * (2 * cz - 1)], -1)
    return fx * fy * fz, dN


def cut_pieces(phi_c):
    """Split cut voxels into sub-tetrahedra and interface triangles (a loop over the voxels).

    Parameters
    ----------
    phi_c : ndarray, shape (m, 8) -- level set at the corners of m cut voxels [any unit]

    Returns
    -------
    subs : ndarray, shape (S, 4, 3) -- sub-tetrahedra [voxel units, voxel at [0, 1]^3]
    sown : ndarray, shape (S,) -- their voxel (index into phi_c)
    ssg : ndarray, shape (S,) -- their sign (-1: phi < 0)
    tris : ndarray, shape (T, 3, 3) -- interface triangles [voxel units]
    town : ndarray of int64, shape (T,) -- their voxel
    tnrm : ndarray, shape (T, 3) -- their unit normal towards phi > 0
    """
    subs, sown, ssg, tris, town, tnrm = [], [], [], [], [], []
    for v in range(phi_c.shape[0]):
        for t in _KUHN:
            parts, faces, nrm = split_tet(_CORN[t], phi_c[v, t])
            for P, s in parts:
                subs.append(P), sown.append(v), ssg.append(s)
            for T in faces:
                tris.append(T), town.append(v), tnrm.append(nrm)
    return (np.array(subs), np.array(sown), np.array(ssg), np.array(tris).reshape(-1, 3, 3),
            np.array(town, dtype=np.int64), np.array(tnrm).reshape(-1, 3))


def tet_negative_volume(P, ph):
    """Volume of ``{phi < 0}`` in tetrahedra with a linear level set (closed form, vectorized).

    Parameters
    ----------
    P : ndarray, shape (T, 4, 3) -- vertices [any length unit]
    ph : ndarray, shape (T, 4) -- level set at the vertices, none exactly zero

    Returns
    -------
    ndarray, shape (T,) -- volumes [unit^3]
    """
    vol = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / 6.0
    neg = ph < 0
    k = neg.sum(axis=1)
    out = np.where(k == 4, vol, 0.0)
    for kk, lone_neg in ((1, True), (3, False)):
        sel = np.flatnonzero(k == kk)
        if sel.size:
            lone = np.argmax(neg[sel] if lone_neg else ~neg[sel], axis=1)
            pa = ph[sel, lone]
            frac = np.ones(sel.size)
            for o in range(4):
                other = lone != o
                frac[other] *= pa[other] / (pa[other] - ph[sel, o][other])
            out[sel] = vol[sel] * (frac if lone_neg else 1.0 - frac)
    sel = np.flatnonzero(k == 2)
    if sel.size:
        order = np.argsort(~neg[sel], axis=1, kind="stable")          # negatives first
        Ps = np.take_along_axis(P[sel], order[:, :, None], axis=1)
        ps = np.take_along_axis(ph[sel], order, axis=1)

        def cut(i, j):
            return Ps[:, i] + (ps[:, i] / (ps[:, i] - ps[:, j]))[:, None] * (Ps[:, j] - Ps[:, i])

        def tv(x0, x1, x2, x3):
            return np.abs(np.linalg.det(np.stack([x1 - x0, x2 - x0, x3 - x0], axis=1))) / 6.0
        a, b = Ps[:, 0], Ps[:, 1]
        pac, pad, pbc, pbd = cut(0, 2), cut(0, 3), cut(1, 2), cut(1, 3)
        out[sel] = tv(a, pac, pad, b) + tv(pac, pad, b, pbc) + tv(pad, b, pbc, pbd)
    return out


def _grid(n):
    """Node positions (n, n, n, 3) [box], indexed [k, j, i], and the corners (n^3, 8) of each
    voxel (node indices, periodic)."""
    k, j, i = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    nodes = np.stack([((i + ax) % n + n * (((j + ay) % n) + n * ((k + az) % n))).ravel()
                      for ax, ay, az in asm.CORNERS], axis=1)               # (n^3, 8)
    return np.stack([i, j, k], axis=-1) / n, nodes


def _nonzero(phi, n):
    """A node exactly on the interface counts as matrix (the split needs a sign)."""
    return np.where(phi == 0.0, 1e-12 / n, phi)


def nodal_phi(phi_fn, n):
    """Level set at the nodes of the n^3 grid.

    Parameters
    ----------
    phi_fn : callable -- ``phi_fn(x)``, x of shape (n, n, n, 3) [box units, indexed [k, j, i],
        components (x, y, z)] -> level set (n, n, n) [box units], < 0 in the particles
    n : int -- voxels per edge

    Returns
    -------
    phi : ndarray, shape (n^3,) -- level set per node (exact zeros moved to the matrix side)
    nodes : ndarray, shape (n^3, 8) -- corner nodes of every voxel
    """
    x, nodes = _grid(n)
    return _nonzero(phi_fn(x).ravel(), n), nodes


def _discrete_volume_nodal(phi, nodes, n):
    pc = phi[nodes]
    nneg = (pc < 0).sum(axis=1)
    cut = np.flatnonzero((nneg > 0) & (nneg < 8))
    P = np.broadcast_to(_CORN[_KUHN], (cut.size, 6, 4, 3)).reshape(-1, 4, 3)
    vals = pc[cut][:, _KUHN].reshape(-1, 4)
    return ((nneg == 8).sum() + tet_negative_volume(P, vals).sum()) / n ** 3


def discrete_volume(phi_fn, n):
    """Volume of ``{phi_h < 0}``, phi_h the Kuhn-linear interpolant on the n^3 grid [box^3]
    (``phi_fn`` as in :func:`nodal_phi`)."""
    phi, nodes = nodal_phi(phi_fn, n)
    return _discrete_volume_nodal(phi, nodes, n)


def sphere_fn(centre, radius):
    """Level set of one periodic sphere: minimum-image distance to ``centre`` minus ``radius``.

    Parameters
    ----------
    centre : ndarray, shape (3,) -- centre [box units]
    radius : float -- radius [box units], < 0.5

    Returns
    -------
    callable -- ``phi(x)``, x of shape (..., 3) [box] -> (...) [box]
    """
    def phi(x):
        return _particles_phi(x, np.reshape(centre, (1, 3)), np.reshape(radius, (1,)))[0]
    return phi


def _match_volume(volume, target, x0, rtol=1e-11):
    """The parameter ``x`` (a radius or a radius scale) at which the increasing, continuous
    ``volume(x)`` equals ``target``: secant iteration from ``(x0, 1.02 x0)``, the discrete
    volume being smooth between the parameters where a node crosses the interface; bisection
    if the secant leaves the positive axis or stalls. Returns x; its volume is within ``rtol``
    of the target when the secant converges, else as close as 200 bisections get."""
    r0, r1 = x0, 1.02 * x0
    v0, v1 = (volume(r) for r in (r0, r1))
    for _ in range(12):
        if v1 == v0:
            break
        r0, v0, r1 = r1, v1, r1 + (target - v1) * (r1 - r0) / (v1 - v0)
        if not (np.isfinite(r1) and r1 > 0.0):
            break
        v1 = volume(r1)
        if abs(v1 / target - 1.0) < rtol:
            return r1
    lo, hi = 0.0, x0
    for _ in range(64):                 # the volume reaches the whole cell for a large parameter
        if volume(hi) >= target:
            break
        lo, hi = hi, 2.0 * hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        v = volume(mid)
        if abs(v / target - 1.0) < rtol or mid in (lo, hi):
            return mid
        lo, hi = (mid, hi) if v < target else (lo, mid)
    return 0.5 * (lo + hi)


def volume_matched_radius(centre, n, radius):
    """Radius whose discrete sphere (Kuhn-linear interface on the n^3 grid) holds the volume
    ``4/3 pi radius^3`` of the sphere of the given radius.

    Parameters
    ----------
    centre : ndarray, shape (3,) -- centre [box units]
    n : int -- voxels per edge
    radius : float -- nominal radius [box units]

    Returns
    -------
    float -- the matched radius [box units] (relative volume error < 1e-11)
    """
    target = 4.0 / 3.0 * np.pi * radius ** 3
    return _match_volume(lambda r: discrete_volume(sphere_fn(centre, r), n), target, radius)


def _particles_phi(x, centres, radii):
    """Level set min_i (|x - c_i|_periodic - r_i) and the particle of the minimum at points
    x (..., 3) [box]; centres (N, 3), radii (N,) [box]."""
    phi = np.full(x.shape[:-1], np.inf)
    owner = np.full(x.shape[:-1], -1, dtype=np.int64)
    unit = PeriodicBox(1.0)
    for i in range(radii.size):
        p = np.linalg.norm(unit.minimum_image(x - centres[i]), axis=-1) - radii[i]
        closer = p < phi
        phi[closer] = p[closer]
        owner[closer] = i
    return phi, owner


# ------------------------------------------------------------------------------------------------
# cut-voxel matrices
# ------------------------------------------------------------------------------------------------

def _iso_K(G, lam, mu):
    """Isotropic stiffness matrices (..., 3F, 3F) (DOF 3 a + c) from the gradient products
    ``G[..., a, b, i, j] = int d_i f_a d_j f_b`` of F scalar functions; lam, mu [Pa]."""
    tr = np.einsum("...abii->...ab", G)
    K = lam * np.swapaxes(G, -3, -2)
    K = K + mu * np.moveaxis(G, (-4, -3, -2, -1), (-4, -2, -1, -3))
    K = K + mu * tr[..., :, None, :, None] * np.eye(3)[:, None, :]
    F = G.shape[-4]
    return K.reshape(G.shape[:-4] + (3 * F, 3 * F))


def _side_integrals(subs, sown, ssg, m, h, fn, q=3):
    """Per side (0: phi < 0, 1: phi > 0) of each of m cut voxels of edge h: the gradient products
    G (2, m, F, F, 3, 3) = int d_i f_a d_j f_b, the integrals g1 (2, m, F, 3) = int d_i f_a and
    the volumes (2, m), for the F scalar functions whose gradients (S, Q, F, 3) are
    ``fn(N, dN, owner, sign)`` (Q1 values and gradients at the quadrature points of the
    sub-tetrahedra of :func:`cut_pieces`)."""
    lam, wq = tet_rule(q)
    G = g1 = None
    vol = np.zeros((2, m))
    for s0 in range(0, subs.shape[0], 2000):
        sl = slice(s0, s0 + 2000)
        P, ow, sg = subs[sl], sown[sl], ssg[sl]
        v = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / 6.0 * h ** 3
        xi = np.einsum("qk,skd->sqd", lam, P)
        N, dN = q1(xi)
        g = fn(N, dN / h, ow, sg)                                       # (S, Q, F, 3)
        if G is None:
            F = g.shape[2]
            G, g1 = np.zeros((2, m, F, F, 3, 3)), np.zeros((2, m, F, 3))
        wg = (wq[None, :] * v[:, None])[..., None, None] * g
        side = (sg > 0).astype(int)
        np.add.at(G, (side, ow), np.einsum("sqai,sqbj->sabij", wg, g, optimize=True))
        np.add.at(g1, (side, ow), wg.sum(axis=1))
        np.add.at(vol, (side, ow), v)
    return G, g1, vol


def nitsche_matrices(phi_c, h, lames, youngs, Es, safety=2.0, q=3):
    """Element matrices of the cut voxels: two Q1 copies ([phi < 0 copy, phi > 0 copy], DOF
    ``24 s + 3 a + c``) glued by symmetric Nitsche with B-bar volumetric terms.

    Parameters
    ----------
    phi_c : ndarray, shape (m, 8) -- level set at the corners of the cut voxels
    h : float -- voxel edge [L] (box units inside this module)
    lames : ((float, float), (float, float)) -- (lambda, mu) of the phi < 0 and phi > 0 phase [Pa]
    youngs : (float, float) -- Young's moduli of the two phases [Pa] (Nitsche weights)
    Es : list of ndarray (6,) -- mean strains, Voigt with engineering shear [1]
    safety : float -- penalty over the per-voxel coercivity bound, > 1
    q : int -- Gauss points per direction of the tetrahedron rule (triangles: q + 1)

    Returns
    -------
    K : ndarray, shape (m, 48, 48) -- stiffness [Pa L]
    loads : list of ndarray (m, 48) -- right-hand sides of the fluctuation problem, one per E
        [Pa L^2]
    vol : ndarray, shape (2, m) -- volume of each phase in each voxel [L^3]
    alpha : ndarray, shape (m,) -- Nitsche penalty [Pa / L]
    """
    m = phi_c.shape[0]
    subs, sown, ssg, tris, town, tnrm = cut_pieces(phi_c)
    G, g1, vol = _side_integrals(subs, sown, ssg, m, h, lambda N, dN, ow, sg: dN, q=q)
    gbar = g1.reshape(2, m, 24) / np.maximum(vol, 1e-300)[:, :, None]    # side-mean d_c N_a
    Kb = np.stack([_iso_K(G[s], 0.0, lames[s][1])
                   + lames[s][0] * vol[s][:, None, None] * gbar[s][:, :, None] * gbar[s][:, None, :]
                   for s in range(2)])                                   # B-bar per side
    lt, wt = tri_rule(q + 1)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                axis=1) * h ** 2
    N, dN = q1(np.einsum("qk,skd->sqd", lt, tris))
    dN = dN / h
    nq = np.broadcast_to(tnrm[:, None, :], N.shape[:2] + (3,))
    w = wt[None, :] * area[:, None]
    dn = np.einsum("sqak,sqk->sqa", dN, nq)
    Tn = []
    for s in range(2):      # traction (B-bar stress) of the 24 functions, (T, Q, 3, 24)
        lam, mu = lames[s]
        T = np.zeros(N.shape[:2] + (3, 8, 3))
        for k in range(3):
            for c in range(3):
                T[..., k, :, c] = mu * dN[..., :, k] * nq[..., c, None]
            T[..., k, :, k] += mu * dn
        T = T.reshape(N.shape[:2] + (3, 24))
        Tn.append(T + lam * nq[..., :, None] * gbar[s][town][:, None, None, :])
    kap = vol / np.asarray(youngs)[:, None]
    wts = kap / kap.sum(axis=0)
    lmax = np.zeros((2, m))
    for s in range(2):
        A = np.zeros((m, 24, 24))
        np.add.at(A, town, np.einsum("sq,sqki,sqkj->sij", w, Tn[s], Tn[s]))
        L = np.linalg.cholesky(Kb[s] + 1e-12 * np.abs(Kb[s]).max(axis=(1, 2))[:, None, None]
                               * np.eye(24))
        Li = np.linalg.inv(L)
        lmax[s] = np.linalg.eigvalsh(Li @ A @ np.swapaxes(Li, 1, 2))[:, -1]
    alpha = safety * (wts ** 2 * lmax).sum(axis=0)
    Jm = np.einsum("sqa,kc->sqkac", N, np.eye(3)).reshape(N.shape[:2] + (3, 24))
    J = np.concatenate([Jm, -Jm], axis=-1)          # [v] = v(phi < 0) - v(phi > 0)
    Tavg = np.concatenate([wts[s][town][:, None, None, None] * Tn[s] for s in range(2)], -1)
    JT = np.einsum("sq,sqki,sqkj->sij", w, J, Tavg)
    JJ = np.einsum("sq,sqki,sqkj->sij", w, J, J)
    K = np.zeros((m, 48, 48))
    np.add.at(K, town, -JT - np.swapaxes(JT, 1, 2) + alpha[town][:, None, None] * JJ)
    K[:, :24, :24] += Kb[0]
    K[:, 24:, 24:] += Kb[1]
    loads = []
    for E in Es:
        f = np.zeros((m, 48))
        tavg = 0.0
        for s in range(2):
            St = voigt_to_tensor(asm.isotropic_voigt(*lames[s]) @ E)
            f[:, 24 * s:24 * s + 24] -= np.einsum("maj,ij->mai", g1[s], St).reshape(m, 24)
            tavg = tavg + wts[s][town][:, None, None] * np.einsum("ij,sqj->sqi", St, nq)
        np.add.at(f, town, np.einsum("sq,sqki,sqk->si", w, J, tavg))
        loads.append(f)
    return K, loads, vol, alpha


# ------------------------------------------------------------------------------------------------
# the periodic cell problem with cut voxels
# ------------------------------------------------------------------------------------------------

#: pyamg smoothed aggregation of the cut-voxel system (rigid-body candidates, pyamg's default
#: strength and candidate smoothing, sparse LU on <= 2000 coarse DOF), with the project's
#: repeatable smoother weights (:data:`homogenize.solvers.SA_SMOOTH`; pyamg's default made C_eff
#: differ by 1e-9 between two calls on two Fe spheres)
_AMG = AMGOptions(strength_theta=None, improve_candidates=True, coarse_solver="splu",
                  max_coarse=2000)


def _wrap_planes(centres, radii, n):
    """Per axis, the node layer k (0..n-1) at which the coordinates of the rigid-body candidates
    wrap: the first layer farther than one voxel from every particle, else the one that cuts the
    fewest. A rotation candidate jumps by one box length at its wrap; across a stiff particle
    that is no rigid motion of it, and smoothed aggregation loses the particle's rotation
    (measured on two Fe spheres at 16^3: 34 CG iterations with the particles inside the cell,
    51-88 with one or both across the boundary of the cell's own coordinates)."""
    p = np.arange(n) / n
    out = []
    for d in range(3):
        dist = np.abs(p[:, None] - centres[None, :, d])
        dist = np.minimum(dist, 1.0 - dist)
        out.append(int(np.argmin((dist < radii[None, :] + 1.0 / n).sum(axis=1))))
    return tuple(out)


def _cut_cell_problem(phi, nodes, n, lames, cases, tol, cut_matrices, two_copies,
                      wrap=(0, 0, 0), energy="variational"):
    """C_eff entries of the periodic unit cell with the particle where the nodal level set
    ``phi`` (n^3,) < 0, whole voxels by SRI Q1 and cut voxels by ``cut_matrices``.

    ``cut_matrices(phi_c (m, 8), h, Es)`` -> (K (m, 48, 48), loads [(m, 48)] per E, side volumes
    (2, m), info): the 48 element unknowns are the standard and the extra DOF of the 8 corners;
    ``two_copies``: [phi < 0 copy, phi > 0 copy], a node's own phase on its standard DOF (Nitsche);
    otherwise [standard, extra] (enrichment). Returns C (len(cases), len(cases)) [Pa], the
    discrete particle volume fraction, CG iterations per case, the number of DOF, of cut voxels
    and ``info`` (None without cut voxels). ``wrap``: node layers (x, y, z) where the coordinates
    of the rigid-body candidates of the AMG wrap (:func:`_wrap_planes`). ``energy``:
    "variational", ``C_ab = A_ab - F_a.W_b - F_b.W_a + W_a.K W_b`` (A the affine energy), whose
    error is quadratic in the CG error (as in :mod:`homogenize.cell.problem`; measured on two Fe spheres
    at tol 1e-10: C changes by 2e-12 under a translation of the grid, against 6e-9 with the
    other); "linear", ``A_ab - F_a.W_b``, the form of results/cell/cut_cell_experiments.py,
    which keeps it to reproduce that study's JSON.
    """
    h = 1.0 / n
    pc = phi[nodes]
    nneg = (pc < 0).sum(axis=1)
    cut = (nneg > 0) & (nneg < 8)
    full = nneg == 8
    lam = np.where(full, lames[0][0], lames[1][0]).reshape(n, n, n)
    mu = np.where(full, lames[0][1], lames[1][1]).reshape(n, n, n)
    lam[cut.reshape(n, n, n)] = mu[cut.reshape(n, n, n)] = 0.0
    Es = [np.eye(6)[c] for c in cases]
    cvox = np.flatnonzero(cut)
    if cvox.size:
        Ke, loads, vol, info = cut_matrices(pc[cvox], h, Es)
    else:
        Ke, loads, vol, info = np.zeros((0, 48, 48)), [np.zeros((0, 48))] * len(Es), \
            np.zeros((2, 0)), None
    xnodes = np.unique(nodes[cvox])
    xid = -np.ones(n ** 3, np.int64)
    xid[xnodes] = np.arange(xnodes.size)
    nstd, ndof = 3 * n ** 3, 3 * n ** 3 + 3 * xnodes.size
    cn = nodes[cvox]
    std = 3 * cn[:, :, None] + np.arange(3)
    ext = nstd + 3 * xid[cn][:, :, None] + np.arange(3)
    if two_copies:     # a node's own phase uses its standard unknowns
        negnode = (phi[cn] < 0)[:, :, None]
        dof = np.concatenate([np.where(negnode, std, ext), np.where(negnode, ext, std)], axis=1)
    else:
        dof = np.concatenate([std, ext], axis=1)
    dof = dof.reshape(-1, 48)
    K = asm.assemble_bsr(lam, mu, h).tocsr()
    K.resize((ndof, ndof))
    K = (K + sp.coo_matrix((Ke.ravel(), (np.repeat(dof, 48, axis=1).ravel(),
                                         np.tile(dof, (1, 48)).ravel())),
                           shape=(ndof, ndof)).tocsr()).tocsr()
    F = []
    for e, c in enumerate(cases):
        f = np.zeros(ndof)
        f[:nstd] = asm.affine_load(lam, mu, h, voigt_to_tensor(np.eye(6)[c], engineering=True))
        np.add.at(f, dof.ravel(), loads[e].ravel())
        F.append(f)
    Cv = [asm.isotropic_voigt(*lm) for lm in lames]
    whole = np.where(full[~cut, None, None], Cv[0], Cv[1])
    aff = np.array([[h ** 3 * np.einsum("i,mij,j->", Ea, whole, Eb)
                     + sum(vol[s].sum() * (Ea @ Cv[s] @ Eb) for s in range(2))
                     for Eb in Es] for Ea in Es])
    keep = np.ones(ndof, bool)
    keep[:3] = False                  # pin node 0 (the loads are balanced)
    Kr = K[keep][:, keep].tocsr()
    B = np.zeros((ndof, 6))
    # node i gets the modes of node i - wrap: its coordinates wrap at the layer
    rb = rigid_body_modes(grid_node_coordinates(n, wrap))
    B[:nstd] = rb
    if two_copies:                    # both copies move with a rigid motion of the cell
        B[nstd:] = rb.reshape(n ** 3, 3, 6)[xnodes].reshape(-1, 6)
    ml = smoothed_aggregation(Kr, B[keep], _AMG)
    W, its = [], []
    fmax = max(np.linalg.norm(f) for f in F)
    for f in F:
        w = np.zeros(ndof)
        if np.linalg.norm(f) > 1e-12 * fmax:        # a load that vanishes by symmetry
            res = []
            w[keep] = ml.solve(f[keep], tol=tol, accel="cg", maxiter=5000, residuals=res)
            if res[-1] > 10 * tol * res[0]:
                raise ConvergenceError(f"CG of the cut-voxel cell problem did not converge: "
                                       f"relative residual {res[-1] / res[0]:.1e} after "
                                       f"{len(res) - 1} iterations (tol {tol:g})",
                                       [r / res[0] for r in res])
            its.append(len(res) - 1)
        else:
            its.append(0)
        W.append(w)
    if energy == "linear":
        C = np.array([[aff[a, b] - F[a] @ W[b] for b in range(len(cases))]
                      for a in range(len(cases))])
    else:
        KW = [K @ w for w in W]
        C = np.array([[aff[a, b] - F[a] @ W[b] - F[b] @ W[a] + W[a] @ KW[b]
                       for b in range(len(cases))] for a in range(len(cases))])
    phi_h = ((full.sum() * h ** 3) + vol[0].sum())
    return C, float(phi_h), its, ndof, int(cvox.size), info


#: the cut-voxel building blocks by public names, for studies of other cut-voxel
#: discretizations on the same cell problem (results/cell/cut_cell_experiments.py: the
#: ridge-enriched XFEM): the isotropic element matrices from gradient products, the per-side
#: integrals over the pieces of :func:`cut_pieces`, and the periodic cell problem that takes the
#: cut voxels' matrices from a callable (the docstrings are those of the private originals)
isotropic_element_matrices = _iso_K
side_integrals = _side_integrals
cut_cell_problem = _cut_cell_problem


# ------------------------------------------------------------------------------------------------
# public entry points
# ------------------------------------------------------------------------------------------------

def check_cut_memory(voxels: int, what: str | None = None) -> int:
    """Refuse (:class:`micro.InputError`) a cut-voxel solve whose memory estimate exceeds the
    machine's share, before allocating; returns the estimate [bytes]."""
    need = memory_estimate_bytes(voxels)
    check_memory(what or f"voxels={int(voxels)} (Nitsche cut voxels)", need,
                 "use fewer voxels, or the composite voxels of homogenize.cell.problem.homogenize_rve")
    return need


def _check_voxels(voxels):
    if isinstance(voxels, (bool, np.bool_)) or not isinstance(voxels, (int, np.integer)) \
            or voxels < 4:
        raise InputError(f"voxels must be an integer >= 4 (voxels per cube edge), got {voxels!r}")
    check_cut_memory(voxels)
    return int(voxels)


def _check_settings(voxels, matrix, particle, cases, tol, safety):
    n = _check_voxels(voxels)
    CELL_RANGES["tol"].check("tol", tol)
    check_range("safety", safety, 1.0, np.inf, "(Nitsche penalty over the coercivity bound)",
                lo_open=True, hi_open=True)
    try:
        cs = tuple(cases)
    except TypeError:
        raise InputError(f"cases must be a sequence of load cases in 0..5, got {cases!r}") from None
    if (not cs or len(set(cs)) != len(cs)
            or not all(isinstance(c, (int, np.integer)) and not isinstance(c, bool)
                       and 0 <= c <= 5 for c in cs)):
        raise InputError("cases must be distinct integers in 0..5 (Voigt 11, 22, 33, 23, 13, 12), "
                         f"at least one, got {cases!r}")
    matrix = elastic(PDMS) if matrix is None else matrix
    particle = elastic(FE) if particle is None else particle
    for name, mat in (("matrix", matrix), ("particle", particle)):
        if not isinstance(mat, ElasticMaterial):
            raise InputError(f"{name} must be a micro.materials.ElasticMaterial, got {mat!r}")
    return n, matrix, particle, tuple(int(c) for c in cs), float(tol), float(safety)


def _solve_nitsche(phi, nodes, n, matrix, particle, cases, tol, safety, wrap=(0, 0, 0)):
    lames = (particle.lame_Pa, matrix.lame_Pa)

    def cut_matrices(pc, h, Es):
        return nitsche_matrices(pc, h, lames, (particle.E_Pa, matrix.E_Pa), Es, safety)
    C, phi_h, its, ndof, ncut, alpha = _cut_cell_problem(phi, nodes, n, lames, cases, tol,
                                                         cut_matrices, two_copies=True,
                                                         wrap=wrap)
    C6 = np.full((6, 6), np.nan)
    C6[np.ix_(cases, cases)] = 0.5 * (C + C.T)       # symmetric already, up to round-off
    E = nu = None
    if len(cases) == 6:
        E, nu = isotropic_projection(C6)[:2]
    pen = None
    if alpha is not None:                 # alpha [Pa / box] x h [box] / E_m [Pa]
        h = 1.0 / n
        pen = tuple(float(f(alpha) * h / matrix.E_Pa) for f in (np.min, np.median, np.max))
    return C6, E, nu, phi_h, {CASES[c]: it for c, it in zip(cases, its)}, pen, ndof, ncut


def homogenize_level_set(phi_fn, voxels, *, matrix=None, particle=None, cases=range(6),
                         tol=1e-10, safety=2.0) -> CutResult:
    """Effective stiffness of the periodic unit cell with the particle phase where a level set is
    negative, by Nitsche cut voxels (the geometry-level sibling of :func:`homogenize_cut`).

    Parameters
    ----------
    phi_fn : callable -- ``phi_fn(x)``: x of shape (n, n, n, 3), node positions in box units
        ([0, 1)^3, indexed [k, j, i], components (x, y, z)) -> level set (n, n, n) [box units],
        < 0 in the particle phase, periodic. Only its nodal values are used: the interface is
        their Kuhn-linear interpolant. Each cut voxel has one particle copy, so particle
        regions must not meet inside one voxel (not checked here; :func:`homogenize_cut` checks
        it for spheres).
    voxels : int -- voxels per cube edge, >= 4
    matrix, particle : ElasticMaterial, optional -- phases at phi > 0 and phi < 0 (default PDMS
        and Fe, :mod:`micro.materials`)
    cases : iterable of int -- load cases to solve (Voigt 0..5 = 11, 22, 33, 23, 13, 12); the
        other rows and columns of ``C_eff_Pa`` are NaN
    tol : float -- relative residual of CG per case, in (0, 1e-2]
    safety : float -- Nitsche penalty over the per-voxel coercivity bound, > 1 (measured on the
        dilute sphere: 1.1 / 2 / 5 give +5.1 / +6.6 / +9.5 % at 5.9 voxels per diameter)

    Returns
    -------
    CutResult -- ``radius_scale`` None, ``settings["volume_matched"]`` None

    Raises
    ------
    InputError -- a setting outside its range or ``phi_fn`` not giving n^3 finite values
    ConvergenceError -- CG not converged in 5000 iterations
    """
    n, matrix, particle, cases, tol, safety = _check_settings(voxels, matrix, particle, cases,
                                                              tol, safety)
    if not callable(phi_fn):
        raise InputError(f"phi_fn must be callable (box-unit points -> level set), got {phi_fn!r}")
    x, nodes = _grid(n)
    phi = np.asarray(phi_fn(x), dtype=float)
    if phi.size != n ** 3 or not np.all(np.isfinite(phi)):
        raise InputError(f"phi_fn must return {n ** 3} finite values (one per node of the "
                         f"{n}^3 grid), got shape {phi.shape}")
    phi = _nonzero(phi.ravel(), n)
    C, E, nu, phi_h, its, pen, ndof, ncut = _solve_nitsche(phi, nodes, n, matrix, particle,
                                                           cases, tol, safety)
    return CutResult(C_eff_Pa=C, E_eff_Pa=E, nu_eff=nu, phi_discrete=phi_h, radius_scale=None,
                     iterations=its, penalty_h_over_E_matrix=pen, n_dof=ndof, n_cut_voxels=ncut,
                     settings={"method": "nitsche-cut", "tol": tol, "safety": safety,
                               "volume_matched": None, "voxels": n, "cases": list(cases)})


def _check_separated(phi, owner, nodes, n):
    """Refuse a voxel whose particle corners belong to two particles (one copy would glue them)."""
    neg = phi[nodes] < 0
    own = owner[nodes]
    hi = np.where(neg, own, -1).max(axis=1)
    lo = np.where(neg, own, np.iinfo(np.int64).max).min(axis=1)
    bad = np.flatnonzero(neg.any(axis=1) & (hi != lo))
    if bad.size:
        i, j = int(lo[bad[0]]), int(hi[bad[0]])
        raise InputError(f"particles {i} and {j} are closer than one voxel at voxels={n}: a cut "
                         "voxel would glue them; use method='composite' or more voxels")


def homogenize_cut(rve, voxels, *, matrix=None, particle=None, cases=range(6), tol=1e-10,
                   volume_matched=True, safety=2.0) -> CutResult:
    """Effective stiffness of a periodic RVE of spheres by Nitsche cut voxels (second order in
    the voxel size; module docstring).

    Parameters
    ----------
    rve : RVE -- or any object with ``box_m`` [m], ``centers_m`` (N, 3) [m], ``radii_m`` (N,) [m]
        (as :func:`homogenize.voxels.mesh.voxelize` accepts); N >= 1, radii < box_m / 2. The level
        set is the minimum over the particles of the periodic (minimum-image) distance to the
        centre minus the radius.
    voxels : int -- voxels per cube edge, >= 4
    matrix, particle : ElasticMaterial, optional -- default PDMS and Fe (:mod:`micro.materials`)
    cases : iterable of int -- load cases to solve (Voigt 0..5 = 11, 22, 33, 23, 13, 12); the
        other rows and columns of ``C_eff_Pa`` are NaN and E_eff_Pa, nu_eff None
    tol : float -- relative residual of CG per case, in (0, 1e-2]; C_eff is variational, its
        error is of the order of the squared solution error
    volume_matched : bool -- scale all radii by one common factor (``radius_scale``) so that the
        discrete particles hold the exact total particle volume (the faceted interface lies
        inside a convex particle: 11 % of the volume is lost at 4.3 voxels per diameter, which
        hides part of the error by cancellation)
    safety : float -- Nitsche penalty over the per-voxel coercivity bound, > 1

    Returns
    -------
    CutResult

    Raises
    ------
    InputError -- before any solve: voxels not an integer >= 4 or beyond the machine's memory
        (:func:`memory_estimate_bytes`), tol outside (0, 1e-2], safety
        <= 1, bad cases, materials or RVE, a particle that contains no grid node, or two particles
        closer than one voxel (their particle corners meet in one voxel)
    ConvergenceError -- CG not converged in 5000 iterations
    """
    n, matrix, particle, cases, tol, safety = _check_settings(voxels, matrix, particle, cases,
                                                              tol, safety)
    box, centres_m, radii_m = _as_geometry(rve)
    if radii_m.size == 0:
        raise InputError("rve has no particles: the cut-voxel method needs at least one (without "
                         "particles C_eff is the matrix stiffness)")
    if np.any(radii_m >= 0.5 * box):
        raise InputError(f"rve.radii_m must be < box_m / 2 = {0.5 * box:.3g} m for the periodic "
                         f"level set, got {radii_m.max():.3g} m")
    c, r = centres_m / box, radii_m / box           # box units
    if 4.0 / 3.0 * np.pi * np.sum(r ** 3) >= 1.0:
        raise InputError("rve: the particles' total volume is not below the box volume "
                         "(overlapping particles)")
    x, nodes = _grid(n)

    def geometry(scale):
        phi, owner = _particles_phi(x, c, scale * r)
        return _nonzero(phi.ravel(), n), owner.ravel()

    phi, owner = geometry(1.0)
    _check_separated(phi, owner, nodes, n)
    scale = 1.0
    if volume_matched:
        target = 4.0 / 3.0 * np.pi * np.sum(r ** 3)
        scale = _match_volume(lambda s: _discrete_volume_nodal(geometry(s)[0], nodes, n),
                              target, 1.0)
        phi, owner = geometry(scale)
        _check_separated(phi, owner, nodes, n)
    empty = np.setdiff1d(np.arange(r.size), owner[phi < 0])
    if empty.size:
        i = int(empty[0])
        raise InputError(f"particle {i} (radius {r[i] * n:.2f} voxels) contains no grid node at "
                         f"voxels={n}: the cut-voxel level set cannot represent it; use "
                         "method='composite' or more voxels")
    C, E, nu, phi_h, its, pen, ndof, ncut = _solve_nitsche(phi, nodes, n, matrix, particle,
                                                           cases, tol, safety,
                                                           _wrap_planes(c, scale * r, n))
    return CutResult(C_eff_Pa=C, E_eff_Pa=E, nu_eff=nu, phi_discrete=phi_h,
                     radius_scale=float(scale), iterations=its, penalty_h_over_E_matrix=pen,
                     n_dof=ndof, n_cut_voxels=ncut,
                     settings={"method": "nitsche-cut", "tol": tol, "safety": safety,
                               "volume_matched": bool(volume_matched), "voxels": n,
                               "cases": list(cases)})
