"""Magnetization laws of one particle in its local field, vectorised over particles.

Every law maps the local field ``H`` [A/m] acting on a particle to its moment ``m`` [A m^2],
parallel to ``H``, with the particle's own saturation moment ``m_sat`` [A m^2] (core-shell
aware: the RVE carries one ``m_sat`` per particle) and its volume ``V`` [m^3]; ``Ms = m_sat/V``.

Intrinsic laws (physical): a material law on the particle's internal field
``H_in = H_loc - M / 3`` (uniformly magnetized sphere), solved per particle, or, for
coherent rotation, on the local field (a sphere's own field exerts no torque):

======================  =============================================================  ==============
law                     material law                                                    parameters
======================  =============================================================  ==============
``linear``              ``M = min(chi H_in, Ms)`` (closed form ``3 chi/(3 + chi) H``)   ``chi``
``soft-fk``             ``M = chi_i Ms H_in / (Ms + chi_i H_in)``                       ``chi_i``
``approach``            ``min(chi_i H_in, Ms (1 - b/(H_in^2 + c)))``, cubic anisotropy  ``chi_i, K1``
``stoner-wohlfarth``    random-axis single-domain particles, anhysteretic              ``K_J_m3, T_K``
``langevin``            ``m_sat L(mu0 m_sat |H| / (k_B T))`` (superparamagnetic)        ``T_K``
``regime``              per particle the law of its regime (:func:`particle_regime`)    ``T_K, ...``
======================  =============================================================  ==============

Apparent laws (kept to reproduce earlier results; NOT physical for soft spheres):

======================  =============================================================  ==========
``saturated``           ``m_sat`` along the field (the seed paper's assumption)         --
``apparent-fk``         ``V chi0 h Ms / (Ms + chi0 h)`` on the LOCAL field              ``chi0``
======================  =============================================================  ==========

``apparent-fk`` (alias ``frohlich-kennelly``, its former name, accepted for old study files)
applies Froehlich-Kennelly with the sphere's apparent susceptibility ``chi0 = 3`` to the local
field, so the demagnetization also sets the approach to saturation: a 25 nm Fe sphere gets
M/Ms = 0.51 at 0.6 T and 0.63 at 1 T, where a soft iron sphere is at min(3 H, Ms), i.e.
saturated from mu0 Ms / 3 = 0.59 T on.

:data:`DEFAULT_LAW` (``regime``) is the physical default; for the seed's 25 nm Fe particles it
selects ``approach`` (multi-domain; see :func:`particle_regime`). Laws that need per-particle
core radii provide ``bind(rve)``, which :func:`micro.dipoles.solve` calls.

Each law also gives ``coenergy_J`` ``mu0 int_0^h |m|(h') dh'`` [J] (minus the energy of a
particle whose moment follows the law; used to check forces against finite differences of the
energy) and the slope ``d|m|/dh`` used by Newton-type solvers.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.constants import k as _KB
from scipy.constants import mu_0 as MU0

from micro.common.validate import (ConvergenceError, InputError, check_choice, check_finite, check_positive,
                        check_range)
from micro import _kernels as K
from micro.materials import FE, FE3O4, Constituent

__all__ = ["MagnetizationLaw", "SaturatedLaw", "LinearLaw", "FrohlichKennellyLaw", "LangevinLaw",
           "SoftFKLaw", "ApproachLaw", "StonerWohlfarthLaw", "RegimeLaw",
           "get_law", "LAW_NAMES", "LAW_ALIASES", "DEFAULT_LAW", "REGIMES", "particle_regime",
           "superparamagnetic_radius_m", "single_domain_radius_m", "approach_coefficient",
           "wall_motion_end", "switching_field", "stoner_wohlfarth_loop", "N_SPHERE", "TAU0_S"]

#: Every name :func:`get_law` accepts: the laws, then the alias ``frohlich-kennelly`` (the former
#: name of ``apparent-fk``, kept for old study files and callers).
LAW_NAMES = ("regime", "approach", "soft-fk", "linear", "stoner-wohlfarth", "langevin",
             "apparent-fk", "saturated", "frohlich-kennelly")


def _as_fields(H_A_m):
    H = np.asarray(H_A_m, dtype=float)
    if H.ndim != 2 or H.shape[1] != 3:
        raise InputError(f"H_A_m must have shape (N, 3) [A/m], got {H.shape}")
    return H


class MagnetizationLaw:
    """Base class: a law gives ``|m|`` as a function of ``|H|``; the moment is along ``H``."""

    name = "base"

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        """Moment magnitude [A m^2] for field magnitudes ``H_abs_A_m`` [A/m] (arrays broadcast)."""
        raise NotImplementedError

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        """``d|m|/d|H|`` [A m^2 per A/m = m^3]."""
        raise NotImplementedError

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        """``mu0 int_0^h |m|(h') dh'`` [J]: minus the energy of a particle following the law."""
        raise NotImplementedError

    def moment(self, H_A_m, m_sat_Am2, volume_m3):
        """Moments [A m^2], shape (N, 3), along the local fields ``H_A_m`` (N, 3) [A/m].

        A particle in zero field has zero moment, except under the saturated law where the
        direction is undefined: that is an error, not a silent zero.
        """
        H = _as_fields(H_A_m)
        h = np.sqrt(np.einsum("ij,ij->i", H, H))
        mag = np.asarray(self.magnitude(h, m_sat_Am2, volume_m3), dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(h[:, None] > 0, H / np.where(h > 0, h, 1.0)[:, None], 0.0)
        return unit * mag[:, None]

    def params(self) -> dict:
        return {}

    def __repr__(self):
        p = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({p})"


@dataclass(frozen=True, repr=False)
class SaturatedLaw(MagnetizationLaw):
    """``|m| = m_sat`` along the local field, whatever its strength (the seed's assumption)."""

    name = "saturated"

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        h = np.asarray(H_abs_A_m, dtype=float)
        if np.any(h <= 0):
            raise InputError("saturated law: the local field is zero at some particle, so the "
                             "moment direction is undefined; apply a field B_T != 0")
        return np.broadcast_to(np.asarray(m_sat_Am2, dtype=float), h.shape).copy()

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return np.zeros(np.broadcast(H_abs_A_m, m_sat_Am2).shape)

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return MU0 * np.asarray(m_sat_Am2) * np.asarray(H_abs_A_m)


@dataclass(frozen=True, repr=False)
class LinearLaw(MagnetizationLaw):
    """Soft sphere: ``|m| = V 3 chi/(3 + chi) |H|``, capped at ``m_sat``.

    ``chi`` -- intrinsic susceptibility [-], > 0; ``inf`` gives the demagnetisation limit 3.
    """

    chi: float = math.inf
    name = "linear"

    def __post_init__(self):
        if not (self.chi == math.inf):
            check_positive("chi", self.chi, "(dimensionless susceptibility)")

    @property
    def chi_apparent(self) -> float:
        """Apparent susceptibility of the sphere, ``3 chi / (3 + chi)`` (3 for chi -> inf)."""
        return 3.0 if self.chi == math.inf else 3.0 * self.chi / (3.0 + self.chi)

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return np.minimum(self.chi_apparent * np.asarray(volume_m3) * np.asarray(H_abs_A_m),
                          np.asarray(m_sat_Am2, dtype=float))

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        lin = self.chi_apparent * np.asarray(volume_m3) * np.asarray(H_abs_A_m)
        return np.where(lin < m_sat_Am2, self.chi_apparent * np.asarray(volume_m3), 0.0)

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        h = np.asarray(H_abs_A_m, dtype=float)
        a = self.chi_apparent * np.asarray(volume_m3)
        hs = np.asarray(m_sat_Am2) / a                      # field at which the cap starts
        below = 0.5 * a * h ** 2
        above = 0.5 * a * hs ** 2 + np.asarray(m_sat_Am2) * (h - hs)
        return MU0 * np.where(h <= hs, below, above)

    def params(self):
        return {"chi": self.chi}


@dataclass(frozen=True, repr=False)
class FrohlichKennellyLaw(MagnetizationLaw):
    """APPARENT Froehlich-Kennelly: ``M = chi0 M_s H / (M_s + chi0 H)`` on the local field.

    ``chi0`` -- apparent initial susceptibility of the particle [-] (default 3: a soft sphere).

    Caveat: the law is applied to the local field, not to the particle's internal field, so the
    sphere's demagnetization (``chi0 = 3``) also sets the approach to saturation: a 25 nm Fe
    sphere reaches only M/Ms = 0.51 at 0.6 T and 0.63 at 1 T, where a soft iron sphere follows
    ``M = min(3 H, Ms)`` up to ``mu0 Ms / 3`` (0.59 T) and is saturated within ~1e-3 at 1 T.
    Kept for reproducing earlier results; the intrinsic laws (``soft-fk``, ``approach``,
    ``regime``) are the physical ones.
    """

    chi0: float = 3.0
    name = "apparent-fk"

    def __post_init__(self):
        check_positive("chi0", self.chi0, "(dimensionless susceptibility)")

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        h = np.asarray(H_abs_A_m, dtype=float)
        ms = np.asarray(m_sat_Am2, dtype=float)
        a = self.chi0 * np.asarray(volume_m3)
        return a * h * ms / (ms + a * h)

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        h = np.asarray(H_abs_A_m, dtype=float)
        ms = np.asarray(m_sat_Am2, dtype=float)
        a = self.chi0 * np.asarray(volume_m3)
        return a * ms ** 2 / (ms + a * h) ** 2

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        h = np.asarray(H_abs_A_m, dtype=float)
        ms = np.asarray(m_sat_Am2, dtype=float)
        a = self.chi0 * np.asarray(volume_m3)
        # int_0^h a ms t / (ms + a t) dt = ms h - ms^2/a ln(1 + a h / ms)
        return MU0 * (ms * h - ms ** 2 / a * np.log1p(a * h / ms))

    def params(self):
        return {"chi0": self.chi0}


def _langevin(x):
    """``L(x) = coth x - 1/x``, accurate near 0 (series) and for large x."""
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-3
    xs = np.where(small, 1.0, x)
    big = 1.0 / np.tanh(xs) - 1.0 / xs
    return np.where(small, x / 3.0 - x ** 3 / 45.0, big)


@dataclass(frozen=True, repr=False)
class LangevinLaw(MagnetizationLaw):
    """Single-domain particle in thermal equilibrium: ``|m| = m_sat L(mu0 m_sat |H| / (k_B T))``.

    ``T_K`` -- temperature [K] (default 300).
    """

    T_K: float = 300.0
    name = "langevin"

    def __post_init__(self):
        check_positive("T_K", self.T_K, "K")

    def _x(self, h, ms):
        return MU0 * np.asarray(ms) * np.asarray(h, dtype=float) / (_KB * self.T_K)

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return np.asarray(m_sat_Am2) * _langevin(self._x(H_abs_A_m, m_sat_Am2))

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        x = self._x(H_abs_A_m, m_sat_Am2)
        small = np.abs(x) < 1e-3
        xs = np.where(small, 1.0, x)
        e = np.exp(-2.0 * np.abs(xs))
        csch2 = 4.0 * e / (1.0 - e) ** 2            # 1/sinh^2, no overflow for large x
        dl = np.where(small, 1.0 / 3.0 - x ** 2 / 15.0, 1.0 / xs ** 2 - csch2)
        return np.asarray(m_sat_Am2) * dl * MU0 * np.asarray(m_sat_Am2) / (_KB * self.T_K)

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        # mu0 int_0^h m_s L(b t) dt = (m_s mu0 / b) ln(sinh(x)/x), b = mu0 m_s / kT, x = b h
        x = np.asarray(self._x(H_abs_A_m, m_sat_Am2), dtype=float)
        small = x < 1e-3
        xs = np.where(small, 1.0, x)
        # ln(sinh x / x) = x + ln(1 - exp(-2x)) - ln(2x), stable for large x
        lnsx = np.where(small, x ** 2 / 6.0, xs + np.log1p(-np.exp(-2 * xs)) - np.log(2 * xs))
        return _KB * self.T_K * lnsx

    def params(self):
        return {"T_K": self.T_K}


# ------------------------------------------------------------------------------------------
# Intrinsic laws: the material law on the particle's internal field H_in = H_loc - N_p M
# ------------------------------------------------------------------------------------------

#: Demagnetizing factor of a sphere [-].
N_SPHERE = 1.0 / 3.0
#: Attempt time of Neel-Brown relaxation [s] (the usual 1e-9 s; Coey 2010, ch. 8).
TAU0_S = 1e-9


def _safe_newton(fun, lo, hi, x0, xtol, args=(), where=None, maxit=200):
    """Vectorised safeguarded Newton: the root of ``F`` in ``[lo, hi]`` with ``F(lo) <= 0 <=
    F(hi)``; ``fun(x, *args) -> (F, dF/dx)``, elementwise, with ``args`` arrays that broadcast
    against ``x``. ``xtol`` (array or scalar) is the absolute tolerance on ``x``.

    A Newton step is replaced by bisection of the bracket when it leaves the bracket or is
    more than half the previous step (the safeguard of ``rtsafe``, Press et al., Numerical
    Recipes, 3rd ed. 2007, sect. 9.4). So at a double root (a Stoner-Wohlfarth minimum at its
    switching field), where Newton converges linearly and round-off in ``F`` can send it back
    and forth between two points a few ulps further apart than ``xtol``, the iteration still
    ends. Quadratic near a simple root.

    Each element iterates on its own and stops when its step or bracket is below its ``xtol``
    (or ``F = 0``); only the elements still running are evaluated, so a few slow elements do
    not keep the whole array iterating, and every element's result is the same as if it were
    solved alone. ``where`` (boolean, broadcast against ``x``): only those elements are solved,
    the others return ``x0`` clipped to the bracket (for elements whose root the caller knows,
    or whose bracket holds none)."""
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (lo, hi, x0, xtol)
                                   + tuple(args)))
    shape = arrays[0].shape
    lo, hi, x0, xtol = (a.ravel().copy() for a in arrays[:4])
    args = [a.ravel() for a in arrays[4:]]
    x = np.clip(x0, lo, hi)
    step = hi - lo                                   # the previous step (first: the bracket)
    act = (np.arange(x.size) if where is None
           else np.flatnonzero(np.broadcast_to(np.asarray(where, dtype=bool), shape)))
    for _ in range(maxit):
        if act.size == 0:
            return x.reshape(shape)
        xa, la, ha, ta = x[act], lo[act], hi[act], xtol[act]
        F, dF = fun(xa, *(a[act] for a in args))
        root = F == 0
        neg = F < 0
        la = np.where(neg, xa, la)
        ha = np.where(neg | root, ha, xa)
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = xa - F / dF
        bad = ~((xn >= la) & (xn <= ha) & (np.abs(xn - xa) <= 0.5 * step[act]))
        xn = np.where(bad, 0.5 * (la + ha), xn)
        xn = np.where(root, xa, xn)              # a root found stays found
        done = root | (np.abs(xn - xa) <= ta) | (ha - la <= ta)
        x[act], lo[act], hi[act], step[act] = xn, la, ha, np.abs(xn - xa)
        act = act[~done]
    if act.size == 0:
        return x.reshape(shape)
    raise ConvergenceError("intrinsic magnetization solve did not converge in "
                           f"{maxit} safeguarded Newton steps")


class _IntrinsicLaw(MagnetizationLaw):
    """A material law ``M = f(H_in)`` [A/m] on the internal field of a uniformly magnetized
    sphere, ``H_in = h - N_p M`` with ``h = |H_loc|`` and ``N_p = 1/3``.

    Subclasses give ``_f(u, Ms)``, its derivative ``_df`` and its integral
    ``_F(u, Ms) = int_0^u f`` (closed forms), and ``_f0(Ms)``, the limit ``f(0+)`` (non-zero
    when the intrinsic susceptibility is infinite). ``Ms = m_sat / V`` is the particle's mean
    saturation magnetization (core and shell). The scalar equation ``M = f(h - N_p M)`` is
    monotone in ``M`` (its residual ``M - f(h - N_p M)`` increases strictly), its root lies in
    ``[0, min(Ms, h / N_p, f(h))]`` and is found by a safeguarded Newton iteration, vectorised
    over particles. Then

    * slope (implicit differentiation): ``dM/dh = f'(H_in) / (1 + N_p f'(H_in))``;
    * co-energy (exact): ``mu0 V int_0^h M dh' = mu0 V (int_0^H_in f du + N_p M^2 / 2)``,
      since ``dh = dH_in + N_p dM`` along the curve.
    """

    demag_factor = N_SPHERE

    def _f(self, u, Ms):
        raise NotImplementedError

    def _df(self, u, Ms):
        raise NotImplementedError

    def _F(self, u, Ms):
        raise NotImplementedError

    def _f0(self, Ms):
        return np.zeros_like(np.asarray(Ms, dtype=float))

    def _solve(self, h, Ms):
        """``M`` [A/m] and ``H_in`` [A/m] of the sphere in the local field ``h``."""
        N = self.demag_factor
        h, Ms = np.broadcast_arrays(np.asarray(h, dtype=float), np.asarray(Ms, dtype=float))
        if np.any(h < 0):
            raise InputError("field magnitude must be >= 0 A/m")
        # H_in = 0 with M = h / N while the jump f(0+) can carry it (infinite intrinsic chi)
        pinned = h / N <= self._f0(Ms)
        hi = np.minimum(np.minimum(Ms, h / N), self._f(h, Ms))

        def fun(M, h, Ms):
            u = np.maximum(h - N * M, 0.0)
            return M - self._f(u, Ms), 1.0 + N * self._df(u, Ms)

        M = _safe_newton(fun, np.zeros_like(h), hi, 0.5 * hi, 1e-14 * np.maximum(Ms, 1e-300),
                         args=(h, Ms), where=~pinned)
        M = np.where(pinned, h / N, M)
        return M, np.where(pinned, 0.0, np.maximum(h - N * M, 0.0))

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        V = np.asarray(volume_m3, dtype=float)
        M, _ = self._solve(H_abs_A_m, np.asarray(m_sat_Am2, dtype=float) / V)
        return M * V

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        V = np.asarray(volume_m3, dtype=float)
        Ms = np.asarray(m_sat_Am2, dtype=float) / V
        M, u = self._solve(H_abs_A_m, Ms)
        N = self.demag_factor
        d = self._df(u, Ms)
        with np.errstate(invalid="ignore"):
            s = np.where(np.isinf(d), 1.0 / N, d / (1.0 + N * d))
        # pinned at H_in = 0 by an infinite initial susceptibility: M = h / N
        s = np.where((u == 0) & (M > 0) & (M < Ms), 1.0 / N, s)
        return s * V

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        V = np.asarray(volume_m3, dtype=float)
        Ms = np.asarray(m_sat_Am2, dtype=float) / V
        M, u = self._solve(H_abs_A_m, Ms)
        return MU0 * V * (self._F(u, Ms) + 0.5 * self.demag_factor * M ** 2)

    def internal_field(self, H_abs_A_m, m_sat_Am2, volume_m3):
        """Internal field ``H_in = h - N_p M`` [A/m] of the particle in the local field."""
        V = np.asarray(volume_m3, dtype=float)
        return self._solve(H_abs_A_m, np.asarray(m_sat_Am2, dtype=float) / V)[1]


@dataclass(frozen=True, repr=False)
class SoftFKLaw(_IntrinsicLaw):
    """Soft ferromagnet, intrinsic Froehlich-Kennelly law on the internal field:
    ``M = chi_i Ms H_in / (Ms + chi_i H_in)`` (never above ``Ms``), ``H_in = H_loc - M / 3``.

    ``chi_i`` -- intrinsic initial susceptibility [-], > 0 (default 1000; polycrystalline iron
    has initial relative permeabilities of a few hundred (commercial) to ~1e4 (purified),
    Cullity & Graham 2009 ch. 13; ``inf`` gives the demagnetization-limited sphere
    ``M = min(3 H, Ms)``). The approach to saturation is ``Ms / (chi_i H_in)`` (FK's 1/H tail).
    The linear intrinsic law capped at ``Ms`` is the law ``linear`` (closed form).
    """

    chi_i: float = 1000.0
    name = "soft-fk"

    def __post_init__(self):
        if self.chi_i != math.inf:
            check_positive("chi_i", self.chi_i, "(dimensionless susceptibility)")

    def _f(self, u, Ms):
        if self.chi_i == math.inf:
            return np.where(u > 0, Ms, 0.0) + 0.0 * u
        return self.chi_i * Ms * u / (Ms + self.chi_i * u)

    def _df(self, u, Ms):
        if self.chi_i == math.inf:
            return np.where(u > 0, 0.0, math.inf) + 0.0 * Ms
        return self.chi_i * Ms ** 2 / (Ms + self.chi_i * u) ** 2

    def _F(self, u, Ms):
        if self.chi_i == math.inf:
            return Ms * u
        return Ms * u - Ms ** 2 / self.chi_i * np.log1p(self.chi_i * u / Ms)

    def _f0(self, Ms):
        return (np.asarray(Ms, dtype=float) if self.chi_i == math.inf
                else np.zeros_like(np.asarray(Ms, dtype=float)))

    def params(self):
        return {"chi_i": self.chi_i}


def wall_motion_end(K1_J_m3: float) -> float:
    """``M/Ms`` of a random cubic polycrystal once domain-wall motion has put every grain along
    its easy axis nearest the field [-]: the average of the largest direction cosine to the
    easy axes, <100> for ``K1 > 0`` and <111> for ``K1 < 0`` (Cullity & Graham 2009 ch. 9:
    0.832 for iron, 0.866 for nickel).

    ``K1 > 0``: closed form ``(6 / (pi sqrt 2)) arctan(1 / sqrt 2)`` (integral over the 1/48 of
    the sphere where z > x > y > 0). ``K1 < 0``: Gauss-Legendre product quadrature over the
    sphere (the max() makes the integrand kinked; 400 x 800 nodes give ~1e-5).
    """
    if K1_J_m3 >= 0:
        return 6.0 / (math.pi * math.sqrt(2.0)) * math.atan(1.0 / math.sqrt(2.0))
    return _wall_motion_end_111()


@functools.lru_cache(maxsize=1)
def _wall_motion_end_111():
    xc, wc = np.polynomial.legendre.leggauss(400)          # cos(theta) in [-1, 1]
    xp, wp = np.polynomial.legendre.leggauss(800)          # phi in [0, 2 pi]
    phi = math.pi * (xp + 1.0)
    st = np.sqrt(1.0 - xc ** 2)
    n = np.stack([st[:, None] * np.cos(phi)[None, :], st[:, None] * np.sin(phi)[None, :],
                  np.broadcast_to(xc[:, None], (400, 800))], axis=-1)
    a = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]]) / math.sqrt(3.0)
    g = np.abs(n @ a.T).max(axis=-1)
    return float(wc @ g @ wp) * math.pi / (4.0 * math.pi)


def approach_coefficient(K1_J_m3: float, Ms_A_m: float) -> float:
    """Coefficient ``b = (8/105) (K1 / (mu0 Ms))^2`` [(A/m)^2] of the law of approach to
    saturation ``M = Ms (1 - b / H^2)`` of a cubic polycrystal with random axes (Akulov 1931;
    Neel 1948; Chikazumi, Physics of Ferromagnetism, 2nd ed. 1997, sect. 18.3)."""
    check_positive("Ms_A_m", Ms_A_m, "A/m")
    return 8.0 / 105.0 * (K1_J_m3 / (MU0 * Ms_A_m)) ** 2


@dataclass(frozen=True, repr=False)
class ApproachLaw(_IntrinsicLaw):
    """Multi-domain cubic ferromagnet (Fe): wall motion, then rotation against the
    magnetocrystalline anisotropy with the law of approach to saturation, on the internal field.

    ``M = min(chi_i H_in, M_rot(H_in))``, ``M_rot(H) = Ms (1 - b / (H^2 + c))``, with

    * ``b = (8/105) (K1 / (mu0 Ms_core))^2`` (random cubic axes; :func:`approach_coefficient`),
      so that ``M_rot = Ms (1 - b / H^2 + O(H^-4))``: the exact law of approach at high field;
    * ``c = b / (1 - w)``, ``w`` = :func:`wall_motion_end` (0.831 for K1 > 0): ``M_rot(0+) =
      w Ms``, the state after wall motion, where rotation starts (Cullity & Graham ch. 9).

    How the two combine (documented choice): the soft law ``chi_i H_in`` describes wall motion
    and holds until it meets the rotation curve; beyond, rotation holds. Between ``w Ms`` and
    the ``1/H^2`` tail the interpolation is ours (the true rotation curve of a random cubic
    ensemble differs by a few % of ``Ms`` there, over fields ~K1/(mu0 Ms) ~ 0.03 T for Fe).

    Parameters
    ----------
    chi_i : float -- intrinsic susceptibility of wall motion [-] (default ``inf``: walls move
        freely, the sphere is demagnetization-limited, ``M = 3 H`` below ``w Ms``); finite
        values must exceed 20 (the rotation curve's largest slope is ~0.045 Ms/sqrt(b),
        ~12 for Fe, so that wall motion ends at one field).
    K1_J_m3 : float -- first cubic anisotropy constant of the core [J/m^3] (default Fe's,
        :data:`micro.materials.FE`).
    Ms_core_A_m : float -- saturation magnetization of the core material [A/m], which fixes the
        anisotropy field in ``b`` (default Fe's). The particle's own ``Ms = m_sat / V`` scales M.
    """

    chi_i: float = math.inf
    K1_J_m3: float = FE.K1_J_m3
    Ms_core_A_m: float = FE.Ms_A_m
    name = "approach"

    def __post_init__(self):
        if self.chi_i != math.inf:
            check_range("chi_i", self.chi_i, 20.0, math.inf, "(dimensionless susceptibility)")
        check_finite("K1_J_m3", self.K1_J_m3, "J/m^3")
        if self.K1_J_m3 == 0:
            raise InputError("K1_J_m3 must be != 0 J/m^3 for the approach law (use 'linear' "
                             "or 'soft-fk' for an isotropic soft material)")
        check_range("Ms_core_A_m", self.Ms_core_A_m, 1e3, 1e7, "A/m")

    @property
    def b(self) -> float:
        """Approach coefficient ``b`` [(A/m)^2]."""
        return approach_coefficient(self.K1_J_m3, self.Ms_core_A_m)

    @property
    def c(self) -> float:
        return self.b / (1.0 - wall_motion_end(self.K1_J_m3))

    def _rot(self, u, Ms):
        return Ms * (1.0 - self.b / (u ** 2 + self.c))

    def _drot(self, u, Ms):
        return Ms * 2.0 * self.b * u / (u ** 2 + self.c) ** 2

    def _cross(self, Ms):
        """Field where wall motion meets rotation, ``chi_i u = M_rot(u)`` [A/m] (unique for
        chi_i above the rotation curve's largest slope)."""
        Ms = np.asarray(Ms, dtype=float)
        if self.chi_i == math.inf:
            return np.zeros_like(Ms)

        def fun(u, Ms):
            return self.chi_i * u - self._rot(u, Ms), self.chi_i - self._drot(u, Ms)

        hi = Ms / self.chi_i
        return _safe_newton(fun, np.zeros_like(Ms), hi, 0.8 * hi, 1e-15 * hi, args=(Ms,))

    def _f(self, u, Ms):
        rot = self._rot(u, Ms)
        if self.chi_i == math.inf:
            return np.where(u > 0, rot, 0.0)
        return np.minimum(self.chi_i * u, rot)

    def _df(self, u, Ms):
        if self.chi_i == math.inf:
            return np.where(u > 0, self._drot(u, Ms), math.inf)
        return np.where(self.chi_i * u < self._rot(u, Ms), self.chi_i, self._drot(u, Ms))

    def _F(self, u, Ms):
        sc = math.sqrt(self.c)

        def Frot(t):          # int_0^t M_rot
            return Ms * (t - self.b / sc * np.arctan(t / sc))

        if self.chi_i == math.inf:
            return Frot(u)
        ux = self._cross(Ms)
        return np.where(u <= ux, 0.5 * self.chi_i * u ** 2,
                        0.5 * self.chi_i * ux ** 2 + Frot(u) - Frot(ux))

    def _f0(self, Ms):
        Ms = np.asarray(Ms, dtype=float)
        return self._rot(0.0, Ms) if self.chi_i == math.inf else np.zeros_like(Ms)

    def params(self):
        return {"chi_i": self.chi_i, "K1_J_m3": self.K1_J_m3, "Ms_core_A_m": self.Ms_core_A_m}


# ------------------------------------------------------------------------------------------
# Stoner-Wohlfarth: single-domain particles, uniaxial anisotropy, random easy axes
# ------------------------------------------------------------------------------------------
#
# Reduced energy of one particle, in units of K V: e(theta) = sin^2 theta - 2 h cos(theta - psi)
# with theta the moment's angle from the easy axis, psi the field's, h = H / H_K and
# H_K = 2 K V / (mu0 m_sat). For psi in [0, pi/2] and h >= 0 the global minimum lies in
# [0, psi]; the other minimum, near theta = pi, exists while h < h_sw(psi) and is the mirror of
# the minimum near 0 under the reversed field. A uniformly magnetized sphere's own
# demagnetizing field is parallel to M and exerts no torque (its energy does not depend on the
# direction), so coherent-rotation laws take the local field, not H_loc - M/3.

def switching_field(psi):
    """Stoner-Wohlfarth switching field ``h_sw = (cos^(2/3) psi + sin^(2/3) psi)^(-3/2)``
    [in units of H_K] for the field at angle ``psi`` [rad] to the easy axis."""
    c, s = np.abs(np.cos(psi)), np.abs(np.sin(psi))
    return (c ** (2.0 / 3.0) + s ** (2.0 / 3.0)) ** -1.5


def _sw_stable(h, psi):
    """Global minimum ``theta`` in [0, psi] (h >= 0, psi in [0, pi/2])."""
    def fun(t, h, psi):
        return np.sin(2 * t) + 2 * h * np.sin(t - psi), 2 * np.cos(2 * t) + 2 * h * np.cos(t - psi)
    return _safe_newton(fun, np.zeros_like(psi + h), psi + 0.0 * h, 0.5 * (psi + 0 * h), 1e-13,
                        args=(h, psi))


def _sw_reversed(h, psi):
    """Minimum near 0 under the reversed field -h (h >= 0): ``phi`` in [theta_c, 0] with
    ``tan theta_c = -tan^(1/3) psi``, and whether it exists (``h < h_sw(psi)``)."""
    tc = -np.arctan(np.tan(psi) ** (1.0 / 3.0)) + 0.0 * h
    exists = h < switching_field(psi)

    def fun(t, h, psi):
        return np.sin(2 * t) - 2 * h * np.sin(t - psi), 2 * np.cos(2 * t) - 2 * h * np.cos(t - psi)
    # where the minimum does not exist the bracket holds no root: not solved (phi = tc / 2,
    # never used: its population is 0)
    phi = _safe_newton(fun, tc, np.zeros_like(tc), 0.5 * tc, 1e-13, args=(h, psi), where=exists)
    return phi, exists


_GL_AXES = 48       # Gauss-Legendre nodes in cos(psi) for smooth ensemble averages


def _axes(n=_GL_AXES):
    x, w = np.polynomial.legendre.leggauss(n)
    u = 0.5 * (x + 1.0)                       # cos psi, uniform on (0, 1) for random axes
    return np.arccos(u), 0.5 * w


@functools.lru_cache(maxsize=None)
def _axis_table(n=_GL_AXES):
    """The fixed easy axes of the random-axis average, computed once: angles ``psi``, weights,
    the bound ``-atan(tan(psi)^(1/3))`` of each reversed minimum's bracket and the switching
    fields ``h_sw(psi)``. Private: the kernel only reads them."""
    psi, w = _axes(n)
    return psi, w, -np.arctan(np.tan(psi) ** (1.0 / 3.0)), switching_field(psi)


def _sw_anhysteretic(hr, kappa, with_slope=False):
    """Random-axis average of the equilibrium ``M/Ms`` at reduced field ``hr`` (>= 0) and
    barrier parameter ``kappa = K V / (k_B T)`` (inf: T = 0), and ``d(M/Ms)/dhr``.

    Two-state thermal equilibrium between the two energy minima (valid for blocked particles,
    kappa >> 1, the regime where Stoner-Wohlfarth applies): populations ``p+- ~ exp(-kappa e+-)``;
    where only one minimum exists ``p+ = 1``. At ``kappa = inf`` the global minimum (p+ = 1 for
    h > 0, 1/2 at h = 0): the energy-minimum anhysteretic, which jumps to Ms/2 at h = 0+.

    Each element's minima (the roots :func:`_sw_stable` and :func:`_sw_reversed` find) are
    solved by the same safeguarded Newton iteration in a numba kernel, parallel over elements:
    the dipole solve calls this on every particle at every step, and a numpy version was
    serial (results/bench/threads.md)."""
    h, kap = np.broadcast_arrays(np.asarray(hr, dtype=float), np.asarray(kappa, dtype=float))
    shape = h.shape
    h = np.ascontiguousarray(h).ravel()
    kap = np.ascontiguousarray(kap).ravel()
    psi, w, tc, h_sw = _axis_table()
    m, dm = np.empty_like(h), np.empty_like(h)
    steps = np.empty(h.shape, dtype=np.int64)
    maxit = 200
    K.sw_average(h, kap, psi, w, tc, h_sw, bool(with_slope), maxit, m, dm, steps)
    if steps.size and steps.max() > maxit:
        raise ConvergenceError("intrinsic magnetization solve did not converge in "
                               f"{maxit} safeguarded Newton steps")
    if not with_slope:
        return m.reshape(shape)
    return m.reshape(shape), dm.reshape(shape)


def _segments(a):
    """Edges in psi of the switched band of the descending branch at |h| = a: for a in
    (1/2, 1) the axes with h_sw(psi) < a, i.e. psi in (psi1, pi/2 - psi1)."""
    a = np.asarray(a, dtype=float)
    lo, hi = np.zeros_like(a), np.full_like(a, math.pi / 4)
    for _ in range(60):                      # h_sw decreases from 1 to 1/2 on [0, pi/4]
        mid = 0.5 * (lo + hi)
        above = switching_field(mid) > a
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    psi1 = np.where(a <= 0.5, math.pi / 4, np.where(a >= 1.0, 0.0, 0.5 * (lo + hi)))
    return psi1


def stoner_wohlfarth_loop(H_A_m, H_K_A_m, branch="descending", n_axes=64):
    """Major hysteresis loop of Stoner-Wohlfarth particles with random easy axes (T = 0):
    ``M/Ms`` [-] on the ``"descending"`` branch (from positive saturation) or the
    ``"ascending"`` one (``M_asc(H) = -M_desc(-H)``).

    Each particle stays in the energy minimum it was carried into until that minimum
    disappears at its switching field ``h_sw(psi)``; the ensemble average over axes uniform in
    ``cos psi`` uses Gauss-Legendre quadrature on the pieces of ``psi`` between which the
    switched set changes (so the jump of the integrand is not smeared).

    Parameters
    ----------
    H_A_m : float or ndarray -- applied (local) field along the loop axis [A/m], signed
    H_K_A_m : float -- anisotropy field ``2 K / (mu0 Ms)`` [A/m], > 0
    branch : {"descending", "ascending"}
    n_axes : int -- quadrature nodes per piece (default 64)
    """
    check_positive("H_K_A_m", H_K_A_m, "A/m")
    check_choice("branch", branch, ("descending", "ascending"))
    H = np.asarray(H_A_m, dtype=float)
    check_finite("H_A_m", H, "A/m")
    sign = 1.0 if branch == "descending" else -1.0
    h = sign * H / H_K_A_m
    a = np.abs(h)[..., None]
    x, w = np.polynomial.legendre.leggauss(int(n_axes))
    psi1 = _segments(np.abs(h))[..., None]
    total = np.zeros(h.shape)
    for lo, hi in ((0.0 * psi1, psi1), (psi1, math.pi / 2 - psi1), (math.pi / 2 - psi1,
                                                                     math.pi / 2 + 0 * psi1)):
        psi = lo + (hi - lo) * 0.5 * (x + 1.0)
        ww = (hi - lo) * 0.5 * w * np.sin(psi)
        tp = _sw_stable(a + 0 * psi, psi)
        cp = np.cos(tp - psi)
        phi, ex = _sw_reversed(a + 0 * psi, psi)
        neg = np.where(ex, np.cos(phi - psi), -cp)        # h < 0: unswitched or switched
        val = np.where(h[..., None] >= 0, cp, neg)
        total = total + (ww * val).sum(axis=-1)
    return sign * total


@dataclass(frozen=True, repr=False, eq=False)
class StonerWohlfarthLaw(MagnetizationLaw):
    """Single-domain particles with uniaxial (effective) anisotropy and random easy axes: the
    anhysteretic (equilibrium) moment along the local field, for the self-consistent solve.

    ``|m| = m_sat <p+ cos(theta+ - psi) + p- cos(theta- - psi)>_psi`` with the two energy minima
    of ``E = K V_c sin^2 theta - mu0 m_sat H cos(theta - psi)`` populated by Boltzmann weights
    (two-state equilibrium, valid for blocked particles) and axes uniform in ``cos psi``
    (48-node Gauss-Legendre). ``T_K = 0`` gives the energy-minimum anhysteretic (global
    minimum), which jumps to ``m_sat / 2`` at ``h = 0+``. Low-field slope:
    ``mu0 m_sat^2 / (3 k_B T) + (2/3) m_sat / H_K`` (thermal + rotation), ``H_K = 2 K V_c /
    (mu0 m_sat)``. The sphere's own demagnetizing field exerts no torque, so the law takes the
    local field. The hysteresis loop is :func:`stoner_wohlfarth_loop`.

    Parameters
    ----------
    K_J_m3 : float -- effective uniaxial anisotropy of the core [J/m^3], > 0 (default
        ``|K1|`` of Fe; see :func:`particle_regime` for this convention)
    T_K : float -- temperature [K], >= 0 (default 300)
    core_radii_m : ndarray or None -- per-particle core radius [m] (set by :meth:`bind`); None:
        the anisotropic volume is the whole particle ``V``.
    """

    K_J_m3: float = abs(FE.K1_J_m3)
    T_K: float = 300.0
    core_radii_m: np.ndarray | None = None
    name = "stoner-wohlfarth"

    def __post_init__(self):
        check_positive("K_J_m3", self.K_J_m3, "J/m^3")
        check_positive("T_K", self.T_K, "K", allow_zero=True)

    def bind(self, rve):
        """The law with the RVE's per-particle core radii (anisotropy lives in the core)."""
        return _replace(self, core_radii_m=np.asarray(rve.core_radii_m, dtype=float))

    def _core_volume(self, volume_m3):
        if self.core_radii_m is None:
            return np.asarray(volume_m3, dtype=float)
        return 4.0 / 3.0 * math.pi * self.core_radii_m ** 3

    def _reduced(self, H_abs_A_m, m_sat_Am2, volume_m3):
        ms = np.asarray(m_sat_Am2, dtype=float)
        KV = self.K_J_m3 * self._core_volume(volume_m3)
        HK = 2.0 * KV / (MU0 * ms)
        kappa = KV / (_KB * self.T_K) if self.T_K > 0 else np.inf * KV
        h = np.asarray(H_abs_A_m, dtype=float)
        h, ms, HK, kappa = np.broadcast_arrays(h, ms, HK, kappa)
        return h / HK, ms, HK, kappa

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        hr, ms, _, kappa = self._reduced(H_abs_A_m, m_sat_Am2, volume_m3)
        return ms * _sw_anhysteretic(hr, kappa)

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        hr, ms, HK, kappa = self._reduced(H_abs_A_m, m_sat_Am2, volume_m3)
        return ms * _sw_anhysteretic(hr, kappa, with_slope=True)[1] / HK

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        hr, ms, HK, kappa = self._reduced(H_abs_A_m, m_sat_Am2, volume_m3)
        # the curve rises over h ~ 1/kappa (thermal) near 0: geometric panels resolve it
        s = np.where(np.isinf(kappa), 1e-6, 1.0 / np.where(np.isinf(kappa), 1.0, kappa))
        integral = _geometric_quadrature(lambda t, k: _sw_anhysteretic(t, k), hr, s, kappa)
        return MU0 * ms * HK * integral

    def params(self):
        return {"K_J_m3": self.K_J_m3, "T_K": self.T_K}


def _geometric_quadrature(fun, x, s, extra, panels=24, nodes=12):
    """``int_0^x fun(t, extra) dt`` by Gauss-Legendre on [0, s'] and ``panels`` geometric
    panels from ``s' = min(s, x)`` to ``x`` (for integrands that vary on the scale s near 0)."""
    x = np.asarray(x, dtype=float)
    s = np.minimum(np.asarray(s, dtype=float), x)
    g, gw = np.polynomial.legendre.leggauss(nodes)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(s > 0, (x / np.where(s > 0, s, 1.0)) ** (1.0 / panels), 1.0)
    edges = [np.zeros_like(x), s] + [s * ratio ** k for k in range(1, panels + 1)]
    total = np.zeros_like(x)
    ex = np.broadcast_to(np.asarray(extra, dtype=float), x.shape)
    for a, b in zip(edges[:-1], edges[1:]):
        t = a[..., None] + (b - a)[..., None] * 0.5 * (g + 1.0)
        vals = fun(t, np.broadcast_to(ex[..., None], t.shape))
        total = total + (b - a) * 0.5 * (vals * gw).sum(axis=-1)
    return total


def _replace(obj, **changes):
    return dataclasses.replace(obj, **changes)


# ------------------------------------------------------------------------------------------
# Regimes: superparamagnetic, single-domain, multi-domain
# ------------------------------------------------------------------------------------------

REGIMES = ("superparamagnetic", "single-domain", "multi-domain")


def superparamagnetic_radius_m(material: Constituent = FE, T_K: float = 300.0,
                               measurement_time_s: float = 100.0, K_J_m3: float | None = None
                               ) -> float:
    """Blocking radius [m]: below it the Neel time ``tau0 exp(K V / k_B T)`` (tau0 = 1e-9 s)
    is shorter than the measurement time, ``K V = k_B T ln(t_m / tau0)`` (25.3 k_B T at 100 s;
    Neel 1949, Brown 1963; Coey 2010 ch. 8). ``K`` defaults to ``|K1|`` of the material (the
    usual order-of-magnitude convention; the bulk cubic barrier of K1 > 0 is K1 V / 4, which
    would give a radius 4^(1/3) = 1.59 times larger, while surface anisotropy of real
    nanoparticles raises K above K1)."""
    check_positive("T_K", T_K, "K")
    check_range("measurement_time_s", measurement_time_s, TAU0_S, math.inf, "s", lo_open=True)
    K = abs(material.K1_J_m3) if K_J_m3 is None else check_positive("K_J_m3", K_J_m3, "J/m^3")
    if K <= 0:
        return math.inf
    V = _KB * T_K * math.log(measurement_time_s / TAU0_S) / K
    return (3.0 * V / (4.0 * math.pi)) ** (1.0 / 3.0)


def single_domain_radius_m(material: Constituent = FE) -> float:
    """Largest radius [m] of a sphere whose ground state is uniformly magnetized.

    Soft materials (``Q = 2 |K1| / (mu0 Ms^2) < 1``, Fe: 0.026, Fe3O4: 0.077): the
    coherent-rotation radius of a sphere, ``R_coh = sqrt(26) sqrt(A / (mu0 Ms^2)) = 5.099 l_ex``
    (Aharoni, Introduction to the Theory of Ferromagnetism, 2nd ed. 2000, ch. 9; equal to
    Brown's lower bound of the single-domain radius, below which the uniform state is the
    ground state); above it a vortex (curling) state has lower energy and the particle's mean
    magnetization follows the field by vortex/domain processes ("multi-domain" here). Hard
    materials (Q >= 1): Kittel's ``R_sd = 36 sqrt(A K1) / (mu0 Ms^2)`` (Coey 2010 ch. 8).
    Fe: 12.2 nm."""
    Ms, A, K = material.Ms_A_m, material.A_J_m, abs(material.K1_J_m3)
    if Ms <= 0 or A <= 0:
        raise InputError(f"material {material.name!r} is not magnetic (Ms = {Ms:g} A/m, "
                         f"A = {A:g} J/m); a regime needs Ms > 0 and A > 0")
    Q = 2.0 * K / (MU0 * Ms ** 2)
    if Q < 1.0:
        return math.sqrt(26.0 * A / (MU0 * Ms ** 2))
    return 36.0 * math.sqrt(A * K) / (MU0 * Ms ** 2)


def _regime_codes(core_radius_m, material, T_K, measurement_time_s):
    r = np.asarray(core_radius_m, dtype=float)
    r_sp = superparamagnetic_radius_m(material, T_K, measurement_time_s)
    r_sd = single_domain_radius_m(material)
    return np.where(r < r_sp, 0, np.where(r < r_sd, 1, 2))


def particle_regime(core_radius_m, material: Constituent = FE, T_K: float = 300.0,
                    measurement_time_s: float = 100.0):
    """Magnetic regime of a particle core: ``"superparamagnetic"``, ``"single-domain"`` or
    ``"multi-domain"``.

    Criteria (checked in this order): superparamagnetic below
    :func:`superparamagnetic_radius_m` (Neel-Brown blocking at ``T_K`` and
    ``measurement_time_s``), single-domain below :func:`single_domain_radius_m`, else
    multi-domain (vortex or domains). For Fe at 300 K and 100 s: 8.0 nm and 12.2 nm, so the
    seed's 25 nm particles are multi-domain (K1 V / k_B T = 760 at 25 nm: blocked).

    Parameters
    ----------
    core_radius_m : float or ndarray -- radius of the magnetic core [m], > 0
    material : micro.materials.Constituent -- core material (default Fe)
    T_K : float -- temperature [K] (default 300)
    measurement_time_s : float -- measurement time [s] (default 100)

    Returns
    -------
    str, or ndarray of str for array input
    """
    r = np.asarray(core_radius_m, dtype=float)
    check_finite("core_radius_m", r, "m")
    if np.any(r <= 0):
        raise InputError(f"core_radius_m must be > 0 m, got {core_radius_m!r}")
    codes = _regime_codes(r, material, T_K, measurement_time_s)
    names = np.array(REGIMES)[codes]
    return str(names) if names.ndim == 0 else names


@dataclass(frozen=True, repr=False, eq=False)
class RegimeLaw(MagnetizationLaw):
    """Each particle follows the intrinsic law of its regime (:func:`particle_regime` of its
    core radius): ``langevin`` if superparamagnetic, ``stoner-wohlfarth`` (anhysteretic,
    ``K = |K1|``) if single-domain, ``approach`` (wall motion + cubic anisotropy on the internal
    field, ``chi_i``) if multi-domain.

    Oxide shell: the RVE's ``m_sat`` includes the shell's moment (Fe3O4, 92 A m^2/kg); the
    shell is taken as exchange-coupled to the core and magnetized like it, so every law scales
    the whole ``m_sat``; the regime and the anisotropy volume are the core's. Without
    :meth:`bind` (no RVE) the core is the whole particle, ``r = (3 V / 4 pi)^(1/3)``.

    Parameters
    ----------
    T_K : float -- temperature [K] (default 300)
    measurement_time_s : float -- time scale for Neel-Brown blocking [s] (default 100)
    chi_i : float -- wall-motion susceptibility of multi-domain particles (default inf)
    material : micro.materials.Constituent -- core material (default Fe)
    core_radii_m : ndarray or None -- per-particle core radii [m], set by :meth:`bind`
    """

    T_K: float = 300.0
    measurement_time_s: float = 100.0
    chi_i: float = math.inf
    material: Constituent = FE
    core_radii_m: np.ndarray | None = None
    name = "regime"

    def __post_init__(self):
        check_positive("T_K", self.T_K, "K")
        check_range("measurement_time_s", self.measurement_time_s, TAU0_S, math.inf, "s",
                    lo_open=True)
        single_domain_radius_m(self.material)       # refuses a non-magnetic material
        self._laws()                                 # validates chi_i

    def _laws(self):
        m = self.material
        return (LangevinLaw(T_K=self.T_K),
                StonerWohlfarthLaw(K_J_m3=abs(m.K1_J_m3), T_K=self.T_K),
                ApproachLaw(chi_i=self.chi_i, K1_J_m3=m.K1_J_m3, Ms_core_A_m=m.Ms_A_m))

    def bind(self, rve):
        """The law with the RVE's per-particle core radii."""
        return _replace(self, core_radii_m=np.asarray(rve.core_radii_m, dtype=float))

    def regimes(self, volume_m3):
        """Regime code per particle (0 superparamagnetic, 1 single-domain, 2 multi-domain)."""
        r = (self.core_radii_m if self.core_radii_m is not None
             else (3.0 * np.asarray(volume_m3, dtype=float) / (4.0 * math.pi)) ** (1.0 / 3.0))
        return _regime_codes(r, self.material, self.T_K, self.measurement_time_s)

    def _apply(self, method, H_abs_A_m, m_sat_Am2, volume_m3):
        h, ms, V = np.broadcast_arrays(np.asarray(H_abs_A_m, dtype=float),
                                       np.asarray(m_sat_Am2, dtype=float),
                                       np.asarray(volume_m3, dtype=float))
        codes = np.broadcast_to(self.regimes(V), h.shape)
        rc = (None if self.core_radii_m is None
              else np.broadcast_to(self.core_radii_m, h.shape))
        out = np.zeros(h.shape)
        for k, law in enumerate(self._laws()):
            sel = codes == k
            if not np.any(sel):
                continue
            if k == 1 and rc is not None:
                law = _replace(law, core_radii_m=rc[sel])
            out[sel] = getattr(law, method)(h[sel], ms[sel], V[sel])
        return out

    def magnitude(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return self._apply("magnitude", H_abs_A_m, m_sat_Am2, volume_m3)

    def slope(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return self._apply("slope", H_abs_A_m, m_sat_Am2, volume_m3)

    def coenergy_J(self, H_abs_A_m, m_sat_Am2, volume_m3):
        return self._apply("coenergy_J", H_abs_A_m, m_sat_Am2, volume_m3)

    def params(self):
        return {"T_K": self.T_K, "measurement_time_s": self.measurement_time_s,
                "chi_i": self.chi_i, "material": self.material.name}


# ------------------------------------------------------------------------------------------
# Registry
# ------------------------------------------------------------------------------------------

#: The default law: each particle's regime. The seed's particles (Fe, 25 nm mean radius,
#: 7870 kg/m^3 x 178 A m^2/kg, no shell by default) are multi-domain: radius 25 nm > R_coh =
#: 12.2 nm (and K1 V / k_B T = 760 >> 25: blocked), so they follow ``approach``, i.e. the
#: demagnetization-limited sphere M = 3 H up to 0.83 Ms, then rotation with the law of approach.
DEFAULT_LAW = "regime"

_LAWS = {"saturated": (SaturatedLaw, ()), "linear": (LinearLaw, ("chi",)),
         "apparent-fk": (FrohlichKennellyLaw, ("chi0",)), "langevin": (LangevinLaw, ("T_K",)),
         "soft-fk": (SoftFKLaw, ("chi_i",)),
         "approach": (ApproachLaw, ("chi_i", "K1_J_m3", "Ms_core_A_m")),
         "stoner-wohlfarth": (StonerWohlfarthLaw, ("K_J_m3", "T_K")),
         "regime": (RegimeLaw, ("T_K", "measurement_time_s", "chi_i", "material"))}

#: Former names accepted for old study files: ``frohlich-kennelly`` is the apparent law.
LAW_ALIASES = {"frohlich-kennelly": "apparent-fk"}

_MATERIALS = {"Fe": FE, "Fe3O4": FE3O4}


def get_law(name: str, **params) -> MagnetizationLaw:
    """The magnetization law ``name`` with its parameters.

    Parameters
    ----------
    name : str -- one of :data:`LAW_NAMES`; ``"frohlich-kennelly"`` is an alias of
        ``"apparent-fk"`` (old study files)
    **params
        ``chi`` [-] for linear (default inf); ``chi0`` [-] for apparent-fk (default 3);
        ``T_K`` [K] for langevin, stoner-wohlfarth, regime (default 300); ``chi_i`` [-] for
        soft-fk (default 1000), approach and regime (default inf); ``K1_J_m3``, ``Ms_core_A_m``
        for approach (default Fe); ``K_J_m3`` for stoner-wohlfarth (default |K1| of Fe);
        ``measurement_time_s`` [s] (default 100) and ``material`` ("Fe", "Fe3O4" or a
        :class:`micro.materials.Constituent`; default Fe) for regime. Parameters of other laws
        are an error; ``None`` values are ignored (so CLI defaults can be passed through).
    """
    if isinstance(name, MagnetizationLaw):
        return name
    name = LAW_ALIASES.get(name, name)
    if name not in _LAWS:
        raise InputError(f"law must be one of {', '.join(LAW_NAMES)}; got {name!r}")
    cls, allowed = _LAWS[name]
    given = {k: v for k, v in params.items() if v is not None}
    extra = sorted(set(given) - set(allowed))
    if extra:
        raise InputError(f"law {name!r} takes parameters {list(allowed) or 'none'}; "
                         f"got unexpected {extra}")
    if "chi" in given and given["chi"] != math.inf:
        check_range("chi", given["chi"], 0.0, math.inf, "(dimensionless)", lo_open=True)
    if "material" in given and not isinstance(given["material"], Constituent):
        check_choice("material", given["material"], tuple(_MATERIALS))
        given["material"] = _MATERIALS[given["material"]]
    return cls(**{k: (v if k == "material" else float(v)) for k, v in given.items()})
