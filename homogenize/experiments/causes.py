"""Causes and their model extensions: the seed model composed with any set of extensions.

A :class:`ModelSpec` is the seed model of one kind plus a set of causes (spec section 4) and,
where a cause has several physical forms, the form used (the magnetization law's shape, the
hyperelastic law). :func:`parameters` lists its fitted parameters; :func:`predict` evaluates it
on an :class:`~homogenize.experiments.io.Experiment`.

How each cause extends the seed model (the physics comes from the project's modules, through
the adapters of ``_physics``):

=============================== =================================================================
cause                           extension (fitted parameters)
=============================== =================================================================
field_dependent_magnetization   particle magnetization ``M_p(H_loc)`` from
                                ``micro.magnetization`` -- linear-capped, Froehlich-Kennelly or
                                Langevin, chosen by cross-validation (``chi0``: initial
                                susceptibility of a particle)
dipolar_interaction             local field of randomly dispersed interacting dipoles,
                                ``H_loc = H_int + c(phi) M``, with c(phi) tabulated from random
                                RVEs solved by ``micro.dipoles`` (0.35-0.40; the Lorentz
                                cavity's 1/3 is its mean-field limit). Magnetostriction: axial
                                strain ``(k_shape(a) - k_rve(phi, m) + kappa_extra) mu0 M^2 / E``
                                with the PREDICTED specimen-shape (Maxwell) stress ``k_shape``
                                of the cylinder and the RVE stress ``k_rve`` of random dipoles
                                (virial table from ``micro.dipoles`` times the share the stiff
                                particles pass on to the matrix, ``homogenize.cell.problem``);
                                ``kappa_extra`` (fitted) is the stress this affine dipole
                                picture does not explain
oxide_shell                     Fe core + Fe3O4 shell per particle (``micro.particles.CoreShell``
                                calibrated to the powder's sigma_s at its nominal radius):
                                smaller particles carry less moment (``shell_m``)
filler_stiffening               effective modulus of iron spheres in the matrix: the voxel-FEM
                                homogenization (``homogenize.cell.problem``) of random RVEs, tabulated
                                against phi (none)
geometric_nonlinearity          elastica instead of Euler-Bernoulli, from
                                ``homogenize.macro.closed_form`` (none)
hyperelasticity                 incompressible neo-Hookean (none), Mooney-Rivlin (``beta``) or
                                Gent (``J_m``) matrix, chosen by cross-validation
gravity                         self-weight ``rho_c g`` of the composite as a body force along
                                (or against) the magnetic one; subtracted again when the
                                deflection is measured from the field-off state (none)
hysteresis                      magnetic kinds: the law lags the field by a coercive field,
                                ``M_up(H) = M(H - H_c)``, ``M_down(H) = M(H + H_c)`` (``H_c``);
                                tensile: unloading stress softened by a factor (``softening``)
demagnetization                 internal field ``H_int = H_a - N M`` with N the magnetometric
                                factor of the cylinder's aspect ratio (none)
microstructure_evolution        magnetostriction, on top of ``dipolar_interaction``: the
                                particles move in the matrix under their forces (two-way
                                coupled RVE, ``homogenize.cell.relax``). Form ``coupled_rve``: the
                                relaxed-minus-affine strain of the coupled RVE, read from a
                                relax table made by ``mapsim batch`` (``evaluator = "relax"``,
                                ``data/relax_*.h5`` with provenance) at the specimen's phi and
                                matrix E (none); form ``fitted``: a stress growing faster than
                                M^2, ``kappa += c_restructure mu0 M^2 / E`` (``c_restructure``,
                                FITTED, reported as such)
=============================== =================================================================
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from micro.materials import PDMS, SEED

from homogenize.experiments import _physics as P
from homogenize.experiments.io import Experiment
from homogenize.experiments.rve_tables import (Unavailable, microstructure_stress_coefficient,
                                           restructuring_table)

__all__ = ["CAUSES", "DESCRIPTIONS", "VARIANTS", "REQUIRES", "ModelSpec", "Param", "parameters",
           "predict", "applicable", "forms", "coupled_rve_available", "restructuring_strain",
           "LORENTZ_FACTOR"]

CAUSES = ("field_dependent_magnetization", "dipolar_interaction", "oxide_shell",
          "filler_stiffening", "geometric_nonlinearity", "hyperelasticity", "gravity",
          "hysteresis", "demagnetization", "microstructure_evolution")

DESCRIPTIONS = {
    "field_dependent_magnetization": "the particles are not saturated: their magnetization "
                                     "follows a law M(H) that levels off",
    "dipolar_interaction": "the particles' own fields matter: interacting dipoles raise the "
                           "local field and stress the matrix",
    "oxide_shell": "an oxide shell: smaller particles carry less moment per volume",
    "filler_stiffening": "the particles stiffen the matrix",
    "geometric_nonlinearity": "large deflection: the beam is stiffer than linear theory",
    "hyperelasticity": "the matrix is hyperelastic: stress is not proportional to strain",
    "gravity": "self-weight adds a load",
    "hysteresis": "rising and falling branches differ",
    "demagnetization": "the specimen's shape reduces the internal field (demagnetizing factor)",
    "microstructure_evolution": "the particles move in the soft matrix under their forces: "
                                "the strain grows faster than M^2, beyond the affine picture",
}

#: Physical forms among which cross-validation chooses (None: a single form).
VARIANTS = {"field_dependent_magnetization": P.LAWS, "hyperelasticity": P.HYPERELASTIC_FORMS,
            "microstructure_evolution": ("coupled_rve", "fitted")}

#: causes that only extend a model which already has another (tried once it is accepted)
REQUIRES = {"microstructure_evolution": "dipolar_interaction"}

#: Mean-field (Lorentz cavity) local-field factor, the reference the RVE table is checked against.
LORENTZ_FACTOR = 1.0 / 3.0

_KINDS_OF = {
    "field_dependent_magnetization": ("deflection", "magnetization", "magnetostriction"),
    "dipolar_interaction": ("deflection", "magnetization", "magnetostriction"),
    "oxide_shell": ("deflection", "magnetization", "magnetostriction"),
    "filler_stiffening": ("deflection", "magnetostriction", "tensile"),
    "geometric_nonlinearity": ("deflection",),
    "hyperelasticity": ("tensile",),
    "gravity": ("deflection",),
    "hysteresis": ("deflection", "magnetization", "magnetostriction", "tensile"),
    "demagnetization": ("magnetization", "magnetostriction"),
    "microstructure_evolution": ("magnetostriction",),
}


@dataclass(frozen=True)
class ModelSpec:
    """Seed model of ``kind`` plus ``causes`` (ordered as accepted) and chosen forms."""
    kind: str
    causes: tuple = ()
    law: str | None = None           # with field_dependent_magnetization
    hyper: str | None = None         # with hyperelasticity
    restructure: str | None = None   # with microstructure_evolution: coupled_rve | fitted

    def plus(self, cause: str, variant: str | None = None) -> "ModelSpec":
        law, hyper, rs = self.law, self.hyper, self.restructure
        if cause == "field_dependent_magnetization":
            law = variant
        if cause == "hyperelasticity":
            hyper = variant
        if cause == "microstructure_evolution":
            rs = variant
        return ModelSpec(self.kind, self.causes + (cause,), law, hyper, rs)

    def has(self, cause: str) -> bool:
        return cause in self.causes

    def label(self) -> str:
        parts = []
        for c in self.causes:
            if c == "field_dependent_magnetization":
                parts.append(f"{c}[{self.law}]")
            elif c == "hyperelasticity":
                parts.append(f"{c}[{self.hyper}]")
            elif c == "microstructure_evolution":
                parts.append(f"{c}[{self.restructure}]")
            else:
                parts.append(c)
        return "seed" + "".join(" + " + p for p in parts)


@dataclass(frozen=True)
class Param:
    """A fitted parameter: fitted as log(value) when ``log``; ``starts`` are trial values."""
    name: str
    log: bool
    lo: float
    hi: float
    starts: tuple
    amplitude: bool = False          # prediction ~ proportional to it (closed-form start)


def applicable(cause: str, exp: Experiment) -> tuple[bool, str]:
    """Whether ``cause`` can be tested on ``exp`` and, if not, why (the design cannot show it)."""
    if exp.kind not in _KINDS_OF[cause]:
        return False, f"not a cause for kind '{exp.kind}'"
    c = exp.columns
    if cause == "hysteresis" and not (exp.down.any() and (~exp.down).any()):
        return False, "needs rows on both the rising ('up') and the falling ('down') branch"
    if cause == "oxide_shell" and ("radius_mean_m" not in c or np.unique(c["radius_mean_m"]).size < 2):
        return False, "needs specimens of at least two mean particle radii (radius_mean_m)"
    if cause == "filler_stiffening" and np.unique(c["phi"]).size < 2:
        return False, "needs at least two volume fractions (phi): one phi only rescales E"
    if cause == "demagnetization" and "aspect_ratio" not in c:
        return False, "needs the specimen's aspect_ratio"
    try:
        _probe(cause, exp)
    except P.Unavailable as exc:
        return False, f"unavailable: {exc}"
    return True, ""


def forms(cause: str, exp: Experiment, spec: ModelSpec | None = None) -> tuple:
    """The physical forms of ``cause`` that can run on ``exp`` on top of ``spec``.

    ``microstructure_evolution``: ``coupled_rve`` needs a relax table at the specimen's phi and
    matrix E; ``fitted`` (a stress growing as M^4 instead of M^2) needs a magnetization that
    varies within a specimen, i.e. ``field_dependent_magnetization`` in the model: with
    saturated particles M is constant per specimen and the term would only re-weight the
    specimens by phi^2, which a restructuring cannot be told from a phi-dependent stress by.
    """
    fs = VARIANTS.get(cause) or ()
    if cause == "microstructure_evolution":
        out = []
        for f in fs:
            if f == "coupled_rve" and not coupled_rve_available(exp)[0]:
                continue
            if f == "fitted" and not (spec is not None
                                      and spec.has("field_dependent_magnetization")):
                continue
            out.append(f)
        return tuple(out)
    return fs


def coupled_rve_available(exp: Experiment) -> tuple[bool, str]:
    """Whether a relax table holds the coupled RVE at every specimen's phi and the matrix E."""
    try:
        for phi in np.unique(exp.columns["phi"]):
            restructuring_table(float(phi), float(exp.matrix.E_Pa))
    except Unavailable as exc:
        return False, str(exc)
    return True, ""


def restructuring_strain(exp: Experiment) -> np.ndarray:
    """Per row, the coupled RVE's restructuring strain (relaxed minus affine, with the
    specimen's shape stress on the change of mu0 M^2 / E) from the relax table [-]."""
    c = exp.columns
    k_shape = np.asarray(P.shape_stress_coefficient(c["aspect_ratio"]), dtype=float)
    out = np.empty(exp.n_rows)
    for phi in np.unique(c["phi"]):
        sel = c["phi"] == phi
        tab = restructuring_table(float(phi), float(exp.matrix.E_Pa))
        out[sel] = tab.delta_strain(c["B_T"][sel], k_shape[sel] if k_shape.ndim else k_shape)
    return out


def _probe(cause, exp):
    """Raise Unavailable if the project module behind ``cause`` has not landed."""
    if cause in ("field_dependent_magnetization", "hysteresis", "dipolar_interaction",
                 "demagnetization") and exp.kind != "tensile":
        P.particle_magnetization_A_per_m("frohlich-kennelly", np.array([1.0]), 1.0, 1.0)
    if cause == "dipolar_interaction":
        P.local_field_factor(0.1)
        if exp.kind == "magnetostriction":
            microstructure_stress_coefficient(0.1, 1.0)
    if cause == "oxide_shell":
        P.core_shell_moment_ratio(np.array([20e-9]), 1e-9, 25e-9, SEED.particle_density_kg_m3,
                                  SEED.sigma_s_Am2_kg)
    if cause == "filler_stiffening":
        P.stiffening_ratio(np.array([0.1]), PDMS.nu)
    if cause == "microstructure_evolution":
        microstructure_stress_coefficient(0.1, 1.0)
    if cause in ("geometric_nonlinearity",):
        P.elastica_ratio(np.array([1.0]))
    if cause == "gravity" or exp.kind == "deflection":
        P.eb_compliance_m4_N(np.array([1.0]), np.array([1.0]), np.array([1.0]), 1.0)


def parameters(spec: ModelSpec, exp: Experiment) -> list[Param]:
    """The fitted parameters of ``spec`` on ``exp`` (the first is the seed's own)."""
    ps = []
    kind = spec.kind
    if kind == "tensile":
        ps.append(Param("E_Pa", True, 1e2, 1e12, (exp.matrix.E_Pa,), amplitude=True))
    elif kind == "magnetostriction":
        if spec.has("dipolar_interaction"):
            # stress beyond the predicted one, in units of mu0 M^2 (0: fully predicted)
            ps.append(Param("kappa_extra", False, -1e3, 1e3, (0.0,)))
    else:
        ps.append(Param("scale", True, 1e-6, 1e3, (1.0,), amplitude=True))
    if spec.has("field_dependent_magnetization"):
        hi = 3.0 if spec.law == "linear" else 1e6
        starts = (0.3, 2.0) if spec.law == "linear" else (0.3, 3.0, 30.0, 300.0)
        ps.append(Param("chi0", True, 1e-4, hi, starts))
    if spec.has("oxide_shell"):
        rmin = float(np.min(exp.columns["radius_mean_m"]))
        ps.append(Param("shell_m", True, 1e-3 * rmin, 0.95 * min(rmin, exp.particles.radius_mean_m),
                        (0.05 * rmin, 0.2 * rmin, 0.5 * rmin)))
    if spec.has("hysteresis"):
        if kind == "tensile":
            ps.append(Param("softening", False, 0.0, 0.95, (0.05, 0.2, 0.5)))
        else:
            Hs = np.abs(_applied_field(exp))
            Hmax = float(Hs.max()) if Hs.size and Hs.max() > 0 else 1e5
            ps.append(Param("H_c_A_per_m", True, 1e-4 * Hmax, 2.0 * Hmax,
                            (0.01 * Hmax, 0.05 * Hmax, 0.2 * Hmax)))
    if spec.has("hyperelasticity") and spec.hyper == "mooney-rivlin":
        # beta = C2 / (C1 + C2); beta < 0 (C2 < 0) stiffens in tension, as fits often need
        ps.append(Param("beta", False, -2.0, 1.0, (0.0, 0.5, -0.5)))
    if spec.has("hyperelasticity") and spec.hyper == "gent":
        ps.append(Param("J_m", True, 0.3, 1e4, (3.0, 30.0, 300.0)))
    if spec.has("microstructure_evolution") and spec.restructure == "fitted":
        # FITTED restructuring stress: kappa grows by c mu0 M^2 / E (faster than M^2)
        ps.append(Param("c_restructure", False, -1e4, 1e4, (0.0, 1.0, 10.0, 100.0)))
    return ps


def _applied_field(exp: Experiment) -> np.ndarray:
    c = exp.columns
    if exp.kind == "magnetization":
        return c["H_A_per_m"]
    return c["B_T"] / P.mu_0


def _stiffening(spec, exp):
    if spec.has("filler_stiffening"):
        return P.stiffening_ratio(exp.columns["phi"], exp.matrix.nu, exp.matrix.E_Pa)
    return 1.0


def composite_magnetization_A_per_m(spec: ModelSpec, exp: Experiment, p: dict) -> np.ndarray:
    """Composite magnetization along the applied field [A/m] of every row."""
    c = exp.columns
    H_a = _applied_field(exp)
    scale = p.get("scale", 1.0)
    Ms = np.full(exp.n_rows, exp.particles.Ms_A_per_m)
    if spec.has("oxide_shell"):
        Ms = Ms * P.core_shell_moment_ratio(c["radius_mean_m"], p["shell_m"],
                                            exp.particles.radius_mean_m,
                                            exp.particles.density_kg_m3,
                                            exp.particles.sigma_s_Am2_kg)
    Mmax = scale * c["phi"] * Ms
    if not spec.has("field_dependent_magnetization"):
        # saturated particles: neither the local nor the internal field changes |M|
        return Mmax * np.sign(H_a)
    N = P.cylinder_demag_factor(c["aspect_ratio"]) if spec.has("demagnetization") else 0.0
    cL = P.local_field_factor(c["phi"]) if spec.has("dipolar_interaction") else 0.0
    shift = 0.0
    if spec.has("hysteresis"):
        shift = np.where(exp.down, 1.0, -1.0) * p["H_c_A_per_m"]
    feedback = cL - N
    chi0 = p["chi0"]

    def g(M):
        return scale * c["phi"] * P.particle_magnetization_A_per_m(
            spec.law, H_a + feedback * M + shift, Ms, chi0)

    if np.all(feedback == 0.0):
        return g(0.0)
    # F(M) = M - g(H_a + feedback M) is increasing where the mean field is stable and changes
    # sign on [-Mmax, Mmax] (|g| <= Mmax): vectorised Illinois (regula falsi) iteration on that
    # bracket, to |F| <= 1e-13 Mmax (far below the 1e-8 steps of the fit's finite differences).
    def F(M):
        return M - g(M)

    a, b = -Mmax.copy(), Mmax.copy()
    Fa, Fb = F(a), F(b)
    tol = 1e-13 * np.maximum(Mmax, 1e-300)
    x = np.where(np.abs(Fa) < np.abs(Fb), a, b)
    for _ in range(200):
        den = Fb - Fa
        x = np.where(den != 0, (a * Fb - b * Fa) / np.where(den != 0, den, 1.0), 0.5 * (a + b))
        Fx = F(x)
        if np.all(np.abs(Fx) <= tol):
            break
        same = np.sign(Fx) == np.sign(Fb)
        # Illinois: when the new point replaces the same end again, halve the other end's F
        a, Fa = np.where(same, a, b), np.where(same, 0.5 * Fa, Fb)
        b, Fb = x, Fx
    return x


def predicted_stress_coefficients(exp: Experiment, M) -> tuple[np.ndarray, np.ndarray]:
    """(k_shape, k_rve) per row: the specimen's Maxwell (shape) stress and the particles'
    interaction (RVE virial) stress, both over ``mu0 M^2`` [-] (module doc)."""
    c = exp.columns
    m = np.clip(np.abs(M) / (c["phi"] * exp.particles.Ms_A_per_m), 0.0, 1.0)
    return (np.asarray(P.shape_stress_coefficient(c["aspect_ratio"]), dtype=float),
            np.asarray(microstructure_stress_coefficient(c["phi"], m), dtype=float))


def magnetostriction_coefficient(spec: ModelSpec, exp: Experiment, M, p: dict) -> np.ndarray:
    """kappa = k_shape - k_rve + kappa_extra per row: axial strain = kappa mu0 M^2 / E."""
    k_shape, k_rve = predicted_stress_coefficients(exp, M)
    kappa = k_shape - k_rve + p.get("kappa_extra", 0.0)
    if "c_restructure" in p:
        kappa = kappa + p["c_restructure"] * P.mu_0 * M ** 2 / _matrix_E(spec, exp)
    return kappa


def _matrix_E(spec, exp):
    return exp.matrix.E_Pa * _stiffening(spec, exp)


def predict(spec: ModelSpec, exp: Experiment, p: dict) -> np.ndarray:
    """Prediction of the measured column of ``exp`` [its SI unit] with parameters ``p``."""
    c = exp.columns
    if spec.kind == "tensile":
        E = p["E_Pa"] * _stiffening(spec, exp)
        if spec.has("hyperelasticity"):
            extra = p.get("beta") if spec.hyper == "mooney-rivlin" else p.get("J_m")
            s = P.uniaxial_stress_Pa(spec.hyper, c["strain"], E, extra)
        else:
            s = E * c["strain"]
        if spec.has("hysteresis"):
            s = np.where(exp.down, (1.0 - p["softening"]) * s, s)
        return s
    M = composite_magnetization_A_per_m(spec, exp, p)
    if spec.kind == "magnetization":
        return M
    E = exp.matrix.E_Pa * _stiffening(spec, exp)
    if spec.kind == "magnetostriction":
        if not (spec.has("dipolar_interaction") or spec.has("microstructure_evolution")):
            return np.zeros(exp.n_rows)
        # axial magnetic stress kappa mu0 M^2 on an incompressible linear matrix (small strain)
        strain = magnetostriction_coefficient(spec, exp, M, p) * P.mu_0 * M ** 2 / E
        if spec.has("microstructure_evolution") and spec.restructure == "coupled_rve":
            strain = strain + restructuring_strain(exp)
        return strain
    # deflection
    f = M * c["gradB_T_per_m"]
    comp = P.eb_compliance_m4_N(c["length_m"], c["width_m"], c["thickness_m"], 1.0) / E

    def beam(force):
        d = comp * force
        if spec.has("geometric_nonlinearity"):
            alpha = 8.0 * d / c["length_m"]          # Euler-Bernoulli: delta / L = alpha / 8
            d = d * P.elastica_ratio(alpha)
        return d

    if not spec.has("gravity"):
        return beam(f)
    rho = P.composite_density_kg_m3(c["phi"], exp.matrix.density_kg_m3,
                                    exp.particles.density_kg_m3)
    fg = rho * exp.setup.gravity_m_s2 * (1.0 if exp.setup.gravity_along_force else -1.0)
    d = beam(f + fg)
    if exp.setup.deflection_reference == "field_off":
        d = d - beam(fg)
    return d


def default_params(spec: ModelSpec, exp: Experiment) -> dict:
    """A priori parameter values: the seed's scale 1 / the matrix E; first start otherwise."""
    return {q.name: q.starts[0] for q in parameters(spec, exp)}

