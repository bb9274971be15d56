"""Liquid flow through the tunable channel: Poiseuille on the deformed cross-section, two-way
pressure coupling along the channel, and the body force (field) for a target gap.

The channel of :mod:`homogenize.macro.channel` (width ``a``, height ``b``, ceiling thickness
``c``, length ``d``) carries a Newtonian liquid at low Reynolds number. Three layers:

1. **Cross-section** -- fully developed flow ``w(y, z)`` along ``x`` solves the 2D Poiseuille
   problem ``-mu lap w = G_p`` (``G_p = -dp/dx``), ``w = 0`` on the walls, on the region
   ``0 < y < a, 0 < z < h(y)`` under the (deflected) ceiling; the conductance per unit length
   ``K = Q / G_p = int w dA / G_p`` [m^4/(Pa s)] comes from P2 finite elements (scikit-fem) on a
   mesh mapped to ``h(y)``. The hydraulic resistance of a length ``L`` is ``L / K``.
2. **Ceiling** -- :class:`CeilingModel` gives the gap ``h(y) = b - f u_f(y) + p u_p(y)``,
   linear in the body force ``f`` (towards the glass) and the local liquid pressure ``p``
   (bulges the ceiling up), from the 3D FEM of :func:`~homogenize.macro.channel.solve_channel`
   (``from_fem``) or from the clamped plate strip (``clamped_plate``).
3. **Along the channel** -- lubrication approximation as in Gervais et al., Lab Chip 6 (2006)
   500: each section deforms with its own pressure, ``Q = -K(p(x)) dp/dx`` with ``Q`` the same
   at every ``x`` (mass conservation). Integrating once, ``Q (d - x) = Phi(p(x))`` with
   ``Phi(p) = int_{p_out}^{p} K(p') dp'``: the coupled problem is solved together, exactly,
   by one quadrature of ``K`` over the pressure range and one inversion per ``x``.

A gap that reaches the glass (contact) is reported as closure: gaps are clipped at zero and a
closed section conducts nothing (the linear ceiling model does not hold after contact, so the
flow through the side lobes beside a contact line is not modelled).

Because the ceiling only rises with pressure and ``p(x) >= p_out``, the smallest gap is always
at the outlet, ``x = d``: the field that sets the minimum gap does not depend on the flow
unless the outlet pressure does (``outlet_pressure_Pa``).

Units: SI throughout (m, Pa, Pa s, m^3/s, N/m^3).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
from numpy.polynomial import chebyshev as C
from scipy.optimize import brentq
from skfem import Basis, BilinearForm, ElementTriP2, LinearForm, MeshTri, asm, condense, solve
from skfem.helpers import dot, grad

from homogenize.macro.channel import ChannelGeometry, solve_channel
from homogenize.macro.fem import Material
from micro.common.validate import InputError, check_finite, check_positive

__all__ = ["Liquid", "BLOOD_PLASMA", "rectangular_duct_conductance_m4_Pa_s",
           "section_conductance_m4_Pa_s", "CeilingModel", "ChannelFlowResult",
           "solve_channel_flow", "FlowInterval", "flow_with_interval", "TargetGapResult",
           "field_for_target_gap", "ClosureResult", "closure", "plot_channel_flow"]


@dataclass(frozen=True)
class Liquid:
    """A Newtonian liquid: ``viscosity_Pa_s`` [Pa s], with the ``source`` of that number."""
    name: str
    viscosity_Pa_s: float
    source: str = ""

    def __post_init__(self):
        check_positive("viscosity_Pa_s", self.viscosity_Pa_s, "Pa s")


#: Human blood plasma at 37 C, 1.2 mPa s (Newtonian: plasma viscosity does not depend on the
#: shear rate). Reference ranges are quoted at 25 C, 1.50-1.72 mPa s (Chanarin, Laboratory
#: Haematology, 1989, the range UK laboratories use); plasma viscosity falls by about 2.5 % per
#: K (Harkness, MD thesis, Univ. Glasgow 1952), giving about 1.1-1.3 mPa s at 37 C. Rosenson,
#: McCormick & Uretz, Clin. Chem. 42 (1996) 1189 measured 1.39 +/- 0.08 mPa s at 37 C in 126
#: healthy adults (coaxial-cylinder viscometer). 1.2 mPa s is a round value in that band;
#: pass another Liquid for a specific sample.
BLOOD_PLASMA = Liquid(
    "blood plasma, 37 C", 1.2e-3,
    source="1.50-1.72 mPa s at 25 C (Chanarin, Laboratory Haematology 1989) with ~2.5 %/K "
           "(Harkness 1952) -> ~1.1-1.3 mPa s at 37 C; Rosenson et al., Clin. Chem. 42 (1996) "
           "1189: 1.39 +/- 0.08 mPa s at 37 C. Round value 1.2 mPa s.")


# ------------------------------------------------------------------------------ cross-section
def rectangular_duct_conductance_m4_Pa_s(width_m: float, height_m: float,
                                         viscosity_Pa_s: float, n_terms: int = 200) -> float:
    """Conductance per unit length ``Q / (-dp/dx)`` of a rectangular duct [m^4/(Pa s)].

    Series solution of ``-mu lap w = G_p`` on ``[0, W] x [0, H]`` (``H <= W`` after swapping):
    ``K = H^3 W / (12 mu) [1 - (192 H / (pi^5 W)) sum_{n odd} tanh(n pi W / (2 H)) / n^5]``.
    The terms fall as ``n^-5``: 200 odd terms leave a truncation error below 1e-12.

    Parameters
    ----------
    width_m, height_m : float -- sides of the duct [m]
    viscosity_Pa_s : float -- dynamic viscosity [Pa s]
    n_terms : int -- odd terms of the series
    """
    W = check_positive("width_m", width_m, "m")
    H = check_positive("height_m", height_m, "m")
    mu = check_positive("viscosity_Pa_s", viscosity_Pa_s, "Pa s")
    if H > W:
        W, H = H, W
    n = 2.0 * np.arange(int(n_terms)) + 1.0
    s = np.sum(np.tanh(n * np.pi * W / (2.0 * H)) / n**5)
    return float(H**3 * W / (12.0 * mu) * (1.0 - 192.0 * H / (np.pi**5 * W) * s))


def _section_y_nodes(a_m: float, b_m: float, n_wall: int = 12, n_mid: int = 24) -> np.ndarray:
    """Columns of the section mesh: graded towards both side walls, uniform in the middle.

    The side-wall boundary layer of the Poiseuille profile is ~``b`` wide, so the layer
    ``min(a/2, 3 b)`` next to each wall gets ``n_wall`` cells shrinking towards the wall (last
    over first = 1/8); beyond it the profile is locally parabolic in ``z`` (exact for P2) and
    only the slow variation of ``h(y)`` needs resolving (``n_mid`` cells per half width).
    """
    half = a_m / 2.0
    layer = min(half, 3.0 * b_m)
    ratio = 8.0
    h = (ratio ** (1.0 / (n_wall - 1))) ** np.arange(n_wall)
    wall = layer * np.concatenate(([0.0], np.cumsum(h) / h.sum()))
    if layer < half:
        mid = np.linspace(layer, half, max(2, n_mid) + 1)[1:]
        left = np.concatenate((wall, mid))
    else:
        left = wall
    return np.concatenate((left, a_m - left[-2::-1]))


def section_conductance_m4_Pa_s(y_m, gap_m, viscosity_Pa_s: float, *, n_z: int = 6) -> float:
    """Conductance per unit length of the section under a gap profile [m^4/(Pa s)].

    Solves ``-lap w = 1``, ``w = 0`` on the boundary of ``{0 < z < h(y)}`` with P2 triangles on
    a tensor mesh whose columns are ``y_m`` and whose ``n_z`` rows are mapped to ``z = eta
    h(y)``; ``K = int w dA / mu``. Zero if any gap is <= 0 (the section is closed).

    Parameters
    ----------
    y_m : ndarray, shape (n,) -- increasing column positions across the channel, first and
        last on the side walls [m]
    gap_m : ndarray, shape (n,) -- gap between glass and ceiling at ``y_m`` [m]
    viscosity_Pa_s : float -- dynamic viscosity [Pa s]
    n_z : int -- element rows through the gap
    """
    y = np.asarray(y_m, float)
    h = np.asarray(gap_m, float)
    check_finite("gap_m", h, "m")
    mu = check_positive("viscosity_Pa_s", viscosity_Pa_s, "Pa s")
    if y.ndim != 1 or h.shape != y.shape or y.size < 2 or np.any(np.diff(y) <= 0):
        raise InputError("y_m must increase and gap_m must have its shape (n,), n >= 2")
    if np.any(h <= 0.0):
        return 0.0
    m = MeshTri.init_tensor(y, np.linspace(0.0, 1.0, int(n_z) + 1))
    p = m.p.copy()
    p[1] = p[1] * np.interp(p[0], y, h)
    mesh = MeshTri(p, m.t)
    basis = Basis(mesh, ElementTriP2())
    A = asm(_laplace, basis)
    f = asm(_unit, basis)
    w = solve(*condense(A, f, D=basis.get_dofs().all()))
    return float(f @ w) / mu


@BilinearForm
def _laplace(u, v, w):
    return dot(grad(u), grad(v))


@LinearForm
def _unit(v, w):
    return v


# ------------------------------------------------------------------------------ ceiling
@dataclass(frozen=True, eq=False)
class CeilingModel:
    """Gap under the ceiling, linear in the local pressure and the body force.

    ``h(y) = b - f down_per_force(y) + p up_per_pressure(y)`` at the section columns ``y_m``.

    Attributes
    ----------
    a_m, b_m : float -- channel width and undeformed height [m]
    y_m : ndarray, shape (n,) -- section columns, 0 ... a [m]
    down_per_force_m4_N : ndarray, shape (n,) -- ceiling deflection towards the glass per unit
        body force [m / (N/m^3)]
    up_per_pressure_m_Pa : ndarray, shape (n,) -- ceiling uplift per unit liquid gauge
        pressure [m/Pa]
    source : str -- "fem" or "clamped plate"
    """
    a_m: float
    b_m: float
    y_m: np.ndarray
    down_per_force_m4_N: np.ndarray
    up_per_pressure_m_Pa: np.ndarray
    source: str = ""

    def __post_init__(self):
        if np.any(self.up_per_pressure_m_Pa < 0) or np.any(self.down_per_force_m4_N < 0):
            raise InputError("the ceiling must rise with pressure and sink with body force "
                             "(non-negative compliances)")

    @classmethod
    def clamped_plate(cls, geometry: ChannelGeometry, material: Material) -> "CeilingModel":
        """Ceiling as a plate strip clamped on rigid side walls (cylindrical bending).

        ``w(y) = q y^2 (a - y)^2 / (24 D)``, ``D = E c^3 / (12 (1 - nu^2))``, load ``q = f c``
        (body force over the thickness) or ``q = -p`` (pressure on its underside). Stiffer than
        the 3D block, whose side walls let the ceiling edges rotate (about 1.5x less
        deflection at a/c = 10, see the tests).
        """
        a, c = geometry.a_m, geometry.c_m
        D = material.E_Pa * c**3 / (12.0 * (1.0 - material.nu**2))
        y = _section_y_nodes(a, geometry.b_m)
        shape = y**2 * (a - y) ** 2 / (24.0 * D)
        return cls(a, geometry.b_m, y, c * shape, shape.copy(), "clamped plate")

    @classmethod
    def from_fem(cls, geometry: ChannelGeometry, material: Material, *, nc: int = 3,
                 aspect: float = 2.0, order: int = 2) -> "CeilingModel":
        """Compliances from two runs of the 3D channel FEM (unit body force, unit pressure).

        The mid-length ceiling profile of :func:`solve_channel` (half width, mirrored) is
        interpolated linearly onto the section columns. For the seed channel (a/c = 10) the
        centre uplift per Pa is 9.11e-8 m/Pa at ``nc = 3, aspect = 2`` (1.3 s), 9.20e-8 at
        ``nc = 4`` and 9.31e-8 at ``nc = 6`` (80 s): the default is ~2-3 % stiff.
        """
        kw = dict(nc=nc, aspect=aspect, order=order)
        rf = solve_channel(geometry, material, 1.0, **kw)
        rp = solve_channel(geometry, material, 0.0, pressure_Pa=1.0, **kw)
        a = geometry.a_m
        y = _section_y_nodes(a, geometry.b_m)
        yh = np.asarray(rf.ceiling_y_m)
        half = np.minimum(y, a - y)
        down = np.interp(half, yh, np.asarray(rf.ceiling_deflection_m))
        up = np.interp(half, yh, -np.asarray(rp.ceiling_deflection_m))
        # guard: the gap model needs non-negative compliances (the seed channel's FEM profiles
        # have the right sign everywhere, edge included: 0.2 % of the centre value there)
        return cls(a, geometry.b_m, y, np.clip(down, 0.0, None), np.clip(up, 0.0, None), "fem")

    def gap_m(self, pressure_Pa: float, body_force_N_m3: float) -> np.ndarray:
        """Linear gap ``b - f u_f + p u_p`` at ``y_m`` [m] (can be < 0: contact)."""
        return (self.b_m - body_force_N_m3 * self.down_per_force_m4_N
                + pressure_Pa * self.up_per_pressure_m_Pa)

    def min_gap_m(self, pressure_Pa: float, body_force_N_m3: float) -> float:
        """Smallest gap across the section, clipped at 0 (contact) [m]."""
        return max(0.0, float(self.gap_m(pressure_Pa, body_force_N_m3).min()))

    def conductance_m4_Pa_s(self, pressure_Pa: float, body_force_N_m3: float,
                            viscosity_Pa_s: float) -> float:
        """Conductance per unit length of the section at this pressure and body force."""
        return section_conductance_m4_Pa_s(self.y_m, self.gap_m(pressure_Pa, body_force_N_m3),
                                           viscosity_Pa_s)

    def opening_pressure_Pa(self, body_force_N_m3: float) -> float:
        """Smallest pressure at which every column of the gap is > 0 (-inf if never closed)."""
        h0 = self.gap_m(0.0, body_force_N_m3)
        up = self.up_per_pressure_m_Pa
        closed = h0 <= 0.0
        if not np.any(closed):
            # pressure (possibly negative) at which the first column would touch
            with np.errstate(divide="ignore"):
                return float(np.max(np.where(up > 0, -h0 / np.where(up > 0, up, 1), -np.inf)))
        if np.any(closed & (up <= 0)):
            return math.inf
        return float(np.max(-h0[closed] / up[closed]))


# ------------------------------------------------------------------------------ along x
@dataclass(frozen=True)
class ChannelFlowResult:
    """Pressure and gap along the channel, flow rate and pressure drop.

    x_m, pressure_Pa, min_gap_m, mean_gap_m : tuples, shape (n_x,) -- position from the inlet
    [m], gauge pressure [Pa], smallest gap across the section (>= 0, 0 = contact) [m], mean gap
    across the width [m]; flow_rate_m3_s; inlet/outlet_pressure_Pa; pressure_drop_Pa;
    rigid_flow_rate_m3_s : flow of the undeformed rectangular duct at the same pressure drop
    (series solution, no body force, no bulging); closed : the gap reaches the glass somewhere;
    closure_x_m : (first, last) position of closed sections, or () when open.
    """
    a_m: float
    b_m: float
    length_m: float
    body_force_N_m3: float
    viscosity_Pa_s: float
    flow_rate_m3_s: float
    inlet_pressure_Pa: float
    outlet_pressure_Pa: float
    pressure_drop_Pa: float
    rigid_flow_rate_m3_s: float
    min_gap_overall_m: float
    x_min_gap_m: float
    closed: bool
    closure_x_m: tuple
    x_m: tuple
    pressure_Pa: tuple
    min_gap_m: tuple
    mean_gap_m: tuple
    ceiling_source: str = ""
    liquid: str = ""

    @property
    def hydraulic_resistance_Pa_s_m3(self) -> float:
        """``pressure_drop / flow_rate`` [Pa s/m^3] (inf if nothing flows)."""
        return self.pressure_drop_Pa / self.flow_rate_m3_s if self.flow_rate_m3_s > 0 \
            else math.inf

    def to_dict(self) -> dict:
        d = asdict(self)
        r = self.hydraulic_resistance_Pa_s_m3
        d["hydraulic_resistance_Pa_s_m3"] = r if math.isfinite(r) else None
        return d


class _Conductance:
    """K(p) on [p_lo, p_hi] as a Chebyshev interpolant of FEM values, and its integral."""

    def __init__(self, ceiling, f, mu, p_lo, p_hi, n_p):
        self.p_lo, self.p_hi = p_lo, p_hi
        t = np.cos(np.pi * (np.arange(n_p) + 0.5) / n_p)      # Chebyshev points of the 1st kind
        p = p_lo + (p_hi - p_lo) * (t + 1.0) / 2.0
        K = np.array([ceiling.conductance_m4_Pa_s(pi, f, mu) for pi in p])
        self.coef = C.chebfit(t, K, n_p - 1)
        # Phi(p) = int_{p_lo}^{p} K dp' = (p_hi - p_lo)/2 int_{-1}^{t} K dt'
        self.icoef = C.chebint(self.coef, lbnd=-1.0) * (p_hi - p_lo) / 2.0

    def _t(self, p):
        return 2.0 * (np.asarray(p, float) - self.p_lo) / (self.p_hi - self.p_lo) - 1.0

    def K(self, p):
        return C.chebval(self._t(p), self.coef)

    def Phi(self, p):
        return C.chebval(self._t(p), self.icoef)

    def invert(self, phi):
        """p with Phi(p) = phi for each entry (Phi increases: K > 0 above p_lo)."""
        pd = np.linspace(self.p_lo, self.p_hi, 4001)
        Pd = self.Phi(pd)
        p = np.interp(phi, Pd, pd)
        for _ in range(3):   # Newton polish, Phi' = K; stays inside the bracket
            k = self.K(p)
            step = np.where(k > 0, (self.Phi(p) - phi) / np.where(k > 0, k, 1.0), 0.0)
            p = np.clip(p - step, self.p_lo, self.p_hi)
        return p


def solve_channel_flow(ceiling: CeilingModel, length_m: float, *, body_force_N_m3: float = 0.0,
                       flow_rate_m3_s: float | None = None, pressure_drop_Pa: float | None = None,
                       outlet_pressure_Pa: float = 0.0, liquid: Liquid = BLOOD_PLASMA,
                       n_x: int = 101, n_p: int = 24) -> ChannelFlowResult:
    """Steady flow through the channel with the ceiling deformed by pressure and body force.

    Give exactly one of ``flow_rate_m3_s`` and ``pressure_drop_Pa``.

    Parameters
    ----------
    ceiling : CeilingModel -- gap model of the cross-section
    length_m : float -- channel length d [m]
    body_force_N_m3 : float -- magnetic body force towards the glass [N/m^3]
    flow_rate_m3_s : float -- imposed volume flow rate [m^3/s]
    pressure_drop_Pa : float -- imposed inlet minus outlet pressure [Pa]
    outlet_pressure_Pa : float -- gauge pressure at the outlet [Pa] (0: open to atmosphere)
    liquid : Liquid
    n_x : int -- output stations along the channel
    n_p : int -- Chebyshev nodes of the conductance over the pressure range; K(p) is a cubic
        polynomial in the Hele-Shaw limit, so 24 nodes resolve it to round-off away from
        contact

    Returns
    -------
    ChannelFlowResult
    """
    d = check_positive("length_m", length_m, "m")
    f = check_positive("body_force_N_m3", body_force_N_m3, "N/m^3", allow_zero=True)
    p_out = float(check_finite("outlet_pressure_Pa", outlet_pressure_Pa, "Pa"))
    if (flow_rate_m3_s is None) == (pressure_drop_Pa is None):
        raise InputError("give exactly one of flow_rate_m3_s and pressure_drop_Pa")
    mu = liquid.viscosity_Pa_s
    if int(n_x) < 2 or int(n_p) < 4:
        raise InputError(f"n_x must be >= 2 and n_p >= 4, got {n_x}, {n_p}")
    x = np.linspace(0.0, d, int(n_x))
    p_open = ceiling.opening_pressure_Pa(f)
    if not math.isfinite(p_open) and p_open > 0:
        raise InputError("the ceiling touches the glass where pressure cannot lift it")
    p_lo = max(p_out, p_open)   # K = 0 below p_open: the section is shut

    if pressure_drop_Pa is not None:
        dp = check_positive("pressure_drop_Pa", pressure_drop_Pa, "Pa", allow_zero=True)
        p_in = p_out + dp
        if p_in <= p_lo or dp == 0.0:
            Q = 0.0
            p = np.full_like(x, p_in) if dp == 0.0 else np.where(x < d, p_in, p_out)
        else:
            cond = _Conductance(ceiling, f, mu, p_lo, p_in, n_p)
            Q = float(cond.Phi(p_in)) / d
            p = cond.invert(Q * (d - x))
    else:
        Q = check_positive("flow_rate_m3_s", flow_rate_m3_s, "m^3/s", allow_zero=True)
        if Q == 0.0:
            p_in, p = p_out, np.full_like(x, p_out)
        else:
            p_hi = _pressure_bracket(ceiling, f, mu, p_lo, Q * d)
            p_in = float(_Conductance(ceiling, f, mu, p_lo, p_hi, n_p).invert(Q * d))
            # again on the range actually used: the interpolant is most accurate there
            cond = _Conductance(ceiling, f, mu, p_lo, p_in * (1 + 1e-9) + 1e-12, n_p)
            p = cond.invert(Q * (d - x))
    # the outlet holds p_out; if the outlet section is shut (p_lo > p_out) the pressure jumps
    # there across the contact line
    p[-1] = p_out
    gaps = np.array([ceiling.gap_m(pi, f) for pi in p])
    closed_x = np.nonzero(gaps.min(axis=1) <= 0.0)[0]
    hmin = np.clip(gaps.min(axis=1), 0.0, None)
    hmean = np.clip(gaps, 0.0, None)
    hmean = np.trapezoid(hmean, ceiling.y_m, axis=1) / ceiling.a_m
    i_min = int(np.argmin(hmin))
    dp_total = float(p[0] - p_out) if pressure_drop_Pa is None else float(pressure_drop_Pa)
    rigid = rectangular_duct_conductance_m4_Pa_s(ceiling.a_m, ceiling.b_m, mu) * dp_total / d
    return ChannelFlowResult(
        ceiling.a_m, ceiling.b_m, d, f, mu, float(Q), float(p_out + dp_total), p_out, dp_total,
        float(rigid), float(hmin[i_min]), float(x[i_min]), bool(closed_x.size),
        (float(x[closed_x[0]]), float(x[closed_x[-1]])) if closed_x.size else (),
        tuple(map(float, x)), tuple(map(float, p)), tuple(map(float, hmin)),
        tuple(map(float, hmean)), ceiling.source, liquid.name)


def _pressure_bracket(ceiling, f, mu, p_lo, phi_target):
    """An upper bound of the inlet pressure: since K rises with p, ``Phi(p_hi) >= K(m) (p_hi -
    m)`` with ``m`` the midpoint of [p_lo, p_hi]; grow p_hi until that bound exceeds the target."""
    K0 = ceiling.conductance_m4_Pa_s(p_lo, f, mu)
    if K0 > 0:
        return p_lo + phi_target / K0
    span = max(abs(p_lo), ceiling.b_m / float(np.max(ceiling.up_per_pressure_m_Pa)) * 1e-3)
    for _ in range(200):
        mid = p_lo + span / 2
        if ceiling.conductance_m4_Pa_s(mid, f, mu) * span / 2 >= phi_target:
            return p_lo + span
        span *= 2.0
    raise InputError("no inlet pressure carries this flow rate through the closed channel")


@dataclass(frozen=True)
class FlowInterval:
    """Flow at a body force known with an interval (e.g. from a batch table).

    Each quantity is ``(at ci_low force, at mean force, at ci_high force)``: flow_rate_m3_s,
    pressure_drop_Pa, min_gap_m (the smallest gap, at the outlet). The response is monotone in
    the body force (every gap shrinks as it grows, whatever the pressure), so the interval of
    the force maps onto these end values; ``confidence`` is the force interval's.
    """
    body_force_N_m3: tuple
    flow_rate_m3_s: tuple
    pressure_drop_Pa: tuple
    min_gap_m: tuple
    confidence: float | None
    closed: tuple

    def to_dict(self) -> dict:
        return asdict(self)


def flow_with_interval(ceiling: CeilingModel, length_m: float, body_force, **operating
                       ) -> FlowInterval:
    """:func:`solve_channel_flow` at the mean and both interval ends of a body force.

    Parameters
    ----------
    ceiling : CeilingModel
    length_m : float -- channel length [m]
    body_force : Estimate-like (``mean``, ``ci_low``, ``ci_high`` [N/m^3], optional
        ``confidence``), e.g. :func:`homogenize.tables.batch.body_force_from_table`'s result, or a
        (low, mean, high) tuple [N/m^3]
    **operating : flow_rate_m3_s or pressure_drop_Pa, and the other keywords of
        :func:`solve_channel_flow`
    """
    if hasattr(body_force, "mean"):
        fs = (body_force.ci_low, body_force.mean, body_force.ci_high)
        conf = getattr(body_force, "confidence", None)
    else:
        fs, conf = tuple(body_force), None
        if len(fs) != 3:
            raise InputError("body_force must be an Estimate or a (low, mean, high) tuple")
    fs = tuple(max(0.0, float(v)) for v in fs)   # a force interval reaching below 0: clip
    rs = [solve_channel_flow(ceiling, length_m, body_force_N_m3=v, **operating) for v in fs]
    return FlowInterval(fs, tuple(r.flow_rate_m3_s for r in rs),
                        tuple(r.pressure_drop_Pa for r in rs),
                        tuple(r.min_gap_overall_m for r in rs), conf,
                        tuple(r.closed for r in rs))


# ------------------------------------------------------------------------------ device
@dataclass(frozen=True)
class TargetGapResult:
    """Body force (and field) that brings the smallest gap to ``target_gap_m``.

    body_force_N_m3 : needed body force [N/m^3]; field : control value giving it (None if no
    ``body_force_of_field`` was given), in ``field_unit``; x_target_m : where along the channel
    the smallest gap is reached [m] (the outlet, see the module docstring); flow : the coupled
    flow at that body force.
    """
    target_gap_m: float
    body_force_N_m3: float
    field: float | None
    field_unit: str
    x_target_m: float
    flow: ChannelFlowResult

    def to_dict(self) -> dict:
        d = asdict(self)
        d["flow"] = self.flow.to_dict()
        return d


def field_for_target_gap(ceiling: CeilingModel, length_m: float, target_gap_m: float, *,
                         flow_rate_m3_s: float | None = None,
                         pressure_drop_Pa: float | None = None, outlet_pressure_Pa: float = 0.0,
                         liquid: Liquid = BLOOD_PLASMA,
                         body_force_range_N_m3: tuple[float, float] = (0.0, 1e8),
                         body_force_of_field: Callable[[float], float] | None = None,
                         field_range: tuple[float, float] | None = None,
                         field_unit: str = "T", n_x: int = 101) -> TargetGapResult:
    """The body force (and the field) that brings the smallest gap to ``target_gap_m``.

    The liquid pressure is lowest at the outlet and only lifts the ceiling, so the smallest gap
    of the coupled problem sits at the outlet section, where ``p = outlet_pressure_Pa``: the
    needed body force solves ``min_y h(y; p_out, f) = target`` (decreasing in ``f``). The
    coupled flow at that force is then solved to give the pressure and gap along the channel
    (and checked to place its smallest gap at the target).

    Parameters
    ----------
    ceiling : CeilingModel
    length_m : float -- channel length [m]
    target_gap_m : float -- wanted smallest gap [m], e.g. 10e-6 to 20e-6 to hold back cells
    flow_rate_m3_s, pressure_drop_Pa : float -- exactly one: the operating point
    outlet_pressure_Pa : float -- gauge pressure at the outlet [Pa]
    liquid : Liquid
    body_force_range_N_m3 : (lo, hi) -- admissible body forces [N/m^3] (without a field map)
    body_force_of_field : callable(field) -> body force [N/m^3], optional -- e.g. from a batch
        table (:func:`homogenize.tables.batch.body_force_from_table`) or the seed formula; the field
        is then searched in ``field_range`` (in ``field_unit``: B in T, a gradient in T/m, ...)
    field_range : (lo, hi) -- range of the control value; required with body_force_of_field
    field_unit : str -- unit of the control value, for messages and the result
    n_x : int -- output stations along the channel

    Raises
    ------
    InputError -- the target cannot be reached in the given range (one message with the
        force needed and the range available)
    """
    t = check_positive("target_gap_m", target_gap_m, "m")
    p_out = float(check_finite("outlet_pressure_Pa", outlet_pressure_Pa, "Pa"))
    if (flow_rate_m3_s is None) == (pressure_drop_Pa is None):
        raise InputError("give exactly one of flow_rate_m3_s and pressure_drop_Pa")

    def outlet_gap(fb):
        return float(ceiling.gap_m(p_out, fb).min())

    g0 = outlet_gap(0.0)
    if t >= g0:
        raise InputError(f"target_gap_m = {t:g} m is not below the gap without body force "
                         f"({g0:g} m at the outlet): a body force only closes the channel")
    slope = float(ceiling.down_per_force_m4_N.max())
    if slope <= 0:
        raise InputError("the ceiling model does not respond to the body force")
    # the outlet gap is concave and decreasing in f; at f_hi the most compliant column is
    # at or below the target whatever its gap without force
    f_hi = (float(ceiling.gap_m(p_out, 0.0).max()) - t) / slope
    f_need = brentq(lambda fb: outlet_gap(fb) - t, 0.0, f_hi, xtol=1e-14 * max(f_hi, 1.0),
                    rtol=1e-12)
    field_value = None
    if body_force_of_field is None:
        lo, hi = body_force_range_N_m3
        if not lo <= f_need <= hi:
            raise InputError(f"target gap {t:g} m needs a body force of {f_need:.4g} N/m^3, "
                             f"outside body_force_range_N_m3 [{lo:g}, {hi:g}] N/m^3")
    else:
        if field_range is None:
            raise InputError("field_range is required with body_force_of_field")
        field_value = _invert_field(body_force_of_field, f_need, field_range, field_unit, t)
    flow = solve_channel_flow(ceiling, length_m, body_force_N_m3=f_need,
                              flow_rate_m3_s=flow_rate_m3_s, pressure_drop_Pa=pressure_drop_Pa,
                              outlet_pressure_Pa=p_out, liquid=liquid, n_x=n_x)
    return TargetGapResult(t, float(f_need), field_value, field_unit, flow.x_min_gap_m, flow)


@dataclass(frozen=True)
class ClosureResult:
    """Where and at which body force the ceiling shuts the channel (:func:`closure`).

    body_force_N_m3 : the smallest body force with no flow at ``inlet_pressure_Pa`` [N/m^3]
    body_force_first_contact_N_m3 : the ceiling first touches the glass at the outlet
        (``p = p_out``) [N/m^3]; between the two the liquid lifts the ceiling off the contact
        line and flows
    y_contact_m, x_contact_m : where the contact starts: the most compliant column of the
        section (the centre line for a symmetric ceiling) at the outlet ``x = d`` [m]
    lift_off_Pa_per_N_m3 : how much more inlet pressure a closed channel holds per N/m^3 of
        extra body force [Pa / (N/m^3)] (the lift-off pressure is linear in f)
    field, field_unit : the control value giving ``body_force_N_m3`` (None without a map)
    """
    inlet_pressure_Pa: float
    outlet_pressure_Pa: float
    body_force_N_m3: float
    body_force_first_contact_N_m3: float
    y_contact_m: float
    x_contact_m: float
    lift_off_Pa_per_N_m3: float
    field: float | None = None
    field_unit: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def closure(ceiling: CeilingModel, length_m: float, *, pressure_drop_Pa: float = 0.0,
            outlet_pressure_Pa: float = 0.0,
            body_force_of_field: Callable[[float], float] | None = None,
            field_range: tuple[float, float] | None = None,
            field_unit: str = "T") -> ClosureResult:
    """The body force (and field) at which the channel shuts against ``pressure_drop_Pa``.

    In the gap model ``h_j = b - f d_j + p u_j`` (columns j) a section conducts nothing once a
    column touches the glass, and it re-opens when the local pressure exceeds its lift-off
    pressure ``max_j (f d_j - b) / u_j`` (:meth:`CeilingModel.opening_pressure_Pa`). With no
    flow the pressure upstream of a contact is the inlet's, so the channel holds
    ``p_in = p_out + pressure_drop_Pa`` exactly when some column is shut at ``p_in``::

        f_close(p_in) = min_j (b + p_in u_j) / d_j

    (the first contact, ``pressure_drop_Pa = 0``, is ``f_close(p_out)``, at the outlet where the
    pressure is lowest). For a clamped plate strip ``d_j = c u_j`` and this is
    ``384 D b / (c a^4) + p_in / c``: the body force per area ``f c`` must carry the liquid's
    pressure and bend the plate by ``b`` at its centre. With an imposed flow rate (a syringe
    pump) the channel never shuts in this model: the inlet pressure rises to the lift-off
    pressure, ``lift_off_Pa_per_N_m3`` per N/m^3.
    """
    check_positive("length_m", length_m, "m")
    dp = check_positive("pressure_drop_Pa", pressure_drop_Pa, "Pa", allow_zero=True)
    p_out = float(check_finite("outlet_pressure_Pa", outlet_pressure_Pa, "Pa"))
    d = np.asarray(ceiling.down_per_force_m4_N, dtype=float)
    u = np.asarray(ceiling.up_per_pressure_m_Pa, dtype=float)
    ok = d > 0
    if not np.any(ok):
        raise InputError("the ceiling model does not respond to the body force")

    def f_close(p):
        h = ceiling.b_m + p * u[ok]
        if np.any(h <= 0):
            raise InputError(f"the outlet pressure {p:g} Pa already shuts the channel")
        r = h / d[ok]
        return float(r.min()), int(np.flatnonzero(ok)[np.argmin(r)])

    f_first, j = f_close(p_out)
    f_need, k = f_close(p_out + dp)
    field_value = None
    if body_force_of_field is not None:
        if field_range is None:
            raise InputError("field_range is required with body_force_of_field")
        field_value = _invert_field(body_force_of_field, f_need, field_range, field_unit, 0.0)
    return ClosureResult(p_out + dp, p_out, f_need, f_first, float(ceiling.y_m[k]),
                         float(length_m), float(d[k] / u[k]) if u[k] > 0 else math.inf,
                         field_value, field_unit if field_value is not None else "")


def _invert_field(force_of, f_need, field_range, unit, target):
    """First control value in ``field_range`` (from its low end) where the force reaches
    ``f_need``; one InputError naming the force range available otherwise."""
    lo, hi = (float(v) for v in field_range)
    grid = np.linspace(lo, hi, 129)
    fs = np.array([float(force_of(v)) for v in grid])
    check_finite("body_force_of_field(field)", fs, "N/m^3")
    r = fs - f_need
    hit = np.nonzero(r == 0.0)[0]
    if hit.size:
        return float(grid[hit[0]])
    sign = np.nonzero(np.sign(r[:-1]) != np.sign(r[1:]))[0]
    if not sign.size:
        raise InputError(f"target gap {target:g} m needs a body force of {f_need:.4g} N/m^3; "
                         f"the field range [{lo:g}, {hi:g}] {unit} gives only "
                         f"[{fs.min():.4g}, {fs.max():.4g}] N/m^3")
    i = int(sign[0])
    return float(brentq(lambda v: float(force_of(v)) - f_need, grid[i], grid[i + 1],
                        xtol=1e-12 * max(abs(hi), abs(lo), 1e-300)))


def plot_channel_flow(result: ChannelFlowResult, *, target_gap_m: float | None = None):
    """Gap [um] and pressure [kPa] along the channel [mm]; returns a matplotlib Figure.

    Uses ``matplotlib.figure.Figure`` directly (no pyplot state, no backend change); save it
    with ``fig.savefig(path)``.
    """
    from matplotlib.figure import Figure
    x = np.asarray(result.x_m) * 1e3
    fig = Figure(figsize=(6.0, 5.0), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(x, np.asarray(result.min_gap_m) * 1e6, label="smallest gap (channel centre)")
    ax1.plot(x, np.asarray(result.mean_gap_m) * 1e6, "--", label="mean gap across the width")
    ax1.axhline(result.b_m * 1e6, color="0.6", lw=0.8, label="undeformed height b")
    if target_gap_m is not None:
        ax1.axhline(target_gap_m * 1e6, color="C3", ls=":", label="target gap")
    if result.closed:
        ax1.axvspan(result.closure_x_m[0] * 1e3, result.closure_x_m[1] * 1e3, color="C3",
                    alpha=0.2, label="closed (contact)")
    ax1.set_ylabel("gap [um]")
    ax1.set_ylim(bottom=0.0)
    ax1.legend(fontsize="small")
    ax2.plot(x, np.asarray(result.pressure_Pa) * 1e-3, color="C2")
    ax2.set_ylabel("pressure [kPa]")
    ax2.set_xlabel("x along the channel [mm]")
    ax1.set_title(f"Q = {result.flow_rate_m3_s * 6e10:.3g} uL/min, "
                  f"dp = {result.pressure_drop_Pa * 1e-3:.3g} kPa, "
                  f"f = {result.body_force_N_m3 * 1e-3:.3g} kN/m^3", fontsize="medium")
    return fig
