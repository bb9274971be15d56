"""Finite-strain, nearly incompressible elasticity of a specimen: axisymmetric and 3D (scikit-fem).

A solid of revolution about the ``z`` axis is meshed in the ``(r, z)`` half plane (scikit-fem
``MeshTri``; every integral carries the weight ``2 pi r``, the hoop stretch is ``1 + u_r / r``).
The material is a decoupled neo-Hookean solid (shear modulus ``G``, bulk modulus ``K``, possibly
infinite) in a mixed displacement-pressure form with Taylor-Hood elements (P2 displacement, P1
pressure), so that nothing locks as ``nu -> 1/2``. Total Lagrangian, Newton's method on the
consistent tangent (material, pressure, prescribed stress and follower-load parts), load
stepping with step cuts and :class:`ConvergenceError` (with the residual history) when Newton
fails.

* bodies -- :func:`sphere_body`, :func:`spheroid_body`, :func:`cylinder_body`: conforming
  meshes of the quarter section ``r >= 0, z >= 0`` (symmetry planes ``r = 0`` and ``z = 0``) or,
  with ``mid_plane=False``, of the whole section ``r >= 0`` (free body);
* material -- :class:`NeoHookeanSolid` (``G`` and Poisson's ratio, or ``G`` and ``K``);
* loads -- :class:`Traction` (callable of the current position and current normal, a follower
  load; or dead, in the reference configuration; or arrays at the facet quadrature points),
  a body force per reference volume (uniform, callable or array at the element quadrature
  points) and a uniform prescribed stress added to the elastic one (the RVE's magnetic stress),
  all in :class:`Loads`;
* :func:`solve_axisymmetric` -> :class:`AxisymmetricSolution`; observables
  :func:`length_change_m`, :func:`diameter_change_m`, :func:`mean_strain`, :func:`pole_strain`;
* closed forms used by the tests: :func:`uniaxial_stretch` (homogeneous uniaxial state of this
  material law) and :func:`lamb_sphere_strains` (incompressible linear sphere under
  ``p0 cos^2(theta) n``);
* three dimensions, same law, loads and driver on P2/P1 tetrahedra (direct solver: modest
  meshes): :func:`box_body`, :func:`cylinder_body_3d` -> :class:`SolidBody`,
  :func:`solve_3d` -> :class:`Solution3D` (symmetry planes ``x, y, z = 0``, the remaining
  rigid-body modes removed by constraints); the observables take either solution.

Units: SI throughout (m, Pa, N/m^3 for body forces, Pa for tractions and stresses).

Material law (``J = det F``, ``I1 = tr(F^T F)``)::

    W(F, p) = G/2 (J^(-2/3) I1 - 3) + p (J - 1) - p^2 / (2 K)

stationary in ``p`` at ``p = K (J - 1)``, i.e. ``W = G/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2``;
``p`` is the Cauchy mean stress (positive in tension). Small strain: ``sigma = 2 G dev(eps) +
K tr(eps) I`` (linear elasticity with ``nu = (3K - 2G) / (6K + 2G)``); ``K = inf``: the
incompressible neo-Hookean solid, uniaxial nominal stress ``G (lambda - lambda^-2)``.

Coupling with a magnetostatic solve: :func:`element_points` and :func:`facet_points` give the
reference quadrature points at which array loads are expected, :func:`current_facet_points`
where they sit in a solved state; :meth:`AxisymmetricSolution.deformed_mesh` keeps the element
and facet numbering and the boundary names, so a field solved on the deformed mesh with the
same rule (``INTORDER``) can be handed back point by point (a body force per current volume
``f_c`` as ``J f_c`` per reference volume).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import brentq
from scipy.spatial import Delaunay
from skfem import CellBasis, ElementTetP1, ElementTetP2, ElementTriP1, ElementTriP2, \
    FacetBasis, MeshTet, MeshTri

from micro.common.validate import ConvergenceError, InputError, check_choice, check_finite, \
    check_positive, check_range
from micro.materials import ElasticMaterial

__all__ = ["NeoHookeanSolid", "AxisymmetricBody", "sphere_body", "spheroid_body",
           "cylinder_body", "Traction", "Loads", "AxisymmetricSolution", "solve_axisymmetric",
           "element_points", "facet_points", "length_change_m", "diameter_change_m",
           "mean_strain", "pole_strain", "traction_moment_Pa", "uniaxial_stretch",
           "lamb_sphere_strains", "ConvergenceError", "INTORDER", "SolidBody", "box_body",
           "cylinder_body_3d", "Solution3D", "solve_3d", "current_facet_points",
           "deformation_gradient"]

#: Quadrature degree of the element and facet rules (6 points per triangle, 3 per facet): exact
#: for the P2 x P2 stiffness times the weight ``r`` of an undeformed body.
INTORDER = 4

_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------------------------
# material

@dataclass(frozen=True)
class NeoHookeanSolid:
    """Decoupled neo-Hookean solid (see the module docstring for the strain energy).

    Parameters
    ----------
    G_Pa : float -- shear modulus [Pa], > 0
    K_Pa : float -- bulk modulus [Pa], > 0; ``math.inf`` for an incompressible solid

    Build it from Poisson's ratio with :meth:`from_poisson`, from the project's
    :class:`micro.materials.ElasticMaterial` with :meth:`from_material`, or
    :meth:`incompressible`.
    """

    G_Pa: float
    K_Pa: float

    def __post_init__(self):
        check_positive("G_Pa (shear modulus)", self.G_Pa, "Pa")
        if not (isinstance(self.K_Pa, (int, float)) and self.K_Pa == math.inf):
            check_positive("K_Pa (bulk modulus)", self.K_Pa, "Pa")

    @classmethod
    def from_poisson(cls, G_Pa: float, nu: float) -> "NeoHookeanSolid":
        """Shear modulus ``G_Pa`` [Pa] and Poisson's ratio ``nu`` in (-1, 0.5)."""
        G = check_positive("G_Pa (shear modulus)", G_Pa, "Pa")
        nu = check_range("nu (Poisson's ratio)", nu, -1.0, 0.5, "", lo_open=True,
                         hi_open=True)
        return cls(G, 2.0 * G * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu)))

    @classmethod
    def from_material(cls, material: ElasticMaterial) -> "NeoHookeanSolid":
        """The solid with the small-strain constants of ``material`` (E [Pa], nu)."""
        K, G = material.bulk_shear_Pa
        return cls(G, K)

    @classmethod
    def incompressible(cls, G_Pa: float) -> "NeoHookeanSolid":
        """Incompressible solid of shear modulus ``G_Pa`` [Pa] (``K = inf``)."""
        return cls(check_positive("G_Pa (shear modulus)", G_Pa, "Pa"), math.inf)

    @property
    def nu(self) -> float:
        """Small-strain Poisson's ratio [-] (0.5 if incompressible)."""
        if self.K_Pa == math.inf:
            return 0.5
        K, G = self.K_Pa, self.G_Pa
        return (3.0 * K - 2.0 * G) / (6.0 * K + 2.0 * G)

    @property
    def inv_K_per_Pa(self) -> float:
        """1 / K [1/Pa] (0 if incompressible)."""
        return 0.0 if self.K_Pa == math.inf else 1.0 / self.K_Pa


def _material_pointwise(H, p, G):
    """First Piola stress and tangent of the mixed neo-Hookean law at quadrature points.

    ``H = Grad u``, shape (..., 3, 3), ``p`` [Pa], shape (...). Returns ``P`` (..., 3, 3),
    ``A = dP/dF`` at fixed ``p`` (..., 3, 3, 3, 3), ``J - 1`` (...) and ``J F^-T`` (..., 3, 3)
    (the derivative of ``J`` with respect to ``F``).
    """
    F = np.eye(3) + H
    trH = np.trace(H, axis1=-2, axis2=-1)
    I2 = 0.5 * (trH ** 2 - np.einsum("...ij,...ji->...", H, H))
    # J - 1 without cancellation at small strain
    Jm1 = trH + I2 + np.linalg.det(H)
    if np.any(Jm1 <= -1.0):
        raise FloatingPointError("inverted element (J <= 0)")
    J = 1.0 + Jm1
    FiT = np.swapaxes(np.linalg.inv(F), -1, -2)
    I1 = np.einsum("...ij,...ij->...", F, F)
    a = G * J ** (-2.0 / 3.0)
    e = (..., None, None)
    P = a[e] * (F - (I1 / 3.0)[e] * FiT) + (p * J)[e] * FiT
    e4 = (..., None, None, None, None)
    eye = np.eye(3)
    FiT_FiT = np.einsum("...ij,...kl->...ijkl", FiT, FiT)
    FiT_x = np.einsum("...il,...kj->...ijkl", FiT, FiT)
    # d/dF of a (F - I1/3 F^-T) and of p J F^-T; both symmetric in (ij) <-> (kl)
    A = a[e4] * (np.einsum("ik,jl->ijkl", eye, eye)
                 - (2.0 / 3.0) * (np.einsum("...ij,...kl->...ijkl", F, FiT)
                                  + np.einsum("...ij,...kl->...ijkl", FiT, F))
                 + (2.0 / 9.0) * I1[e4] * FiT_FiT + (I1 / 3.0)[e4] * FiT_x) \
        + (p * J)[e4] * (FiT_FiT - FiT_x)
    return P, A, Jm1, J[e] * FiT


def _prescribed_pointwise(H, S, measure):
    """Prescribed stress ``S`` ((3, 3) or shaped like ``H``, in the frame of the kinematics) as
    a first Piola stress and its tangent: ``P = S`` ("piola") or ``P = J S F^-T`` ("cauchy").
    """
    if measure == "piola":
        return np.broadcast_to(S, H.shape), None
    F = np.eye(3) + H
    J = np.linalg.det(F)
    FiT = np.swapaxes(np.linalg.inv(F), -1, -2)
    SF = J[..., None, None] * np.matmul(S, FiT)
    A = (np.einsum("...ij,...kl->...ijkl", SF, FiT) - np.einsum("...il,...kj->...ijkl", SF, FiT))
    return SF, A


# --------------------------------------------------------------------------------------------
# bodies and meshes

@dataclass(frozen=True)
class AxisymmetricBody:
    """A solid of revolution about ``z`` and its mesh in the ``(r, z)`` half plane.

    Parameters
    ----------
    mesh : skfem.MeshTri -- coordinates (r, z) [m]; named boundaries ``"axis"`` (r = 0),
        ``"mid"`` (z = 0, only with ``mid_plane``), ``"surface"`` (the free surface) and, for a
        cylinder, ``"side"``, ``"end"`` (z = +L/2) and ``"end_bottom"`` (z = -L/2, whole
        section only)
    shape : "sphere" | "spheroid" | "cylinder"
    radius_m : float -- equatorial radius / cylinder radius [m]
    half_length_m : float -- polar semi-axis / half of the cylinder length [m]
    mid_plane : bool -- True: the mesh is the quarter ``z >= 0`` with ``u_z = 0`` on ``z = 0``;
        False: the whole section, a free body (its axial translation is removed by the
        solver)
    """

    mesh: MeshTri
    shape: str
    radius_m: float
    half_length_m: float
    mid_plane: bool

    @property
    def volume_m3(self) -> float:
        """Volume of the meshed (polygonal) body of revolution, whole body [m^3]."""
        p, t = self.mesh.p, self.mesh.t
        x = p[:, t]
        area = 0.5 * np.abs((x[0, 1] - x[0, 0]) * (x[1, 2] - x[1, 0])
                            - (x[0, 2] - x[0, 0]) * (x[1, 1] - x[1, 0]))
        v = float(np.sum(_TWO_PI * area * x[0].mean(axis=0)))
        return 2.0 * v if self.mid_plane else v


def _tag(mesh, names):
    """Named boundaries from facet-midpoint predicates, first match wins."""
    bf = mesh.boundary_facets()
    mid = mesh.p[:, mesh.facets[:, bf]].mean(axis=1)
    taken = np.zeros(bf.size, bool)
    out = {}
    for name, pred in names:
        sel = pred(mid) & ~taken
        taken |= sel
        out[name] = bf[sel]
    out["surface"] = bf[~taken]
    return _with_facets(mesh, out)


def _with_facets(mesh, facets: dict):
    return type(mesh)(mesh.p, mesh.t, _boundaries={k: np.asarray(v, dtype=np.int32)
                                                 for k, v in facets.items()})


def _ccw(p, t):
    x = p[:, t]
    det = (x[0, 1] - x[0, 0]) * (x[1, 2] - x[1, 0]) - (x[0, 2] - x[0, 0]) * (x[1, 1] - x[1, 0])
    t = t.copy()
    flip = det < 0
    t[1, flip], t[2, flip] = t[2, flip].copy(), t[1, flip].copy()
    return t, np.abs(det)


def _mirror(p, t, axis):
    """The mesh ``(p, t)`` and its mirror image about the plane ``x_axis = 0``, glued along it
    (nodes on the plane shared): the whole of a body whose half is ``(p, t)``."""
    on = np.abs(p[axis]) <= 1e-12 * np.abs(p).max()
    idx = np.empty(p.shape[1], dtype=np.int64)
    new = np.flatnonzero(~on)
    idx[on] = np.flatnonzero(on)
    idx[new] = p.shape[1] + np.arange(new.size)
    pm = p[:, new].copy()
    pm[axis] *= -1.0
    tm = idx[t][[0, 2, 1] + list(range(3, t.shape[0]))]
    return np.hstack([p, pm]), np.hstack([t, tm])


def _quarter_disk(n, grading):
    """Triangle mesh of the unit quarter disk ``x, y >= 0``: nodes on ``n`` concentric quarter
    circles (radii ``1 - (1 - k/n)^grading``), ring ``k`` with about ``k pi / 2`` equal
    angular steps, Delaunay triangulation (nearly equilateral triangles)."""
    pts = [np.zeros((2, 1))]
    for k in range(1, n + 1):
        rho = 1.0 - (1.0 - k / n) ** grading
        m = max(1, int(math.ceil(rho * n * 0.5 * math.pi)))
        psi = np.linspace(0.0, 0.5 * math.pi, m + 1)
        pts.append(rho * np.vstack([np.sin(psi), np.cos(psi)]))
    p = np.hstack(pts)
    t = Delaunay(p.T).simplices.T.astype(np.int64)
    t, det = _ccw(p, t)
    t = t[:, det > 1e-10 * det.max()]
    if np.unique(t).size != p.shape[1]:
        raise RuntimeError("quarter-disk mesh: a node was left out of the triangulation")
    return p, t


def spheroid_body(radius_m: float, half_length_m: float, n: int = 8, *, mid_plane: bool = True,
                  grading: float = 1.0) -> AxisymmetricBody:
    """Conforming triangle mesh of a spheroid ``(r/a)^2 + (z/c)^2 <= 1``.

    Parameters
    ----------
    radius_m : float -- equatorial semi-axis ``a`` [m], > 0
    half_length_m : float -- polar semi-axis ``c`` [m], > 0
    n : int -- number of rings from the centre to the surface (element size ~ a / n), >= 1
    mid_plane : bool -- quarter section ``z >= 0`` (True) or whole section (False)
    grading : float -- >= 1; ring radii ``1 - (1 - k/n)^grading``: finer near the surface

    Notes
    -----
    Nodes on concentric quarter ellipses, ring ``k`` with about ``k pi / 2`` equal angular
    steps, triangulated by Delaunay in the unit quarter disk and stretched by ``(a, c)``:
    nearly equilateral triangles in a sphere, every boundary node on the spheroid. The whole
    section is the quarter and its mirror image (a symmetric mesh: a symmetric load gives the
    quarter's solution to round-off).
    """
    a = check_positive("radius_m", radius_m, "m")
    c = check_positive("half_length_m", half_length_m, "m")
    n = int(check_positive("n (rings)", n, ""))
    grading = check_range("grading", grading, 1.0, 10.0)
    p, t = _quarter_disk(n, grading)
    if not mid_plane:
        p, t = _mirror(p, t, 1)
    p = p * np.array([[a], [c]])
    mesh = MeshTri(p, np.ascontiguousarray(t))
    tol_r, tol_z = 1e-9 * a, 1e-9 * c
    names = [("axis", lambda x: x[0] < tol_r)]
    if mid_plane:
        names.append(("mid", lambda x: np.abs(x[1]) < tol_z))
    mesh = _tag(mesh, names)
    shape = "sphere" if a == c else "spheroid"
    return AxisymmetricBody(mesh, shape, a, c, bool(mid_plane))


def sphere_body(radius_m: float, n: int = 8, *, mid_plane: bool = True,
                grading: float = 1.0) -> AxisymmetricBody:
    """Conforming triangle mesh of a sphere of radius ``radius_m`` [m] (see
    :func:`spheroid_body`)."""
    return spheroid_body(radius_m, radius_m, n, mid_plane=mid_plane, grading=grading)


def _graded(n, grading):
    """n + 1 points in [0, 1], refined towards 1 (``1 - (1 - s)^grading``)."""
    s = np.linspace(0.0, 1.0, n + 1)
    return 1.0 - (1.0 - s) ** grading


def cylinder_body(radius_m: float, length_m: float, n_r: int = 6, n_z: int | None = None, *,
                  mid_plane: bool = True, grading: float = 1.5) -> AxisymmetricBody:
    """Structured triangle mesh of a finite cylinder (radius ``R``, length ``L``, centred on
    ``z = 0``), graded towards the lateral surface and the end faces (the stress-singular rim).

    Parameters
    ----------
    radius_m : float -- R [m], > 0
    length_m : float -- L [m], > 0 (the end faces at ``z = +-L/2``)
    n_r : int -- elements along the radius, >= 1
    n_z : int or None -- elements along the half length (default: the same size as radially)
    mid_plane : bool -- quarter section ``z >= 0`` (True) or whole section (False)
    grading : float -- >= 1, exponent of :func:`_graded` (1: uniform)
    """
    R = check_positive("radius_m", radius_m, "m")
    L = check_positive("length_m", length_m, "m")
    n_r = int(check_positive("n_r", n_r, ""))
    n_z = max(1, int(round(n_r * 0.5 * L / R))) if n_z is None else \
        int(check_positive("n_z", n_z, ""))
    grading = check_range("grading", grading, 1.0, 10.0)
    r = R * _graded(n_r, grading)
    z = 0.5 * L * _graded(n_z, grading)
    if not mid_plane:
        z = np.concatenate([-z[::-1], z[1:]])
    mesh = MeshTri.init_tensor(r, z)
    tol = 1e-9 * min(R, L)
    names = [("axis", lambda x: x[0] < tol), ("end", lambda x: x[1] > 0.5 * L - tol),
             ("end_bottom", lambda x: x[1] < -0.5 * L + tol), ("side", lambda x: x[0] > R - tol)]
    if mid_plane:
        names.insert(1, ("mid", lambda x: np.abs(x[1]) < tol))
    mesh = _tag(mesh, names)
    b = dict(mesh.boundaries)
    b["surface"] = np.concatenate([b["side"], b["end"], b["end_bottom"]])
    if mid_plane:
        del b["end_bottom"]
    return AxisymmetricBody(_with_facets(mesh, b), "cylinder", R, 0.5 * L, bool(mid_plane))


# --------------------------------------------------------------------------------------------
# loads

@dataclass(frozen=True, eq=False)
class Traction:
    """Surface traction on the facets of one named boundary [Pa].

    Parameters
    ----------
    value : callable or array_like
        * callable ``t(x, n) -> (d, ...)``: the traction [Pa] at positions ``x`` [m], shape
          (d, ...), with unit outward normals ``n``, shape (d, ...) (``d = 2``: (r, z)
          components of an axisymmetric body; ``d = 3``: (x, y, z) of a :class:`SolidBody`);
          ``follower=True``: current position and normal, force per current area;
          ``follower=False``: reference position and normal, force per reference area;
        * array, shape (d, n_facets, n_qp) at the points of :func:`facet_points` (or (d,), one
          vector everywhere): per current area (``follower=True``, direction fixed) or per
          reference area (``follower=False``).
    boundary : str -- name of the boundary (``"surface"``, ``"end"``, ``"side"``, ...)
    follower : bool -- see ``value``

    Notes
    -----
    The follower load's tangent is exact for the change of area, normal and position; a
    callable's own dependence on ``x`` and ``n`` is differentiated by central differences
    (steps ``1e-6`` of the body size and of the normal), so it must be defined for nearby
    non-unit ``n`` (any formula such as ``p0 n_z^2 n`` is).
    """

    value: object
    boundary: str = "surface"
    follower: bool = True

    def __post_init__(self):
        if not callable(self.value):
            check_finite("Traction.value", self.value, "Pa")


@dataclass(frozen=True, eq=False)
class Loads:
    """Everything that loads the body, applied together and scaled by the load factor.

    Parameters
    ----------
    tractions : tuple of :class:`Traction`
    body_force_N_m3 : None, array_like (2,), array (2, n_elements, n_qp) at the points of
        :func:`element_points`, or callable ``f(X) -> (2, ...)`` of the reference position
        ``X`` [m], shape (2, ...) -- dead body force per reference volume [N/m^3] (a force per
        current volume ``f_c`` enters as ``J f_c``)
    prescribed_stress_Pa : None, array_like (3, 3) or array (n_elements, n_qp, 3, 3) -- stress
        added to the elastic one [Pa], Cartesian (x, y, z) components: uniform (3, 3) (for an
        axisymmetric body ``diag(s_t, s_t, s_a)``), or per element quadrature point
        (:func:`element_points`; for an axisymmetric body the components at the point of the
        meridian plane ``y = 0``, where x is r and y is theta: no (x, y), (y, z) shear). The
        body is in equilibrium under the total stress: a free body deforms until its elastic
        stress cancels the prescribed one (a positive ``s_a`` shortens it).
    prescribed_measure : "cauchy" (the true stress in the deformed body, attached to the
        material point) | "piola" (the first Piola-Kirchhoff stress)
    """

    tractions: tuple = ()
    body_force_N_m3: object = None
    prescribed_stress_Pa: object = None
    prescribed_measure: str = "cauchy"

    def __post_init__(self):
        check_choice("prescribed_measure", self.prescribed_measure, ("cauchy", "piola"))
        for t in self.tractions:
            if not isinstance(t, Traction):
                raise InputError(f"Loads.tractions must hold Traction objects, got {t!r}")
        if self.prescribed_stress_Pa is not None:
            S = np.asarray(check_finite("prescribed_stress_Pa", self.prescribed_stress_Pa,
                                        "Pa"), float)
            if S.shape[-2:] != (3, 3) or S.ndim not in (2, 4):
                raise InputError("prescribed_stress_Pa must have shape (3, 3) or (n_elements, "
                                 f"n_qp, 3, 3), got {S.shape}")
        if self.body_force_N_m3 is not None and not callable(self.body_force_N_m3):
            check_finite("body_force_N_m3", self.body_force_N_m3, "N/m^3")

    def _stress_rz_theta(self):
        """The prescribed stress in the (r, z, theta) frame of the kinematics, or None."""
        if self.prescribed_stress_Pa is None:
            return None
        S = np.asarray(self.prescribed_stress_Pa, float)
        scale = max(np.abs(S).max(), 1e-300)
        if S.ndim == 2:
            off = S - np.diag(np.diag(S))
            if np.abs(off).max() > 1e-12 * scale or abs(S[0, 0] - S[1, 1]) > 1e-12 * scale:
                raise InputError("prescribed_stress_Pa of an axisymmetric body must be "
                                 "axisymmetric about z, diag(s_t, s_t, s_a) [Pa]; got "
                                 f"{S.tolist()}")
        elif np.abs(S[..., [0, 1, 1, 2], [1, 0, 2, 1]]).max() > 1e-12 * scale:
            raise InputError("prescribed_stress_Pa at the quadrature points of an axisymmetric "
                             "body must have no (x, y) and (y, z) components (torsion)")
        # (x, y, z) in the meridian plane y = 0 is (r, theta, z): reorder to (r, z, theta)
        return S[..., [0, 2, 1], :][..., :, [0, 2, 1]]


def _cell_bases(mesh):
    ub = CellBasis(mesh, ElementTriP2(), intorder=INTORDER)
    pb = CellBasis(mesh, ElementTriP1(), intorder=INTORDER)
    return ub, pb


def _p2(mesh):
    return ElementTetP2() if isinstance(mesh, MeshTet) else ElementTriP2()


def element_points(body) -> np.ndarray:
    """Quadrature points [m] of the element rule, shape (d, n_elements, n_qp) (``d = 2``:
    (r, z) of an :class:`AxisymmetricBody`; 3: (x, y, z) of a :class:`SolidBody`): where an
    array body force is expected. The same on the deformed mesh (same element order)."""
    elem = ElementTetP1() if isinstance(body.mesh, MeshTet) else ElementTriP1()
    return np.asarray(CellBasis(body.mesh, elem, intorder=INTORDER).global_coordinates())


def facet_points(body, boundary: str = "surface"):
    """Reference quadrature points [m] and unit outward normals of the facets of
    ``boundary``, each shape (d, n_facets, n_qp): where an array traction is expected (facets
    in the order of ``body.mesh.boundaries[boundary]``)."""
    fb = _facet_basis(body, boundary)
    return np.asarray(fb.global_coordinates()), np.asarray(fb.normals)


def current_facet_points(sol, boundary: str = "surface"):
    """Current positions ``x = X + u(X)`` [m] and current unit outward normals of the facet
    quadrature points of ``boundary`` in the solved state ``sol``, each shape
    (d, n_facets, n_qp): where a follower traction is evaluated (the points of
    :func:`facet_points`, moved). Evaluate a field solved on the deformed body there and hand
    it back as an array :class:`Traction` (``follower=True``: per current area)."""
    fb = _facet_basis(sol.body, boundary)
    X, Nn = np.asarray(fb.global_coordinates()), np.asarray(fb.normals)
    u = np.stack([np.asarray(fb.interpolate(ui)) for ui in sol.u_m])
    grads = [np.asarray(fb.interpolate(ui).grad) for ui in sol.u_m]   # each (d, nf, nq)
    H = np.stack(grads)                                                # (i, j, nf, nq)
    F = np.eye(X.shape[0])[:, :, None, None] + H
    # Nanson: n da = J F^-T N dA
    Fm = np.moveaxis(F, (0, 1), (-2, -1))
    a = np.einsum("...ji,j...->i...", np.linalg.inv(Fm), Nn)
    return X + u, a / np.linalg.norm(a, axis=0)


def _facet_basis(body, boundary):
    check_choice("boundary", boundary, tuple(body.mesh.boundaries))
    return FacetBasis(body.mesh, _p2(body.mesh), facets=body.mesh.boundaries[boundary],
                      intorder=INTORDER)


def _eval_field(name, value, points, unit):
    """A load given as (d,), as an array shaped like ``points`` (d, ...) or as a callable of
    them."""
    d = points.shape[0]
    if callable(value):
        out = np.asarray(value(points), float)
    else:
        out = np.asarray(value, float)
        if out.shape == (d,):
            out = np.broadcast_to(out.reshape((d,) + (1,) * (points.ndim - 1)), points.shape)
    if out.shape != points.shape:
        raise InputError(f"{name} must have shape ({d},) or {points.shape}, got {out.shape}")
    check_finite(name, out, unit)
    return out


class _FacetLoad:
    """One :class:`Traction` on its facets: force vector and load stiffness."""

    def __init__(self, body, traction: Traction, length_scale):
        fb = _facet_basis(body, traction.boundary)
        self.t = traction
        self.w = np.asarray(fb.dx)                                  # (nf, nq) reference arc
        self.X = np.asarray(fb.global_coordinates())          # (2, nf, nq)
        Nn = np.asarray(fb.normals)
        self.T = np.stack([-Nn[1], Nn[0]])                          # unit tangent, Rot(T) = N
        self.N = np.stack([np.asarray(fb.basis[a][0]) for a in range(fb.Nbfun)])
        self.dNT = np.stack([np.einsum("jfq,jfq->fq", fb.basis[a][0].grad, self.T)
                             for a in range(fb.Nbfun)])             # (nb, nf, nq)
        ed = fb.element_dofs                                        # (nb, nf)
        self.vd = np.stack([2 * ed, 2 * ed + 1], axis=1)            # (nb, 2, nf)
        self.h = 1e-6 * length_scale
        if not traction.follower:
            if callable(traction.value):
                t0 = self._t(self.X, Nn)
                check_finite("traction(X, N)", t0, "Pa")
            else:
                t0 = _eval_field("traction", traction.value, self.X, "Pa")
            g = t0 * (_TWO_PI * self.X[0])                          # per reference arc length
            self.f_dead = self._scatter(np.einsum("afq,fq,ifq->aif", self.N, self.w, g))
        else:
            self.f_dead = None
            if not callable(traction.value):
                self.t_fixed = _eval_field("traction", traction.value, self.X, "Pa")

    def _scatter(self, fe):
        return self.vd.ravel(), fe.ravel()

    def _t(self, x, n):
        out = np.asarray(self.t.value(x, n), float)
        if out.shape != x.shape:
            raise InputError(f"the traction callable must return shape {x.shape}, "
                             f"got {out.shape}")
        return out

    def follower(self, u_nodal, tangent):
        """Force (rows, values) and stiffness (rows, cols, values) at displacement ``u``."""
        ue = u_nodal[self.vd]                                       # (nb, 2, nf)
        x = self.X + np.einsum("aif,afq->ifq", ue, self.N)
        m = self.T + np.einsum("aif,afq->ifq", ue, self.dNT)
        mn = np.sqrt(m[0] ** 2 + m[1] ** 2)
        n = np.stack([m[1], -m[0]]) / mn
        r = x[0]
        if callable(self.t.value):
            t = self._t(x, n)
        else:
            t = self.t_fixed
        s = _TWO_PI * r * mn
        g = t * s
        f = np.einsum("afq,fq,ifq->aif", self.N, self.w, g)
        if not tangent:
            return (self.vd.ravel(), f.ravel()), None
        dg_du = np.zeros((2, 2) + r.shape)                          # [i, k]
        dg_dm = np.zeros((2, 2) + r.shape)
        dg_du[:, 0] += t * (_TWO_PI * mn)
        dg_dm += np.einsum("ifq,kfq->ikfq", t, _TWO_PI * r * m / mn)
        if callable(self.t.value):
            Rot = np.array([[0.0, 1.0], [-1.0, 0.0]])
            dn_dm = (Rot[:, :, None, None] - np.einsum("lfq,kfq->lkfq", n, m / mn)) / mn
            for k in range(2):
                e = np.zeros((2, 1, 1))
                e[k] = 1.0
                dtx = (self._t(x + self.h * e, n) - self._t(x - self.h * e, n)) / (2 * self.h)
                dtn = (self._t(x, n + 1e-6 * e) - self._t(x, n - 1e-6 * e)) / 2e-6
                dg_du[:, k] += dtx * s
                dg_dm += np.einsum("ifq,kfq->ikfq", dtn * s, dn_dm[k])
        # K[a i, b k] = sum_q w N_a (dg_i/du_k N_b + dg_i/dm_k dN_b.T)
        Ke = (np.einsum("afq,fq,ikfq,bfq->aibkf", self.N, self.w, dg_du, self.N)
              + np.einsum("afq,fq,ikfq,bfq->aibkf", self.N, self.w, dg_dm, self.dNT))
        nb = self.N.shape[0]
        rows = np.broadcast_to(self.vd[:, :, None, None, :], (nb, 2, nb, 2, self.vd.shape[2]))
        cols = np.broadcast_to(self.vd[None, None, :, :, :], rows.shape)
        return (self.vd.ravel(), f.ravel()), (rows.ravel(), cols.ravel(), Ke.ravel())


# --------------------------------------------------------------------------------------------
# assembly

class _Mixed:
    """Residual and tangent of the mixed u-p problem, vectorised over elements, in any
    dimension: the kinematics enter only through ``B`` (``Grad v`` of each element dof).

    Unknowns ``[u (n_u, interleaved components), p (n_p), mu (n_c)]``; ``mu`` are the Lagrange
    multipliers of the constraints ``C u = 0`` (rigid-body modes of a free body).

    Parameters (all arrays per element ``e`` and quadrature point ``q``)
    ----------
    dx : (ne, nq) volume weights [m^3]; B : (ne, nq, nm, 3, 3) ``Grad v`` of the element's
    displacement dofs; vd : (ne, nm) their global numbers; psi : (ne, nq, ns) pressure shape
    functions; pd : (ne, ns) their global numbers (offset by n_u); C : (n_c, n_u) constraint
    rows; fixed : Dirichlet dofs (u = 0); f_dead : (n_u + n_p + n_c,) dead load at factor 1;
    facet_loads : objects with ``follower(u, tangent)``; S : prescribed stress in the frame of
    ``B`` (3, 3) or None
    """

    def __init__(self, solid, loads, S, dx, B, vd, psi, pd, n_u, n_p, C, fixed, f_dead,
                 facet_loads, volume):
        self.solid, self.loads, self.S = solid, loads, S
        self.dx, self.B, self.vd, self.psi, self.pd = dx, B, vd, psi, pd
        self.nu_dof, self.np_dof = n_u, n_p
        self.C = C
        self.n = n_u + n_p + C.shape[0]
        self.f_dead = f_dead
        self.facet_loads = facet_loads
        self.volume = volume
        self.displacement_only = psi.shape[-1] == 0
        self.fixed = np.unique(np.asarray(fixed, dtype=np.int64))
        self.free = np.setdiff1d(np.arange(self.n), self.fixed)
        self.free_u = self.free[self.free < n_u]
        self.free_p = self.free[(self.free >= n_u) & (self.free < n_u + n_p)]

    def grad_u(self, x):
        return np.einsum("em,eqmij->eqij", x[self.vd], self.B)

    def residual(self, x, lam, tangent=True):
        """Residual ``r(x; lam)`` and its Jacobian (CSR) at load factor ``lam``."""
        G, invK = self.solid.G_Pa, self.solid.inv_K_per_Pa
        n_u, n_p = self.nu_dof, self.np_dof
        H = self.grad_u(x)
        if self.displacement_only:
            # p = K (J - 1) at the quadrature points: the plain displacement formulation, which
            # locks as nu -> 1/2 (kept as the foil of the locking test)
            F = np.eye(3) + H
            p = self.solid.K_Pa * (np.linalg.det(F) - 1.0)
            P, A, Jm1, dJ = _material_pointwise(H, p, G)
            A = A + self.solid.K_Pa * np.einsum("...ij,...kl->...ijkl", dJ, dJ)
        else:
            p = np.einsum("es,eqs->eq", x[self.pd], self.psi)
            P, A, Jm1, dJ = _material_pointwise(H, p, G)
        if self.S is not None:
            Ps, As = _prescribed_pointwise(H, self.S, self.loads.prescribed_measure)
            P = P + lam * Ps
            if As is not None:
                A = A + lam * As
        r = np.zeros(self.n)
        re = np.einsum("eq,eqij,eqmij->em", self.dx, P, self.B)
        r += np.bincount(self.vd.ravel(), re.ravel(), minlength=self.n)
        rp = np.einsum("eq,eqs,eq->es", self.dx, self.psi, Jm1 - p * invK)
        r += np.bincount(self.pd.ravel(), rp.ravel(), minlength=self.n)
        r -= lam * self.f_dead
        rows, cols, vals = [], [], []
        for fl in self.facet_loads:
            if fl.f_dead is not None:
                continue
            (fr, fv), Kf = fl.follower(x[:n_u], tangent)
            r -= lam * np.bincount(fr, fv, minlength=self.n)
            if tangent:
                rows.append(Kf[0])
                cols.append(Kf[1])
                vals.append(-lam * Kf[2])
        nc = self.C.shape[0]
        if nc:
            mu = x[n_u + n_p:]
            r[:n_u] += self.C.T @ mu
            r[n_u + n_p:] = self.C @ x[:n_u]
        if not tangent:
            return r, None
        T = np.einsum("eqijkl,eqnkl->eqijn", A, self.B)
        Kuu = np.einsum("eq,eqmij,eqijn->emn", self.dx, self.B, T)
        Kup = np.einsum("eq,eqmij,eqij,eqs->ems", self.dx, self.B, dJ, self.psi)
        Kpp = -invK * np.einsum("eq,eqs,eqt->est", self.dx, self.psi, self.psi)
        for blk, rd, cd in ((Kuu, self.vd, self.vd), (Kup, self.vd, self.pd),
                            (np.swapaxes(Kup, 1, 2), self.pd, self.vd), (Kpp, self.pd, self.pd)):
            rows.append(np.broadcast_to(rd[:, :, None], blk.shape).ravel())
            cols.append(np.broadcast_to(cd[:, None, :], blk.shape).ravel())
            vals.append(blk.ravel())
        for j in range(nc):
            iu = np.flatnonzero(self.C[j])
            mj = np.full(iu.size, n_u + n_p + j)
            rows += [iu, mj]
            cols += [mj, iu]
            vals += [self.C[j, iu], self.C[j, iu]]
        K = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.n, self.n)).tocsr()
        return r, K

    def constraint_force(self, x):
        """Nodal forces [N] the constraints exert on the body, shape (n_u,)."""
        if not self.C.shape[0]:
            return np.zeros(self.nu_dof)
        return -self.C.T @ x[self.nu_dof + self.np_dof:]


def _scaled(C, G, size):
    """Constraint rows scaled to the size of the stiffness' entries (G x length): keeps the
    saddle-point system well conditioned; the multipliers' scale is irrelevant."""
    if not C.shape[0]:
        return C
    return C * (G * size / np.abs(C).max(axis=1, keepdims=True))


def _check_stress(S, ne, nq):
    if S is not None and S.ndim == 4 and S.shape != (ne, nq, 3, 3):
        raise InputError(f"prescribed_stress_Pa per quadrature point must have shape "
                         f"({ne}, {nq}, 3, 3) (element_points), got {S.shape}")
    return S


def _axi_assembler(body, solid, loads, displacement_only=False):
    """The axisymmetric problem of ``body``: kinematics (r, z, theta), weight 2 pi r
    (``displacement_only``: no pressure unknowns, the locking foil of the tests)."""
    ub, pb = _cell_bases(body.mesh)
    X = np.asarray(ub.global_coordinates())                         # (2, ne, nq)
    dx = np.asarray(ub.dx) * _TWO_PI * X[0]                         # (ne, nq)
    nb = ub.Nbfun
    N = np.stack([np.asarray(ub.basis[a][0]) for a in range(nb)], axis=-1)
    dN = np.stack([np.asarray(ub.basis[a][0].grad) for a in range(nb)], axis=-1)
    ne, nq = dx.shape
    B = np.zeros((ne, nq, nb, 2, 3, 3))
    B[..., 0, 0, 0] = dN[0]
    B[..., 0, 0, 1] = dN[1]
    B[..., 0, 2, 2] = N / X[0][..., None]                             # hoop: u_r / r
    B[..., 1, 1, 0] = dN[0]
    B[..., 1, 1, 1] = dN[1]
    psi = np.stack([np.asarray(pb.basis[s][0]) for s in range(pb.Nbfun)], -1)
    n_u, n_p = 2 * ub.N, pb.N
    ed = ub.element_dofs.T
    vd = np.stack([2 * ed, 2 * ed + 1], axis=-1).reshape(ne, 2 * nb)
    pd = n_u + pb.element_dofs.T
    if displacement_only:
        if solid.K_Pa == math.inf:
            raise InputError("the displacement formulation needs a finite bulk modulus")
        psi, pd, n_p = psi[..., :0], pd[:, :0], 0
    size = max(body.radius_m, body.half_length_m)
    # free body: int u_z dV = 0 removes the only rigid mode (u_r = const is no rigid motion)
    C = np.zeros((0 if body.mid_plane else 1, n_u))
    if not body.mid_plane:
        C[0] = np.bincount(vd[:, 1::2].ravel(), np.einsum("eq,eqa->ea", dx, N).ravel(),
                           minlength=n_u)
    C = _scaled(C, solid.G_Pa, size)
    n = n_u + n_p + C.shape[0]
    f = np.zeros(n)
    if loads.body_force_N_m3 is not None:
        fb = _eval_field("body_force_N_m3", loads.body_force_N_m3, X, "N/m^3")
        fe = np.einsum("eq,eqa,ieq->eai", dx, N, fb).reshape(ne, 2 * nb)
        f += np.bincount(vd.ravel(), fe.ravel(), minlength=n)
    facet_loads = [_FacetLoad(body, t, size) for t in loads.tractions]
    for fl in facet_loads:
        if fl.f_dead is not None:
            f += np.bincount(fl.f_dead[0], fl.f_dead[1], minlength=n)
    fixed = [2 * ub.get_dofs("axis").all()]                          # u_r = 0 on the axis
    if body.mid_plane:
        fixed.append(2 * ub.get_dofs("mid").all() + 1)                # u_z = 0 on z = 0
    asm_ = _Mixed(solid, loads, _check_stress(loads._stress_rz_theta(), ne, nq), dx,
                  B.reshape(ne, nq, 2 * nb, 3, 3),
                  vd, psi, pd, n_u, n_p, C, np.concatenate(fixed), f, facet_loads,
                  float(dx.sum()))
    asm_.ub, asm_.body = ub, body
    return asm_


def _newton(asm_, load_steps, tol, max_newton, max_cuts, x0=None):
    """Load stepping with Newton's method; returns (x, residuals, load factors, iterations).
    ``x0``: the first iterate (default zero: the undeformed body)."""
    targets = list(_steps(load_steps))
    tol = check_positive("tol", tol, "")
    x = np.zeros(asm_.n) if x0 is None else np.array(x0, float)
    free, fu, fp = asm_.free, asm_.free_u, asm_.free_p
    hist, done = [], []
    lam_done, it_total, cuts = 0.0, 0, 0
    while targets:
        target = targets[0]
        r0, _ = asm_.residual(np.zeros(asm_.n), target, tangent=False)
        ref = np.linalg.norm(r0[fu]) or 1.0
        x_try = x.copy()
        ok, prev = False, np.inf
        try:
            with warnings.catch_warnings():
                # a singular tangent (e.g. past a limit point) is a failed step, not a warning
                warnings.simplefilter("error", spla.MatrixRankWarning)
                warnings.simplefilter("error", RuntimeWarning)
                for _ in range(max_newton):
                    r, K = asm_.residual(x_try, target)
                    rel = max(np.linalg.norm(r[fu]) / ref,
                              np.linalg.norm(r[fp]) / asm_.volume)
                    hist.append(float(rel))
                    # converged, or stalled at the round-off floor
                    if rel < tol or (rel < 1e3 * tol and rel > 0.5 * prev):
                        ok = True
                        break
                    prev = rel
                    dx = spla.spsolve(K[free][:, free].tocsc(), -r[free])
                    if not np.all(np.isfinite(dx)):
                        raise FloatingPointError("singular tangent")
                    x_try[free] += dx
                    it_total += 1
        except (FloatingPointError, spla.MatrixRankWarning, RuntimeWarning,
                np.linalg.LinAlgError):
            ok = False
        if ok:
            x, lam_done = x_try, target
            done.append(float(target))
            targets.pop(0)
        else:
            cuts += 1
            if cuts > max_cuts:
                raise ConvergenceError(
                    f"Newton failed at load factor {target:.4g} (last converged "
                    f"{lam_done:.4g}) after {max_cuts} step cuts; last relative residual "
                    f"{hist[-1] if hist else float('nan'):.3g}", hist)
            targets.insert(0, 0.5 * (lam_done + target))
    return x, tuple(hist), tuple(done), it_total


# --------------------------------------------------------------------------------------------
# solution and driver

@dataclass(frozen=True)
class AxisymmetricSolution:
    """Converged state of :func:`solve_axisymmetric`.

    Attributes
    ----------
    body : AxisymmetricBody; solid : NeoHookeanSolid; loads : Loads
    u_m : ndarray, shape (2, N) -- displacement (r, z) [m] at the P2 nodes (``doflocs_m``;
        the first ``n_vertices`` are the mesh vertices)
    p_Pa : ndarray, shape (n_vertices,) -- Cauchy mean stress of the material (pressure field,
        positive in tension) [Pa], without the prescribed stress
    reaction_N : float -- axial force of the free-body constraint [N] (0 with ``mid_plane``):
        minus the net axial load, spread as a uniform body force (d'Alembert's force of a
        freely accelerating body); ~0 for self-equilibrated loads
    load_factors : tuple -- converged load factors; residuals : tuple -- relative Newton
        residuals, first to last; newton_iterations : int
    """

    body: AxisymmetricBody
    solid: NeoHookeanSolid
    loads: Loads
    u_m: np.ndarray
    p_Pa: np.ndarray
    reaction_N: float
    load_factors: tuple
    residuals: tuple
    newton_iterations: int
    basis: object = field(repr=False, compare=False, default=None)

    @property
    def doflocs_m(self) -> np.ndarray:
        """Reference positions (r, z) [m] of the P2 nodes, shape (2, N)."""
        return np.asarray(self.basis.doflocs)

    def displacement_m(self, points_m) -> np.ndarray:
        """Displacement [m] at reference points ``points_m`` [m], shape (d, P) -> (d, P)
        (``d = 2``: (r, z); ``d = 3``: (x, y, z))."""
        d_ = self.u_m.shape[0]
        pts = np.asarray(points_m, float).reshape(d_, -1)
        out = np.empty_like(pts)
        # a point on a node (the pole, the rim) is read off the node: the element finder may
        # miss boundary points by round-off
        d = np.linalg.norm(self.doflocs_m[:, None, :] - pts[:, :, None], axis=0)
        near = np.argmin(d, axis=1)
        on = d[np.arange(pts.shape[1]), near] <= 1e-9 * max(self.body.radius_m,
                                                           self.body.half_length_m)
        out[:, on] = self.u_m[:, near[on]]
        if np.any(~on):
            Pm = self.basis.probes(pts[:, ~on])
            out[:, ~on] = np.vstack([Pm @ self.u_m[i] for i in range(d_)])
        return out

    def deformed_mesh(self) -> MeshTri:
        """The deformed mesh (straight-sided, vertices moved by ``u``), same element and facet
        numbering and boundary names: hand it to a magnetostatic solve."""
        nv = self.body.mesh.p.shape[1]
        return MeshTri(self.body.mesh.p + self.u_m[:, :nv], self.body.mesh.t,
                       _boundaries=dict(self.body.mesh.boundaries))


def _steps(load_steps):
    if isinstance(load_steps, (int, np.integer)):
        n = int(check_positive("load_steps", load_steps, ""))
        return np.arange(1, n + 1) / n
    s = np.asarray(check_finite("load_steps", load_steps, ""), float).ravel()
    if s.size == 0 or np.any(np.diff(s) <= 0) or s[0] <= 0 or abs(s[-1] - 1.0) > 1e-12:
        raise InputError("load_steps must be a positive int or a strictly increasing sequence "
                         f"of load factors in (0, 1] ending at 1; got {s.tolist()}")
    return s


def solve_axisymmetric(body: AxisymmetricBody, solid: NeoHookeanSolid, loads: Loads, *,
                       load_steps=1, tol: float = 1e-10, max_newton: int = 25,
                       max_cuts: int = 6) -> AxisymmetricSolution:
    """Finite-strain equilibrium of ``body`` of ``solid`` under ``loads`` (all scaled together).

    Parameters
    ----------
    body : AxisymmetricBody -- mesh and symmetry (``u_r = 0`` on the axis always; ``u_z = 0``
        on ``z = 0`` if ``body.mid_plane``, else the axial translation is removed by
        ``int u_z dV = 0``)
    solid : NeoHookeanSolid
    loads : Loads
    load_steps : int or sequence -- number of equal load increments, or the strictly increasing
        load factors in (0, 1] ending at 1
    tol : float -- Newton stops when the free residual is below ``tol`` times the norm of the
        load at ``u = 0`` and the volumetric residual below ``tol`` times the volume (or
        stalls below ``1000 tol``, the round-off floor)
    max_newton : int -- iterations per increment; max_cuts : int -- halvings of an increment
        that failed before :class:`ConvergenceError` is raised

    Returns
    -------
    AxisymmetricSolution

    Raises
    ------
    InputError (ValueError) -- bad ``load_steps`` or loads; ConvergenceError (RuntimeError) --
    Newton failed after ``max_cuts`` cuts; ``residual_history`` holds the relative residuals.
    """
    if not isinstance(body, AxisymmetricBody):
        raise InputError(f"body must be an AxisymmetricBody, got {type(body).__name__}")
    if not isinstance(solid, NeoHookeanSolid):
        raise InputError(f"solid must be a NeoHookeanSolid, got {type(solid).__name__}")
    asm_ = _axi_assembler(body, solid, loads)
    x, hist, done, its = _newton(asm_, load_steps, tol, max_newton, max_cuts)
    nu = asm_.nu_dof
    u = np.vstack([x[0:nu:2], x[1:nu:2]])
    p = x[nu:nu + asm_.np_dof]
    reaction = float(asm_.constraint_force(x)[1::2].sum())
    return AxisymmetricSolution(body, solid, loads, u, p, reaction, done, hist, its, asm_.ub)


# --------------------------------------------------------------------------------------------
# three dimensions: the same material, loads and driver on tetrahedra

@dataclass(frozen=True)
class SolidBody:
    """A three-dimensional body and its tetrahedral mesh.

    Parameters
    ----------
    mesh : skfem.MeshTet -- coordinates (x, y, z) [m]; named boundaries ``"sym_x"``,
        ``"sym_y"``, ``"sym_z"`` (the symmetry planes ``x = 0`` ... present), ``"end"``
        (z = +c), ``"end_bottom"`` (z = -c, whole body only), ``"side"`` and ``"surface"`` (all
        but the symmetry planes)
    shape : "box" | "cylinder"
    half_extent_m : tuple (a, b, c) -- half sizes along x, y, z [m] (cylinder: (R, R, L/2))
    symmetry : tuple of 3 bool -- ``u_i = 0`` on the plane ``x_i = 0`` (the mesh is the part
        ``x_i >= 0``); rigid-body modes not removed by them are removed by constraints
    """

    mesh: MeshTet
    shape: str
    half_extent_m: tuple
    symmetry: tuple

    @property
    def radius_m(self) -> float:
        """Half size along x [m] (the radius of a cylinder)."""
        return float(self.half_extent_m[0])

    @property
    def half_length_m(self) -> float:
        """Half size along z [m] (the end faces at ``z = +-c``)."""
        return float(self.half_extent_m[2])

    @property
    def volume_m3(self) -> float:
        """Volume of the whole (mirrored) body [m^3]."""
        p, t = self.mesh.p, self.mesh.t
        x = p[:, t]
        v = np.abs(np.einsum("ie,ie->e", x[:, 1] - x[:, 0],
                             np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0], axis=0))).sum() / 6
        return float(v * 2 ** sum(self.symmetry))


def _tag3(mesh, half, symmetric):
    tol = 1e-9 * max(half)
    names = []
    if symmetric:
        names += [("sym_x", lambda x: np.abs(x[0]) < tol), ("sym_y", lambda x: np.abs(x[1]) < tol),
                  ("sym_z", lambda x: np.abs(x[2]) < tol)]
    names += [("end", lambda x: x[2] > half[2] - tol),
              ("end_bottom", lambda x: x[2] < -half[2] + tol)]
    mesh = _tag(mesh, names)
    b = dict(mesh.boundaries)
    b["side"] = b.pop("surface")
    b["surface"] = np.concatenate([b["side"], b["end"], b["end_bottom"]])
    if symmetric:
        del b["end_bottom"]
    return _with_facets(mesh, b)


def box_body(size_m, n=(2, 2, 2), *, symmetric: bool = True, grading: float = 1.0
             ) -> SolidBody:
    """Structured tetrahedral mesh of a box ``size_m = (Lx, Ly, Lz)`` [m] centred on the origin
    (``symmetric``: the octant ``x, y, z >= 0`` with three symmetry planes, ``n`` elements per
    half side; else the whole box, ``2 n`` per side), graded towards the faces."""
    size = np.asarray(check_finite("size_m", size_m, "m"), float).reshape(3)
    for k in range(3):
        check_positive(f"size_m[{k}]", size[k], "m")
    n = np.broadcast_to(np.asarray(n, int), (3,))
    grading = check_range("grading", grading, 1.0, 10.0)
    axes = []
    for k in range(3):
        h = 0.5 * size[k] * _graded(int(check_positive(f"n[{k}]", n[k], "")), grading)
        axes.append(h if symmetric else np.concatenate([-h[::-1], h[1:]]))
    mesh = MeshTet.init_tensor(*axes)
    half = tuple(0.5 * size)
    return SolidBody(_tag3(mesh, half, symmetric), "box", tuple(float(h) for h in half),
                     (bool(symmetric),) * 3)


def cylinder_body_3d(radius_m: float, length_m: float, n_r: int = 3, n_z: int | None = None,
                     *, symmetric: bool = True, grading: float = 1.5,
                     radial_grading: float = 1.0) -> SolidBody:
    """Tetrahedral mesh of a finite cylinder (radius ``R``, length ``L``, axis ``z``, centred
    on the origin): the quarter disk of :func:`spheroid_body` extruded in layers graded
    towards the end faces, each prism split in three tetrahedra by the global node order
    (conforming). ``symmetric``: the part ``x, y, z >= 0`` with three symmetry planes.
    ``radial_grading`` >= 1: the disk's rings at radii ``1 - (1 - k/n_r)^radial_grading``
    (finer towards the side; 1: uniform)."""
    R = check_positive("radius_m", radius_m, "m")
    L = check_positive("length_m", length_m, "m")
    n_r = int(check_positive("n_r", n_r, ""))
    n_z = max(1, int(round(n_r * 0.5 * L / R))) if n_z is None else \
        int(check_positive("n_z", n_z, ""))
    grading = check_range("grading", grading, 1.0, 10.0)
    radial_grading = check_range("radial_grading", radial_grading, 1.0, 10.0)
    p2, t2 = _quarter_disk(n_r, radial_grading)
    if not symmetric:
        p2, t2 = _mirror(p2, t2, 0)
        p2, t2 = _mirror(p2, t2, 1)
    p2 = R * p2
    z = 0.5 * L * _graded(n_z, grading)
    if not symmetric:
        z = np.concatenate([-z[::-1], z[1:]])
    nv = p2.shape[1]
    p = np.vstack([np.tile(p2, z.size), np.repeat(z, nv)])
    a, b, c = np.sort(t2, axis=0)
    tets = []
    for k in range(z.size - 1):
        lo, hi = k * nv, (k + 1) * nv
        tets += [[a + lo, b + lo, c + lo, c + hi], [a + lo, b + lo, b + hi, c + hi],
                 [a + lo, a + hi, b + hi, c + hi]]
    t = np.hstack([np.array(q) for q in tets])
    mesh = MeshTet(p, np.ascontiguousarray(t))
    return SolidBody(_tag3(mesh, (R, R, 0.5 * L), symmetric), "cylinder", (R, R, 0.5 * L),
                     (bool(symmetric),) * 3)


_EPS3 = np.zeros((3, 3, 3))
_EPS3[0, 1, 2] = _EPS3[1, 2, 0] = _EPS3[2, 0, 1] = 1.0
_EPS3[0, 2, 1] = _EPS3[2, 1, 0] = _EPS3[1, 0, 2] = -1.0


class _FacetLoad3D:
    """One :class:`Traction` on triangular facets of a tetrahedral mesh (3 components)."""

    def __init__(self, body, traction: Traction, length_scale):
        check_choice("boundary", traction.boundary, tuple(body.mesh.boundaries))
        fb = FacetBasis(body.mesh, ElementTetP2(), facets=body.mesh.boundaries[traction.boundary],
                        intorder=INTORDER)
        self.t = traction
        self.w = np.asarray(fb.dx)
        self.X = np.asarray(fb.global_coordinates())
        Nn = np.asarray(fb.normals)
        # orthonormal tangents with T1 x T2 = N
        e = np.zeros_like(Nn)
        k = np.argmin(np.abs(Nn), axis=0)
        np.put_along_axis(e, k[None], 1.0, axis=0)
        T1 = np.cross(Nn, e, axis=0)
        T1 /= np.linalg.norm(T1, axis=0)
        self.T = (T1, np.cross(Nn, T1, axis=0))
        self.N = np.stack([np.asarray(fb.basis[a][0]) for a in range(fb.Nbfun)])
        self.dNT = [np.stack([np.einsum("jfq,jfq->fq", fb.basis[a][0].grad, T)
                              for a in range(fb.Nbfun)]) for T in self.T]
        ed = fb.element_dofs
        self.vd = np.stack([3 * ed, 3 * ed + 1, 3 * ed + 2], axis=1)    # (nb, 3, nf)
        self.h = 1e-6 * length_scale
        if not traction.follower:
            if callable(traction.value):
                t0 = _FacetLoad._t(self, self.X, Nn)
                check_finite("traction(X, N)", t0, "Pa")
            else:
                t0 = _eval_field("traction", traction.value, self.X, "Pa")
            self.f_dead = (self.vd.ravel(),
                           np.einsum("afq,fq,ifq->aif", self.N, self.w, t0).ravel())
        else:
            self.f_dead = None
            if not callable(traction.value):
                self.t_fixed = _eval_field("traction", traction.value, self.X, "Pa")

    _t = _FacetLoad._t

    def follower(self, u, tangent):
        ue = u[self.vd]                                             # (nb, 3, nf)
        x = self.X + np.einsum("aif,afq->ifq", ue, self.N)
        m1, m2 = (T + np.einsum("aif,afq->ifq", ue, d) for T, d in zip(self.T, self.dNT))
        a = np.cross(m1, m2, axis=0)                                # J F^-T N per ref. area
        an = np.linalg.norm(a, axis=0)
        n = a / an
        t = self._t(x, n) if callable(self.t.value) else self.t_fixed
        f = np.einsum("afq,fq,ifq->aif", self.N, self.w, t * an)
        if not tangent:
            return (self.vd.ravel(), f.ravel()), None
        dg_dx = np.zeros((3, 3) + an.shape)
        dg_da = np.einsum("ifq,lfq->ilfq", t, n)
        if callable(self.t.value):
            proj = np.eye(3)[:, :, None, None] - np.einsum("mfq,lfq->mlfq", n, n)
            for k in range(3):
                e = np.zeros((3, 1, 1))
                e[k] = 1.0
                dtx = (self._t(x + self.h * e, n) - self._t(x - self.h * e, n)) / (2 * self.h)
                dtn = (self._t(x, n + 1e-6 * e) - self._t(x, n - 1e-6 * e)) / 2e-6
                dg_dx[:, k] = dtx * an
                dg_da += np.einsum("ifq,lfq->ilfq", dtn, proj[k])
        da_dm1 = np.einsum("lkj,jfq->lkfq", _EPS3, m2)
        da_dm2 = np.einsum("ljk,jfq->lkfq", _EPS3, m1)
        Ke = np.einsum("afq,fq,ikfq,bfq->aibkf", self.N, self.w, dg_dx, self.N)
        for da, dN in ((da_dm1, self.dNT[0]), (da_dm2, self.dNT[1])):
            dg_dm = np.einsum("ilfq,lkfq->ikfq", dg_da, da)
            Ke += np.einsum("afq,fq,ikfq,bfq->aibkf", self.N, self.w, dg_dm, dN)
        nb = self.N.shape[0]
        rows = np.broadcast_to(self.vd[:, :, None, None, :], (nb, 3, nb, 3, self.vd.shape[2]))
        cols = np.broadcast_to(self.vd[None, None, :, :, :], rows.shape)
        return (self.vd.ravel(), f.ravel()), (rows.ravel(), cols.ravel(), Ke.ravel())


def _tet_assembler(body, solid, loads):
    """The problem of a :class:`SolidBody`: P2/P1 tetrahedra, Cartesian kinematics."""
    mesh = body.mesh
    ub = CellBasis(mesh, ElementTetP2(), intorder=INTORDER)
    pb = CellBasis(mesh, ElementTetP1(), intorder=INTORDER)
    X = np.asarray(ub.global_coordinates())                         # (3, ne, nq)
    dx = np.asarray(ub.dx)
    nb = ub.Nbfun
    N = np.stack([np.asarray(ub.basis[a][0]) for a in range(nb)], axis=-1)
    dN = np.stack([np.asarray(ub.basis[a][0].grad) for a in range(nb)], axis=-1)
    ne, nq = dx.shape
    B = np.zeros((ne, nq, nb, 3, 3, 3))
    for i in range(3):
        for j in range(3):
            B[..., i, i, j] = dN[j]
    psi = np.stack([np.asarray(pb.basis[s][0]) for s in range(pb.Nbfun)], -1)
    n_u, n_p = 3 * ub.N, pb.N
    ed = ub.element_dofs.T
    vd = np.stack([3 * ed, 3 * ed + 1, 3 * ed + 2], axis=-1).reshape(ne, 3 * nb)
    pd = n_u + pb.element_dofs.T
    fixed = [3 * ub.get_dofs(f"sym_{c}").all() + k
             for k, c in enumerate("xyz") if body.symmetry[k]]
    fixed = np.concatenate(fixed) if fixed else np.zeros(0, np.int64)
    # rigid-body modes e_k and e_k x (X - Xc) not already excluded by the symmetry planes,
    # removed by int mode . u dV = 0
    Xc = np.einsum("eq,ieq->i", dx, X) / dx.sum()
    loc = np.asarray(ub.doflocs) - Xc[:, None]
    rows = []
    for k in range(6):
        e = np.eye(3)[k % 3]
        mode_q = (np.broadcast_to(e[:, None, None], X.shape) if k < 3
                  else np.cross(e[:, None, None], X - Xc[:, None, None], axis=0))
        mode_n = (np.broadcast_to(e[:, None], loc.shape) if k < 3
                  else np.cross(e[:, None], loc, axis=0))
        vals = np.ravel(mode_n.T)                                    # interleaved dofs
        if np.abs(vals[fixed]).max(initial=0.0) > 1e-9 * max(body.half_extent_m):
            continue                                                 # excluded by symmetry
        ce = np.einsum("eq,eqa,ieq->eai", dx, N, mode_q).reshape(ne, 3 * nb)
        rows.append(np.bincount(vd.ravel(), ce.ravel(), minlength=n_u))
    C = _scaled(np.array(rows).reshape(len(rows), n_u), solid.G_Pa, max(body.half_extent_m))
    n = n_u + n_p + C.shape[0]
    f = np.zeros(n)
    if loads.body_force_N_m3 is not None:
        fbv = _eval_field("body_force_N_m3", loads.body_force_N_m3, X, "N/m^3")
        fe = np.einsum("eq,eqa,ieq->eai", dx, N, fbv).reshape(ne, 3 * nb)
        f += np.bincount(vd.ravel(), fe.ravel(), minlength=n)
    facet_loads = [_FacetLoad3D(body, t, max(body.half_extent_m)) for t in loads.tractions]
    for fl in facet_loads:
        if fl.f_dead is not None:
            f += np.bincount(fl.f_dead[0], fl.f_dead[1], minlength=n)
    S = None if loads.prescribed_stress_Pa is None else _check_stress(
        np.asarray(loads.prescribed_stress_Pa, float), ne, nq)
    asm_ = _Mixed(solid, loads, S, dx, B.reshape(ne, nq, 3 * nb, 3, 3), vd, psi, pd, n_u, n_p,
                  C, fixed, f, facet_loads, float(dx.sum()))
    asm_.ub, asm_.body = ub, body
    return asm_


@dataclass(frozen=True)
class Solution3D:
    """Converged state of :func:`solve_3d`.

    Attributes
    ----------
    body : SolidBody; solid : NeoHookeanSolid; loads : Loads
    u_m : ndarray, shape (3, N) -- displacement [m] at the P2 nodes (``doflocs_m``)
    p_Pa : ndarray, shape (n_vertices,) -- Cauchy mean stress of the material [Pa]
    reaction_force_N, reaction_moment_N_m : ndarray (3,) -- resultant force [N] and moment about
        the origin [N m] of the rigid-mode constraints (minus the net load; ~0 when
        self-equilibrated)
    load_factors, residuals : tuple; newton_iterations : int
    """

    body: SolidBody
    solid: NeoHookeanSolid
    loads: Loads
    u_m: np.ndarray
    p_Pa: np.ndarray
    reaction_force_N: np.ndarray
    reaction_moment_N_m: np.ndarray
    load_factors: tuple
    residuals: tuple
    newton_iterations: int
    basis: object = field(repr=False, compare=False, default=None)

    @property
    def doflocs_m(self) -> np.ndarray:
        """Reference positions [m] of the P2 nodes, shape (3, N)."""
        return np.asarray(self.basis.doflocs)

    displacement_m = AxisymmetricSolution.displacement_m

    def deformed_mesh(self) -> MeshTet:
        """The deformed mesh (vertices moved by ``u``), same numbering and boundary names."""
        nv = self.body.mesh.p.shape[1]
        return MeshTet(self.body.mesh.p + self.u_m[:, :nv], self.body.mesh.t,
                       _boundaries=dict(self.body.mesh.boundaries))


def solve_3d(body: SolidBody, solid: NeoHookeanSolid, loads: Loads, *, load_steps=1,
             tol: float = 1e-10, max_newton: int = 25, max_cuts: int = 6,
             initial: Solution3D | None = None) -> Solution3D:
    """Finite-strain equilibrium of a three-dimensional ``body`` (see
    :func:`solve_axisymmetric`; same material law, loads, load stepping and errors).

    Tractions and body forces have three components (x, y, z); ``prescribed_stress_Pa`` may be
    any (3, 3) stress, uniform or per quadrature point. Symmetry planes of ``body`` carry
    ``u_i = 0``; the rigid-body modes they leave free are removed by ``int mode . u dV = 0``
    (a net load is balanced by the constraint forces, reported in ``reaction_force_N`` and
    ``reaction_moment_N_m``). Direct sparse solver (SuperLU): meant for meshes of up to a
    few thousand tetrahedra (the constraint rows are dense).

    ``initial`` : a :class:`Solution3D` of the same body and solid (e.g. under nearby loads)
    whose displacement and pressure start Newton instead of the undeformed body (then
    ``load_steps=1`` is the natural choice: the load factor still runs from 0 to 1, but the
    first iterate is already deformed).
    """
    if not isinstance(body, SolidBody):
        raise InputError(f"body must be a SolidBody, got {type(body).__name__}")
    if not isinstance(solid, NeoHookeanSolid):
        raise InputError(f"solid must be a NeoHookeanSolid, got {type(solid).__name__}")
    asm_ = _tet_assembler(body, solid, loads)
    x0 = None
    if initial is not None:
        if not isinstance(initial, Solution3D) or initial.u_m.shape[1] * 3 != asm_.nu_dof \
                or initial.p_Pa.size != asm_.np_dof:
            raise InputError("initial must be a Solution3D of the same body mesh")
        x0 = np.zeros(asm_.n)
        x0[:asm_.nu_dof] = initial.u_m.T.ravel()
        x0[asm_.nu_dof:asm_.nu_dof + asm_.np_dof] = initial.p_Pa
    x, hist, done, its = _newton(asm_, load_steps, tol, max_newton, max_cuts, x0)
    nu = asm_.nu_dof
    u = np.vstack([x[i:nu:3] for i in range(3)])
    fc = asm_.constraint_force(x).reshape(-1, 3).T                   # (3, N) nodal forces
    # X = sum_a N_a X_a exactly (affine elements): the moment is sum_a X_a x f_a
    moment = np.cross(np.asarray(asm_.ub.doflocs), fc, axis=0).sum(axis=1)
    return Solution3D(body, solid, loads, u, x[nu:nu + asm_.np_dof], fc.sum(axis=1), moment,
                      done, hist, its, asm_.ub)


# --------------------------------------------------------------------------------------------
# observables

def _is3(sol):
    return isinstance(sol, Solution3D)


def _facet_mean(sol, name, comp):
    """Area mean of displacement component ``comp`` over the reference facets ``name``."""
    mesh = sol.body.mesh
    elem = ElementTetP2() if _is3(sol) else ElementTriP2()
    fb = FacetBasis(mesh, elem, facets=mesh.boundaries[name], intorder=INTORDER)
    u = np.asarray(fb.interpolate(sol.u_m[comp]))
    w = np.asarray(fb.dx) * (1.0 if _is3(sol) else np.asarray(fb.global_coordinates())[0])
    return float(np.sum(u * w) / np.sum(w))


def length_change_m(sol) -> tuple[float, float]:
    """Change of length between the end faces [m]: (on the axis, mean over the end faces).

    ``sol`` : :class:`AxisymmetricSolution` or :class:`Solution3D`. On the axis:
    ``u_z(axis, z_top) - u_z(axis, z_bottom)``; the face mean is the area mean of ``u_z`` over
    the end faces (cylinder and box; ``nan`` for a sphere or spheroid, whose "end faces" are
    the poles). With a mid-plane symmetry the bottom half is the mirror image.
    """
    b = sol.body
    c = b.half_length_m
    if _is3(sol):
        zsym = b.symmetry[2]
        top = sol.displacement_m([[0.0], [0.0], [c]])[2, 0]
        bot = -top if zsym else sol.displacement_m([[0.0], [0.0], [-c]])[2, 0]
        comp = 2
    else:
        zsym = b.mid_plane
        top = sol.displacement_m([[0.0], [c]])[1, 0]
        bot = -top if zsym else sol.displacement_m([[0.0], [-c]])[1, 0]
        comp = 1
    if b.shape not in ("cylinder", "box"):
        return float(top - bot), float("nan")
    mt = _facet_mean(sol, "end", comp)
    mb = -mt if zsym else _facet_mean(sol, "end_bottom", comp)
    return float(top - bot), mt - mb


def diameter_change_m(sol) -> float:
    """Change of the diameter at mid-height / at the equator (``z = 0``) [m]: ``2 u_r(R, 0)``
    (three dimensions: ``2 u_x(a, 0, 0)``, the width along x of a box)."""
    if _is3(sol):
        return float(2.0 * sol.displacement_m([[sol.body.radius_m], [0.0], [0.0]])[0, 0])
    return float(2.0 * sol.displacement_m([[sol.body.radius_m], [0.0]])[0, 0])


def pole_strain(sol) -> float:
    """Axial displacement of the upper pole over the polar semi-axis, ``u_z(0, c) / c`` [-]
    (for a free body, half the change of length over ``c``)."""
    dl, _ = length_change_m(sol)
    return float(0.5 * dl / sol.body.half_length_m)


def mean_strain(sol) -> np.ndarray:
    """Volume mean of the small-strain tensor over the whole body, Cartesian (x, y, z), shape
    (3, 3) [-], from the boundary integral ``(1/V) int sym(u x N) dA`` of the reference body.

    It is the symmetric part of the mean displacement gradient (exact at any strain:
    ``mean(F) = I + (1/V) int u x N dA``). For an axisymmetric field it is
    ``diag(e_t, e_t, e_a)`` with ``e_t = (1/2V) int u_r N_r dA`` and
    ``e_a = (1/V) int u_z N_z dA``; with symmetry planes the meshed part gives the same
    diagonal means, and the off-diagonal ones of the whole body vanish by symmetry.
    """
    b = sol.body
    mesh = b.mesh
    elem = ElementTetP2() if _is3(sol) else ElementTriP2()
    fb = FacetBasis(mesh, elem, facets=mesh.boundary_facets(), intorder=INTORDER)
    X = np.asarray(fb.global_coordinates())
    Nn = np.asarray(fb.normals)
    u = np.stack([np.asarray(fb.interpolate(ui)) for ui in sol.u_m])
    if _is3(sol):
        nsym = sum(b.symmetry)
        V = b.volume_m3 / 2 ** nsym
        g = np.einsum("ifq,jfq,fq->ij", u, Nn, np.asarray(fb.dx)) / V
        e = 0.5 * (g + g.T)
        return np.diag(np.diag(e)) if nsym else e
    w = np.asarray(fb.dx) * _TWO_PI * X[0]
    V = b.volume_m3 / (2.0 if b.mid_plane else 1.0)
    et = 0.5 * float(np.sum(u[0] * Nn[0] * w)) / V
    ea = float(np.sum(u[1] * Nn[1] * w)) / V
    return np.diag([et, et, ea])


def deformation_gradient(sol) -> np.ndarray:
    """Deformation gradient ``F`` [-] at the element quadrature points (:func:`element_points`),
    shape (n_elements, n_qp, 3, 3): components (r, z, theta) of an axisymmetric solution
    (``F_tt = 1 + u_r / r``), (x, y, z) of a 3D one. ``det F = J`` turns a force per current
    volume into one per reference volume; ``F`` pushes the RVE's fields forward."""
    b = sol.basis
    d = sol.u_m.shape[0]
    grads = np.stack([np.asarray(b.interpolate(ui).grad) for ui in sol.u_m])   # (i, j, e, q)
    H = np.zeros(grads.shape[2:] + (3, 3))
    H[..., :d, :d] = np.moveaxis(grads, (0, 1), (-2, -1))
    if d == 2:
        X = np.asarray(b.global_coordinates())
        H[..., 2, 2] = np.asarray(b.interpolate(sol.u_m[0])) / X[0]
    return np.eye(3) + H


def traction_moment_Pa(body: AxisymmetricBody, traction, boundary: str = "surface"):
    """Mean stress of the body from the first moment of a traction on its reference surface,
    ``(1/V) int X x t dA`` (equilibrium without body force), Cartesian, shape (3, 3) [Pa].

    ``traction`` is a callable ``t(X, N)`` of reference points and normals (as a dead
    :class:`Traction`). Axisymmetric: ``diag(s_t, s_t, s_a)`` with
    ``s_t = (1/2V) int r t_r dA``, ``s_a = (1/V) int z t_z dA``.
    """
    fb = _facet_basis(body, boundary)
    X = np.asarray(fb.global_coordinates())
    t = np.asarray(traction(X, np.asarray(fb.normals)), float)
    w = np.asarray(fb.dx) * _TWO_PI * X[0]
    V = body.volume_m3 / (2.0 if body.mid_plane else 1.0)
    st = 0.5 * float(np.sum(X[0] * t[0] * w)) / V
    sa = float(np.sum(X[1] * t[1] * w)) / V
    return np.diag([st, st, sa])


# --------------------------------------------------------------------------------------------
# closed forms

def uniaxial_stretch(solid: NeoHookeanSolid, stress_Pa: float, *, measure: str = "nominal"):
    """Homogeneous uniaxial state of ``solid`` under an axial stress, lateral faces free.

    Parameters
    ----------
    solid : NeoHookeanSolid
    stress_Pa : float -- axial stress [Pa] (positive in tension), nominal (force per reference
        area) or Cauchy (per current area) as ``measure`` says
    measure : "nominal" | "cauchy"

    Returns
    -------
    (lambda_axial, lambda_lateral) : the principal stretches [-]

    Notes
    -----
    Cauchy stress of the law: ``sigma = G J^(-5/3) dev(b) + K (J - 1) I``; the lateral
    stretch makes ``sigma_rr = 0`` (bisection), the axial one the requested stress. For
    ``K = inf``: ``lambda_lat = lambda^-1/2`` and ``P = G (lambda - lambda^-2)``.
    """
    check_choice("measure", measure, ("nominal", "cauchy"))
    s = float(check_finite("stress_Pa", stress_Pa, "Pa"))
    G, K = solid.G_Pa, solid.K_Pa

    def lateral(la):
        if K == math.inf:
            return la ** -0.5

        def f(ll):
            J = la * ll * ll
            I1 = la * la + 2 * ll * ll
            return G * J ** (-5 / 3) * (ll * ll - I1 / 3) + K * (J - 1)
        return brentq(f, 1e-3, 1e3, xtol=1e-15, rtol=1e-15)

    def axial_stress(la):
        ll = lateral(la)
        # sigma_zz = sigma_zz - sigma_rr: the pressure cancels (exact for K = inf too)
        sig = G * (la * ll * ll) ** (-5 / 3) * (la * la - ll * ll)
        return sig * ll * ll if measure == "nominal" else sig

    la = brentq(lambda a: axial_stress(a) - s, 0.05, 20.0, xtol=1e-15, rtol=1e-15)
    return float(la), float(lateral(la))


def lamb_sphere_strains(p0_Pa: float, G_Pa: float) -> dict:
    """Incompressible linear elastic sphere under the normal traction ``p0 cos^2(theta) n``.

    The traction is ``(p0/3) n + S P2(cos theta) n`` with ``S = 2 p0 / 3``; the degree-0 part
    strains nothing (incompressible). Lamb's degree-2 solution (``u = grad Phi +
    5/(42 G) r^2 grad p - 2/(21 G) x p`` with ``Phi``, ``p`` multiples of ``r^2 P2``), with
    zero shear traction and the normal traction ``S P2`` at ``r = R``, gives on the surface
    ``u_r = 5 S R / (19 G) P2(cos theta)``, ``u_theta = 3 S R / (38 G) dP2/dtheta`` and the
    volume mean strain ``e_zz = S / (5 G)``.

    Returns
    -------
    dict -- ``"pole"``: ``u_z(pole)/R = (5/57) 2 p0/G``; ``"equator"``: ``u_r(equator)/R =
    -(5/114) 2 p0/G``; ``"mean_axial"``: ``(1/15) 2 p0/G``; ``"mean_transverse"``:
    ``-(1/30) 2 p0/G`` [-]
    """
    p0 = float(check_finite("p0_Pa", p0_Pa, "Pa"))
    G = check_positive("G_Pa", G_Pa, "Pa")
    q = 2.0 * p0 / G
    return {"pole": 5.0 / 57.0 * q, "equator": -5.0 / 114.0 * q, "mean_axial": q / 15.0,
            "mean_transverse": -q / 30.0}
