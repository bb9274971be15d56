"""The cantilever's 3D finite-strain FEM with the magnet's field on the DEFORMED body.

The strip ``[0, L] x [0, w] x [0, t]`` (:class:`~homogenize.macro.cantilever.Strip`), clamped on
``x = 0`` (all displacement components zero, as ``mapsim beam --model neo-hookean``), is the
compressible neo-Hookean solid of :func:`homogenize.macro.fem.neo_hookean_solve` (total
Lagrangian, P1/P2 tetrahedra, the same residual and exact tangent: its assembler). The magnet
(a :class:`~homogenize.macro.magnets.PermanentMagnet`, axis along z, below the strip, its top
face at ``z = -g``) pulls it with the body force of :mod:`homogenize.macro.magnets`,

    ``f(x) = M_eff(H_in) grad |B_a|(x)``  [N/m^3],  ``H_in + N M(H_in) = |H_a|``,

evaluated at the CURRENT position ``x = X + u(X)`` of every quadrature point (a follower load),
per unit reference volume (the particles move with the matrix: their number per reference
volume is fixed; the change of volume ``J - 1`` of the bent strip is ~1e-3 and not applied to
``M``). Self-weight (``rho g`` along -z) is a dead load.

Equilibrium (one gap ``g``): ``R(u) = r_int(u) - F(u, g) = 0`` with ``F_a = int N_a f(X + u)
dV``. It is solved MONOLITHICALLY by Newton's method (not a staggered fixed point: that one
slows down as the fold is approached, its contraction rate tending to 1), with the Jacobian
``K(u) - K_f(u)``, ``K_f = int N_a (d f / d x) N_b dV``, ``d f / d x`` by central differences of
``f`` (step :data:`FD_STEP_REL` ``* min(t, magnet size)``), symmetrised: ``f`` is the gradient of
``W(|B|) = int_0^|B| M db`` (the load is conservative), so the Jacobian is the Hessian of the
total potential energy and a converged state is STABLE when it is positive definite on the
free dofs (checked by the inertia of a symmetric LU factorization: the number of negative
pivots).

Continuation (:func:`follower_fem_at_gap`): from a far gap (the strip nearly straight, Newton
from ``u = 0``) the gap is stepped down to the asked one, each step started from the secant
predictor of the last two converged states. A step whose Newton iteration fails (no
convergence in ``max_newton`` iterations, a growing residual, an inverted element, a point of
the strip below the plane of the magnet's face) or converges to an unstable state is halved.
Near pull-in no equilibrium exists below the fold ``g*``: the steps halve until they are
smaller than ``gap_tol_m``, and the result is the bracket ``[first failed, last converged]``
of the FEM's pull-in gap (a step that failed only because it was too long is retried from
closer, so the bracket is that of the fold, to ``gap_tol_m``; a fold is bracketed, not
traced: the unstable branch beyond it is not computed). No contact in the FEM: below the
bracket the strip has snapped (:mod:`homogenize.macro.pullin` models the contact).

Units: SI (m, N, Pa, T, A/m); names carry them.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis

from homogenize.macro.cantilever import Strip, beam_divisions
from homogenize.macro.fem import (FEMSolution, _NeoHookeanAssembler, box_mesh,
                                  probe_displacement, vector_basis)
from homogenize.macro.magnets import PermanentMagnet
from homogenize.macro.pullin import magnet_below, magnet_body_force
from micro.common.validate import InputError, check_choice, check_positive, check_range
from micro.materials import ElasticMaterial

__all__ = ["FollowerFEM", "FollowerFEMResult", "follower_fem_at_gap", "FD_STEP_REL"]

#: step of the central differences of the force with respect to position (for the Jacobian
#: only), relative to ``min(t, smallest magnet dimension)``: the force varies on the distance
#: to the magnet (>= ~t near pull-in), truncation ~(1e-3)^2, noise ~1e-10 / 1e-3: the Jacobian
#: to ~1e-6; the converged states do not depend on it
FD_STEP_REL = 1e-3


class FollowerFEM:
    """The clamped strip as a 3D neo-Hookean solid in the field of a magnet below it.

    Parameters
    ----------
    strip : Strip [m]; material : ElasticMaterial (E [Pa], nu, density [kg/m^3])
    magnet : PermanentMagnet -- axis along z; its x, y place it (its z is set by the gap)
    M_of_H : callable -- ``M_eff(H)`` [A/m]
    nz, aspect, divisions : the mesh (:func:`~homogenize.macro.cantilever.beam_divisions`:
        ``nz`` layers through the thickness, element aspect <= ``aspect``), or ``divisions``
        (nx, ny, nz) hexahedra of six tetrahedra each, ny across the modelled width (half of
        it when the magnet is centred across the width: mirror plane ``u_y = 0`` at ``y = w/2``)
    order : 1 or 2 (tetrahedron degree)
    demag_factor : ``N`` in ``H_in + N M = |H_a|``, in [0, 1]
    gravity_m_s2 : self-weight along -z (dead), >= 0
    follower : True: the field at the current positions; False: at the reference ones (the
        dead load of ``mapsim beam --model neo-hookean --magnet ...``)
    quad_order : quadrature degree of the magnetic load (default ``order + 2``)
    """

    def __init__(self, strip, material, magnet, M_of_H, *, nz=2, aspect=3.0, divisions=None,
                 order=2, demag_factor=0.0, gravity_m_s2=0.0, follower=True, quad_order=None):
        if not isinstance(strip, Strip):
            raise InputError(f"strip must be a Strip, got {type(strip).__name__}")
        if not isinstance(material, ElasticMaterial):
            raise InputError(f"material must be an ElasticMaterial, got "
                             f"{type(material).__name__}")
        if not isinstance(magnet, PermanentMagnet) or tuple(magnet.axis) != (0.0, 0.0, 1.0):
            raise InputError("the follower FEM needs a permanent magnet with its axis along z "
                             "(below the strip, facing it)")
        if not callable(M_of_H):
            raise InputError("M_of_H must be a callable M(H) [A/m]")
        check_choice("order", order, (1, 2))
        self.demag = check_range("demag_factor", demag_factor, 0.0, 1.0, "")
        gr = check_positive("gravity_m_s2", gravity_m_s2, "m/s^2", allow_zero=True)
        self.strip, self.material, self.magnet, self.M_of_H = strip, material, magnet, M_of_H
        self.follower = bool(follower)
        L, w, t = strip.length_m, strip.width_m, strip.thickness_m
        self.L, self.w, self.t = L, w, t
        self.half = abs(magnet.position_m[1] - 0.5 * w) <= 1e-9 * w
        wm = 0.5 * w if self.half else w
        if divisions is None:
            divisions = beam_divisions(Strip(L, wm, t), nz, aspect)
        self.divisions = tuple(int(d) for d in divisions)
        if len(self.divisions) != 3 or min(self.divisions) < 1:
            raise InputError(f"divisions must be three positive integers, got {divisions}")
        nx, ny, nzz = self.divisions
        mesh = box_mesh(np.linspace(0.0, L, nx + 1), np.linspace(0.0, wm, ny + 1),
                        np.linspace(0.0, t, nzz + 1))
        self.order = int(order)
        self.basis = vector_basis(mesh, self.order)
        lam, mu = material.lame_Pa
        self.asm = _NeoHookeanAssembler(self.basis, lam, mu, np.zeros(3))
        self.n = self.asm.n
        # clamp, and the mirror plane
        x = self.basis.doflocs
        comp = np.arange(x.shape[1]) % 3
        tol = 1e-9 * L
        fixed = x[0] < tol
        if self.half:
            fixed |= (x[1] > wm - tol) & (comp == 1)
        self.free = np.nonzero(~fixed)[0]
        self.node_xyz = x[:, comp == 0]                       # (3, n_nodes) reference
        # the magnetic load's quadrature (its own rule, same dofs)
        q = int(quad_order) if quad_order is not None else self.order + 2
        lb = Basis(mesh, self.basis.elem, intorder=q)
        sb = lb.with_element(lb.elem.elem)
        self.Nq = np.stack([np.asarray(sb.basis[a][0]) for a in range(sb.Nbfun)], axis=-1)
        self.dx = np.asarray(sb.dx)
        self.Xq = np.asarray(sb.global_coordinates())   # (3, ne, nq)
        edofs = sb.element_dofs.T
        nb = sb.Nbfun
        self.vdofs = (3 * edofs[:, :, None] + np.arange(3)).reshape(len(edofs), 3 * nb)
        self.rows = np.repeat(self.vdofs, 3 * nb, axis=1).ravel()
        self.cols = np.tile(self.vdofs, (1, 3 * nb)).ravel()
        self.weight_N_m3 = material.density_kg_m3 * gr
        self.fd_step_m = FD_STEP_REL * min(t, min(magnet.dimensions_m))
        self._dead = {}

    @property
    def n_dof(self) -> int:
        return int(self.n)

    # ------------------------------------------------------------------ the force
    def body_force(self, points_m, gap_m, jacobian=True):
        """``f`` [N/m^3] at points (P, 3) [m] (self-weight included) and ``d f / d x`` (P, 3, 3)
        [N/m^4] (None without ``jacobian``)."""
        f0, D = magnet_body_force(magnet_below(self.magnet, gap_m), self.M_of_H, self.demag,
                                  points_m, self.fd_step_m if jacobian else None)
        f0 = f0.copy()
        f0[:, 2] -= self.weight_N_m3
        if not jacobian:
            return f0, None
        return f0, 0.5 * (D + np.swapaxes(D, 1, 2))

    def _positions(self, u):
        ne, nq, nb = self.Nq.shape
        ue = u[self.vdofs].reshape(ne, nb, 3)
        return self.Xq + np.einsum("eai,eqa->ieq", ue, self.Nq)

    def external(self, u, gap_m, tangent=True):
        """Nodal forces ``F`` (n,) [N] and their derivative ``K_f = dF/du`` (sparse, or None)."""
        ne, nq, nb = self.Nq.shape
        if not self.follower:
            if gap_m not in self._dead:
                f, _ = self.body_force(self.Xq.reshape(3, -1).T, gap_m, jacobian=False)
                fq = f.T.reshape(3, ne, nq)
                fe = np.einsum("eq,eqa,ieq->eai", self.dx, self.Nq, fq).reshape(ne, 3 * nb)
                self._dead[gap_m] = np.bincount(self.vdofs.ravel(), fe.ravel(),
                                                minlength=self.n)
            return self._dead[gap_m], None
        x = self._positions(u)
        f, D = self.body_force(x.reshape(3, -1).T, gap_m, jacobian=tangent)
        fq = f.T.reshape(3, ne, nq)
        fe = np.einsum("eq,eqa,ieq->eai", self.dx, self.Nq, fq).reshape(ne, 3 * nb)
        F = np.bincount(self.vdofs.ravel(), fe.ravel(), minlength=self.n)
        if not tangent:
            return F, None
        Dq = D.reshape(ne, nq, 3, 3)
        ke = np.einsum("eq,eqa,eqij,eqb->eaibj", self.dx, self.Nq, Dq,
                       self.Nq).reshape(ne, 3 * nb, 3 * nb)
        Kf = sp.coo_matrix((ke.ravel(), (self.rows, self.cols)),
                           shape=(self.n, self.n)).tocsr()
        return F, Kf

    def clearance_m(self, u, gap_m):
        """Lowest height of the strip (nodes and load quadrature points) above the plane of the
        magnet's face [m] (< 0: the strip would pass through the magnet)."""
        zn = self.node_xyz[2] + u[2::3]
        zq = self._positions(u)[2]
        return float(min(zn.min(), zq.min()) + gap_m)

    def system(self, u, gap_m):
        """Residual on the free dofs [N], Jacobian (free x free, sparse), load norm [N]."""
        r, K = self.asm.internal(u)
        F, Kf = self.external(u, gap_m)
        fr = self.free
        J = K if Kf is None else K - Kf
        return r[fr] - F[fr], J[fr][:, fr], float(np.linalg.norm(F[fr]))

    def tip_deflection_m(self, u):
        """Displacement of the tip's centre ``(L, w/2, t/2)`` along -z [m]."""
        sol = FEMSolution(np.asarray(u, float), self.basis, "newton")
        yc = 0.5 * self.w * (1 - 1e-9) if self.half else 0.5 * self.w
        pt = np.array([[self.L * (1 - 1e-9)], [yc], [0.5 * self.t]])
        return float(-probe_displacement(sol, pt)[2, 0])

    # ------------------------------------------------------------------ one gap
    def solve(self, gap_m, u0=None, *, tol=1e-8, max_newton=12):
        """Newton at one gap from ``u0`` (default 0). Returns ``(u, iterations, stable)`` or
        None when it fails (see the module docstring)."""
        u = np.zeros(self.n) if u0 is None else np.array(u0, float)
        prev, grow = math.inf, 0
        for it in range(max_newton + 1):
            try:
                R, J, fnorm = self.system(u, gap_m)
            except (FloatingPointError, InputError):
                return None                   # an inverted element, a field beyond a table
            rel = float(np.linalg.norm(R)) / max(fnorm, 1e-300)
            if not math.isfinite(rel):
                return None
            # converged, or stalled at the round-off floor of a slender body (as in
            # neo_hookean_solve)
            if rel < tol or (rel < 1e3 * tol and rel > 0.5 * prev):
                return u, it, self.is_stable(J)
            # two iterations in a row without halving the residual: no quadratic convergence
            # in sight (past the fold, Newton wanders)
            grow = grow + 1 if rel > 0.5 * prev else 0
            if grow >= 2 or it == max_newton:
                return None
            prev = rel
            try:
                du = spla.spsolve(J.tocsc(), -R)
            except RuntimeError:
                return None
            if not np.all(np.isfinite(du)):
                return None
            u = u.copy()
            u[self.free] += du
            if self.clearance_m(u, gap_m) < 0.0:
                return None
        return None

    @staticmethod
    def is_stable(J):
        """Positive definite (the Hessian of the potential energy): no negative pivot of a
        symmetric LU (rows and columns permuted alike), or the smallest eigenvalue."""
        A = sp.csc_matrix(J)
        A = 0.5 * (A + A.T)
        try:
            lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options=dict(SymmetricMode=True))
            if np.array_equal(lu.perm_r, lu.perm_c):
                return bool(np.all(lu.U.diagonal() > 0.0))
        except RuntimeError:
            return False                      # singular: at the fold
        return bool(sla.eigvalsh(A.toarray(), subset_by_index=[0, 0])[0] > 0.0)


@dataclass(frozen=True)
class FollowerFEMResult:
    """Follower FEM at one gap, reached by continuation from ``far_gap_m``.

    gap_m : the asked gap [m]; converged : an equilibrium was found there (False: the gap is
    below the FEM's pull-in bracket, the strip has snapped); tip_deflection_m : at the asked
    gap [m] (nan if not converged); pull_in_bracket_m : (first failed, last converged) [m], or
    None when the asked gap was reached; pull_in_tip_deflection_m : the tip deflection at the
    last converged gap of the bracket [m]; path_gap_m, path_tip_deflection_m : the converged
    states [m]; far_gap_m [m]; newton_iterations : in all; n_dof; divisions; order; follower.
    """
    gap_m: float
    converged: bool
    tip_deflection_m: float
    pull_in_bracket_m: tuple | None
    pull_in_tip_deflection_m: float
    path_gap_m: tuple
    path_tip_deflection_m: tuple
    far_gap_m: float
    newton_iterations: int
    n_dof: int
    divisions: tuple
    order: int
    follower: bool

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def follower_fem_at_gap(model: FollowerFEM, gap_m: float, *, far_gap_m: float | None = None,
                        gap_tol_m: float | None = None, n_initial_steps: int = 6,
                        return_state: bool = False):
    """Continuation of the follower FEM from a far gap down to ``gap_m`` (module docstring).

    far_gap_m : the start (default ``max(gap_m, L)``, enlarged by 1.5x until Newton converges
        from the straight strip); gap_tol_m : width of the pull-in bracket (default 1e-3 L);
    n_initial_steps : the first step is ``(far - gap) / n_initial_steps`` (then 1.5x after each
        success until a failure, halved on failure).
    Returns :class:`FollowerFEMResult` (and the displacement dofs at the last converged gap
    with ``return_state``).
    """
    if not isinstance(model, FollowerFEM):
        raise InputError(f"model must be a FollowerFEM, got {type(model).__name__}")
    g_t = check_positive("gap_m", gap_m, "m", allow_zero=True)
    L = model.L
    tol_g = (check_positive("gap_tol_m", gap_tol_m, "m") if gap_tol_m is not None
             else 1e-3 * L)
    g_far = max(g_t, L) if far_gap_m is None else check_positive("far_gap_m", far_gap_m, "m")
    if g_far < g_t:
        raise InputError(f"far_gap_m ({g_far:g} m) must be >= gap_m ({g_t:g} m)")
    its = 0
    for _ in range(8):
        res = model.solve(g_far)
        if res is not None and res[2]:
            break
        g_far *= 1.5
    else:
        raise InputError("no far gap found where the strip is in a stable equilibrium "
                         "(Newton from the straight strip)")
    u, it, _ = res
    its += it
    gs, us = [g_far], [u]
    dg = (g_far - g_t) / max(int(n_initial_steps), 1)
    failed = None
    while gs[-1] > g_t and dg > 0:
        g_c = gs[-1]
        g_try = max(g_t, g_c - dg)
        if len(us) >= 2:
            guess = us[-1] + (us[-1] - us[-2]) * (g_try - g_c) / (g_c - gs[-2])
        else:
            guess = us[-1]
        res = model.solve(g_try, guess)
        if res is not None and res[2]:
            gs.append(g_try)
            us.append(res[0])
            its += res[1]
            if failed is None:
                dg *= 1.5
            continue
        failed = g_try
        if g_c - g_try <= tol_g:
            break
        dg = 0.5 * (g_c - g_try)
    defl = [model.tip_deflection_m(x) for x in us]
    reached = gs[-1] <= g_t
    out = FollowerFEMResult(
        gap_m=float(g_t), converged=bool(reached),
        tip_deflection_m=defl[-1] if reached else math.nan,
        pull_in_bracket_m=None if reached else (float(failed), float(gs[-1])),
        pull_in_tip_deflection_m=math.nan if reached else defl[-1],
        path_gap_m=tuple(float(g) for g in gs), path_tip_deflection_m=tuple(defl),
        far_gap_m=float(g_far), newton_iterations=int(its), n_dof=model.n_dof,
        divisions=model.divisions, order=model.order, follower=model.follower)
    return (out, us[-1]) if return_state else out
