"""A magnet-driven cantilever with the field on the DEFORMED strip: pull-in, contact, release.

The strip (:class:`~homogenize.macro.cantilever.Strip`, ``[0, L] x [0, w] x [0, t]``, clamped at
``x = 0``) is pulled down (along ``-z``) by a permanent magnet placed below its tip. The magnet's
force grows steeply as the strip approaches it, so the field must be taken where the strip IS
(a follower load), not where it was (the dead load of :func:`~homogenize.macro.magnets.
body_force_along_strip`); and below a critical gap no free equilibrium exists: the strip snaps
onto the magnet (pull-in), rests on it (contact), and lets go again only at a larger gap on the
way back (release; the device's hysteresis).

Model
-----
*Mechanics.* A planar, inextensible, unsheared elastica (the large-rotation Euler-Bernoulli
beam), bending stiffness ``EI`` (:func:`~homogenize.macro.closed_form.bending_stiffness_N_m2`).
The unknown is the rotation ``theta(s)`` of the cross-sections, ``s`` the arc length, the
centreline ``r(s) = (0, t/2) + int_0^s (cos theta, sin theta)`` in the ``(x, z)`` plane.
Discretization (a Ritz method on the total potential energy, so that the discrete Jacobian is
a symmetric Hessian and stability is the sign of its eigenvalues): ``theta`` piecewise linear on
``N`` equal segments, ``theta_0 = 0`` at the clamp; the bending energy ``sum EI (theta_i -
theta_{i-1})^2 / (2 h)`` is exact for it; the node positions by the trapezoidal rule of the
tangent, and the magnetic energy by the trapezoidal rule over the nodes. Both rules are second
order: the tip deflection and the pull-in gap converge as ``h^2`` (measured in the tests).

*Magnetic load.* As in :mod:`homogenize.macro.magnets`: ``f = M_eff(H_in) grad |B_a|``
[N/m^3] with ``H_in`` from the thin-body demagnetizing correction ``H_in + N M(H_in) = |H_a|``
(one factor ``N`` for the strip, as in :func:`~homogenize.macro.magnets.body_force_along_strip`;
its direction is not followed as the strip rotates). ``f`` is the gradient of ``W(|B_a|) =
int_0^{|B_a|} M_eff db``, so the load is conservative; the potential energy of the strip is
``Pi = int EI theta'^2 / 2 ds - w t <W>`` with ``<.>`` the mean over the cross-section. The
field is evaluated (magpylib, through :func:`~homogenize.macro.magnets.sample_field`) at
``n_cross x n_cross`` Gauss points of every DEFORMED cross-section (across the width and
through the rotated thickness), so both in-plane components of the force, along ``x`` and
``z``, act, with their moment about the centreline. The lateral component ``f_y`` (zero for a
magnet centred across the width) and torsion are not modelled.

*Jacobian.* Exact chain rule through the kinematics; the force's own derivative with respect
to the position, ``d f / d r`` (2 x 2 in ``x, z``), by central differences of ``f`` with the
step ``FD_HESSIAN_REL * min(t, magnet size)`` (error ~``1e-6`` relative, see
:data:`FD_HESSIAN_REL`), symmetrised (``f`` is a gradient). Newton converges with it to round-off;
the equilibria themselves do not depend on the Jacobian's accuracy. Moving the magnet down by
``dg`` is the same as moving every point up by ``dg``: the derivative with respect to the gap
is the z column of ``d f / d r``, no extra field evaluation.

*Contact.* The lowest point of the bent strip is the bottom edge of its tip, ``r(L) - (t/2)
n(L)``; its gap to the plane of the magnet's top face (``z = -g``), ``gamma = z_corner + g``,
must stay >= 0. On contact ``gamma = 0`` is enforced with a Lagrange multiplier (exact: the tip
gap is zero to the Newton tolerance, no penalty parameter), the multiplier being the contact
force [N], >= 0; the contact is frictionless (the tip may slide on the plane). The contact
surface is the whole PLANE of the face (a magnet flush in a holder plate): the strip shortens
as it bends, and with a soft strip the tip reaches the plane near or beyond the magnet's rim
(``PullInResult.tip_over_magnet`` says where; contact with the rim's edge itself is not
modelled).

*The strip lying on the face.* The same unilateral contact at the bottom edge of EVERY node,
``gamma_k = z_k - (t/2) cos theta_k + g >= 0`` (k = 1..N), with an active set: a Lagrange
multiplier ``lambda_k >= 0`` (the contact force at node k [N]) and ``gamma_k = 0`` at the nodes
in contact, ``gamma_k > 0`` and no force elsewhere (:meth:`MagnetElastica.system_lying`; the
tip-only contact above is the set ``{N}``, with the same residual and Jacobian). At a fixed gap
the set is found by a primal-dual active-set iteration (:func:`solve_lying`); along the branch
(:func:`lying_contact_branch`) a node leaves the set where its force reaches zero and joins it
where its gap reaches zero, both located by Brent's method. The contact is only at the nodes
(between them the bottom face may dip below the plane by ``~h^2`` times the curvature); with
the trapezoidal kinematics the forces of a flat-lying stretch may alternate node to node around
their mean (a distributed moment on the cross-sections), so that a node inside the stretch can
lift off (at 16 segments, 3 mm, the realistic case has nodes 13, 14 and 16 on the face); the
contact length is the arc length between the first and the last node in contact.

Path following
--------------
:func:`trace_branch` is a generic pseudo-arc-length continuation of ``R(u, p) = 0`` (tangent
predictor, Newton corrector on the hyperplane normal to the tangent, step halving on failure or
on a turn of the tangent by more than ``max_turn_deg``, growth after easy steps). A limit point
(fold) is a sign change of the parameter component of the tangent between two points; it is
then located by Brent's method along the step (each trial point corrected onto the branch), to
the Newton tolerance. Events (the tip touching the magnet, the end of the gap range) are located
the same way. Arc length, not displacement control, because the same routine must also cross
the fold of the one-degree-of-freedom spring of the tests, and because it needs no choice of a
monotone control variable. The cantilever is traced as follows:

1. the free branch from a far gap (where the strip is nearly straight, the force tiny) towards
   smaller gaps: stable until the fold, the pull-in gap ``g*``; past it the unstable branch
   comes back to larger gaps as the tip approaches the magnet, until the tip touches the plane
   of the face (``gamma = 0``);
2. the contact branch, started at the smallest gap asked for (Newton from a tip-load shape
   resting on the face, damped) and followed opening the gap until the contact force
   vanishes: the release gap ``g_r`` (or until the branch folds: a snap-off there). For the
   20 MPa strip of the tests it ends exactly where the unstable free branch touched the face
   (the two branches meet at zero contact force), and ``g_r > g*``: the hysteresis. Opening
   further, the strip returns to the small-deflection branch (``snap_back_gap_m``). For the
   soft 2 MPa strip of the realistic case the tip-only contact branch folds below the pull-in
   gap, or a second node reaches the face: then
3. the strip lying on the face (:func:`contact_release`): from deep contact at the smallest gap
   (at least ``LYING_MIN_GAP_REL`` t; a length of the strip on the face, found from the shape
   of a beam landing flat, :func:`deep_contact_start`), the distributed contact is followed
   opening the gap; where it folds the strip snaps, and the state it settles in is found by a
   gradient flow with the contact (:func:`relax_on_face`); a contact state: its stable
   segment is traced whole and followed on (``contact_jumps_m`` lists these snaps); until
   every contact force vanishes (the release gap, ``release_by`` "contact force zero") or a
   fold leaves no contact state (a snap-off, "fold of the contact branch"). These segments
   replace the tip-only branch from the smallest gap in the path and the sweep.

   When the tip-only branch from the touch point ends because a second node reaches the
   face, the strip lying on the face takes over at once (no tip-only trials from a small
   gap). The lying branch is opened up to the largest gap of the sweep (not beyond: the sweep
   never goes there; "still on the face at the largest gap" if it holds that far). A node
   that leaves the active set and must rejoin it at the same gap (or the reverse), or one
   that joins with a zero force which then turns negative, ends the contact state: a fold of
   the piecewise-smooth branch, where the strip snaps (without this the continuation ran on
   along a branch where the face pulls the strip, to 18 mm and minutes).

The state the strip lands in at pull-in (``pull_in_lands_on``): the stable segment of the
traced path that holds the pull-in gap, other than the small-deflection one; of several, the
one with the smallest tip deflection beyond the fold's (the first met moving towards the
magnet; for the CLI case below :func:`relax_on_face`'s gradient flow from the fold lands in
the same state). For a soft strip with a strong magnetization the free branch folds twice
(pull-in, then back at a larger gap) and between its touch point and the second fold a stable
free state exists, the tip beside the magnet's rim: the strip snaps into it WITHOUT
contact, touches the face later without a snap (``touch_gap_m``), lifts off there on the way
back (release gap < pull-in gap, no contradiction: it never snapped into contact) and snaps
back to the small deflection at the second fold (``snap_back_gap_m`` > pull-in gap). CLI case
(2.2496 MPa, the synthetic table's M_eff at phi 0.05, 32 segments): pull-in 13.41 mm into
the free state (tip deflection 12.16 mm, 1.42 mm above the face), touch 12.36 mm, lying on
the face below 9.35 mm, opening from deep contact a jump at 8.43 mm, lift-off 12.36 mm, snap
back 14.59 mm.

Budget: every evaluation of the strip (:meth:`MagnetElastica.system_free`, which each
system calls once) spends one unit of the sweep's :class:`EvaluationBudget`
(``max_evaluations``, default :data:`MAX_EVALUATIONS`); past it :class:`PathBudgetError`, which
no fallback swallows, naming the last converged state (``last_converged``). Each loop is also
bounded by its own steps (``max_steps``, ``max_segments``, ``max_jumps``, ``max_outer``).

The quasi-static sweep moves along stable segments and jumps, at the end of one, to the next
stable segment containing the gap (towards the magnet when closing, away when opening; on
leaving the small-deflection segment, to the landing state).
If the tip reaches the face before any fold (a weak magnet, a stiff strip), there is no snap:
pull-in gap = release gap = that gap (``snap`` False).

Units: SI (m, N, Pa, T, A/m); names carry them.

Realistic case (issue 35)
-------------------------
Strip 20 x 5 x 1 mm, E = 2 MPa (the seed's PDMS), 3 vol% iron, ``M_eff = min(0.1 H_in,
0.03 Ms_Fe)`` with the strip's demagnetizing factor across its thickness (``N_z`` = 0.77,
:func:`micro.demag.prism_demag_factors`), NdFeB cylinder 10 mm x 10 mm, ``B_r`` = 1.3 T, axis
along z, centred under the tip, no self-weight, ``n_cross`` = 3: the pull-in gap is 11.33 /
11.32 / 11.317 mm at 16 / 32 / 64 segments (second-order convergence; extrapolated 11.316 mm)
with 3.08 mm of tip deflection at the fold; the tip deflects 2 mm at a gap of 11.55 mm. The
one-mode Galerkin model gives 11.44 mm (+1.1 %). With E = 1 MPa: 12.94 mm (3.41 mm), 2 mm at
13.29 mm (one mode: 13.10 mm). The user's fixed-point estimate (snap at ~12.3 mm, 2 mm at
~12.6 mm) lies between the two moduli. With the strip lying on the face, the release gap is
12.325 / 12.253 / 12.203 mm at 16 / 32 / 64 segments (from deep contact at 3 mm, through two
snaps between contact states: the tip settles at the magnet's rim), above the pull-in gap: see
:data:`REALISTIC_CASE`.

CLI wiring
----------
For ``mapsim beam --magnet ... --gap-m G`` / ``--gap-sweep-m A:B:N`` the CLI should build the
magnet with :func:`place_magnet` (centred under the tip end by default; ``--magnet-position``'s
x and y when given) and call :func:`pullin_sweep` with ``gap_sweep_m=numpy.linspace(A, B, N)``
(a single gap: ``[G]``, which still traces the path down to ``G``), the material
(:class:`~micro.materials.ElasticMaterial`), ``M_of_H`` from the table
(:func:`~homogenize.macro.magnets.tabulated_magnetization`) and the demagnetizing factor it
already uses; print ``sweep_gap_m``/``sweep_tip_deflection_m``/``sweep_contact_force_N``/
``sweep_branch`` and ``pull_in_gap_m``/``release_gap_m`` (``PullInResult.to_dict()`` is JSON
ready), plot ``gap_m`` against ``tip_deflection_m`` with the stable/unstable/contact parts and
the two gaps marked. :class:`~micro.common.validate.InputError` -> exit 2;
:class:`PathFollowingError` (a :class:`~micro.common.validate.ConvergenceError`) -> exit 3, its
``last_converged`` dict holds the last converged state (gap, deflection, shape) to be written
and named as such.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.constants import mu_0 as MU0
from scipy.optimize import brentq, minimize_scalar

from homogenize.macro.cantilever import Strip
from homogenize.macro.closed_form import bending_stiffness_N_m2
from homogenize.macro.magnets import (PermanentMagnet, _call_M, _check_overlap, _internal_field,
                                      sample_field)
from micro.common.validate import ConvergenceError, InputError, check_finite, check_positive, \
    check_range
from micro.materials import PDMS, ElasticMaterial

__all__ = ["BranchTrace", "LimitPoint", "EventPoint", "PathFollowingError", "trace_branch",
           "place_magnet", "magnet_below", "magnet_body_force", "MagnetElastica", "PullInResult", "pullin_sweep",
           "one_mode_pullin", "OneModeResult", "FD_HESSIAN_REL", "REALISTIC_CASE",
           "LyingBranch", "ContactRelease", "solve_lying", "relax_on_face", "deep_contact_start",
           "lying_contact_branch", "contact_release", "LYING_MIN_GAP_REL", "interval_ends",
           "PathBudgetError", "EvaluationBudget", "MAX_EVALUATIONS"]

#: the smallest gap the strip lying on the face is started from, relative to the thickness:
#: at a zero gap the whole strip lies flat on the face (every node in contact, a degenerate
#: start); below it the sweep reports "unmodelled"
LYING_MIN_GAP_REL = 0.1

#: step of the central differences of the force with respect to position, relative to
#: ``min(t, smallest magnet dimension)``. The force varies on the distance ``d`` to the magnet
#: (>= ~0.1 t for the Gauss points of a strip touching it): truncation ~``(step/d)^2`` < 1e-4 and
#: cancellation ~``1e-10 d / step`` (``f`` carries ~1e-10 relative noise from
#: ``sample_field``'s own differences) < 1e-6: a Jacobian accurate to ~1e-4 at worst, plenty
#: for Newton, whose converged point does not depend on it.
FD_HESSIAN_REL = 1e-3

#: the numbers this module finds for the realistic case of issue 35 (see the module docstring):
#: free-branch folds at 16/32/64 segments, n_cross=3, extrapolated
REALISTIC_CASE = {
    "strip_m": (20e-3, 5e-3, 1e-3), "E_Pa": PDMS.E_Pa, "chi": 0.1, "phi_Fe": 0.03,
    "demag_factor": "N_z of the 20 x 5 x 1 mm prism, 0.772",
    "magnet": "NdFeB cylinder 10 mm x 10 mm, B_r 1.3 T, axis z, centred under the tip",
    "pull_in_gap_m": 11.316e-3, "pull_in_tip_deflection_m": 3.08e-3,
    "gap_for_2mm_tip_deflection_m": 11.55e-3,
    "one_mode_pull_in_gap_m": 11.44e-3,
    # the release, with the strip lying on the face (contact_release from deep contact at
    # 3 mm, n_cross 3). At 16 segments: at 3 mm nodes 13, 14 and 16 are on the face (3.75 mm of
    # the strip); opening, the nodes lift one by one to the tip alone (8.58 mm); that tip-only
    # branch, the tip over the face at x ~ 15.7 mm, folds at 10.60 mm; the strip snaps to the
    # tip resting at the magnet's rim (x ~ 15.3 mm; stable between 8.53 mm and 11.80 mm: this
    # is also the state it snaps into at the pull-in gap, found by relax_on_face from the
    # fold); at 11.80 mm it snaps to the tip just beyond the rim (x ~ 14.97 mm: the branch from
    # the touch point of the unstable free branch, stable between 11.68 mm and the release) and
    # lets go where the contact force vanishes, 12.325 mm (the touch point). At 32 and 64
    # segments the branch over the face folds at 9.01 and 9.03 mm and the rim branch holds
    # without a fold up to the release. Release gap at 16 / 32 / 64 segments: 12.325 / 12.253
    # / 12.203 mm (differences 0.072, 0.050 mm: converging, more slowly than h^2 -- the tip
    # lets go at the rim, where the field varies steeply); > the pull-in gap: the hysteresis.
    # A stable free branch with the tip hovering near the rim exists between the release and
    # 13.17 mm (snap back to the small-deflection branch at 13.17 mm, 16 segments).
    "release_gap_m": 12.203e-3,                  # at 64 segments, n_cross 3
    "release_gap_m_by_segments": {16: 12.325e-3, 32: 12.253e-3, 64: 12.203e-3},
    "E_1MPa": {"pull_in_gap_m": 12.94e-3, "pull_in_tip_deflection_m": 3.41e-3,
               "gap_for_2mm_tip_deflection_m": 13.29e-3},
}


class PathFollowingError(ConvergenceError):
    """The path could not be followed. ``last_converged``: the last converged state (a dict)."""

    def __init__(self, message, last_converged=None):
        super().__init__(message)
        self.last_converged = last_converged or {}


class PathBudgetError(PathFollowingError):
    """The evaluation budget of a path ran out (:class:`EvaluationBudget`): never caught by
    the fallbacks that try another route after a failed one, so the path ends here;
    ``last_converged`` names the last converged state."""


#: ``release_by`` when the strip lying on the face is still on it at the largest gap of the
#: sweep (no release within the sweep; ``release_gap_m`` nan)
ON_FACE_AT_END = "still on the face at the largest gap"

#: the scale of the contact force in the tip-only contact trace from the touch point, in units
#: of the magnetic pull there: the force grows ~5x along that branch, and with the pull as its
#: scale the arc length was mostly the force's (~100 steps of ds_max); x10: ~30 steps, the
#: states and events the same (each corrected by Newton, events located by Brent's method)
CONTACT_FORCE_SCALE = 10.0


#: the default evaluation budget of one :func:`pullin_sweep` (evaluations of the strip's
#: residual and Hessian, each one field evaluation of ~1.5k points: ~10-25 ms at 32
#: segments, n_cross 3): a few times what the realistic sweeps need (module docstring)
MAX_EVALUATIONS = 6000


class EvaluationBudget:
    """A count of the model's evaluations (:meth:`MagnetElastica.system_free`, which every
    system of the strip calls once) with a limit: past it :class:`PathBudgetError`. ``stage``
    names the loop running (set by the caller), ``last`` the last converged state seen
    (``(stage, u, p)``, set by :func:`trace_branch` and :func:`relax_on_face`)."""

    def __init__(self, max_evaluations):
        if not float(max_evaluations).is_integer() or int(max_evaluations) < 1:
            raise InputError(f"max_evaluations must be an integer >= 1, got "
                             f"{max_evaluations!r}")
        self.max = int(max_evaluations)
        self.n = 0
        self.stage = ""
        self.last = None

    def spend(self):
        self.n += 1
        if self.n > self.max:
            raise PathBudgetError(f"the evaluation budget ({self.max} evaluations of the strip) "
                                  f"ran out in: {self.stage or 'the path'}")

    def note(self, u, p):
        self.last = (self.stage, np.array(u, float), float(p))


# ============================================================================================
# generic pseudo-arc-length continuation

@dataclass(frozen=True, eq=False)
class LimitPoint:
    """A fold of the branch: ``u`` [unknowns], ``p`` [parameter]; ``index`` into the trace."""
    u: np.ndarray
    p: float
    index: int


@dataclass(frozen=True, eq=False)
class EventPoint:
    """Where an event function crossed zero: its ``name``, ``u``, ``p``, ``index``."""
    name: str
    u: np.ndarray
    p: float
    index: int


@dataclass(frozen=True, eq=False)
class BranchTrace:
    """A traced branch of ``R(u, p) = 0``.

    u : (n, n_u) unknowns; p : (n,) parameter; dp_ds : (n,) parameter component of the unit
    tangent (scaled variables; its sign is the direction of travel in p); stable : (n,) bool
    (a limit point counts as stable when a neighbour on the trace is: the end of its segment);
    limit_points : tuple of :class:`LimitPoint` (also inserted in the arrays);
    event : the terminal :class:`EventPoint` (the last point of the arrays) or None;
    stop_reason : "event" | "max_steps".
    """
    u: np.ndarray
    p: np.ndarray
    dp_ds: np.ndarray
    stable: np.ndarray
    limit_points: tuple
    event: EventPoint | None
    stop_reason: str


class _Scaled:
    """``z = (u / u_scale, p / p_scale)``, ``F = R / r_scale``: the continuation's variables."""

    def __init__(self, system, n_u, u_scale, p_scale, r_scale):
        self.system, self.n = system, n_u
        self.us = np.broadcast_to(np.asarray(u_scale, float), (n_u,)).copy()
        self.ps = float(p_scale)
        self.rs = np.broadcast_to(np.asarray(r_scale, float), (n_u,)).copy()

    def split(self, z):
        return z[:-1] * self.us, float(z[-1] * self.ps)

    def join(self, u, p):
        return np.concatenate([np.asarray(u, float) / self.us, [p / self.ps]])

    def eval(self, z):
        self.n_eval = getattr(self, "n_eval", 0) + 1
        u, p = self.split(z)
        R, J, Rp = self.system(u, p)
        F = np.asarray(R, float) / self.rs
        Jz = np.empty((self.n, self.n + 1))
        Jz[:, :-1] = np.asarray(J, float) * self.us[None, :] / self.rs[:, None]
        Jz[:, -1] = np.asarray(Rp, float) * self.ps / self.rs
        return F, Jz

    def raw_jacobian(self, Jz):
        return Jz[:, :-1] * self.rs[:, None] / self.us[None, :]


def _correct(sc, z_guess, tau, z_anchor, sigma, xtol, ftol, max_newton):
    """Newton on ``F(z) = 0``, ``tau . (z - z_anchor) = sigma``; None if it fails."""
    z = z_guess.copy()
    dz_norm = math.inf
    for it in range(max_newton + 1):
        try:
            F, Jz = sc.eval(z)
        except InputError as exc:         # e.g. a field beyond a magnetization table
            sc.last_refusal = str(exc)
            return None
        except (FloatingPointError, ValueError):
            return None
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(Jz))):
            return None
        if dz_norm <= xtol and np.max(np.abs(F), initial=0.0) <= ftol:
            return z, Jz, it
        if it == max_newton:
            return None
        A = np.vstack([Jz, tau])
        b = -np.concatenate([F, [tau @ (z - z_anchor) - sigma]])
        try:
            dz = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            return None
        dz_norm = float(np.max(np.abs(dz)))
        if not np.isfinite(dz_norm) or dz_norm > 0.5:
            return None                      # leaving the neighbourhood: a smaller step
        z = z + dz
    return None


def _tangent(Jz, tau_prev):
    A = np.vstack([Jz, tau_prev])
    b = np.zeros(A.shape[0])
    b[-1] = 1.0
    t = np.linalg.solve(A, b)
    return t / np.linalg.norm(t)


def _default_stability(u, p, J):
    return bool(np.all(np.linalg.eigvalsh(0.5 * (J + J.T)) > 0.0))


def trace_branch(system, u0, p0, *, direction=-1.0, ds=0.05, ds_min=1e-7, ds_max=0.2,
                 p_min=-math.inf, p_max=math.inf, events=(), u_scale=1.0, p_scale=1.0,
                 r_scale=1.0, xtol=1e-10, ftol=1e-9, max_newton=12, max_steps=2000,
                 max_turn_deg=20.0, stability=None, stop_at_fold=False,
                 budget=None, max_evaluations=None) -> BranchTrace:
    """Follow the branch of ``R(u, p) = 0`` through limit points (pseudo arc length).

    Parameters
    ----------
    system : callable ``(u, p) -> (R, J, R_p)`` -- residual (n_u,), its Jacobian dR/du
        (n_u, n_u) and dR/dp (n_u,)
    u0, p0 : start (u0 a guess, corrected by Newton at fixed p0)
    direction : initial sign of the change of p
    ds, ds_min, ds_max : arc-length steps in the scaled variables ``(u / u_scale, p / p_scale)``
    p_min, p_max : the branch ends (terminal events "p_min" / "p_max") where p leaves them
    events : sequence of ``(name, fun(u, p) -> float)``; terminal when ``fun`` goes from > 0 to
        <= 0 along the path; located by Brent's method
    u_scale, p_scale, r_scale : scales of the unknowns, the parameter, the residual rows
    xtol, ftol : Newton converged when the last update <= xtol and |R / r_scale| <= ftol
    max_turn_deg : a step whose tangent turns more than this is halved (keeps the corrector on
        the same branch near a fold)
    stability : callable ``(u, p, J) -> bool``; default: ``J`` (a Hessian) positive definite
    stop_at_fold : end the trace at the first limit point (a terminal event named "fold")
    budget : an :class:`EvaluationBudget` told each converged point (``note``), so that when
        it runs out (the system spends it) the last converged point is known; ``max_steps``
        bounds the steps (a halving is a step): past it the trace ends, stop_reason
        "max_steps"
    max_evaluations : at most this many evaluations of the system (None: no limit); past
        them :class:`PathFollowingError` (a trace that no longer progresses: steps halved
        and retried without end)

    Returns
    -------
    BranchTrace

    Raises
    ------
    PathFollowingError -- the step fell below ``ds_min``; ``last_converged`` has u and p
    """
    u0 = np.atleast_1d(np.asarray(u0, float))
    n = u0.size
    sc = _Scaled(system, n, u_scale, p_scale, r_scale)
    stab = stability or _default_stability
    cos_turn = math.cos(math.radians(max_turn_deg))
    all_events = list(events)
    if math.isfinite(p_min):
        all_events.append(("p_min", lambda u, p: p - p_min))
    if math.isfinite(p_max):
        all_events.append(("p_max", lambda u, p: p_max - p))

    e_p = np.zeros(n + 1)
    e_p[-1] = 1.0
    z0 = sc.join(u0, p0)
    res = _correct(sc, z0, e_p, z0, 0.0, xtol, ftol, 4 * max_newton)
    if res is None:
        raise PathFollowingError(f"no equilibrium found at the start, p = {p0:g}",
                                 {"u": u0, "p": p0})
    z, Jz, _ = res
    tau = _tangent(Jz, float(np.sign(direction) or -1.0) * e_p)

    def record(z, Jz, tau):
        u, p = sc.split(z)
        if budget is not None:
            budget.note(u, p)
        zs.append(z.copy())
        taus.append(tau[-1])
        stables.append(stab(u, p, sc.raw_jacobian(Jz)))

    zs, taus, stables = [], [], []
    limits = []
    record(z, Jz, tau)
    event_vals = [fun(*sc.split(z)) for _, fun in all_events]
    step = float(ds)
    for _ in range(max_steps):
        if max_evaluations is not None and sc.n_eval > max_evaluations:
            u, p = sc.split(z)
            raise PathFollowingError(f"path following stopped: {sc.n_eval} evaluations "
                                     f"(limit {max_evaluations}) reached at p = {p:.6g} with "
                                     f"{len(zs)} points", {"u": u, "p": p})
        res = _correct(sc, z + step * tau, tau, z, step, xtol, ftol, max_newton)
        tau_new = None
        if res is not None:
            z_new, J_new, its = res
            try:
                tau_new = _tangent(J_new, tau)
            except np.linalg.LinAlgError:
                tau_new = None
            if tau_new is not None and tau_new @ tau < cos_turn:
                tau_new = None
        if tau_new is None:
            step *= 0.5
            if step < ds_min:
                u, p = sc.split(z)
                why = getattr(sc, "last_refusal", None)
                raise PathFollowingError(
                    f"path following stopped: step below {ds_min:g} at p = {p:.6g}"
                    + (f"; the trial steps beyond it were refused: {why}" if why else ""),
                    {"u": u, "p": p})
            continue

        def on_step(sigma, z_a=z, tau_a=tau, z_b=z_new, h=step):
            guess = z_a + (sigma / h) * (z_b - z_a)
            r = _correct(sc, guess, tau_a, z_a, sigma, xtol, ftol, 4 * max_newton)
            if r is None:
                raise PathFollowingError(f"could not locate a point along the step at "
                                         f"p = {sc.split(z_a)[1]:.6g}",
                                         dict(zip(("u", "p"), sc.split(z_a))))
            return r

        # candidate happenings along this step, by arc length
        found = []
        new_vals = [fun(*sc.split(z_new)) for _, fun in all_events]
        for k, (name, _) in enumerate(all_events):
            if event_vals[k] > 0.0 >= new_vals[k]:
                fun = all_events[k][1]

                def ev(s, fun=fun, k=k):
                    # the step's ends by their known values (a re-corrected point at s = 0
                    # can land on the other side of an event that sits at the step's start)
                    if s <= 0.0:
                        return event_vals[k]
                    if s >= step:
                        return new_vals[k]
                    return fun(*sc.split(on_step(s)[0]))
                try:
                    sig = brentq(ev, 0.0, step, xtol=1e-13, rtol=1e-12)
                except ValueError:
                    raise PathFollowingError(f"could not locate the event {name} along the "
                                             f"step at p = {sc.split(z)[1]:.6g}",
                                             dict(zip(("u", "p"), sc.split(z)))) from None
                found.append((sig, "event", name))
        if np.sign(tau_new[-1]) != np.sign(tau[-1]) and tau[-1] != 0.0:
            def tp(s):
                if s <= 0.0:
                    return tau[-1]
                if s >= step:
                    return tau_new[-1]
                zz, JJ, _ = on_step(s)
                return _tangent(JJ, tau)[-1]
            sig = brentq(tp, 0.0, step, xtol=1e-13, rtol=1e-12)
            found.append((sig, "fold", None))
        found.sort(key=lambda x: x[0])
        for sig, kind, name in found:
            zz, JJ, _ = on_step(sig) if sig < step else (z_new, J_new, 0)
            tt = _tangent(JJ, tau)
            if kind == "fold":
                record(zz, JJ, tt)
                u, p = sc.split(zz)
                limits.append(LimitPoint(u, p, len(zs) - 1))
                if stop_at_fold:
                    ev = EventPoint("fold", u, p, len(zs) - 1)
                    return _pack(sc, zs, taus, stables, limits, ev, "event")
            else:
                record(zz, JJ, tt)
                u, p = sc.split(zz)
                ev = EventPoint(name, u, p, len(zs) - 1)
                return _pack(sc, zs, taus, stables, limits, ev, "event")
        record(z_new, J_new, tau_new)
        z, tau, event_vals = z_new, tau_new, new_vals
        if its <= 3:
            step = min(step * 1.5, ds_max)
    return _pack(sc, zs, taus, stables, limits, None, "max_steps")


def _pack(sc, zs, taus, stables, limits, event, reason):
    # a fold is where an eigenvalue of the Jacobian crosses zero: its own stability test
    # compares a round-off-sized eigenvalue with 0. It is the end of the stable part it
    # bounds, so it is stable when a neighbour is (a segment's end, e.g. the snap-back gap,
    # is then the located fold, not the step before it on one CPU and the fold on another)
    stables = list(stables)
    for lp in limits:
        k = lp.index
        stables[k] = (k > 0 and stables[k - 1]) or (k + 1 < len(stables) and stables[k + 1])
    Z = np.array(zs)
    u = Z[:, :-1] * sc.us[None, :]
    p = Z[:, -1] * sc.ps
    return BranchTrace(u, p, np.array(taus), np.array(stables, bool), tuple(limits), event,
                       reason)


# ============================================================================================
# the magnet and the strip

def _default_material(material):
    """None: the seed's PDMS (E, nu, density from :data:`micro.materials.PDMS`)."""
    if material is None:
        return ElasticMaterial(PDMS.E_Pa, PDMS.nu, PDMS.density_kg_m3)
    return material


def _check_axis_z(magnet):
    if not isinstance(magnet, PermanentMagnet):
        raise InputError(f"magnet must be a PermanentMagnet, got {type(magnet).__name__}")
    if abs(abs(magnet.axis[2]) - 1.0) > 1e-12:
        raise InputError(f"the magnet's axis must be along z (a flat top face under the tip), "
                         f"got axis={magnet.axis}")


def _half_height(magnet):
    return 0.5 * (magnet.dimensions_m[1] if magnet.shape == "cylinder"
                  else magnet.dimensions_m[2])


def magnet_below(magnet, gap_m: float):
    """``magnet`` moved along z so that its top face lies ``gap_m`` below the strip's underside
    (z = 0), at its own x and y."""
    x, y, _ = magnet.position_m
    return dataclasses.replace(magnet, position_m=(x, y, -gap_m - _half_height(magnet)))


def magnet_body_force(source, M_of_H, demag_factor: float, points_m, step_m=None,
                      axes=(0, 1, 2)):
    """The body force ``f = M(H_in) grad|B_a|`` [N/m^3] of a source at points (P, 3) [m]
    (``H_in + N M = |H_a|``), and with ``step_m`` its derivative along the coordinates ``axes``
    by central differences, ``D[:, a, k] = d f_a / d x_axes[k]`` (P, 3, len(axes)) [N/m^4]
    (None without ``step_m``). All shifted points are evaluated in one call."""
    p = np.asarray(points_m, float)
    if step_m is None:
        offs = np.zeros((1, 3))
    else:
        e = np.eye(3)[list(axes)] * step_m
        offs = np.vstack([np.zeros(3), e, -e])
    allp = (offs[:, None, :] + p[None, :, :]).reshape(-1, 3)
    B, grad = sample_field(source, allp)
    Ha = np.linalg.norm(B, axis=1) / MU0
    M = _call_M(M_of_H, _internal_field(M_of_H, Ha, demag_factor))
    f = (M[:, None] * grad).reshape(len(offs), -1, 3)
    if step_m is None:
        return f[0], None
    k = len(axes)
    D = np.stack([(f[1 + j] - f[1 + k + j]) / (2 * step_m) for j in range(k)], axis=-1)
    return f[0], D


def _over_face(magnet, x, y_lo, y_hi):
    """True where the segment ``{x} x [y_lo, y_hi]`` lies (partly) over the top face."""
    xm, ym, _ = magnet.position_m
    dy = np.maximum(0.0, np.maximum(y_lo - ym, ym - y_hi))
    dx = np.abs(np.asarray(x, float) - xm)
    if magnet.shape == "cylinder":
        return dx**2 + dy**2 <= (0.5 * magnet.dimensions_m[0]) ** 2
    return (dx <= 0.5 * magnet.dimensions_m[0]) & (dy <= 0.5 * magnet.dimensions_m[1])


def place_magnet(magnet: PermanentMagnet, strip: Strip, gap_m: float, *,
                 tip_offset_m: float = 0.0, lateral_offset_m: float = 0.0) -> PermanentMagnet:
    """The magnet with its axis at ``x = L - tip_offset_m``, ``y = w/2 + lateral_offset_m`` and
    its top face ``gap_m`` below the strip's bottom face (``z = -gap_m``).

    The gap is what a user measures: from the strip's bottom face at the tip to the magnet's
    top face [m], >= 0.
    """
    _check_axis_z(magnet)
    g = check_positive("gap_m", gap_m, "m", allow_zero=True)
    check_finite("tip_offset_m", tip_offset_m, "m")
    check_finite("lateral_offset_m", lateral_offset_m, "m")
    pos = (strip.length_m - float(tip_offset_m), 0.5 * strip.width_m + float(lateral_offset_m),
           -g - _half_height(magnet))
    return dataclasses.replace(magnet, position_m=pos)


class MagnetElastica:
    """Discrete planar elastica of the strip in the field of a magnet below it.

    Parameters
    ----------
    strip : Strip; material : ElasticMaterial (E, nu, density) or None (the seed's PDMS)
    magnet : PermanentMagnet -- axis along z; its x and y position the magnet (the z is set by
        the gap ``g`` in every call); the tip must lie over its top face
    M_of_H : callable -- ``M_eff(H)`` [A/m] (see :mod:`homogenize.macro.magnets`)
    n_segments : int -- elements along the strip, >= 2
    n_cross : int -- Gauss points per cross-section direction (width, thickness), >= 1
    demag_factor : float -- ``N`` in ``H_in + N M = |H_a|``, in [0, 1]
    gravity_m_s2 : float -- self-weight along -z (a dead load), >= 0
    follower : bool -- True: the field at the deformed cross-sections; False: at the undeformed
        ones (the dead load of :func:`~homogenize.macro.magnets.body_force_along_strip`)
    plate : bool -- plate bending stiffness ``EI / (1 - nu^2)``

    Unknowns: ``theta_1 .. theta_N`` [rad] (free), plus the contact force ``lam`` [N] (contact).
    """

    def __init__(self, strip, material, magnet, M_of_H, *, n_segments=32, n_cross=3,
                 demag_factor=0.0, gravity_m_s2=0.0, follower=True, plate=False):
        if not isinstance(strip, Strip):
            raise InputError(f"strip must be a Strip, got {type(strip).__name__}")
        material = _default_material(material)
        if not isinstance(material, ElasticMaterial):
            raise InputError(f"material must be an ElasticMaterial, got "
                             f"{type(material).__name__}")
        _check_axis_z(magnet)
        if not callable(M_of_H):
            raise InputError("M_of_H must be a callable M(H) [A/m]")
        if not float(n_segments).is_integer() or int(n_segments) < 2:
            raise InputError(f"n_segments must be an integer >= 2, got {n_segments!r}")
        if not float(n_cross).is_integer() or int(n_cross) < 1:
            raise InputError(f"n_cross must be an integer >= 1, got {n_cross!r}")
        self.demag = check_range("demag_factor", demag_factor, 0.0, 1.0, "")
        gr = check_positive("gravity_m_s2", gravity_m_s2, "m/s^2", allow_zero=True)
        self.strip, self.material, self.magnet, self.M_of_H = strip, material, magnet, M_of_H
        self.follower = bool(follower)
        L, w, t = strip.length_m, strip.width_m, strip.thickness_m
        self.L, self.w, self.t = L, w, t
        if not _over_face(magnet, L, 0.0, w):
            raise InputError(f"the strip's tip (x = {L:g} m) must lie over the magnet's top face "
                             f"(axis at x = {magnet.position_m[0]:g}, y = "
                             f"{magnet.position_m[1]:g} m): contact away from the tip is not "
                             f"modelled")
        N = int(n_segments)
        self.N = N
        self.h = L / N
        self.s = np.linspace(0.0, L, N + 1)
        self.wq = np.full(N + 1, self.h)
        self.wq[[0, -1]] = 0.5 * self.h
        C = np.zeros((N + 1, N + 1))
        for k in range(1, N + 1):
            C[k, 0] = 0.5 * self.h
            C[k, 1:k] = self.h
            C[k, k] = 0.5 * self.h
        self.C = C
        self.EI = bending_stiffness_N_m2(w, t, material.E_Pa, material.nu, plate)
        K = np.zeros((N + 1, N + 1))
        for i in range(N):
            K[i:i + 2, i:i + 2] += self.EI / self.h * np.array([[1.0, -1.0], [-1.0, 1.0]])
        self.K = K[1:, 1:]
        self.area = w * t
        gx, gw = np.polynomial.legendre.leggauss(int(n_cross))
        Y, E = np.meshgrid(0.5 * w * (1 + gx), 0.5 * t * gx, indexing="ij")
        self.yc, self.eta = Y.ravel(), E.ravel()
        self.omega = (np.outer(gw, gw) / 4.0).ravel()
        self.n_cross = int(n_cross)
        self.weight_N_m3 = material.density_kg_m3 * gr
        self.fd_step = FD_HESSIAN_REL * min(t, min(magnet.dimensions_m))
        self._dead_cache = {}
        #: an :class:`EvaluationBudget` spent by every evaluation (None: no limit)
        self.budget = None

    # ---------------------------------------------------------------- geometry
    def magnet_at(self, gap_m):
        return magnet_below(self.magnet, gap_m)

    def kinematics(self, theta_full):
        """Tangents, normals (N+1, 2) and centreline nodes r (N+1, 2) in the (x, z) plane."""
        c, s = np.cos(theta_full), np.sin(theta_full)
        tng = np.column_stack([c, s])
        nrm = np.column_stack([-s, c])
        r = np.array([0.0, 0.5 * self.t]) + self.C @ tng
        return tng, nrm, r

    def _full(self, u):
        return np.concatenate([[0.0], np.asarray(u, float)[:self.N]])

    def tip_corner(self, theta):
        """The bottom edge of the tip, ``r(L) - (t/2) n(L)``, in (x, z) [m]."""
        tng, nrm, r = self.kinematics(self._full(theta))
        return r[-1] - 0.5 * self.t * nrm[-1]

    def tip_gap_m(self, theta, gap_m):
        """Gap between the lowest point of the strip (the tip's bottom edge) and the face [m]."""
        return float(self.tip_corner(theta)[1] + gap_m)

    def tip_deflection_m(self, theta):
        """Downward displacement of the tip's centre [m]."""
        return float(0.5 * self.t - self.kinematics(self._full(theta))[2][-1, 1])

    def bottom_face(self, theta):
        """Points of the bottom face at the nodes, (N+1, 2) [m]."""
        tng, nrm, r = self.kinematics(self._full(theta))
        return r - 0.5 * self.t * nrm

    # ---------------------------------------------------------------- the force
    def force_and_gradient(self, points_m, gap_m, hessian=True):
        """Body force (x, z) at 3D points [N/m^3] and its derivative d f_a / d r_b (x, z)."""
        f, D = magnet_body_force(self.magnet_at(gap_m), self.M_of_H, self.demag, points_m,
                                 self.fd_step if hessian else None, axes=(0, 2))
        if not hessian:
            return f[:, [0, 2]], None
        H = D[:, [0, 2], :]
        return f[:, [0, 2]], 0.5 * (H + np.swapaxes(H, 1, 2))

    def _points(self, r, nrm):
        c = self.eta.size
        pts = np.empty((self.N + 1, c, 3))
        pts[..., 0] = r[:, None, 0] + self.eta[None, :] * nrm[:, None, 0]
        pts[..., 1] = self.yc[None, :]
        pts[..., 2] = r[:, None, 1] + self.eta[None, :] * nrm[:, None, 1]
        return pts

    def _loads(self, theta_full, gap_m, hessian=True):
        tng, nrm, r = self.kinematics(theta_full)
        c = self.eta.size
        if self.follower:
            pts = self._points(r, nrm)
            f, H = self.force_and_gradient(pts.reshape(-1, 3), gap_m, hessian)
        else:
            key = (float(gap_m), hessian)
            if key not in self._dead_cache:
                t0, n0, r0 = self.kinematics(np.zeros(self.N + 1))
                self._dead_cache[key] = self.force_and_gradient(
                    self._points(r0, n0).reshape(-1, 3), gap_m, hessian)
            f, H = self._dead_cache[key]
        f = f.reshape(self.N + 1, c, 2)
        aw = self.area * self.wq
        P = aw[:, None] * np.einsum("c,kca->ka", self.omega, f)
        P[:, 1] -= aw * self.weight_N_m3
        m = aw[:, None] * np.einsum("c,kca->ka", self.omega * self.eta, f)
        out = dict(tng=tng, nrm=nrm, r=r, P=P, m=m)
        if H is not None:
            H = H.reshape(self.N + 1, c, 2, 2)
            out["S"] = aw[:, None, None] * np.einsum("c,kcab->kab", self.omega, H)
            out["S1"] = aw[:, None, None] * np.einsum("c,kcab->kab", self.omega * self.eta, H)
            out["S2"] = aw[:, None, None] * np.einsum("c,kcab->kab",
                                                       self.omega * self.eta**2, H)
        return out

    def magnetic_force_N(self, theta, gap_m):
        """Net magnetic force on the strip (x, z) [N] (trapezoid over the nodes)."""
        ld = self._loads(self._full(theta), gap_m, hessian=False)
        return ld["P"].sum(axis=0) + np.array([0.0, self.area * self.L * self.weight_N_m3])

    def magnetic_moment_about_clamp_Nm(self, theta, gap_m):
        """Moment of the magnetic forces about the clamp's centre, counter-clockwise in (x, z)
        [N m], taken at the cross-section points (so it includes the distributed moment)."""
        th = self._full(theta)
        tng, nrm, r = self.kinematics(th)
        pts = self._points(r, nrm)
        f, _ = self.force_and_gradient(pts.reshape(-1, 3), gap_m, hessian=False)
        f = f.reshape(pts.shape[0], pts.shape[1], 2)
        arm = pts[..., [0, 2]] - np.array([0.0, 0.5 * self.t])
        cross = arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0]
        return float(self.area * np.sum(self.wq[:, None] * self.omega[None, :] * cross))

    # ---------------------------------------------------------------- systems
    def _gradient_and_hessian(self, theta_full, gap_m):
        ld = self._loads(theta_full, gap_m, hessian=True)
        tng, nrm, P, m = ld["tng"], ld["nrm"], ld["P"], ld["m"]
        S, S1, S2 = ld["S"], ld["S1"], ld["S2"]
        C = self.C
        T = C.T @ P
        G = -(np.sum(nrm * T, axis=1) - np.sum(tng * m, axis=1))
        diag = -np.sum(tng * T, axis=1) - np.sum(nrm * m, axis=1)
        if self.follower:
            V = C[:, :, None] * nrm[None, :, :]
            term1 = np.einsum("kja,kab,klb->jl", V, S, V, optimize=True)
            a = np.einsum("ja,lab,lb->jl", nrm, S1, tng)
            term2 = -C.T * a
            tS2t = np.einsum("ja,jab,jb->j", tng, S2, tng)
            Hm = -(np.diag(diag + tS2t) + term1 + term2 + term2.T)
        else:
            Hm = -np.diag(diag)
        dT = C.T @ S[:, :, 1]
        Gp = -(np.sum(nrm * dT, axis=1) - np.sum(tng * S1[:, :, 1], axis=1))
        return G, Hm, Gp

    def system_free(self, u, gap_m):
        """``(R, J, dR/dg)`` of the free strip; ``u`` = theta_1..N [rad], ``gap_m`` [m]."""
        if self.budget is not None:
            self.budget.spend()
        th = self._full(u)
        G, Hm, Gp = self._gradient_and_hessian(th, gap_m)
        R = self.K @ th[1:] + G[1:]
        return R, self.K + Hm[1:, 1:], Gp[1:]

    def _gap_derivatives(self, th):
        c, s = np.cos(th), np.sin(th)
        d1 = self.C[-1] * c
        d1[-1] += 0.5 * self.t * s[-1]
        d2 = -self.C[-1] * s
        d2[-1] += 0.5 * self.t * c[-1]
        return d1[1:], d2[1:]

    def system_contact(self, u, gap_m):
        """``(R, J, dR/dg)`` with the tip on the face; ``u`` = (theta_1..N, contact force [N])."""
        th = self._full(u)
        lam = float(u[-1])
        R0, J0, Rp0 = self.system_free(u[:-1], gap_m)
        d1, d2 = self._gap_derivatives(th)
        gamma = self.tip_gap_m(u[:-1], gap_m)
        n = self.N
        R = np.concatenate([R0 - lam * d1, [-gamma]])
        J = np.zeros((n + 1, n + 1))
        J[:n, :n] = J0 - lam * np.diag(d2)
        J[:n, n] = -d1
        J[n, :n] = -d1
        Rp = np.concatenate([Rp0, [-1.0]])
        return R, J, Rp

    def stable_contact(self, u, gap_m, J):
        """Constrained Hessian positive definite on the tangent space of the contact."""
        n = self.N
        d1 = -J[n, :n]
        q, _ = np.linalg.qr(np.column_stack([d1, np.eye(n)[:, :n - 1]]))
        Z = q[:, 1:]
        Hc = Z.T @ J[:n, :n] @ Z
        return bool(np.all(np.linalg.eigvalsh(0.5 * (Hc + Hc.T)) > 0.0))

    def linear_guess(self, gap_m):
        """One Newton step from the straight strip: theta (N,) [rad]."""
        R, J, _ = self.system_free(np.zeros(self.N), gap_m)
        return np.linalg.solve(J, -R)

    def other_clearance_m(self, theta, gap_m):
        """Smallest height of a bottom-face node other than the tip above the face's plane."""
        return float(np.min(self.bottom_face(theta)[:-1, 1]) + gap_m)

    def check_no_other_contact(self, theta, gap_m, tol_m):
        """Raise if a bottom-face node other than the tip lies below the face's plane."""
        b = self.bottom_face(theta)[:-1]
        if np.any(b[:, 1] + gap_m < -tol_m):
            raise PathFollowingError(
                "the strip reaches the plane of the magnet's face away from its tip: not "
                f"modelled (gap {gap_m:g} m)", {"gap_m": gap_m, "theta_rad": np.asarray(theta)})

    # ---------------------------------------------------------------- lying on the face
    def node_gaps_m(self, theta, gap_m):
        """Height of the bottom face above the face's plane at the nodes 1..N, (N,) [m]."""
        return self.bottom_face(theta)[1:, 1] + gap_m

    def _node_gap_jacobian(self, th):
        """``D[k-1, j-1] = d gamma_k / d theta_j`` (N, N) for the nodes k = 1..N, and
        ``D2[k-1, j-1] = d^2 gamma_k / d theta_j^2`` (each ``gamma_k`` is a sum of functions of
        one ``theta_j`` each: no mixed second derivatives)."""
        c, s = np.cos(th), np.sin(th)
        D = self.C[1:, 1:] * c[None, 1:]
        D2 = -self.C[1:, 1:] * s[None, 1:]
        i = np.arange(self.N)
        D[i, i] += 0.5 * self.t * s[1:]
        D2[i, i] += 0.5 * self.t * c[1:]
        return D, D2

    def system_lying(self, u, gap_m, active):
        """``(R, J, dR/dg)`` with the bottom face on the face's plane at the nodes ``active``
        (node numbers in 1..N, sorted); ``u`` = (theta_1..N [rad], the contact forces at the
        active nodes [N]). ``active = [N]`` is :meth:`system_contact` (the tip alone)."""
        act = np.asarray(active, int) - 1
        n, m = self.N, act.size
        u = np.asarray(u, float)
        th = self._full(u)
        lam = u[n:]
        R0, J0, Rp0 = self.system_free(u[:n], gap_m)
        D, D2 = self._node_gap_jacobian(th)
        Da = D[act]
        gam = self.node_gaps_m(u[:n], gap_m)[act]
        R = np.concatenate([R0 - Da.T @ lam, -gam])
        J = np.zeros((n + m, n + m))
        J[:n, :n] = J0 - np.diag(D2[act].T @ lam)
        J[:n, n:] = -Da.T
        J[n:, :n] = -Da
        Rp = np.concatenate([Rp0, -np.ones(m)])
        return R, J, Rp

    def stable_lying(self, J):
        """Hessian positive definite on the tangent space of the active contacts (``J`` from
        :meth:`system_lying`)."""
        n = self.N
        Da = -J[n:, :n]
        if Da.shape[0] == 0:
            Z = np.eye(n)
        else:
            q, _ = np.linalg.qr(np.column_stack([Da.T, np.eye(n)]))
            Z = q[:, Da.shape[0]:n]
        Hc = Z.T @ J[:n, :n] @ Z
        return bool(np.all(np.linalg.eigvalsh(0.5 * (Hc + Hc.T)) > 0.0))

    def clamp_reaction_N(self, u, gap_m, active=()):
        """Vertical force of the clamp on the strip [N] (upward positive), from moments alone.

        ``u`` = (theta_1..N, the contact forces at the nodes ``active``). The first half segment
        ``[0, h/2]`` is a lever held by the clamp: its equation (``d Pi / d theta_0``, which the
        clamp's moment balances) reads ``M_c = -mu_1/2 - (h/2) sum_{k>=1} F_z,k + m_0,x`` (the
        bending moment ``mu_1/2 = EI theta_1 / h`` in the first segment, ``F_z,k`` the nodal
        magnetic and contact forces, ``m_0`` the distributed moment at the clamp's node), and
        the rotation of the whole strip about the clamp gives ``M_c`` = minus the moment about
        the clamp of all the loads (:meth:`magnetic_moment_about_clamp_Nm`, evaluated at the
        cross-section points, plus ``sum lambda_k x_k`` of the contact forces at the bottom
        edge). Solved for ``sum F_z`` this gives the clamp's reaction without summing the
        forces: the force balance ``sum lambda = F_magnetic - V_clamp`` is then a check of the
        equilibrium (exact for the discrete model, to the Newton tolerance)."""
        act = np.asarray(active, int) - 1
        u = np.asarray(u, float)
        th = u[:self.N]
        lam = u[self.N:]
        M_mag = self.magnetic_moment_about_clamp_Nm(th, gap_m)
        r = self.kinematics(self._full(th))[2]
        M_mag -= float(np.sum(r[:, 0] * self.area * self.wq)) * self.weight_N_m3   # weight
        M_con = float(np.sum(lam * self.bottom_face(th)[1:, 0][act]))
        ld = self._loads(self._full(th), gap_m, hessian=False)
        mu_half = self.EI * th[0] / self.h
        sum_fz = (2.0 / self.h) * (M_mag + M_con - mu_half + ld["m"][0, 0])
        return float(-(sum_fz + ld["P"][0, 1]))


# ============================================================================================
# the sweep

@dataclass(frozen=True, eq=False)
class PullInResult:
    """Equilibrium path of the strip against the magnet gap, pull-in and release.

    The path (all traced equilibria, in the order traced: the free branch from a far gap through
    the fold to the touch point, then the contact branches: the tip-only one from the touch
    point, then the pieces of the strip lying on the face, the one it leaves last first):
    gap_m (n,) magnet gap [m]; tip_deflection_m (n,) downward deflection of the tip's centre
    [m]; tip_gap_m (n,) gap between the tip's bottom edge and the face [m] (0 on tip contact;
    > 0 where the strip lies on the face with its tip lifted); contact_force_N (n,) the total
    contact force [N] (0 on the free branch); n_contact (n,) nodes in contact;
    contact_length_m (n,) arc length from the first to the last node in contact [m] (0 for
    the tip alone); branch (n,) "free" | "contact";
    stable (n,) bool; tip_x_m (n,) x of the tip's bottom edge [m]; tip_over_magnet (n,) bool:
    that edge lies over the magnet's face (False: beside it, on the plane of the face); theta_rad
    (n, N+1) cross-section rotations at ``s_m`` (N+1,) [m].

    pull_in_gap_m, pull_in_tip_deflection_m : the fold of the free branch (nan if the range
    of gaps ends before it); snap : False if the tip reached the face without a fold (then
    pull-in = release = the touching gap); release_gap_m, release_tip_deflection_m : where the
    contact force vanishes (the touch point, lift-off; nan if the range ends before it);
    snap_back_gap_m : opening the gap from contact, where the strip returns to the
    small-deflection branch it left at pull-in (= release_gap_m unless a stable free branch
    with the tip hovering near the face exists between them; nan without contact);
    release_by : "contact force zero" (lift-off), "fold of the contact branch" (the contact
    state disappears with no contact state to land on: a snap-off) or "" (no contact traced);
    contact_jumps_m : the gaps at which, opening the gap from deep contact, the strip snapped
    from one contact state to another before the release (the strip lying on the face);
    far_gap_m : the gap the path started from [m]; contact_end_gap_m : the smallest gap with
    a modelled contact state: nan if the contact reaches the smallest gap of the sweep; the
    strip lying on the face starts at ``LYING_MIN_GAP_REL`` t at least (below it the whole
    strip lies flat, a degenerate start); if the lying contact could not be followed, where
    the tip-only branch ends (a second point of the strip reaching the face, or a fold). Sweep
    gaps below it are nan, branch "unmodelled".

    The quasi-static sweep (history: the strip starts straight, the magnet brought from far to
    the first gap, then moved through the sweep, and back if ``round_trip``):
    sweep_gap_m, sweep_tip_deflection_m, sweep_tip_gap_m, sweep_contact_force_N, sweep_branch,
    sweep_n_contact (-1 where unmodelled), sweep_contact_length_m.
    """
    gap_m: np.ndarray
    tip_deflection_m: np.ndarray
    tip_gap_m: np.ndarray
    contact_force_N: np.ndarray
    branch: np.ndarray
    stable: np.ndarray
    tip_x_m: np.ndarray
    tip_over_magnet: np.ndarray
    theta_rad: np.ndarray
    s_m: np.ndarray
    pull_in_gap_m: float
    pull_in_tip_deflection_m: float
    snap: bool
    release_gap_m: float
    release_tip_deflection_m: float
    snap_back_gap_m: float
    far_gap_m: float
    release_by: str
    contact_end_gap_m: float
    sweep_gap_m: np.ndarray
    sweep_tip_deflection_m: np.ndarray
    sweep_tip_gap_m: np.ndarray
    sweep_contact_force_N: np.ndarray
    sweep_branch: np.ndarray
    n_segments: int
    n_cross: int
    demag_factor: float
    follower: bool
    # the strip lying on the face (nodes in contact other than the tip alone)
    n_contact: np.ndarray = None
    contact_length_m: np.ndarray = None
    sweep_n_contact: np.ndarray = None
    sweep_contact_length_m: np.ndarray = None
    contact_jumps_m: tuple = ()
    # what the strip does at pull-in (the state it lands in) and the touch point
    touch_gap_m: float = math.nan
    pull_in_lands_on: str = ""
    landing_tip_deflection_m: float = math.nan
    landing_tip_gap_m: float = math.nan
    landing_n_contact: int = -1
    landing_contact_force_N: float = math.nan
    evaluations: int = 0

    def to_dict(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else v
        return out


def check_gap_sweep(gap_sweep_m, below_zero: str = "puts the magnet inside the strip; gaps "
                    "must be >= 0 m (strip face to magnet face)",
                    round_trip_hint: str = "; run two sweeps for a round trip (or "
                                           "round_trip=True)") -> np.ndarray:
    """The magnet gaps [m] of a sweep: finite, 1-D, >= 0, strictly monotonic; one InputError
    naming ``gap_sweep_m`` otherwise (``below_zero``: what a negative gap means for the device,
    ``round_trip_hint``: appended to the monotonicity message)."""
    g = np.atleast_1d(np.asarray(check_finite("gap_sweep_m", gap_sweep_m, "m"), float))
    if g.ndim != 1 or g.size < 1:
        raise InputError(f"gap_sweep_m must be a 1-D array of gaps [m], got shape {g.shape}")
    if np.any(g < 0):
        raise InputError(f"gap_sweep_m: a gap below zero ({g.min():g} m) {below_zero}")
    d = np.diff(g)
    if g.size > 1 and not (np.all(d > 0) or np.all(d < 0)):
        raise InputError("gap_sweep_m must be strictly monotonic (all increasing or all "
                         "decreasing) [m]" + round_trip_hint)
    return g



def _solve_at(system, u_guess, gap, tol, r_scale, max_newton=30):
    u = np.asarray(u_guess, float).copy()
    for _ in range(max_newton):
        R, J, _ = system(u, gap)
        du = np.linalg.solve(J, -R)
        u = u + du
        if np.max(np.abs(R / r_scale)) < tol and np.max(np.abs(du[:-1] if u.size > 1
                                                               else du)) < 1e-10:
            return u
    R, J, _ = system(u, gap)
    if np.max(np.abs(R / r_scale)) < 1e3 * tol:
        return u
    raise PathFollowingError(f"Newton did not converge at the sweep gap {gap:g} m",
                             {"gap_m": gap, "u": u})


def _solve_damped(system, u, p, r_scale, max_it=80, max_step_rad=0.1):
    """Newton at fixed p with the rotation update limited to ``max_step_rad``."""
    u = np.asarray(u, float).copy()
    for _ in range(max_it):
        R, J, _ = system(u, p)
        try:
            du = np.linalg.solve(J, -R)
        except np.linalg.LinAlgError:
            break
        u = u + min(1.0, max_step_rad / max(np.abs(du[:-1]).max(), 1e-300)) * du
        if not np.all(np.isfinite(u)):
            break
        if np.abs(du[:-1]).max() < 1e-12 and np.max(np.abs(R / r_scale)) < 1e-8:
            return u
    raise PathFollowingError(f"no contact equilibrium found at the gap {p:g} m",
                             {"gap_m": p, "u": u})


def _interp_branch(p, u, g):
    """u at g on a branch segment monotone in p (p decreasing or increasing)."""
    order = np.argsort(p)
    return np.array([np.interp(g, p[order], u[order, j]) for j in range(u.shape[1])])


# ============================================================================================
# the strip lying on the magnet: distributed unilateral contact with an active set

@dataclass(frozen=True, eq=False)
class LyingBranch:
    """The contact branch of the strip lying on the face's plane, from deep contact (the
    smallest gap) opening the gap until every contact force vanishes (release) or the branch
    folds (a snap-off).

    gap_m (n,) [m]; theta_rad (n, N) rotations theta_1..N [rad]; contact_forces_N (n, N) the
    contact force at each node 1..N [N] (0 where the node is free); contact_force_N (n,) their
    sum [N]; n_contact (n,) nodes in contact; contact_length_m (n,) arc length from the first
    to the last node in contact [m] (0 for one node); node_gaps_m (n, N) heights of the bottom
    face above the plane at the nodes [m] (0 in contact); stable (n,) bool; active: tuple of the
    active sets (node numbers 1..N) of the points; release_gap_m, release_tip_deflection_m;
    release_by: "contact force zero" | "fold of the contact branch"; events: tuple of
    ``(gap_m, "add" | "drop", node)``, the changes of the active set along the branch.
    """
    gap_m: np.ndarray
    theta_rad: np.ndarray
    contact_forces_N: np.ndarray
    contact_force_N: np.ndarray
    n_contact: np.ndarray
    contact_length_m: np.ndarray
    node_gaps_m: np.ndarray
    stable: np.ndarray
    active: tuple
    release_gap_m: float
    release_tip_deflection_m: float
    release_by: str
    events: tuple
    fold_gaps_m: tuple = ()


def _newton_lying(model, u, g, active, r_scale, max_it=80, max_step_rad=0.1):
    """Damped Newton at fixed gap and active set (rotation update limited to
    ``max_step_rad``); the converged u, or None."""
    n = model.N
    u = np.asarray(u, float).copy()
    for _ in range(max_it):
        R, J, _ = model.system_lying(u, g, active)
        try:
            du = np.linalg.solve(J, -R)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(du)):
            return None
        big = np.abs(du[:n]).max()
        u = u + min(1.0, max_step_rad / max(big, 1e-300)) * du
        if big < 1e-12 and np.max(np.abs(R / r_scale)) < 1e-8:
            return u
    return None


def solve_lying(model, gap_m, theta_guess, active, *, lam_scale=None, max_outer=40,
                max_newton=80):
    """Equilibrium of the strip with frictionless unilateral contact on the face's plane at a
    fixed gap: a primal-dual active-set iteration (Newton at a fixed active set, then nodes
    whose contact force is negative leave the set and nodes below the plane join it; one node
    at a time once a set repeats). Returns ``(theta (N,), forces (N,) per node [N], active)``
    or raises :class:`PathFollowingError`."""
    n, L = model.N, model.L
    ls = lam_scale or max(model.EI / L**2, abs(model.magnetic_force_N(np.zeros(n), gap_m)[1]))
    tol_l, tol_g = 1e-10 * ls, 1e-10 * L
    A = sorted(set(int(k) for k in active))
    th = np.asarray(theta_guess, float).copy()
    lam = np.zeros(n)
    lam[np.array(A, int) - 1] = ls / max(len(A), 1)
    seen = set()
    for _ in range(max_outer):
        rs = np.concatenate([np.full(n, model.EI / L), np.full(len(A), L)])
        u = _newton_lying(model, np.concatenate([th, lam[np.array(A, int) - 1]]), gap_m, A, rs,
                          max_it=max_newton)
        if u is None:
            raise PathFollowingError(f"no equilibrium on the face found at the gap {gap_m:g} m "
                                     f"(active nodes {A})", {"gap_m": gap_m, "theta_rad": th})
        th = u[:n]
        lam = np.zeros(n)
        lam[np.array(A, int) - 1] = u[n:]
        gam = model.node_gaps_m(th, gap_m)
        drop = [k for k in A if lam[k - 1] < -tol_l]
        add = [k for k in range(1, n + 1) if k not in A and gam[k - 1] < -tol_g]
        if not drop and not add:
            return th, lam, tuple(A)
        seen.add(tuple(A))
        new = sorted((set(A) - set(drop)) | set(add))
        if tuple(new) in seen:              # cycling: change the worst node only
            worst_drop = min(drop, key=lambda k: lam[k - 1] / ls, default=None)
            worst_add = min(add, key=lambda k: gam[k - 1] / L, default=None)
            if worst_add is None or (worst_drop is not None
                                     and lam[worst_drop - 1] / ls < gam[worst_add - 1] / L):
                new = sorted(set(A) - {worst_drop})
            else:
                new = sorted(set(A) | {worst_add})
        A = new
    raise PathFollowingError(f"the active set did not settle at the gap {gap_m:g} m",
                             {"gap_m": gap_m, "theta_rad": th})


class _Proximal:
    """``model`` with ``mu/2 |theta - theta_ref|^2`` added to the energy (one implicit step of
    the gradient flow); duck-types what :func:`solve_lying` uses."""

    def __init__(self, model, theta_ref, mu):
        self.m, self.ref, self.mu = model, np.asarray(theta_ref, float).copy(), float(mu)
        self.N, self.L, self.EI = model.N, model.L, model.EI

    def system_lying(self, u, g, active):
        R, J, Rp = self.m.system_lying(u, g, active)
        n = self.N
        R = R.copy()
        R[:n] += self.mu * (np.asarray(u[:n]) - self.ref)
        J = J.copy()
        J[np.arange(n), np.arange(n)] += self.mu
        return R, J, Rp

    def node_gaps_m(self, theta, g):
        return self.m.node_gaps_m(theta, g)

    def magnetic_force_N(self, theta, g):
        return self.m.magnetic_force_N(theta, g)


def relax_on_face(model, gap_m, theta0, *, active=(), max_steps=400):
    """The stable state the strip settles in at the gap ``gap_m`` from ``theta0`` (e.g. the
    fold of the free branch, after the snap): implicit steps of the gradient flow of the
    energy with the unilateral contact (each a :func:`solve_lying` of the energy plus
    ``mu/2 |theta - theta_k|^2``, ``mu`` large enough for a convex step, decreasing as the
    residual falls), then Newton with the active set. Returns ``(theta, forces, active)``."""
    n, L = model.N, model.L
    ls = max(model.EI / L**2, abs(model.magnetic_force_N(np.zeros(n), gap_m)[1]))
    th = np.asarray(theta0, float).copy()
    A = tuple(active)
    lam = np.zeros(n)
    mu = model.EI / model.h
    for _ in range(max_steps):
        try:
            th_new, lam_new, A_new = solve_lying(_Proximal(model, th, mu), gap_m, th, A,
                                                 lam_scale=ls, max_newton=15)
        except PathBudgetError:
            raise
        except PathFollowingError:
            mu *= 4.0
            continue
        step = float(np.abs(th_new - th).max())
        th, lam, A = th_new, lam_new, A_new
        if step < 1e-4:
            try:
                th2, lam2, A2 = solve_lying(model, gap_m, th, A, lam_scale=ls, max_newton=15)
            except PathBudgetError:
                raise
            except PathFollowingError:
                th2 = None
            if th2 is not None:
                u = np.concatenate([th2, lam2[np.array(A2, int) - 1]])
                if model.stable_lying(model.system_lying(u, gap_m, A2)[1]):
                    return th2, lam2, A2
        mu = max(mu * 0.5, 1e-4 * model.EI / model.h) if step < 0.05 else mu * 2.0
    raise PathFollowingError(f"the strip did not settle at the gap {gap_m:g} m",
                             {"gap_m": gap_m, "theta_rad": th})


def deep_contact_start(model, gap_m, *, lam_scale=None):
    """A stable equilibrium with the strip lying on the face at the gap ``gap_m`` (> 0).

    Guesses: the strip leaves the clamp flat, comes down over a length ``l`` along the shape of
    a uniformly loaded beam landing flat with zero moment (``z = -g (3 xi^4 - 8 xi^3 +
    6 xi^2)``, ``xi = x / l``) and lies flat beyond, the nodes beyond ``l`` in contact; ``l``
    from the uniform-load estimate ``(72 EI g / q)^(1/4)`` then shorter and longer; the first
    guess that settles (:func:`solve_lying`) on a stable state is returned as
    ``(theta, forces, active)``."""
    n, L, g = model.N, model.L, float(gap_m)
    ls = lam_scale or max(model.EI / L**2, abs(model.magnetic_force_N(np.zeros(n), g)[1]))
    q = max(abs(model.magnetic_force_N(np.zeros(n), g)[1]) / L, 1e-300)
    l0 = (72.0 * model.EI * g / q) ** 0.25
    s = model.s[1:]
    fails = []
    for l in sorted({min(max(f * l0, 2 * model.h), L) for f in
                     (1.0, 0.8, 1.25, 0.6, 1.6, 0.45, 2.0, 0.3, 2.5)},
                    key=lambda x: abs(math.log(x / l0))):
        xi = np.clip(s / l, 0.0, 1.0)
        slope = -12.0 * g * xi * (xi - 1.0) ** 2 / l
        th0 = np.arctan(slope)
        active = [k for k in range(1, n + 1) if s[k - 1] >= l - 1e-12 * L] or [n]
        try:
            th, lam, A = solve_lying(model, g, th0, active, lam_scale=ls)
        except PathBudgetError:
            raise
        except PathFollowingError as exc:
            fails.append(str(exc))
            continue
        u = np.concatenate([th, lam[np.array(A, int) - 1]])
        if model.stable_lying(model.system_lying(u, g, A)[1]):
            return th, lam, A
        fails.append(f"l = {l:g} m: unstable")
    raise PathFollowingError(f"no stable state lying on the face at the gap {g:g} m: "
                             + "; ".join(fails[-3:]), {"gap_m": g})


def lying_contact_branch(model, gap_start_m, gap_max_m, *, ds_max=0.05, max_segments=400,
                         through_folds=False, start=None, gap_min_m=None,
                         direction=1.0, max_steps=600,
                         max_evaluations=1500) -> LyingBranch:
    """Follow the strip lying on the face's plane from deep contact at ``gap_start_m`` opening
    the gap (up to ``gap_max_m``) until every contact force vanishes (the release gap).

    Along the way the active set changes: a node whose contact force reaches zero leaves it
    (event "drop", located by Brent's method on the smallest force), a free node reaching the
    plane joins it (event "add", on the smallest height of the free nodes); each active set is
    a branch of :meth:`MagnetElastica.system_lying` followed by :func:`trace_branch` (at most
    ``max_steps`` steps and ``max_evaluations`` evaluations each: past them
    :class:`PathFollowingError`; most pieces take < 150, a long one, the tip at the rim from a
    jump to the release, ~700). The
    branch ends when the set is empty (release_by "contact force zero"; the last point is the
    free strip touching the plane with zero force) or at a fold (the contact state disappears:
    release_by "fold of the contact branch", a snap-off).
    """
    n, L = model.N, model.L
    g0 = float(gap_start_m)
    ls = max(model.EI / L**2, abs(model.magnetic_force_N(np.zeros(n), g0)[1]))
    th, lam, A = start if start is not None else deep_contact_start(model, g0, lam_scale=ls)
    # the scale of the contact forces: the magnetic pull on the bent strip
    ls = max(ls, abs(model.magnetic_force_N(th, g0)[1]), float(np.sum(lam)))
    A = list(A)
    u = np.concatenate([th, lam[np.array(A, int) - 1]])
    g = g0
    rows = []          # (gap, theta, forces per node, stable, active)
    events = []
    release_by, release_gap, release_defl = "", math.nan, math.nan
    ds = 0.02
    direction = float(np.sign(direction) or 1.0)
    folds = []

    def drop_fun(act):
        return lambda uu, p: float(np.min(uu[n:])) / ls

    def add_fun(act):
        free = np.array([k for k in range(1, n + 1) if k not in act], int) - 1

        def fun(uu, p):
            return float(np.min(model.node_gaps_m(uu[:n], p)[free])) / L
        return fun

    for _ in range(max_segments):
        act = tuple(A)
        m = len(act)
        system = (lambda uu, p, act=act: model.system_lying(uu, p, act))
        evs = [("drop", drop_fun(act))]
        if m < n:
            evs.append(("add", add_fun(act)))
        tr = trace_branch(
            system, u, g, direction=direction, p_max=gap_max_m,
            p_min=0.5 * g0 if gap_min_m is None else gap_min_m, events=evs,
            ds=ds, ds_max=ds_max,
            u_scale=np.concatenate([np.full(n, math.sqrt(n)), np.full(m, ls)]), p_scale=L,
            r_scale=np.concatenate([np.full(n, model.EI / L), np.full(m, L)]),
            ftol=1e-9, xtol=1e-10, max_steps=max_steps, stop_at_fold=not through_folds,
            max_evaluations=max_evaluations,
            budget=getattr(model, "budget", None),
            stability=lambda uu, p, J: model.stable_lying(J))
        if rows and len(tr.p) > 1:
            # a node that has just joined (left) the set with a zero force (gap) whose force
            # (gap) turns negative at once: no event can fire (it starts at zero), and the
            # branch traced is not a contact state (the face pulling, or the strip through
            # it): no contact state continues this way, a fold -- the strip snaps here
            free_k = np.array([k for k in range(1, n + 1) if k not in act], int) - 1
            pull = float(np.min(tr.u[1:, n:])) < -1e-7 * ls if m else False
            through = bool(free_k.size) and min(
                float(np.min(model.node_gaps_m(tr.u[k, :n], tr.p[k])[free_k]))
                for k in range(1, len(tr.p))) < -1e-7 * L
            if pull or through:
                folds.append(g)
                release_by, release_gap = "fold of the contact branch", g
                release_defl = model.tip_deflection_m(u[:n])
                break
        for k in range(len(tr.p)):
            if rows and k == 0:
                continue                            # the event point, already recorded
            f = np.zeros(n)
            f[np.array(act, int) - 1] = tr.u[k, n:]
            rows.append((float(tr.p[k]), tr.u[k, :n].copy(), f, bool(tr.stable[k]), act))
        ev = tr.event
        if ev is None:
            raise PathFollowingError("the contact branch did not end within its steps",
                                     {"gap_m": float(tr.p[-1]), "theta_rad": tr.u[-1, :n]})
        g, u = float(ev.p), ev.u.copy()
        direction = float(np.sign(tr.dp_ds[-1])) or direction
        folds.extend(float(lp.p) for lp in tr.limit_points)
        if ev.name in ("drop", "add"):
            if ev.name == "drop":
                k_ev = act[int(np.argmin(u[n:]))]
            else:
                free = [k for k in range(1, n + 1) if k not in act]
                k_ev = free[int(np.argmin(model.node_gaps_m(u[:n], g)[np.array(free) - 1]))]
            if events and events[-1][2] == k_ev and events[-1][1] != ev.name \
                    and abs(events[-1][0] - g) <= 1e-7 * L:
                # the node that has just left (joined) the set at this gap must join (leave)
                # it again at once: with it the contact force would pull, without it the
                # node would be below the plane -- no contact state continues this way (a
                # fold of the piecewise-smooth branch): the strip snaps here
                folds.append(g)
                release_by, release_gap = "fold of the contact branch", g
                release_defl = model.tip_deflection_m(u[:n])
                break
        if ev.name == "drop":
            j = int(np.argmin(u[n:]))
            events.append((g, "drop", act[j]))
            A = [k for i, k in enumerate(act) if i != j]
            u = np.delete(u, n + j)
            if not A:
                release_by, release_gap = "contact force zero", g
                release_defl = model.tip_deflection_m(u[:n])
                f = np.zeros(n)
                rows.append((g, u[:n].copy(), f, rows[-1][3], ()))
                break
        elif ev.name == "add":
            free = [k for k in range(1, n + 1) if k not in act]
            k_new = free[int(np.argmin(model.node_gaps_m(u[:n], g)[np.array(free) - 1]))]
            events.append((g, "add", k_new))
            A = sorted(act + (k_new,))
            u = np.insert(u, n + A.index(k_new), 0.0)
        elif ev.name == "fold":
            release_by, release_gap = "fold of the contact branch", g
            release_defl = model.tip_deflection_m(u[:n])
            break
        else:                                   # p_min / p_max: the strip still on the face
            break
        ds = 0.005
    else:
        raise PathFollowingError("too many changes of the contact set", {"gap_m": g})
    gap = np.array([r[0] for r in rows])
    th = np.array([r[1] for r in rows])
    F = np.array([r[2] for r in rows])
    act_l = tuple(r[4] for r in rows)
    s = model.s
    clen = np.array([s[max(a)] - s[min(a)] if a else 0.0 for a in act_l])
    ng = np.array([model.node_gaps_m(t, p) for t, p in zip(th, gap)])
    out = LyingBranch(gap, th, F, F.sum(axis=1), np.array([len(a) for a in act_l]), clen, ng,
                      np.array([r[3] for r in rows], bool), act_l, release_gap, release_defl,
                      release_by, tuple(events), tuple(folds))
    for a in (out.gap_m, out.theta_rad, out.contact_forces_N, out.contact_force_N,
              out.n_contact, out.contact_length_m, out.node_gaps_m, out.stable):
        a.flags.writeable = False
    return out


def _join_branches(down, up):
    """One branch from ``down`` (traced closing the gap from a point) reversed and ``up``
    (traced opening the gap from the same point)."""
    def cat(a, b):
        return np.concatenate([np.asarray(a)[::-1], np.asarray(b)[1:]])
    out = LyingBranch(cat(down.gap_m, up.gap_m), cat(down.theta_rad, up.theta_rad),
                      cat(down.contact_forces_N, up.contact_forces_N),
                      cat(down.contact_force_N, up.contact_force_N),
                      cat(down.n_contact, up.n_contact),
                      cat(down.contact_length_m, up.contact_length_m),
                      cat(down.node_gaps_m, up.node_gaps_m), cat(down.stable, up.stable),
                      tuple(down.active[::-1]) + tuple(up.active[1:]), up.release_gap_m,
                      up.release_tip_deflection_m, up.release_by,
                      tuple(down.events[::-1]) + tuple(up.events),
                      tuple(down.fold_gaps_m) + tuple(up.fold_gaps_m))
    for a in (out.gap_m, out.theta_rad, out.contact_forces_N, out.contact_force_N,
              out.n_contact, out.contact_length_m, out.node_gaps_m, out.stable):
        a.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class ContactRelease:
    """The quasi-static opening of the gap from deep contact (:func:`contact_release`).

    pieces : tuple of :class:`LyingBranch`, the stable contact segments the strip passes
        through, in the order of opening (the first from deep contact; each later one whole,
        from its closing fold or the smallest gap to where it ends opening);
    jumps_m : the gaps at which the strip snapped from one piece to the next (the folds);
    release_gap_m : where the last contact force vanishes (release_by "contact force zero") or
        the last piece folds with no contact state to land on (release_by "fold of the contact
        branch": a snap-off to the free strip) [m]; release_tip_deflection_m [m].
    """
    pieces: tuple
    jumps_m: tuple
    release_gap_m: float
    release_tip_deflection_m: float
    release_by: str


def contact_release(model, gap_start_m, gap_max_m, *, ds_max=0.05, max_jumps=8):
    """Open the gap from the strip lying on the face at ``gap_start_m`` until the strip lets go.

    The contact branch from deep contact (:func:`lying_contact_branch`) is followed opening
    the gap; if it folds (the contact state disappears), the strip snaps: the state it settles
    in just beyond the fold is found by the gradient flow (:func:`relax_on_face`, from the fold
    state); with the strip still on the face, that stable contact segment is traced whole
    (closing to its own fold, opening to its end) and followed on; without contact the strip
    has snapped off (released at the fold). Ends where every contact force vanishes.
    """
    L = model.L
    g0 = float(gap_start_m)
    up = lying_contact_branch(model, g0, gap_max_m, ds_max=ds_max)
    pieces, jumps = [up], []
    for _ in range(max_jumps):
        if up.release_by != "fold of the contact branch":
            break
        g_f = float(up.release_gap_m)
        g_j = g_f + 1e-6 * L
        th, lam, A = relax_on_face(model, g_j, up.theta_rad[-1], active=up.active[-1])
        if not A:
            break                                 # snapped off the face: released at the fold
        jumps.append(g_f)
        kw = dict(ds_max=ds_max, start=(th, lam, A), gap_min_m=min(g0, g_j))
        down = lying_contact_branch(model, g_j, gap_max_m, direction=-1.0, **kw)
        up = lying_contact_branch(model, g_j, gap_max_m, direction=1.0, **kw)
        pieces.append(_join_branches(down, up))
    else:
        raise PathFollowingError(f"more than {max_jumps} snaps between contact states opening "
                                 f"the gap", {"gap_m": float(up.gap_m[-1])})
    last = pieces[-1]
    return ContactRelease(tuple(pieces), tuple(jumps), float(last.release_gap_m),
                          float(last.release_tip_deflection_m), last.release_by)


def pullin_sweep(strip: Strip, material: ElasticMaterial, magnet: PermanentMagnet, M_of_H,
                 gap_sweep_m=None, *, round_trip: bool = True, n_segments: int = 32,
                 n_cross: int = 3, demag_factor: float = 0.0, gravity_m_s2: float = 0.0,
                 follower: bool = True, plate: bool = False, far_gap_m: float | None = None,
                 ds_max: float = 0.05, lying: bool = True,
                 max_evaluations: int = MAX_EVALUATIONS) -> PullInResult:
    """Tip deflection of the strip against the magnet gap, with pull-in, contact and release.

    ``lying``: where the tip-only contact cannot be followed, trace the strip lying on the
    face (:func:`contact_release`; default). False keeps the tip-only result (its
    ``contact_end_gap_m`` says where it ends): the lying branch from deep contact at a small
    gap can take minutes for a soft strip.

    Parameters
    ----------
    strip, material : the strip [m] and its elastic constants (E [Pa], nu, density; None: the
        seed's PDMS, :data:`micro.materials.PDMS`)
    magnet : PermanentMagnet -- axis along z; its ``position_m`` x and y place its axis (use
        :func:`place_magnet` for the default, centred under the tip end); with ``gap_sweep_m``
        its z is ignored, without it the magnet's position is the start (and must not overlap
        the strip)
    M_of_H : callable -- ``M_eff(H)`` [A/m]
    gap_sweep_m : array_like or None -- magnet gaps [m], >= 0, strictly monotonic (the
        strip's bottom face at the tip to the magnet's top face); None: from the magnet's
        position down to 0 (contact), 33 gaps
    round_trip : bool -- the sweep is run forward then back (the hysteresis loop)
    n_segments, n_cross, demag_factor, gravity_m_s2, follower, plate : see
        :class:`MagnetElastica`
    far_gap_m : the gap the path starts from (default: found, from the largest gap of the
        sweep up, such that the linear tip deflection is < 2 % of the gap)
    ds_max : largest arc-length step (scaled: gap / L and rms rotation [rad])

    Returns
    -------
    PullInResult

    Raises
    ------
    InputError -- bad parameters, the magnet overlapping the strip at the start, a gap < 0, a
        sweep that is not monotonic, the tip not over the magnet's face, the magnet not along z
    PathFollowingError -- the path could not be followed (``last_converged`` holds the last
        converged state)
    """
    _check_axis_z(magnet)
    if not isinstance(strip, Strip):
        raise InputError(f"strip must be a Strip, got {type(strip).__name__}")
    if gap_sweep_m is None:
        _check_overlap(magnet, strip)
        g0 = -(magnet.position_m[2] + _half_height(magnet))
        if g0 < 0:
            raise InputError(f"the magnet at position_m={magnet.position_m} overlaps the strip "
                             f"(its top face is {-g0:g} m above the strip's bottom face)")
        gaps = np.linspace(g0, 0.0, 33)
    else:
        gaps = check_gap_sweep(gap_sweep_m)
        _check_overlap(place_magnet_xy(magnet, gaps[0]), strip)
    model = MagnetElastica(strip, material, magnet, M_of_H, n_segments=n_segments,
                           n_cross=n_cross, demag_factor=demag_factor,
                           gravity_m_s2=gravity_m_s2, follower=follower, plate=plate)
    budget = model.budget = EvaluationBudget(max_evaluations)
    try:
        return _trace_sweep(model, strip, gaps, far_gap_m, ds_max, lying, round_trip)
    except PathBudgetError as exc:
        raise _budget_error(model, budget) from exc


def _budget_error(model, budget):
    """The :class:`PathBudgetError` of a sweep whose budget ran out, naming its last converged
    state (``last_converged``: the loop it was in, the gap, the shape, the contact forces)."""
    last = {"what": "the last converged state before the evaluation budget ran out",
            "evaluations": budget.n, "max_evaluations": budget.max}
    if budget.last is not None:
        stage, u, p = budget.last
        th = u[:model.N]
        last.update(stage=stage, gap_m=p, tip_deflection_m=model.tip_deflection_m(th),
                    tip_gap_m=model.tip_gap_m(th, p),
                    contact_force_N=float(np.sum(u[model.N:])),
                    theta_rad=np.concatenate([[0.0], th]), s_m=model.s.copy())
        where = (f"; the last converged state: gap {p:.6g} m, tip deflection "
                 f"{last['tip_deflection_m']:.6g} m ({stage})")
    else:
        where = "; no converged state yet"
    return PathBudgetError(f"path following stopped: the evaluation budget ({budget.max} "
                           f"evaluations of the strip) ran out in {budget.stage or 'the path'}"
                           + where, last)


def _trace_sweep(model, strip, gaps, far_gap_m, ds_max, lying, round_trip):
    """The body of :func:`pullin_sweep` (the model built, the gaps checked)."""
    budget = model.budget
    L = strip.length_m
    g_max, g_min = float(gaps.max()), float(gaps.min())
    # the start: a gap where the strip is nearly straight
    if far_gap_m is None:
        g_far = max(g_max, 0.25 * L)
        for _ in range(40):
            th = model.linear_guess(g_far)
            if model.tip_deflection_m(th) < 0.02 * g_far:
                break
            g_far *= 1.5
        else:
            raise PathFollowingError("no far gap with a small deflection found", {})
    else:
        g_far = check_positive("far_gap_m", far_gap_m, "m")
        if g_far < g_max:
            raise InputError(f"far_gap_m ({g_far:g} m) must be >= the largest gap of the sweep "
                             f"({g_max:g} m)")
    rs_free = model.EI / L
    tol_gap = 1e-9 * L
    common = dict(ds=0.02, ds_max=ds_max, u_scale=math.sqrt(model.N), p_scale=L,
                  ftol=1e-9, xtol=1e-10, budget=budget)
    budget.stage = "the free branch from the far gap"
    free = trace_branch(model.system_free, model.linear_guess(g_far), g_far, direction=-1.0,
                        p_min=g_min, p_max=4.0 * g_far, r_scale=rs_free,
                        events=[("touch", lambda u, p: model.tip_gap_m(u, p))], **common)
    if free.event is None:
        raise PathFollowingError(f"the free branch did not reach the smallest gap or the face "
                                 f"within its steps ({len(free.p)} points)",
                                 {"what": "the last converged state", "stage": budget.stage,
                                  "gap_m": float(free.p[-1]), "theta_rad": free.u[-1]})
    if free.event.name == "p_max":
        raise PathFollowingError("the free branch left the range of gaps without touching the "
                                 "magnet", {"gap_m": float(free.p[-1]), "theta_rad": free.u[-1]})
    for k in range(len(free.p)):
        model.check_no_other_contact(free.u[k], free.p[k], 1e-6 * strip.thickness_m)
    touched = free.event is not None and free.event.name == "touch"
    g_touch = float(free.event.p) if touched else math.nan
    if free.limit_points:
        g_lost = float(free.limit_points[0].p)
    else:
        g_lost = g_touch
    # contact branch: the tip on the plane of the magnet's face. It is started at the smallest
    # gap (the strip lands there after the snap) and followed opening the gap until the contact
    # force vanishes (release), the branch folds (the contact state disappears: release by a
    # snap-off) or a second point reaches the face
    rs_contact = np.concatenate([np.full(model.N, rs_free), [L]])
    contact = None
    contact_end_gap = release_gap = release_defl = math.nan
    release_by = ""
    contact_top = None
    if touched and g_touch > g_min + tol_gap:
        # first from the touch point of the free branch, closing the gap (zero contact force
        # there): the branch the strip lands on after the snap when it reaches below the
        # pull-in gap
        ls_t = max(model.EI / L**2, abs(model.magnetic_force_N(free.event.u, g_touch)[1]))
        us_t = np.concatenate([np.full(model.N, math.sqrt(model.N)),
                               [CONTACT_FORCE_SCALE * ls_t]])
        budget.stage = "the tip-only contact branch from the touch point, closing"
        try:
            contact_top = trace_branch(
                model.system_contact, np.concatenate([free.event.u, [0.0]]), g_touch,
                direction=-1.0, p_min=g_min, r_scale=rs_contact,
                events=[("other_contact", lambda u, p: model.other_clearance_m(u[:-1], p))],
                stability=lambda u, p, J: (u[-1] >= -1e-9 * ls_t
                                           and model.stable_contact(u, p, J)),
                stop_at_fold=True, max_steps=300, **{**common, "u_scale": us_t})
        except PathBudgetError:
            raise
        except PathFollowingError:
            contact_top = None
        if contact_top is not None and len(contact_top.p) > 1 and contact_top.stable[1] \
                and contact_top.p.min() < g_lost:
            release_by = "contact force zero"
            release_gap, release_defl = g_touch, model.tip_deflection_m(free.event.u)
        if contact_top is not None and contact_top.event is not None \
                and contact_top.event.name == "p_min":
            g_lost = math.nan                       # the whole range is covered
    # a second node of the strip reached the face on the tip-only branch, or it folded: with
    # the strip lying on the face modelled, that takes over from the smallest gap (below),
    # without the tip-only trials from a small gap (~1500 evaluations, and a second node
    # reaches the face there too)
    second_node = (lying and contact_top is not None and contact_top.event is not None
                   and contact_top.event.name in ("other_contact", "fold"))
    if second_node and np.isfinite(g_lost) and g_min < g_lost - tol_gap:
        contact_end_gap = float(contact_top.event.p)
        g_lost = math.nan
    if np.isfinite(g_lost) and g_min < g_lost - tol_gap:
        ls = max(model.EI / L**2, abs(model.magnetic_force_N(np.zeros(model.N), g_min)[1]))
        us = np.concatenate([np.full(model.N, math.sqrt(model.N)), [ls]])
        s_n = model.s[1:]
        u_start = None
        for frac in np.linspace(0.0, 0.9, 10):
            g_start = g_min + frac * (g_lost - g_min)
            d = g_start
            th0 = -(3 * d / (2 * L**3)) * (2 * L * s_n - s_n**2)
            budget.stage = "the tip-only contact at a small gap (a start)"
            try:
                u_try = _solve_damped(model.system_contact, np.concatenate([th0, [0.1 * ls]]),
                                      g_start, rs_contact)
            except PathBudgetError:
                raise
            except PathFollowingError:
                continue
            if u_try[-1] > 0 and model.other_clearance_m(u_try[:-1], g_start) > 0:
                u_start = u_try
                break
        if u_start is not None:
            if frac > 0:
                contact_end_gap = g_start
            budget.stage = "the tip-only contact branch from a small gap, opening"
            try:
                contact = trace_branch(
                    model.system_contact, u_start, g_start, direction=1.0, p_max=g_far,
                    r_scale=rs_contact,
                    events=[("release", lambda u, p: u[-1]),
                            ("other_contact", lambda u, p: model.other_clearance_m(u[:-1], p))],
                    stability=lambda u, p, J: (u[-1] >= -1e-9 * ls
                                               and model.stable_contact(u, p, J)),
                    stop_at_fold=True, max_steps=400, **{**common, "u_scale": us})
            except PathBudgetError:
                raise
            except PathFollowingError:
                # the tip-only contact branch cannot be followed (e.g. an event at a kink of
                # the contact state): the strip lying on the face below takes over from the
                # smallest gap (contact_release)
                contact, contact_end_gap = None, g_start
        if u_start is not None and contact is not None:
            if contact.event is not None and contact.event.name in ("release", "fold") \
                    and not release_by:
                release_by = ("contact force zero" if contact.event.name == "release"
                              else "fold of the contact branch")
                release_gap = float(contact.event.p)
                release_defl = model.tip_deflection_m(contact.event.u[:-1])
            # in the order of the path: closing the gap
            contact = dataclasses.replace(contact, u=contact.u[::-1], p=contact.p[::-1],
                                          dp_ds=-contact.dp_ds[::-1],
                                          stable=contact.stable[::-1])
        elif u_start is None:
            contact_end_gap = g_lost

    # the strip lying on the face: where the tip-only contact above does not reach the
    # smallest gap (a second point of the strip reached the face, or the tip-only branch
    # folded), the distributed contact with an active set, from deep contact at the smallest
    # gap opened until the strip lets go (contact_release); it replaces the tip-only branch
    # from the smallest gap and gives the release gap
    lying_rel = None
    if lying and (np.isfinite(contact_end_gap) or release_by == "fold of the contact branch"):
        g_deep = max(g_min, LYING_MIN_GAP_REL * strip.thickness_m)
        budget.stage = "the strip lying on the face, opened from deep contact"
        try:
            # opened up to the largest gap of the sweep (the sweep goes no further)
            lying_rel = contact_release(model, g_deep, g_max, ds_max=ds_max)
        except PathBudgetError:
            raise
        except PathFollowingError:
            lying_rel = None                  # keep the tip-only result (contact_end_gap says)
        if lying_rel is not None and not lying_rel.release_by \
                and lying_rel.pieces[-1].gap_m[-1] >= g_max - tol_gap:
            # still on the face at the largest gap: no release within the sweep
            lying_rel = dataclasses.replace(lying_rel, release_by=ON_FACE_AT_END)
        if lying_rel is not None and lying_rel.release_by:
            contact = None
            release_gap, release_by = lying_rel.release_gap_m, lying_rel.release_by
            release_defl = lying_rel.release_tip_deflection_m
            contact_end_gap = g_deep if g_deep > g_min + tol_gap else math.nan
        else:
            lying_rel = None

    # the path: the free branch, then the contact branch
    th_rows, gap_l, lam_l, br_l, st_l, part_l = [], [], [], [], [], []
    act_l, nc_l, cl_l = [], [], []
    for k in range(len(free.p)):
        part_l.append(0)
        th_rows.append(free.u[k])
        gap_l.append(free.p[k])
        lam_l.append(0.0)
        br_l.append("free")
        st_l.append(bool(free.stable[k]))
        act_l.append(None)
    for i_part, c_br in enumerate((contact_top, contact)):
        if c_br is None:
            continue
        for k in range(len(c_br.p)):
            part_l.append(1 + i_part)
            th_rows.append(c_br.u[k, :-1])
            gap_l.append(c_br.p[k])
            lam_l.append(c_br.u[k, -1])
            br_l.append("contact")
            st_l.append(bool(c_br.stable[k]))
            act_l.append("tip")
    # the pieces of the strip on the face, in the order of the path (closing the gap: the
    # piece the strip leaves last first, deep contact last)
    for i_piece, pc in enumerate(lying_rel.pieces[::-1] if lying_rel is not None else ()):
        for k in range(len(pc.gap_m) - 1, -1, -1):
            part_l.append(4 + i_piece)
            th_rows.append(np.asarray(pc.theta_rad[k]))
            gap_l.append(float(pc.gap_m[k]))
            lam_l.append(float(pc.contact_force_N[k]))
            br_l.append("contact")
            st_l.append(bool(pc.stable[k]) and pc.n_contact[k] > 0)
            act_l.append(tuple(pc.active[k]))
    for a in act_l:
        if a is None:
            nc_l.append(0)
            cl_l.append(0.0)
        elif a == "tip":
            nc_l.append(1)
            cl_l.append(0.0)
        else:
            nc_l.append(len(a))
            cl_l.append(float(model.s[max(a)] - model.s[min(a)]) if a else 0.0)
    th = np.array(th_rows)
    gap_arr = np.array(gap_l)
    lam_arr = np.array(lam_l)
    br_arr = np.array(br_l)
    st_arr = np.array(st_l, bool)
    defl = np.array([model.tip_deflection_m(x) for x in th])
    tgap = np.array([model.tip_gap_m(x, g) for x, g in zip(th, gap_arr)])
    tip_x = np.array([model.tip_corner(x)[0] for x in th])
    over = _over_face(model.magnet, tip_x, 0.0, strip.width_m)

    # stable segments: runs of stable points of one branch, each monotone in the gap
    segs = []
    k = 0
    while k < len(gap_arr):
        if not st_arr[k]:
            k += 1
            continue
        j = k
        while j + 1 < len(gap_arr) and st_arr[j + 1] and part_l[j + 1] == part_l[k]:
            j += 1
        segs.append((k, j))
        k = j + 1
    if not segs or segs[0][0] != 0:
        raise PathFollowingError("the far end of the free branch is not stable",
                                 {"gap_m": g_far, "theta_rad": free.u[0]})
    lo = [float(gap_arr[a:b + 1].min()) for a, b in segs]
    hi = [float(gap_arr[a:b + 1].max()) for a, b in segs]
    eps = 1e-12 * L

    def contains(i, g):
        return lo[i] - eps <= g <= hi[i] + eps

    def move(i, g, closing):
        """The stable segment holding the state at gap g, coming from segment i."""
        if contains(i, g):
            return i
        order = range(i + 1, len(segs)) if closing else range(i - 1, -1, -1)
        for j in order:
            if contains(j, g):
                return j
        raise PathFollowingError(f"no stable state at the gap {g:g} m on the traced path",
                                 {"gap_m": g})

    # pull-in: where the first (small-deflection) segment ends as the gap closes
    a0, b0 = segs[0]
    first_fold = next((lp for lp in free.limit_points if lp.index == b0 + 1
                       or lp.index == b0), None)
    if first_fold is not None:
        pull_in_gap, pull_in_defl, snap = float(first_fold.p), \
            model.tip_deflection_m(first_fold.u), True
    elif touched and b0 == free.event.index:
        # the tip reached the face on the stable branch: contact without a snap
        pull_in_gap, pull_in_defl, snap = g_touch, model.tip_deflection_m(free.event.u), False
    else:
        pull_in_gap = pull_in_defl = math.nan
        snap = False
    budget.stage = "the states at the sweep's gaps"

    def state_on(i, g):
        """The equilibrium at the gap g on the stable segment i: (theta, total contact force,
        nodes in contact, contact length)."""
        a, b = segs[i]
        guess = _interp_branch(gap_arr[a:b + 1], np.column_stack([th[a:b + 1],
                                                                  lam_arr[a:b + 1]]), g)
        if br_arr[a] == "free":
            return _solve_at(model.system_free, guess[:-1], g, 1e-9, rs_free), 0.0, 0, 0.0
        if act_l[a] == "tip":
            u = _solve_at(model.system_contact, guess, g, 1e-9, rs_contact)
            return u[:-1], float(u[-1]), 1, 0.0
        j = a + int(np.argmin(np.abs(gap_arr[a:b + 1] - g)))
        try:
            u, f_nodes, act = solve_lying(model, g, guess[:-1], act_l[j])
        except PathBudgetError:
            raise
        except PathFollowingError:
            # the interpolated guess mixes two active sets: from the nearest traced state
            u, f_nodes, act = solve_lying(model, g, th[j], act_l[j])
        cl = float(model.s[max(act)] - model.s[min(act)]) if act else 0.0
        return u, float(np.sum(f_nodes)), len(act), cl

    # where the strip lands at pull-in: the stable states at the pull-in gap on the traced
    # path other than the small-deflection one; if one, that one; if several, the nearest in
    # the direction of the snap: the smallest tip deflection beyond the fold's (the strip
    # moves from the fold towards the magnet and stops at the first stable state it meets;
    # for the case of issue 35's CLI check, relax_on_face's gradient flow from the fold lands
    # in that same state, the free strip with its tip beside the magnet's rim -- the flow
    # itself costs ~1500 evaluations, so it is not run here)
    landing_seg = None
    landing = {"kind": "", "tip_deflection_m": math.nan, "tip_gap_m": math.nan,
               "n_contact": -1, "contact_force_N": math.nan}
    if snap and first_fold is not None:
        cands = [i for i in range(1, len(segs)) if contains(i, pull_in_gap)]
        if len(cands) == 1:
            landing_seg = cands[0]
        elif cands:
            budget.stage = "the states at the pull-in gap"
            near = []
            for i in cands:
                a, b = segs[i]
                o = np.argsort(gap_arr[a:b + 1])
                near.append((float(np.interp(pull_in_gap, gap_arr[a:b + 1][o],
                                             defl[a:b + 1][o])), i))
            beyond = [x for x in near if x[0] > pull_in_defl]
            landing_seg = min(beyond or near)[1]
        if landing_seg is not None:
            budget.stage = "the state the strip lands in at pull-in"
            u_l, f_l, nc_l_, _ = state_on(landing_seg, pull_in_gap)
            landing = {"kind": ("free" if nc_l_ == 0 else "tip contact"
                                if act_l[segs[landing_seg][0]] == "tip" or
                                tuple(act_l[segs[landing_seg][0]]) == (model.N,)
                                else "lying on the face"),
                       "tip_deflection_m": model.tip_deflection_m(u_l),
                       "tip_gap_m": model.tip_gap_m(u_l, pull_in_gap),
                       "n_contact": int(nc_l_), "contact_force_N": float(f_l)}

    # snap-back: from contact, opening the gap, the gap at which the state returns to the
    # first segment
    snap_back = math.nan
    cseg = [i for i, (a, b) in enumerate(segs) if br_arr[a] == "contact"]
    if cseg:
        i = cseg[0]
        while i != 0:
            g_end = hi[i] + 1e-9 * L
            try:
                i_new = move(i, g_end, closing=False)
            except PathFollowingError:
                break                     # the traced path does not say where it goes
            if i_new == 0:
                snap_back = hi[i]
            i = i_new

    # the quasi-static sweep
    fwd = [float(g) for g in gaps]
    legs = fwd + (fwd[-2::-1] if round_trip and len(fwd) > 1 else [])
    seg = 0
    g_prev = g_far
    sw_def, sw_tg, sw_lam, sw_br = [], [], [], []
    sw_nc, sw_cl = [], []
    for g in legs:
        closing = g < g_prev
        if seg is not None and not contains(seg, g):
            cands = range(seg + 1, len(segs)) if closing else range(seg - 1, -1, -1)
            if seg == 0 and closing and landing_seg is not None:
                cands = [landing_seg] + [j for j in cands if j != landing_seg]
            seg = next((j for j in cands if contains(j, g)), None)
        elif seg is None and not closing:
            # from beyond the modelled contact (the strip lying on the face), opening the gap
            seg = next((j for j in range(len(segs) - 1, -1, -1) if contains(j, g)), None)
        g_prev = g
        if seg is None:
            sw_def.append(math.nan)
            sw_tg.append(math.nan)
            sw_lam.append(math.nan)
            sw_br.append("unmodelled")
            sw_nc.append(-1)
            sw_cl.append(math.nan)
            continue
        u, lam, nc, cl = state_on(seg, g)
        a = segs[seg][0]
        sw_nc.append(nc)
        sw_cl.append(cl)
        sw_def.append(model.tip_deflection_m(u))
        sw_tg.append(model.tip_gap_m(u, g))
        sw_lam.append(lam)
        sw_br.append(str(br_arr[a]))

    arrays = dict(gap_m=gap_arr, tip_deflection_m=defl, tip_gap_m=tgap,
                  contact_force_N=lam_arr, branch=br_arr, stable=st_arr,
                  tip_x_m=tip_x, tip_over_magnet=over,
                  theta_rad=np.column_stack([np.zeros(len(th)), th]), s_m=model.s.copy(),
                  sweep_gap_m=np.array(legs, float), sweep_tip_deflection_m=np.array(sw_def),
                  sweep_tip_gap_m=np.array(sw_tg), sweep_contact_force_N=np.array(sw_lam),
                  sweep_branch=np.array(sw_br), n_contact=np.array(nc_l, int),
                  contact_length_m=np.array(cl_l, float),
                  sweep_n_contact=np.array(sw_nc, int),
                  sweep_contact_length_m=np.array(sw_cl, float))
    for arr in arrays.values():
        arr.flags.writeable = False
    return PullInResult(**arrays, pull_in_gap_m=pull_in_gap,
                        pull_in_tip_deflection_m=pull_in_defl, snap=snap,
                        release_gap_m=release_gap, release_tip_deflection_m=release_defl,
                        snap_back_gap_m=snap_back, far_gap_m=g_far, release_by=release_by,
                        contact_end_gap_m=contact_end_gap,
                        n_segments=model.N, n_cross=model.n_cross,
                        demag_factor=model.demag, follower=model.follower,
                        contact_jumps_m=tuple(lying_rel.jumps_m) if lying_rel is not None else (),
                        touch_gap_m=g_touch, pull_in_lands_on=landing["kind"],
                        landing_tip_deflection_m=landing["tip_deflection_m"],
                        landing_tip_gap_m=landing["tip_gap_m"],
                        landing_n_contact=landing["n_contact"],
                        landing_contact_force_N=landing["contact_force_N"],
                        evaluations=budget.n)


def interval_ends(E_Pa, M_of_H, E_estimate=None, M_bounds=None) -> dict:
    """The (modulus [Pa], magnetization law) pairs of a pull-in computation and of the two ends
    of its interval: ``{"mean": (E, M), "low": ..., "high": ...}``.

    The magnet's pull grows with the composite's magnetization and the strip's resistance with
    its modulus, so the pull-in gap (and the deflection at a gap) is smallest for the weakest
    magnetization on the stiffest strip and largest for the strongest on the softest:
    ``"low" = (E high, M low)``, ``"high" = (E low, M high)``. ``E_estimate``: a table's
    :class:`homogenize.tables.Estimate` of E_eff (its interval widened by the discretization
    error, ``total_low`` / ``total_high``), or None for a modulus without interval;
    ``M_bounds``: ``{"low": law, "high": law}`` from the ends of the table's M_eff interval, or
    None. Only the mean when neither has an interval."""
    if E_estimate is None and not M_bounds:
        return {"mean": (float(E_Pa), M_of_H)}
    E_lo = E_hi = float(E_Pa)
    if E_estimate is not None:
        E_lo, E_hi = float(E_estimate.total_low), float(E_estimate.total_high)
        if not 0.0 < E_lo <= E_hi:
            raise InputError(f"the modulus interval [{E_lo:.4g}, {E_hi:.4g}] Pa is not positive")
    M_lo = (M_bounds or {}).get("low", M_of_H)
    M_hi = (M_bounds or {}).get("high", M_of_H)
    return {"mean": (float(E_Pa), M_of_H), "low": (E_hi, M_lo), "high": (E_lo, M_hi)}


def place_magnet_xy(magnet, gap_m):
    """The magnet at its own x, y with its top face ``gap_m`` below ``z = 0``."""
    x, y, _ = magnet.position_m
    return dataclasses.replace(magnet, position_m=(x, y, -gap_m - _half_height(magnet)))


# ============================================================================================
# one-mode Galerkin reduced-order model (an independent estimate of the pull-in gap)

@dataclass(frozen=True)
class OneModeResult:
    """One-mode model: ``k q = F(q, g)``. pull_in_gap_m, pull_in_tip_deflection_m [m];
    stiffness_N_m = k [N/m]; contact_gap_m: the gap at which the tip reaches the face on the
    unstable branch (the release gap of this model) [m]."""
    pull_in_gap_m: float
    pull_in_tip_deflection_m: float
    stiffness_N_m: float
    contact_gap_m: float


def one_mode_pullin(strip: Strip, material: ElasticMaterial, magnet: PermanentMagnet, M_of_H,
                    *, n_cross: int = 3, demag_factor: float = 0.0, n_quad: int = 64,
                    plate: bool = False) -> OneModeResult:
    """Pull-in gap of a one-mode Galerkin (Rayleigh-Ritz) model of the strip and magnet.

    Mode: the clamped-free beam under uniform load, ``phi(x) = (6 L^2 x^2 - 4 L x^3 + x^4) /
    (3 L^4)`` (``phi(L) = 1``); displacement ``-q phi(x)`` along z (small rotations, no
    shortening), so ``q`` is the tip deflection. Stiffness ``k = EI int phi''^2 = 3.2 EI /
    L^3`` (the exact tip stiffness under a tip load is 3 EI / L^3: one mode is stiffer).
    Generalized magnetic force ``F(q, g) = w t int_0^L <-f_z>(x, z - q phi) phi dx``, the field
    at the displaced cross-section points (Gauss-Legendre, ``n_quad`` points along x,
    ``n_cross^2`` over the section). Equilibrium ``k q = F``: ``g(q)`` by Brent's method for
    each q; pull-in = ``min_q g(q)`` (bounded Brent), the unstable branch ending where the tip
    reaches the face (``q = g``).
    """
    _check_axis_z(magnet)
    material = _default_material(material)
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    EI = bending_stiffness_N_m2(w, t, material.E_Pa, material.nu, plate)
    k = 3.2 * EI / L**3
    xg, wg = np.polynomial.legendre.leggauss(int(n_quad))
    x = 0.5 * L * (1 + xg)
    wx = 0.5 * L * wg
    phi = (6 * L**2 * x**2 - 4 * L * x**3 + x**4) / (3 * L**4)
    gx, gw = np.polynomial.legendre.leggauss(int(n_cross))
    Y, Z = np.meshgrid(0.5 * w * (1 + gx), 0.5 * t * (1 + gx), indexing="ij")
    om = (np.outer(gw, gw) / 4.0).ravel()
    pts0 = np.empty((x.size, om.size, 3))
    pts0[..., 0] = x[:, None]
    pts0[..., 1] = Y.ravel()[None, :]
    pts0[..., 2] = Z.ravel()[None, :]
    N = check_range("demag_factor", demag_factor, 0.0, 1.0, "")

    def F(q, g):
        src = place_magnet_xy(magnet, g)
        p = pts0.copy()
        p[..., 2] -= q * phi[:, None]
        B, grad = sample_field(src, p.reshape(-1, 3))
        Ha = np.linalg.norm(B, axis=1) / MU0
        M = _call_M(M_of_H, _internal_field(M_of_H, Ha, N))
        fz = -(M * grad[:, 2]).reshape(p.shape[:2])
        return w * t * float(np.sum(wx * phi * (fz @ om)))

    def g_of_q(q):
        # F decreases with the gap; at the touching gap g = q the force is largest
        lo, hi = q * (1 + 1e-12) + 1e-12 * L, max(2 * q, L)
        if k * q > F(q, lo):
            return math.nan
        while k * q < F(q, hi):
            hi *= 2.0
        return brentq(lambda g: F(q, g) - k * q, lo, hi, xtol=1e-14 * L, rtol=1e-13)

    # the end of the branch: k q = F(q, q)
    q_hi = 1e-6 * L
    while k * q_hi < F(q_hi, q_hi * (1 + 1e-12) + 1e-12 * L):
        q_hi *= 1.5
        if q_hi > 10 * L:
            raise PathFollowingError("one-mode model: no end of the free branch found", {})
    q_end = brentq(lambda q: k * q - F(q, q * (1 + 1e-12) + 1e-12 * L), q_hi / 1.5, q_hi,
                   xtol=1e-14 * L)
    res = minimize_scalar(lambda q: g_of_q(q), bounds=(1e-9 * L, q_end * (1 - 1e-9)),
                          method="bounded", options={"xatol": 1e-10 * L})
    return OneModeResult(float(res.fun), float(res.x), k, float(q_end))
