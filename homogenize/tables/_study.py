"""Study files (TOML): parsing, validation, grid expansion and per-realization seeds.

A study declares a grid of conditions and how many random RVEs to evaluate at each grid point::

    [study]
    name = "seed conditions"       # free text
    seed = 20130402                # study seed (integer >= 0)
    particle_material = "carbonyl-iron"   # optional presets of micro.materials (default
    matrix_material = "sylgard184-10to1"  # "seed-paper"): they fill the keys below not given
    realizations = 8               # random RVEs per grid point (>= 2, for a standard deviation)
    n_particles = 200              # particles per RVE (the RVE size)
    evaluator = "rve"              # "rve" (particles -> dipoles -> FEM), "relax" (particles
                                   # that move: coupled RVE through the B steps) or "synthetic"
    fem = false                    # run the FEM homogenization (E_eff, nu_eff, stress_mag)
    voxels = 16                    # FEM voxels per RVE edge (when fem = true)
    coarse_voxels = 10             # second grid of the discretization-error estimate (fem =
                                   # true; default: the even count nearest 2/3 voxels; 0: no
                                   # estimate); homogenize.tables.resolution
    confidence = 0.95              # level of the confidence intervals in the table

    [grid]                         # every key is a grid axis: one value or a list of values
    phi = [0.0175, 0.035]          # particle volume fraction [1]
    B_T = [0.005, 0.05, 0.5]       # applied flux density mu0 H along z [T]
    gradB_T_per_m = 1.78           # d|B|/dz [T/m]
    law = "regime"                 # magnetization law of one particle (micro.magnetization)
    arrangement = ["dispersed", "clusters"]    # any keyword of micro.particles.generate_rve

    [rve]        # fixed keywords of micro.particles.generate_rve
    [law]        # fixed parameters of micro.magnetization.get_law
    [magnetics]  # fixed keywords of micro.dipoles.solve (tol, accuracy, method, ...)
    [cell]       # fixed keywords of homogenize.cell.problem.homogenize_rve (matrix_E_Pa, ...)
    [relax]      # evaluator = "relax" only: keywords of homogenize.cell.relax.relax (elastic_model,
                 # boundary, min_gap_m, tol, max_iter, demag_factor, accuracy, cell_tol,
                 # matrix_E_Pa, matrix_nu, near_field); see homogenize/studies/relax_example.toml

    [synthetic]  # evaluator = "synthetic" only: work_seconds = CPU seconds per realization

    [rve_size]   # for `mapsim rve-size`
    n_particles = [25, 50, 100, 200]
    realizations = 16
    quantity = "f_eff_N_m3"
    component = "z"
    target_rel_precision = 0.02

``particle_material`` fills, where neither the grid nor the table gives them, the ``[rve]``
keys ``mean_radius_m``, ``gsd``, ``shell_thickness_m``, ``core_density_kg_m3``,
``core_sigma_Am2_kg``, ``calibrate_sigma_Am2_kg``, the ``[magnetics]`` reference
``rho_kg_m3``, ``sigma_s_Am2_kg`` (rve evaluator), the core ``material`` of the ``regime``
law (non-iron cores) and, with ``fem = true``, ``[cell] particle_E_Pa``, ``particle_nu``;
``matrix_material`` fills ``[cell] matrix_E_Pa``, ``matrix_nu`` (rve evaluator, ``fem =
true``) or ``[relax] matrix_E_Pa``, ``matrix_nu`` (relax evaluator). The filled numbers are
part of the study's settings (and of every realization's hash); ``"seed-paper"`` fills nothing
(its numbers are the defaults).

The grid is the Cartesian product of the axes, taken in the canonical order of
:data:`AXIS_ORDER` (then alphabetical for other axes), C order (last axis fastest). Grid point
``g`` realization ``r`` gets the seed ``SeedSequence(study seed, spawn_key=(g, r))``: independent
streams, reproducible one by one, whatever the number of workers or the order of execution.
With ``evaluator = "relax"`` the B_T axis is the sequence of field steps of one continuation:
every B value of a realization relaxes the SAME random RVE, so its seed is that of the grid
point at the first B value (``Task.seed_group``), and B_T must be strictly increasing.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import stat
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from micro.common.validate import InputError
import dataclasses
from micro.common.validate import Range
from micro.dipoles import FIELD_RANGES, METHODS, SUMMATIONS
from homogenize.cell.problem import CELL_RANGES
from micro.magnetization import LAW_ALIASES, LAW_NAMES
from homogenize.tables import _evaluate
from homogenize.voxels._budget import cheapest_cell_bytes, check_memory
from homogenize.tables.resolution import coarse_voxels

__all__ = ["Study", "Task", "load_study", "parse_study", "AXIS_ORDER"]

# Canonical order of the common axes; the grid index (and hence the seeds) does not depend on
# the order in which the axes are written in the file.
AXIS_ORDER = ("phi", "distribution", "mean_radius_m", "gsd", "shell_thickness_m",
              "arrangement", "law", "matrix_E_Pa", "B_T", "gradB_T_per_m")

# Units of the common axes (others: taken from their name, "1" if none can be told).
AXIS_UNITS = {"phi": "1", "mean_radius_m": "m", "shell_thickness_m": "m", "B_T": "T",
              "gradB_T_per_m": "T/m", "gsd": "1", "matrix_E_Pa": "Pa"}

_STUDY_KEYS = {
    "name": str, "seed": int, "realizations": int, "n_particles": int, "evaluator": str,
    "fem": bool, "voxels": int, "confidence": float, "description": str,
    "particle_material": str, "matrix_material": str, "coarse_voxels": int,
}
_TABLES = ("study", "grid", "rve", "law", "magnetics", "cell", "relax", "rve_size", "synthetic")
_RVE_SIZE_KEYS = {"n_particles": list, "realizations": int, "quantity": str, "component": str,
                  "target_rel_precision": float}
EVALUATORS = ("rve", "relax", "synthetic")


# Value rules of the known keys of [rve], [magnetics], [cell], [law] (and of the same keys as
# grid axes), checked at parse time so that no worker ever starts on a value that cannot run:
# key -> ("enum", choices) | ("bool",) | ("int", lo, hi) | ("float", lo, hi, unit, lo_open)
#        | ("vec3",) | a Range of the parameter's owner (micro.dipoles.FIELD_RANGES,
#        homogenize.cell.problem.CELL_RANGES): the same object the config class, the keyword
#        function and the CLI option check, never a copy of its numbers
_R = ("float", 1e-10, 1e-3, "m", False)
_SIGMA = ("float", 0.0, 300.0, "A m^2/kg", True)
_RHO = ("float", 0.0, 3e4, "kg/m^3", True)
_F, _C = FIELD_RANGES, CELL_RANGES
_RULES = {
    # particles (micro.particles.generate_rve, distribution and composition)
    "arrangement": ("enum", ("dispersed", "clusters", "chains")),
    "placement": ("enum", ("auto", "rsa", "compress")),
    "distribution": ("enum", ("lognormal", "monodisperse")),
    "gap_m": ("float", 0.0, 1e-3, "m", False),
    "cluster_size": ("int", 2, 5000),
    "cluster_density": ("float", 0.0, 0.6, "", True),
    "chain_length": ("float", 2.0, 1e4, "", False),
    "chain_direction": ("vec3",),
    "chain_spread_deg": ("float", 0.0, 90.0, "deg", False),
    "agglomerated_fraction": ("float", 0.0, 1.0, "", False),
    "max_attempts": ("int", 1, 10 ** 9),
    "mean_radius_m": _R, "r_min_m": _R, "r_max_m": _R,
    "gsd": ("float", 1.0, 10.0, "", True),
    "shell_thickness_m": ("float", 0.0, 1e-3, "m", False),
    "core_density_kg_m3": _RHO, "shell_density_kg_m3": _RHO,
    "core_sigma_Am2_kg": _SIGMA, "calibrate_sigma_Am2_kg": _SIGMA,
    "shell_sigma_Am2_kg": ("float", 0.0, 300.0, "A m^2/kg", False),
    # magnetics (micro.dipoles.solve)
    "tol": _F["tol"], "accuracy": _F["accuracy"],
    "method": ("enum", METHODS),
    "summation": ("enum", SUMMATIONS),
    "max_iter": _F["max_iter"],
    "damping": _F["damping"],
    "precondition": ("bool",),
    "demag_factor": _F["demag_factor"],
    "rho_kg_m3": _F["rho_kg_m3"], "sigma_s_Am2_kg": _F["sigma_s_Am2_kg"],
    "c_powder": _F["c_powder"],
    # magnetization law parameters (micro.magnetization.get_law)
    "chi": ("float", 0.0, math.inf, "", True), "chi0": ("float", 0.0, 1e6, "", True),
    "chi_i": ("float", 0.0, math.inf, "", True), "T_K": ("float", 0.0, 1e4, "K", True),
    "measurement_time_s": ("float", 0.0, 1e12, "s", True),
    "K1_J_m3": ("float", -1e8, 1e8, "J/m^3", False), "K_J_m3": ("float", 0.0, 1e8, "J/m^3", False),
    "Ms_core_A_m": ("float", 0.0, 1e7, "A/m", True),
    # cell (homogenize.cell.problem.homogenize_rve)
    "matrix_E_Pa": _C["E_Pa"], "particle_E_Pa": _C["E_Pa"], "matrix_nu": _C["nu"],
    "particle_nu": _C["nu"],
    "rigid": ("bool",), "deflate": ("bool",), "maxiter": _C["maxiter"],
    "tol_magnetic": _C["tol_magnetic"],
    # relax (homogenize.cell.relax.relax; tol, max_iter, accuracy, demag_factor, matrix_* above)
    "elastic_model": ("enum", ("green", "fem")), "boundary": ("enum", ("free", "strain")),
    "min_gap_m": ("float", 0.0, 1e-3, "m", True), "cell_tol": _C["tol"], "near_field": ("bool",),
}
# [cell] keys that share a name with a [magnetics] key: the cell's own rules
_CELL_RULES = {"method": ("enum", ("composite", "laminate", "centre", "fraction")),
               "tol": _C["tol"]}

#: resident memory per realization held by the client [bytes] (task, future, stored results)
_BYTES_PER_TASK = 4e3
#: memory of one RVE realization per particle [bytes] (measured ~0.5 kB/particle for the
#: placement; the dipole solve about doubles it); the cell solve's from homogenize.voxels._budget
_BYTES_PER_PARTICLE = 1.6e3


def _check_rule(where: str, key: str, v, rules=None):
    """Check ``v`` against the rule of ``key`` (unknown keys pass: the evaluator names them)."""
    rule = (rules or {}).get(key) or _RULES.get(key)
    if rule is None:
        return v
    if isinstance(rule, Range):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            what = "" if rule.integer else "a number "
            raise InputError(f"{where} must be {what}{rule.describe()}, got {v!r}")
        rule.check(where, v)
        return v
    kind = rule[0]
    if kind == "enum":
        if not isinstance(v, str) or v not in rule[1]:
            raise InputError(f"{where} must be one of {', '.join(rule[1])}; got {v!r}")
    elif kind == "bool":
        if not isinstance(v, bool):
            raise InputError(f"{where} must be true or false, got {v!r}")
    elif kind == "int":
        if isinstance(v, bool) or not isinstance(v, int) or not rule[1] <= v <= rule[2]:
            raise InputError(f"{where} must be an integer in [{rule[1]}, {rule[2]}], got {v!r}")
    elif kind == "vec3":
        if (not isinstance(v, list) or len(v) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) or
                       not math.isfinite(x) for x in v) or not any(v)):
            raise InputError(f"{where} must be a list of 3 finite numbers, not all zero; "
                             f"got {v!r}")
    else:
        _, lo, hi, unit, lo_open = rule
        hi_open = False
        u = f" {unit}" if unit else ""
        left, right = ("(" if lo_open else "["), (")" if hi_open else "]")
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise InputError(f"{where} must be a number in {left}{lo:g}, {hi:g}{right}{u}, "
                             f"got {v!r}")
        if (v != v or (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi)):
            raise InputError(f"{where} must be in {left}{lo:g}, {hi:g}{right}{u}, got {v!r}")
    return v


def _unit_of(axis: str) -> str:
    if axis in AXIS_UNITS:
        return AXIS_UNITS[axis]
    for suffix, unit in (("_m", "m"), ("_T", "T"), ("_Pa", "Pa"), ("_T_per_m", "T/m"),
                         ("_A_per_m", "A/m"), ("_kg_m3", "kg/m^3")):
        if axis.endswith(suffix):
            return unit
    return "1"


@dataclass(frozen=True)
class RveSizeSpec:
    """The ``[rve_size]`` table: RVE sizes to compare and the target precision."""

    n_particles: tuple
    realizations: int
    quantity: str = "f_eff_N_m3"
    component: str = "z"
    target_rel_precision: float = 0.02


@dataclass(frozen=True)
class Study:
    """A validated study: fixed settings plus grid axes (immutable).

    ``axes`` is a tuple of ``(name, values)`` in canonical order; ``points()`` expands it.
    """

    path: str
    text: str
    name: str
    seed: int
    realizations: int
    n_particles: int
    evaluator: str
    fem: bool
    voxels: int
    confidence: float
    axes: tuple
    coarse_voxels: int = 0       # second grid of the discretization error (0: none)
    rve: dict = field(default_factory=dict)
    law: dict = field(default_factory=dict)
    magnetics: dict = field(default_factory=dict)
    cell: dict = field(default_factory=dict)
    relax: dict = field(default_factory=dict)        # [relax] (evaluator = "relax")
    rve_size: RveSizeSpec | None = None
    synthetic: dict = field(default_factory=dict)   # options of the synthetic evaluator

    @property
    def axis_names(self) -> tuple:
        return tuple(a for a, _ in self.axes)

    @property
    def grid_shape(self) -> tuple:
        return tuple(len(v) for _, v in self.axes)

    @property
    def n_points(self) -> int:
        return math.prod(self.grid_shape)

    def points(self) -> list[dict]:
        """Grid points in grid-index order (C order over ``axes``)."""
        names = self.axis_names
        return [dict(zip(names, combo)) for combo in itertools.product(*(v for _, v in self.axes))]

    def settings(self) -> dict:
        """Everything besides the grid point that determines one realization's result."""
        s = {"n_particles": self.n_particles, "fem": self.fem, "voxels": self.voxels,
             "rve": self.rve, "law": self.law, "magnetics": self.magnetics, "cell": self.cell}
        if self.coarse_voxels:
            s["coarse_voxels"] = self.coarse_voxels
        if self.evaluator == "relax":
            # the whole continuation path determines the result at each of its steps
            s["relax"] = self.relax
            s["B_steps_T"] = [float(b) for b in dict(self.axes)["B_T"]]
        return s

    def tasks(self) -> list["Task"]:
        """All realizations in grid order (point-major), each with its own seed."""
        settings = self.settings()
        groups = self._seed_groups()
        return [Task(grid_index=g, realization=r, point=p, settings=settings,
                     study_seed=self.seed, seed_group=groups[g])
                for g, p in enumerate(self.points()) for r in range(self.realizations)]

    def _seed_groups(self) -> list:
        """Per grid point, the grid index whose seeds it uses: itself, or for the relax
        evaluator the point with the same other axes at the first B value (one RVE per
        continuation path)."""
        P = self.n_points
        if self.evaluator != "relax":
            return list(range(P))
        names = self.axis_names
        k = names.index("B_T")
        shape = self.grid_shape
        out = []
        for g in range(P):
            idx = list(np.unravel_index(g, shape))
            idx[k] = 0
            out.append(int(np.ravel_multi_index(tuple(idx), shape)))
        return out

    def replace(self, **changes) -> "Study":
        return dataclasses.replace(self, **changes)

    def config(self) -> dict:
        """JSON-serialisable description (for manifests)."""
        return {"path": self.path, "name": self.name, "seed": self.seed,
                "realizations": self.realizations, "n_particles": self.n_particles,
                "evaluator": self.evaluator, "fem": self.fem, "voxels": self.voxels,
                "coarse_voxels": self.coarse_voxels, "confidence": self.confidence,
                "axes": {a: list(v) for a, v in self.axes},
                "rve": self.rve, "law": self.law, "magnetics": self.magnetics,
                "cell": self.cell, "relax": self.relax, "synthetic": self.synthetic,
                "study_file_text": self.text}


@dataclass(frozen=True)
class Task:
    """One realization: grid point, realization index, settings and seed."""

    grid_index: int
    realization: int
    point: dict
    settings: dict
    study_seed: int
    seed_group: int | None = None     # grid index whose seeds this task shares (relax)

    def seed_sequence(self) -> np.random.SeedSequence:
        """``SeedSequence(study seed, spawn_key=(grid index, realization index))``; the grid
        index is ``seed_group`` when set (all field steps of one relax realization)."""
        g = self.grid_index if self.seed_group is None else self.seed_group
        return np.random.SeedSequence(self.study_seed, spawn_key=(g, self.realization))

    def seed_int(self) -> int:
        """A 63-bit integer seed drawn from :meth:`seed_sequence` (for APIs that take an int)."""
        w = self.seed_sequence().generate_state(2, np.uint32)
        return int((int(w[0]) << 31) ^ int(w[1]))

    def rng(self) -> np.random.Generator:
        return np.random.default_rng(self.seed_sequence())

    def key(self, evaluator_id: str) -> str:
        """Hash of everything that determines the result: names the stored part."""
        doc = {"evaluator": evaluator_id, "point": self.point, "settings": self.settings,
               "seed": self.study_seed, "spawn_key": [self.grid_index, self.realization]}
        text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]


# --------------------------------------------------------------------------- parsing
_MAX_STUDY_BYTES = 4 * 2 ** 20


def load_study(path) -> Study:
    """Read and validate a study file; raise :class:`InputError` naming file, table and key."""
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise InputError(f"study file {path} does not exist") from None
    except OSError as exc:
        raise InputError(f"study file {path} cannot be read: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode) or st.st_size > _MAX_STUDY_BYTES:
        raise InputError(f"study file {path} must be a regular file of at most "
                         f"{_MAX_STUDY_BYTES // 2 ** 20} MiB (a TOML text)")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"study file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"study file {path} cannot be read: {exc}") from None
    return parse_study(text, str(path))


def _type_name(t) -> str:
    return {str: "a string", int: "an integer", float: "a number", bool: "true or false",
            list: "a list"}[t]


def _coerce(where: str, value, t):
    if t is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if t is int and isinstance(value, bool):
        raise InputError(f"{where} must be {_type_name(t)}, got {value!r}")
    if not isinstance(value, t):
        raise InputError(f"{where} must be {_type_name(t)}, got {value!r}")
    return value


def _check_scalar_value(where: str, axis: str, v):
    """Range checks for the values of the common axes."""
    if isinstance(v, bool) or not isinstance(v, (int, float, str)):
        raise InputError(f"{where} values must be numbers or strings, got {v!r}")
    if axis == "law":
        if not isinstance(v, str) or (v not in LAW_NAMES and v not in LAW_ALIASES):
            raise InputError(f"{where} values must be names of magnetization laws "
                             f"({', '.join(LAW_NAMES)}), got {v!r}")
        return v
    if isinstance(v, str):
        if axis in ("phi", "B_T", "gradB_T_per_m", "mean_radius_m", "shell_thickness_m"):
            raise InputError(f"{where} values must be numbers [{_unit_of(axis)}], got {v!r}")
        return _check_rule(f"{where} value", axis, v)
    v = float(v)
    if not math.isfinite(v):
        raise InputError(f"{where} values must be finite, got {v!r}")
    if axis == "phi" and not 0 < v <= 0.6:
        raise InputError(f"{where} values must be in (0, 0.6] (particle volume fraction), got {v:g}")
    if axis == "B_T" and v < 0:
        raise InputError(f"{where} values must be >= 0 T, got {v:g}")
    if axis in ("mean_radius_m",) and not 0 < v < 1e-5:
        raise InputError(f"{where} values must be in (0, 1e-05) m, got {v:g}")
    if axis in ("shell_thickness_m",) and v < 0:
        raise InputError(f"{where} values must be >= 0 {_unit_of(axis)}, got {v:g}")
    if axis == "B_T" and v > 50:
        raise InputError(f"{where} values must be <= 50 T, got {v:g}")
    if axis == "gradB_T_per_m" and abs(v) > 1e4:
        raise InputError(f"{where} values must be in [-1e4, 1e4] T/m, got {v:g}")
    if axis in _RULES and axis != "phi":
        _check_rule(f"{where} value", axis, v)
    return v


def parse_study(text: str, path: str = "<study>") -> Study:
    """Parse and validate the text of a study file (see the module docstring)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    for key, val in doc.items():
        if key not in _TABLES:
            raise InputError(f"{path}: unknown table or key '{key}'; allowed tables: "
                             f"{', '.join('[' + t + ']' for t in _TABLES)}")
        if not isinstance(val, dict):
            raise InputError(f"{path}: '{key}' must be a table [{key}]")
    st = doc.get("study")
    if st is None:
        raise InputError(f"{path}: missing table [study] (with at least seed and realizations)")
    for key in st:
        if key not in _STUDY_KEYS:
            raise InputError(f"{path}: [study] unknown key '{key}'; allowed: "
                             f"{', '.join(_STUDY_KEYS)}")
    s = {k: _coerce(f"{path}: [study] {k}", v, _STUDY_KEYS[k]) for k, v in st.items()}
    for req in ("seed", "realizations"):
        if req not in s:
            raise InputError(f"{path}: [study] missing key '{req}'")
    if s["seed"] < 0:
        raise InputError(f"{path}: [study] seed must be an integer >= 0, got {s['seed']}")
    if s["realizations"] < 2:         # the top is bounded by the memory estimate below
        raise InputError(f"{path}: [study] realizations must be >= 2 (a standard deviation "
                         f"needs two), got {s['realizations']}")
    n_particles = s.get("n_particles", 100)
    if not 1 <= n_particles <= 5 * 10 ** 7:
        raise InputError(f"{path}: [study] n_particles must be in [1, 50000000], "
                         f"got {n_particles}")
    voxels = s.get("voxels", 16)
    CELL_RANGES["voxels"].check(f"{path}: [study] voxels", voxels)
    confidence = s.get("confidence", 0.95)
    if not 0 < confidence < 1:
        raise InputError(f"{path}: [study] confidence must be in (0, 1), got {confidence:g}")
    evaluator = s.get("evaluator", "rve")
    if evaluator not in EVALUATORS:
        raise InputError(f"{path}: [study] evaluator must be one of {', '.join(EVALUATORS)}; "
                         f"got {evaluator!r}")
    coarse = _coarse_voxels(path, s, evaluator, voxels)

    grid = doc.get("grid")
    if not grid:
        raise InputError(f"{path}: [grid] is empty or missing: the study needs at least one "
                         f"axis (e.g. B_T = [0.01, 0.1])")
    axes = []
    for axis, raw in grid.items():
        where = f"{path}: [grid] {axis}"
        values = raw if isinstance(raw, list) else [raw]
        if not values:
            raise InputError(f"{where} is an empty list: every grid axis needs at least one value")
        values = [_check_scalar_value(where, axis, v) for v in values]
        kinds = {isinstance(v, str) for v in values}
        if len(kinds) > 1:
            raise InputError(f"{where} mixes numbers and strings")
        if len(set(values)) != len(values):
            raise InputError(f"{where} has repeated values {values}")
        axes.append((axis, tuple(values)))
    rank = {a: i for i, a in enumerate(AXIS_ORDER)}
    axes.sort(key=lambda av: (rank.get(av[0], len(AXIS_ORDER)), av[0]))

    tables = {}
    for t in ("rve", "law", "magnetics", "cell", "relax"):
        tab = doc.get(t, {})
        if t == "relax" and tab and evaluator != "relax":
            raise InputError(f"{path}: [relax] is given but [study] evaluator = {evaluator!r}")
        for k, v in tab.items():
            if k in dict(axes):
                raise InputError(f"{path}: [{t}] {k} is also a grid axis; give it in one place")
            _check_rule(f"{path}: [{t}] {k}", k, v, _CELL_RULES if t == "cell" else None)
        tables[t] = dict(tab)
    _apply_presets(path, s, dict(axes), tables, evaluator)
    _check_study_size(path, math.prod(len(v) for _, v in axes), s["realizations"], n_particles,
                      s.get("fem", False), voxels)

    rve_size = None
    if "rve_size" in doc:
        rs = doc["rve_size"]
        for key in rs:
            if key not in _RVE_SIZE_KEYS:
                raise InputError(f"{path}: [rve_size] unknown key '{key}'; allowed: "
                                 f"{', '.join(_RVE_SIZE_KEYS)}")
        r = {k: _coerce(f"{path}: [rve_size] {k}", v, _RVE_SIZE_KEYS[k]) for k, v in rs.items()}
        sizes = r.get("n_particles")
        if not sizes:
            raise InputError(f"{path}: [rve_size] n_particles must be a non-empty list of "
                             f"particle counts")
        for n in sizes:
            if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 5 * 10 ** 7:
                raise InputError(f"{path}: [rve_size] n_particles must be integers in "
                                 f"[1, 50000000], got {n!r}")
        if len(sizes) < 3:
            raise InputError(f"{path}: [rve_size] n_particles needs at least three sizes (a "
                             f"power-law fit with an error estimate), got {sizes}")
        if len(set(sizes)) != len(sizes):
            raise InputError(f"{path}: [rve_size] n_particles has repeated values {sizes}")
        reals = r.get("realizations", s["realizations"])
        if reals < 3:
            raise InputError(f"{path}: [rve_size] realizations must be >= 3, got {reals}")
        n_points = math.prod(len(v) for _, v in axes)
        for n in sizes:
            _check_study_size(path, n_points, reals, n, s.get("fem", False), voxels)
        prec = r.get("target_rel_precision", 0.02)
        if not 0 < prec < 1:
            raise InputError(f"{path}: [rve_size] target_rel_precision must be in (0, 1), "
                             f"got {prec:g}")
        quantity = r.get("quantity", "f_eff_N_m3")
        hits = [q for q in _evaluate.QUANTITIES if (q == quantity or q.startswith(quantity + "_"))
                and not q.endswith(_evaluate.COARSE)]
        if quantity not in _evaluate.QUANTITIES and len(hits) != 1:
            raise InputError(f"{path}: [rve_size] quantity must be one of (or a unique prefix "
                             f"of) {', '.join(_evaluate.QUANTITIES)}; got {quantity!r}")
        comp = r.get("component", "z")
        if comp not in ("x", "y", "z", "norm", ""):
            raise InputError(f"{path}: [rve_size] component must be x, y, z or norm; got {comp!r}")
        rve_size = RveSizeSpec(n_particles=tuple(sorted(sizes)), realizations=reals,
                               quantity=r.get("quantity", "f_eff_N_m3"), component=comp,
                               target_rel_precision=prec)

    synth = _synthetic_options(doc, path, evaluator)
    study = Study(path=str(path), text=text, name=s.get("name", Path(path).stem), seed=s["seed"],
                  realizations=s["realizations"], n_particles=n_particles, evaluator=evaluator,
                  fem=s.get("fem", False), voxels=voxels, coarse_voxels=coarse,
                  confidence=confidence,
                  axes=tuple(axes), rve_size=rve_size, synthetic=synth, **tables)
    _evaluate.get_evaluator(evaluator).check(study)
    return study


def _apply_presets(path: str, s: dict, axes: dict, tables: dict, evaluator: str) -> None:
    """Fill the keys of ``[study] particle_material`` / ``matrix_material`` (named presets of
    :mod:`micro.materials`) that neither the grid nor their table gives (see the module doc)."""
    from micro.materials import (DEFAULT_PRESET, FE, MATRIX_PRESETS, PARTICLE_PRESETS,
                                 matrix_preset, particle_preset)
    names = {k: s[k] for k in ("particle_material", "matrix_material") if k in s}
    for key, table in (("particle_material", PARTICLE_PRESETS),
                       ("matrix_material", MATRIX_PRESETS)):
        if key in names and names[key] not in table:
            raise InputError(f"{path}: [study] {key} must be one of {', '.join(table)}; got "
                             f"{names[key]!r}")
    names = {k: v for k, v in names.items() if v != DEFAULT_PRESET}
    if names and evaluator not in ("rve", "relax"):
        raise InputError(f"{path}: [study] {next(iter(names))} needs evaluator \"rve\" or "
                         f"\"relax\" (the {evaluator} evaluator takes no material parameters)")
    fem = s.get("fem", False)

    def fill(table: str, values: dict) -> None:
        t = tables[table]
        for k, v in values.items():
            if v is not None and k not in t and k not in axes:
                t[k] = v

    if "particle_material" in names:
        p = particle_preset(names["particle_material"])
        fill("rve", {"mean_radius_m": p.mean_radius_m, "gsd": p.gsd,
                     "shell_thickness_m": p.shell_m, "core_density_kg_m3": p.density_kg_m3,
                     "core_sigma_Am2_kg": p.core_sigma_Am2_kg,
                     "calibrate_sigma_Am2_kg": p.calibrate_sigma_Am2_kg})
        if evaluator == "rve":
            fill("magnetics", {"rho_kg_m3": p.density_kg_m3,
                               "sigma_s_Am2_kg": p.powder_sigma_Am2_kg})
            if fem:
                fill("cell", {"particle_E_Pa": p.E_Pa, "particle_nu": p.nu})
        laws = axes.get("law", ("regime",))
        if p.core is not FE and all(law == "regime" for law in laws):
            fill("law", {"material": p.core.name})
    if "matrix_material" in names:
        m = matrix_preset(names["matrix_material"])
        if evaluator == "relax":
            fill("relax", {"matrix_E_Pa": m.E_Pa, "matrix_nu": m.nu})
        elif fem:
            fill("cell", {"matrix_E_Pa": m.E_Pa, "matrix_nu": m.nu})
        else:
            raise InputError(f"{path}: [study] matrix_material needs fem = true (the matrix "
                             f"enters only the cell FEM)")


def _check_study_size(path, n_points: int, realizations: int, n_particles: int, fem: bool,
                      voxels: int) -> None:
    """Refuse a study whose client bookkeeping or single realization exceeds the machine."""
    n_tasks = n_points * realizations
    check_memory(f"{path}: {n_points} grid points x {realizations} realizations "
                 f"({n_tasks:.3g} tasks)", n_tasks * _BYTES_PER_TASK,
                 "use fewer realizations or grid values")
    per = 0.3e9 + _BYTES_PER_PARTICLE * n_particles + (cheapest_cell_bytes(voxels) if fem
                                                       else 0.0)
    check_memory(f"{path}: one realization of n_particles = {n_particles}"
                 + (f" with voxels = {voxels}" if fem else ""), 2 * per,
                 "two workers run at once; use fewer particles or voxels")


def _coarse_voxels(path, s: dict, evaluator: str, voxels: int) -> int:
    """``[study] coarse_voxels``: the second grid of the discretization-error estimate
    (:mod:`homogenize.tables.resolution`). Default with ``fem = true`` (rve and relax evaluators): the
    even count nearest 2/3 ``voxels`` (none below 6 voxels); 0 turns the estimate off; the
    synthetic evaluator only with an explicit value."""
    fem = s.get("fem", False)
    if "coarse_voxels" not in s:
        return coarse_voxels(voxels) if (fem and evaluator != "synthetic" and voxels >= 6) \
            else 0
    c = s["coarse_voxels"]
    if c == 0:
        return 0
    if not fem:
        raise InputError(f"{path}: [study] coarse_voxels = {c} is given but fem = false: "
                         f"there is no cell FEM to estimate (use 0 or leave it out)")
    if not 4 <= c < voxels:
        raise InputError(f"{path}: [study] coarse_voxels must be 0 (no discretization-error "
                         f"estimate) or in [4, voxels - 1] = [4, {voxels - 1}], got {c}")
    return c


def _synthetic_options(doc: dict, path: str, evaluator: str) -> dict:
    """The ``[synthetic]`` table: ``work_seconds`` of CPU per realization (benchmarks, demos)."""
    syn = doc.get("synthetic", {})
    if syn and evaluator != "synthetic":
        raise InputError(f"{path}: [synthetic] is given but [study] evaluator = {evaluator!r}")
    for k, v in syn.items():
        if k != "work_seconds":
            raise InputError(f"{path}: [synthetic] unknown key '{k}'; allowed: work_seconds")
        v = _coerce(f"{path}: [synthetic] work_seconds", v, float)
        if not 0 <= v <= 3600:
            raise InputError(f"{path}: [synthetic] work_seconds must be in [0, 3600] s, got {v:g}")
    return {k: float(v) for k, v in syn.items()}
