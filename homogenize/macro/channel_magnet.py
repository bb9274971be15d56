"""The channel ceiling under a real magnet, with the field on the DEFORMED ceiling: its
deflection against the magnet gap, the gap at which it shuts the channel (contact) or snaps
down (pull-in), and the gap at which the shut channel holds a pressure drop.

The channel of :mod:`homogenize.macro.channel` (width ``a``, height ``b``, ceiling thickness
``c``, length ``d``; frame: ``x`` along the channel, ``y`` across it from one side wall,
``z`` up from the glass, the channel floor at ``z = 0``) lies on glass; a permanent magnet
(:class:`~homogenize.macro.magnets.PermanentMagnet`, a cylinder or a cuboid, axis along ``z``)
sits under the glass with its axis at ``(x_axis, y_axis)`` (default: under the middle of the
channel, ``(d/2, a/2)``, coaxial).

The gap
-------
The user's control variable is ``gap_m``: from the magnet's TOP face to the channel floor
(the top of the glass, ``z = 0``), >= 0. It includes the glass: a magnet pressed against a
1 mm glass slide is at ``gap_m = 1e-3``. The magnet's top face is at ``z = -gap_m``
(:func:`place_channel_magnet`).

Model
-----
*Load.* As for the cantilever (:mod:`homogenize.macro.magnets`,
:func:`homogenize.macro.pullin.magnet_body_force`): ``f = M_eff(H_in) grad |B_a|`` [N/m^3]
with ``H_in + N M_eff(H_in) = |H_a|`` and ``N`` the thin-plate demagnetizing factor of the
PDMS block through its height (Aharoni's prism, :func:`micro.demag.prism_demag_factors`, of the
block ``d x (a + 2 wall) x (b + c)``: :func:`channel_demag_factor`, 0.87 for the seed's
channel), one factor for the whole block and every field direction, as for the strip. Only the
component towards the glass, ``-f_z``, loads the ceiling; the lateral components ``f_x, f_y``
(zero on the magnet's axis) are not modelled.

*Where the field is taken.* At ``n_x`` sections ``x_i`` (equally spaced, ends included), on
``n_y`` Gauss-Legendre columns ``y_k`` across the width and ``n_z`` Gauss-Legendre points
through the ceiling's thickness, each column at its DEFORMED height: the ceiling column at
``y`` occupies ``z in [b - w(y) + p u(y), b + c - w(y) + p u(y)]`` (a rigid shift of the column
by its deflection ``w`` towards the glass and its uplift by the liquid pressure ``p``; the
bending strains of the column are not followed). The force on a column is its mean over the
``n_z`` points.

*Mechanics: a consistent one-mode (Galerkin) projection of the CeilingModel.* The
:class:`~homogenize.macro.flow.CeilingModel` knows the ceiling's response to a UNIFORM body
force, ``w(y) = f d(y)``, and to a uniform pressure, ``u(y)``, at its columns (from the 3D FEM
:func:`~homogenize.macro.channel.solve_channel`, or the clamped plate). Under a magnet the
force varies across the section; the deflection of each section is taken in the shape of the
uniform-force response, ``w(y) = q phi(y)``, ``phi = d / max d`` (``q``: the deflection of the
most compliant column, the centre line). Ritz/Galerkin with that mode gives ``k q = F`` with

    F(q) = c int_0^a <f_down>(y; q) phi(y) dy,    k = c int_0^a phi dy / max d  [N/m^2]

(the same quadrature in both). ``k`` is exactly the Ritz stiffness ``a(phi, phi)`` of the
ceiling when ``phi`` is the exact uniform-load solution of a self-adjoint linear operator
(``a(w0, v) = <f0 c, v>`` for all v, with ``v = phi``). Hence:

* a UNIFORM force ``f`` (any gap dependence, no position dependence) gives ``w = f d(y)``
  exactly, to round-off, so the channel shuts exactly where :func:`homogenize.macro.flow.closure`
  says (tested);
* a force that varies across the section is weighted by ``phi``: the projection's error is
  that of one mode. Against the exact clamped plate strip under loads that vary like the field
  of a magnet across the channel the centre deflection is 0.23 % low for a parabola
  ``1 + 0.3 (1 - (2 y / a - 1)^2)`` and exact for a ramp ``1 + 0.3 (2 y / a - 1)`` (its
  antisymmetric part loads no symmetric mode and does not deflect the centre, in both; tested).
* the FEM's compliance includes the force on the side walls and the block (the uniform force
  acts on the whole block); here the ceiling's own force is projected and the walls' share is
  carried in proportion. For the seed channel the one-mode projection of the liquid PRESSURE
  (a load on the underside only, a different distribution than the body force) gives a centre
  uplift 0.15 % above the FEM's own (tested): the size of that approximation.

*Along the channel.* The deflection is ``w(x, y) = q(x) phi(y)`` (Kantorovich). Two models:

* coupled (``plate_rigidity_N_m = D = E c^3 / (12 (1 - nu^2))`` given; the CLI's): the
  ceiling also bends along ``x`` as a plate. Putting ``w = q phi`` into the plate's energy and
  integrating over ``y`` (``phi phi'`` vanishing at the side walls, ``int phi phi'' = -I1``)
  gives, up to a term at the channel's ends,

      U = int_0^d [ D I0 q''^2 / 2 + D I1 q'^2 + k q^2 / 2 ] dx - int_0^d F q dx,
      I0 = int phi^2 dy,  I1 = int phi'^2 dy

  with the section stiffness ``k`` of the CeilingModel (the FEM's, not the plate's ``D int
  phi''^2``) and ``I0, I1`` from its shape. The end term (``- D nu I1 [q q']_0^d``, which would
  make the free ends of a uniformly loaded ceiling deflect more) is left out, so that a uniform
  force still gives exactly ``q = f max d`` (the uniform limit stays ``closure``'s); the real
  free ends are softer (the FEM under a uniform force: +27 % at the end faces, +2 % 2 mm
  inside, nothing beyond 3 mm; the CeilingModel is the mid-length one). Discretized on the
  ``n_x`` equally spaced sections (second and first differences, trapezoid weights ``W``; the
  free-end conditions are the discrete energy's natural ones): ``K q = W F(q, g)``, ``K``
  symmetric positive definite. Against the 3D FEM of :func:`~homogenize.macro.channel.
  solve_channel` under a force varying along the channel (tested, seed channel): the
  mid-length centre deflection is 0.7 % / 1.7 % / 1.9 % below the FEM's for ``1 + 0.3 cos(2 pi
  (x - d/2) / d)`` and Gaussians of 3 mm / 2 mm 1/e half-width, where independent sections are
  11 % / 27 % / 54 % above it.
  A ceiling whose shape has ``I1 = 0`` (a rigid piston) has no stiffness against a rotation
  along ``x`` beyond ``k``: under a force uniform along ``x`` its uniform and linear modes fold
  together (a bifurcation the path following does not cross); a bent ceiling has ``I1 > 0``.
* independent sections (``plate_rigidity_N_m = None``): each section bends on its own, as in
  the flow model of :mod:`homogenize.macro.flow`: ``n_x`` one-degree-of-freedom problems
  ``k q_i = F_i(q_i, g)``, coupled only through the gap ``g``. Exact only for a force that
  does not vary along ``x``; kept for the one-degree-of-freedom checks.

The force grows as the ceiling comes down towards the magnet (follower), so the ceiling can
lose its equilibrium before it touches the glass (snap-down).

*Contact.* A column touches the glass when its gap ``h_j = b - q phi_j + p u_j`` reaches 0 (the
CeilingModel's columns ``j``), i.e. at ``q_c(p) = min_j (b + p u_j) / phi_j``, on the most
compliant column: as :func:`~homogenize.macro.flow.closure` (with one mode the contact column
is the mode's most compliant one whatever the force's distribution across the width; a magnet
off the channel's centre line shifts the real contact towards it). Beyond the first contact the
linear ceiling model does not hold: states below the closure (or pull-in) gap are reported
as ``closed`` without numbers.

Path following
--------------
:func:`homogenize.macro.pullin.trace_branch` (pseudo arc length, the cantilever's) on the
unknowns ``q`` with the parameter ``g``, from a far gap (where the dead-load deflection is
< 10 % of ``q_c``) towards smaller gaps, with the exact Jacobian (``K - W diag(dF_i/dq_i)``,
symmetric; ``dF/dg`` from the same central differences of ``f`` along ``z``: moving the magnet
down by ``dg`` is moving the points up by ``dg``). Coupled sections are traced together;
independent ones section by section (traced together, the mirror-image sections of a centred
magnet would fold at the same gap and make the combined system a bifurcation, not a fold).
A trace stops at the first of:

* ``contact`` -- the most compliant column of a section reaches the glass on the stable
  branch (no snap);
* ``pull-in`` -- a fold of the branch (the Jacobian singular): below that gap no equilibrium
  exists near the branch; the ceiling snaps down onto the glass (snap-down);
* the smallest gap asked for, without either (``"none"``).

The channel's event is the first met as the magnet approaches (independent sections: the
section's event with the LARGEST gap): ``closure_gap_m``, with where it happens (the sections
with the largest deflection, ``x``, and the column, ``y``). For a centred cylinder that need
not be on the axis: near the face ``|grad |B||`` peaks off the axis, under the rim (the seed's
channel with the plate ceiling: at ``x = d/2 +- 2 mm``, 1.553 mm, coupled).

The liquid: with no flow the channel's pressure is ``outlet_pressure_Pa`` everywhere (the
first touch is computed there, the sweep's deflections too). With ``pressure_drop_Pa`` the
trace is repeated with ``p_in = p_out + pressure_drop_Pa`` on every section: the largest gap
at which some section is shut (touching, or snapped) at the inlet pressure is the gap that
holds the channel shut against the drop (``hold_gap_m``; as ``closure`` does for a uniform
force, the pressure upstream of a shut section being the inlet's). The coupling with a flowing
liquid (pressure varying along ``x`` while still open) is not modelled here.

Realistic case
--------------
See :data:`REALISTIC_CASE`: the seed's channel (a = 5 mm, b = 50 um, c = 0.5 mm, d = 10 mm,
PDMS 2 MPa, 0.45) with the seed's composite (soft spheres at phi = 0.0175, Ms of the seed
powder), an NdFeB cylinder 10 mm x 10 mm, B_r = 1.3 T, coaxial under the middle of the channel.
The ceiling touches the glass (no snap: the channel height b = 50 um is far below the field's
length scale, the follower correction is 2 % of the deflection) at a gap of 2.21 mm, on the
centre line at mid-length (2.23 mm with the FEM compliance at nc 4; 2.18 mm with the dead
load; 2.24 mm with independent sections; the quadrature is converged to 1e-5: 41 sections or
24 x 5 points change the fifth digit); it is shut against 100 Pa below 1.92 mm. The deflection
at 6 / 5 / 4 / 3 mm: 5.3 / 9.3 / 16.9 / 31.0 um. A snap-down before contact needs a field that
varies on the scale of b (a sub-millimetre magnet, or a much taller channel): the tests show
the criterion.

CLI: :mod:`homogenize.cli.cmd_channel_magnet` (``mapsim channel --magnet ... --close`` /
``--gap-sweep-m A:B:N``).

Units: SI throughout (m, Pa, T, A/m, N/m^3); names carry them.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from homogenize.macro.channel import ChannelGeometry
from homogenize.macro.flow import CeilingModel
from homogenize.macro.magnets import PermanentMagnet
from homogenize.macro.pullin import (PathFollowingError, magnet_body_force, place_magnet_xy,
                                     trace_branch)
from homogenize.macro.pullin import check_gap_sweep as _check_gaps
from micro.common.validate import ConvergenceError, InputError, check_finite, check_positive, \
    check_range
from micro.demag import prism_demag_factors
from micro.materials import PDMS

__all__ = ["channel_demag_factor", "place_channel_magnet", "check_gap_sweep", "ChannelMagnet",
           "ChannelMagnetResult", "channel_magnet_sweep", "REALISTIC_CASE",
           "FAR_DEFLECTION_FRACTION"]

#: the path starts at a gap where the dead-load deflection of every section is below this
#: fraction of the contact deflection ``q_c`` (the follower correction is small there)
FAR_DEFLECTION_FRACTION = 0.1

#: the numbers this module finds for the realistic case (module docstring): the seed's channel,
#: CeilingModel.from_fem (nc 3, P2), coupled sections (plate rigidity of the 0.5 mm PDMS
#: ceiling), 21 sections x 12 columns x 3 points, no liquid pressure unless said
REALISTIC_CASE = {
    "channel_m": {"a": 5e-3, "b": 50e-6, "c": 0.5e-3, "d": 10e-3}, "E_Pa": PDMS.E_Pa,
    "nu": PDMS.nu,
    "magnetization": "soft spheres, phi = 0.0175 (SEED.c * SEED.d), Ms of the seed powder",
    "demag_factor": 0.8724,
    "magnet": "NdFeB cylinder 10 mm x 10 mm, B_r 1.3 T, axis z, under the middle (5, 2.5) mm",
    "event": "contact",
    "closure_gap_m": 2.212e-3,                 # at x = 5 mm, y = 2.5 mm (the centre line)
    "closure_gap_m_nc4": 2.228e-3,             # the FEM compliance at nc 4 (+0.7 %)
    "closure_gap_m_dead_load": 2.175e-3,       # the field of the undeformed ceiling
    "closure_gap_m_independent_sections": 2.244e-3,
    "closure_gap_m_plate": 1.553e-3,           # the stiffer clamped-plate ceiling, x = d/2 +- 2 mm
    "hold_gap_m_100Pa": 1.923e-3,              # at x = 5 mm (nc 4: 1.937e-3)
    "deflection_m_at_gap": {6e-3: 5.28e-6, 5e-3: 9.32e-6, 4e-3: 1.687e-5, 3e-3: 3.101e-5,
                            2.5e-3: 4.204e-5},
    "uniform_force_closure_N_m3": 1.096e6,     # closure() of the same CeilingModel, for scale
}


def channel_demag_factor(geometry: ChannelGeometry) -> float:
    """Demagnetizing factor of the PDMS block through its height [-]: Aharoni's prism
    ``d x (a + 2 wall) x (b + c)``, ``N_z`` (a thin plate: close to 1)."""
    if not isinstance(geometry, ChannelGeometry):
        raise InputError(f"geometry must be a ChannelGeometry, got {type(geometry).__name__}")
    g = geometry
    return float(prism_demag_factors(g.d_m, g.a_m + 2.0 * g.wall, g.b_m + g.c_m)[2])


def _check_magnet(magnet):
    if not isinstance(magnet, PermanentMagnet):
        raise InputError(f"magnet must be a PermanentMagnet (cuboid or cylinder), got "
                         f"{type(magnet).__name__}")
    if abs(abs(magnet.axis[2]) - 1.0) > 1e-12:
        raise InputError(f"magnet: its axis must be along z (a flat top face under the glass), "
                         f"got axis={magnet.axis}")


def place_channel_magnet(magnet: PermanentMagnet, geometry: ChannelGeometry, gap_m: float, *,
                         x_axis_m: float | None = None,
                         y_axis_m: float | None = None) -> PermanentMagnet:
    """The magnet with its axis at ``(x_axis_m, y_axis_m)`` (default: the middle of the
    channel, ``(d/2, a/2)``) and its top face ``gap_m`` below the channel floor (``z = -gap_m``).

    ``gap_m`` [m], >= 0: from the magnet's top face to the channel floor (the top of the glass;
    the glass thickness is part of it). A negative gap would put the magnet into the glass
    and the channel: refused.
    """
    _check_magnet(magnet)
    g = float(check_finite("gap_m", gap_m, "m"))
    if g < 0:
        raise InputError(f"gap_m = {g:g} m < 0 puts the magnet into the glass and the channel "
                         f"(its top face above the channel floor z = 0); gaps must be >= 0 m")
    x = geometry.d_m / 2 if x_axis_m is None else float(check_finite("x_axis_m", x_axis_m, "m"))
    y = geometry.a_m / 2 if y_axis_m is None else float(check_finite("y_axis_m", y_axis_m, "m"))
    return place_magnet_xy(dataclasses.replace(magnet, position_m=(x, y, 0.0)), g)


def check_gap_sweep(gap_sweep_m) -> np.ndarray:
    """The magnet gaps [m] of a sweep: finite, >= 0, strictly monotonic (InputError naming
    ``gap_sweep_m`` otherwise; :func:`homogenize.macro.pullin.check_gap_sweep`)."""
    return _check_gaps(gap_sweep_m, below_zero="puts the magnet into the glass and the channel; "
                                               "gaps must be >= 0 m (magnet face to channel "
                                               "floor)", round_trip_hint="")


class ChannelMagnet:
    """The ceiling's one-mode sections under a magnet (module docstring).

    Parameters
    ----------
    geometry : ChannelGeometry -- a, b, c, d [m]
    ceiling : CeilingModel -- compliances of the section (``from_fem`` or ``clamped_plate``)
    magnet : PermanentMagnet -- axis along z; its ``position_m`` x and y place its axis in the
        channel frame (its z is set by the gap); None with ``body_force``
    M_of_H : callable -- ``M_eff(H)`` [A/m] of the composite (e.g.
        :func:`homogenize.macro.effective.magnetization_from_table`)
    demag_factor : float in [0, 1] or None -- None: :func:`channel_demag_factor`
    n_x, n_y, n_z : sections along the channel (ends included); Gauss-Legendre columns across
        the width; Gauss-Legendre points through the ceiling's thickness
    body_force : callable ``(points_m (P, 3), gap_m) -> (f_down (P,), df_down_dz (P,))``
        [N/m^3, N/m^4], optional -- replaces the magnet (tests, other sources): the force
        towards the glass at the points and its derivative along z
    gap_scale_m : float -- length scale of the gap for the continuation (default: the magnet's
        smallest dimension, or ``d`` with ``body_force``)
    self_weight_N_m3 : float >= 0 -- a uniform extra force towards the glass, ``rho g``
        [N/m^3] (uniform: exact in the one-mode projection)
    plate_rigidity_N_m : float or None -- the ceiling's plate rigidity ``D = E c^3 / (12 (1 -
        nu^2))`` [N m]: the sections are coupled by the ceiling's bending along the channel
        (module docstring, "Along the channel"); None: independent sections
    """

    def __init__(self, geometry: ChannelGeometry, ceiling: CeilingModel,
                 magnet: PermanentMagnet | None, M_of_H=None, *,
                 demag_factor: float | None = None, n_x: int = 21, n_y: int = 12,
                 n_z: int = 3, body_force: Callable | None = None,
                 gap_scale_m: float | None = None, self_weight_N_m3: float = 0.0,
                 plate_rigidity_N_m: float | None = None):
        if not isinstance(geometry, ChannelGeometry):
            raise InputError(f"geometry must be a ChannelGeometry, got "
                             f"{type(geometry).__name__}")
        if not isinstance(ceiling, CeilingModel):
            raise InputError(f"ceiling must be a CeilingModel, got {type(ceiling).__name__}")
        a, b, c, d = geometry.a_m, geometry.b_m, geometry.c_m, geometry.d_m
        if not (math.isclose(ceiling.a_m, a, rel_tol=1e-9)
                and math.isclose(ceiling.b_m, b, rel_tol=1e-9)):
            raise InputError(f"ceiling: its channel ({ceiling.a_m:g} x {ceiling.b_m:g} m) is not "
                             f"the geometry's ({a:g} x {b:g} m)")
        for name, v, lo in (("n_x", n_x, 1), ("n_y", n_y, 2), ("n_z", n_z, 1)):
            if not float(v).is_integer() or int(v) < lo:
                raise InputError(f"{name} must be an integer >= {lo}, got {v!r}")
        if body_force is None:
            _check_magnet(magnet)
            if not callable(M_of_H):
                raise InputError("M_of_H must be a callable M(H) [A/m]")
        elif not callable(body_force):
            raise InputError("body_force must be a callable (points_m, gap_m) -> (f, df/dz)")
        self.geometry, self.ceiling, self.magnet, self.M_of_H = geometry, ceiling, magnet, M_of_H
        self.body_force = body_force
        self.self_weight = check_positive("self_weight_N_m3", self_weight_N_m3, "N/m^3",
                                          allow_zero=True)
        self.demag = (channel_demag_factor(geometry) if demag_factor is None
                      else check_range("demag_factor", demag_factor, 0.0, 1.0, ""))
        self.a, self.b, self.c, self.d = a, b, c, d
        self.x_m = np.linspace(0.0, d, int(n_x)) if int(n_x) > 1 else np.array([d / 2])
        gy, wy = np.polynomial.legendre.leggauss(int(n_y))
        self.y_q, self.w_y = 0.5 * a * (1 + gy), 0.5 * a * wy
        gz, wz = np.polynomial.legendre.leggauss(int(n_z))
        self.zeta, self.w_z = 0.5 * c * (1 + gz), 0.5 * wz
        down = np.asarray(ceiling.down_per_force_m4_N, float)
        up = np.asarray(ceiling.up_per_pressure_m_Pa, float)
        self.d_max = float(down.max())
        if self.d_max <= 0:
            raise InputError("ceiling: the ceiling model does not respond to the body force")
        self.y_col = np.asarray(ceiling.y_m, float)
        self.phi_col, self.up_col = down / self.d_max, up
        self.phi_q = np.interp(self.y_q, self.y_col, self.phi_col)
        self.up_q = np.interp(self.y_q, self.y_col, up)
        self.wphi = c * self.w_y * self.phi_q              # generalized-force weights [m^2]
        self.k = float(np.sum(self.wphi)) / self.d_max    # [N/m^2]
        if gap_scale_m is not None:
            self.gap_scale = check_positive("gap_scale_m", gap_scale_m, "m")
        else:
            self.gap_scale = magnet.length_scale_m if body_force is None else d
        self.step = 1e-3 * min(c, self.gap_scale)
        self.evaluations = 0
        self.coupled = plate_rigidity_N_m is not None
        n = self.n_x
        self.W = np.full(n, d / max(n - 1, 1))                      # trapezoid weights [m]
        if n > 1:
            self.W[[0, -1]] *= 0.5
        self.K = self.k * np.diag(self.W)
        if self.coupled:
            D = check_positive("plate_rigidity_N_m", plate_rigidity_N_m, "N m")
            if n < 3:
                raise InputError(f"n_x must be >= 3 for sections coupled along the channel, "
                                 f"got {n}")
            h = d / (n - 1)
            dy = np.diff(self.y_col)
            self.I0_m = float(np.sum(0.5 * (self.phi_col[1:] ** 2 + self.phi_col[:-1] ** 2)
                                     * dy))
            self.I1_per_m = float(np.sum(np.diff(self.phi_col) ** 2 / dy))
            S = (np.eye(n, k=0)[:-2] - 2 * np.eye(n, k=1)[:-2] + np.eye(n, k=2)[:-2]) / h ** 2
            Dm = (np.eye(n, k=1)[:-1] - np.eye(n)[:-1]) / h
            self.K = (self.K + D * self.I0_m * h * S.T @ S
                      + 2.0 * D * self.I1_per_m * h * Dm.T @ Dm)

    # ------------------------------------------------------------------ geometry and loads
    @property
    def n_x(self) -> int:
        return self.x_m.size

    def magnet_at(self, gap_m: float) -> PermanentMagnet:
        """The magnet with its top face ``gap_m`` below the channel floor."""
        return place_magnet_xy(self.magnet, gap_m)

    def points_m(self, q_m, pressure_Pa: float = 0.0, sections=None) -> np.ndarray:
        """Evaluation points of the deformed ceiling, shape (n_s, n_y, n_z, 3) [m]: section
        ``i`` (all, or the indices ``sections``) deflected by ``q_i phi(y)`` and lifted by
        ``p u(y)``."""
        x = self.x_m if sections is None else self.x_m[np.atleast_1d(sections)]
        q = np.broadcast_to(np.asarray(q_m, float), (x.size,))
        z = (self.b + self.zeta[None, None, :] - q[:, None, None] * self.phi_q[None, :, None]
             + pressure_Pa * self.up_q[None, :, None])
        pts = np.empty(z.shape + (3,))
        pts[..., 0] = x[:, None, None]
        pts[..., 1] = self.y_q[None, :, None]
        pts[..., 2] = z
        return pts

    def force_down(self, points_m, gap_m: float):
        """``(f_down (P,), d f_down / dz (P,))`` at points (P, 3) [N/m^3, N/m^4]: the force
        towards the glass, ``-f_z``, of the magnet at ``gap_m``, and its z derivative."""
        p = np.asarray(points_m, float).reshape(-1, 3)
        self.evaluations += 1
        if self.body_force is not None:
            f, dfdz = self.body_force(p, float(gap_m))
            return np.asarray(f, float).reshape(-1), np.asarray(dfdz, float).reshape(-1)
        f, D = magnet_body_force(self.magnet_at(gap_m), self.M_of_H, self.demag, p, self.step,
                                 axes=(2,))
        return -f[:, 2], -D[:, 2, 0]

    def generalized_force(self, q_m, gap_m: float, pressure_Pa: float = 0.0, *,
                          follower: bool = True, sections=None):
        """``(F, dF/dq, dF/dg)`` per section (all, or the indices ``sections``), shape (n_s,)
        each [N/m, N/m^2, N/m^2].

        ``F_i = c sum_k w_k phi_k <f_down>(x_i, y_k)`` with the field at the deflected columns
        (``follower``) or at the undeformed ceiling (``follower=False``: the dead load, the
        pressure's uplift left out too; then ``dF/dq = 0``)."""
        pts = self.points_m(q_m if follower else 0.0, pressure_Pa if follower else 0.0,
                            sections)
        f, dfdz = self.force_down(pts.reshape(-1, 3), gap_m)
        shape = pts.shape[:3]
        fbar = f.reshape(shape) @ self.w_z                 # (n_x, n_y) column means
        dbar = dfdz.reshape(shape) @ self.w_z
        F = (fbar + self.self_weight) @ self.wphi
        dF_dq = -(dbar * self.phi_q) @ self.wphi if follower else np.zeros(F.size)
        dF_dg = dbar @ self.wphi                           # magnet down = points up
        return F, dF_dq, dF_dg

    def residual(self, q_m, gap_m: float, pressure_Pa: float = 0.0, sections=None):
        """Independent sections: ``R = k q - F``, ``dR/dq`` (n_s, n_s) (diagonal), ``dR/dg``
        (n_s,). Coupled (all sections): ``R = K q - W F`` with the trapezoid weights ``W``
        (the discrete energy's gradient), ``dR/dq = K - W diag(dF/dq)`` (symmetric),
        ``dR/dg = -W dF/dg``."""
        q = np.asarray(q_m, float)
        F, Fq, Fg = self.generalized_force(q, gap_m, pressure_Pa, sections=sections)
        if self.coupled:
            return self.K @ q - self.W * F, self.K - np.diag(self.W * Fq), -self.W * Fg
        return self.k * q - F, np.diag(self.k - Fq), -Fg

    def dead_load_deflection_m(self, gap_m: float, sections=None) -> np.ndarray:
        """Section deflections ``q_i`` [m] with the field of the UNDEFORMED ceiling."""
        if self.coupled:
            F = self.generalized_force(0.0, gap_m, follower=False)[0]
            q = np.linalg.solve(self.K, self.W * F)
            return q if sections is None else q[np.atleast_1d(sections)]
        return self.generalized_force(0.0, gap_m, follower=False, sections=sections)[0] / self.k

    def contact_deflection_m(self, pressure_Pa: float = 0.0):
        """``(q_c, j)``: the deflection ``q`` at which the first column (index ``j`` of the
        CeilingModel's ``y_m``) touches the glass at pressure ``p`` [m]."""
        ok = self.phi_col > 0
        h = self.b + pressure_Pa * self.up_col[ok]
        if np.any(h <= 0):
            raise InputError(f"the pressure {pressure_Pa:g} Pa already shuts the channel")
        r = h / self.phi_col[ok]
        j = int(np.flatnonzero(ok)[np.argmin(r)])
        return float(r.min()), j

    def column_gaps_m(self, q_m: float, pressure_Pa: float = 0.0) -> np.ndarray:
        """Gap under the CeilingModel's columns of a section deflected by ``q`` [m]."""
        return self.b - q_m * self.phi_col + pressure_Pa * self.up_col

    # ------------------------------------------------------------------ solving
    def solve_at(self, gap_m: float, q_guess, pressure_Pa: float = 0.0, *, tol: float = 1e-11,
                 max_it: int = 40) -> np.ndarray:
        """Newton on the sections at one gap from ``q_guess`` [m] (a point near the stable
        branch); ConvergenceError with the residual history if it fails."""
        q = np.array(np.broadcast_to(np.asarray(q_guess, float), (self.n_x,)))
        scale = self.k * self.b
        hist = []
        for _ in range(max_it):
            R, J, _ = self.residual(q, gap_m, pressure_Pa)
            hist.append(float(np.max(np.abs(R / (self.W if self.coupled else 1.0)))) / scale)
            if hist[-1] <= tol:
                return q
            q = q - (np.linalg.solve(J, R) if self.coupled else R / np.diag(J))
        raise ConvergenceError(f"channel magnet: Newton did not converge at gap {gap_m:.6g} m",
                               hist)


@dataclass(frozen=True, eq=False)
class ChannelMagnetResult:
    """The ceiling against the magnet gap (:func:`channel_magnet_sweep`).

    The event as the magnet approaches, with the liquid at ``outlet_pressure_Pa``: ``event``
    "contact" (the ceiling touches the glass on the stable branch; ``closure_gap_m``),
    "pull-in" (the branch folds first: snap-down at ``closure_gap_m``) or "none" (neither down
    to the smallest gap of the sweep; ``closure_gap_m`` NaN); ``x_event_m`` the sections where
    it happens (a tuple: a centred magnet acts alike on mirror-image sections), ``y_event_m``
    the column (the most compliant); ``event_deflection_m`` the deflection ``q`` there [m];
    ``event_dead_load_deflection_m`` the dead-load answer at that gap [m];
    ``contact_deflection_m`` ``q_c`` at the outlet pressure [m].

    With ``pressure_drop_Pa`` > 0: ``hold_gap_m`` the largest gap at which the channel is shut
    at the inlet pressure (holds the drop), ``hold_event``, ``x_hold_m`` (tuple), ``y_hold_m``
    (equal to the closure's without a drop).

    Per section (``x_m``, (n_x,)): ``section_event`` and ``section_event_gap_m`` (NaN: none).
    The traced path of the section that closes first (``path_x_m``; closing, from
    ``far_gap_m``): ``path_gap_m``, ``path_deflection_m``, ``path_stable``. The sweep:
    ``sweep_gap_m`` (m,), ``sweep_max_deflection_m`` (largest over the sections, NaN when
    closed), ``sweep_min_gap_m`` (smallest gap under the ceiling, 0 when closed),
    ``sweep_x_max_m`` (that section), ``sweep_dead_load_max_deflection_m``,
    ``sweep_centre_force_N_m3`` (the force towards the glass at the deflected centre column of
    that section, thickness mean), ``sweep_state`` ("open" | "closed": at or below the closure
    / pull-in gap, contact and the snapped ceiling are not modelled), ``sweep_deflection_m``
    (m, n_x).
    """
    x_m: np.ndarray
    event: str
    closure_gap_m: float
    x_event_m: tuple
    y_event_m: float
    event_deflection_m: float
    event_dead_load_deflection_m: float
    contact_deflection_m: float
    pressure_drop_Pa: float
    outlet_pressure_Pa: float
    hold_gap_m: float
    hold_event: str
    x_hold_m: tuple
    y_hold_m: float
    far_gap_m: float
    section_event: tuple
    section_event_gap_m: np.ndarray
    path_x_m: float
    path_gap_m: np.ndarray
    path_deflection_m: np.ndarray
    path_stable: np.ndarray
    sweep_gap_m: np.ndarray
    sweep_max_deflection_m: np.ndarray
    sweep_min_gap_m: np.ndarray
    sweep_x_max_m: np.ndarray
    sweep_dead_load_max_deflection_m: np.ndarray
    sweep_centre_force_N_m3: np.ndarray
    sweep_state: np.ndarray
    sweep_deflection_m: np.ndarray
    demag_factor: float
    stiffness_N_m2: float
    n_y: int
    n_z: int
    ceiling_source: str
    evaluations: int = 0

    def to_dict(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = [None if isinstance(e, float) and not math.isfinite(e) else e
                     for e in v.ravel().tolist()] if v.ndim == 1 else \
                    [[None if not math.isfinite(e) else e for e in row] for row in v.tolist()]
            elif isinstance(v, float) and not math.isfinite(v):
                v = None
            out[f.name] = v
        return out


def _far_gap(model, g_start, q_c):
    """From ``g_start`` up (x 1.5) to a gap where the magnet's dead-load deflection is below
    ``FAR_DEFLECTION_FRACTION`` of what is left to contact after the self-weight's."""
    q_w = model.self_weight * model.d_max
    if q_w >= q_c:
        raise InputError(f"self_weight_N_m3 = {model.self_weight:g} N/m^3 alone shuts the "
                         f"channel (deflection {q_w:.4g} m >= {q_c:.4g} m)")
    g = max(float(g_start), 1e-3 * model.gap_scale)
    for _ in range(80):
        if np.max(model.dead_load_deflection_m(g)) - q_w < FAR_DEFLECTION_FRACTION * (q_c - q_w):
            return g
        g *= 1.5
    raise InputError(f"the magnet deflects the ceiling by more than "
                     f"{FAR_DEFLECTION_FRACTION:g} of the way to the glass even at a gap of "
                     f"{g:.3g} m: no far start for the path (give far_gap_m)")


def _trace_section(model, i, pressure_Pa, g_far, g_end, ds_max):
    """Trace section ``i`` from ``g_far`` down to ``g_end`` at a pressure (module docstring):
    ``(BranchTrace, event, event gap)``, event "pull-in" | "contact" | "none"."""
    q_c, _ = model.contact_deflection_m(pressure_Pa)
    sec = [i]

    def system(u, g):
        return model.residual(u, g, pressure_Pa, sections=sec)

    u0 = model.dead_load_deflection_m(g_far, sections=sec)
    tr = trace_branch(system, u0, g_far, direction=-1.0, ds=0.02, ds_max=ds_max,
                      p_min=g_end, events=[("contact", lambda u, g: 1.0 - float(u[0]) / q_c)],
                      u_scale=q_c, p_scale=model.gap_scale, r_scale=model.k * q_c,
                      xtol=1e-10, ftol=1e-10, stop_at_fold=True)
    ev = tr.event
    if ev is None:
        raise PathFollowingError(f"channel magnet: the path of the section at x = "
                                 f"{model.x_m[i]:.4g} m did not reach the smallest gap within "
                                 f"the step limit",
                                 {"gap_m": float(tr.p[-1]), "deflection_m": float(tr.u[-1, 0])})
    name = {"fold": "pull-in", "contact": "contact"}.get(ev.name, "none")
    return tr, name, float(ev.p) if name != "none" else math.nan


def _trace_coupled(model, pressure_Pa, g_far, g_end, ds_max):
    """The coupled sections traced together: ``(BranchTrace, event, event gap, i)`` with ``i``
    the section of the largest deflection at the event (-1: none)."""
    q_c, _ = model.contact_deflection_m(pressure_Pa)

    def system(u, g):
        return model.residual(u, g, pressure_Pa)

    tr = trace_branch(system, model.dead_load_deflection_m(g_far), g_far, direction=-1.0,
                      ds=0.02, ds_max=ds_max, p_min=g_end,
                      events=[("contact", lambda u, g: 1.0 - float(np.max(u)) / q_c)],
                      u_scale=q_c, p_scale=model.gap_scale,
                      r_scale=model.k * q_c * model.W.max(), xtol=1e-10, ftol=1e-10,
                      stop_at_fold=True)
    ev = tr.event
    if ev is None:
        raise PathFollowingError("channel magnet: the path did not reach the smallest gap "
                                 "within the step limit",
                                 {"gap_m": float(tr.p[-1]), "deflection_m": tr.u[-1]})
    name = {"fold": "pull-in", "contact": "contact"}.get(ev.name, "none")
    if name == "none":
        return tr, name, math.nan, -1
    return tr, name, float(ev.p), int(np.argmax(ev.u))


def _trace_all(model, pressure_Pa, g_far, g_end, ds_max):
    """Every section traced alone; the channel's event is the first as the gap closes (the
    largest event gap): ``(traces, events, gaps, i_first)`` (i_first -1: none)."""
    if model.coupled:
        tr, ev, g, i = _trace_coupled(model, pressure_Pa, g_far, g_end, ds_max)
        events, gaps = ["none"] * model.n_x, np.full(model.n_x, np.nan)
        if i >= 0:
            q = tr.event.u
            for k in np.flatnonzero(np.isclose(q, q[i], rtol=1e-7, atol=0.0)):
                events[k], gaps[k] = ev, g
        return [tr] * model.n_x, events, gaps, i
    traces, events, gaps = [], [], np.full(model.n_x, np.nan)
    for i in range(model.n_x):
        tr, ev, g = _trace_section(model, i, pressure_Pa, g_far, g_end, ds_max)
        traces.append(tr)
        events.append(ev)
        gaps[i] = g
    i_first = int(np.nanargmax(gaps)) if np.any(np.isfinite(gaps)) else -1
    return traces, events, gaps, i_first


def channel_magnet_sweep(geometry: ChannelGeometry, ceiling: CeilingModel,
                         magnet: PermanentMagnet | None, M_of_H=None, gap_sweep_m=None, *,
                         pressure_drop_Pa: float = 0.0, outlet_pressure_Pa: float = 0.0,
                         demag_factor: float | None = None, n_x: int = 21, n_y: int = 12,
                         n_z: int = 3, far_gap_m: float | None = None,
                         body_force: Callable | None = None, gap_scale_m: float | None = None,
                         self_weight_N_m3: float = 0.0, plate_rigidity_N_m: float | None = None,
                         ds_max: float = 0.1) -> ChannelMagnetResult:
    """The ceiling's deflection against the magnet gap, the closure / pull-in gap and the gap
    that holds a pressure drop (module docstring).

    Parameters
    ----------
    geometry, ceiling : the channel [m] and its CeilingModel
    magnet : PermanentMagnet -- axis along z, its x, y in the channel frame (e.g. from
        :func:`place_channel_magnet`); its z is set by the gap. None with ``body_force``
    M_of_H : callable -- ``M_eff(H)`` [A/m]
    gap_sweep_m : array_like -- magnet gaps [m] (magnet top face to channel floor), >= 0,
        strictly monotonic; the path is traced from a far gap down to the smallest of them
        (which may be 0)
    pressure_drop_Pa : float >= 0 -- the drop the shut channel must hold (``hold_gap_m``)
    outlet_pressure_Pa : float -- gauge pressure of the liquid at rest / at the outlet [Pa]
    demag_factor, n_x, n_y, n_z, body_force, gap_scale_m, self_weight_N_m3,
        plate_rigidity_N_m : see :class:`ChannelMagnet` (the last: None, the sections bend on
        their own; ``E c^3 / (12 (1 - nu^2))``, coupled along the channel)
    far_gap_m : the path's start (default: from the largest gap of the sweep up, until the
        dead-load deflection is below ``FAR_DEFLECTION_FRACTION`` of the contact deflection)
    ds_max : largest arc-length step (scaled: q / q_c and gap / gap scale)

    Returns
    -------
    ChannelMagnetResult

    Raises
    ------
    InputError -- a gap < 0 (the magnet in the glass and the channel), a sweep that is not
        monotonic, bad parameters
    PathFollowingError -- the path could not be followed (``last_converged``);
        ConvergenceError -- Newton failed at a sweep gap (with its residual history)
    """
    gaps = check_gap_sweep(gap_sweep_m)
    dp = check_positive("pressure_drop_Pa", pressure_drop_Pa, "Pa", allow_zero=True)
    p_out = float(check_finite("outlet_pressure_Pa", outlet_pressure_Pa, "Pa"))
    p_in = p_out + dp
    model = ChannelMagnet(geometry, ceiling, magnet, M_of_H, demag_factor=demag_factor,
                          n_x=n_x, n_y=n_y, n_z=n_z, body_force=body_force,
                          gap_scale_m=gap_scale_m, self_weight_N_m3=self_weight_N_m3,
                          plate_rigidity_N_m=plate_rigidity_N_m)
    q_c, _ = model.contact_deflection_m(p_out)
    model.contact_deflection_m(p_in)                     # refuses a shut channel at p_in
    g_max, g_min = float(gaps.max()), float(gaps.min())
    if far_gap_m is not None:
        g_far = check_positive("far_gap_m", far_gap_m, "m")
        if g_far < g_max:
            raise InputError(f"far_gap_m = {g_far:g} m is below the sweep's largest gap "
                             f"{g_max:g} m")
    else:
        g_far = _far_gap(model, g_max, q_c)
    traces, events, ev_gaps, i_ev = _trace_all(model, p_out, g_far, g_min, ds_max)
    _, j_ev = model.contact_deflection_m(p_out)
    event = events[i_ev] if i_ev >= 0 else "none"
    g_ev = float(ev_gaps[i_ev]) if i_ev >= 0 else math.nan
    if dp > 0:
        _, h_events, h_gaps, i_h = _trace_all(model, p_in, g_far, g_min, ds_max)
        _, j_h = model.contact_deflection_m(p_in)
        hold = h_events[i_h] if i_h >= 0 else "none"
        g_hold = float(h_gaps[i_h]) if i_h >= 0 else math.nan
    else:
        h_gaps, i_h, j_h, hold, g_hold = ev_gaps, i_ev, j_ev, event, g_ev

    def where(gaps_, i):
        # every section whose event gap ties with the first (mirror images of a centred magnet)
        if i < 0:
            return ()
        tie = np.isclose(gaps_, gaps_[i], rtol=1e-7, atol=0.0)
        return tuple(float(v) for v in model.x_m[tie])

    # the sweep: each section on the stable part of its traced branch
    branch = []
    for i, tr in enumerate(traces):
        col = i if model.coupled else 0
        stop = len(tr.p) if tr.event.name not in ("fold", "contact") else tr.event.index + 1
        o = np.argsort(tr.p[:stop])
        branch.append((tr.p[:stop][o], tr.u[:stop, col][o]))
    m = gaps.size
    q_sw = np.full((m, model.n_x), np.nan)
    dead = np.full(m, np.nan)
    f_centre = np.full(m, np.nan)
    states = np.empty(m, dtype=object)
    i_centre_y = int(np.argmax(model.phi_q))
    for n, g in enumerate(gaps):
        dead[n] = float(np.max(model.dead_load_deflection_m(g)))
        if event != "none" and g <= g_ev:
            states[n] = "closed"
            continue
        guess = np.array([np.interp(g, pb, ub) for pb, ub in branch])
        q_sw[n] = model.solve_at(g, guess, p_out)
        states[n] = "open"
        i = int(np.argmax(q_sw[n]))
        pts = model.points_m(q_sw[n], p_out)[i, i_centre_y]
        f_centre[n] = float(model.force_down(pts, g)[0] @ model.w_z)
    is_open = states == "open"
    qmax = np.full(m, np.nan)
    xmax = np.full(m, np.nan)
    min_gap = np.zeros(m)
    for n in np.flatnonzero(is_open):
        i = int(np.argmax(q_sw[n]))
        qmax[n], xmax[n] = q_sw[n, i], model.x_m[i]
        min_gap[n] = float(np.min(model.column_gaps_m(qmax[n], p_out)))
    i_path = i_ev if i_ev >= 0 else int(np.argmax(model.dead_load_deflection_m(g_far)))
    path = traces[i_path]
    col = i_path if model.coupled else 0
    ev_q = float(path.event.u[col]) if event != "none" else math.nan
    ev_dead = (float(model.dead_load_deflection_m(g_ev, sections=[i_ev])[0])
               if event != "none" else math.nan)
    return ChannelMagnetResult(
        model.x_m.copy(), event, g_ev, where(ev_gaps, i_ev),
        float(model.y_col[j_ev]) if i_ev >= 0 else math.nan, ev_q, ev_dead, q_c, dp, p_out,
        g_hold, hold, where(h_gaps, i_h), float(model.y_col[j_h]) if i_h >= 0 else math.nan,
        g_far, tuple(events), ev_gaps, float(model.x_m[i_path]), path.p.copy(),
        path.u[:, col].copy(), path.stable.copy(), gaps, qmax, min_gap, xmax, dead, f_centre,
        states.astype(str), q_sw, float(model.demag), model.k, int(n_y), int(n_z),
        ceiling.source, model.evaluations)
