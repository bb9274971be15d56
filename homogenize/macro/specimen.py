"""The specimen in its field: magneto-mechanics of a finite, deforming body (of revolution, or 3D).

What a magnetostriction experiment measures is the change of LENGTH of a specimen between its
end faces (or poles), not the volume-mean strain of an RVE. This module predicts it: the field
in and around the body (:mod:`homogenize.macro.magnetostatics`, exact exterior by the Kelvin
transformation, the body's nonlinear law ``M(H)`` by Newton) and the finite-strain, nearly
incompressible neo-Hookean body (:mod:`homogenize.macro.finite_strain`, Taylor-Hood u-p) are
solved in turn on the DEFORMED body until the change of length stops changing (staggered
coupling), field step after field step.

Magnetic loads, in one formulation (Kelvin's; see :mod:`homogenize.macro.magnetostatics` for
its equivalence with the Maxwell stress): the surface traction ``(mu0 / 2) (M . n)^2 n`` and the
body force ``f = mu0 (M . grad) H``. For the isotropic laws of a soft composite ``M`` is parallel
to ``H`` and ``curl H = 0``, so ``f = mu0 M grad|H| = grad psi`` with the magnetic pressure

    psi(x) = mu0 int_0^|H(x)| M(h) dh   [Pa]

(``mu0 chi H^2 / 2`` for a linear law). A gradient body force is the divergence of the isotropic
stress ``psi I``; moving it to the boundary gives the loads actually applied, equal to the
Kelvin ones in the continuum and free of field gradients (which a P2 potential resolves only to
first order, and not at all across the surface):

* traction ``t = [(mu0 / 2) (M . n)^2 + psi] n`` per current area on the current surface
  (``M``, ``H`` the inside values);
* the Cauchy stress ``psi I`` added to the elastic one at each material point: it loads a
  nearly incompressible body only through the non-uniform part of ``psi`` (a uniform ``psi``,
  as inside an ellipsoid, cancels the extra traction exactly);
* the microstructural magnetic stress of the particles' interactions (models ``affine`` and
  ``relaxed``): the RVE's ``stress_mag`` as a Cauchy stress at each material point,
  ``sigma_mag = kappa mu0 |M|^2 (m m - I/3)``, ``m = M / |M|``: a positive ``kappa`` shortens a
  free body along ``M`` by ``kappa mu0 M^2 / (3 G)`` (small strain, incompressible). Only its
  deviatoric part is kept: the RVE's isotropic part is a pressure that a nearly incompressible
  body does not feel.

A uniform part of ``psi`` loads nothing (``psi_ref n`` on the surface and ``psi_ref I`` inside
are in equilibrium for any shape), so the solver takes the body's volume mean ``psi_ref`` out
of both. This matters for the mechanics' Newton, not for the answer: the loads are frozen at
each staggered iterate (the traction's direction is the last iterate's normal), and a frozen
traction of several G (``psi`` reaches ~4 G near 1 T in the Diguet composite) that no longer
turns with the surface has a spurious load stiffness that put a limit point into the Newton
near the rim (the cylinders stopped at 0.85-0.99 T before; they reach 1.13 T now, and the
staggered iteration contracts faster). A field step that still fails is cut in half
(``max_substeps``) before :class:`ConvergenceError`; the staggered iteration stops when its
change, divided by the Aitken factor of that update, is below ``tol``.

Models (``model=``), so that three descriptions can be compared on the same specimen:

* ``"continuum"`` -- the Kelvin loads only (no microstructural term), as the continuum models
  of Lefevre, Danas & Lopez-Pamies (J. Mech. Phys. Solids 107, 343, 2017) and Stewart & Anand
  (J. Mech. Phys. Solids 194, 105934, 2025) assume;
* ``"affine"`` -- plus ``sigma_mag`` of randomly dispersed particles moving affinely with the
  matrix, ``kappa(phi, m)`` from the project's cell FEM
  (:func:`homogenize.experiments.rve_tables.affine_kappa`, reduced magnetization
  ``m = |M| / (phi Ms)``);
* ``"relaxed"`` -- plus ``sigma_mag`` of RVEs whose particles restructure in the field; its
  ``kappa(|M|)`` comes from relax tables and is passed in by the caller (``kappa=``).

For a sphere with a uniform magnetization (the linear limit) the continuum model's pole strain
is ``(5/57) mu0 M^2 / G`` and its volume-mean strain ``(1/15) mu0 M^2 / G`` (Lamb's solution;
tests), while a uniform ``sigma_mag`` strains the free body uniformly: the affine model with the
isotropic (Lorentz) value ``kappa = 1/5`` cancels the mean strain of a sphere exactly but not
its change of length, ``(5/57 - 1/15) mu0 M^2 / G``.

Three dimensions (``Specimen(..., geometry="3d")``: a cylinder or a box, issue 34). The same
loads, staggered loop and observables on tetrahedra, with the three symmetry planes of a body
centred in a uniform axial field: the mechanics on the octant ``x, y, z >= 0``
(:func:`homogenize.macro.finite_strain.cylinder_body_3d` / ``box_body``, P2/P1 Taylor-Hood,
rim or edges rounded as the axisymmetric rim), the field on that same mesh plus air layers
extruded along rays to the sphere of twice the body's size and its Kelvin image
(:func:`homogenize.macro.magnetostatics.octant_mesh_3d`: ``phi = 0`` on ``z = 0``, AMG-CG
solves). The field mesh's body part IS the mechanics mesh, so it moves with the body exactly
(vertex displacements; the air blended along its rays). Each staggered iterate's mechanics
starts Newton from the previous one (``solve_3d(initial=...)``). Accuracy against the
axisymmetric solve of the same cylinder (tests, bench): strains within 0.2-0.8 % at n_mesh 6
and 2-7 % at 4 in the linear regime, within 0.2-1.2 % at n_mesh 6 at 1.2 T (2 % strain);
cost of the 13-step benchmark in :mod:`homogenize.bench.bench_specimen` (n_mesh 6: 83 s CPU,
0.47 GB). Not covered in 3D: spheres and spheroids (axisymmetric only). VTU output: the octant
mirrored to the whole body (:func:`homogenize.macro._specimen_output.write_specimen_vtu`).

In the field of a magnet (:func:`solve_specimen_on_magnet`, :func:`solve_specimen_in_field`,
issue 34). A cylinder resting with its bottom face on a rigid, frictionless plate (``u_z = 0``
there, ``u_r`` free; or ``support="free"``), a coaxial cylindrical permanent magnet (magpylib,
:class:`homogenize.macro.magnets.PermanentMagnet`) below the plate, its field ``H_a(x)``
entering the field solve as the applied field (the reduced potential is the specimen's own;
the magnet is rigid). The experimenter's steps: the magnet approached, the gap between its top
face and the specimen's bottom face strictly decreasing. The loads are the ones above: ``f =
mu0 (M . grad) H = grad psi`` needs only ``curl H = 0`` and ``M`` parallel to ``H``, true in
any applied field, so the same traction and stress ``psi I`` apply; in a non-uniform field
they have a net force, which the plate carries. Verified (tests/homogenize/macro/
test_specimen_magnet.py): the plate's reaction against the Maxwell stress on a shell in the
air (-0.6 %), a small weakly magnetizable cylinder against the dipole force
``chi V mu0 (H . grad) H`` at its centre (+1.2 %, the field's curvature) and against the
applied field's own volume integral (-1.7e-4), a uniform ``H_a`` callable against the
uniform-field path (``<M>`` 2e-7, mean strain 2e-4, changes of length 0.2 %).

Units: SI (m, Pa, A/m, T).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.constants import mu_0 as MU0
from scipy.spatial import cKDTree
from skfem import MeshTet, MeshTri

from homogenize.macro import finite_strain as fs
from homogenize.macro import magnetostatics as ms
from micro.common.validate import ConvergenceError, InputError, check_choice, check_positive

__all__ = ["MODELS", "SHAPES", "SHAPES_3D", "GEOMETRIES", "SUPPORTS", "Specimen",
           "SpecimenStep", "SpecimenResult", "SupportedStep", "solve_specimen",
           "solve_specimen_in_field", "solve_specimen_on_magnet", "check_gaps",
           "magnetic_pressure_Pa", "volume_change_m3"]

MODELS = ("continuum", "affine", "relaxed")
#: shapes of an axisymmetric specimen (``geometry="axisymmetric"``)
SHAPES = ("sphere", "spheroid", "cylinder")
#: shapes of a three-dimensional specimen (``geometry="3d"``)
SHAPES_3D = ("cylinder", "box")
GEOMETRIES = ("axisymmetric", "3d")


@dataclass(frozen=True)
class Specimen:
    """A specimen centred on the origin, its axis z along the applied field.

    shape : "sphere" | "spheroid" | "cylinder" (axisymmetric); "cylinder" | "box" (3D)
    radius_m : equatorial radius / cylinder radius R [m]; a box: half its width, the box's
        cross-section is the square ``|x|, |y| <= R``
    length_m : length along the field, pole to pole or end face to end face [m] (a sphere:
        ``2 R``, given or not)
    n_mesh : elements along the radius of the mechanics mesh (quarter section; 3D: of the
        octant, along the radius / half width) [-]
    n_boundary : segments of the field mesh along the body's meridian profile [-] (default
        48; axisymmetric only: the 3D field mesh's body part is the mechanics mesh itself)
    edge_radius_m : a cylinder's rim (a box's edges and corners) rounded with this radius [m]
        (default ``0.1 R``; 0: a sharp edge). At a sharp edge the field, hence the Kelvin loads,
        are singular and the rubber strains without bound at finite field; a cast or cut
        specimen's edge has some radius, and the results' sensitivity to it is part of their
        model error.
    geometry : "axisymmetric" (default: a body of revolution, meridian meshes) | "3d" (the
        octant ``x, y, z >= 0`` of a cylinder or box meshed in tetrahedra, with its three
        symmetry planes; field and mechanics in 3D)
    """
    shape: str
    radius_m: float
    length_m: float | None = None
    n_mesh: int = 8
    n_boundary: int | None = None
    edge_radius_m: float | None = None
    geometry: str = "axisymmetric"

    def __post_init__(self):
        check_choice("geometry", self.geometry, GEOMETRIES)
        if self.geometry == "3d":
            if self.shape not in SHAPES_3D:
                raise InputError(f"a 3D specimen (geometry='3d') is a {' or a '.join(SHAPES_3D)},"
                                 f" got shape {self.shape!r} (a sphere or spheroid: use the "
                                 "axisymmetric geometry)")
            if self.n_boundary is not None:
                raise InputError("n_boundary is the axisymmetric field mesh's resolution; a 3D "
                                 "specimen's field mesh is built on its mechanics mesh "
                                 "(set n_mesh)")
        else:
            if self.shape == "box":
                raise InputError("a box is not a body of revolution: use geometry='3d'")
            check_choice("shape", self.shape, SHAPES)
            if self.n_boundary is None:
                object.__setattr__(self, "n_boundary", 48)
        R = check_positive("radius_m", self.radius_m, "m")
        if self.length_m is None:
            if self.shape != "sphere":
                raise InputError(f"a {self.shape} needs length_m (its length along the field)")
            object.__setattr__(self, "length_m", 2.0 * R)
        L = check_positive("length_m", self.length_m, "m")
        if self.shape == "sphere" and abs(L - 2.0 * R) > 1e-9 * R:
            raise InputError(f"a sphere of radius {R:g} m has length 2R = {2 * R:g} m, got "
                             f"length_m = {L:g} m (use shape='spheroid')")
        for name, lo in (("n_mesh", 2), ("n_boundary", 16)):
            v = getattr(self, name)
            if v is None and self.geometry == "3d":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer)) \
                    or int(v) != v or v < lo:
                raise InputError(f"{name} must be an integer >= {lo}, got {v!r}")
        if self.shape not in ("cylinder", "box"):
            if self.edge_radius_m not in (None, 0, 0.0):
                raise InputError(f"edge_radius_m is for a cylinder's rim, not a {self.shape}")
            object.__setattr__(self, "edge_radius_m", 0.0)
        elif self.edge_radius_m is None:
            object.__setattr__(self, "edge_radius_m", 0.1 * (R if self.shape == "cylinder"
                                                             else min(R, 0.5 * L)))
        else:
            rho = check_positive("edge_radius_m", self.edge_radius_m, "m", allow_zero=True)
            if rho >= 0.5 * min(R, 0.5 * L):
                raise InputError(f"edge_radius_m = {rho:g} m must be below half the radius "
                                 f"({0.5 * R:g} m) and half the half-length "
                                 f"({0.25 * L:g} m)")

    @property
    def aspect_ratio(self) -> float:
        """Length over diameter, ``L / (2 R)`` [-]."""
        return self.length_m / (2.0 * self.radius_m)

    def mechanics_body(self):
        """The quarter section ``r >= 0, z >= 0`` (symmetry planes r = 0 and z = 0), an
        :class:`~homogenize.macro.finite_strain.AxisymmetricBody`; 3D: the octant
        ``x, y, z >= 0`` (:class:`~homogenize.macro.finite_strain.SolidBody`)."""
        if self.geometry == "3d":
            return _mechanics_body_3d(self)
        R, c, n = self.radius_m, 0.5 * self.length_m, int(self.n_mesh)
        if self.shape == "sphere":
            return fs.sphere_body(R, n)
        if self.shape == "spheroid":
            return fs.spheroid_body(R, c, n)
        body = fs.cylinder_body(R, self.length_m, n)
        rho = float(self.edge_radius_m)
        if rho == 0.0:
            return body
        # round the rim: the corner square of side rho mapped onto a quarter disk
        # (a' = a sqrt(1 - b^2 / 2 rho^2), b' = b sqrt(1 - a^2 / 2 rho^2) in the square's
        # coordinates from the fillet's centre); its edges a = 0 and b = 0 stay in place
        mesh = body.mesh
        p = mesh.p.copy()
        a, b = p[0] - (R - rho), p[1] - (c - rho)
        sel = (a > 0) & (b > 0)
        an, bn = a[sel] / rho, b[sel] / rho
        p[0, sel] = R - rho + rho * an * np.sqrt(1.0 - 0.5 * bn * bn)
        p[1, sel] = c - rho + rho * bn * np.sqrt(1.0 - 0.5 * an * an)
        bnd = dict(mesh.boundaries)
        flat = np.all(np.abs(p[1, mesh.facets[:, bnd["end"]]] - c) <= 1e-12 * c, axis=0)
        bnd["end"] = bnd["end"][flat]                     # the flat part of the end face
        return fs.AxisymmetricBody(MeshTri(p, mesh.t, _boundaries=bnd), "cylinder", R, c,
                                   True)


def _mechanics_body_3d(spec: Specimen) -> fs.SolidBody:
    """The octant of a 3D cylinder or box, its rim (edges) rounded with ``edge_radius_m``.

    Cylinder: :func:`~homogenize.macro.finite_strain.cylinder_body_3d` with the quarter disk's
    rings graded towards the side as the axisymmetric mesh's (exponent 1.5), its rim rounded
    by the axisymmetric map in each meridian plane. Box:
    :func:`~homogenize.macro.finite_strain.box_body` (graded towards the faces), its edges and
    corners rounded by mapping the cube of side ``rho`` at each of them onto the ball octant
    (``e_i' = e_i sqrt(1 - (e_j^2 + e_k^2) / 2 + e_j^2 e_k^2 / 3)`` of the coordinates
    ``e = (|x_i| - (h_i - rho)) / rho`` in ``[0, 1]``; an edge's square onto the quarter disk
    when one of them is 0). ``"end"``: the flat part of the end face."""
    R, L, n = spec.radius_m, spec.length_m, int(spec.n_mesh)
    c = 0.5 * L
    rho = float(spec.edge_radius_m)
    n_z = max(1, int(round(n * c / R)))
    if spec.shape == "cylinder":
        body = fs.cylinder_body_3d(R, L, n, n_z, radial_grading=1.5)
    else:
        body = fs.box_body((2 * R, 2 * R, L), (n, n, n_z), grading=1.5)
    if rho == 0.0:
        return body
    mesh = body.mesh
    p = mesh.p.copy()
    if spec.shape == "cylinder":
        r = np.hypot(p[0], p[1])
        a, b = r - (R - rho), p[2] - (c - rho)
        sel = (a > 0) & (b > 0)
        an, bn = a[sel] / rho, b[sel] / rho
        r_new = R - rho + rho * an * np.sqrt(1.0 - 0.5 * bn * bn)
        p[0, sel] *= r_new / r[sel]
        p[1, sel] *= r_new / r[sel]
        p[2, sel] = c - rho + rho * bn * np.sqrt(1.0 - 0.5 * an * an)
    else:
        h = np.array([[R], [R], [c]])
        e = np.clip((p - (h - rho)) / rho, 0.0, None)
        e2 = e * e
        f = np.empty_like(e)
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            f[i] = e[i] * np.sqrt(1.0 - 0.5 * (e2[j] + e2[k]) + e2[j] * e2[k] / 3.0)
        sel = e > 0
        p[sel] = (h - rho + rho * f)[sel]
    bnd = dict(mesh.boundaries)
    flat = np.all(np.abs(p[2, mesh.facets[:, bnd["end"]]] - c) <= 1e-12 * c, axis=0)
    bnd["end"] = bnd["end"][flat]
    return fs.SolidBody(MeshTet(p, mesh.t, _boundaries=bnd), body.shape, body.half_extent_m,
                        body.symmetry)


@dataclass(frozen=True)
class SpecimenStep:
    """The converged state at one applied field (SI).

    B_applied_T : mu0 H0 of the uniform applied field [T]
    M_mean_A_per_m : volume mean of M_z over the deformed body [A/m]
    H_mean_A_per_m : volume mean of H_z inside [A/m]; demag_factor : (H0 - <H>) / <M> [-]
    length_change_axis_m, length_change_mean_m : change of the length between the end faces on
        the axis, and between the area means of the end faces (cylinder; NaN for a sphere or
        spheroid, whose ends are the poles) [m]
    strain_axis, strain_end_mean : the same over the initial length [-]
    diameter_change_m, lateral_strain : at mid-height / the equator [m], [-]
    mean_strain_zz : volume mean of the axial strain (what an RVE gives) [-]
    volume_change_m3 : change of the body's volume, ``int (J - 1) dV`` [m^3]
    stagger_iterations : field-mechanics iterations; newton_iterations : all Newton steps
    stagger_history : relative change of the length per iteration [-]
    """
    B_applied_T: float
    M_mean_A_per_m: float
    H_mean_A_per_m: float
    demag_factor: float
    length_change_axis_m: float
    length_change_mean_m: float
    strain_axis: float
    strain_end_mean: float
    diameter_change_m: float
    lateral_strain: float
    mean_strain_zz: float
    stagger_iterations: int
    newton_iterations: int
    stagger_history: tuple
    volume_change_m3: float = float("nan")


def volume_change_m3(sol) -> float:
    """``int (J - 1) dV`` [m^3] over the whole reference body (mirror images included) of a
    mechanics solution: the change of the volume of the deformed (curved, P2) body; the
    element rule integrates the cubic ``det F`` of P2 displacements exactly."""
    J = np.linalg.det(fs.deformation_gradient(sol))
    b = sol.basis
    dx = np.asarray(b.dx)
    if isinstance(sol, fs.Solution3D):
        factor = 2.0 ** sum(sol.body.symmetry)
    else:
        dx = dx * 2.0 * math.pi * np.asarray(b.global_coordinates())[0]
        factor = 2.0 if sol.body.mid_plane else 1.0
    return float(factor * np.sum((J - 1.0) * dx))


@dataclass(frozen=True)
class SpecimenResult:
    """All field steps of :func:`solve_specimen` (``steps``), with what produced them."""
    specimen: Specimen
    model: str
    shear_modulus_Pa: float
    bulk_modulus_Pa: float
    law: str
    steps: tuple
    solution: object = field(repr=False, compare=False, default=None)
    field_result: object = field(repr=False, compare=False, default=None)
    #: a specimen on a plate in a non-uniform field (:func:`solve_specimen_in_field`): its
    #: support, frame and magnet (None: the free body in a uniform field)
    setup: dict | None = field(compare=False, default=None)

    def to_dict(self) -> dict:
        """JSON-ready (SI units)."""
        s = self.specimen
        # the supported body's volume_m3 counts the image of its plate (a plane of symmetry)
        vol = (None if self.solution is None else
               float(self.solution.body.volume_m3)
               / (2.0 if (self.setup or {}).get("support") == "plate" else 1.0))
        return {"specimen": {"shape": s.shape, "radius_m": s.radius_m, "length_m": s.length_m,
                             "aspect_ratio_L_over_D": s.aspect_ratio, "n_mesh": s.n_mesh,
                             "n_boundary": s.n_boundary,
                             "mesh_volume_m3": vol,
                             **({"geometry": "3d", "edge_radius_m": s.edge_radius_m}
                                if s.geometry == "3d" else {})},
                "model": self.model, "shear_modulus_Pa": self.shear_modulus_Pa,
                "bulk_modulus_Pa": self.bulk_modulus_Pa, "law": self.law,
                "steps": [dict(st.__dict__, stagger_history=list(st.stagger_history))
                          for st in self.steps],
                **({"setup": self.setup} if self.setup else {})}


def _check_steps(B_applied_T) -> np.ndarray:
    B = np.atleast_1d(np.asarray(B_applied_T, dtype=float))
    if B.ndim != 1 or B.size == 0 or not np.all(np.isfinite(B)):
        raise InputError("the applied field steps B_applied_T must be a non-empty list of "
                         "finite values [T]")
    if B[0] < 0 or np.any(np.diff(B) <= 0):
        raise InputError(f"the applied field steps must increase strictly from >= 0 T, got "
                         f"{B.tolist()}")
    return B


def _field_shape(specimen: Specimen):
    R, c = specimen.radius_m, 0.5 * specimen.length_m
    if specimen.shape == "sphere":
        return ms.Sphere(R)
    if specimen.shape == "spheroid":
        return ms.Spheroid(c, R)
    rho = float(specimen.edge_radius_m)
    if rho == 0.0:
        return ms.Cylinder(R, specimen.length_m)
    t = np.linspace(0.0, 0.5 * np.pi, 17)
    arc = np.column_stack([R - rho + rho * np.sin(t), c - rho + rho * np.cos(t)])
    upper = np.vstack([[0.0, c], arc])
    return ms.Profile(np.vstack([upper, upper[::-1] * np.array([1.0, -1.0])]))


def _vertex_displacement(sol, x, mirror: bool = True) -> np.ndarray:
    """The mechanics displacement [m] at points ``x`` (2, n) of the whole section: the quarter's
    vertex displacements interpolated linearly in the triangle holding each point (mirrored
    about z = 0; ``mirror=False``: a mesh of the whole section, as it is), or extrapolated
    from the nearest triangle for a point just outside the
    quarter's polygon (the exact profile bulges past the inscribed mesh). Plain numpy: scipy's
    Delaunay-based interpolators make one small LAPACK call per triangle, which multithreaded
    BLAS slows by orders of magnitude."""
    mesh = sol.body.mesh
    nv = mesh.p.shape[1]
    xq = np.vstack([x[0], np.abs(x[1]) if mirror else x[1]])
    P = mesh.p[:, mesh.t]                                       # (2, 3, ne)
    cent = P.mean(axis=1).T
    k = min(8, mesh.t.shape[1])
    _, cand = cKDTree(cent).query(xq.T, k=k)
    cand = cand.reshape(x.shape[1], k)
    a, b, c = P[:, 0][:, cand], P[:, 1][:, cand], P[:, 2][:, cand]   # (2, n, k)
    det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
    dx, dy = xq[0][:, None] - a[0], xq[1][:, None] - a[1]
    l1 = (dx * (c[1] - a[1]) - (c[0] - a[0]) * dy) / det
    l2 = ((b[0] - a[0]) * dy - dx * (b[1] - a[1])) / det
    lam = np.stack([1.0 - l1 - l2, l1, l2])                     # (3, n, k)
    best = np.argmax(lam.min(axis=0), axis=1)
    rows = np.arange(x.shape[1])
    el = cand[rows, best]
    w = lam[:, rows, best]                                      # (3, n)
    u = sol.u_m[:, :nv][:, mesh.t[:, el]]                       # (2, 3, n)
    out = np.einsum("ivn,vn->in", u, w)
    if mirror:
        out[1] *= np.sign(x[1]) + (x[1] == 0)
    return out


def _moved_geometry(g0: ms.BodyMesh, sol, mirror: bool = True) -> ms.BodyMesh:
    """The field mesh ``g0`` of the undeformed body moved with the body: its body vertices by
    the mechanics displacement (:func:`_vertex_displacement`), the air vertices by the displacement of the
    body surface on their ray, blended linearly to zero at the domain sphere (whose Kelvin
    exterior stays as it is). Moving one mesh instead of meshing the deformed body anew keeps
    the field a smooth function of the deformation: the staggered iteration then converges to
    its tolerance, not to the noise of re-meshing."""
    if sol is None:
        return g0
    mesh = g0.mesh
    p = mesh.p
    body_v = np.unique(mesh.t[:, g0.body_elements])
    d = np.zeros_like(p)
    d[:, body_v] = _vertex_displacement(sol, p[:, body_v], mirror)
    # air: the body surface's displacement along each ray, to zero at the domain sphere
    c = g0.center_m.reshape(2, 1)
    y = p - c
    rho, theta = np.hypot(y[0], y[1]), np.arctan2(y[0], y[1])
    surf = np.unique(mesh.facets[:, g0.body_facets])
    order = surf[np.argsort(theta[surf])]
    air = np.setdiff1d(np.arange(p.shape[1]), body_v)
    ts = theta[order]
    rho_b = np.interp(theta[air], ts, rho[order])
    w = np.clip((g0.radius_m - rho[air]) / (g0.radius_m - rho_b), 0.0, 1.0)
    for i in range(2):
        d[i, air] = w * np.interp(theta[air], ts, d[i, order])
    d[0, p[0] == 0.0] = 0.0                                # the axis stays the axis
    return ms.BodyMesh(MeshTri(p + d, mesh.t), g0.body_elements, g0.exterior_mesh,
                       g0.center_m, g0.radius_m, True)


def _moved_geometry_3d(g0: ms.BodyMesh, sol, rays) -> ms.BodyMesh:
    """The 3D field mesh ``g0`` (:func:`homogenize.macro.magnetostatics.octant_mesh_3d` of the
    mechanics mesh) moved with the body: its body vertices ARE the mechanics mesh's vertices
    (moved by their displacement, no interpolation), an air vertex by the displacement of the
    surface vertex on its ray ``rays`` blended linearly to zero at the domain sphere (the
    Kelvin exterior stays as it is)."""
    if sol is None:
        return g0
    p = g0.mesh.p
    nv = sol.body.mesh.p.shape[1]
    d = np.zeros_like(p)
    d[:, :nv] = sol.u_m[:, :nv]
    air = np.arange(nv, p.shape[1])
    rho = np.linalg.norm(p[:, air], axis=0)
    rho_b = np.linalg.norm(p[:, rays], axis=0)
    w = np.clip((g0.radius_m - rho) / (g0.radius_m - rho_b), 0.0, 1.0)
    d[:, air] = w * d[:, rays]
    return ms.BodyMesh(MeshTet(p + d, g0.mesh.t), g0.body_elements, g0.exterior_mesh,
                       g0.center_m, g0.radius_m, False, True)


def _air_rays(g0: ms.BodyMesh, body_mesh) -> np.ndarray:
    """For each air vertex of the :func:`~homogenize.macro.magnetostatics.octant_mesh_3d` mesh
    of ``body_mesh``, the body-surface vertex on its ray (the builder's layer order)."""
    bn = np.unique(ms.octant_surface_facets(body_mesh))
    nv = body_mesh.p.shape[1]
    return bn[np.arange(g0.mesh.p.shape[1] - nv) % bn.size]


def _prescribed_stress(M, kappa) -> np.ndarray:
    """``kappa mu0 |M|^2 (m m - I/3)`` at points: ``M`` (2, ne, nq) (r, z) -> (ne, nq, 3, 3)
    Cartesian at the meridian plane (x = r, y = theta, z); ``M`` (3, ne, nq) (x, y, z) ->
    Cartesian."""
    if M.shape[0] == 3:
        M2 = np.sum(M * M, axis=0)
        k = np.asarray(kappa(np.sqrt(M2)), float) * MU0
        S = np.einsum("i...,j...->...ij", M, M) - (M2 / 3.0)[..., None, None] * np.eye(3)
        return k[..., None, None] * S
    Mr, Mz = M
    M2 = Mr * Mr + Mz * Mz
    k = np.asarray(kappa(np.sqrt(M2)), float) * MU0
    S = np.zeros(M2.shape + (3, 3))
    S[..., 0, 0] = k * (Mr * Mr - M2 / 3.0)
    S[..., 2, 2] = k * (Mz * Mz - M2 / 3.0)
    S[..., 1, 1] = k * (-M2 / 3.0)
    S[..., 0, 2] = S[..., 2, 0] = k * Mr * Mz
    return S


#: Gauss-Legendre rule of the magnetic pressure integral psi = mu0 int_0^H M(h) dh: M(h) of
#: the laws is smooth (analytic) on [0, H]; 24 points integrate it to round-off for H up to
#: many times the saturation knee (checked against the closed forms in the tests)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


def magnetic_pressure_Pa(law, H_abs) -> np.ndarray:
    """``psi = mu0 int_0^H M(h) dh`` [Pa] of an isotropic law at field magnitudes ``H_abs``
    [A/m] (array); the Kelvin body force of a soft body is ``grad psi``."""
    H = np.asarray(H_abs, float)
    h = 0.5 * H[..., None] * (_GL_X + 1.0)
    return MU0 * 0.5 * H * np.sum(_GL_W * np.asarray(law.M_A_per_m(h), float), axis=-1)


def _element_state(body, sol):
    """Current positions (2, ne, nq) of the element quadrature points and J = det F."""
    X = fs.element_points(body)
    if sol is None:
        return X, np.ones(X.shape[1:])
    u = np.stack([np.asarray(sol.basis.interpolate(ui)) for ui in sol.u_m])
    return X + u, np.linalg.det(fs.deformation_gradient(sol))


def _reference_weights(body) -> np.ndarray:
    """Reference volume weights (ne, nq) at the points of :func:`fs.element_points` (an
    axisymmetric body's with ``2 pi r``) [m^3]."""
    from skfem import CellBasis
    b = CellBasis(body.mesh, fs._p2(body.mesh), intorder=fs.INTORDER)
    dx = np.asarray(b.dx)
    if isinstance(body, fs.AxisymmetricBody):
        dx = dx * 2.0 * math.pi * np.asarray(b.global_coordinates())[0]
    return dx


def _law_name(law) -> str:
    params = ", ".join(f"{k}={v:g}" for k, v in getattr(law, "__dict__", {}).items()
                       if isinstance(v, (int, float)))
    return f"{type(law).__name__}({params})"


def _solve_mechanics_3d(body, solid, loads, load_steps, previous):
    """The 3D mechanics: Newton from the previous staggered iterate or field step (its loads
    are near these: two or three Newton steps instead of a load ramp from the undeformed
    body), from the undeformed body in ``load_steps`` if that fails or there is none."""
    if previous is not None:
        try:
            return fs.solve_3d(body, solid, loads, load_steps=1, initial=previous, max_cuts=2)
        except ConvergenceError:
            pass
    return fs.solve_3d(body, solid, loads, load_steps=load_steps)


#: Newton tolerance of the 3D field solves (AMG-CG inside): the staggered iteration's own
#: tolerance (1e-4 on the change of length) is far above it
_FIELD_RTOL_3D = 1e-8


def _staggered_step(body, law, solid, kappa, field_solve, mech_solve, length_change, L0,
                    tol, max_stagger, relaxation, sol, label, trivial, steps):
    """One field step's staggered field-mechanics iteration (Aitken-relaxed loads, module
    docstring): ``field_solve(sol)`` the field on the body deformed by ``sol`` (None: the
    undeformed body), ``mech_solve(loads, sol)`` the mechanics under the Kelvin loads,
    ``length_change(sol)`` [m] the observable whose relative change stops the iteration;
    ``label`` names the step in errors, ``trivial`` (no field) stops after one iteration.
    Returns ``(sol, res, iterations, newton_iterations, history)``."""
    hist, newton, dl_prev, w = [], 0, None, relaxation
    x_prev = r_prev = None
    w_used = 1.0
    vol_w = _reference_weights(body)
    for it in range(1, max_stagger + 1):
        res = field_solve(sol)
        ms.check_table_range(res, "the composite's magnetization table")
        if sol is None:
            xf, nf = fs.facet_points(body)
        else:
            xf, nf = fs.current_facet_points(sol)
        xe, _ = _element_state(body, sol)
        Hf, Mf = ms.body_fields_at(res, xf)
        nf = nf / np.linalg.norm(nf, axis=0)
        He, Me = ms.body_fields_at(res, xe)
        psi_e = magnetic_pressure_Pa(law, np.linalg.norm(He, axis=0))
        # the uniform part of psi (its volume mean) loads nothing: psi_ref n on the surface
        # and psi_ref I inside are in equilibrium for any shape. Subtracted from both, it no
        # longer stiffens or softens the frozen loads of the mechanics' Newton (their
        # direction is the last iterate's normal): at large fields psi_ref reaches several
        # G and its spurious load stiffness put a limit point into the mechanics
        psi_ref = float(np.sum(psi_e * vol_w) / np.sum(vol_w))
        psi_f = magnetic_pressure_Pa(law, np.linalg.norm(Hf, axis=0)) - psi_ref
        t = (0.5 * MU0 * np.sum(Mf * nf, axis=0) ** 2 + psi_f) * nf
        S = (psi_e - psi_ref)[..., None, None] * np.eye(3)
        if kappa is not None:
            S = S + _prescribed_stress(Me, kappa)
        g = np.concatenate([t.ravel(), S.ravel()])
        if x_prev is None:                # the step's first iteration: the loads as they are
            x = g
        else:
            # Aitken's dynamic relaxation (Irons & Tuck) of the load vector: the staggered
            # iteration is a fixed point x = g(x) that contracts slowly where the body's
            # elongation and its magnetization feed each other
            r = g - x_prev
            if r_prev is not None:
                dr = r - r_prev
                den = float(dr @ dr)
                if den > 0.0:
                    w = float(np.clip(-w * float(r_prev @ dr) / den, 0.05, 1.0))
            x = x_prev + w * r
            r_prev = r
            w_used = w
        x_prev = x
        t = x[:t.size].reshape(t.shape)
        S = x[t.size:].reshape(S.shape)
        loads = fs.Loads((fs.Traction(t, "surface", follower=True),),
                         prescribed_stress_Pa=S)
        try:
            sol = mech_solve(loads, sol)
        except ConvergenceError as exc:
            err = ConvergenceError(
                f"the mechanics did not converge at {label} (staggered iteration "
                f"{it}): {exc}", getattr(exc, "residual_history", ()))
            err.steps_converged = tuple(steps)
            raise err from None
        newton += sol.newton_iterations
        dl = length_change(sol)
        if dl_prev is not None:
            # relative to the change of length, or to the magnetic strain scale
            # mu0 <M>^2 / G where the two load parts cancel (affine sphere)
            scale = max(abs(dl), L0 * MU0 * float(res.M_mean_A_per_m[-1]) ** 2
                        / solid.G_Pa, 1e-300)
            change = abs(dl - dl_prev) / scale
            hist.append(float(change))
            # the change after a load update relaxed by w_used is about w_used times the
            # fixed point's residual: a strongly damped iteration must not stop on its own
            # small steps
            if change <= tol * w_used:
                break
        elif trivial:
            hist.append(0.0)
            break
        dl_prev = dl
    else:
        err = ConvergenceError(
            f"the field-mechanics iteration did not converge at {label} in "
            f"{max_stagger} iterations (relative changes of the length "
            f"{', '.join(f'{h:.2g}' for h in hist[-5:])}); try relaxation < 1 or smaller "
            "field steps", hist)
        err.steps_converged = tuple(steps)
        raise err
    return sol, res, it, newton, hist


def _check_loop_inputs(model: str, kappa, tol, relaxation):
    """``(kappa(|M|) or None, tol, relaxation)`` of the field-mechanics loop, checked: the
    continuum model has no microstructural stress; the others need kappa (a number or a
    function of |M| [A/m])."""
    if model == "continuum":
        kappa = None
    elif kappa is None:
        raise InputError(f"model {model!r} needs kappa (the microstructural stress "
                         "coefficient): experiments.tables.affine_kappa(phi, Ms) for 'affine', "
                         "one from relax tables for 'relaxed'")
    elif not callable(kappa):
        k0 = float(kappa)
        kappa = lambda M_abs, k0=k0: np.full(np.shape(M_abs), k0)  # noqa: E731
    tol = check_positive("tol", tol)
    relaxation = float(relaxation)
    if not 0.0 < relaxation <= 1.0:
        raise InputError(f"relaxation must lie in (0, 1], got {relaxation}")
    return kappa, tol, relaxation


def solve_specimen(specimen: Specimen, law, solid: fs.NeoHookeanSolid, B_applied_T, *,
                   model: str = "continuum", kappa=None, tol: float = 1e-4,
                   max_stagger: int = 30, relaxation: float = 1.0,
                   load_steps: int = 2, max_substeps: int = 4,
                   progress=None) -> SpecimenResult:
    """Field steps of a specimen in a uniform applied field along its axis.

    Parameters
    ----------
    specimen : Specimen -- axisymmetric (default) or ``geometry="3d"`` (a cylinder or a box:
        octant meshes, 3D field and mechanics; same loads and observables, the "diameter" of a
        box its width along x)
    law : magnetization law of the composite (``M_A_per_m(H)``, ``dM_dH(H)``; e.g.
        :func:`homogenize.macro.magnetostatics.froehlich_kennelly`)
    solid : NeoHookeanSolid -- the composite's shear and bulk moduli [Pa]
    B_applied_T : increasing applied fields ``mu0 H0`` [T], >= 0
    model : "continuum" | "affine" | "relaxed" (module docstring)
    kappa : callable ``kappa(|M| [A/m]) -> [-]`` (or a number) -- the microstructural stress
        coefficient; required by "affine" (e.g.
        :func:`homogenize.experiments.rve_tables.affine_kappa`) and "relaxed"
    tol : relative change of the change of length between two staggered iterations at which
        a field step is converged [-]
    max_stagger : staggered iterations per step before :class:`ConvergenceError`
    relaxation : the first relaxation factor of the magnetic loads in each field step, (0, 1];
        later ones follow Aitken's rule (Irons & Tuck), clipped to [0.05, 1]
    load_steps : load steps of each mechanics solve (Newton from the undeformed body)
    max_substeps : halvings of a field increment whose staggered iteration or mechanics failed
        (adaptive field sub-steps from the last converged field; the intermediate states are
        starting points, not reported steps) before :class:`ConvergenceError` [-], >= 0
    progress : callable ``progress(i, n, B)`` after each field step, or None

    Returns
    -------
    SpecimenResult (``steps``: one :class:`SpecimenStep` per field; ``solution`` and
    ``field_result``: the last mechanics and field solutions, e.g. for VTU output)

    Raises
    ------
    InputError -- bad input (before any work), or a :class:`TableLaw` whose range the body's
    internal field leaves (never extrapolated); ConvergenceError -- a field step whose
    staggered iteration or Newton failed (``residual_history``: the relative changes or
    residuals; ``steps_converged``: the :class:`SpecimenStep` s before it)
    """
    if not isinstance(specimen, Specimen):
        raise InputError(f"specimen must be a Specimen, got {type(specimen).__name__}")
    if not isinstance(solid, fs.NeoHookeanSolid):
        raise InputError(f"solid must be a NeoHookeanSolid, got {type(solid).__name__}")
    check_choice("model", model, MODELS)
    B = _check_steps(B_applied_T)
    ms.check_law(law)
    kappa, tol, relaxation = _check_loop_inputs(model, kappa, tol, relaxation)
    if isinstance(max_substeps, bool) or not isinstance(max_substeps, (int, np.integer)) \
            or max_substeps < 0:
        raise InputError(f"max_substeps must be an integer >= 0, got {max_substeps!r}")
    body = specimen.mechanics_body()
    is3 = specimen.geometry == "3d"
    field_rtol = _FIELD_RTOL_3D
    if is3:
        g0 = ms.octant_mesh_3d(body.mesh)
        rays = _air_rays(g0, body.mesh)
    else:
        g0 = ms.axisymmetric_mesh(_field_shape(specimen),
                                  ms.MeshOptions(n_boundary=int(specimen.n_boundary)))
    L0 = specimen.length_m

    def solvers(b):
        H0 = b / MU0
        if is3:
            def field_solve(sol):
                return ms.solve_3d(_moved_geometry_3d(g0, sol, rays), law, H0, rtol=field_rtol)

            def mech_solve(loads, sol):
                return _solve_mechanics_3d(body, solid, loads, load_steps, sol)
        else:
            def field_solve(sol):
                return ms.solve_axisymmetric(None, law, H0, geometry=_moved_geometry(g0, sol))

            def mech_solve(loads, sol):
                return fs.solve_axisymmetric(body, solid, loads, load_steps=load_steps)
        return field_solve, mech_solve

    def length_change(sol):
        return fs.length_change_m(sol)[0]

    sol, res, steps = None, None, []
    b_done = 0.0
    for i, b in enumerate(B):
        # adaptive field sub-steps: a field step whose staggered iteration or mechanics fails
        # is cut in half (the body's state at the intermediate field is only the next
        # attempt's starting geometry, not a reported step), at most max_substeps times
        pending, cuts, it, newton, hist = [float(b)], 0, 0, 0, []
        while pending:
            bt = pending[-1]
            field_solve, mech_solve = solvers(bt)
            try:
                sol_t, res_t, it_t, newton_t, hist_t = _staggered_step(
                    body, law, solid, kappa, field_solve, mech_solve, length_change, L0, tol,
                    max_stagger, relaxation, sol, f"B = {bt:g} T", bt == 0.0, steps)
            except ConvergenceError as exc:
                cuts += 1
                if cuts > max_substeps or bt == 0.0:
                    err = ConvergenceError(
                        f"field step B = {b:g} T failed after {cuts - 1} field sub-step "
                        f"cut(s) (max_substeps = {max_substeps}; last converged B = "
                        f"{b_done:g} T, last tried {bt:g} T): {exc}",
                                           getattr(exc, "residual_history", ()))
                    err.steps_converged = tuple(steps)
                    raise err from None
                pending.append(0.5 * (b_done + bt))
                continue
            sol, res, b_done = sol_t, res_t, bt
            it, newton = it + it_t, newton + newton_t
            hist += list(hist_t)
            pending.pop()
        dl_axis, dl_mean = fs.length_change_m(sol)
        dd = fs.diameter_change_m(sol)
        steps.append(SpecimenStep(
            B_applied_T=float(b), M_mean_A_per_m=float(res.M_mean_A_per_m[-1]),
            H_mean_A_per_m=float(res.H_mean_A_per_m[-1]),
            demag_factor=float(res.demag_factor) if b > 0 else float("nan"),
            length_change_axis_m=dl_axis, length_change_mean_m=float(dl_mean),
            strain_axis=dl_axis / L0, strain_end_mean=float(dl_mean) / L0,
            diameter_change_m=dd, lateral_strain=dd / (2.0 * specimen.radius_m),
            mean_strain_zz=float(fs.mean_strain(sol)[2, 2]), stagger_iterations=it,
            newton_iterations=newton, stagger_history=tuple(hist),
            volume_change_m3=volume_change_m3(sol)))
        if progress is not None:
            progress(i + 1, len(B), float(b))
    return SpecimenResult(specimen, model, solid.G_Pa, solid.K_Pa, _law_name(law),
                          tuple(steps), sol, res)


# --------------------------------------------------------------------------------------------
# a specimen in a non-uniform applied field (a permanent magnet), resting on a plate

#: supports of a specimen in a non-uniform field (the body feels a net force): "plate" -- its
#: bottom face on a rigid frictionless plate; "free" -- none, the net force balanced by
#: d'Alembert's uniform body force (the body accelerating quasi-statically; with no net force,
#: the free body of :func:`solve_specimen`)
SUPPORTS = ("plate", "free")


@dataclass(frozen=True)
class SupportedStep(SpecimenStep):
    """A field step of a specimen resting on a plate in a non-uniform field
    (:func:`solve_specimen_in_field`, :func:`solve_specimen_on_magnet`): the observables of
    :class:`SpecimenStep` (``B_applied_T``: ``mu0 H_a,z`` of the applied field at the
    undeformed body's centre; ``diameter_change_m`` at mid-height), and

    gap_m : the magnet gap (its top face to the specimen's bottom face) [m] (NaN: no magnet)
    gradB_applied_T_per_m : ``mu0 dH_a,z/dz`` at the undeformed centre [T/m]
    reaction_N : axial force of the plate on the body [N] (> 0: pushes it up, away from a
        magnet below; the plate's consistent nodal reactions)
    kelvin_force_N : net axial magnetic force [N] from the Kelvin loads on the field mesh
        (:func:`homogenize.macro.magnetostatics.magnetic_loads`)
    maxwell_force_N : the same from the Maxwell stress on a shell in the air between the body
        and the sources (:func:`homogenize.macro.magnetostatics.maxwell_force_N`); NaN when no
        shell fits between them (a magnet closer to the body's centre than ~1.15 times the
        body's largest distance from it)
    """
    gap_m: float = float("nan")
    gradB_applied_T_per_m: float = float("nan")
    reaction_N: float = float("nan")
    kelvin_force_N: float = float("nan")
    maxwell_force_N: float = float("nan")


def _supported_cylinder_body(spec: Specimen, support: str = "plate") -> fs.AxisymmetricBody:
    """The whole meridian section of a cylinder resting with its bottom face on the plate
    ``z = 0`` (it occupies ``0 <= z <= L``), both rims rounded as in
    :meth:`Specimen.mechanics_body`. The plate is frictionless and rigid: ``u_z = 0`` on the
    flat part of the bottom face, ``u_r`` free. It is imposed through the solver's plane of
    symmetry (the boundary ``"mid"`` with ``mid_plane=True``: ``u_z = 0`` there, nothing else;
    a frictionless plate and a symmetry plane impose the same condition). Beware: this body's
    ``volume_m3`` counts a mirror image (twice the body); :func:`fs.mean_strain` divides it
    out, :func:`fs.length_change_m` and :func:`fs.diameter_change_m` assume a mirror image and
    are not used for it. Boundaries: ``"axis"``, ``"mid"`` = ``"end_bottom"`` (the flat part
    of the bottom face), ``"end"`` (the flat part of the top face), ``"side"``,
    ``"surface"`` (all of the body's surface but the axis: the Kelvin traction acts on the
    bottom face too, the plate's reaction adds to it). ``support="free"``: the same mesh
    without the plate (``mid_plane=False``: ``int u_z dV = 0``, a free body)."""
    R, L, n = spec.radius_m, spec.length_m, int(spec.n_mesh)
    c = 0.5 * L
    mesh = fs.cylinder_body(R, L, n, mid_plane=False).mesh
    p = mesh.p.copy()
    rho = float(spec.edge_radius_m)
    if rho > 0.0:
        a, b = p[0] - (R - rho), np.abs(p[1]) - (c - rho)
        sel = (a > 0) & (b > 0)
        an, bn = a[sel] / rho, b[sel] / rho
        sgn = np.sign(p[1, sel])
        p[0, sel] = R - rho + rho * an * np.sqrt(1.0 - 0.5 * bn * bn)
        p[1, sel] = sgn * (c - rho + rho * bn * np.sqrt(1.0 - 0.5 * an * an))
    p[1] += c
    bnd = dict(mesh.boundaries)
    for name, z in (("end", L), ("end_bottom", 0.0)):
        flat = np.all(np.abs(p[1, mesh.facets[:, bnd[name]]] - z) <= 1e-12 * c, axis=0)
        bnd[name] = bnd[name][flat]
    plate = support == "plate"
    if plate:
        bnd["mid"] = bnd["end_bottom"]
    return fs.AxisymmetricBody(MeshTri(p, mesh.t, _boundaries=bnd), "cylinder", R, c, plate)


def _plate_reaction_N(sol) -> float:
    """The plate's axial force on the body [N]: the residual of the mechanics (internal minus
    applied nodal forces) at the converged state, summed over the plate's ``u_z`` dofs."""
    asm_ = fs._axi_assembler(sol.body, sol.solid, sol.loads)
    nu = asm_.nu_dof
    x = np.zeros(asm_.n)
    x[0:nu:2], x[1:nu:2] = sol.u_m
    x[nu:nu + asm_.np_dof] = sol.p_Pa
    r, _ = asm_.residual(x, 1.0, tangent=False)
    return float(r[2 * asm_.ub.get_dofs("mid").all() + 1].sum())


def _face_mean_uz(sol, name) -> float:
    """Area mean of ``u_z`` over the reference facets ``name`` (weight ``r``)."""
    from skfem import ElementTriP2, FacetBasis
    mesh = sol.body.mesh
    fb = FacetBasis(mesh, ElementTriP2(), facets=mesh.boundaries[name], intorder=fs.INTORDER)
    w = np.asarray(fb.dx) * np.asarray(fb.global_coordinates())[0]
    return float(np.sum(np.asarray(fb.interpolate(sol.u_m[1])) * w) / np.sum(w))


def _maxwell_or_nan(res, source_distance_m) -> float:
    """Axial Maxwell force [N] on a shell between the body and the sources (at
    ``source_distance_m`` or farther from the field mesh's centre), NaN if none fits."""
    g = res.geometry
    c = g.center_m.reshape(2, 1)
    pts = g.mesh.p[:, g.mesh.t[:, g.body_elements]].reshape(2, -1)
    rb = float(np.max(np.linalg.norm(pts - c, axis=0)))
    upper = min(float(source_distance_m), g.radius_m)
    if not upper > 1.15 * rb:
        return float("nan")
    return float(ms.maxwell_force_N(res, rb + 0.2 * (upper - rb), rb + 0.8 * (upper - rb))[1])


def solve_specimen_in_field(specimen: Specimen, law, solid: fs.NeoHookeanSolid, H_applied, *,
                            source_distance_m=None, gaps_m=None, support: str = "plate",
                            model: str = "continuum",
                            kappa=None, tol: float = 1e-4, max_stagger: int = 30,
                            relaxation: float = 1.0, load_steps: int = 2,
                            progress=None) -> SpecimenResult:
    """Field steps of a cylinder resting on a rigid, frictionless plate in a non-uniform
    applied field (e.g. of a magnet below the plate).

    Frame: the specimen's axis is z, its bottom face on the plate ``z = 0``, the body in
    ``0 <= z <= L`` (:func:`_supported_cylinder_body`). In a non-uniform field the body feels
    a net force; the plate holds it (``u_z = 0`` on the flat bottom face, ``u_r`` free) and
    its reaction is reported. The loads are those of :func:`solve_specimen` (Kelvin's, as the
    traction ``[(mu0/2)(M.n)^2 + psi] n`` and the stress ``psi I``): ``f = mu0 (M . grad) H =
    grad psi`` holds for ANY curl-free total field ``H = H_a - grad phi`` with ``M`` parallel
    to ``H`` (isotropic law), uniform or not, so they carry over unchanged; their net force
    ``int [(mu0/2)(M.n)^2 + psi] n dA`` is the Kelvin force (tests: against the Maxwell stress
    and the dipole limit). The staggered iteration, models and tolerances are those of
    :func:`solve_specimen`; the field mesh moves with the body including its rigid motion.

    Parameters
    ----------
    specimen : Specimen -- an axisymmetric cylinder (the plate needs a flat face)
    H_applied : sequence of callables -- one per field step, ``H_a(x)`` for ``x`` (2, ...) =
        (r, z) [m] in the frame above, returning ``(H_r, H_z)`` [A/m]; curl- and
        divergence-free in the body, axisymmetric (e.g.
        :func:`homogenize.macro.magnetostatics.applied_field` of a magpylib source)
    source_distance_m : sequence of float, optional -- per step, the distance from the body's
        centre ``(0, L/2)`` to the nearest point of the field's sources [m]: the Maxwell
        force is computed on a shell inside it (None: no Maxwell force)
    gaps_m : sequence of float, optional -- the magnet gap of each step, recorded [m]
    support : "plate" (default) | "free" (:data:`SUPPORTS`; ``reaction_N`` is then the free-body
        constraint's axial force, minus the net magnetic force)

    Returns
    -------
    SpecimenResult with :class:`SupportedStep` s
    """
    if not isinstance(specimen, Specimen):
        raise InputError(f"specimen must be a Specimen, got {type(specimen).__name__}")
    if specimen.geometry != "axisymmetric" or specimen.shape != "cylinder":
        raise InputError("a specimen on a plate in a non-uniform field is an axisymmetric "
                         f"cylinder (a flat face to rest on), got a {specimen.geometry} "
                         f"{specimen.shape}")
    if not isinstance(solid, fs.NeoHookeanSolid):
        raise InputError(f"solid must be a NeoHookeanSolid, got {type(solid).__name__}")
    check_choice("model", model, MODELS)
    check_choice("support", support, SUPPORTS)
    fields = list(H_applied) if not callable(H_applied) else [H_applied]
    if not fields or not all(callable(f) for f in fields):
        raise InputError("H_applied must be a non-empty sequence of callables H_a(x) [A/m]")
    n = len(fields)
    dist = [math.inf] * n if source_distance_m is None else \
        [float(d) for d in np.atleast_1d(source_distance_m)]
    gaps = [float("nan")] * n if gaps_m is None else [float(g) for g in np.atleast_1d(gaps_m)]
    if len(dist) != n or len(gaps) != n:
        raise InputError("source_distance_m and gaps_m need one value per field step")
    ms.check_law(law)
    kappa, tol, relaxation = _check_loop_inputs(model, kappa, tol, relaxation)
    body = _supported_cylinder_body(specimen, support)
    plate = support == "plate"
    L0 = specimen.length_m
    c = 0.5 * L0
    g0 = ms.axisymmetric_mesh(_field_shape(specimen),
                              ms.MeshOptions(n_boundary=int(specimen.n_boundary)),
                              center_z_m=c)
    centre = np.array([[0.0], [c]])
    h_fd = 1e-4 * L0

    def dl_axis(sol):
        u = sol.displacement_m([[0.0, 0.0], [L0, 0.0]])[1]
        return float(u[0] - u[1])

    def mech_solve(loads, sol):
        return fs.solve_axisymmetric(body, solid, loads, load_steps=load_steps)

    sol, res, steps = None, None, []
    for i, Ha in enumerate(fields):
        Hc = np.asarray(Ha(centre), float).reshape(2)
        dHz = float((np.asarray(Ha(centre + [[0.0], [h_fd]]), float).reshape(2)[1]
                     - np.asarray(Ha(centre - [[0.0], [h_fd]]), float).reshape(2)[1])
                    / (2 * h_fd))
        label = (f"gap = {gaps[i]:g} m" if math.isfinite(gaps[i])
                 else f"field step {i + 1} (mu0 H_a,z = {MU0 * Hc[1]:.4g} T at the centre)")

        def field_solve(sol, Ha=Ha):
            return ms.solve_axisymmetric(None, law, H_applied=Ha,
                                         geometry=_moved_geometry(g0, sol, mirror=False))
        sol, res, it, newton, hist = _staggered_step(
            body, law, solid, kappa, field_solve, mech_solve, dl_axis, L0, tol, max_stagger,
            relaxation, sol, label, False, steps)
        dl = dl_axis(sol)
        dl_mean = _face_mean_uz(sol, "end") - _face_mean_uz(sol, "end_bottom")
        dd = float(2.0 * sol.displacement_m([[specimen.radius_m], [c]])[0, 0])
        steps.append(SupportedStep(
            B_applied_T=float(MU0 * Hc[1]), M_mean_A_per_m=float(res.M_mean_A_per_m[-1]),
            H_mean_A_per_m=float(res.H_mean_A_per_m[-1]),
            demag_factor=float(res.demag_factor),
            length_change_axis_m=dl, length_change_mean_m=dl_mean, strain_axis=dl / L0,
            strain_end_mean=dl_mean / L0, diameter_change_m=dd,
            lateral_strain=dd / (2.0 * specimen.radius_m),
            mean_strain_zz=float(fs.mean_strain(sol)[2, 2]), stagger_iterations=it,
            newton_iterations=newton, stagger_history=tuple(hist),
            # the plate's body is solved as a half with a plane of symmetry: no image
            volume_change_m3=(0.5 if plate else 1.0) * volume_change_m3(sol),
            gap_m=gaps[i], gradB_applied_T_per_m=MU0 * dHz,
            reaction_N=_plate_reaction_N(sol) if plate else float(sol.reaction_N),
            kelvin_force_N=float(ms.magnetic_loads(res).total_force_N[1]),
            maxwell_force_N=_maxwell_or_nan(res, dist[i])))
        if progress is not None:
            progress(i + 1, n, gaps[i] if math.isfinite(gaps[i]) else float(MU0 * Hc[1]))
    return SpecimenResult(specimen, model, solid.G_Pa, solid.K_Pa, _law_name(law),
                          tuple(steps), sol, res,
                          setup={"support": support, "frame": (
                              "z along the specimen's axis, its bottom face at z = 0" +
                              (" on the rigid frictionless plate (u_z = 0 there)" if plate
                               else " (free body: int u_z dV = 0)"))})


def check_gaps(gaps_m) -> np.ndarray:
    """Magnet gaps [m]: finite, > 0 (a gap <= 0 puts the magnet into the specimen) and
    strictly decreasing (the magnet approached step by step, as in an experiment)."""
    g = np.atleast_1d(np.asarray(gaps_m, dtype=float))
    if g.ndim != 1 or g.size == 0 or not np.all(np.isfinite(g)):
        raise InputError("the magnet gaps must be a non-empty list of finite values [m]")
    if np.any(g <= 0):
        raise InputError(f"the magnet gaps must be > 0 m (a gap <= 0 puts the magnet into the "
                         f"specimen), got {g.tolist()}")
    if np.any(np.diff(g) >= 0):
        raise InputError(f"the magnet gaps must decrease strictly (the magnet approached step by "
                         f"step), got {g.tolist()}")
    return g


def solve_specimen_on_magnet(specimen: Specimen, law, solid: fs.NeoHookeanSolid,
                             magnet_diameter_m: float, magnet_height_m: float,
                             remanence_T: float, gaps_m, **kwargs) -> SpecimenResult:
    """A cylinder on a plate above a coaxial cylindrical permanent magnet (e.g. NdFeB),
    magnetized along the axis, approached gap by gap.

    The experimenter's sequence: the magnet is brought closer in steps, ``gaps_m`` strictly
    decreasing, > 0 [m] -- the gap between the magnet's top face and the specimen's bottom
    face (the thickness of the non-magnetic plate and spacers between them). Frame of
    :func:`solve_specimen_in_field` (specimen on ``z = 0``); the magnet occupies
    ``-gap - height <= z <= -gap``, its field from magpylib
    (:class:`homogenize.macro.magnets.PermanentMagnet`, remanence ``B_r`` [T]). The magnet is
    rigid (its magnetization is not changed by the specimen: ``mu_r`` ~ 1.05 of NdFeB).
    ``kwargs``: those of :func:`solve_specimen_in_field`.
    """
    from homogenize.macro.magnets import PermanentMagnet, _magpylib_source
    g = check_gaps(gaps_m)
    D = check_positive("magnet_diameter_m", magnet_diameter_m, "m")
    Hm = check_positive("magnet_height_m", magnet_height_m, "m")
    if not isinstance(specimen, Specimen):
        raise InputError(f"specimen must be a Specimen, got {type(specimen).__name__}")
    c = 0.5 * specimen.length_m
    fields, dist = [], []
    for gap in g:
        m = PermanentMagnet("cylinder", (D, Hm), remanence_T, (0.0, 0.0, -gap - 0.5 * Hm))
        fields.append(ms.applied_field(_magpylib_source(m).getH, axisymmetric=True))
        dist.append(c + gap)                   # the centre of the magnet's top face
    res = solve_specimen_in_field(specimen, law, solid, fields, source_distance_m=dist,
                                  gaps_m=g, **kwargs)
    setup = dict(res.setup)
    setup["magnet"] = {"shape": "cylinder", "diameter_m": D, "height_m": Hm,
                       "remanence_T": float(remanence_T), "magnetization": "+z (along the axis)",
                       "position": "coaxial below the plate, top face at z = -gap_m"}
    return SpecimenResult(res.specimen, res.model, res.shear_modulus_Pa, res.bulk_modulus_Pa,
                          res.law, res.steps, res.solution, res.field_result, setup=setup)
