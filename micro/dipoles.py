"""Self-consistent point-dipole moments of the particles of a periodic RVE; forces and effective
quantities.

Model
-----
Each particle i is a point dipole ``m_i`` [A m^2] at its centre, magnetised by its local field
(law from :mod:`micro.magnetization`)::

    H_loc,i = H_ext(x_i) + sum_{j, images} H_dip(x_i - x_j - n L; m_j) - N M_eff

``H_ext = (B + G (x - x_c)) / mu0`` is the applied field: uniform flux density ``B`` [T] plus a
uniform gradient ``G_ab = dB_a/dx_b`` [T/m] about the box centre ``x_c``. The periodic sum is an
Ewald sum (plain, or smooth particle-mesh Ewald for large N) with metallic ("tin-foil")
boundary: the mean field in the sample equals the applied field. A demagnetizing factor ``N``
(0: long rod along the field, 1/3: sphere, 1: thin plate normal to the field) turns the applied
field into the internal one, ``H_applied - N M_eff``, solved self-consistently.

Forces: ``F_i = mu0 (m_i . grad) H`` at the centre, split into the external-gradient part
``G m_i`` and the dipole-dipole part. For an induced moment this is ``-grad`` of the particle's
energy ``-mu0 int_0^|H| m(h) dh`` (e.g. ``(mu0 alpha / 2) grad |H|^2`` for a linear particle),
not ``grad(m . B)`` at fixed m, which would double it.

Effective quantities: ``M_eff = sum m / V`` [A/m], ``f_eff = sum F_ext / V`` [N/m^3], the
magnetic virial stress ``sigma = -(1/V) sum_pairs r_ij (x) F_ij`` [Pa] of the dipole-dipole
interaction (tin-foil lattice sum; the specimen's demagnetizing term is a macroscopic Maxwell
stress and not included), ``phi_eff = f_eff.g / (rho sigma_s |g|^2)`` with ``g = grad|B|`` (the
volume fraction of saturated material giving the same force) and ``d_eff = phi_eff / c`` (what
the seed paper's packing density 0.5 should have been, for its powder concentration ``c``).

Units: SI throughout (m, A m^2, A/m, T, T/m, N, N/m^3, Pa).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.constants import mu_0 as MU0

from micro import _kernels as K
from micro._ewald import PeriodicSum
from micro.common.jit import one_blas_thread
from micro.common.validate import ConvergenceError, InputError, Range, check_choice, check_finite, check_positive
from micro.magnetization import DEFAULT_LAW, MagnetizationLaw, get_law
from micro.materials import SEED
from micro.box import PeriodicBox
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import NoConvergence, newton_krylov
from scipy.sparse.linalg import LinearOperator
from scipy.constants import k as KB

__all__ = ["MagneticState", "ConvergenceError", "solve", "applied_gradient", "DipoleSum",
           "langevin_coupling", "LANGEVIN_LAMBDA_MAX",
           "dipole_field_direct", "dipole_pair_interactions", "FieldConfig", "magnetize", "METHODS", "SUMMATIONS",
           "PME_ABOVE_N", "FIELD_RANGES"]

METHODS = ("anderson", "fixed-point", "newton-krylov")
SUMMATIONS = ("auto", "ewald", "pme")
#: The allowed values of the magnetic stage's numeric settings, defined once: FieldConfig,
#: solve, DipoleSum, the study files' rules (homogenize.tables._study) and the CLI options
#: (``FIELD_RANGES["tol"].arg("--tol")``) all check these objects. tol: a relative residual
#: below 1e-14 is not reachable in double precision, above 1e-2 the moments are meaningless.
FIELD_RANGES = {
    "tol": Range(1e-14, 1e-2, "(relative residual)"),
    "accuracy": Range(1e-12, 1e-2, "(relative accuracy)"),
    "demag_factor": Range(0.0, 1.0),
    "damping": Range(0.0, 2.0, lo_open=True, hi_open=True),
    "max_iter": Range(1, 10 ** 5, integer=True),
    "c_powder": Range(0.0, 1.0, lo_open=True),
    "rho_kg_m3": Range(0.0, 3e4, "kg/m^3", lo_open=True),
    "sigma_s_Am2_kg": Range(0.0, 300.0, "A m^2/kg", lo_open=True),
}
_STALL_ITERATIONS = 40         # Anderson gives up after this many iterations without progress
PME_ABOVE_N = 3000            # "auto": plain Ewald below, PME above (both O(N^1.5)/O(N log N))


# ------------------------------------------------------------------------------------------
# Non-periodic sums (open boundary): direct kernel
# ------------------------------------------------------------------------------------------
def dipole_field_direct(sources_m, moments_Am2, observers_m, parallel=True):
    """Field [A/m] of point dipoles at observer points, open boundary, O(Ns No).

    Parameters
    ----------
    sources_m : ndarray, shape (Ns, 3) -- dipole positions [m]
    moments_Am2 : ndarray, shape (Ns, 3) -- dipole moments [A m^2]
    observers_m : ndarray, shape (No, 3) -- observer positions [m]; an observer on a source
        gets no contribution from that source (self-field excluded)

    Returns
    -------
    H_A_m : ndarray, shape (No, 3)
    """
    src = np.asarray(sources_m, dtype=float)
    mom = np.asarray(moments_Am2, dtype=float)
    obs = np.asarray(observers_m, dtype=float)
    for name, a in (("sources_m", src), ("moments_Am2", mom), ("observers_m", obs)):
        if a.ndim != 2 or a.shape[1] != 3:
            raise InputError(f"{name} must have shape (N, 3), got {a.shape}")
        check_finite(name, a)
    if src.shape != mom.shape:
        raise InputError(f"moments_Am2 shape {mom.shape} must match sources_m {src.shape}")
    # relative coordinates about a common origin keep the differences exact-ish
    o = src.mean(axis=0) if src.shape[0] else np.zeros(3)
    out = np.empty((3, obs.shape[0]))
    fn = K.dipole_field_direct_par if parallel else K.dipole_field_direct
    fn(np.ascontiguousarray((src - o).T), np.ascontiguousarray(mom.T),
       np.ascontiguousarray((obs - o).T), out)
    return out.T / (4 * math.pi)


def dipole_pair_interactions(centers_m, moments_Am2):
    """Field, force and torque on each of a few dipoles from all the others, open boundary.

    Returns ``(H_A_m (N,3), F_N (N,3), torque_Nm (N,3))`` with ``F_i = mu0 (m_i . grad) H`` and
    ``torque_i = mu0 m_i x H``. Uses the bare (alpha = 0) real-space kernel on a box large enough
    to contain no images; meant for small N and tests.
    """
    c = np.asarray(centers_m, dtype=float)
    m = np.asarray(moments_Am2, dtype=float)
    if c.ndim != 2 or c.shape[1] != 3 or m.shape != c.shape:
        raise InputError("centers_m and moments_Am2 must both have shape (N, 3)")
    ext = float(np.ptp(c, axis=0).max()) or 1.0
    box = 4.0 * ext
    pos = np.ascontiguousarray((c - c.min(axis=0)) / box + 0.25)
    n = c.shape[0]
    h = np.empty((n, 3))
    f = np.empty((n, 3))
    v = np.empty((n, 9))
    order = np.arange(n, dtype=np.int64)
    start = np.array([0, n], dtype=np.int64)
    # one cell, no neighbour offsets: only the n = 0 image; all pairs closer than rc = 0.5 box
    K.ewald_real(pos, np.ascontiguousarray(m), order, order, start, 1, 0, 0.0, 0.5, True, h, f,
                 v)
    H = h / (4 * math.pi * box ** 3)
    F = MU0 * f / (4 * math.pi * box ** 4)
    return H, F, MU0 * np.cross(m, H)


# ------------------------------------------------------------------------------------------
# Periodic sums in SI units
# ------------------------------------------------------------------------------------------
class DipoleSum:
    """Periodic dipolar field of point dipoles at fixed centres in a cubic box (SI wrapper).

    Parameters
    ----------
    box_m : float -- cube edge L [m]
    centers_m : ndarray, shape (N, 3) -- centres [m] (wrapped into the box)
    accuracy : float -- relative accuracy of the field, in (1e-12, 1e-1]
    summation : {"ewald", "pme"} -- plain Ewald (reference) or smooth particle-mesh Ewald
    demag_factor : float or None -- None: metallic boundary; else the specimen demagnetizing
        factor N in [0, 1], adding ``-N sum(m)/V`` to every field
    alpha_per_m : float, optional -- Ewald splitting parameter [1/m]; automatic if None
    """

    def __init__(self, box_m, centers_m, *, accuracy=1e-6, summation="pme", demag_factor=None,
                 alpha_per_m=None, pme_order=None, pme_grid=None):
        self.box_m = check_positive("box_m", box_m, "m")
        FIELD_RANGES["accuracy"].check("accuracy", accuracy)
        check_choice("summation", summation, ("ewald", "pme"))
        c = np.asarray(centers_m, dtype=float)
        if c.ndim != 2 or c.shape[1] != 3:
            raise InputError(f"centers_m must have shape (N, 3), got {c.shape}")
        check_finite("centers_m", c, "m")
        if demag_factor is not None:
            FIELD_RANGES["demag_factor"].check("demag_factor", demag_factor)
        self.demag_factor = demag_factor
        u = PeriodicBox(self.box_m).fractional(c)
        alpha = None if alpha_per_m is None else float(alpha_per_m) * self.box_m
        self._sum = PeriodicSum(u, accuracy, summation, alpha, pme_order, grid=pme_grid)
        self.n = c.shape[0]
        self.volume_m3 = self.box_m ** 3

    @property
    def evaluations(self) -> int:
        """Number of field evaluations so far."""
        return self._sum.evaluations

    @property
    def parameters(self) -> dict:
        """Splitting parameter [1/m], real-space cutoff [m], k cutoff or PME grid."""
        s = self._sum
        out = {"summation": s.method, "alpha_per_m": s.alpha / self.box_m,
               "rc_m": s.rc * self.box_m, "accuracy": s.accuracy}
        if s.method == "pme":
            out.update(pme_grid=s.grid, pme_order=s.order)
        else:
            out.update(n_kvectors=int(s.kvec.shape[0]))
        return out

    def _surface(self, mom):
        if self.demag_factor is None:
            return 0.0
        return -self.demag_factor * mom.sum(axis=0) / self.volume_m3

    def field_A_m(self, moments_Am2):
        """Field [A/m] at each centre from all other dipoles and all images, shape (N, 3)."""
        mom = np.ascontiguousarray(moments_Am2, dtype=float)
        return self._sum.field(mom) / self.box_m ** 3 + self._surface(mom)

    def interactions(self, moments_Am2):
        """Dipole-dipole field [A/m], forces [N], energy [J] and virial stress [Pa].

        The stress is ``-(1/V) sum_pairs r_ij (x) F_ij`` over the periodic lattice sum
        (tin-foil; the demagnetizing surface term is not part of it).
        """
        mom = np.ascontiguousarray(moments_Am2, dtype=float)
        h, f, u, p = self._sum.interactions(mom)
        L = self.box_m
        H = h / L ** 3 + self._surface(mom)
        F = MU0 * f / L ** 4
        energy = MU0 * u / L ** 3
        sigma = MU0 * p.T / L ** 6
        return H, F, energy, sigma


# ------------------------------------------------------------------------------------------
# Applied field
# ------------------------------------------------------------------------------------------
def applied_gradient(B_T, gradB_T_per_m):
    """The applied flux density vector [T] and its gradient tensor ``G_ab = dB_a/dx_b`` [T/m].

    ``B_T`` is a scalar (along z) or a 3-vector. ``gradB_T_per_m`` is either a scalar
    ``d|B|/dz`` -- then G is the symmetric, traceless (curl- and divergence-free) tensor with
    ``grad|B| = G^T b = gradB z`` (for B along z: ``diag(-1/2, -1/2, 1) gradB``) -- or a 3x3
    tensor, which must be symmetric and traceless (Maxwell in free space).
    """
    check_finite("B_T", B_T, "T")
    check_finite("gradB_T_per_m", gradB_T_per_m, "T/m")
    B = np.asarray(B_T, dtype=float)
    if B.ndim == 0:
        B = np.array([0.0, 0.0, float(B)])
    if B.shape != (3,):
        raise InputError(f"B_T must be a scalar or a 3-vector [T], got shape {B.shape}")
    Bn = float(np.linalg.norm(B))
    b = B / Bn if Bn > 0 else np.array([0.0, 0.0, 1.0])
    g = np.asarray(gradB_T_per_m, dtype=float)
    if g.ndim == 0:
        z = np.array([0.0, 0.0, 1.0])
        c = float(b @ z)
        G = float(g) * (np.outer(b, z) + np.outer(z, b) - c * np.outer(b, b)
                        - 0.5 * c * (np.eye(3) - np.outer(b, b)))
    elif g.shape == (3, 3):
        G = g.copy()
        scale = max(float(np.abs(G).max()), 1e-300)
        if np.abs(G - G.T).max() > 1e-9 * scale or abs(np.trace(G)) > 1e-9 * scale:
            raise InputError("gradB_T_per_m as a 3x3 tensor dB_a/dx_b must be symmetric and "
                             "traceless (curl B = 0 and div B = 0 in the matrix) [T/m]")
    else:
        raise InputError(f"gradB_T_per_m must be a scalar or 3x3 [T/m], got shape {g.shape}")
    return B, G


# ------------------------------------------------------------------------------------------
# Self-consistent solve
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MagneticState:
    """Converged magnetic state of an RVE (SI units).

    Attributes
    ----------
    moments_Am2 : (N, 3) particle moments [A m^2]
    H_local_A_m : (N, 3) local field at each centre (applied + others + demag) [A/m]
    force_ext_N : (N, 3) external-gradient force ``G m_i`` [N]
    force_dd_N : (N, 3) dipole-dipole force ``mu0 (m_i . grad) H_dd`` [N]
    M_eff_A_per_m : (3,) ``sum m / V`` [A/m]
    f_eff_N_m3 : (3,) ``sum F_ext / V`` [N/m^3]
    virial_stress_Pa : (3, 3) ``-(1/V) sum_pairs r_ij (x) F_ij`` [Pa]
    phi_eff, d_eff : effective saturated volume fraction and packing density (None if no
        gradient)
    iterations : number of solver iterations
    residual_history : relative residual ``|m_new - m| / |m_new|`` per iteration
    """

    moments_Am2: np.ndarray
    H_local_A_m: np.ndarray
    force_ext_N: np.ndarray
    force_dd_N: np.ndarray
    M_eff_A_per_m: np.ndarray
    f_eff_N_m3: np.ndarray
    virial_stress_Pa: np.ndarray
    phi_eff: float | None
    d_eff: float | None
    iterations: int
    residual_history: tuple
    field_evaluations: int = 0
    energy_dd_J: float = 0.0
    B_applied_T: np.ndarray = field(default=None)
    gradient_T_per_m: np.ndarray = field(default=None)
    summation: dict = field(default_factory=dict)
    law: str = ""

    @property
    def residual(self) -> float:
        """Final relative residual."""
        return float(self.residual_history[-1]) if self.residual_history else 0.0

    @property
    def total_force_N(self) -> np.ndarray:
        """(N, 3) total magnetic force on each particle, external gradient + dipole-dipole [N]:
        what the cell problem spreads over the particles."""
        return np.asarray(self.force_ext_N) + np.asarray(self.force_dd_N)

    @property
    def dd_force_sum_rel(self) -> float:
        """|sum of dipole-dipole forces| / sum |F_dd|: zero by Newton's third law."""
        tot = float(np.abs(self.force_dd_N).sum())
        return float(np.linalg.norm(self.force_dd_N.sum(axis=0))) / tot if tot > 0 else 0.0


def _law_jacobian(law, H_A_m, m_sat, vol):
    """``dm/dH`` (N, 3, 3) [m^3] of moments ``|m|(h) H/h``: ``(|m|/h) (I - u u) + |m|'(h) u u``
    (the initial slope at h = 0)."""
    h = np.sqrt(np.einsum("ij,ij->i", H_A_m, H_A_m))
    hs = np.where(h > 0, h, 1.0)
    mag = law.magnitude(h, m_sat, vol)
    slope = law.slope(h, m_sat, vol)
    chord = np.where(h > 0, mag / hs, law.slope(np.zeros_like(h), m_sat, vol))
    u = np.where(h[:, None] > 0, H_A_m / hs[:, None], 0.0)
    uu = u[:, :, None] * u[:, None, :]
    return chord[:, None, None] * (np.eye(3) - uu) + slope[:, None, None] * uu


class _NearFieldPreconditioner:
    """Approximate inverse of ``I - J`` (J: Jacobian of the fixed-point map) from near pairs.

    The slow modes of the fixed-point iteration ``x = g(x)`` are those of strongly coupled
    neighbours (chains, clusters, contacts), whose field ``~ m / (4 pi d^3)`` is a sizeable
    fraction of the applied one. ``P = I - D T_near`` keeps the bare dipole coupling ``T_near``
    of pairs closer than ``factor (r_i + r_j)`` (minimum image) and the per-particle law
    Jacobian ``D = dm/dH`` (``(|m|/h) (I - u u) + |m|'(h) u u``); an incomplete LU of P is
    applied to the residual. The preconditioned map ``x + P^-1 (g(x) - x)`` has the same fixed
    point as g (P only changes the path), and its Jacobian ``P^-1 D T_far`` is much smaller.
    """

    factor = 1.25            # pairs with gaps below a quarter of the contact distance

    def __init__(self, centers_m, box_m, radii_m, law, m_sat, vol):
        n = centers_m.shape[0]
        self.law, self.m_sat, self.vol = law, m_sat, vol
        self.n = n
        self.T = None
        cut = self.factor * 2.0 * float(radii_m.max())
        if n < 2 or cut >= 0.5 * box_m:        # tiny box: leave it to Anderson alone
            return
        pbox = PeriodicBox(box_m)
        i, j, _ = pbox.pairs_within(centers_m, cut)
        if i.size == 0:
            return
        d = centers_m[i] - centers_m[j]
        d = pbox.minimum_image(d)
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        keep = (r < self.factor * (radii_m[i] + radii_m[j])) & (r > 0)
        if not keep.any():
            return
        i, j, d, r = i[keep], j[keep], d[keep], r[keep]
        u = d / r[:, None]
        blk = (3.0 * u[:, :, None] * u[:, None, :] - np.eye(3)) / (4 * math.pi * r[:, None, None]
                                                                     ** 3)
        rows = np.broadcast_to(3 * np.r_[i, j][:, None, None] + np.arange(3)[None, :, None],
                               (2 * len(i), 3, 3))
        cols = np.broadcast_to(3 * np.r_[j, i][:, None, None] + np.arange(3)[None, None, :],
                               (2 * len(i), 3, 3))
        self.T = sp.csr_matrix((np.concatenate([blk, blk]).ravel(),
                                (rows.ravel(), cols.ravel())), shape=(3 * n, 3 * n))
        self.n_pairs = len(i)
        self.lu = None

    @property
    def active(self) -> bool:
        return self.T is not None

    def update(self, H_A_m):
        """Factorise ``P = I - D(H) T_near`` at the local fields ``H_A_m`` (N, 3)."""
        D = _law_jacobian(self.law, H_A_m, self.m_sat, self.vol)
        n = self.n
        Dm = sp.bsr_matrix((D, np.arange(n), np.arange(n + 1)), shape=(3 * n, 3 * n))
        P = (sp.identity(3 * n, format="csr") - Dm.tocsr() @ self.T).tocsc()
        # incomplete LU: bounded memory whatever the connectivity of the near-pair graph
        # (a complete LU fills in badly for dense random packings); P is only a preconditioner
        self.lu = spla.spilu(P, drop_tol=1e-5, fill_factor=10)

    def solve(self, f):
        return self.lu.solve(f)


def _anderson(g, x0, tol, max_iter, depth=8, precond=None, refresh=None):
    """Anderson acceleration (type II, Walker & Ni 2011) of the fixed point x = g(x).

    With ``precond`` (a callable r -> P^-1 r) Anderson accelerates the preconditioned map
    ``x + P^-1 (g(x) - x)``; ``refresh(it)`` may rebuild the preconditioner after evaluation
    ``it`` and returns True if it did (the history of the old map is then dropped). The
    convergence test always uses the true residual.

    Returns ``(x, number of g evaluations, residual history, converged)``; the residual is
    ``|g(x) - x| / |g(x)|``.
    """
    x = x0
    hist = []
    dG, dF = [], []
    g_prev = f_prev = None
    best, best_it, best_x, best_g = math.inf, 0, None, None
    for it in range(max_iter):
        gx = g(x)
        f = gx - x
        res = float(np.linalg.norm(f) / max(np.linalg.norm(gx), 1e-300))
        hist.append(res)
        if res <= tol:
            return gx, it + 1, hist, True
        if res < best:
            best, best_it, best_x, best_g = res, it, x, gx
        elif it - best_it >= _STALL_ITERATIONS:
            return x, it + 1, hist, False            # no progress: not going to converge
        restart = res > 1e3 * best                   # extrapolation ran away: restart
        if restart:
            x, gx = best_x, best_g
            f = gx - x
        if (refresh is not None and refresh(it)) or restart:
            dG, dF = [], []
            g_prev = f_prev = None
        if precond is not None:
            f = precond(f)
            gx = x + f
        if f_prev is not None:
            dG.append(gx - g_prev)
            dF.append(f - f_prev)
            if len(dF) > depth:
                dG.pop(0)
                dF.pop(0)
        g_prev, f_prev = gx, f
        if dF:
            Fm = np.stack(dF, axis=1)
            gamma = np.linalg.lstsq(Fm, f, rcond=None)[0]
            x = gx - np.stack(dG, axis=1) @ gamma
        else:
            x = gx
    return x, max_iter, hist, False


def _fixed_point(g, x0, tol, max_iter, damping=1.0):
    x = x0
    hist = []
    for it in range(max_iter):
        gx = g(x)
        res = float(np.linalg.norm(gx - x) / max(np.linalg.norm(gx), 1e-300))
        hist.append(res)
        if res <= tol:
            return gx, it + 1, hist, True
        x = (1 - damping) * x + damping * gx
    return x, max_iter, hist, False


def _newton_krylov(g, x0, tol, max_iter, precond=None):
    hist = []

    def resid(x):
        gx = g(x)
        return gx - x

    def cb(x, f):
        hist.append(float(np.linalg.norm(f) / max(np.linalg.norm(x + f), 1e-300)))

    # the Jacobian of g(x) - x is -(I - J) ~ -P: its approximate inverse is -P^-1
    inner_M = None if precond is None else LinearOperator(
        (x0.size, x0.size), matvec=lambda v: -precond(v), dtype=float)
    scale = max(float(np.abs(x0).max()), 1e-300)
    try:
        x = newton_krylov(resid, x0, f_tol=tol * scale * 1e-1, maxiter=max_iter, callback=cb,
                          method="lgmres", line_search=None, inner_M=inner_M)
        ok = True
    except NoConvergence as exc:
        x = exc.args[0]
        ok = False
    gx = g(x)
    res = float(np.linalg.norm(gx - x) / max(np.linalg.norm(gx), 1e-300))
    hist.append(res)
    return gx, len(hist), hist, ok and res <= tol


LANGEVIN_LAMBDA_MAX = 1.5


def langevin_coupling(centers_m, box_m, m_sat_Am2, T_K):
    """Dipolar coupling parameter of each particle with its nearest neighbour (or own image).

    ``lambda_i = mu0 m_i m_j / (4 pi r_ij^3 k_B T)`` [-]: the ratio of the largest dipolar
    pair energy to the thermal energy. Returns ``(lambda (N,), nearest index (N,))``.
    """
    n = centers_m.shape[0]
    lam_img = MU0 * m_sat_Am2 ** 2 / (4 * math.pi * box_m ** 3 * KB * T_K)
    if n < 2:
        return lam_img, np.zeros(n, dtype=np.int64)
    d, j = PeriodicBox(box_m).nearest(centers_m, k=2)
    d, j = np.maximum(d[:, 1], 1e-300), j[:, 1]
    lam = MU0 * m_sat_Am2 * m_sat_Am2[j] / (4 * math.pi * d ** 3 * KB * T_K)
    return np.maximum(lam, lam_img), j


def _check_langevin_coupling(c, box, m_sat, T_K):
    """The Langevin law describes independent superparamagnetic particles; refuse strongly
    coupled ones with one message naming the physics.

    In the local-field (mean-field) model each particle follows ``m_s L(mu0 m_s H_loc / kT)``.
    Linearised at zero field its susceptibility is ``mu0 m_s^2 / (3 kT)``, so a pair on the
    field axis feeds back ``2 lambda / 3`` of its moment: at ``lambda >= 3/2`` the equations
    give the pair a spontaneous moment (a mean-field artefact: a thermal pair has none), the
    fixed point is no longer unique, and at weak fields no method converges. Such particles are
    in fact thermally blocked or chained (Fe: blocked above ~8 nm radius, Neel time
    ``tau0 exp(K V / kT)`` with K = 4.8e4 J/m^3 beyond 100 s), i.e. hysteretic, not Langevin.
    """
    lam, j = langevin_coupling(c, box, m_sat, T_K)
    i = int(np.argmax(lam))
    if lam[i] < LANGEVIN_LAMBDA_MAX:
        return
    # moment at which lambda = 3/2 for this pair distance (m_i m_j -> m^2)
    ratio = math.sqrt(LANGEVIN_LAMBDA_MAX / lam[i])
    dist = float((MU0 * m_sat[i] * m_sat[j[i]] / (4 * math.pi * lam[i] * KB * T_K)) ** (1 / 3))
    raise InputError(
        f"law 'langevin' is not valid for these particles: the dipolar coupling parameter "
        f"lambda = mu0 m_i m_j / (4 pi r^3 k_B T) reaches {lam[i]:.3g} (median "
        f"{float(np.median(lam)):.3g}) between nearest neighbours at T = {T_K:g} K "
        f"(particle {i}: m_sat = {m_sat[i]:.3g} A m^2, neighbour at {dist:.3g} m); it must stay below {LANGEVIN_LAMBDA_MAX:g}, where the local-field Langevin "
        f"equations of a near pair turn spontaneously magnetised and lose their unique "
        f"solution. Particles this strongly coupled are not independent superparamagnets (Fe "
        f"is thermally blocked above ~8 nm radius: Neel time >> 100 s): use law "
        f"'regime' or 'linear', or moments below {ratio * m_sat[i]:.3g} A m^2 at "
        f"this spacing (e.g. smaller or oxide cores), or a higher T_K.")


def _rve_arrays(rve):
    try:
        c = np.asarray(rve.centers_m, dtype=float)
        box = float(rve.box_m)
        ms = np.asarray(rve.m_sat_Am2, dtype=float)
        vol = 4.0 / 3.0 * np.pi * np.asarray(rve.radii_m, dtype=float) ** 3
    except AttributeError as exc:
        raise InputError(f"rve must be a micro.rve.RVE (missing {exc.name})") from None
    return box, c, ms, vol


@one_blas_thread
def solve(rve, B_T, gradB_T_per_m, law=DEFAULT_LAW, *, demag_factor=None, tol=1e-8,
          accuracy=1e-6, method="anderson", summation="auto", max_iter=500, damping=1.0,
          precondition=True,
          rho_kg_m3=SEED.particle_density_kg_m3, sigma_s_Am2_kg=SEED.sigma_s_Am2_kg, c_powder=SEED.c,
          initial_moments_Am2=None, **law_params) -> MagneticState:
    """Self-consistent moments, forces and effective quantities of an RVE in an applied field.

    Parameters
    ----------
    rve : micro.rve.RVE -- particles (centres, outer radii [m], saturation moments [A m^2])
    B_T : float or (3,) -- applied flux density mu0 H [T]; a scalar points along z
    gradB_T_per_m : float or (3, 3) -- d|B|/dz [T/m], or the gradient tensor dB_a/dx_b
    law : str or MagnetizationLaw -- "saturated", "linear", "frohlich-kennelly", "langevin";
        the particle volume in the laws is the outer (core + shell) sphere. "saturated" is the
        seed's assumption, every moment m_sat along the applied field (no iteration)
    demag_factor : float in [0, 1] or None -- specimen demagnetizing factor; None = metallic
    tol : float -- relative residual of the moments at convergence (default 1e-8)
    accuracy : float -- relative accuracy of the periodic field sums (default 1e-6)
    method : {"anderson", "fixed-point", "newton-krylov"} -- Anderson (default) and
        Newton-Krylov use the near-field preconditioner (``precondition``); the fixed point
        ``m <- (1 - damping) m + damping g(m)`` is the plain reference
    damping : float in (0, 2) -- relaxation of the fixed-point method (default 1)
    precondition : bool -- precondition Anderson / Newton-Krylov with the exact coupling of
        near pairs (gap < 1/4 of the contact distance, incomplete LU; default True)
    summation : {"auto", "ewald", "pme"} -- periodic sum; auto: PME above 3000 particles
    rho_kg_m3, sigma_s_Am2_kg : density [kg/m^3] and specific saturation moment [A m^2/kg] of
        the reference saturated material in phi_eff (defaults: the seed paper's Fe)
    c_powder : float -- the seed's powder concentration c in d_eff (default 0.035)
    **law_params : chi, chi0, T_K (see :func:`micro.magnetization.get_law`)

    Raises
    ------
    ConvergenceError -- if the residual does not reach ``tol`` in ``max_iter`` iterations.
    """
    box, c, m_sat, vol = _rve_arrays(rve)
    n = c.shape[0]
    if n == 0:
        raise InputError("rve has no particles")
    law_obj = law if isinstance(law, MagnetizationLaw) else get_law(law, **law_params)
    if getattr(law_obj, "bind", None) is not None:
        law_obj = law_obj.bind(rve)        # per-particle core radii (core-shell laws)
    R = FIELD_RANGES
    R["tol"].check("tol", tol)
    check_choice("method", method, METHODS)
    check_choice("summation", summation, SUMMATIONS)
    R["rho_kg_m3"].check("rho_kg_m3", rho_kg_m3)
    R["sigma_s_Am2_kg"].check("sigma_s_Am2_kg", sigma_s_Am2_kg)
    R["c_powder"].check("c_powder", c_powder)
    R["max_iter"].check("max_iter", max_iter)
    R["damping"].check("damping", damping)
    B, G = applied_gradient(B_T, gradB_T_per_m)
    if law_obj.name == "langevin":
        _check_langevin_coupling(c, box, m_sat, law_obj.T_K)
    if summation == "auto":
        summation = "pme" if n > PME_ABOVE_N else "ewald"
    dsum = DipoleSum(box, c, accuracy=accuracy, summation=summation, demag_factor=demag_factor)
    xc = np.full(3, 0.5 * box)
    H_app = (B[None, :] + (c - xc) @ G.T) / MU0           # (N, 3)
    m_scale = float(np.mean(m_sat)) if np.mean(m_sat) > 0 else 1.0

    last_H = [H_app]

    def g(x):
        mom = x.reshape(n, 3) * m_scale
        H = H_app + dsum.field_A_m(mom)
        last_H[0] = H
        return law_obj.moment(H, m_sat, vol).ravel() / m_scale

    if initial_moments_Am2 is not None:
        x0 = np.asarray(initial_moments_Am2, dtype=float).reshape(-1) / m_scale
    else:
        x0 = law_obj.moment(H_app, m_sat, vol).ravel() / m_scale
    t0 = time.perf_counter()
    if law_obj.name == "saturated":
        # The seed's assumption: every particle saturated along the applied field. Saturated
        # moments along their *local* field are a frustrated spin problem (several or no fixed
        # points once neighbour fields exceed the applied one), not a magnetization law.
        x, its, hist, ok = x0, 0, [0.0], True
    elif method == "fixed-point":
        x, its, hist, ok = _fixed_point(g, x0, tol, int(max_iter), float(damping))
    else:
        pc = _NearFieldPreconditioner(c, box, np.asarray(rve.radii_m, dtype=float), law_obj,
                                      m_sat, vol) if precondition else None
        if pc is not None and not pc.active:
            pc = None
        if pc is not None:
            pc.update(H_app)

        def refresh(it):
            # nonlinear laws: the Jacobian at the first self-consistent field is much closer
            # to the converged one than at the applied field; later changes are small
            if it == 0 and law_obj.name != "linear":
                pc.update(last_H[0])
                return True
            return False

        if method == "anderson":
            x, its, hist, ok = _anderson(g, x0, tol, int(max_iter),
                                         precond=None if pc is None else pc.solve,
                                         refresh=None if pc is None else refresh)
        else:
            x, its, hist, ok = _newton_krylov(g, x0, tol, int(max_iter),
                                              precond=None if pc is None else pc.solve)
    if not ok:
        tail = ", ".join(f"{r:.2e}" for r in hist[-5:])
        raise ConvergenceError(
            f"magnetic moments did not converge with method {method!r}: relative residual "
            f"{hist[-1]:.3e} > tol {tol:g} after {its} iterations ({time.perf_counter() - t0:.1f}"
            f" s; last residuals {tail}); try "
            + ("method='anderson', " if method != "anderson" else "")
            + "a larger max_iter or tol",
            hist)
    mom = x.reshape(n, 3) * m_scale
    H_dd, F_dd, energy, sigma = dsum.interactions(mom)
    H_loc = H_app + H_dd
    F_ext = mom @ G.T                                       # F_a = m_b dB_a/dx_b
    V = box ** 3
    M_eff = mom.sum(axis=0) / V
    f_eff = F_ext.sum(axis=0) / V
    gradabs = G.T @ (B / np.linalg.norm(B)) if np.linalg.norm(B) > 0 else G.T @ np.array([0, 0, 1.])
    gg = float(gradabs @ gradabs)
    if gg > 0:
        phi_eff = float(f_eff @ gradabs) / (rho_kg_m3 * sigma_s_Am2_kg * gg)
        d_eff = phi_eff / c_powder
    else:
        phi_eff = d_eff = None
    return MagneticState(
        moments_Am2=mom, H_local_A_m=H_loc, force_ext_N=F_ext, force_dd_N=F_dd,
        M_eff_A_per_m=M_eff, f_eff_N_m3=f_eff, virial_stress_Pa=sigma, phi_eff=phi_eff,
        d_eff=d_eff, iterations=int(its), residual_history=tuple(hist),
        field_evaluations=dsum.evaluations, energy_dd_J=energy, B_applied_T=B,
        gradient_T_per_m=G, summation=dsum.parameters, law=law_obj.name)


# ------------------------------------------------------------------------------------------
# The stage: RVE + field configuration -> MagneticState
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FieldConfig:
    """Everything the magnetic stage needs besides the RVE (frozen; SI units).

    Parameters
    ----------
    B_T : float or tuple of 3 floats -- applied flux density mu0 H [T] (a scalar is along z)
    gradB_T_per_m : float -- d|B|/dz of the applied field [T/m]
    law : str -- magnetization law name (:data:`micro.magnetization.LAW_NAMES`)
    law_params : tuple of (name, value) pairs -- the law's parameters (e.g. ``(("T_K", 300),)``)
    demag_factor : float or None -- specimen demagnetizing factor along the field (None: metallic
        boundary, the internal field equals the applied field)
    tol, accuracy, method, summation : solver settings of :func:`solve`
    """

    B_T: float | tuple = 0.1
    gradB_T_per_m: float = SEED.gradB_T_per_m
    law: str = DEFAULT_LAW
    law_params: tuple = ()
    demag_factor: float | None = None
    tol: float = 1e-8
    accuracy: float = 1e-6
    method: str = "anderson"
    summation: str = "auto"
    c_powder: float = SEED.c
    rho_kg_m3: float = SEED.particle_density_kg_m3
    sigma_s_Am2_kg: float = SEED.sigma_s_Am2_kg

    def __post_init__(self):
        check_choice("method", self.method, METHODS)
        check_choice("summation", self.summation, SUMMATIONS)
        for key in ("tol", "accuracy", "c_powder", "rho_kg_m3", "sigma_s_Am2_kg"):
            FIELD_RANGES[key].check(key, getattr(self, key))
        check_finite("B_T", self.B_T, "T")
        check_finite("gradB_T_per_m", self.gradB_T_per_m, "T/m")
        if self.demag_factor is not None:
            FIELD_RANGES["demag_factor"].check("demag_factor", self.demag_factor)

    @property
    def B_vector_T(self) -> np.ndarray:
        """The applied flux density as a 3-vector [T]."""
        B = np.asarray(self.B_T, dtype=float)
        return B if B.ndim else np.array([0.0, 0.0, float(B)])


def magnetize(rve, field: FieldConfig) -> MagneticState:
    """The magnetic stage: self-consistent moments and forces of ``rve`` in ``field``."""
    return solve(rve, field.B_vector_T, field.gradB_T_per_m, field.law,
                 demag_factor=field.demag_factor, tol=field.tol, accuracy=field.accuracy,
                 method=field.method, summation=field.summation, c_powder=field.c_powder,
                 rho_kg_m3=field.rho_kg_m3, sigma_s_Am2_kg=field.sigma_s_Am2_kg,
                 **dict(field.law_params))
