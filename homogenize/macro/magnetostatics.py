"""Magnetostatics of a finite magnetizable body and the space around it, and its magnetic loads.

A body (sphere, spheroid, finite cylinder, any star-shaped axisymmetric profile, or a region of
a 3D tetrahedral mesh) sits in an applied field ``H_a`` [A/m]: uniform ``H0`` along ``z``, or any
curl- and divergence-free callable ``H_a(x)`` (e.g. magpylib sources placed away from the body).
Its macroscopic magnetization follows an isotropic, nonlinear law ``M = M(|H|) H / |H|`` [A/m]
(:func:`linear`, :func:`froehlich_kennelly`, :func:`langevin`, :func:`tanh`, or any object with
``M_A_per_m(H)`` and ``dM_dH(H)``), or is imposed (a permanent magnet, ``M_imposed``).

Formulation (reduced scalar potential)
-------------------------------------
``H = H_a - grad phi`` [A/m], ``phi`` [A] vanishing at infinity. Because the sources of ``H_a``
lie outside the body and ``div B_a = 0``, ``div B = 0`` reduces to
``div(grad phi - M(H_a - grad phi)) = 0`` in all space: ``phi`` is the potential of the body's own
magnetization, ``H_a`` only enters through the law's argument. Weak form, for all ``v``::

    R(phi; v) = int (grad phi - M(H)) . grad v dV = 0,

solved by Newton's method with the consistent tangent
``int (I + chi_d) grad dphi . grad v dV``, ``chi_d = dM/dH n n + M/H (I - n n)``, ``n = H / |H|``
(``mu0 (I + chi_d)`` is the differential permeability), and a backtracking line search on the
residual norm; :class:`ConvergenceError` (``residual_history``) if it fails. A linear law
converges in one step (the tangent is the linear operator). Elements: quadratic Lagrange (P2),
so ``H`` is linear per element; the material interface runs along element edges (conforming).

Geometry. Main path: axisymmetric ``(r, z)`` meridian meshes (:class:`skfem.MeshTri`, every
volume integral weighted by ``2 pi r``), field along the axis. The mesh is a structured polar
mesh built here (no gmsh): rays from the body centre through points of the body's meridian
profile (arc-length spacing, corners kept), the body filled by rings ``s P_i``, the air by rings
with geometric grading ``rho_b (R / rho_b)^t`` (element size proportional to the distance to
the centre), so the body boundary is conforming and refined (:func:`axisymmetric_mesh`,
:class:`MeshOptions`). 3D (:class:`skfem.MeshTet`) for bodies without axial symmetry:
:func:`ball_mesh_3d` maps scikit-fem's ball ray by ray onto a star-shaped body and extrudes its
surface triangulation in graded layers out to ``R`` (prisms cut conformingly into tetrahedra);
CG preconditioned by smoothed-aggregation AMG (:func:`homogenize.solvers.smoothed_aggregation`)
solves the tangents, one hierarchy per solve, reused by every Newton step. A general mesh region
enters as a :class:`BodyMesh` built by the caller (mesh of the ball, body elements, Kelvin
exterior).

Outer boundary: exact (Kelvin transformation). The exterior ``|x - c| > R`` is mapped by the
inversion ``x' = R^2 (x - c) / |x - c|^2`` onto a second ball (a half-disk in the meridian
plane) of radius ``R``, glued dof by dof to the first on ``|x - c| = R``; the centre of the
second ball is infinity (``phi = 0``). The map is conformal with scale ``R^2 / |x'|^2``, so
``int |grad phi|^2 dV`` over the exterior becomes ``int |grad' phi|^2 (R^2 / |x'|^2) dV'`` and
``phi(x) = phi'(x')`` is smooth at ``x' = 0`` (a dipole maps to ``m . x' |x'| / R^4``). No
truncation error is left: for a sphere (n_boundary = 32) the measured ``N - 1/3`` is -6.9e-5,
-3.0e-5, -2.4e-5 at ``R = 2a, 4a, 8a`` (discretization only: the air mesh changes with R),
where a grounded sphere at ``R`` (``exterior="dirichlet"``, kept for that comparison) errs by
-4.2e-2, -5.2e-3, -6.7e-4, i.e. ``~ (a / R)^3`` (fitted slope -2.97; tests).

Accuracy (tests): demagnetizing factors of spheres, spheroids and cylinders to < 2e-3 at
``n_boundary = 48`` with second-order convergence (measured rate 2.5); the field of a magnet to
< 1.3e-3 of magpylib's at ``n_boundary = 64``.

Loads (Kelvin formulation, for a body in vacuum)
----------------------------------------------
* body force inside ``f = mu0 (M . grad) H`` [N/m^3] (``H`` the total field; for ``M`` parallel to
  ``H`` and ``curl H = 0`` it equals ``mu0 M grad |H|``);
* traction on the body surface ``t = (mu0 / 2) (M . n)^2 n`` [Pa], ``n`` the outward normal and
  ``M`` the inside value: the limit of ``mu0 (M . grad) H`` across the surface layer where
  ``H . n`` jumps by ``M . n`` (``int mu0 (H_out,n - H_n) dH_n = mu0 (M . n)^2 / 2``; ``H_t`` is
  continuous and gives nothing).

Equivalence with the Maxwell stress. With ``T = mu0 (H H - |H|^2 I / 2)`` and ``curl H = 0``,
``div T = mu0 H div H = -mu0 H div M`` (the "magnetic charge" force), and
``mu0 (M . grad) H = -mu0 H div M + mu0 div(H M)`` (components ``d_j (H_i M_j)``). The last term
is the divergence of a stress that vanishes where ``M = 0``: over any region enclosing the body
it integrates to zero, so the Kelvin loads (with their surface term, the same identity in
distributions) give the same net force (and torque, with M parallel to H) as
``F = int_S T n dA`` over any surface
``S`` in the air enclosing the body and no other source. The local distributions differ: for
the deformation of a soft body the Kelvin distribution must be paired with the magnetic part of
the constitutive stress that belongs to it (the RVE's magnetic stress in this project).
:func:`magnetic_loads` returns the loads at quadrature points of this mesh with their weights;
:func:`body_force_at` and :func:`traction_at` evaluate them at the points of another (e.g. the
mechanics) mesh; :func:`maxwell_force_N` is the independent route (volume form of the Maxwell
stress with a smooth cut-off in the air); :func:`coenergy_J` gives the co-energy of a linear
body for the virtual-work check ``F = dW'/dx`` at fixed sources.

Discretization of the loads: ``grad H`` in the body force is ``grad H_a`` (central differences)
plus the gradient of the L2 projection of the self-field ``-grad phi`` onto continuous P2 over
the body (its element-wise Hessian is noisier and converges more slowly). Their sum converges at
first order (measured rate 1.4: 0.95 %, 0.36 %, 0.14 % for a sphere in a gradient field at
``n_boundary = 24, 48, 96``), the Maxwell route faster (6e-5 at 64).

Units: m, A/m, A (potential), T, N/m^3, Pa, N, J.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.constants import mu_0 as MU0
from scipy.spatial import cKDTree
from skfem import (Basis, BilinearForm, ElementTetP2, ElementTriP2, LinearForm, MeshTet,
                   MeshTri, asm)
from skfem.helpers import dot, grad

from homogenize.solvers import AMGOptions, smoothed_aggregation
from micro.common.validate import ConvergenceError, InputError, check_choice, check_finite, \
    check_positive

__all__ = ["ConvergenceError", "LinearLaw", "FroehlichKennellyLaw", "LangevinLaw", "TanhLaw",
           "TableLaw", "check_table_range", "linear", "froehlich_kennelly", "langevin", "tanh",
           "check_law",
           "Sphere", "Spheroid", "Cylinder", "Profile", "MeshOptions", "BodyMesh",
           "axisymmetric_mesh", "ball_mesh_3d", "octant_mesh_3d",
           "uniform_applied_gradient_field",
           "applied_field", "MagnetostaticResult", "solve_axisymmetric", "solve_3d", "field_at",
           "body_fields_at", "MagneticLoads", "magnetic_loads", "body_force_at", "traction_at",
           "maxwell_force_N", "coenergy_J"]

TWO_PI = 2.0 * math.pi
#: the 3D solver's AMG (scalar Laplacian, one hierarchy per solve; pyamg's default strength)
_AMG = AMGOptions(symmetry="symmetric", strength_theta=None, max_coarse=500)
#: relative residual of the 3D CG solves: well below Newton's tolerance (1e-8 by default)
_CG_RTOL = 1e-10


# --------------------------------------------------------------------------- material laws

def _series_or(x, small, big, cut):
    x = np.asarray(x, float)
    out = np.empty_like(x)
    s = np.abs(x) < cut
    out[s] = small(x[s])
    out[~s] = big(x[~s])
    return out


@dataclass(frozen=True)
class LinearLaw:
    """``M = chi H`` [A/m]; ``chi`` [-] >= 0."""
    chi: float

    def __post_init__(self):
        check_positive("chi", self.chi, "", allow_zero=True)

    def M_A_per_m(self, H_A_per_m):
        """Magnitude of M [A/m] at field magnitudes ``H`` [A/m] (array)."""
        return self.chi * np.asarray(H_A_per_m, float)

    def dM_dH(self, H_A_per_m):
        """Differential susceptibility d|M|/d|H| [-] at ``H`` [A/m]."""
        return np.full_like(np.asarray(H_A_per_m, float), self.chi)


@dataclass(frozen=True)
class FroehlichKennellyLaw:
    """``M = chi0 Ms H / (Ms + chi0 H)``: initial susceptibility ``chi0`` [-], saturation
    ``Ms_A_per_m`` [A/m]."""
    chi0: float
    Ms_A_per_m: float

    def __post_init__(self):
        check_positive("chi0", self.chi0)
        check_positive("Ms_A_per_m", self.Ms_A_per_m, "A/m")

    def M_A_per_m(self, H_A_per_m):
        h = np.asarray(H_A_per_m, float)
        return self.chi0 * self.Ms_A_per_m * h / (self.Ms_A_per_m + self.chi0 * h)

    def dM_dH(self, H_A_per_m):
        h = np.asarray(H_A_per_m, float)
        return self.chi0 * self.Ms_A_per_m ** 2 / (self.Ms_A_per_m + self.chi0 * h) ** 2


def _lang(x):
    return _series_or(x, lambda y: y / 3 - y ** 3 / 45 + 2 * y ** 5 / 945 - y ** 7 / 4725,
                      lambda y: 1.0 / np.tanh(y) - 1.0 / y, 0.05)


def _dlang(x):
    def big(y):
        e = np.exp(-2.0 * np.abs(y))
        return 1.0 / y ** 2 - 4.0 * e / (1.0 - e) ** 2
    return _series_or(x, lambda y: 1 / 3 - y ** 2 / 15 + 2 * y ** 4 / 189 - y ** 6 / 675, big,
                      0.05)


@dataclass(frozen=True)
class LangevinLaw:
    """``M = Ms L(3 chi0 H / Ms)``, ``L(x) = coth x - 1/x``: initial susceptibility ``chi0``."""
    chi0: float
    Ms_A_per_m: float

    def __post_init__(self):
        check_positive("chi0", self.chi0)
        check_positive("Ms_A_per_m", self.Ms_A_per_m, "A/m")

    def M_A_per_m(self, H_A_per_m):
        return self.Ms_A_per_m * _lang(3 * self.chi0 * np.asarray(H_A_per_m, float)
                                       / self.Ms_A_per_m)

    def dM_dH(self, H_A_per_m):
        return 3 * self.chi0 * _dlang(3 * self.chi0 * np.asarray(H_A_per_m, float)
                                      / self.Ms_A_per_m)


@dataclass(frozen=True)
class TanhLaw:
    """``M = Ms tanh(chi0 H / Ms)``."""
    chi0: float
    Ms_A_per_m: float

    def __post_init__(self):
        check_positive("chi0", self.chi0)
        check_positive("Ms_A_per_m", self.Ms_A_per_m, "A/m")

    def M_A_per_m(self, H_A_per_m):
        return self.Ms_A_per_m * np.tanh(self.chi0 * np.asarray(H_A_per_m, float)
                                         / self.Ms_A_per_m)

    def dM_dH(self, H_A_per_m):
        t = np.tanh(self.chi0 * np.asarray(H_A_per_m, float) / self.Ms_A_per_m)
        return self.chi0 * (1.0 - t * t)


def linear(chi: float) -> LinearLaw:
    """Linear law ``M = chi H`` (chi [-])."""
    return LinearLaw(float(chi))


def froehlich_kennelly(chi0: float, Ms_A_per_m: float) -> FroehlichKennellyLaw:
    """Froehlich-Kennelly law (chi0 [-], Ms [A/m])."""
    return FroehlichKennellyLaw(float(chi0), float(Ms_A_per_m))


def langevin(chi0: float, Ms_A_per_m: float) -> LangevinLaw:
    """Langevin law with initial susceptibility chi0 [-] and saturation Ms [A/m]."""
    return LangevinLaw(float(chi0), float(Ms_A_per_m))


def tanh(chi0: float, Ms_A_per_m: float) -> TanhLaw:
    """Hyperbolic-tangent law (chi0 [-], Ms [A/m])."""
    return TanhLaw(float(chi0), float(Ms_A_per_m))


@dataclass(frozen=True, eq=False)
class TableLaw:
    """A tabulated composite law ``|M|(|H|)`` [A/m], e.g. ``M_eff`` of random RVEs against their
    internal field: monotone cubic (PCHIP) through ``(0, 0)`` and the nodes, its derivative for
    Newton's tangent. It is not extrapolated: :attr:`H_max_A_per_m` is the largest tabulated
    field, and a solver that needs more must refuse (:func:`check_table_range`); inside a Newton
    iteration a trial field beyond it sees the last value (zero slope), so that the iteration
    can come back.

    H_nodes_A_per_m, M_nodes_A_per_m : nodes [A/m], H strictly increasing and > 0, M >= 0 and
        non-decreasing
    source : where the table comes from (reported with results)
    """
    H_nodes_A_per_m: tuple
    M_nodes_A_per_m: tuple
    source: str = ""

    def __post_init__(self):
        from scipy.interpolate import PchipInterpolator
        H = np.asarray(check_finite("H_nodes_A_per_m", self.H_nodes_A_per_m, "A/m"),
                       float).ravel()
        M = np.asarray(check_finite("M_nodes_A_per_m", self.M_nodes_A_per_m, "A/m"),
                       float).ravel()
        if H.size < 2 or H.shape != M.shape:
            raise InputError(f"a table law needs >= 2 nodes of H and M of the same length, got "
                             f"{H.size} and {M.size}")
        if H[0] <= 0 or np.any(np.diff(H) <= 0):
            raise InputError("the table law's H_nodes_A_per_m must be > 0 and strictly "
                             "increasing")
        if M[0] < 0 or np.any(np.diff(M) < 0):
            raise InputError("the table law's M_nodes_A_per_m must be >= 0 and non-decreasing")
        f = PchipInterpolator(np.concatenate([[0.0], H]), np.concatenate([[0.0], M]))
        object.__setattr__(self, "H_nodes_A_per_m", tuple(H.tolist()))
        object.__setattr__(self, "M_nodes_A_per_m", tuple(M.tolist()))
        object.__setattr__(self, "_f", f)
        object.__setattr__(self, "_df", f.derivative())

    @property
    def H_max_A_per_m(self) -> float:
        """The largest tabulated field [A/m]."""
        return self.H_nodes_A_per_m[-1]

    def M_A_per_m(self, H_A_per_m):
        """|M| [A/m] at field magnitudes ``H`` [A/m] (held at the last node beyond it)."""
        return self._f(np.clip(np.asarray(H_A_per_m, float), 0.0, self.H_max_A_per_m))

    def dM_dH(self, H_A_per_m):
        """d|M|/d|H| [-] (zero beyond the last node)."""
        h = np.asarray(H_A_per_m, float)
        return np.where(h < self.H_max_A_per_m,
                        self._df(np.clip(h, 0.0, self.H_max_A_per_m)), 0.0)


def check_table_range(result, what: str = "the table law") -> None:
    """Refuse a solution whose internal field leaves the range of a :class:`TableLaw`
    (never extrapolated): :class:`InputError` naming the largest field needed and the range."""
    law = result.law
    if not isinstance(law, TableLaw):
        return
    H = np.linalg.norm(result.H_A_per_m[:, result.geometry.body_elements], axis=0)
    if H.max() > law.H_max_A_per_m * (1 + 1e-9):
        raise InputError(f"{what} ({law.source or 'tabulated M(H)'}) covers |H| up to "
                         f"{law.H_max_A_per_m:.4g} A/m (mu0 H = {MU0 * law.H_max_A_per_m:.3g} T) "
                         f"but the body's internal field reaches {H.max():.4g} A/m "
                         f"({MU0 * H.max():.3g} T): extend the table; it is not extrapolated")


def _check_law(law):
    if law is None:
        return None
    for name in ("M_A_per_m", "dM_dH"):
        if not callable(getattr(law, name, None)):
            raise InputError(f"the magnetization law must provide {name}(H_A_per_m), got "
                             f"{type(law).__name__}")
    return law


def _law_response(law, H):
    """M vectors and the tangent chi_d at field vectors ``H`` (dim, ...)."""
    h = np.sqrt(np.sum(H * H, axis=0))
    m = np.asarray(law.M_A_per_m(h), float)
    dm = np.asarray(law.dM_dH(h), float)
    tiny = h <= 1e-300
    # secant M / H, with its limit dM/dH(0) at H = 0
    sec = np.where(tiny, dm, m / np.where(tiny, 1.0, h))
    n = H / np.where(tiny, 1.0, h)
    M = sec * H
    dim = H.shape[0]
    eye = np.eye(dim).reshape((dim, dim) + (1,) * (H.ndim - 1))
    nn = n[:, None] * n[None, :]
    K = sec * eye + (dm - sec) * nn
    return M, K


# --------------------------------------------------------------------------- geometry

def _resample_polyline(vertices, n):
    """``n`` segments on the polyline through ``vertices`` (k, 2): proportional to length,
    every vertex kept (corners stay exact), at least one segment per edge."""
    v = np.asarray(vertices, float)
    lens = np.hypot(*np.diff(v, axis=0).T)
    counts = np.maximum(1, np.round(n * lens / lens.sum()).astype(int))
    pts = [v[:1]]
    for a, b, c in zip(v[:-1], v[1:], counts):
        t = np.arange(1, c + 1)[:, None] / c
        pts.append(a + t * (b - a))
    return np.vstack(pts)


@dataclass(frozen=True)
class Sphere:
    """Sphere of radius ``radius_m`` [m] centred on the origin."""
    radius_m: float

    def __post_init__(self):
        check_positive("radius_m", self.radius_m, "m")

    def profile(self, n: int) -> np.ndarray:
        t = np.linspace(0.0, math.pi, n + 1)
        return np.column_stack([self.radius_m * np.sin(t), self.radius_m * np.cos(t)])

    @property
    def volume_m3(self) -> float:
        return 4.0 / 3.0 * math.pi * self.radius_m ** 3


@dataclass(frozen=True)
class Spheroid:
    """Spheroid with semi-axis ``polar_m`` along z and ``equatorial_m`` [m] (Osborn's c, a)."""
    polar_m: float
    equatorial_m: float

    def __post_init__(self):
        check_positive("polar_m", self.polar_m, "m")
        check_positive("equatorial_m", self.equatorial_m, "m")

    def profile(self, n: int) -> np.ndarray:
        # eccentric angle, refined by arc length so thin spheroids keep their tips
        t = np.linspace(0.0, math.pi, 8 * n + 1)
        p = np.column_stack([self.equatorial_m * np.sin(t), self.polar_m * np.cos(t)])
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        ti = np.interp(np.linspace(0.0, s[-1], n + 1), s, t)
        return np.column_stack([self.equatorial_m * np.sin(ti), self.polar_m * np.cos(ti)])

    @property
    def volume_m3(self) -> float:
        return 4.0 / 3.0 * math.pi * self.equatorial_m ** 2 * self.polar_m


@dataclass(frozen=True)
class Cylinder:
    """Finite circular cylinder of radius ``radius_m`` and length ``length_m`` [m], axis z."""
    radius_m: float
    length_m: float

    def __post_init__(self):
        check_positive("radius_m", self.radius_m, "m")
        check_positive("length_m", self.length_m, "m")

    def profile(self, n: int) -> np.ndarray:
        R, h = self.radius_m, 0.5 * self.length_m
        return _resample_polyline([(0.0, h), (R, h), (R, -h), (0.0, -h)], n)

    @property
    def volume_m3(self) -> float:
        return math.pi * self.radius_m ** 2 * self.length_m


@dataclass(frozen=True)
class Profile:
    """A general axisymmetric body: its meridian polyline ``points_rz_m`` (k, 2) [m], from the
    north pole ``(0, z_top)`` to the south pole ``(0, z_bottom)``, ``r >= 0``, star-shaped with
    respect to the origin (the polar angle from +z increases strictly along it)."""
    points_rz_m: tuple

    def __post_init__(self):
        p = np.asarray(check_finite("points_rz_m", self.points_rz_m, "m"), float)
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
            raise InputError(f"points_rz_m must have shape (k >= 3, 2) [m], got {p.shape}")
        if abs(p[0, 0]) > 0 or abs(p[-1, 0]) > 0 or np.any(p[:, 0] < 0):
            raise InputError("points_rz_m must start and end on the axis (r = 0) with r >= 0")
        object.__setattr__(self, "points_rz_m", tuple(map(tuple, p)))

    def profile(self, n: int) -> np.ndarray:
        return _resample_polyline(self.points_rz_m, n)

    @property
    def volume_m3(self) -> float:
        # Pappus on the closed polygon (profile + axis): V = 2 pi A r_centroid
        p = np.asarray(self.points_rz_m)
        r, z = p[:, 0], p[:, 1]
        r2, z2 = np.roll(r, -1), np.roll(z, -1)
        cross = r * z2 - r2 * z
        return abs(TWO_PI * np.sum((r + r2) * cross) / 6.0)


@dataclass(frozen=True)
class MeshOptions:
    """Resolution of the axisymmetric mesh.

    n_boundary : segments along the body's meridian profile (pole to pole) [-]
    domain_factor : radius R of the meshed ball over the body's largest distance from its
        centre [-] (> 1.05; the exterior beyond R is exact through the Kelvin map)
    grading : air element radial size over angular size [-] (geometric layers)
    n_exterior : radial layers of the Kelvin-mapped exterior disk [-]
    """
    n_boundary: int = 64
    domain_factor: float = 2.0
    grading: float = 1.0
    n_exterior: int = 16

    def __post_init__(self):
        if int(self.n_boundary) != self.n_boundary or self.n_boundary < 8:
            raise InputError(f"n_boundary must be an integer >= 8, got {self.n_boundary!r}")
        check_positive("domain_factor", self.domain_factor)
        check_positive("grading", self.grading)
        if int(self.n_exterior) != self.n_exterior or self.n_exterior < 2:
            raise InputError(f"n_exterior must be an integer >= 2, got {self.n_exterior!r}")


@dataclass(frozen=True)
class BodyMesh:
    """Meshes of the field problem.

    mesh : MeshTri (r, z) or MeshTet -- the ball ``|x - c| <= R`` with the body [m]
    body_elements : int array -- elements of ``mesh`` inside the body
    exterior_mesh : mesh of the Kelvin image of ``|x - c| > R`` (local coordinates), or None
    center_m : (dim,) -- centre ``c`` of the ball and of the Kelvin inversion [m]
    radius_m : R [m]
    axisymmetric : bool
    octant : bool -- 3D only: the meshes hold the octant ``x, y, z >= 0`` (relative to the
        centre) of a body symmetric about the three coordinate planes, in a uniform applied
        field along z (:func:`octant_mesh_3d`): ``phi`` is odd in z (``phi = 0`` on ``z = 0``)
        and even in x and y (natural condition on ``x = 0``, ``y = 0``); volumes and means are
        those of the whole body. Only the solve and the body fields at points of the octant
        (:func:`body_fields_at`) are meant for it.
    """
    mesh: object
    body_elements: np.ndarray
    exterior_mesh: object
    center_m: np.ndarray
    radius_m: float
    axisymmetric: bool
    octant: bool = False

    def __post_init__(self):
        be = np.asarray(self.body_elements)
        n_el = self.mesh.t.shape[1]
        if be.ndim != 1 or be.size == 0 or be.dtype.kind not in "iu" or be.min() < 0 \
                or be.max() >= n_el or np.unique(be).size != be.size:
            raise InputError(f"body_elements must be distinct element indices in [0, {n_el}), "
                             "at least one")
        R = check_positive("radius_m", self.radius_m, "m")
        if self.octant and self.axisymmetric:
            raise InputError("octant symmetry is for a 3D BodyMesh, not an axisymmetric one")
        c = np.asarray(self.center_m, float).reshape(-1, 1)
        rho = np.linalg.norm(self.mesh.p[:, self.mesh.t[:, be]].reshape(c.shape[0], -1) - c,
                             axis=0)
        if not rho.max() < R / 1.05:
            raise InputError(f"the body (largest distance {rho.max():.4g} m from the centre) must "
                             f"lie strictly inside the field domain of radius {R:.4g} m, with at "
                             "least 5 % clearance (the body touches or leaves the domain "
                             "boundary)")

    @property
    def body_facets(self) -> np.ndarray:
        """Facets between a body element and an air element (the body surface)."""
        f2t = self.mesh.f2t
        body = np.zeros(self.mesh.t.shape[1], bool)
        body[self.body_elements] = True
        inner = f2t[1] >= 0
        a = body[f2t[0]]
        b = np.where(inner, body[np.maximum(f2t[1], 0)], False)
        return np.nonzero(inner & (a != b))[0]


def _ring_triangles(inner, outer, nodes):
    """Triangles between two rings of equal length (shorter diagonal of each quad)."""
    a, b = inner[:-1], inner[1:]
    c, d = outer[1:], outer[:-1]
    d1 = np.sum((nodes[:, a] - nodes[:, c]) ** 2, axis=0)
    d2 = np.sum((nodes[:, b] - nodes[:, d]) ** 2, axis=0)
    # ties (symmetric quads) broken the same way at every length scale
    use_ac = d1 <= d2 * (1.0 + 1e-9)
    t1 = np.where(use_ac, [a, b, c], [a, b, d])
    t2 = np.where(use_ac, [a, c, d], [b, c, d])
    return np.hstack([t1, t2])


def _orient(t, p):
    x = p[:, t]
    area = ((x[0, 1] - x[0, 0]) * (x[1, 2] - x[1, 0]) - (x[0, 2] - x[0, 0]) * (x[1, 1] - x[1, 0]))
    t = t.copy()
    flip = area < 0
    t[[1, 2]] = np.where(flip, t[[2, 1]], t[[1, 2]])
    return t


def _polar_mesh(directions, radii_rings):
    """Nodes: centre + rings ``radii_rings[k][i] * directions[:, i]``; fan + ring triangles."""
    nodes = [np.zeros((2, 1))]
    rings = []
    idx = 1
    for rho in radii_rings:
        nodes.append(directions * rho)
        rings.append(np.arange(idx, idx + directions.shape[1]))
        idx += directions.shape[1]
    p = np.hstack(nodes)
    fan = np.array([np.zeros(len(rings[0]) - 1, int), rings[0][:-1], rings[0][1:]])
    tris = [fan] + [_ring_triangles(rings[k], rings[k + 1], p) for k in range(len(rings) - 1)]
    t = _orient(np.hstack(tris), p)
    return p, t, [fan.shape[1]] + [tt.shape[1] for tt in tris[1:]]


def axisymmetric_mesh(body, options: MeshOptions = MeshOptions(), center_z_m: float = 0.0,
                      domain_radius_m: float | None = None) -> BodyMesh:
    """Conforming, graded meridian mesh of a star-shaped body and the ball around it.

    Parameters
    ----------
    body : Sphere | Spheroid | Cylinder | Profile -- shape centred at the origin [m]
    options : MeshOptions
    center_z_m : float -- position of the body's centre on the axis [m]
    domain_radius_m : float, optional -- radius R of the meshed ball [m]; default
        ``options.domain_factor`` times the body's largest distance from its centre

    Raises
    ------
    InputError (a ValueError) -- body not star-shaped, or not strictly inside the domain
    """
    check_finite("center_z_m", center_z_m, "m")
    n = int(options.n_boundary)
    P = np.asarray(body.profile(n), float).T              # (2, n+1) from north to south pole
    rho_b = np.hypot(P[0], P[1])
    if np.any(rho_b <= 0):
        raise InputError("the body's centre must lie strictly inside it (star-shaped profile)")
    theta = np.arctan2(P[0], P[1])
    if np.any(np.diff(theta) <= 0):
        raise InputError("the body's meridian profile must be star-shaped with respect to its "
                         "centre (polar angle strictly increasing from the north pole)")
    rho_max = float(rho_b.max())
    R = options.domain_factor * rho_max if domain_radius_m is None else \
        check_positive("domain_radius_m", domain_radius_m, "m")
    if not R > 1.05 * rho_max:
        raise InputError(f"the body (largest distance {rho_max:.4g} m from its centre) must lie "
                         f"strictly inside the field domain of radius {R:.4g} m, with at least "
                         f"5 % clearance (the body touches or leaves the domain boundary)")
    u = P / rho_b
    perim = float(np.sum(np.hypot(*np.diff(P, axis=1))))
    h_arc = perim / n
    n_body = max(2, int(math.ceil(float(np.mean(rho_b)) / h_arc)))
    dtheta = math.pi / n
    q = 1.0 + options.grading * max(dtheta, h_arc / rho_max)
    n_air = max(2, int(math.ceil(math.log(R / float(rho_b.min())) / math.log(q))))
    rings = [rho_b * (k / n_body) for k in range(1, n_body + 1)]
    rings += [rho_b * (R / rho_b) ** (j / n_air) for j in range(1, n_air)]
    rings += [np.full_like(rho_b, R)]
    p, t, counts = _polar_mesh(u, rings)
    n_body_el = sum(counts[:n_body])
    body_elements = np.arange(n_body_el)
    p = p + np.array([[0.0], [center_z_m]])
    n_ext = int(options.n_exterior)
    pe, te, _ = _polar_mesh(u, [np.full_like(rho_b, R * j / n_ext) for j in range(1, n_ext)]
                            + [np.full_like(rho_b, R)])
    return BodyMesh(MeshTri(np.ascontiguousarray(p), np.ascontiguousarray(t)), body_elements,
                    MeshTri(np.ascontiguousarray(pe), np.ascontiguousarray(te)),
                    np.array([0.0, float(center_z_m)]), float(R), True)


def _prisms_to_tets(bottom, top):
    """Conforming split of prisms ``bottom (3, n)``/``top (3, n)`` (node ``i`` of the top above
    node ``i`` of the bottom) into 3 tetrahedra each: every quad face is cut by the diagonal
    through its smallest global node index (Dompierre et al., 1999), so neighbours agree."""
    v = np.vstack([bottom, top])                      # (6, n): a b c A B C
    k = np.argmin(v, axis=0)
    up = k >= 3
    v[:, up] = np.vstack([v[3:, up], v[:3, up]])
    k = np.where(up, k - 3, k)
    cols = np.arange(v.shape[1])
    rot = np.stack([(k + j) % 3 for j in range(3)])    # cyclic rotation bringing k to 'a'
    a, b, c = v[rot[0], cols], v[rot[1], cols], v[rot[2], cols]
    A, B, C = v[3 + rot[0], cols], v[3 + rot[1], cols], v[3 + rot[2], cols]
    bc = np.minimum(b, C) < np.minimum(c, B)          # diagonal b-C, else c-B
    t1 = np.where(bc, [a, b, c, C], [a, b, c, B])
    t2 = np.where(bc, [a, b, C, B], [a, B, c, C])
    t3 = np.array([a, B, C, A])
    return np.hstack([t1, t2, t3])


def _orient_tets(t, p):
    x = p[:, t]
    vol = np.einsum("in,in->n", x[:, 1] - x[:, 0],
                    np.cross((x[:, 2] - x[:, 0]).T, (x[:, 3] - x[:, 0]).T).T)
    t = t.copy()
    flip = vol < 0
    t[[1, 2]] = np.where(flip, t[[2, 1]], t[[1, 2]])
    return t, np.abs(vol) / 6.0


def ball_mesh_3d(radius_fn: Callable, radius_m: float | None = None, refinements: int = 3,
                 center_m=(0.0, 0.0, 0.0), domain_factor: float = 1.5,
                 grading: float = 1.0) -> BodyMesh:
    """3D mesh of a star-shaped body and the ball around it, conforming and graded.

    Parameters
    ----------
    radius_fn : callable -- ``rho_b(u)``: the body's surface distance from its centre [m] along
        the unit directions ``u`` (3, n); e.g. an ellipsoid ``1 / sqrt(sum(u_i^2 / a_i^2))``
    radius_m : float, optional -- radius R of the meshed ball [m]; default ``domain_factor``
        times the largest ``rho_b`` on the mesh's directions
    refinements : int -- refinements of scikit-fem's ball (``MeshTet.init_ball``): 2 -> 128
        surface triangles, 3 -> 512, 4 -> 2048
    center_m : (3,) -- centre [m]; grading : air layer thickness over the surface edge size

    Notes
    -----
    The body is scikit-fem's unit ball mapped ray by ray, ``x = rho_b(y / |y|) y``; the air is
    the body's surface triangulation extruded along the same rays in geometric layers
    ``rho_b (R / rho_b)^t`` (prisms split conformingly into tetrahedra), so element size grows
    with the distance; the Kelvin exterior is the unit ball scaled to R, whose surface is the
    air's outer layer node for node.
    """
    c = np.asarray(check_finite("center_m", center_m, "m"), float).reshape(3, 1)
    if int(refinements) != refinements or not 1 <= refinements <= 5:
        raise InputError(f"refinements must be an integer in [1, 5], got {refinements!r}")
    ball = MeshTet.init_ball(nrefs=int(refinements))
    y = ball.p
    ry = np.linalg.norm(y, axis=0)
    u = y / np.where(ry > 0, ry, 1.0)
    u[:, ry == 0] = np.array([[0.0], [0.0], [1.0]])
    rho = np.asarray(radius_fn(u), float).reshape(-1)
    if rho.shape != (y.shape[1],) or not np.all(np.isfinite(rho)) or np.any(rho <= 0):
        raise InputError("radius_fn(u) must return finite distances > 0 [m], one per direction")
    bf = ball.boundary_facets()
    tri = ball.facets[:, bf]
    bn = np.unique(tri)
    rho_max = float(rho[bn].max())
    R = domain_factor * rho_max if radius_m is None else check_positive("radius_m", radius_m, "m")
    if not R > 1.05 * rho_max:
        raise InputError(f"the body (largest distance {rho_max:.4g} m from its centre) must lie "
                         f"strictly inside the field domain of radius {R:.4g} m, with at least "
                         f"5 % clearance (the body touches or leaves the domain boundary)")
    p_body = rho * y
    h_rel = float(np.mean(np.linalg.norm(y[:, tri[0]] - y[:, tri[1]], axis=0)))
    n_air = max(2, int(math.ceil(math.log(R / float(rho[bn].min()))
                                 / math.log(1.0 + grading * h_rel))))
    nb = bn.size
    local = np.full(y.shape[1], -1)
    local[bn] = np.arange(nb)
    layers = [bn]
    pts = [p_body]
    n0 = y.shape[1]
    for j in range(1, n_air + 1):
        r_j = rho[bn] * (R / rho[bn]) ** (j / n_air) if j < n_air else np.full(nb, R)
        pts.append(u[:, bn] * r_j)
        layers.append(n0 + (j - 1) * nb + np.arange(nb))
    p = np.hstack(pts)
    tets = [ball.t]
    for j in range(n_air):
        tets.append(_prisms_to_tets(layers[j][local[tri]], layers[j + 1][local[tri]]))
    t, vol = _orient_tets(np.hstack(tets), p)
    if np.min(vol) <= 1e-12 * np.max(vol):
        raise InputError("the mapped mesh has degenerate elements: is the body star-shaped?")
    mesh = MeshTet(np.ascontiguousarray(p + c), np.ascontiguousarray(t))
    ext = MeshTet(np.ascontiguousarray(R * y / np.max(ry)), ball.t)
    return BodyMesh(mesh, np.arange(ball.t.shape[1]), ext, c.ravel(), float(R), False)


def octant_surface_facets(body_mesh: MeshTet) -> np.ndarray:
    """The vertices (3, n) of the boundary facets of an octant body mesh that are not on a
    symmetry plane ``x_i = 0``: its outer surface (``np.unique`` of them: the surface vertices
    whose rays :func:`octant_mesh_3d` extrudes, in that order)."""
    p0 = np.asarray(body_mesh.p, float)
    tol = 1e-9 * float(np.abs(p0).max())
    bf = body_mesh.boundary_facets()
    fv = p0[:, body_mesh.facets[:, bf]]                       # (3, 3, nf)
    on_plane = np.any(np.all(np.abs(fv) <= tol, axis=1), axis=0)
    return body_mesh.facets[:, bf[~on_plane]]


def octant_mesh_3d(body_mesh: MeshTet, radius_m: float | None = None,
                   domain_factor: float = 2.0, grading: float = 1.0) -> BodyMesh:
    """Field mesh of the octant ``x, y, z >= 0`` of a body symmetric about the three coordinate
    planes (its centre at the origin) and of the space around it, for a field along z.

    Parameters
    ----------
    body_mesh : MeshTet -- the body's octant [m], star-shaped with respect to the origin, which
        must be one of its vertices (e.g. the mechanics mesh of
        :func:`homogenize.macro.finite_strain.cylinder_body_3d` or ``box_body``); it becomes
        the body part of the field mesh node for node and element for element (vertex ``i``
        and element ``e`` of ``body_mesh`` are vertex ``i`` and element ``e`` of the result)
    radius_m : float, optional -- radius R of the meshed ball [m]; default ``domain_factor``
        times the body's largest distance from the origin
    grading : air layer thickness over the relative surface edge size [-]

    Notes
    -----
    The air: the body's outer surface triangulation (its boundary facets off the symmetry
    planes) extruded along the rays from the origin in geometric layers
    ``rho_b (R / rho_b)^t`` up to the sphere ``R`` (prisms split conformingly into tetrahedra,
    as in :func:`ball_mesh_3d`); air vertex ``n_body + (j - 1) n_s + i`` lies on the ray of the
    ``i``-th surface vertex (``np.unique`` order) in layer ``j``. The Kelvin image of the
    exterior is this whole mesh (a ball octant of radius R whose surface is the outer layer
    node for node; its origin is infinity).
    """
    if not isinstance(body_mesh, MeshTet):
        raise InputError(f"body_mesh must be a skfem MeshTet, got {type(body_mesh).__name__}")
    p0 = np.asarray(body_mesh.p, float)
    scale = float(np.abs(p0).max())
    tol = 1e-9 * scale
    if np.any(p0 < -tol):
        raise InputError("body_mesh must lie in the octant x, y, z >= 0")
    if not np.any(np.linalg.norm(p0, axis=0) <= tol):
        raise InputError("the origin (the body's centre) must be a vertex of body_mesh")
    tri = octant_surface_facets(body_mesh)
    bn = np.unique(tri)
    rho_b = np.linalg.norm(p0[:, bn], axis=0)
    if np.any(rho_b <= tol):
        raise InputError("the body's outer surface must not pass through its centre")
    u = p0[:, bn] / rho_b
    rho_max = float(rho_b.max())
    R = float(domain_factor) * rho_max if radius_m is None else \
        check_positive("radius_m", radius_m, "m")
    if not R > 1.05 * rho_max:
        raise InputError(f"the body (largest distance {rho_max:.4g} m from its centre) must lie "
                         f"strictly inside the field domain of radius {R:.4g} m, with at least "
                         f"5 % clearance (the body touches or leaves the domain boundary)")
    check_positive("grading", grading)
    local = np.full(p0.shape[1], -1)
    local[bn] = np.arange(bn.size)
    e = np.hstack([tri[[0, 1]], tri[[1, 2]], tri[[2, 0]]])         # surface edges
    h_rel = float(np.mean(np.linalg.norm(p0[:, e[0]] - p0[:, e[1]], axis=0)
                          / (0.5 * (np.linalg.norm(p0[:, e[0]], axis=0)
                                    + np.linalg.norm(p0[:, e[1]], axis=0)))))
    n_air = max(2, int(math.ceil(math.log(R / float(rho_b.min()))
                                 / math.log(1.0 + grading * h_rel))))
    nv, ns = p0.shape[1], bn.size
    pts, layers = [p0], [bn]
    for j in range(1, n_air + 1):
        r_j = rho_b * (R / rho_b) ** (j / n_air) if j < n_air else np.full(ns, R)
        pts.append(u * r_j)
        layers.append(nv + (j - 1) * ns + np.arange(ns))
    p = np.hstack(pts)
    tets = [np.asarray(body_mesh.t)]
    for j in range(n_air):
        tets.append(_prisms_to_tets(layers[j][local[tri]], layers[j + 1][local[tri]]))
    t = np.hstack(tets)
    nb = body_mesh.t.shape[1]
    t_air, vol = _orient_tets(t[:, nb:], p)
    if np.min(vol) <= 1e-12 * np.max(vol):
        raise InputError("the extruded air mesh has degenerate elements: is the body "
                         "star-shaped with respect to its centre?")
    t_body, _ = _orient_tets(t[:, :nb], p)
    t = np.ascontiguousarray(np.hstack([t_body, t_air]))
    mesh = MeshTet(np.ascontiguousarray(p), t)
    return BodyMesh(mesh, np.arange(nb), MeshTet(np.ascontiguousarray(p), t),
                    np.zeros(3), float(R), False, True)


# --------------------------------------------------------------------------- solver

def uniform_applied_gradient_field(H0_A_per_m: float, G_A_per_m2: float, z0_m: float = 0.0):
    """Axisymmetric applied field with a uniform axial gradient, as an ``H_applied`` callable.

    ``H_z = H0 + G (z - z0)``, ``H_r = -G r / 2`` [A/m]: curl- and divergence-free (the first
    two terms of any axisymmetric source-free field about ``z0``). Input ``x`` (2, ...) = (r, z).
    """
    H0, G, z0 = float(H0_A_per_m), float(G_A_per_m2), float(z0_m)

    def H(x):
        x = np.asarray(x, float)
        return np.stack([-0.5 * G * x[0], H0 + G * (x[1] - z0)])
    return H


def applied_field(H_of_points: Callable, axisymmetric: bool = True,
                  offset_m=(0.0, 0.0, 0.0)) -> Callable:
    """An ``H_applied`` callable from a field of Cartesian points, e.g. a magpylib source.

    H_of_points : callable -- ``H(P)`` for points ``P`` (n, 3) [m] returning (n, 3) [A/m], such
        as ``source.getH`` of a magpylib source or collection (sources away from the body)
    axisymmetric : bool -- True: the result takes ``x = (r, z)`` (2, ...) and returns
        ``(H_r, H_z)`` sampled in the plane ``y = 0`` (the source must be axisymmetric about z);
        False: ``x`` (3, ...) -> (3, ...)
    offset_m : (3,) -- the body's frame is shifted by ``offset_m`` relative to the source's
        (sample ``H`` at ``x + offset``): a virtual displacement of the body for virtual work
    """
    off = np.asarray(check_finite("offset_m", offset_m, "m"), float).reshape(3)

    def H(x):
        x = np.asarray(x, float)
        xf = x.reshape(x.shape[0], -1)
        if axisymmetric:
            P = np.column_stack([xf[0], np.zeros(xf.shape[1]), xf[1]]) + off
            h = np.asarray(H_of_points(P), float).reshape(-1, 3)
            return np.stack([h[:, 0], h[:, 2]]).reshape(x.shape)
        h = np.asarray(H_of_points(xf.T + off), float).reshape(-1, 3)
        return h.T.reshape(x.shape)
    return H


def _weight(x, axisymmetric):
    return TWO_PI * x[0] if axisymmetric else np.ones_like(x[0])


def _fit_gradients(basis, phi):
    """Per element: P2 gradient ``g(x) = g0 + Hs (x - x0)`` (linear) from the first dim+1
    quadrature points of ``basis`` (non-degenerate for intorder=2)."""
    g = basis.interpolate(phi).grad                    # (dim, nel, nq)
    x = np.asarray(basis.global_coordinates())   # (dim, nel, nq)
    dim = x.shape[0]
    X = np.moveaxis(x[:, :, 1:dim + 1] - x[:, :, :1], 1, 0)    # (nel, dim, q)
    Gd = np.moveaxis(g[:, :, 1:dim + 1] - g[:, :, :1], 1, 0)   # (nel, dim, q)
    # Gd = Hs X  ->  Hs^T solves X^T Hs^T = Gd^T
    Hs = np.linalg.solve(np.transpose(X, (0, 2, 1)), np.transpose(Gd, (0, 2, 1)))
    Hs = np.transpose(Hs, (0, 2, 1))                   # (nel, dim, dim): Hs[e, i, j] = d_j g_i
    return g[:, :, 0], x[:, :, 0], np.moveaxis(Hs, 0, 2)        # g0 (dim, nel), x0, (dim,dim,nel)


@dataclass(frozen=True)
class MagnetostaticResult:
    """Solution of the field problem (frozen). Vectors are (r, z) components (axisymmetric) or
    (x, y, z) (3D); per-element values at element centroids.

    geometry : BodyMesh; basis : P2 basis on ``geometry.mesh``; phi_A : potential dofs [A];
    phi_exterior_A : dofs on the Kelvin exterior mesh [A] (None for ``exterior="dirichlet"``);
    H_A_per_m, M_A_per_m, B_T : (dim, n_el) total field, magnetization, flux density;
    M_mean_A_per_m, H_mean_A_per_m, H_applied_mean_A_per_m : (dim,) volume means over the body
    (vector means: the r entry of an axisymmetric body is 0);
    volume_m3 : meshed body volume (the whole body of an octant geometry); demag_factor :
    magnetometric N along ``axis`` ``e``
    ``(<H_a> - <H>) . e / <M> . e`` [-] (``e``: the uniform applied field's direction, else z;
    along ``<M>`` for a magnet without applied field); iterations, residual_history :
    Newton's record; law, H_applied (callable of x (dim, ...) -> (dim, ...)), M_imposed
    (callable or None).
    """
    geometry: BodyMesh
    basis: object
    phi_A: np.ndarray
    phi_exterior_A: np.ndarray | None
    H_A_per_m: np.ndarray
    M_A_per_m: np.ndarray
    B_T: np.ndarray
    M_mean_A_per_m: np.ndarray
    H_mean_A_per_m: np.ndarray
    H_applied_mean_A_per_m: np.ndarray
    volume_m3: float
    demag_factor: float
    iterations: int
    residual_history: tuple
    law: object
    H_applied: Callable = field(repr=False)
    M_imposed: Callable | None = field(repr=False)
    axis: np.ndarray = field(repr=False)
    _g0: np.ndarray = field(repr=False)
    _x0: np.ndarray = field(repr=False)
    _hess: np.ndarray = field(repr=False)

    @property
    def mesh(self):
        return self.geometry.mesh

    def grad_phi(self, x, elements):
        """grad phi [A/m] at points ``x`` (dim, n) lying in ``elements`` (n,) of the mesh."""
        return (self._g0[:, elements]
                + np.einsum("ijn,jn->in", self._hess[:, :, elements], x - self._x0[:, elements]))


def _applied(H0, H_applied, dim):
    if H_applied is not None:
        if not callable(H_applied):
            raise InputError("H_applied must be a callable H(x) -> (dim, ...) [A/m]")
        return H_applied, False
    if np.ndim(H0) == 0:
        H0v = np.zeros(dim)
        H0v[-1] = float(check_finite("H0_A_per_m", H0, "A/m"))
    else:
        H0v = np.asarray(check_finite("H0_A_per_m", H0, "A/m"), float).reshape(dim)

    def Hu(x):
        x = np.asarray(x, float)
        return np.broadcast_to(H0v.reshape((dim,) + (1,) * (x.ndim - 1)), x.shape).copy()
    return Hu, True


def _imposed(M_imposed, dim):
    if M_imposed is None or callable(M_imposed):
        return M_imposed
    Mv = np.asarray(check_finite("M_imposed", M_imposed, "A/m"), float).reshape(dim)

    def Mu(x):
        x = np.asarray(x, float)
        return np.broadcast_to(Mv.reshape((dim,) + (1,) * (x.ndim - 1)), x.shape).copy()
    return Mu


def _sphere_facets(mesh, c, R):
    """Boundary facets with every vertex on the sphere ``|x - c| = R``."""
    bf = mesh.boundary_facets()
    rho = np.linalg.norm(mesh.p - c, axis=0)
    on = np.abs(rho - R) < 1e-9 * R
    return bf[np.all(on[mesh.facets[:, bf]], axis=0)]


def _plane_facets(mesh, axis, value, R):
    """Boundary facets with every vertex on the plane ``x_axis = value``."""
    bf = mesh.boundary_facets()
    on = np.abs(mesh.p[axis] - value) < 1e-9 * R
    return bf[np.all(on[mesh.facets[:, bf]], axis=0)]


def _solve(geometry: BodyMesh, law, H0, H_applied, M_imposed, exterior, rtol, max_iter,
           linear_solver):
    law = _check_law(law)
    check_choice("exterior", exterior, ("kelvin", "dirichlet"))
    if exterior == "kelvin" and geometry.exterior_mesh is None:
        raise InputError("exterior='kelvin' needs the BodyMesh's exterior_mesh")
    if (law is None) == (M_imposed is None):
        raise InputError("give exactly one of law (a magnetization law) and M_imposed "
                         "(a fixed magnetization [A/m])")
    axi = geometry.axisymmetric
    mesh = geometry.mesh
    dim = mesh.p.shape[0]
    Ha, uniform = _applied(H0, H_applied, dim)
    Mimp = _imposed(M_imposed, dim)
    octant = bool(getattr(geometry, "octant", False))
    if octant and (not uniform or np.ndim(H0) > 0 or M_imposed is not None):
        raise InputError("an octant geometry (octant_mesh_3d) needs a uniform applied field "
                         "along z given as a number H0_A_per_m, and a magnetization law")
    elem = ElementTriP2() if axi else ElementTetP2()
    basis = Basis(mesh, elem, intorder=3 if axi else 2)
    bbody = Basis(mesh, elem, elements=geometry.body_elements, intorder=4 if axi else 3)
    R = geometry.radius_m
    c = geometry.center_m.reshape(dim, 1, 1)

    @BilinearForm
    def lap(u, v, w):
        return dot(grad(u), grad(v)) * _weight(w.x, axi)

    @BilinearForm
    def lap_kelvin(u, v, w):
        r2 = np.sum(w.x ** 2, axis=0)
        return dot(grad(u), grad(v)) * _weight(w.x, axi) * R ** 2 / r2

    @LinearForm
    def load(v, w):
        return dot(w.M, grad(v)) * _weight(w.x, axi)

    @BilinearForm
    def tangent(u, v, w):
        return dot(np.einsum("ij...,j...->i...", w.K, grad(u)), grad(v)) * _weight(w.x, axi)

    A = asm(lap, basis).tocsr()
    n1 = basis.N
    outer = basis.get_dofs(_sphere_facets(mesh, c[:, :, 0], R)).all()
    if exterior == "kelvin":
        bext = Basis(geometry.exterior_mesh, elem, intorder=4 if axi else 3)
        Ae = asm(lap_kelvin, bext).tocsr()
        ext_outer = bext.get_dofs(_sphere_facets(geometry.exterior_mesh, 0.0, R)).all()
        tree = cKDTree((basis.doflocs[:, outer] - c[:, :, 0]).T)
        dist, j = tree.query(bext.doflocs[:, ext_outer].T)
        if np.max(dist) > 1e-8 * R:
            raise RuntimeError("Kelvin exterior does not match the domain boundary")
        gmap = np.full(bext.N, -1)
        gmap[ext_outer] = outer[j]
        rest = np.nonzero(gmap < 0)[0]
        gmap[rest] = n1 + np.arange(rest.size)
        N = n1 + rest.size
        Pm = sp.csr_matrix((np.ones(bext.N), (np.arange(bext.N), gmap)), shape=(bext.N, N))
        A = sp.block_diag([A, sp.csr_matrix((rest.size, rest.size))]).tocsr() + (Pm.T @ Ae @ Pm)
        origin = np.nonzero(np.linalg.norm(bext.doflocs, axis=0) < 1e-12 * R)[0]
        fixed = gmap[origin]
    else:
        bext, N, gmap = None, n1, None
        fixed = outer
    if octant:
        # phi is odd in z: phi = 0 on the plane z = 0 (of the exterior image too: the
        # inversion maps the plane onto itself)
        zfix = [basis.get_dofs(_plane_facets(mesh, 2, float(c[2, 0, 0]), R)).all()]
        if bext is not None:
            zfix.append(gmap[bext.get_dofs(_plane_facets(geometry.exterior_mesh, 2, 0.0,
                                                          R)).all()])
        fixed = np.unique(np.concatenate([np.atleast_1d(fixed)] + zfix))
    A = A.tocsr()
    free = np.setdiff1d(np.arange(N), fixed)
    xq = np.asarray(bbody.global_coordinates())
    Haq = Ha(xq)
    check_finite("H_applied(x)", Haq, "A/m")
    if Haq.shape != xq.shape:
        raise InputError(f"H_applied must return shape {xq.shape}, got {Haq.shape}")

    def pad(b1):
        out = np.zeros(N)
        out[:n1] = b1
        return out

    def state(phi):
        H = Haq - bbody.interpolate(phi[:n1]).grad
        if law is None:
            return Mimp(xq), None
        return _law_response(law, H)

    def residual(phi, M):
        return A @ phi - pad(asm(load, bbody, M=M))

    history = []
    phi = np.zeros(N)
    iterations = 0
    amg = None
    if law is None:
        M, _ = state(phi)
        b = pad(asm(load, bbody, M=M))
        phi[free] = _linsolve(A[free][:, free], b[free], linear_solver, dim)
        history = [1.0, float(np.linalg.norm(residual(phi, M)[free]) /
                              max(np.linalg.norm(b[free]), 1e-300))]
    else:
        M, K = state(phi)
        r = residual(phi, M)
        ref = float(np.linalg.norm(r[free]))
        if ref == 0.0:
            history = [0.0]
        else:
            rn = ref
            history = [1.0]
            while history[-1] > rtol:
                if iterations >= max_iter:
                    raise ConvergenceError(
                        f"Newton did not reach the relative residual {rtol:g} in {max_iter} "
                        f"iterations (last {history[-1]:.3g})", history)
                J = (A + _pad_matrix(asm(tangent, bbody, K=K), N)).tocsr()
                Jf = J[free][:, free]
                d = np.zeros(N)
                d[free], amg = _linsolve(Jf, -r[free], linear_solver, dim, amg, ret_amg=True)
                step = 1.0
                while True:
                    trial = phi + step * d
                    Mt, Kt = state(trial)
                    rt = residual(trial, Mt)
                    rtn = float(np.linalg.norm(rt[free]))
                    if rtn <= (1.0 - 1e-4 * step) * rn or step < 1.0 / 64:
                        break
                    step *= 0.5
                if not np.isfinite(rtn) or (step < 1.0 / 64 and rtn > rn):
                    raise ConvergenceError("Newton's line search found no decrease of the "
                                           "residual", history + [rtn / ref])
                phi, M, K, r, rn = trial, Mt, Kt, rt, rtn
                iterations += 1
                history.append(rn / ref)
    phi_in = phi[:n1]
    phi_ext = phi[gmap] if bext is not None else None
    # per-element fields at centroids
    bfit = Basis(mesh, elem, intorder=2)
    g0, x0, hess = _fit_gradients(bfit, phi_in)
    xc = mesh.p[:, mesh.t].mean(axis=1)
    Hc = Ha(xc) - (g0 + np.einsum("ijn,jn->in", hess, xc - x0))
    Mc = np.zeros_like(Hc)
    be = geometry.body_elements
    if law is None:
        Mc[:, be] = Mimp(xc[:, be])
    else:
        Mc[:, be] = _law_response(law, Hc[:, be])[0]
    Bc = MU0 * (Hc + Mc)
    # body means with the body quadrature
    Mq, _ = state(phi)
    Hq = Haq - bbody.interpolate(phi_in).grad
    wq = bbody.dx * _weight(xq, axi)
    V = float(wq.sum())
    Mmean = np.einsum("ien,en->i", Mq, wq) / V
    Hmean = np.einsum("ien,en->i", Hq, wq) / V
    Hamean = np.einsum("ien,en->i", Haq, wq) / V
    if axi:
        # vector means of an axisymmetric field: e_r averages to zero over the revolution
        for v in (Mmean, Hmean, Hamean):
            v[0] = 0.0
    if octant:
        # the whole body: x and y components average to zero over the mirror images
        for v in (Mmean, Hmean, Hamean):
            v[:2] = 0.0
        V *= 8.0
    # the axis of N: the uniform applied field's direction, else z (a field along the axis),
    # else (no applied field: a magnet) the mean magnetization's
    e = np.zeros(dim)
    e[-1] = 1.0
    if uniform and np.ndim(H0) > 0 and np.linalg.norm(H0) > 0:
        e = np.asarray(H0, float) / np.linalg.norm(H0)
    elif np.linalg.norm(Hamean) == 0 and np.linalg.norm(Mmean) > 0:
        e = Mmean / np.linalg.norm(Mmean)
    Ndem = float((Hamean - Hmean) @ e / (Mmean @ e)) if abs(Mmean @ e) > 0 else float("nan")
    return MagnetostaticResult(geometry, basis, phi_in, phi_ext, Hc, Mc, Bc, Mmean, Hmean,
                               Hamean, V, Ndem, iterations, tuple(history), law, Ha, Mimp, e,
                               g0, x0, hess)


def _pad_matrix(Kb, N):
    """Embed the inner-mesh matrix ``Kb`` in the global (N x N) numbering."""
    Kb = Kb.tocoo()
    return sp.csr_matrix((Kb.data, (Kb.row, Kb.col)), shape=(N, N))


def _linsolve(A, b, how, dim, amg=None, ret_amg=False):
    if how == "auto":
        how = "direct" if dim == 2 else "amg-cg"
    if how == "direct":
        x = spla.spsolve(A.tocsc(), b)
    else:
        if amg is None:
            # the constant is the near-null space of the scalar Laplacian
            amg = smoothed_aggregation(A.tocsr(), np.ones((A.shape[0], 1)), _AMG)
        res = []
        nb = float(np.linalg.norm(b))
        x, info = spla.cg(A, b, M=amg.aspreconditioner(), rtol=_CG_RTOL, maxiter=1000,
                          callback=lambda xk: res.append(1))
        if info != 0:
            raise ConvergenceError(f"AMG-CG did not converge in {len(res)} iterations "
                                   f"(relative residual {np.linalg.norm(b - A @ x) / nb:.3g})")
    return (x, amg) if ret_amg else x


def solve_axisymmetric(body, law=None, H0_A_per_m: float = 0.0, *, H_applied=None,
                       M_imposed=None, options: MeshOptions = MeshOptions(),
                       center_z_m: float = 0.0, domain_radius_m: float | None = None,
                       geometry: BodyMesh | None = None, exterior: str = "kelvin",
                       rtol: float = 1e-10, max_iter: int = 50) -> MagnetostaticResult:
    """Field, magnetization and demagnetizing factor of an axisymmetric body.

    Parameters
    ----------
    body : Sphere | Spheroid | Cylinder | Profile -- centred at ``(0, center_z_m)`` [m]
    law : magnetization law (``M_A_per_m(H)``, ``dM_dH(H)``), or None with ``M_imposed``
    H0_A_per_m : float -- uniform applied field along +z [A/m] (ignored if ``H_applied``)
    H_applied : callable, optional -- ``H_a(x)`` for ``x`` (2, ...) = (r, z) [m] returning
        ``(H_r, H_z)`` (2, ...) [A/m]; curl- and divergence-free where the mesh is, axisymmetric
    M_imposed : (2,) or callable, optional -- fixed magnetization (M_r, M_z) [A/m] of the body
        (a permanent magnet, no law): ``H`` is then its own field plus ``H_a``
    options : MeshOptions; geometry : BodyMesh, optional -- a prebuilt mesh (then ``body``,
        ``options``, ``center_z_m``, ``domain_radius_m`` are ignored)
    exterior : "kelvin" (exact, default) | "dirichlet" (phi = 0 on |x| = R: truncation study)
    rtol : relative residual of Newton [-]; max_iter : Newton iterations

    Returns
    -------
    MagnetostaticResult

    Raises
    ------
    InputError (ValueError) -- bad input, e.g. body touching the domain boundary;
    ConvergenceError (RuntimeError) -- Newton failed (``residual_history``)
    """
    if geometry is None:
        if not callable(getattr(body, "profile", None)):
            raise InputError("body must be a Sphere, Spheroid, Cylinder or Profile (or pass "
                             f"geometry=), got {body!r}")
        geometry = axisymmetric_mesh(body, options, center_z_m, domain_radius_m)
    elif not isinstance(geometry, BodyMesh) or not geometry.axisymmetric:
        raise InputError("geometry must be an axisymmetric BodyMesh (axisymmetric_mesh)")
    return _solve(geometry, law, H0_A_per_m, H_applied, M_imposed, exterior, rtol, max_iter,
                  "direct")


def solve_3d(geometry: BodyMesh, law=None, H0_A_per_m=0.0, *, H_applied=None, M_imposed=None,
             exterior: str = "kelvin", rtol: float = 1e-8, max_iter: int = 50,
             linear_solver: str = "auto") -> MagnetostaticResult:
    """3D version of :func:`solve_axisymmetric` on a :func:`ball_mesh_3d` geometry.

    ``H0_A_per_m`` : float (along z) or (3,) [A/m]; ``H_applied(x)`` for ``x`` (3, ...) [m];
    ``linear_solver`` : "auto" | "direct" | "amg-cg" (pyamg smoothed aggregation, set up once
    per solve on the first tangent and reused as preconditioner by every Newton step).
    """
    if not isinstance(geometry, BodyMesh) or geometry.axisymmetric:
        raise InputError("solve_3d needs a 3D BodyMesh (ball_mesh_3d)")
    check_choice("linear_solver", linear_solver, ("auto", "direct", "amg-cg"))
    return _solve(geometry, law, H0_A_per_m, H_applied, M_imposed, exterior, rtol, max_iter,
                  linear_solver)


# --------------------------------------------------------------------------- post-processing

def field_at(result: MagnetostaticResult, points_m) -> np.ndarray:
    """Total field ``H`` [A/m] at points ``points_m`` (dim, n) [m] anywhere in space.

    Inside the meshed ball: the P2 field of the containing element; outside it: through the
    Kelvin image (``grad phi = J^T grad' phi'``, ``J = dx'/dx``). ``(r, z)`` with ``r >= 0`` for
    the axisymmetric case.
    """
    x = np.asarray(check_finite("points_m", points_m, "m"), float)
    g = result.geometry
    dim = g.mesh.p.shape[0]
    x = x.reshape(dim, -1)
    c = g.center_m.reshape(dim, 1)
    rho = np.linalg.norm(x - c, axis=0)
    gphi = np.zeros_like(x)
    inside = rho < g.radius_m * (1 - 1e-12)
    if np.any(inside):
        el = _locate(g.mesh, np.arange(g.mesh.t.shape[1]), x[:, inside])
        gphi[:, inside] = result.grad_phi(x[:, inside], el)
    out = ~inside
    if np.any(out):
        if result.phi_exterior_A is None:
            raise InputError("points outside the domain need the Kelvin exterior")
        y = x[:, out] - c
        r2 = np.sum(y * y, axis=0)
        xp = g.radius_m ** 2 * y / r2
        elem = ElementTriP2() if g.axisymmetric else ElementTetP2()
        be = Basis(g.exterior_mesh, elem, intorder=2)
        g0, x0, hs = _fit_gradients(be, result.phi_exterior_A)
        el = _locate(g.exterior_mesh, np.arange(g.exterior_mesh.t.shape[1]), xp)
        gp = g0[:, el] + np.einsum("ijn,jn->in", hs[:, :, el], xp - x0[:, el])
        yhat = y / np.sqrt(r2)
        # J_ij = (R^2 / |y|^2) (delta_ij - 2 yhat_i yhat_j), symmetric
        s = g.radius_m ** 2 / r2
        gphi[:, out] = s * (gp - 2 * yhat * np.sum(yhat * gp, axis=0))
    return result.H_applied(x) - gphi


def _applied_gradient(Ha, x, h):
    """``dH_i/dx_j`` (dim, dim, ...) by central differences with step ``h`` [m]."""
    dim = x.shape[0]
    out = np.empty((dim, dim) + x.shape[1:])
    for j in range(dim):
        e = np.zeros((dim,) + (1,) * (x.ndim - 1))
        e[j] = h
        out[:, j] = (Ha(x + e) - Ha(x - e)) / (2 * h)
    return out


@dataclass(frozen=True)
class MagneticLoads:
    """Kelvin loads at quadrature points, for a mechanics solver (frozen; see module notes).

    elements : (n_e,) body elements; x_element_m : (dim, n_e, q) points [m];
    body_force_N_m3 : (dim, n_e, q) ``mu0 (M . grad) H`` [N/m^3];
    dV_m3 : (n_e, q) quadrature weights (with ``2 pi r`` if axisymmetric) [m^3];
    facets : (n_f,) body-surface facets of the mesh; facet_elements : (n_f,) their body
    element; x_facet_m : (dim, n_f, qf) [m]; normal : (dim, n_f) outward unit normal;
    traction_Pa : (dim, n_f, qf) ``(mu0 / 2) (M . n)^2 n`` [Pa]; dA_m2 : (n_f, qf) [m^2];
    axisymmetric : bool -- (r, z) components, weights of the whole revolution.

    A mechanics solver on this mesh adds ``sum f . v dV + sum t . v dA`` to its load vector; one
    on its own mesh evaluates :func:`body_force_at` and :func:`traction_at` at its points.
    """
    elements: np.ndarray
    x_element_m: np.ndarray
    body_force_N_m3: np.ndarray
    dV_m3: np.ndarray
    facets: np.ndarray
    facet_elements: np.ndarray
    x_facet_m: np.ndarray
    normal: np.ndarray
    traction_Pa: np.ndarray
    dA_m2: np.ndarray
    axisymmetric: bool

    def _net(self, v):
        # axisymmetric: the weights hold the whole revolution, over which e_r averages to 0
        return v * np.array([0.0, 1.0]) if self.axisymmetric else v

    @property
    def body_force_total_N(self) -> np.ndarray:
        """Net force of the body force (dim,) [N] (r entry 0 if axisymmetric)."""
        return self._net(np.einsum("ien,en->i", self.body_force_N_m3, self.dV_m3))

    @property
    def traction_total_N(self) -> np.ndarray:
        """Net force of the surface traction (dim,) [N] (r entry 0 if axisymmetric)."""
        return self._net(np.einsum("ifn,fn->i", self.traction_Pa, self.dA_m2))

    @property
    def total_force_N(self) -> np.ndarray:
        """Net magnetic force on the body (dim,) [N]."""
        return self.body_force_total_N + self.traction_total_N


def _M_of(result, H, x):
    if result.law is None:
        return result.M_imposed(x)
    return _law_response(result.law, H)[0]


def _recovered_field(bb, h, dV):
    """L2 projection of the field ``h`` (dim, n_e, q) onto continuous P2 over the elements of
    ``bb`` (the body): dof vectors (dim, bb.N), zero off the body."""

    @BilinearForm
    def mass(u, v, w):
        return u * v * w.wt

    @LinearForm
    def rhs(v, w):
        return w.h * v * w.wt

    wt = dV / bb.dx
    Mm = asm(mass, bb, wt=wt).tocsr()
    used = np.unique(bb.element_dofs)
    Mu = Mm[used][:, used].tocsc()
    direct = bb.mesh.p.shape[0] == 2 or used.size < 60000
    lu = spla.splu(Mu) if direct else None
    dim = h.shape[0]
    out = np.zeros((dim, bb.N))
    for i in range(dim):
        b = asm(rhs, bb, wt=wt, h=h[i])[used]
        if direct:
            out[i, used] = lu.solve(b)
        else:
            # a mass matrix is spectrally equivalent to its diagonal: Jacobi-CG
            out[i, used], _ = spla.cg(Mu, b, M=sp.diags(1.0 / Mu.diagonal()), rtol=1e-12,
                                      maxiter=2000)
    return out


def _body_field(result, intorder):
    """Body basis, its points, weights, and the recovered self-field ``-grad phi`` dofs."""
    g = result.geometry
    mesh = g.mesh
    dim = mesh.p.shape[0]
    elem = ElementTriP2() if g.axisymmetric else ElementTetP2()
    be = g.body_elements
    bb = Basis(mesh, elem, elements=be, intorder=intorder)
    x = np.asarray(bb.global_coordinates())
    ne, nq = x.shape[1:]
    dV = bb.dx * _weight(x, g.axisymmetric)
    hd = -result.grad_phi(x.reshape(dim, -1), np.repeat(be, nq)).reshape(dim, ne, nq)
    return bb, x, dV, hd, _recovered_field(bb, hd, dV)


def magnetic_loads(result: MagnetostaticResult, intorder: int = 4,
                   fd_step_m: float | None = None, recover: bool = True) -> MagneticLoads:
    """Kelvin body force at element quadrature points and surface traction at body-facet
    quadrature points (see the module docstring for the formulation).

    Parameters
    ----------
    result : MagnetostaticResult
    intorder : int -- quadrature degree of the element points (facets: Gauss-Legendre with
        ``max(2, (intorder + 2) // 2)`` points per segment; a 6-point rule on 3D triangles)
    fd_step_m : float, optional -- central-difference step for ``grad H_a`` of the applied field
        [m] (default 1e-5 R: truncation ~1e-10, round-off ~1e-11 relative)
    recover : bool -- ``grad H`` from the L2 projection of the self-field onto continuous P2
        over the body (default), or from the element-wise Hessian of the P2 potential (noisier;
        for a sphere in a gradient field its body-force sum errs by +5 % at n_boundary = 48
        against -0.16 % recovered)

    Returns
    -------
    MagneticLoads
    """
    g = result.geometry
    mesh = g.mesh
    dim = mesh.p.shape[0]
    axi = g.axisymmetric
    be = g.body_elements
    bb, x, dV, hd, rec = _body_field(result, intorder)
    ne, nq = x.shape[1:]
    el = np.repeat(be, nq)
    xf = x.reshape(dim, -1)
    H = result.H_applied(xf) + hd.reshape(dim, -1)
    M = _M_of(result, H, xf)
    h = fd_step_m if fd_step_m is not None else 1e-5 * g.radius_m
    dHa = _applied_gradient(result.H_applied, xf, h)
    if recover:
        dH = dHa + np.stack([np.asarray(bb.interpolate(rec[i]).grad)
                             for i in range(dim)]).reshape(dim, dim, -1)
    else:
        dH = dHa - result._hess[:, :, el]
    f = MU0 * np.einsum("ijn,jn->in", dH, M)
    # facets: Gauss points on each surface facet, M from the body side
    facets = g.body_facets
    f2t = mesh.f2t[:, facets]
    body = np.zeros(mesh.t.shape[1], bool)
    body[be] = True
    fe = np.where(body[f2t[0]], f2t[0], f2t[1])
    verts = mesh.p[:, mesh.facets[:, facets]]         # (dim, nv, nf)
    cen_e = mesh.p[:, mesh.t[:, fe]].mean(axis=1)
    if axi:
        gx, gw = np.polynomial.legendre.leggauss(max(2, (intorder + 2) // 2))
        s = 0.5 * (gx + 1.0)
        xq = verts[:, 0, :, None] * (1 - s) + verts[:, 1, :, None] * s     # (2, nf, q)
        d = verts[:, 1] - verts[:, 0]
        length = np.linalg.norm(d, axis=0)
        nrm = np.array([d[1], -d[0]]) / length
        dA = 0.5 * gw[None, :] * length[:, None] * TWO_PI * xq[0]
    else:
        # degree-3 symmetric rule on the triangle (6 points, exact to degree 4 with weights)
        bary = np.array([[0.659027622374092, 0.231933368553031, 0.109039009072877]])
        bary = np.vstack([np.roll(bary[0], k) for k in range(3)]
                         + [np.roll(bary[0][::-1], k) for k in range(3)])
        wts = np.full(6, 1.0 / 6.0)
        xq = np.einsum("qk,ikf->ifq", bary, verts)
        a, b2 = verts[:, 1] - verts[:, 0], verts[:, 2] - verts[:, 0]
        cr = np.cross(a.T, b2.T).T
        area = 0.5 * np.linalg.norm(cr, axis=0)
        nrm = cr / (2 * area)
        dA = wts[None, :] * area[:, None]
    fc = verts.mean(axis=1)
    flip = np.sum(nrm * (fc - cen_e), axis=0) < 0
    nrm[:, flip] *= -1
    nf, qf = xq.shape[1:]
    xfq = xq.reshape(dim, -1)
    elq = np.repeat(fe, qf)
    Hs = result.H_applied(xfq) - result.grad_phi(xfq, elq)
    Ms = _M_of(result, Hs, xfq).reshape(dim, nf, qf)
    Mn = np.sum(Ms * nrm[:, :, None], axis=0)
    t = 0.5 * MU0 * Mn ** 2 * nrm[:, :, None]
    return MagneticLoads(be, x, f.reshape(dim, ne, nq), dV, facets, fe, xq, nrm, t, dA, axi)


def _locate(mesh, elements, x, k_near: int = 12):
    """Index into ``elements`` (of ``mesh``) of the element holding each point ``x`` (dim, n).

    Candidates: the ``k_near`` elements with the nearest centroids; the one whose smallest
    barycentric coordinate is largest wins, so a point on a facet gets one of its elements and
    a point just outside the meshed region (between a polygonal boundary and the true curve,
    or a mechanics mesh's own surface) gets the nearest element (its fields are polynomials
    and extrapolate smoothly)."""
    t = mesh.t[:, elements]
    P = mesh.p[:, t]                                     # (dim, dim+1, ne)
    k_near = min(k_near, t.shape[1])
    _, cand = cKDTree(P.mean(axis=1).T).query(x.T, k=k_near)
    cand = cand.reshape(x.shape[1], k_near)
    T = np.transpose(P[:, 1:] - P[:, :1], (2, 0, 1))     # (ne, dim, dim): columns edges
    Tinv = np.linalg.inv(T)
    d = x.T[:, None, :] - np.transpose(P[:, 0], (1, 0))[cand]    # (n, k, dim)
    lam = np.einsum("nkij,nkj->nki", Tinv[cand], d)
    bary = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)
    best = np.argmax(bary.min(axis=2), axis=1)
    return cand[np.arange(x.shape[1]), best]


def _body_elements_at(result, x):
    """Index into ``body_elements`` of the body element holding each point ``x`` (dim, n), or
    the nearest one (see :func:`_locate`)."""
    g = result.geometry
    return _locate(g.mesh, g.body_elements, x)


def _loads_at(result, points_m, normals, fd_step_m):
    g = result.geometry
    dim = g.mesh.p.shape[0]
    x = np.asarray(check_finite("points_m", points_m, "m"), float)
    shape = x.shape
    if shape[0] != dim:
        raise InputError(f"points_m must have shape ({dim}, ...) [m], got {shape}")
    xf = x.reshape(dim, -1)
    k = _body_elements_at(result, xf)
    el = g.body_elements[k]
    H = result.H_applied(xf) - result.grad_phi(xf, el)
    M = _M_of(result, H, xf)
    if normals is not None:
        nrm = np.asarray(check_finite("normals", normals, ""), float).reshape(dim, -1)
        if nrm.shape != xf.shape:
            raise InputError(f"normals must have the shape of points_m {shape}")
        nrm = nrm / np.linalg.norm(nrm, axis=0)
        Mn = np.sum(M * nrm, axis=0)
        return (0.5 * MU0 * Mn ** 2 * nrm).reshape(shape)
    _, _, _, _, rec = _body_field(result, 4)
    elem = ElementTriP2() if g.axisymmetric else ElementTetP2()
    bfit = Basis(g.mesh, elem, elements=g.body_elements, intorder=2)
    dH = _applied_gradient(result.H_applied, xf, fd_step_m or 1e-5 * g.radius_m)
    for i in range(dim):
        g0, x0, hs = _fit_gradients(bfit, rec[i])
        dH[i] += g0[:, k] + np.einsum("ijn,jn->in", hs[:, :, k], xf - x0[:, k])
    return (MU0 * np.einsum("ijn,jn->in", dH, M)).reshape(shape)


def body_fields_at(result: MagnetostaticResult, points_m):
    """Inside values of the total field ``H`` and the magnetization ``M`` [A/m] at body points.

    points_m : (dim, ...) [m] -- points of the body (e.g. a mechanics mesh's quadrature or
        surface points); a point on the surface or slightly outside this mesh's polygonal body
        takes the fields of the body element holding it or of the nearest one.
    Returns ``(H, M)``, each (dim, ...) [A/m].
    """
    g = result.geometry
    dim = g.mesh.p.shape[0]
    x = np.asarray(check_finite("points_m", points_m, "m"), float)
    if x.shape[0] != dim:
        raise InputError(f"points_m must have shape ({dim}, ...) [m], got {x.shape}")
    xf = x.reshape(dim, -1)
    el = g.body_elements[_body_elements_at(result, xf)]
    H = result.H_applied(xf) - result.grad_phi(xf, el)
    return H.reshape(x.shape), _M_of(result, H, xf).reshape(x.shape)


def check_law(law):
    """Return ``law`` if it has the interface of a magnetization law: ``M_A_per_m(H)`` (|M| [A/m]
    at field magnitudes ``H`` [A/m], arrays, ``H >= 0``) and ``dM_dH(H)`` (d|M|/d|H| [-]);
    raise :class:`InputError` otherwise."""
    if law is None:
        raise InputError("a magnetization law is required (M_A_per_m(H), dM_dH(H))")
    return _check_law(law)


def body_force_at(result: MagnetostaticResult, points_m, fd_step_m: float | None = None):
    """Kelvin body force ``mu0 (M . grad) H`` [N/m^3] at any points of the body.

    points_m : (dim, ...) [m] -- e.g. the element quadrature points of a mechanics mesh of the
        same body (:func:`homogenize.macro.finite_strain.element_points`); points slightly
        outside this mesh's polygonal body use the nearest body element's (linear) fields.
    Returns (dim, ...) [N/m^3], same recovered gradient as :func:`magnetic_loads`.
    """
    return _loads_at(result, points_m, None, fd_step_m)


def traction_at(result: MagnetostaticResult, points_m, normals):
    """Kelvin surface traction ``(mu0 / 2) (M . n)^2 n`` [Pa] at points of the body surface.

    points_m : (dim, ...) [m]; normals : (dim, ...) -- outward normals there (normalised here),
    e.g. :func:`homogenize.macro.finite_strain.facet_points` of a mechanics mesh. ``M`` is the
    inside value (the body element holding the point, or the nearest one).
    """
    return _loads_at(result, points_m, normals, None)


def maxwell_force_N(result: MagnetostaticResult, rho1_m: float | None = None,
                    rho2_m: float | None = None) -> np.ndarray:
    """Net force [N] (dim,) from the Maxwell stress in the air (independent of the loads).

    ``F_i = -int T_ij d_j psi dV`` over the air, ``T = mu0 (H H - |H|^2 I / 2)``, with the smooth
    cut-off ``psi(rho)`` = 1 for ``rho < rho1``, 0 for ``rho > rho2`` (cosine ramp); any
    ``rho1 >`` body, ``rho2 < R`` gives the same force for the exact field (``div T = 0`` in the
    air). Defaults: 20 % and 80 % of the gap between the body and ``R``. The applied field's
    sources must lie outside ``rho2``; the stress of the applied field alone (zero net) is
    subtracted before the quadrature.
    """
    g = result.geometry
    mesh = g.mesh
    dim = mesh.p.shape[0]
    axi = g.axisymmetric
    c = g.center_m.reshape(dim, 1)
    rb = float(np.max(np.linalg.norm(mesh.p[:, mesh.t[:, g.body_elements]].reshape(dim, -1) - c,
                                     axis=0)))
    R = g.radius_m
    r1 = rb + 0.2 * (R - rb) if rho1_m is None else float(rho1_m)
    r2 = rb + 0.8 * (R - rb) if rho2_m is None else float(rho2_m)
    if not rb < r1 < r2 < R:
        raise InputError(f"need body radius {rb:.4g} < rho1 < rho2 < R = {R:.4g} m")
    elem = ElementTriP2() if axi else ElementTetP2()
    xc = mesh.p[:, mesh.t].mean(axis=1)
    rc = np.linalg.norm(xc - c, axis=0)
    air = np.setdiff1d(np.arange(mesh.t.shape[1]), g.body_elements)
    hmax = float(np.max(np.linalg.norm(mesh.p[:, mesh.t[0]] - mesh.p[:, mesh.t[1]], axis=0)))
    sel = air[(rc[air] > r1 - 2 * hmax) & (rc[air] < r2 + 2 * hmax)]
    b = Basis(mesh, elem, elements=sel, intorder=4)
    x = np.asarray(b.global_coordinates())
    nq = x.shape[2]
    xf = x.reshape(dim, -1)
    Ha = result.H_applied(xf)
    h = -result.grad_phi(xf, np.repeat(sel, nq))
    y = xf - c
    rho = np.linalg.norm(y, axis=0)
    s = np.clip((rho - r1) / (r2 - r1), 0.0, 1.0)
    dpsi = np.where((s > 0) & (s < 1), -0.5 * math.pi / (r2 - r1) * np.sin(math.pi * s), 0.0)
    gpsi = dpsi * y / rho
    # T(H_a + h) - T(H_a): the applied field's own stress is divergence-free in the annulus and
    # integrates to zero exactly, but not by quadrature when H_a is strong and non-uniform
    T = MU0 * (h[:, None] * h[None, :] + h[:, None] * Ha[None, :] + Ha[:, None] * h[None, :]
               - (0.5 * np.sum(h * h, axis=0) + np.sum(h * Ha, axis=0)) * np.eye(dim)[:, :, None])
    w = (b.dx * _weight(x, axi)).ravel()
    return -np.einsum("ijn,jn,n->i", T, gpsi, w)


def _interaction_J(result: MagnetostaticResult, scale: float = 1.0) -> float:
    """``mu0 int_body M . (scale H_a) dV`` [J] of a solved state."""
    g = result.geometry
    dim = g.mesh.p.shape[0]
    elem = ElementTriP2() if g.axisymmetric else ElementTetP2()
    b = Basis(g.mesh, elem, elements=g.body_elements, intorder=4)
    x = np.asarray(b.global_coordinates())
    nq = x.shape[2]
    xf = x.reshape(dim, -1)
    Ha = result.H_applied(xf)
    H = Ha - result.grad_phi(xf, np.repeat(g.body_elements, nq))
    M = _M_of(result, H, xf)
    w = (b.dx * _weight(x, g.axisymmetric)).ravel()
    return float(MU0 * np.sum(np.sum(M * Ha, axis=0) * w) / scale)


def coenergy_J(result: MagnetostaticResult, n_ramp: int = 8) -> float:
    """Co-energy [J] of the body in the applied field at fixed sources (relative to no body).

    ``W' = mu0 int_0^1 dl int_body M_l . H_a dV``, where ``M_l`` is the magnetization under the
    applied field ``l H_a`` (the sources ramped up at fixed geometry: by reciprocity the body
    adds ``mu0 int M . h_a dV`` to the flux linked by a source of unit strength). A linear law
    gives ``(mu0 / 2) int M . H_a dV`` directly; any other law is integrated over ``l`` by
    ``n_ramp``-point Gauss-Legendre, one solve on the same mesh per point. The integrand is
    analytic in ``l``; for the saturating laws here its nearest singularity sits near
    ``l = -Ms / (chi0 |H|)``, so the rule converges fast while ``chi0 |H| < Ms`` and slowly deep
    in saturation (then raise ``n_ramp``). The force
    at fixed sources is ``F = +dW'/dx`` of the body's position (virtual work). Not defined for
    an imposed magnetization.
    """
    if result.law is None:
        raise InputError("coenergy_J needs a magnetization law (not M_imposed)")
    if isinstance(result.law, LinearLaw):
        return 0.5 * _interaction_J(result)
    if int(n_ramp) != n_ramp or n_ramp < 1:
        raise InputError(f"n_ramp must be an integer >= 1, got {n_ramp!r}")
    lam, wl = np.polynomial.legendre.leggauss(int(n_ramp))
    lam, wl = 0.5 * (lam + 1.0), 0.5 * wl
    Ha = result.H_applied
    total = 0.0
    for li, wi in zip(lam, wl):
        ri = _solve(result.geometry, result.law, 0.0, lambda x, li=li: li * Ha(x), None,
                    "kelvin" if result.phi_exterior_A is not None else "dirichlet",
                    1e-10 if result.geometry.axisymmetric else 1e-8, 50,
                    "direct" if result.geometry.axisymmetric else "auto")
        # M_l . H_a = (M_l . l H_a) / l
        total += wi * _interaction_J(ri, li)
    return total
