"""Cantilever strip under a body force: closed forms, 3D FEM, large deformation.

Geometry: the strip occupies ``[0, L] x [0, w] x [0, t]``, is clamped (all displacement
components zero) on the face ``x = 0`` and carries a body force of magnitude ``f`` along ``-z``
(the thickness direction). The force is uniform (a number) or varies along the strip, ``f(x)``
(a callable of ``x`` [m] or a :class:`~homogenize.macro.closed_form.BodyForceProfile`, e.g. the
force of a real magnet from :mod:`homogenize.macro.magnets`). The tip deflection is the
displacement along the force of the centre of the free end, ``(L, w/2, t/2)``.

:func:`tip_deflection_m` is the one-call entry point used by ``mapsim beam`` and by other layers;
:func:`solve_cantilever` returns the full :class:`CantileverResult`.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from homogenize.macro import closed_form as cf
from homogenize.macro.fem import Material, box_mesh, linear_solve, neo_hookean_solve, \
    probe_displacement
from micro.common.validate import InputError, check_choice, check_positive, check_slender
from micro.materials import PDMS

__all__ = ["Strip", "CantileverResult", "MODELS", "beam_divisions", "solve_cantilever",
           "tip_deflection_m"]

#: models understood by :func:`solve_cantilever`
MODELS = ("eb", "eb-plate", "timoshenko", "elastica", "fem", "neo-hookean")


#: smallest length / thickness of a strip: every model here (Euler-Bernoulli, Timoshenko,
#: elastica, the 3D FEM meshed as a beam) takes the strip as slender; the shortest strip of the
#: tests and studies has 6, a strip thicker than a quarter of its length is a block (or a
#: thickness given in the wrong unit)
MIN_SLENDERNESS = 4.0


@dataclass(frozen=True)
class Strip:
    """A rectangular strip: length, width and thickness [m] (the load acts along thickness)."""
    length_m: float
    width_m: float
    thickness_m: float

    def __post_init__(self):
        check_positive("length_m", self.length_m, "m")
        check_positive("width_m", self.width_m, "m")
        check_positive("thickness_m", self.thickness_m, "m")
        check_slender("strip", "length_m", self.length_m, "thickness_m", self.thickness_m,
                      MIN_SLENDERNESS, assumption="a beam: slender along its length")


@dataclass(frozen=True)
class CantileverResult:
    """Tip displacement of a cantilever.

    tip_m : deflection of the tip centre along the force [m];
    tip_horizontal_m : shortening of the tip along the beam axis [m] (0 for linear models);
    f_N_m3 : total transverse body force applied [N/m^3] (its mean over the length for a force
    that varies along the strip);
    divisions : (nx, ny, nz) hexahedra along length, width, thickness (6 tets each), FEM only;
    order : polynomial degree of the tetrahedra; n_dof : displacement dofs;
    solver : "closed-form" | "bvp" | "direct" | "amg-pcg" | "newton"; iterations : Krylov or
    Newton iterations.
    """
    model: str
    tip_m: float
    tip_horizontal_m: float
    f_N_m3: float
    divisions: tuple | None = None
    order: int | None = None
    n_dof: int = 0
    n_elements: int = 0
    solver: str = "closed-form"
    iterations: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def beam_divisions(strip: Strip, nz: int = 2, aspect: float = 3.0) -> tuple[int, int, int]:
    """Mesh divisions with ``nz`` layers through the thickness and element aspect <= ``aspect``.

    The element edge along length and width is at most ``aspect`` times the layer height.
    """
    nz = int(check_positive("nz", nz, ""))
    aspect = check_positive("aspect", aspect, "")
    h = strip.thickness_m / nz
    nx = max(2, math.ceil(strip.length_m / (aspect * h) - 1e-9))
    ny = max(1, math.ceil(strip.width_m / (aspect * h) - 1e-9))
    return nx, ny, nz


def _mesh(strip: Strip, divisions, half=False):
    nx, ny, nz = (int(d) for d in divisions)
    return box_mesh(np.linspace(0.0, strip.length_m, nx + 1),
                    np.linspace(0.0, strip.width_m / (2 if half else 1), ny + 1),
                    np.linspace(0.0, strip.thickness_m, nz + 1))


def _clamp(strip: Strip, lateral: str, half=False, clamp="full"):
    tol = 1e-9 * strip.length_m

    def fixed(basis):
        if clamp == "full":
            dofs = [basis.get_dofs(lambda x: x[0] < tol).all()]
        else:
            # beam-theory clamp: the root section stays plane (u_x = 0) and its neutral line is
            # held (u_z = 0 at z = t/2); lateral contraction of the root is free
            x = basis.doflocs
            comp = np.arange(x.shape[1]) % 3
            root = x[0] < tol
            line = root & (np.abs(x[2] - strip.thickness_m / 2) < tol) & (comp == 2)
            if not line.any():
                raise InputError("clamp='beam' needs nodes on the line z = t/2 at the root: use "
                                 "an even number of layers nz or quadratic elements")
            dofs = [np.nonzero(root & (comp == 0))[0], np.nonzero(line)[0]]
        if half:
            # mirror plane y = w/2 of the symmetric load case: u_y = 0 (dof 3 g + 1)
            mid = basis.get_dofs(lambda x: x[1] > strip.width_m / 2 - tol).all()
            dofs.append(mid[mid % 3 == 1])
        if lateral == "plane-strain":
            # u_y = 0 on both side faces: the strip behaves as a slice of an infinitely wide plate
            side = basis.get_dofs(lambda x: (x[1] < tol) | (x[1] > strip.width_m - tol)).all()
            dofs.append(side[side % 3 == 1])  # interleaved dofs: component y is 3 g + 1
        return np.unique(np.concatenate(dofs))
    return fixed


def solve_cantilever(strip: Strip, material: Material, f_N_m3: float, *, model: str = "fem",
                     order: int = 2, divisions=None, nz: int = 2, aspect: float = 3.0,
                     gravity_m_s2: float = 0.0, lateral: str = "free", solver: str = "auto",
                     n_steps: int = 4, half: bool = True, clamp: str = "full"
                     ) -> CantileverResult:
    """Tip deflection of the clamped strip under the body force ``f_N_m3`` (+ self-weight).

    Parameters
    ----------
    strip : Strip -- geometry [m]
    material : Material -- E [Pa], nu, density [kg/m^3]
    f_N_m3 : float, callable or BodyForceProfile -- magnetic body force along -z [N/m^3]:
        uniform (>= 0), or varying along the strip, ``f(x_m)`` vectorised over an array of ``x``
        in ``[0, L]`` (any sign), or sampled (:class:`closed_form.BodyForceProfile`); the FEM
        integrates it at its quadrature points, the 1D models as in :mod:`.closed_form`
    model : one of :data:`MODELS` -- "eb" Euler-Bernoulli, "eb-plate" with E/(1-nu^2),
        "timoshenko", "elastica" (large deflection, 1D), "fem" (3D linear), "neo-hookean"
        (3D large deformation, total Lagrangian)
    order : 1 or 2 -- tetrahedron degree (FEM models)
    divisions : (nx, ny, nz) or None -- hexahedra per direction (``ny`` across the modelled
        width: half of it with ``half``); None: :func:`beam_divisions`
    nz, aspect : used when ``divisions`` is None
    gravity_m_s2 : float -- self-weight ``density * g`` added along the force [m/s^2]
    lateral : "free" (traction-free sides) or "plane-strain" (u_y = 0 on the sides, FEM only)
    solver : "auto" | "direct" | "amg-pcg" (linear FEM)
    n_steps : load increments of the neo-Hookean solver
    half : bool -- model half the width with the mirror condition u_y = 0 at y = w/2 (exact for
        this symmetric load; halves the cost)
    clamp : "full" (all displacements zero on the root face, a glued or gripped strip) or
        "beam" (root plane, neutral line fixed, lateral contraction free: the boundary condition
        of beam theory; needs ``half``)
    """
    check_choice("model", model, MODELS)
    check_choice("lateral", lateral, ("free", "plane-strain"))
    check_choice("clamp", clamp, ("full", "beam"))
    if clamp == "beam" and not half:
        raise InputError("clamp='beam' uses the mirror plane y = w/2: set half=True")
    g = check_positive("gravity_m_s2", gravity_m_s2, "m/s^2", allow_zero=True)
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    E, nu = material.E_Pa, material.nu
    weight = material.density_kg_m3 * g
    if callable(f_N_m3):
        return _solve_varying(strip, material, f_N_m3, weight, model, order, divisions, nz,
                              aspect, lateral, solver, n_steps, half, clamp)
    f = check_positive("f_N_m3", f_N_m3, "N/m^3", allow_zero=True)
    total = f + weight
    if model in ("eb", "eb-plate"):
        d = cf.eb_tip_deflection_m(total, L, w, t, E, nu, plate=model == "eb-plate")
        return CantileverResult(model, d, 0.0, total)
    if model == "timoshenko":
        return CantileverResult(model, cf.timoshenko_tip_deflection_m(total, L, w, t, E, nu),
                                0.0, total)
    if model == "elastica":
        v, h = cf.elastica_tip_deflection(total, L, w, t, E)
        return CantileverResult(model, v, h, total, solver="bvp")
    load = np.array([0.0, 0.0, -total])
    return _solve_fem(strip, material, load, total, model, order, divisions, nz, aspect,
                      lateral, solver, n_steps, half, clamp)


def _solve_varying(strip, material, f, weight, model, order, divisions, nz, aspect, lateral,
                   solver, n_steps, half, clamp):
    """:func:`solve_cantilever` for a body force ``f(x)`` varying along the strip."""
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    E, nu = material.E_Pa, material.nu

    if isinstance(f, cf.BodyForceProfile):
        # stays a profile, so that the 1D quadratures see its nodes (kinks)
        along = cf.BodyForceProfile(f.x_m, f.f_N_m3 + weight)
    else:
        def along(x):
            return np.asarray(f(x), dtype=float) + weight

    mean = cf._VaryingLoad(along, L).mean_N_m3   # also checks that f covers [0, L]
    if model in ("eb", "eb-plate"):
        d = cf.eb_tip_deflection_m(along, L, w, t, E, nu, plate=model == "eb-plate")
        return CantileverResult(model, d, 0.0, mean)
    if model == "timoshenko":
        return CantileverResult(model, cf.timoshenko_tip_deflection_m(along, L, w, t, E, nu),
                                0.0, mean)
    if model == "elastica":
        v, h = cf.elastica_tip_deflection(along, L, w, t, E)
        return CantileverResult(model, v, h, mean, solver="bvp")

    def load(x):
        # x: reference coordinates, shape (3, ...); the force acts along -z
        fz = -along(x[0])
        return np.stack([np.zeros_like(fz), np.zeros_like(fz), fz])

    return _solve_fem(strip, material, load, mean, model, order, divisions, nz, aspect,
                      lateral, solver, n_steps, half, clamp)


def _solve_fem(strip, material, load, total, model, order, divisions, nz, aspect, lateral,
               solver, n_steps, half, clamp):
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    if divisions is None:
        modelled = Strip(L, w / 2, t) if half else strip
        divisions = beam_divisions(modelled, nz, aspect)
    divisions = tuple(int(d) for d in divisions)
    if len(divisions) != 3 or min(divisions) < 1:
        raise ValueError(f"divisions must be three positive integers, got {divisions}")
    mesh = _mesh(strip, divisions, half)
    fixed = _clamp(strip, lateral, half, clamp)
    if model == "fem":
        sol = linear_solve(mesh, material, load, fixed, order=order, solver=solver)
    else:
        sol = neo_hookean_solve(mesh, material, load, fixed, order=order, n_steps=n_steps)
    # tip centre, probed just inside the mesh (it lies on the mirror plane with ``half``)
    u = probe_displacement(sol, np.array([[L * (1 - 1e-9)], [w / 2.0 * (1 - 1e-9)], [t / 2.0]]))[:, 0]
    return CantileverResult(model, float(-u[2]), float(-u[0]), total, divisions, order,
                            sol.n_dof, sol.n_elements, sol.solver, sol.iterations)


def tip_deflection_m(f_N_m3, length_m, width_m, thickness_m, E_Pa=PDMS.E_Pa, nu=PDMS.nu, *,
                     model="fem", density_kg_m3=PDMS.density_kg_m3, gravity_m_s2=0.0,
                     **fem_options):
    """Tip deflection [m] of a clamped strip under the body force ``f_N_m3`` [N/m^3].

    Vectorised over ``f_N_m3``. Linear models scale one solution; the others are solved per
    force. ``fem_options`` go to :func:`solve_cantilever` (order, divisions, nz, aspect, ...).
    """
    strip = Strip(length_m, width_m, thickness_m)
    mat = Material(E_Pa, nu, density_kg_m3)
    f = np.atleast_1d(np.asarray(f_N_m3, float))
    for v in f:
        check_positive("f_N_m3", v, "N/m^3", allow_zero=True)
    if model in ("eb", "eb-plate", "timoshenko", "fem"):
        # linear: one solve under a unit load, scaled by the total load
        unit = solve_cantilever(strip, mat, 1.0, model=model, **fem_options).tip_m
        out = unit * (f + mat.density_kg_m3 * gravity_m_s2)
    else:
        out = np.array([solve_cantilever(strip, mat, v, model=model, gravity_m_s2=gravity_m_s2,
                                         **fem_options).tip_m for v in f])
    return float(out[0]) if np.ndim(f_N_m3) == 0 else out
