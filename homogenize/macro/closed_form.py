"""Closed-form and one-dimensional references for a cantilever under a uniform body force.

The strip is clamped at ``x = 0``, has length ``L``, width ``w`` and thickness ``t`` and carries a
body force ``f`` [N/m^3] perpendicular to its plane, i.e. a distributed line load
``q = f w t`` [N/m] per unit *undeformed* length of fixed direction.

* Euler-Bernoulli: ``delta = q L^4 / (8 E I)`` with ``I = w t^3 / 12``, hence
  ``delta = 3 f L^4 / (2 E t^2)`` (independent of the width). With ``plate=True`` the bending
  stiffness is the plate (cylindrical bending) value ``E I / (1 - nu^2)``, the limit of a strip
  whose cross-section cannot curl anticlastically (width >> length, or a wide clamped plate).
* Timoshenko: adds the shear deflection ``q L^2 / (2 kappa G A)`` with the shear coefficient of a
  rectangle ``kappa = 10 (1 + nu) / (12 + 11 nu)`` (Cowper 1966).
* Elastica: the inextensible Euler-Bernoulli beam at large rotation,
  ``EI theta'' = q (L - s) cos(theta)``, ``theta(0) = 0``, ``theta'(L) = 0``, with the tip
  position ``(x, y)(L) = int_0^L (cos theta, sin theta) ds``; solved as a two-point boundary
  value problem with :func:`scipy.integrate.solve_bvp` and load continuation; an independent
  shooting solver (:func:`elastica_shooting`) covers the same range of loads.

Body force that varies along the strip: :func:`eb_tip_deflection_m`,
:func:`timoshenko_tip_deflection_m` and :func:`elastica_tip_deflection` also take ``f_N_m3`` as
a callable ``f(x_m) -> N/m^3`` (vectorised over an array of ``x`` in ``[0, L]``) or as a
:class:`BodyForceProfile` (samples on a grid, linear in between), e.g. the force of a real magnet
from :mod:`homogenize.macro.magnets`. A number or an array keeps its meaning (uniform force;
vectorised over loads). With ``q(x) = f(x) w t`` and ``Q(x) = int_x^L q`` (the shear force):

* Euler-Bernoulli by superposition of point loads:
  ``delta = int_0^L q(x) x^2 (3L - x) dx / (6 EI)``;
* Timoshenko adds ``int_0^L Q(x) dx / (kappa G A) = int_0^L q(x) x dx / (kappa G A)``;
* elastica: ``EI theta'' = Q(s) cos(theta)`` with the same boundary conditions.

The integrals of a callable are taken by Gauss-Legendre on 256 panels (8 points each, exact for
polynomial loads up to degree 12); a profile's nodes are added to the panel edges so that its
kinks are integrated exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_bvp, solve_ivp
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from micro.common.validate import InputError, check_finite, check_positive, check_range
from micro.materials import PDMS

__all__ = [
    "BodyForceProfile",
    "eb_tip_deflection_m",
    "timoshenko_tip_deflection_m",
    "elastica_tip_deflection",
    "elastica_shooting",
    "bending_stiffness_N_m2",
    "shear_coefficient_rectangle",
    "plate_clamped_strip_deflection_m",
]


def _check_geometry(length_m, width_m, thickness_m, E_Pa, nu):
    L = check_positive("length_m", length_m, "m")
    w = check_positive("width_m", width_m, "m")
    t = check_positive("thickness_m", thickness_m, "m")
    E = check_positive("E_Pa", E_Pa, "Pa")
    nu = check_range("nu", nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
    return L, w, t, E, nu


def _force_array(f_N_m3):
    check_finite("f_N_m3", f_N_m3, "N/m^3")
    return np.asarray(f_N_m3, dtype=float)


@dataclass(frozen=True, eq=False)
class BodyForceProfile:
    """A transverse body force sampled along the strip, linear between the samples.

    Parameters
    ----------
    x_m : array_like, shape (n,) -- positions along the strip from the clamp, strictly
        increasing, n >= 2 [m]
    f_N_m3 : array_like, shape (n,) -- body force along the load direction (-z) at ``x_m``
        [N/m^3]

    Calling the profile with ``x`` [m] (any shape) interpolates linearly; a point outside
    ``[x_m[0], x_m[-1]]`` raises :class:`InputError` (no silent extrapolation). The solvers
    require the samples to cover the strip, ``x_m[0] <= 0`` and ``x_m[-1] >= L``.
    """

    x_m: np.ndarray
    f_N_m3: np.ndarray

    def __post_init__(self):
        x = np.array(check_finite("x_m", self.x_m, "m"), dtype=float)
        f = np.array(check_finite("f_N_m3", self.f_N_m3, "N/m^3"), dtype=float)
        if x.ndim != 1 or x.size < 2 or f.shape != x.shape:
            raise InputError(f"BodyForceProfile needs x_m and f_N_m3 of the same shape (n,), "
                             f"n >= 2; got {x.shape} and {f.shape}")
        if np.any(np.diff(x) <= 0):
            raise InputError("x_m must be strictly increasing [m]")
        x.flags.writeable = False
        f.flags.writeable = False
        object.__setattr__(self, "x_m", x)
        object.__setattr__(self, "f_N_m3", f)

    def __call__(self, x_m):
        x = np.asarray(x_m, dtype=float)
        span = self.x_m[-1] - self.x_m[0]
        if np.any(x < self.x_m[0] - 1e-12 * span) or np.any(x > self.x_m[-1] + 1e-12 * span):
            raise InputError(f"x_m outside the profile's range [{self.x_m[0]:g}, "
                             f"{self.x_m[-1]:g}] m")
        return np.interp(x, self.x_m, self.f_N_m3)


#: Gauss-Legendre rule used on each panel of a varying load
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_N_PANELS = 256


class _VaryingLoad:
    """A body force ``f(x)`` [N/m^3] on ``[0, L]``: its panel quadrature and shear function."""

    def __init__(self, f, L):
        if isinstance(f, BodyForceProfile):
            span = f.x_m[-1] - f.x_m[0]
            if f.x_m[0] > 1e-12 * span or f.x_m[-1] < L * (1 - 1e-12):
                raise InputError(f"the body force profile covers [{f.x_m[0]:g}, "
                                 f"{f.x_m[-1]:g}] m; it must cover the strip [0, {L:g}] m")
            inner = f.x_m[(f.x_m > 0) & (f.x_m < L)]
        else:
            inner = np.empty(0)
        edges = np.union1d(np.linspace(0.0, L, _N_PANELS + 1), inner)
        # profile nodes that coincide with a panel edge up to round-off would make empty panels
        # (and a spline on repeated abscissae): keep one of each such pair
        edges = edges[np.concatenate([[True], np.diff(edges) > 1e-9 * L])]
        edges[-1] = L
        self.L, self.edges = L, edges
        h = 0.5 * np.diff(edges)
        mid = 0.5 * (edges[1:] + edges[:-1])
        self.x = mid[:, None] + h[:, None] * _GL_X           # (panels, 8) nodes [m]
        self.w = h[:, None] * _GL_W
        q = np.asarray(f(self.x), dtype=float)
        if q.shape != self.x.shape:
            raise InputError(f"the body force callable must return an array shaped like x "
                             f"{self.x.shape}, got {q.shape}")
        check_finite("f_N_m3(x)", q, "N/m^3")
        self.q = q
        # Q(x) = int_x^L f at the panel edges (exact for piecewise polynomials up to degree 15)
        per_panel = (self.w * q).sum(axis=1)
        self.Q_edges = np.concatenate([np.cumsum(per_panel[::-1])[::-1], [0.0]])

    @property
    def mean_N_m3(self) -> float:
        return float(self.Q_edges[0] / self.L)

    def moment(self, weight):
        """``int_0^L f(x) weight(x) dx``."""
        return float(np.sum(self.w * self.q * weight(self.x)))

    def shear_shape(self):
        """``(f_ref, Qhat)``: ``Qhat(s) = Q(s L) / (f_ref L)``, ``f_ref = max |f|``.

        A uniform load has ``Qhat = 1 - s``.
        """
        f_ref = float(np.max(np.abs(self.q)))
        if f_ref == 0.0:
            return 0.0, None
        # Q is the integral of the load: one order smoother than f; the cubic spline through the
        # edge values reproduces Q exactly for loads up to linear and to O(h^4) otherwise
        spline = CubicSpline(self.edges / self.L, self.Q_edges / (f_ref * self.L))
        return f_ref, spline


def _is_varying(f_N_m3) -> bool:
    return callable(f_N_m3)


def bending_stiffness_N_m2(width_m, thickness_m, E_Pa, nu=0.0, plate=False) -> float:
    """Bending stiffness ``E I`` (or ``E I / (1 - nu^2)`` with ``plate``) of a rectangle [N m^2]."""
    _, w, t, E, nu = _check_geometry(1.0, width_m, thickness_m, E_Pa, nu)
    EI = E * w * t**3 / 12.0
    return EI / (1.0 - nu**2) if plate else EI


def shear_coefficient_rectangle(nu: float) -> float:
    """Timoshenko shear coefficient of a rectangular section, ``10 (1+nu) / (12 + 11 nu)``."""
    nu = check_range("nu", nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
    return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)


def eb_tip_deflection_m(f_N_m3, length_m, width_m, thickness_m, E_Pa, nu=0.0, plate=False):
    """Euler-Bernoulli tip deflection of a cantilever under a uniform body force.

    Parameters
    ----------
    f_N_m3 : float, ndarray, callable or BodyForceProfile -- body force perpendicular to the
        strip [N/m^3]: uniform (vectorised over an array), or varying along the strip
        (``f(x_m)``, see the module docstring)
    length_m, width_m, thickness_m : float -- strip length, width, thickness (load along t) [m]
    E_Pa : float -- Young's modulus [Pa]
    nu : float -- Poisson ratio, used only with ``plate`` [-]
    plate : bool -- use the plate bending stiffness ``E I / (1 - nu^2)``

    Returns
    -------
    float or ndarray -- tip deflection along the force [m], same shape as ``f_N_m3`` (a float
    for a varying force)
    """
    if _is_varying(f_N_m3):
        L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
        load = _VaryingLoad(f_N_m3, L)
        # tip deflection of a unit point load at x: x^2 (3L - x) / (6 EI)
        return w * t * load.moment(lambda x: x**2 * (3 * L - x)) / (
            6.0 * bending_stiffness_N_m2(w, t, E, nu, plate))
    f = _force_array(f_N_m3)
    L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
    q = f * w * t
    out = q * L**4 / (8.0 * bending_stiffness_N_m2(w, t, E, nu, plate))
    return float(out) if out.ndim == 0 else out


def timoshenko_tip_deflection_m(f_N_m3, length_m, width_m, thickness_m, E_Pa, nu=PDMS.nu,
                                plate=False):
    """Timoshenko tip deflection: Euler-Bernoulli plus the shear term ``q L^2 / (2 kappa G A)``.

    Same parameters as :func:`eb_tip_deflection_m` (uniform or varying force); ``nu`` also sets
    ``G = E / (2 (1 + nu))`` and the shear coefficient ``kappa``. Returns the tip deflection [m].
    For a varying force the shear term is ``int_0^L q(x) x dx / (kappa G A)``.
    """
    if _is_varying(f_N_m3):
        L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
        load = _VaryingLoad(f_N_m3, L)
        G = E / (2.0 * (1.0 + nu))
        shear = load.moment(lambda x: x) / (shear_coefficient_rectangle(nu) * G)
        return eb_tip_deflection_m(f_N_m3, L, w, t, E, nu, plate) + shear
    f = _force_array(f_N_m3)
    L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
    G = E / (2.0 * (1.0 + nu))
    kappa = shear_coefficient_rectangle(nu)
    shear = f * w * t * L**2 / (2.0 * kappa * G * w * t)
    out = np.asarray(eb_tip_deflection_m(f, L, w, t, E, nu, plate)) + shear
    return float(out) if out.ndim == 0 else out


def plate_clamped_strip_deflection_m(f_N_m3, span_m, thickness_m, E_Pa, nu=PDMS.nu):
    """Mid-span deflection of a plate strip clamped on both long edges (cylindrical bending).

    ``delta = q a^4 / (384 D)`` with ``q = f c`` and ``D = E c^3 / (12 (1 - nu^2))``, i.e.
    ``f a^4 (1 - nu^2) / (32 E c^2)``: the limit of a channel ceiling of span ``a`` and thickness
    ``c`` on rigid walls, ``a >> c``. Returns [m].
    """
    f = _force_array(f_N_m3)
    a = check_positive("span_m", span_m, "m")
    c = check_positive("thickness_m", thickness_m, "m")
    E = check_positive("E_Pa", E_Pa, "Pa")
    nu = check_range("nu", nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
    out = f * a**4 * (1.0 - nu**2) / (32.0 * E * c**2)
    return float(out) if out.ndim == 0 else out


# --------------------------------------------------------------------------------------------
# elastica: dimensionless form with s in [0, 1], alpha = q L^3 / (EI)
#   y = (theta, theta', X, Y):  theta'' = alpha (1 - s) cos(theta), X' = cos, Y' = sin
# The load points towards -Y, so theta < 0 and the deflection is -Y(1).

def _uniform_shape(s):
    return 1.0 - s


def _rhs(alpha, shape=_uniform_shape):
    # shape(s) = Q(s L) / (f_ref L): the dimensionless shear force, 1 - s for a uniform load
    def f(s, y):
        th, k = y[0], y[1]
        return np.array([k, alpha * shape(s) * np.cos(th), np.cos(th), np.sin(th)])
    return f


def _bc(ya, yb):
    return np.array([ya[0], yb[1], ya[2], ya[3]])


def _linear_guess(s, alpha):
    # Euler-Bernoulli shape: w'' = -alpha (1-s)^2 / 2 (downwards), theta = w'
    theta = -alpha * (1.0 - (1.0 - s) ** 3) / 6.0
    k = -alpha * (1.0 - s) ** 2 / 2.0
    Y = -alpha * (s**4 / 24.0 - s**3 / 6.0 + s**2 / 4.0)
    return np.vstack((theta, k, s.copy(), Y))


def _elastica_alpha(alphas, shape=_uniform_shape):
    """Dimensionless tip (vertical, horizontal) displacement for sorted loads ``alphas``."""
    s = np.linspace(0.0, 1.0, 101)
    y = _linear_guess(s, 0.0)
    out = []
    a_prev = 0.0
    for a in alphas:
        # continuation: steps of at most max(2, alpha/2) keep the previous shape a good guess
        ak = a_prev
        while ak < a or ak == a_prev == a:
            ak = min(a, max(ak + 2.0, 1.5 * ak))
            sol = solve_bvp(_rhs(ak, shape), _bc, s, y, tol=1e-9, max_nodes=100000)
            if not sol.success:
                raise RuntimeError(f"elastica did not converge at alpha={ak:g}: {sol.message}")
            s, y = sol.x, sol.y
            if ak == a:
                break
        a_prev = a
        out.append((-y[3, -1], 1.0 - y[2, -1]))
    return np.array(out).reshape(-1, 2)


def elastica_tip_deflection(f_N_m3, length_m, width_m, thickness_m, E_Pa, nu=0.0, plate=False):
    """Large-deflection (elastica) tip displacement of a cantilever under a body force.

    The load ``q = f w t`` per undeformed length keeps its direction (dead load, as the magnetic
    gradient force on a fixed number of particles); the axis is inextensible and unsheared.

    Parameters
    ----------
    f_N_m3 : float or ndarray -- body force [N/m^3], >= 0; or a callable ``f(x_m)`` /
        :class:`BodyForceProfile` varying along the strip (any sign; then
        ``EI theta'' = Q(s) cos(theta)`` with the shear force ``Q(s) = w t int_s^L f``)
    length_m, width_m, thickness_m : float -- strip dimensions [m]
    E_Pa : float -- Young's modulus [Pa]
    nu, plate : as in :func:`eb_tip_deflection_m`

    Returns
    -------
    (vertical_m, horizontal_m) : tip displacement along the force and the shortening of the
    projected length, floats or arrays shaped like ``f_N_m3`` [m] (floats for a varying force)
    """
    if _is_varying(f_N_m3):
        L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
        f_ref, shape = _VaryingLoad(f_N_m3, L).shear_shape()
        if f_ref == 0.0:
            return 0.0, 0.0
        alpha = f_ref * w * t * L**3 / bending_stiffness_N_m2(w, t, E, nu, plate)
        v, h = _elastica_alpha(np.array([alpha]), shape)[0]
        return float(v * L), float(h * L)
    f = _force_array(f_N_m3)
    if np.any(f < 0):
        raise InputError(f"f_N_m3 must be >= 0 N/m^3 (the sign is the force direction), got "
                         f"{f.min():g}")
    L, w, t, E, nu = _check_geometry(length_m, width_m, thickness_m, E_Pa, nu)
    EI = bending_stiffness_N_m2(w, t, E, nu, plate)
    alpha = f.ravel() * w * t * L**3 / EI
    order = np.argsort(alpha)
    res = np.empty((alpha.size, 2))
    res[order] = _elastica_alpha(alpha[order])
    v = (res[:, 0] * L).reshape(f.shape)
    h = (res[:, 1] * L).reshape(f.shape)
    if f.ndim == 0:
        return float(v), float(h)
    return v, h


# Shooting from the free end. The physical unknown is the tip angle; with the load along -Y the
# strip hangs ever closer to vertical, so the angle from the vertical, phi = theta + pi / 2 in
# (0, pi / 2], is the natural variable. Near the tip phi obeys phi'' ~ alpha (1 - s) phi, whose
# solution grows by ~exp(2 sqrt(alpha) / 3) from the tip to the clamp: the tip value is ~1e-29
# at alpha = 1e4, far below the resolution of theta near -pi / 2. Hence psi = ln(phi) is
# integrated, which (i) represents any tip angle, (ii) follows the growing mode, the stable
# direction, from s = 1 down to s = 0, and (iii) makes the shot's outcome monotone in psi(1).
_LOG_HALF_PI = float(np.log(0.5 * np.pi))


def _shooting_rhs(alpha):
    # y = (psi, psi', X, D): phi'' = alpha (1 - s) sin(phi) with phi = exp(psi), i.e.
    # psi'' = alpha (1 - s) sin(phi) / phi - psi'^2; X' = sin(phi) = cos(theta) (horizontal),
    # D' = cos(phi) = -sin(theta) (along the load)
    def f(s, y):
        psi, dpsi = y[0], y[1]
        phi = np.exp(psi)
        sinc = np.sin(phi) / phi if phi > 1e-8 else 1.0 - phi * phi / 6.0
        return [dpsi, alpha * (1.0 - s) * sinc - dpsi * dpsi, np.sin(phi), np.cos(phi)]
    return f


def elastica_shooting(alpha: float) -> tuple[float, float]:
    """Independent elastica solution by shooting from the free end, dimensionless.

    Returns ``(delta / L, shortening / L)`` for ``alpha = q L^3 / (EI)`` >= 0; used to check the
    boundary-value solver and valid over the whole range of loads (tested to alpha = 1e6, where
    ``delta / L -> 1 - (2 - sqrt 2) / sqrt(alpha)``, the strip hanging from a boundary layer of
    length ~ L / sqrt(alpha) at the clamp).

    Method: the free end has ``theta' = 0`` and an unknown angle ``phi_tip`` from the vertical.
    Integrating ``phi'' = alpha (1 - s) sin(phi)`` from the tip towards the clamp (in
    ``psi = ln phi``, DOP853, rtol 1e-12), ``phi`` increases monotonically; the clamp condition
    ``phi(0) = pi / 2`` (horizontal) selects ``psi_tip``. The residual is the arc length at which
    ``phi`` first reaches ``pi / 2`` (positive, the shot went vertical-to-horizontal too early)
    or ``phi(0) - pi / 2`` (negative): continuous and increasing in ``psi_tip``, so the bracket
    ``[psi_lo, ln(pi / 2)]`` holds exactly the physical root (overshooting shots, which loop
    past the horizontal, are stopped at ``pi / 2`` and never offer spurious roots).
    """
    alpha = check_positive("alpha", alpha, "", allow_zero=True)
    if alpha == 0.0:
        return 0.0, 0.0
    rhs = _shooting_rhs(alpha)

    def horizontal(s, y):
        return y[0] - _LOG_HALF_PI
    horizontal.terminal = True

    def run(psi_tip, stop):
        return solve_ivp(rhs, (1.0, 0.0), [psi_tip, 0.0, 0.0, 0.0], method="DOP853",
                         rtol=1e-12, atol=1e-14, events=horizontal if stop else None)

    def residual(psi_tip):
        sol = run(psi_tip, True)
        if sol.t_events[0].size:
            return float(sol.t_events[0][0])
        return float(sol.y[0, -1]) - _LOG_HALF_PI

    hi = _LOG_HALF_PI                 # horizontal tip: the root moment is positive, phi(0) > pi/2
    step = 1.0
    lo = hi - step
    while residual(lo) > 0.0:         # ~ (2/3) sqrt(alpha) e-folds below: doubling finds it
        step *= 2.0
        lo = hi - step
        if step > 1e5:                # alpha ~ 1e9: exp(psi) would underflow long before
            raise RuntimeError(f"elastica_shooting: no bracket at alpha={alpha:g}")
    psi_tip = brentq(residual, lo, hi, xtol=1e-14, rtol=4.0 * np.finfo(float).eps)
    y = run(psi_tip, False).y[:, -1]
    # integrated from s = 1 down to 0: the integrals over [0, 1] are minus the final states
    return float(-y[3]), float(1.0 + y[2])
