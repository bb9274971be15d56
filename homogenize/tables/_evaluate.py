"""Evaluators: what one realization of a study computes.

An evaluator is a picklable callable ``evaluator(task) -> dict[str, ndarray]`` with an ``id``
(name and version: it names the stored results, so results of an older evaluator are never
mixed with newer ones), ``check(study)`` (raises :class:`InputError` for a study it cannot run)
and the quantities it returns, all listed in :data:`QUANTITIES` with their unit and shape.

* :class:`RVEEvaluator` (``evaluator = "rve"``): generate a random RVE
  (:func:`micro.particles.generate_rve`), solve the self-consistent dipoles
  (:func:`micro.dipoles.solve`) and optionally the FEM cell problem
  (:func:`homogenize.cell.problem.homogenize_rve`).
* :class:`RelaxEvaluator` (``evaluator = "relax"``): the coupled RVE whose particles move
  (:func:`homogenize.cell.relax.relax`): for each realization one random RVE relaxed through the
  study's B_T values as field steps (continuation); each grid point stores its step
  (magnetostriction, M_eff, stiffness along and across the field, gaps, displacements).
* :class:`SyntheticEvaluator` (``evaluator = "synthetic"``): normal outputs with a known mean
  and standard deviation (:func:`synthetic_truth`), for testing the batch machinery and the
  statistics against exact answers.
"""
from __future__ import annotations

import hashlib
import inspect
import json
import math
import os
import time
import uuid
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

import micro
from micro import magnetization
from micro.common.validate import InputError
from micro.materials import PDMS, SEED, radius_bounds_m
from micro.particles import CoreShell, LogNormal, Monodisperse
import itertools
from micro.dipoles import solve
from micro.magnetization import get_law
from micro.particles import generate_rve
from homogenize.cell.problem import homogenize_rve
from homogenize.tables.resolution import resolution_warning

__all__ = ["QUANTITIES", "get_evaluator", "RVEEvaluator", "RelaxEvaluator", "SyntheticEvaluator",
           "synthetic_truth"]

# name -> (unit, per-realization shape, description)
QUANTITIES = {
    "f_eff_N_m3": ("N/m^3", (3,), "effective magnetic body force density <sum F_i> / V"),
    "phi_eff": ("1", (), "effective magnetic volume fraction (magnetics solver)"),
    "d_eff": ("1", (), "effective packing factor: body force relative to the seed's N F_g / V "
                       "with d = 1 (magnetics solver)"),
    "M_eff_A_per_m": ("A/m", (3,), "effective magnetization <sum m_i> / V"),
    "virial_stress_Pa": ("Pa", (3, 3), "magnetic stress: virial of the particle forces"),
    "E_eff_Pa": ("Pa", (), "effective Young's modulus (FEM, isotropic projection)"),
    "nu_eff": ("1", (), "effective Poisson's ratio (FEM, isotropic projection)"),
    "stress_mag_Pa": ("Pa", (3, 3), "magnetic stress from the FEM cell problem"),
    "strain_mag": ("1", (3, 3), "strain of a stress-free sample, -C_eff^-1 stress_mag (FEM)"),
    "volume_m3": ("m^3", (), "RVE box volume"),
    "phi_rve": ("1", (), "particle volume fraction of the generated RVE"),
    # relax evaluator (particles that move; field along z)
    "strain_parallel": ("1", (), "free magnetostriction strain along the field, relaxed RVE "
                                 "(cell FEM)"),
    "strain_perpendicular": ("1", (), "free magnetostriction strain across the field (mean of "
                                      "the two transverse axes), relaxed RVE (cell FEM)"),
    "strain_affine_parallel": ("1", (), "free magnetostriction strain along the field of the "
                                        "RVE as placed (particles fixed, cell FEM)"),
    "M_eff_affine_A_per_m": ("A/m", (), "magnetization along the field of the RVE as placed"),
    "E_eff_parallel_Pa": ("Pa", (), "Young's modulus along the field after restructuring "
                                    "(cell FEM)"),
    "E_eff_perpendicular_Pa": ("Pa", (), "Young's modulus across the field after "
                                         "restructuring (cell FEM)"),
    "min_gap_m": ("m", (), "smallest surface gap between particles after relaxation"),
    "displacement_rms_m": ("m", (), "rms particle displacement from the as-placed positions"),
    "n_contacts": ("1", (), "particle pairs in contact (inside the contact layer)"),
    "chain_fraction": ("1", (), "fraction of particles in aligned contact chains of >= 3"),
}

#: quantities of the rve evaluator's cell FEM -> the [cell] key of their value without filler
#: (None: zero), for the discretization error (:mod:`homogenize.tables.resolution`)
FEM_QUANTITIES = {"E_eff_Pa": "matrix_E_Pa", "nu_eff": "matrix_nu", "stress_mag_Pa": None,
                  "strain_mag": None}
#: the same for the relax evaluator's cell FEM on the relaxed (and as-placed) RVE
RELAX_FEM_QUANTITIES = {"strain_mag": None, "strain_parallel": None,
                        "strain_perpendicular": None, "stress_mag_Pa": None,
                        "E_eff_parallel_Pa": "matrix_E_Pa",
                        "E_eff_perpendicular_Pa": "matrix_E_Pa",
                        "strain_affine_parallel": None}
#: suffix of the same quantities on the coarser grid of the two-grid estimate
COARSE = "_coarse"
for _q in {**FEM_QUANTITIES, **RELAX_FEM_QUANTITIES}:
    _unit, _shape, _desc = QUANTITIES[_q]
    QUANTITIES[_q + COARSE] = (_unit, _shape, _desc + ", on the coarser grid of the "
                               "discretization-error estimate ([study] coarse_voxels)")
del _q, _unit, _shape, _desc

# Seed-paper values used by the synthetic model, so that its numbers look like the real ones.
_MS_A_PER_M = SEED.Ms_A_m         # Fe saturation magnetization rho * sigma [A/m]
_B_SAT_T = 0.3                       # field scale of the synthetic magnetization curve [T]
_REL_SD_100 = 0.05                   # relative sd of f_eff at 100 particles
#: synthetic FEM quantities with ``[study] coarse_voxels``: the grid of n voxels adds
#: ``SYNTHETIC_DISC_REL * truth / n`` (first order), which the two-grid estimate recovers
SYNTHETIC_DISC_REL = 0.3


def get_evaluator(name: str, *, fem: bool = False, **options):
    """The evaluator of a study's ``evaluator`` key (``options``: its ``[synthetic]`` table)."""
    if name == "rve":
        return RVEEvaluator(fem=fem)
    if name == "relax":
        return RelaxEvaluator(fem=fem)
    if name == "synthetic":
        return SyntheticEvaluator(**options)
    raise InputError(f"unknown evaluator {name!r}; allowed: rve, relax, synthetic")


def _check_finite_result(out: dict, task) -> dict:
    res = {}
    for k, v in out.items():
        if k not in QUANTITIES:
            raise RuntimeError(f"evaluator returned unknown quantity {k!r}")
        a = np.asarray(v, dtype=np.float64)
        if a.shape != QUANTITIES[k][1]:
            raise RuntimeError(f"evaluator returned {k} with shape {a.shape}, "
                               f"expected {QUANTITIES[k][1]}")
        if not np.all(np.isfinite(a)):
            raise RuntimeError(f"non-finite {k} = {a} at grid point {task.grid_index} "
                               f"realization {task.realization} ({task.point})")
        res[k] = a
    return res


# --------------------------------------------------------------------------- synthetic
_SYNTH_AXES = {"phi", "B_T", "gradB_T_per_m", "mean_radius_m", "arrangement", "law"}
_ARRANGEMENT_FACTOR = {"dispersed": 1.0, "clusters": 1.1, "chains": 1.25}


def synthetic_truth(point: dict, settings: dict) -> dict:
    """Exact mean and standard deviation of each output of :class:`SyntheticEvaluator`.

    Returns ``{quantity: (mean, sd)}`` with arrays of the quantity's shape. The body force
    mimics a saturating Fe suspension, ``f_z = phi Ms tanh(B / 0.3 T) dB/dz`` (times 1.1 for
    ``clusters``, 1.25 for ``chains``), with a relative standard deviation
    ``0.05 sqrt(100 / n_particles)``: variance proportional to 1 / RVE volume (Kanit exponent 1).
    """
    phi = float(point.get("phi", 0.035))
    B = float(point.get("B_T", 0.1))
    g = float(point.get("gradB_T_per_m", 1.78))
    r = float(point.get("mean_radius_m", 25e-9))
    k = _ARRANGEMENT_FACTOR[point.get("arrangement", "dispersed")]
    n = int(settings["n_particles"])
    rel = _REL_SD_100 * math.sqrt(100.0 / n)
    M = phi * _MS_A_PER_M * math.tanh(B / _B_SAT_T) * k
    f = M * g
    out = {
        "f_eff_N_m3": (np.array([0.0, 0.0, f]), np.abs(np.array([0.2, 0.2, 1.0]) * rel * f)
                       + 1e-9),
        "M_eff_A_per_m": (np.array([0.0, 0.0, M]), np.abs(np.array([0.2, 0.2, 1.0]) * rel * M)
                          + 1e-9),
        "phi_eff": (np.array(phi * k), np.array(rel * phi)),
        "d_eff": (np.array(k), np.array(rel)),
        "virial_stress_Pa": (np.diag([-0.5, -0.5, 1.0]) * 1e-7 * M * M * k,
                             np.full((3, 3), rel * 1e-7 * M * M + 1e-9)),
        "volume_m3": (np.array(n * 4.0 / 3.0 * math.pi * r ** 3 / phi), np.array(0.0)),
        "phi_rve": (np.array(phi), np.array(0.0)),
    }
    if settings.get("fem"):
        out["E_eff_Pa"] = (np.array(PDMS.E_Pa * (1 + 2.5 * phi)), np.array(PDMS.E_Pa * rel * phi))
        out["nu_eff"] = (np.array(PDMS.nu), np.array(0.01 * rel))
        out["stress_mag_Pa"] = out["virial_stress_Pa"]
        out["strain_mag"] = (out["virial_stress_Pa"][0] / PDMS.E_Pa,
                             out["virial_stress_Pa"][1] / PDMS.E_Pa)
    return out


@dataclass(frozen=True)
class SyntheticEvaluator:
    """Normal outputs with a known distribution (:func:`synthetic_truth`).

    For tests of the batch machinery: ``counter_dir`` records every call as one file
    ``g<grid>_r<realization>_<uuid>``; ``die_once_dir`` makes the first call of each realization
    kill its worker process (``os._exit``), so the scheduler must retry it; ``fail_on`` lists
    tags ``g<grid>_r<realization>`` that raise; ``work_seconds`` burns CPU per call
    (for benchmarks).
    """

    counter_dir: str | None = None
    die_once_dir: str | None = None
    fail_on: tuple = ()
    work_seconds: float = 0.0

    id = "synthetic-1"

    def check(self, study) -> None:
        for axis, values in study.axes:
            if axis not in _SYNTH_AXES:
                raise InputError(f"{study.path}: [grid] unknown key '{axis}' for the synthetic "
                                 f"evaluator; allowed: {', '.join(sorted(_SYNTH_AXES))}")
            if axis == "arrangement":
                for v in values:
                    if v not in _ARRANGEMENT_FACTOR:
                        raise InputError(f"{study.path}: [grid] arrangement must be one of "
                                         f"{', '.join(_ARRANGEMENT_FACTOR)}; got {v!r}")
        for t in ("rve", "law", "magnetics", "cell"):
            if getattr(study, t):
                k = next(iter(getattr(study, t)))
                raise InputError(f"{study.path}: [{t}] unknown key '{k}' (the synthetic "
                                 f"evaluator takes no [{t}] parameters)")

    def __call__(self, task) -> dict:
        tag = f"g{task.grid_index}_r{task.realization}"
        if self.counter_dir is not None:
            Path(self.counter_dir, f"{tag}_{uuid.uuid4().hex}").touch()
        if self.die_once_dir is not None:
            marker = Path(self.die_once_dir, tag)
            if not marker.exists():
                marker.touch()
                os._exit(1)      # a dying worker, as after a segfault or the OOM killer
        if tag in self.fail_on:
            raise RuntimeError(f"synthetic failure of {tag}")
        if self.work_seconds > 0:
            t_end = time.process_time() + self.work_seconds
            x = 0.0
            while time.process_time() < t_end:
                x += math.sin(x + 1.0)
        truth = synthetic_truth(task.point, task.settings)
        rng = task.rng()
        out = {}
        for name in sorted(truth):     # fixed draw order: the result depends on the seed only
            mean, sd = truth[name]
            out[name] = mean + sd * rng.standard_normal(np.shape(mean))
        nc = task.settings.get("coarse_voxels")
        if task.settings.get("fem") and nc:
            # an exactly first-order discretization error A / voxels on top of the truth (the
            # infinite-grid value), the same realization on both grids
            n = task.settings["voxels"]
            for q in FEM_QUANTITIES:
                a = SYNTHETIC_DISC_REL * truth[q][0]
                out[q] = out[q] + a / n
                out[q + COARSE] = out[q] + a / nc - a / n
        return _check_finite_result(out, task)


# --------------------------------------------------------------------------- real chain
_FIELD_AXES = ("phi", "B_T", "gradB_T_per_m", "law")
DEFAULT_LAW = magnetization.DEFAULT_LAW
# Study keys that build the size distribution and the composition passed to generate_rve
# (they may be grid axes or [rve] keys). Defaults: the seed paper's powder; the bounds
# r_min_m, r_max_m follow the mean radius unless given (micro.materials.radius_bounds_m:
# 0.4 and 2 x the mean, the seed's [10, 50] nm at its 25 nm).
_DIST_KEYS = {"distribution": "lognormal", "mean_radius_m": SEED.radius_m, "gsd": SEED.gsd,
              "r_min_m": SEED.r_min_m, "r_max_m": SEED.r_max_m}
_COMP_KEYS = {"shell_thickness_m": "shell_m", "core_density_kg_m3": "core_density_kg_m3",
              "core_sigma_Am2_kg": "core_sigma_Am2_kg",
              "shell_density_kg_m3": "shell_density_kg_m3",
              "shell_sigma_Am2_kg": "shell_sigma_Am2_kg",
              "calibrate_sigma_Am2_kg": "calibrate_sigma_Am2_kg"}
_DISTRIBUTIONS = ("lognormal", "monodisperse")


#: Libraries whose version can change a stored result.
_RESULT_LIBRARIES = ("numpy", "scipy", "numba", "scikit-fem", "pyamg", "h5py")
_SOURCE_HASH: dict = {}


def _source_hash(fem: bool = False) -> str:
    """sha256 (12 hex digits) of everything that can change a stored result.

    Every ``.py`` file of the ``micro`` and ``homogenize`` packages (not a hand-kept list, which
    went stale when a solver module was added) and the versions of the numerical libraries.
    ``fem`` only tags the key; the FEM sources are always part of it.
    """
    if fem not in _SOURCE_HASH:
        h = hashlib.sha256(b"fem" if fem else b"dipoles")
        for root in (Path(micro.__file__).resolve().parent, Path(__file__).resolve().parents[1]):
            for f in sorted(root.rglob("*.py")):
                h.update(f.relative_to(root.parent).as_posix().encode())
                h.update(f.read_bytes())
        for lib in _RESULT_LIBRARIES:
            try:
                h.update(f"{lib}=={metadata.version(lib)}".encode())
            except metadata.PackageNotFoundError:
                h.update(f"{lib} missing".encode())
        _SOURCE_HASH[fem] = h.hexdigest()[:12]
    return _SOURCE_HASH[fem]


def _signature_keys(func) -> set:
    return {k for k, p in inspect.signature(func).parameters.items()
            if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}


def _particle_keys(generate_rve) -> set:
    """The study keys that describe the particle population (``generate_rve`` keywords)."""
    return ((_signature_keys(generate_rve) - {"phi", "n", "seed", "distribution", "composition",
                                              "progress"})
            | set(_DIST_KEYS) | set(_COMP_KEYS))


def _rve_kwargs(params: dict) -> dict:
    """Keywords of generate_rve from the study's RVE keys (distribution, composition, rest)."""
    p = dict(params)
    d = {k: p.pop(k, v) for k, v in _DIST_KEYS.items() if k not in ("r_min_m", "r_max_m")}
    lo, hi = radius_bounds_m(float(d["mean_radius_m"]))
    d["r_min_m"], d["r_max_m"] = p.pop("r_min_m", lo), p.pop("r_max_m", hi)
    if d["distribution"] == "lognormal":
        dist = LogNormal.from_mean(float(d["mean_radius_m"]), float(d["gsd"]),
                                   float(d["r_min_m"]), float(d["r_max_m"]))
    elif d["distribution"] == "monodisperse":
        dist = Monodisperse(float(d["mean_radius_m"]))
    else:
        raise InputError(f"distribution must be one of {', '.join(_DISTRIBUTIONS)}; "
                         f"got {d['distribution']!r}")
    comp = CoreShell(**{_COMP_KEYS[k]: p.pop(k) for k in list(p) if k in _COMP_KEYS})
    return {"distribution": dist, "composition": comp, **p}


def _check_keys(study, section: str, given, allowed, what: str = "") -> None:
    """Refuse a key of the study's ``[section]`` (or grid axis) that is not in ``allowed`` (listed
    in the order given)."""
    for k in given:
        if k not in allowed:
            raise InputError(f"{study.path}: [{section}] unknown key '{k}'{what}; allowed: "
                             f"{', '.join(allowed)}")


def _check_laws_and_particles(study, gen_keys, get_law) -> None:
    """Every magnetization law of the grid and every distinct particle population of the grid
    must be constructible (before any work starts)."""
    for law in dict(study.axes).get("law", (DEFAULT_LAW,)):
        try:
            get_law(law, **study.law)
        except (InputError, TypeError, ValueError) as exc:
            raise InputError(f"{study.path}: [grid] law / [law]: {exc}") from None
    rve_axes = [(a, v) for a, v in study.axes if a in gen_keys]
    for combo in dict.fromkeys(itertools.product(*(v for _, v in rve_axes))):
        try:
            _rve_kwargs({**study.rve, **dict(zip((a for a, _ in rve_axes), combo))})
        except (InputError, TypeError, ValueError) as exc:
            raise InputError(f"{study.path}: [grid]/[rve] particle parameters: {exc}") from None


def resolution_warnings(study) -> list[str]:
    """One warning per distinct (phi, particle population) of the grid whose mean radius
    is resolved by fewer voxels than the accuracy study needs
    (:func:`homogenize.tables.resolution.resolution_warning`; the box from the expected particle
    volume: the realizations' boxes scatter around it)."""
    if not study.fem:
        return []
    gen = _particle_keys(generate_rve)
    axes = [(a, v) for a, v in study.axes if a == "phi" or a in gen]
    out = []
    for combo in dict.fromkeys(itertools.product(*(v for _, v in axes))):
        point = dict(zip((a for a, _ in axes), combo))
        dist = _rve_kwargs({**study.rve, **{k: v for k, v in point.items()
                                           if k != "phi"}})["distribution"]
        box = (study.n_particles * dist.mean_volume_m3() / float(point["phi"])) ** (1 / 3)
        where = ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                          for k, v in point.items())
        w = resolution_warning(dist.raw_moment(1), box, study.voxels, where)
        if w:
            out.append(w)
    return out


@dataclass(frozen=True)
class RVEEvaluator:
    """particles -> dipoles -> (FEM): one random RVE at one grid point.

    Grid axes ``phi``, ``B_T``, ``gradB_T_per_m`` are required, ``law`` is optional
    (default: :data:`micro.magnetization.DEFAULT_LAW`, each particle the intrinsic law of its
    regime). The size distribution (``distribution`` = lognormal or
    monodisperse, ``mean_radius_m``, ``gsd``, ``r_min_m``, ``r_max_m``; default the seed's
    powder: mean 25 nm, gsd 1.4; bounds unless given 0.4 and 2 x the mean radius, [10, 50] nm
    for the seed), the composition (``shell_thickness_m``,
    ``core_sigma_Am2_kg``, ``calibrate_sigma_Am2_kg``, ...; see :class:`micro.particles.CoreShell`)
    and the other keywords of :func:`micro.particles.generate_rve` (``arrangement``, ``gap_m``,
    ``cluster_size``, ...) may be grid axes or ``[rve]`` keys; ``[law]`` goes to
    :func:`micro.magnetization.get_law`, ``[magnetics]`` to :func:`micro.dipoles.solve`,
    ``[cell]`` to :func:`homogenize.cell.problem.homogenize_rve`.
    """

    fem: bool = False     # the FEM modules' source enters the id only when they run

    @property
    def id(self) -> str:
        """``rve-1-<hash of the physics source code>``: stored results of an older code are
        never mixed with new ones (a changed solver recomputes everything)."""
        return f"rve-1{'-fem' if self.fem else ''}-{_source_hash(self.fem)}"

    def check(self, study) -> None:
        names = dict(study.axes)
        for req in ("phi", "B_T", "gradB_T_per_m"):
            if req not in names:
                raise InputError(f"{study.path}: [grid] missing key '{req}' (required by the "
                                 f"rve evaluator; one value is enough)")
        if any(float(g) == 0 for g in names["gradB_T_per_m"]):
            raise InputError(f"{study.path}: [grid] gradB_T_per_m must be != 0 T/m (no gradient, "
                             f"no body force; phi_eff and d_eff are defined by the force)")
        try:
            from micro.dipoles import solve
            from micro.magnetization import get_law
            from micro.particles import generate_rve
        except ModuleNotFoundError as exc:
            raise InputError(f"{study.path}: evaluator 'rve' needs {exc.name}, which is not "
                             f"available in this installation") from None
        gen_keys = _particle_keys(generate_rve)
        _check_keys(study, "grid", names, sorted(set(_FIELD_AXES) | gen_keys))
        _check_keys(study, "rve", study.rve, sorted(gen_keys))
        solve_keys = _signature_keys(solve) - {"rve", "B_T", "gradB_T_per_m", "law",
                                               "initial_moments_Am2"}
        _check_keys(study, "magnetics", study.magnetics, sorted(solve_keys))
        _check_laws_and_particles(study, gen_keys, get_law)
        if study.fem:
            try:
                from homogenize.cell.problem import homogenize_rve
            except ModuleNotFoundError as exc:
                raise InputError(f"{study.path}: [study] fem = true needs {exc.name}, which is "
                                 f"not available in this installation") from None
            cell_keys = _signature_keys(homogenize_rve) - {"rve", "voxels", "forces_N",
                                                           "virial_stress_Pa", "keep_fields",
                                                           "progress"}
            _check_keys(study, "cell", study.cell, sorted(cell_keys))
        elif study.cell:
            raise InputError(f"{study.path}: [cell] is given but [study] fem = false")

    def resolution_warnings(self, study) -> list[str]:
        """See :func:`resolution_warnings`."""
        return resolution_warnings(study)

    def __call__(self, task) -> dict:
        point = dict(task.point)
        s = task.settings
        phi = point.pop("phi")
        B = point.pop("B_T")
        grad = point.pop("gradB_T_per_m")
        law = get_law(point.pop("law", DEFAULT_LAW), **s["law"])
        kwargs = _rve_kwargs({**s["rve"], **point})
        rve = generate_rve(phi, s["n_particles"], task.seed_int(), **kwargs)
        state = solve(rve, B, grad, law, **s["magnetics"])
        out = {"f_eff_N_m3": state.f_eff_N_m3, "phi_eff": state.phi_eff, "d_eff": state.d_eff,
               "M_eff_A_per_m": state.M_eff_A_per_m, "virial_stress_Pa": state.virial_stress_Pa,
               "volume_m3": rve.volume_m3, "phi_rve": rve.phi}
        if s["fem"]:
            forces = state.total_force_N
            cell = homogenize_rve(rve, s["voxels"], forces_N=forces,
                                  virial_stress_Pa=state.virial_stress_Pa, **s["cell"])
            out.update(E_eff_Pa=cell.E_eff_Pa, nu_eff=cell.nu_eff,
                       stress_mag_Pa=cell.stress_mag_Pa, strain_mag=cell.strain_mag)
            if s.get("coarse_voxels"):
                # the same RVE and forces on the coarser grid: the two-grid estimate of the
                # discretization error (homogenize.tables.resolution)
                coarse = homogenize_rve(rve, s["coarse_voxels"], forces_N=forces,
                                        virial_stress_Pa=state.virial_stress_Pa, **s["cell"])
                out.update({q + COARSE: getattr(coarse, q) for q in FEM_QUANTITIES})
        return _check_finite_result(out, task)


# --------------------------------------------------------------------------- relax
_RELAX_AXES = ("phi", "B_T", "law", "matrix_E_Pa")
#: [relax] keys -> keyword of homogenize.cell.relax.relax (matrix_E_Pa / matrix_nu build the matrix)
_RELAX_KEYS = ("elastic_model", "boundary", "min_gap_m", "tol", "max_iter", "demag_factor",
               "accuracy", "cell_tol", "matrix_E_Pa", "matrix_nu", "near_field")
_RELAX_CACHE: dict = {}
_RELAX_CACHE_SIZE = 4


def _relax_fem_outputs(res, curve, k: int, B: float) -> dict:
    """The cell-FEM quantities (:data:`RELAX_FEM_QUANTITIES`) of field step ``k``."""
    st = res.steps[k]
    if st.get("cell_error"):
        raise RuntimeError(f"B = {B:g} T: {st['cell_error']}")
    eps = np.asarray(st["strain_mag"], dtype=float)
    return {"strain_mag": eps, "strain_parallel": eps[2, 2],
            "strain_perpendicular": 0.5 * (eps[0, 0] + eps[1, 1]),
            "stress_mag_Pa": st["stress_mag_Pa"],
            "E_eff_parallel_Pa": st["E_eff_parallel_Pa"],
            "E_eff_perpendicular_Pa": st["E_eff_perpendicular_Pa"],
            "strain_affine_parallel": curve["strain_affine"][k]}


def _relax_sweep(rve, B_steps, law, law_params, matrix, fem: bool, voxels: int, opts: dict):
    """Relaxed (and, with the cell FEM, as-placed) quantities at every field step."""
    from homogenize.cell.relax import magnetostriction_curve, relax
    if fem:
        curve = magnetostriction_curve(rve, B_steps, law=law, law_params=law_params,
                                       matrix=matrix, voxels=voxels, **opts)
        return curve["result"], curve
    return relax(rve, B_steps, law=law, law_params=law_params, matrix=matrix, voxels=None,
                 **opts), None


@dataclass(frozen=True)
class RelaxEvaluator:
    """Particles that move: one random RVE per realization relaxed through the field steps.

    Grid axes: ``phi`` and ``B_T`` (required; B_T strictly increasing: the field steps of one
    continuation, every step of a realization relaxes the same RVE), ``law`` and
    ``matrix_E_Pa`` (optional), and the particle keys of the rve evaluator (``distribution``,
    ``mean_radius_m``, ``arrangement``, ...). ``[relax]``: ``elastic_model`` (``green``, the
    fast periodic Green's function, default; or ``fem``, needs ``fem = true``), ``boundary``
    (``free``/``strain``), ``min_gap_m``, ``tol``, ``max_iter``, ``demag_factor``, ``accuracy``,
    ``cell_tol``, ``matrix_E_Pa`` (default the seed's PDMS, 2 MPa), ``matrix_nu`` (0.45),
    ``near_field`` (exact two-sphere forces for close pairs, default false).
    ``fem = true`` runs the cell FEM (``voxels``) on the relaxed RVE at every step: strain along
    and across the field, E along and across, and the same strain for the RVE as placed.
    Field along z. The sweep over all B values is computed once (run_batch submits the steps
    of one realization together, ``sweeps``; a per-process cache of the last sweeps serves the
    steps) and each grid point picks its step: results do not depend on which worker computes
    which point.
    """

    fem: bool = False
    #: run_batch submits all field steps of one realization as one task (one sweep each)
    sweeps = True

    def resolution_warnings(self, study) -> list[str]:
        """See :func:`resolution_warnings`."""
        return resolution_warnings(study)

    @property
    def id(self) -> str:
        return f"relax-1{'-fem' if self.fem else ''}-{_source_hash(self.fem)}"

    def check(self, study) -> None:
        names = dict(study.axes)
        for req in ("phi", "B_T"):
            if req not in names:
                raise InputError(f"{study.path}: [grid] missing key '{req}' (required by the "
                                 f"relax evaluator)")
        B = [float(b) for b in names["B_T"]]
        if any(b2 <= b1 for b1, b2 in zip(B, B[1:])):
            raise InputError(f"{study.path}: [grid] B_T must be strictly increasing for the "
                             f"relax evaluator (the field steps of one continuation, >= 0 T), "
                             f"got {B}")
        gen_keys = _particle_keys(generate_rve)
        _check_keys(study, "grid", names, sorted(set(_RELAX_AXES) | gen_keys),
                    " for the relax evaluator")
        _check_keys(study, "rve", study.rve, sorted(gen_keys))
        for t in ("magnetics", "cell"):
            if getattr(study, t):
                k = next(iter(getattr(study, t)))
                raise InputError(f"{study.path}: [{t}] {k}: the relax evaluator takes its "
                                 f"solver options in [relax] (allowed: {', '.join(_RELAX_KEYS)})")
        _check_keys(study, "relax", study.relax, _RELAX_KEYS)
        if "matrix_E_Pa" in study.relax and "matrix_E_Pa" in names:
            raise InputError(f"{study.path}: [relax] matrix_E_Pa is also a grid axis; give it "
                             f"in one place")
        if study.relax.get("elastic_model") == "fem" and not study.fem:
            raise InputError(f"{study.path}: [relax] elastic_model = \"fem\" needs [study] "
                             f"fem = true (the voxel FEM at [study] voxels)")
        nu = study.relax.get("matrix_nu", PDMS.nu)
        if not -1.0 < nu <= 0.5:
            raise InputError(f"{study.path}: [relax] matrix_nu must be in (-1, 0.5], got {nu}")
        _check_laws_and_particles(study, gen_keys, get_law)

    def __call__(self, task) -> dict:
        from micro.materials import ElasticMaterial
        point = dict(task.point)
        s = task.settings
        opts = dict(s["relax"])
        phi = point.pop("phi")
        B = float(point.pop("B_T"))
        law = point.pop("law", DEFAULT_LAW)
        E = float(point.pop("matrix_E_Pa", opts.pop("matrix_E_Pa", PDMS.E_Pa)))
        opts.pop("matrix_E_Pa", None)
        matrix = ElasticMaterial(E, float(opts.pop("matrix_nu", PDMS.nu)))
        kwargs = _rve_kwargs({**s["rve"], **point})
        seed = task.seed_int()
        B_steps = [float(b) for b in s["B_steps_T"]]
        ck = json.dumps({"seed": seed, "point": {k: v for k, v in task.point.items()
                                                 if k != "B_T"}, "settings": s},
                        sort_keys=True, default=str)
        hit = _RELAX_CACHE.get(ck)
        if hit is None:
            rve = generate_rve(phi, s["n_particles"], seed, **kwargs)
            res, curve = _relax_sweep(rve, B_steps, law, s["law"], matrix, s["fem"],
                                      s["voxels"], opts)
            coarse = None
            if s["fem"] and s.get("coarse_voxels"):
                # the same RVE and path with the cell FEM on the coarser grid: the two-grid
                # estimate of the discretization error (homogenize.tables.resolution)
                coarse = _relax_sweep(rve, B_steps, law, s["law"], matrix, True,
                                      s["coarse_voxels"], opts)
            hit = (rve, res, curve, coarse)
            while len(_RELAX_CACHE) >= _RELAX_CACHE_SIZE:
                _RELAX_CACHE.pop(next(iter(_RELAX_CACHE)))
            _RELAX_CACHE[ck] = hit
        rve, res, curve, coarse = hit
        k = min(range(len(B_steps)), key=lambda i: abs(B_steps[i] - B))
        st = res.steps[k]
        ms = st["microstructure"]
        out = {"M_eff_A_per_m": st["M_eff_vector_A_per_m"],
               "virial_stress_Pa": st["virial_stress_Pa"],
               "min_gap_m": st["min_gap_m"], "displacement_rms_m": st["displacement_rms_m"],
               "n_contacts": float(st["n_contacts"]), "chain_fraction": ms["chain_fraction"],
               "volume_m3": rve.volume_m3, "phi_rve": rve.phi}
        if s["fem"]:
            out.update(_relax_fem_outputs(res, curve, k, B),
                       M_eff_affine_A_per_m=curve["M_eff_affine_A_per_m"][k])
            if coarse is not None:
                fem_c = _relax_fem_outputs(*coarse, k, B)
                out.update({q + COARSE: v for q, v in fem_c.items()})
        return _check_finite_result(out, task)
