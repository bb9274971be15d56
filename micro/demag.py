"""Demagnetizing factors of a uniformly magnetized specimen: prism, finite cylinder, spheroid.

All factors here are *magnetometric* (volume-averaged): for a body of volume ``V`` magnetized
uniformly with ``M``, the mean of its own field over the body is ``<H_d> = -N M``; ``N`` is the
factor an experiment on the whole specimen sees (a magnetometer, or the net force in a weak
gradient). The three principal factors of any body sum to 1 (the trace of the magnetometric
tensor is 1), and for an ellipsoid they are also the exact, uniform (fluxmetric) factors.

* :func:`prism_demag_factors` -- rectangular prism, the closed form of A. Aharoni,
  J. Appl. Phys. 83, 3432 (1998), eq. (1), written with ``asinh`` for the logarithms so that thin
  plates and long rods keep their digits.
* :func:`cylinder_demag_factors` -- finite circular cylinder. Axial factor from the charge
  picture of the two end discs (the route of Joseph 1966 and of Chen, Brug & Goldfarb, IEEE
  Trans. Magn. 27, 3601 (1991)) as the exact one-dimensional integral

      N_z = (2 R / L) int_0^inf J1(u)^2 (1 - exp(-u L / R)) / u^2 du,

  evaluated by composite Gauss-Legendre quadrature to ``u = U`` plus the analytic tail of the
  large-``u`` asymptote of ``J1^2`` (absolute error < 1e-10); transverse ``(1 - N_z) / 2`` by the
  trace rule. Derivation: the surface charges ``+-M`` on the end discs have the Hankel
  potential ``phi = (M R / 2) int J0(k rho) J1(k R) exp(-k |z|) / k dk``; the magnetostatic energy
  ``mu0 / 2 int sigma phi dA = mu0 M^2 pi R^2 int J1(kR)^2 (1 - e^{-kL}) / k^2 dk`` equals
  ``mu0 / 2 N M^2 V``.
* :func:`spheroid_demag_factors` -- ellipsoid of revolution, the closed forms of J. A. Osborn,
  Phys. Rev. 67, 351 (1945), eqs. (2.6) prolate and (2.23) oblate; near the sphere, where those
  forms cancel, the same factor from Carlson's symmetric integral
  ``N_z = (a b c / 3) R_D(a^2, b^2, c^2)`` (:func:`ellipsoid_demag_factors`).

Lengths are in metres, but every factor depends on ratios only.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import elliprd, expn, j1

from micro.common.validate import check_positive

__all__ = ["prism_demag_factors", "cylinder_demag_factors", "spheroid_demag_factors",
           "ellipsoid_demag_factors"]


def _aharoni_nz(a: float, b: float, c: float) -> float:
    """Aharoni's ``D_z`` of the prism ``2a x 2b x 2c`` (field along ``c``); ratios only matter."""
    r = math.sqrt(a * a + b * b + c * c)
    rab, rbc, rac = math.hypot(a, b), math.hypot(b, c), math.hypot(a, c)
    # ln((r - a) / (r + a)) = -2 asinh(a / sqrt(b^2 + c^2)), and likewise for the others
    s = ((b * b - c * c) / (2 * b * c) * (-2.0 * math.asinh(a / rbc))
         + (a * a - c * c) / (2 * a * c) * (-2.0 * math.asinh(b / rac))
         + b / (2 * c) * (2.0 * math.asinh(a / b))
         + a / (2 * c) * (2.0 * math.asinh(b / a))
         + c / (2 * a) * (-2.0 * math.asinh(b / c))
         + c / (2 * b) * (-2.0 * math.asinh(a / c))
         + 2.0 * math.atan(a * b / (c * r))
         + (a ** 3 + b ** 3 - 2 * c ** 3) / (3 * a * b * c)
         + (a * a + b * b - 2 * c * c) / (3 * a * b * c) * r
         + c / (a * b) * (rac + rbc)
         - (rab ** 3 + rbc ** 3 + rac ** 3) / (3 * a * b * c))
    return s / math.pi


def prism_demag_factors(a_m: float, b_m: float, c_m: float) -> tuple[float, float, float]:
    """Magnetometric demagnetizing factors of a rectangular prism (Aharoni 1998).

    Parameters
    ----------
    a_m, b_m, c_m : float -- full edge lengths along x, y, z [m], > 0

    Returns
    -------
    (Nx, Ny, Nz) : floats -- factors for magnetization along each edge [-]; they sum to 1

    Notes
    -----
    Aharoni's formula is written for half-edges; the factors depend on the ratios only, so full
    edges enter unchanged. Each factor is the same function with the axes permuted. Accuracy:
    the algebraic terms cancel to ``O(1)`` from terms of size ``max(a, b, c)^2 / (a b c)^(2/3)``,
    so about ``16 - 2 log10(aspect)`` digits remain (>= 10 digits up to aspect 1000).
    """
    a = check_positive("a_m", a_m, "m")
    b = check_positive("b_m", b_m, "m")
    c = check_positive("c_m", c_m, "m")
    # scale out the size: the formula is homogeneous of degree 0
    s = max(a, b, c)
    a, b, c = a / s, b / s, c / s
    nz = _aharoni_nz(a, b, c)
    nx = _aharoni_nz(b, c, a)
    ny = _aharoni_nz(c, a, b)
    return nx, ny, nz


# composite Gauss-Legendre rule on [0, _U] for the cylinder integral: panels of length pi / 2
# (a quarter of J1^2's period) with 16 points integrate the smooth oscillation to round-off
_U = 2000.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)


def _cylinder_axial(beta: float) -> float:
    """``(2 / beta) int_0^inf J1(u)^2 (1 - e^{-beta u}) / u^2 du`` with ``beta = L / R``."""
    edges = np.linspace(0.0, _U, int(round(_U / (0.5 * np.pi))) + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    u = (mid[:, None] + half[:, None] * _GL_X[None, :]).ravel()
    w = (half[:, None] * _GL_W[None, :]).ravel()
    # 1 - e^{-beta u} without cancellation for thin discs
    integrand = (j1(u) / u) ** 2 * -np.expm1(-beta * u)
    body = float(np.dot(w, integrand))
    # tail: J1(u)^2 ~ (1 - sin 2u) / (pi u); the oscillating part and the next asymptotic term
    # contribute O(U^-3) ~ 1e-10; int_U^inf (1 - e^{-beta u}) u^-3 du = (1/2 - E3(beta U)) / U^2
    tail = (0.5 - expn(3, beta * _U)) / (np.pi * _U ** 2)
    return 2.0 / beta * (body + tail)


def cylinder_demag_factors(radius_m: float, length_m: float) -> tuple[float, float, float]:
    """Magnetometric demagnetizing factors of a finite circular cylinder, axis along z.

    Parameters
    ----------
    radius_m : float -- radius R [m], > 0
    length_m : float -- length L along the axis [m], > 0

    Returns
    -------
    (Nx, Ny, Nz) : floats -- transverse, transverse, axial [-]; they sum to 1

    Notes
    -----
    ``N_z`` is the exact integral of the module docstring (charge discs), evaluated to an
    absolute error below 1e-9 for ``1e-3 <= L / R <= 1e4``; ``Nx = Ny = (1 - N_z) / 2``. At
    ``L = 2R`` it gives 0.3116, the magnetometric value tabulated by Chen, Brug & Goldfarb (1991).
    """
    R = check_positive("radius_m", radius_m, "m")
    L = check_positive("length_m", length_m, "m")
    nz = float(_cylinder_axial(L / R))
    nt = 0.5 * (1.0 - nz)
    return nt, nt, nz


def ellipsoid_demag_factors(a_m: float, b_m: float, c_m: float) -> tuple[float, float, float]:
    """Demagnetizing factors of the ellipsoid with semi-axes ``a, b, c`` along x, y, z [m].

    ``N_x = (a b c / 3) R_D(b^2, c^2, a^2)`` and cyclically (Carlson's symmetric elliptic
    integral, :func:`scipy.special.elliprd`); exact and uniform inside an ellipsoid. Returns
    ``(Nx, Ny, Nz)`` [-], summing to 1.
    """
    a = check_positive("a_m", a_m, "m")
    b = check_positive("b_m", b_m, "m")
    c = check_positive("c_m", c_m, "m")
    s = max(a, b, c)
    a, b, c = a / s, b / s, c / s
    k = a * b * c / 3.0
    return (float(k * elliprd(b * b, c * c, a * a)), float(k * elliprd(c * c, a * a, b * b)),
            float(k * elliprd(a * a, b * b, c * c)))


def spheroid_demag_factors(polar_m: float, equatorial_m: float) -> tuple[float, float, float]:
    """Demagnetizing factors of a spheroid with its symmetry axis along z (Osborn 1945).

    Parameters
    ----------
    polar_m : float -- semi-axis along the symmetry axis ``c`` [m], > 0
    equatorial_m : float -- equatorial semi-axis ``a = b`` [m], > 0

    Returns
    -------
    (Nx, Ny, Nz) : floats [-], ``Nx = Ny = (1 - Nz) / 2``

    Notes
    -----
    With ``m = c / a``: prolate (``m > 1``)
    ``N_z = [m / sqrt(m^2 - 1) ln(m + sqrt(m^2 - 1)) - 1] / (m^2 - 1)``; oblate (``m < 1``)
    ``N_z = [1 - m / sqrt(1 - m^2) arccos(m)] / (1 - m^2)``. Both lose digits as ``m -> 1``
    (``1 / (m^2 - 1)`` times a difference of O(m - 1)); for ``|m - 1| < 1e-2`` the factor is taken
    from :func:`ellipsoid_demag_factors` instead (same function, no cancellation).
    """
    c = check_positive("polar_m", polar_m, "m")
    a = check_positive("equatorial_m", equatorial_m, "m")
    m = c / a
    if abs(m - 1.0) < 1e-2:
        return ellipsoid_demag_factors(a, a, c)
    if m > 1.0:
        e = math.sqrt(m * m - 1.0)
        nz = (m / e * math.log(m + e) - 1.0) / (m * m - 1.0)
    else:
        e = math.sqrt(1.0 - m * m)
        nz = (1.0 - m / e * math.acos(m)) / (1.0 - m * m)
    nt = 0.5 * (1.0 - nz)
    return nt, nt, nz
