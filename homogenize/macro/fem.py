"""Three-dimensional finite elements shared by the macro solvers (scikit-fem).

* :func:`box_mesh` -- structured tetrahedral mesh of a box (each hexahedron split in six tets);
* :func:`linear_solve` -- linear isotropic elasticity with P1 or P2 tetrahedra, a body force
  (uniform, or a callable of position: :func:`load_vector`) and
  Dirichlet-fixed dofs, solved directly (SuperLU) or with conjugate gradients preconditioned by
  smoothed-aggregation AMG (pyamg) whose near-null space is the six rigid-body modes;
* :func:`neo_hookean_solve` -- compressible neo-Hookean solid in total-Lagrangian form under a
  dead body force, incremental loading with Newton's method on the exact tangent.

Displacement dofs are interleaved: the dof of component ``i`` at scalar dof ``g`` is ``3 g + i``
(scikit-fem's numbering for ``ElementVector``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import (Basis, ElementTetP1, ElementTetP2, ElementVector, LinearForm, MeshTet, asm,
                   condense)
from skfem.models.elasticity import linear_elasticity

from micro.materials import ElasticMaterial

from micro.common.validate import InputError, check_choice, check_finite, check_positive

from homogenize import solvers
from skfem import BilinearForm
from skfem.helpers import ddot, grad

__all__ = ["Material", "FEMSolution", "box_mesh", "vector_basis", "load_vector", "linear_solve",
           "neo_hookean_solve", "rigid_body_modes", "probe_displacement"]

#: direct sparse factorisation below this many free dofs, AMG-PCG above (``solver="auto"``)
DIRECT_MAX_DOFS = 60000


#: The isotropic elastic solid of every solver (E [Pa], nu, density [kg/m^3]; defaults: the
#: seed's PDMS): one class for the whole project, :class:`micro.materials.ElasticMaterial`.
Material = ElasticMaterial


@dataclass(frozen=True)
class FEMSolution:
    """A displacement field and how it was obtained.

    u_m : (n_dof,) displacement dofs [m] (interleaved); basis : the vector scikit-fem basis;
    solver : "direct" | "amg-pcg" | "newton"; iterations : Krylov or total Newton iterations;
    residuals : convergence history (relative).
    """
    u_m: np.ndarray
    basis: object
    solver: str
    iterations: int = 0
    residuals: tuple = field(default_factory=tuple)
    load_steps: tuple = field(default_factory=tuple)

    @property
    def n_dof(self) -> int:
        return int(self.u_m.size)

    @property
    def n_elements(self) -> int:
        return int(self.basis.mesh.t.shape[1])


def box_mesh(x_m, y_m, z_m) -> MeshTet:
    """Tetrahedral mesh of the tensor grid ``x_m x y_m x z_m`` (node coordinates [m])."""
    return MeshTet.init_tensor(np.asarray(x_m, float), np.asarray(y_m, float),
                               np.asarray(z_m, float))


def vector_basis(mesh, order: int = 2):
    """Vector-valued P1 or P2 basis; quadrature exact for the linear stiffness."""
    check_choice("order", order, (1, 2))
    elem = ElementTetP1() if order == 1 else ElementTetP2()
    return Basis(mesh, ElementVector(elem), intorder=2 * (order - 1) if order > 1 else 1)


def load_vector(basis, body_force_N_m3) -> np.ndarray:
    """Consistent nodal forces ``int N_a f dV`` [N] of a body force on the vector ``basis``.

    Parameters
    ----------
    basis : skfem.Basis -- vector basis from :func:`vector_basis`
    body_force_N_m3 : array_like, shape (3,), or callable -- uniform force per volume [N/m^3],
        or ``f(x) -> array (3, ...)`` of the coordinates ``x`` [m], shape (3, ...) (vectorised over
        quadrature points)

    Returns
    -------
    ndarray, shape (n_dof,) -- interleaved like the displacement dofs

    Notes
    -----
    A uniform force is integrated with the basis' own rule (exact: the integrand has the degree
    of the shape functions). A callable is integrated on the same elements with a rule of degree
    ``order + 3`` (same dof numbering), exact for forces up to cubic in ``x``.
    """
    if callable(body_force_N_m3):
        fun = body_force_N_m3
        order = 1 if isinstance(basis.elem.elem, ElementTetP1) else 2
        lbasis = Basis(basis.mesh, basis.elem, intorder=order + 3)

        @LinearForm
        def load(v, w):
            x = np.asarray(w.x)
            fx = np.asarray(fun(x), dtype=float)
            if fx.shape != x.shape:
                raise InputError(f"the body force callable must return shape {x.shape} "
                                 f"(3, ...) [N/m^3], got {fx.shape}")
            check_finite("body_force_N_m3(x)", fx, "N/m^3")
            vv = np.asarray(v)
            return fx[0] * vv[0] + fx[1] * vv[1] + fx[2] * vv[2]

        return asm(load, lbasis)
    fvec = np.asarray(check_finite("body_force_N_m3", body_force_N_m3, "N/m^3"),
                      float).reshape(3)

    @LinearForm
    def uniform(v, w):
        vv = np.asarray(v)
        return fvec[0] * vv[0] + fvec[1] * vv[1] + fvec[2] * vv[2]

    return asm(uniform, basis)


def rigid_body_modes(basis, dofs=None) -> np.ndarray:
    """The six rigid-body displacement modes (3 translations, 3 rotations), shape (n, 6)."""
    x = basis.doflocs  # (3, n_dof): location of each dof
    n = x.shape[1]
    c = x - x.mean(axis=1, keepdims=True)
    B = solvers.rigid_body_modes(c.T, components=np.arange(n) % 3)
    return B if dofs is None else B[dofs]


#: smoothed aggregation of the condensed P1/P2 stiffness: strength threshold 0 (no stiff
#: inclusions), pyamg's default candidate smoothing and coarsest-level solver, <= 500 unknowns
_AMG = solvers.AMGOptions(symmetry="symmetric", strength_theta=0.0, improve_candidates=True,
                          coarse_solver=None, max_coarse=500)


def _solve_free(K, rhs, fixed, solver, rtol, basis):
    """Solve K u = rhs with u = 0 on ``fixed`` dofs; returns (u, solver, iterations, residuals)."""
    n = K.shape[0]
    free = np.setdiff1d(np.arange(n), fixed)
    Kc, fc, _, I = condense(K, rhs, D=fixed)
    if solver == "auto":
        solver = "direct" if free.size <= DIRECT_MAX_DOFS else "amg-pcg"
    u = np.zeros(n)
    if solver == "direct":
        u[I] = spla.spsolve(Kc.tocsc(), fc)
        return u, "direct", 0, ()
    B = rigid_body_modes(basis, I)
    ml = solvers.smoothed_aggregation(Kc.tocsr(), B, _AMG)
    res = []
    norm_f = np.linalg.norm(fc)

    def cb(xk):
        res.append(float(np.linalg.norm(fc - Kc @ xk) / norm_f))

    x, info = spla.cg(Kc, fc, M=ml.aspreconditioner(cycle="V"), rtol=rtol, maxiter=2000,
                      callback=cb)
    if info != 0:
        raise RuntimeError(f"AMG-preconditioned CG did not converge in {len(res)} iterations "
                           f"(relative residual {res[-1] if res else float('nan'):.3g})")
    u[I] = x
    return u, "amg-pcg", len(res), tuple(res)


def linear_solve(mesh, material: Material, body_force_N_m3, fixed_dofs, *, order=2,
                 solver="auto", rtol=1e-10) -> FEMSolution:
    """Small-strain isotropic elasticity under a body force.

    Parameters
    ----------
    mesh : skfem.MeshTet -- the body [m]
    material : Material
    body_force_N_m3 : array_like, shape (3,), or callable -- force per volume [N/m^3], uniform
        or ``f(x)`` of the coordinates (see :func:`load_vector`)
    fixed_dofs : callable(basis) -> int array -- dofs held at zero displacement
    order : 1 (linear tetrahedra) or 2 (quadratic tetrahedra)
    solver : "auto" | "direct" | "amg-pcg"
    rtol : relative residual of the Krylov solver [-]
    """
    check_choice("solver", solver, ("auto", "direct", "amg-pcg"))
    basis = vector_basis(mesh, order)
    lam, mu = material.lame_Pa
    K = asm(linear_elasticity(lam, mu), basis)
    rhs = load_vector(basis, body_force_N_m3)
    u, name, it, res = _solve_free(K, rhs, fixed_dofs(basis), solver, rtol, basis)
    return FEMSolution(u, basis, name, it, res)


def probe_displacement(sol: FEMSolution, points_m) -> np.ndarray:
    """Displacement [m] at points ``points_m`` (shape (3, P)); returns shape (3, P)."""
    pts = np.asarray(points_m, float).reshape(3, -1)
    sbasis = sol.basis.with_element(sol.basis.elem.elem)
    Pm = sbasis.probes(pts)
    return np.vstack([Pm @ sol.u_m[i::3] for i in range(3)])


# --------------------------------------------------------------------------------------------
# neo-Hookean, total Lagrangian: W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2
#   P = mu (F - F^-T) + lam ln J F^-T
#   dP[H] = mu H + (mu - lam ln J) F^-T H^T F^-T + lam (F^-T : H) F^-T

def _neo_hookean_pointwise(H, lam, mu):
    """First Piola stress and tangent at quadrature points from ``H = grad u``, shape (..., 3, 3).

    Written without cancellation at small strain: ``F - F^-T = (H + H^T + H H^T) F^-T`` and
    ``ln J = log1p(J - 1)`` with ``J - 1 = I1(H) + I2(H) + I3(H)``.
    """
    Fm = np.eye(3) + H
    HT = np.swapaxes(H, -1, -2)
    trH = np.trace(H, axis1=-2, axis2=-1)
    I2 = 0.5 * (trH**2 - np.einsum("...ij,...ji->...", H, H))
    Jm1 = trH + I2 + np.linalg.det(H)
    if np.any(Jm1 <= -1.0):
        raise FloatingPointError("inverted element (J <= 0)")
    FiT = np.swapaxes(np.linalg.inv(Fm), -1, -2)
    lnJ = np.log1p(Jm1)
    P = mu * ((H + HT + H @ HT) @ FiT) + (lam * lnJ)[..., None, None] * FiT
    eye = np.eye(3)
    c = (mu - lam * lnJ)[..., None, None, None, None]
    # A_ijkl = mu d_ik d_jl + (mu - lam lnJ) FiT_il FiT_kj + lam FiT_ij FiT_kl
    A = (mu * np.einsum("ik,jl->ijkl", eye, eye)
         + c * np.einsum("...il,...kj->...ijkl", FiT, FiT)
         + lam * np.einsum("...ij,...kl->...ijkl", FiT, FiT))
    return P, A


class _NeoHookeanAssembler:
    """Residual and tangent of the total-Lagrangian neo-Hookean problem, vectorised."""

    def __init__(self, basis, lam, mu, body_force):
        self.basis = basis
        self.lam, self.mu = lam, mu
        sb = basis.with_element(basis.elem.elem)
        # G[e, q, a, j]: reference gradient of scalar shape function a; N[e, q, a]
        self.G = np.ascontiguousarray(
            np.stack([sb.basis[a][0].grad for a in range(sb.Nbfun)]).transpose(2, 3, 0, 1))
        self.N = np.stack([np.asarray(sb.basis[a][0]) for a in range(sb.Nbfun)]).transpose(1, 2, 0)
        self.dx = sb.dx
        nb = sb.Nbfun
        edofs = sb.element_dofs.T  # (ne, nb)
        self.vdofs = (3 * edofs[:, :, None] + np.arange(3)).reshape(len(edofs), 3 * nb)
        self.rows = np.repeat(self.vdofs, 3 * nb, axis=1).ravel()
        self.cols = np.tile(self.vdofs, (1, 3 * nb)).ravel()
        self.n = 3 * sb.N
        if callable(body_force):
            # dead load varying in the reference configuration: int N_a f(X) dX
            self.f_ext = load_vector(basis, body_force)
        else:
            # dead load: f_i int N_a dX
            fvec = np.asarray(body_force, float).reshape(3)
            fe = np.einsum("eq,eqa,i->eai", self.dx, self.N, fvec).reshape(len(edofs), 3 * nb)
            self.f_ext = np.bincount(self.vdofs.ravel(), fe.ravel(), minlength=self.n)

    def grad_u(self, u):
        ue = u[self.vdofs].reshape(len(self.vdofs), -1, 3)  # (e, a, i)
        return np.einsum("eai,eqaj->eqij", ue, self.G)

    def internal(self, u, tangent=True):
        P, A = _neo_hookean_pointwise(self.grad_u(u), self.lam, self.mu)
        ne, nq, nb = self.G.shape[:3]
        re = np.einsum("eq,eqij,eqaj->eai", self.dx, P, self.G).reshape(ne, 3 * nb)
        r = np.bincount(self.vdofs.ravel(), re.ravel(), minlength=self.n)
        if not tangent:
            return r, None
        # K[e, a, i, b, k] = sum_q dx G[a, j] A[i, j, k, l] G[b, l]
        T = np.einsum("eqijkl,eqbl->eqijkb", A, self.G)
        Ke = np.einsum("eq,eqaj,eqijkb->eaibk", self.dx, self.G, T).reshape(ne, 3 * nb, 3 * nb)
        K = sp.coo_matrix((Ke.ravel(), (self.rows, self.cols)), shape=(self.n, self.n)).tocsr()
        return r, K


def neo_hookean_solve(mesh, material: Material, body_force_N_m3, fixed_dofs, *, order=2,
                      n_steps=5, tol=1e-8, max_newton=25, max_cuts=6, progress=None
                      ) -> FEMSolution:
    """Large-deformation neo-Hookean solution under a dead body force (per reference volume).

    ``body_force_N_m3`` is a uniform vector, shape (3,), or a callable of the reference
    coordinates as in :func:`load_vector` [N/m^3].

    The load is applied in ``n_steps`` equal increments (each halved if Newton fails, at most
    ``max_cuts`` times); each increment is solved by Newton's method until the residual of the
    free dofs is below ``tol`` times the norm of the current external load (or stalls below
    ``1000 tol``, the round-off floor of slender bodies). ``u = 0`` on
    ``fixed_dofs(basis)``. Returns the final state with the Newton history in ``residuals`` and
    the converged load factors in ``load_steps``.
    """
    n_steps = int(check_positive("n_steps", n_steps, ""))
    basis = vector_basis(mesh, order)
    lam, mu = material.lame_Pa
    asmb = _NeoHookeanAssembler(basis, lam, mu, body_force_N_m3)
    fixed = np.asarray(fixed_dofs(basis))
    free = np.setdiff1d(np.arange(asmb.n), fixed)
    fnorm = np.linalg.norm(asmb.f_ext[free]) or 1.0
    u = np.zeros(asmb.n)
    hist, steps = [], []
    lam_done, dlam, cuts, total_it = 0.0, 1.0 / n_steps, 0, 0
    while lam_done < 1.0 - 1e-12:
        target = min(1.0, lam_done + dlam)
        u_try = u.copy()
        ok = False
        try:
            prev = np.inf
            for _ in range(max_newton):
                r, K = asmb.internal(u_try)
                res = r[free] - target * asmb.f_ext[free]
                rel = np.linalg.norm(res) / (target * fnorm)
                hist.append(float(rel))
                # converged, or stalled at the round-off floor (internal nodal forces of a bent
                # strip exceed the external ones by ~ (L/t)^2, which lifts that floor)
                if rel < tol or (rel < 1e3 * tol and rel > 0.5 * prev):
                    ok = True
                    break
                prev = rel
                du = spla.spsolve(K[free][:, free].tocsc(), -res)
                u_try[free] += du
                total_it += 1
        except FloatingPointError:
            ok = False
        if ok:
            u, lam_done = u_try, target
            steps.append(float(target))
            if progress is not None:
                progress(target)
        else:
            cuts += 1
            if cuts > max_cuts:
                raise RuntimeError(f"Newton failed at load factor {target:.3g} after "
                                   f"{max_cuts} step cuts")
            dlam /= 2.0
    return FEMSolution(u, basis, "newton", total_it, tuple(hist), tuple(steps))


def _skfem_neo_hookean(basis, u, lam, mu):
    """Reference: residual and tangent assembled with scikit-fem forms (slow, for checks).

    Same material law, independent assembly (scikit-fem's own loops, quadrature and dof maps).
    """

    def pointwise(w):
        H = np.moveaxis(np.asarray(grad(w["prev"])), (0, 1), (-2, -1))
        return _neo_hookean_pointwise(H, lam, mu)

    @BilinearForm
    def tangent(du, v, w):
        _, A = pointwise(w)
        return np.einsum("...ijkl,kl...,ij...->...", A, grad(du), grad(v))

    @LinearForm
    def residual(v, w):
        P, _ = pointwise(w)
        return ddot(np.moveaxis(P, (-2, -1), (0, 1)), grad(v))

    prev = basis.interpolate(u)
    return asm(residual, basis, prev=prev), asm(tangent, basis, prev=prev)
