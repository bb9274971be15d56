"""Magnetization laws of one particle in its local field, vectorised over particles.

Every law maps the local field ``H`` [A/m] acting on a particle to its moment ``m`` [A m^2],
parallel to ``H``, with the particle's own saturation moment ``m_sat`` [A m^2] (core-shell
aware: the RVE carries one ``m_sat`` per particle) and its volume ``V`` [m^3]:

=====================  ============================================================  ==========
law                    moment magnitude ``|m|(h)`` with ``h = |H|``                  parameters
=====================  ============================================================  ==========
``saturated``          ``m_sat`` (the seed paper's assumption)                       --
``linear``             ``min(V 3 chi / (3 + chi) h, m_sat)`` (soft sphere, capped)   ``chi``
``frohlich-kennelly``  ``V chi0 h M_s / (M_s + chi0 h)``, ``M_s = m_sat / V``         ``chi0``
``langevin``           ``m_sat L(mu0 m_sat h / (k_B T))``                            ``T_K``
=====================  ============================================================  ==========

``chi`` is the intrinsic susceptibility of the particle material; ``chi = inf`` (the default)
is the demagnetisation-limited sphere, ``m = 3 V H``. ``chi0`` is the apparent initial
susceptibility of the sphere (default 3, the same limit). ``L(x) = coth x - 1/x``.

Each law also gives ``energy_density`` ``-mu0 int_0^h |m|(h') dh'`` [J] of a particle whose
moment follows the law (used to check forces against finite differences of the energy) and the
slope ``d|m|/dh`` used by Newton-type solvers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.constants import k as _KB
from scipy.constants import mu_0 as MU0

from ._validate import InputError, check_positive, check_range

__all__ = ["MagnetizationLaw", "SaturatedLaw", "LinearLaw", "FrohlichKennellyLaw", "LangevinLaw",
           "get_law", "LAW_NAMES"]

LAW_NAMES = ("saturated", "linear", "frohlich-kennelly", "langevin")


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
    """Froehlich-Kennelly: ``M = chi0 M_s H / (M_s + chi0 H)`` with ``M_s = m_sat / V``.

    ``chi0`` -- apparent initial susceptibility of the particle [-] (default 3: a soft sphere).
    """

    chi0: float = 3.0
    name = "frohlich-kennelly"

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


_LAWS = {"saturated": (SaturatedLaw, ()), "linear": (LinearLaw, ("chi",)),
         "frohlich-kennelly": (FrohlichKennellyLaw, ("chi0",)), "langevin": (LangevinLaw, ("T_K",))}


def get_law(name: str, **params) -> MagnetizationLaw:
    """The magnetization law ``name`` with its parameters.

    Parameters
    ----------
    name : {"saturated", "linear", "frohlich-kennelly", "langevin"}
    **params
        ``chi`` [-] for linear (default inf), ``chi0`` [-] for frohlich-kennelly (default 3),
        ``T_K`` [K] for langevin (default 300). Parameters of other laws are an error; ``None``
        values are ignored (so CLI defaults can be passed through).
    """
    if isinstance(name, MagnetizationLaw):
        return name
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
    return cls(**{k: float(v) for k, v in given.items()})
