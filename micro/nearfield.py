"""Near-field magnetic force between two magnetizable spheres beyond point dipoles.

Model
-----
Two spheres (radii ``a1``, ``a2``, relative permeabilities ``mu1``, ``mu2``, linear) in a
uniform applied field ``H0`` in a non-magnetic matrix. The scalar potential outside is expanded
in exterior solid harmonics about both centres (multipole orders ``n = 1 .. L``); the
addition theorem for an axial translation re-expands the harmonics of one sphere about the
other, and the interface conditions on each sphere (continuity of the potential and of
``mu dpsi/dr``) give, per azimuthal order ``m`` (0: field along the line of centres, 1:
across it), a linear system of size ``2L`` for the multipole coefficients (the two-centre
multipole method of Clercx & Bossis 1993, here for magnetostatics). Its solution is exact
as ``L -> inf``; ``L`` is chosen from the geometric convergence rate of the coefficients
(set by the limit points of the bispherical coordinates of the pair) and checked by
doubling it (:func:`pair_polarizabilities`, ``check=True``).

The force follows from the co-energy of linear bodies in a field of fixed sources,
``W = (mu0 / 2) H0 . m_total``, with the total moment of the pair
``m_total = alpha_par (H0 . n) n + alpha_perp (H0 - (H0 . n) n)`` (``n`` the unit vector of
the line of centres): ``F_1 = dW / dx_1`` at fixed ``H0`` (:func:`pair_force_N`), so
``F_2 = -F_1`` exactly (Newton's third law) and the force has a radial part (``alpha'(r)``)
and a tangential part (``alpha_par - alpha_perp``) that turns the pair towards the field.
``d alpha / d r`` is exact (differentiated linear system, no finite differences).

Point dipoles of the same spheres (polarizabilities ``4 pi a^3 beta``,
``beta = (mu - 1)/(mu + 2)``, mutually self-consistent) have the closed-form pair
polarizabilities of :func:`point_dipole_polarizabilities`; the correction
(:func:`near_field_correction_N`) is the exact pair force minus the point-dipole pair force
in the same field, which vanishes at large separation (as ``r^-9`` against the ``r^-4`` of
the dipole force for equal spheres). This is what :func:`homogenize.cell.relax.relax` adds to its
periodic self-consistent point-dipole forces with ``near_field=True``.

Nonlinear (saturating) laws: the spheres are treated as linear with their CHORD (secant)
intrinsic susceptibility at their current internal field, ``chi = M / H_in``, from the
apparent one ``chi_a = |m| / (V |H_loc|) = 3 chi / (3 + chi)``
(:func:`chord_permeability`). This is a linearisation: it ignores that the field in a narrow
gap is much higher than the mean field of the sphere (local saturation near contact lowers the
true force), so near contact it overestimates the force of saturating particles. An infinite
intrinsic susceptibility (Fe's ``approach`` law below ``w Ms``: ``chi_a = 3``) is capped at
``mu_max`` (default 1000, the order of iron's initial relative permeability), where the
contact force of a perfectly permeable pair would diverge logarithmically.

Limits: two bodies only (pairwise additive; the near-field interactions of three or more close
spheres are not), uniform background field over the pair, linear magnetization per sphere,
rigid spheres. Units SI throughout (m, A/m, A m^2, N).

References: D. J. Jeffrey, Proc. R. Soc. A 335, 355 (1973) (conduction through two spheres,
pair polarizabilities); H. J. H. Clercx & G. Bossis, Phys. Rev. E 48, 2721 (1993) (multipole
method for magnetizable spheres); E. E. Keaveny & M. R. Maxey, J. Comput. Phys. 227, 9554
(2008) (magnetic forces between close spheres beyond dipoles).
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.constants import mu_0 as MU0
from scipy.linalg import lu_factor, lu_solve
from scipy.special import gammaln

from micro.common.validate import InputError, check_finite, check_range

__all__ = ["pair_polarizabilities", "point_dipole_polarizabilities", "pair_force_N",
           "point_dipole_pair_force_N", "near_field_correction_N", "chord_permeability",
           "multipole_order", "translation_coefficient", "fem_axial_polarizability", "MU_MAX",
           "L_MAX"]

#: Default cap of the chord relative permeability (infinite intrinsic susceptibility).
MU_MAX = 1000.0
#: Largest multipole order the adaptive choice uses.
L_MAX = 600


# ------------------------------------------------------------------------------------------
# Two-centre multipole solution
# ------------------------------------------------------------------------------------------
def _gamma(n, mu):
    """Response of a sphere to a regular harmonic of degree n: A = -gamma a^(2n+1) E."""
    n = np.asarray(n, dtype=float)
    if math.isinf(mu):
        return np.ones_like(n)
    return n * (mu - 1.0) / (n * mu + n + 1.0)


def translation_coefficient(k, n, m):
    """``T(k, n, m)``: an exterior harmonic of degree k about a centre at ``+R e_z`` re-expanded
    in regular harmonics about the origin (``r < R``)::

        r2^-(k+1) P_k^m(cos t2) = sum_n T(k, n, m) r^n P_n^m(cos t) / R^(k+n+1)

    ``T = (-1)^(k+m) (k+n)! / ((k-m)! (n+m)!)`` (``P_n^m`` as :func:`scipy.special.lpmv`, with
    the Condon-Shortley phase). Returns (sign, log|T|) arrays (factorials in logs: orders of
    several hundred)."""
    k = np.asarray(k, dtype=float)
    n = np.asarray(n, dtype=float)
    logT = gammaln(k + n + 1.0) - gammaln(k - m + 1.0) - gammaln(n + m + 1.0)
    sign = np.where((k + m) % 2 == 0, 1.0, -1.0)
    return sign, logT


def multipole_order(R, a1, a2, mu1=math.inf, mu2=math.inf, tol=1e-10):
    """Number of multipole orders L for a relative accuracy ~``tol`` of the pair moment.

    The coefficients decay geometrically as ``rho^n``, ``rho`` the ratio of the distance of
    the image limit point (bispherical coordinates) to the sphere radius, times the strength of
    an image, ``|mu - 1|/(mu + 1)`` per reflection, for the less favourable sphere."""
    # limit points of the bispherical system: x1 from centre 1 along the axis
    x1 = (R * R + a1 * a1 - a2 * a2) / (2.0 * R)
    c = math.sqrt(max(x1 * x1 - a1 * a1, 0.0))
    d1 = x1 - c                     # limit point inside sphere 1, distance from its centre
    d2 = (R - x1) - c               # inside sphere 2
    rho = max(d1 / a1, d2 / a2)

    def q(mu):
        return 1.0 if math.isinf(mu) else abs(mu - 1.0) / (mu + 1.0)

    rho = min(max(rho * math.sqrt(max(q(mu1) * q(mu2), 1e-300)), 1e-3), 1.0 - 1e-9)
    L = int(math.ceil(math.log(tol) / math.log(rho))) + 4
    return int(min(max(L, 6), L_MAX))


@functools.lru_cache(maxsize=64)
def _tables(L, m):
    """Index grids (rows n, columns k), sign and log|T| of the translation coefficients, and
    the parity (-1)^(k+n), for orders 1..L (cached: the factorials dominate the cost)."""
    n = np.arange(1, L + 1, dtype=float)
    K, Nn = np.meshgrid(n, n)                       # rows n (equation), columns k (source)
    sign, logT = translation_coefficient(K, Nn, m)
    if m > 0:
        logT = np.where((Nn >= m) & (K >= m), logT, -np.inf)
    parity = np.where((K + Nn) % 2 == 0, 1.0, -1.0)
    for a in (K, Nn, sign, logT, parity):
        a.setflags(write=False)
    return n, K, Nn, sign, logT, parity


def _system(R, a1, a2, mu1, mu2, L, m):
    """Matrix ``I + Q`` (2L x 2L), ``dQ/dR`` and right-hand side of the scaled coefficients
    ``x_n = A_n / a1^(n+1)``, ``y_n = B_n / a2^(n+1)`` (sphere 1 at the origin, sphere 2 at
    ``+R e_z``), for a unit applied field (along z for m = 0, along x for m = 1)."""
    n, K, Nn, sign, logT, parity = _tables(int(L), int(m))
    t1, t2 = a1 / R, a2 / R
    g1, g2 = _gamma(n, mu1), _gamma(n, mu2)
    # sphere 2's degree-k harmonic seen at sphere 1: T(k, n) t1^n t2^(k+1)
    Q12 = sign * np.exp(logT + Nn * math.log(t1) + (K + 1.0) * math.log(t2))
    # sphere 1's harmonic about sphere 2 (sphere 1 at -R e_z): (-1)^(k+n) T(k, n)
    Q21 = sign * parity * np.exp(logT + Nn * math.log(t2) + (K + 1.0) * math.log(t1))
    I = np.eye(L)
    A = np.block([[I, g1[:, None] * Q12], [g2[:, None] * Q21, I]])
    P = -(K + Nn + 1.0) / R                       # d/dR of R^-(k+n+1)
    dA = np.block([[np.zeros((L, L)), g1[:, None] * Q12 * P],
                   [g2[:, None] * Q21 * P, np.zeros((L, L))]])
    E0 = -1.0 if m == 0 else 1.0                  # psi0 = -H0 z = -H0 r P_1; -H0 x = H0 r P_1^1 cos
    b = np.zeros(2 * L)
    b[0] = -g1[0] * a1 * E0
    b[L] = -g2[0] * a2 * E0
    return A, dA, b


def _alpha(R, a1, a2, mu1, mu2, L, m):
    A, dA, b = _system(R, a1, a2, mu1, mu2, L, m)
    lu = lu_factor(A)
    z = lu_solve(lu, b)
    dz = -lu_solve(lu, dA @ z)
    s = 4.0 * math.pi * (1.0 if m == 0 else -1.0)
    alpha = s * (z[0] * a1 * a1 + z[L] * a2 * a2)
    dalpha = s * (dz[0] * a1 * a1 + dz[L] * a2 * a2)
    return alpha, dalpha


def _check_pair(R, a1, a2, mu1, mu2):
    check_range("a1_m", a1, 0.0, math.inf, "m", lo_open=True, hi_open=True)
    check_range("a2_m", a2, 0.0, math.inf, "m", lo_open=True, hi_open=True)
    check_finite("r_m", R, "m")
    if not R > a1 + a2:
        raise InputError(f"centre distance r_m must exceed a1_m + a2_m = {a1 + a2:.6g} m "
                         f"(spheres may not touch or overlap), got {R:.6g} m")
    for name, mu in (("mu1", mu1), ("mu2", mu2)):
        if not (mu >= 1.0):
            raise InputError(f"{name} (relative permeability) must be in [1, inf], got {mu}")


def pair_polarizabilities(r_m, a1_m, a2_m, mu1=math.inf, mu2=math.inf, *, L=None,
                          tol=1e-10, check=False):
    """Pair polarizabilities of two spheres from the two-centre multipole expansion [m^3].

    Returns ``(alpha_par, alpha_perp, dalpha_par_dr, dalpha_perp_dr)``: the total moment of the
    pair is ``alpha_par H0`` for a unit field along the line of centres, ``alpha_perp H0``
    across it; derivatives with respect to the centre distance [m^2]. ``L`` multipole orders
    (default :func:`multipole_order` for ``tol``); ``check=True`` also solves with ``2L`` and
    returns the largest relative change as a fifth value."""
    R, a1, a2 = float(r_m), float(a1_m), float(a2_m)
    _check_pair(R, a1, a2, mu1, mu2)
    if L is None:
        L = multipole_order(R, a1, a2, mu1, mu2, tol)
    L = int(L)
    if L < 1:
        raise InputError(f"L (multipole orders) must be >= 1, got {L}")
    ap, dap = _alpha(R, a1, a2, mu1, mu2, L, 0)
    at, dat = _alpha(R, a1, a2, mu1, mu2, L, 1)
    out = (ap, at, dap, dat)
    if check:
        ref = pair_polarizabilities(R, a1, a2, mu1, mu2, L=2 * L)
        scale = (abs(ap), abs(at), abs(ap) / R, abs(at) / R)
        err = max(abs(u - v) / s for u, v, s in zip(out, ref, scale))
        return out + (err,)
    return out


def _beta(mu):
    return 1.0 if math.isinf(mu) else (mu - 1.0) / (mu + 2.0)


def point_dipole_polarizabilities(r_m, a1_m, a2_m, mu1=math.inf, mu2=math.inf):
    """Pair polarizabilities of two self-consistent point dipoles [m^3] (and d/dr [m^2]).

    Each sphere is a point dipole of polarizability ``p_i = 4 pi a_i^3 beta_i`` in the applied
    field plus the other's dipole field ``k m`` (``k = 2/(4 pi r^3)`` along the line of centres,
    ``-1/(4 pi r^3)`` across): ``alpha = (p1 + p2 + 2 k p1 p2) / (1 - k^2 p1 p2)``."""
    R = float(r_m)
    p1 = 4.0 * math.pi * float(a1_m) ** 3 * _beta(mu1)
    p2 = 4.0 * math.pi * float(a2_m) ** 3 * _beta(mu2)
    out = []
    for c in (2.0, -1.0):
        k = c / (4.0 * math.pi * R ** 3)
        den = 1.0 - k * k * p1 * p2
        num = p1 + p2 + 2.0 * k * p1 * p2
        dadk = (2.0 * p1 * p2 * den + num * 2.0 * k * p1 * p2) / den ** 2
        out.append((num / den, dadk * (-3.0 * k / R)))
    return out[0][0], out[1][0], out[0][1], out[1][1]


def _force_from_alpha(d, H, ap, at, dap, dat):
    d = np.asarray(d, dtype=float)
    H = np.asarray(H, dtype=float)
    r = float(np.linalg.norm(d))
    n = d / r
    c = float(H @ n)
    H2 = float(H @ H)
    return 0.5 * MU0 * ((dap * c * c + dat * (H2 - c * c)) * n
                        + 2.0 * (ap - at) * c * (H - c * n) / r)


def _check_vectors(d, H):
    d = np.asarray(check_finite("d_m", d, "m"), dtype=float)
    H = np.asarray(check_finite("H0_A_m", H, "A/m"), dtype=float)
    if d.shape != (3,) or H.shape != (3,):
        raise InputError("d_m and H0_A_m must be 3-vectors")
    return d, H


def pair_force_N(d_m, a1_m, a2_m, H0_A_m, mu1=math.inf, mu2=math.inf, *, L=None, tol=1e-10):
    """Exact (multipole) force on sphere 1 from sphere 2 in the uniform field ``H0_A_m`` [N].

    ``d_m = x1 - x2`` [m]; the force on sphere 2 is the negative. ``F_1 = dW/dx_1`` with the
    co-energy ``W = (mu0/2) H0 . m_total`` (see the module docstring)."""
    d, H = _check_vectors(d_m, H0_A_m)
    r = float(np.linalg.norm(d))
    return _force_from_alpha(d, H, *pair_polarizabilities(r, a1_m, a2_m, mu1, mu2, L=L,
                                                           tol=tol))


def point_dipole_pair_force_N(d_m, a1_m, a2_m, H0_A_m, mu1=math.inf, mu2=math.inf):
    """Force on sphere 1 between two mutually self-consistent point dipoles [N]."""
    d, H = _check_vectors(d_m, H0_A_m)
    r = float(np.linalg.norm(d))
    _check_pair(r, float(a1_m), float(a2_m), mu1, mu2)
    return _force_from_alpha(d, H, *point_dipole_polarizabilities(r, a1_m, a2_m, mu1, mu2))


def near_field_correction_N(d_m, a1_m, a2_m, H0_A_m, mu1=math.inf, mu2=math.inf, *, L=None,
                            tol=1e-10):
    """Exact pair force minus the point-dipole pair force on sphere 1 [N] (zero at large
    separation); the correction on sphere 2 is the negative."""
    d, H = _check_vectors(d_m, H0_A_m)
    r = float(np.linalg.norm(d))
    ex = pair_polarizabilities(r, a1_m, a2_m, mu1, mu2, L=L, tol=tol)
    pd = point_dipole_polarizabilities(r, a1_m, a2_m, mu1, mu2)
    return _force_from_alpha(d, H, *(u - v for u, v in zip(ex, pd)))


def chord_permeability(moment_Am2, H_loc_A_m, volume_m3, mu_max=MU_MAX):
    """Chord (secant) relative permeability of a sphere from its moment in its local field.

    ``chi_a = |m| / (V |H_loc|)`` is the apparent susceptibility of the sphere,
    ``chi_a = 3 chi / (3 + chi)`` with ``chi = M / H_in`` the chord intrinsic susceptibility,
    so ``mu = 1 + chi = (3 + 2 chi_a) / (3 - chi_a)``, capped at ``mu_max`` (``chi_a -> 3``:
    infinite intrinsic susceptibility). Zero field: ``mu = 1`` (no moment, no force)."""
    m = np.atleast_2d(np.asarray(moment_Am2, dtype=float))
    H = np.atleast_2d(np.asarray(H_loc_A_m, dtype=float))
    V = np.broadcast_to(np.asarray(volume_m3, dtype=float), (m.shape[0],))
    hm = np.linalg.norm(H, axis=1)
    mm = np.linalg.norm(m, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        chi_a = np.where(hm > 0, mm / (V * np.where(hm > 0, hm, 1.0)), 0.0)
    chi_a = np.clip(chi_a, 0.0, 3.0)
    with np.errstate(divide="ignore"):
        mu = np.where(chi_a < 3.0, (3.0 + 2.0 * chi_a) / np.maximum(3.0 - chi_a, 1e-300),
                      math.inf)
    return np.minimum(mu, float(mu_max))


# ------------------------------------------------------------------------------------------
# Independent check: axisymmetric finite elements (gmsh + scikit-fem)
# ------------------------------------------------------------------------------------------
def fem_axial_polarizability(r_m, a_m, mu, *, h_surface=0.05, domain_factor=30.0,
                             morph_m=0.0):
    """Total moment per unit field along the line of centres, ``alpha_par`` [m^3], of two
    equal spheres from an axisymmetric magnetostatic FEM (independent of the multipoles).

    The reduced scalar potential solves ``div(mu grad psi) = 0`` in the (r, z) half-plane
    (weight ``r``), quadratic triangles (scikit-fem ``ElementTriP2``) on a gmsh mesh that
    conforms to the sphere surfaces (size ``h_surface`` radii there, a quarter of the gap in
    the gap), ``psi = -H0 z`` on a half-circle of ``domain_factor`` centre distances (the
    truncation changes alpha by ~(2a / R_domain)^3 relative) and the moment is
    ``int (mu - 1) H_z dV`` over the spheres. ``morph_m`` stretches the mesh of the gap so that
    the spheres are ``r_m + morph_m`` apart with the same mesh topology: central differences in
    it give ``d alpha / d r`` (the force) without remeshing noise. Needs gmsh (Python API).
    """
    import gmsh
    from skfem import Basis, BilinearForm, ElementTriP2, Functional, MeshTri, asm, condense
    from skfem import solve as fem_solve
    from skfem.helpers import dot, grad

    R, a = float(r_m), float(a_m)
    _check_pair(R, a, a, float(mu), float(mu))
    if math.isinf(mu):
        raise InputError("fem_axial_polarizability needs a finite mu")
    g = R - 2.0 * a
    hs = h_surface * a
    hg = min(hs, g / 4.0)
    Rd = domain_factor * R
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("pair")
        occ = gmsh.model.occ
        half, _ = occ.cut([(2, occ.addDisk(0, 0, 0, Rd, Rd))],
                          [(2, occ.addRectangle(-Rd, -Rd, 0, Rd, 2 * Rd))])
        halves = []
        for zc in (-R / 2, R / 2):
            d, _ = occ.intersect([(2, occ.addDisk(0, zc, 0, a, a))],
                                 [(2, occ.addRectangle(0, zc - a, 0, a, 2 * a))])
            halves += d
        occ.fragment(half, halves)
        occ.synchronize()
        fld = gmsh.model.mesh.field
        f_gap = fld.add("MathEval")
        fld.setString(f_gap, "F", f"{hg} + Max(0, Sqrt(x*x + y*y) - {g}) * {hs / a}")
        f_srf = fld.add("MathEval")
        fld.setString(f_srf, "F", f"{hs} + 0.25 * Max(0, Min(Abs(Sqrt(x*x + (y - {R / 2})^2) - "
                                  f"{a}), Abs(Sqrt(x*x + (y + {R / 2})^2) - {a})))")
        f_min = fld.add("Min")
        fld.setNumbers(f_min, "FieldsList", [f_gap, f_srf])
        fld.setAsBackgroundMesh(f_min)
        for opt in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints",
                    "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(opt, 0)
        gmsh.model.mesh.generate(2)
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        _, _, enodes = gmsh.model.mesh.getElements(2)
    finally:
        gmsh.finalize()
    pos = {int(t): i for i, t in enumerate(tags)}
    p = xyz.reshape(-1, 3)[:, :2].T
    tri = np.array([pos[int(t)] for t in enodes[0]]).reshape(-1, 3).T
    used = np.unique(tri)
    remap = np.full(p.shape[1], -1)
    remap[used] = np.arange(used.size)
    p, tri = p[:, used].copy(), remap[tri]
    p[0] = np.maximum(p[0], 0.0)
    if morph_m:
        p[1] = p[1] + 0.5 * morph_m * np.clip(2.0 * p[1] / g, -1.0, 1.0)
    R2 = R + morph_m
    mesh = MeshTri(np.ascontiguousarray(p), np.ascontiguousarray(tri))
    cen = p[:, tri].mean(axis=1)
    chi = np.where(np.hypot(cen[0], np.abs(cen[1]) - R2 / 2) < a, float(mu) - 1.0, 0.0)
    basis = Basis(mesh, ElementTriP2())
    nq = basis.X.shape[-1]

    @BilinearForm
    def lap(u, v, w):
        return (1.0 + w.chi) * dot(grad(u), grad(v)) * w.x[0]

    @Functional
    def moment(w):
        return 2.0 * math.pi * w.chi * (-w.psi.grad[1]) * w.x[0]

    chi_q = np.repeat(chi[:, None], nq, axis=1)
    A = asm(lap, basis, chi=chi_q)
    X = basis.doflocs
    # Dirichlet on the outer arc: every boundary facet off the axis r = 0 (facet-based, so the
    # midside degrees of freedom of the chords and the morphed nodes are included)
    bf = mesh.boundary_facets()
    mid = mesh.p[:, mesh.facets[:, bf]].mean(axis=1)
    D = basis.get_dofs(bf[np.hypot(mid[0], mid[1]) > 0.5 * Rd]).all()
    psi = np.zeros(basis.N)
    psi[D] = -X[1, D]
    psi = fem_solve(*condense(A, np.zeros(basis.N), x=psi, D=D))
    return float(moment.assemble(basis, psi=basis.interpolate(psi), chi=chi_q))
