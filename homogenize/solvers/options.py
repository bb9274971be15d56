"""The solver settings of the project: frozen, validated once, passed in (an options database, as
PETSc has one), never module globals changed from outside.

* :class:`AMGOptions` -- one pyamg smoothed-aggregation setup (:func:`homogenize.solvers.amg.
  smoothed_aggregation`). Its defaults are the cell FEM's: the other solvers (cut voxels,
  conforming meshes, macro FEM) hold their own instance with their own values.
* :class:`SolverOptions` -- everything the periodic cell solver (:mod:`homogenize.cell.problem`) can be
  tuned by: the AMG, the matrix-free geometric multigrid, the particle patches, the block CG.

Derive a variant with :meth:`SolverOptions.replace` (``SolverOptions().replace(block_cg=
"independent")``); every field is checked where it is defined, with a clear
:class:`micro.InputError` (a ``ValueError``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from micro.common.validate import InputError

__all__ = ["AMGOptions", "SolverOptions", "BLOCK_CG_MODES", "MATFREE_COARSE_SOLVERS"]

#: how the load cases' CGs share their search directions (:attr:`SolverOptions.block_cg`)
BLOCK_CG_MODES = ("coupled", "strains", "independent")
#: the solvers of the matrix-free multigrid's assembled grid (:attr:`SolverOptions.matfree_coarse`)
MATFREE_COARSE_SOLVERS = ("amg", "lu")


def _int(name, value, lo):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < lo:
        raise InputError(f"{name} must be an integer >= {lo}, got {value!r}")


def _real(name, value, lo, hi, lo_open=False):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.floating,
                                                                     np.integer)):
        raise InputError(f"{name} must be a number in {'(' if lo_open else '['}{lo}, {hi}], "
                         f"got {value!r}")
    v = float(value)
    if not np.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
        raise InputError(f"{name} must be in {'(' if lo_open else '['}{lo}, {hi}], got {value!r}")


def _bool(name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")


def _choice(name, value, choices):
    if value not in choices:
        raise InputError(f"{name} must be one of {choices}, got {value!r}")


@dataclass(frozen=True)
class AMGOptions:
    """One pyamg smoothed-aggregation hierarchy. The defaults are the cell FEM's (``"fast"`` and
    the matrix-free solver's coarse grid): strength threshold 0.05 -- a matrix-particle coupling
    ``|a_ij| ~ E_matrix`` against ``sqrt(a_ii a_jj) ~ sqrt(E_m E_p)`` is weak at any contrast above
    ~400, so aggregates do not straddle a particle surface and the coarse space carries every
    particle's rigid motions (CG iterations at Fe/PDMS contrast halve against theta = 0); the
    rigid-body near-null space is exact on the fine level: no candidate smoothing. The
    prolongation smoother is always :data:`homogenize.solvers.amg.SA_SMOOTH`.

    symmetry : {"hermitian", "symmetric"} -- pyamg's ``symmetry``
    strength_theta : float in [0, 1) or None -- symmetric strength of connection with this
        threshold; None: pyamg's default (``"symmetric"``, theta 0)
    improve_candidates : bool -- pyamg's default candidate smoothing (4 block Gauss-Seidel
        sweeps) when True; none (``improve_candidates=None``) when False
    coarse_solver : {"splu", "pinv", "cholesky", "lu"} or None -- the coarsest level's solver;
        None: pyamg's default
    max_coarse : int >= 1 or None -- unknowns (blocks) of the coarsest level; None: the user's
        own size rule (the cell solvers scale it with the grid)
    keep : bool -- keep the tentative prolongators (diagnostics)
    """

    symmetry: str = "hermitian"
    strength_theta: float | None = 0.05
    improve_candidates: bool = False
    coarse_solver: str | None = "splu"
    max_coarse: int | None = None
    keep: bool = False

    def __post_init__(self):
        _choice("AMGOptions.symmetry", self.symmetry, ("hermitian", "symmetric"))
        if self.strength_theta is not None:
            _real("AMGOptions.strength_theta", self.strength_theta, 0.0, 1.0)
            if float(self.strength_theta) >= 1.0:
                raise InputError(f"AMGOptions.strength_theta must be in [0, 1), got "
                                 f"{self.strength_theta!r}")
        _bool("AMGOptions.improve_candidates", self.improve_candidates)
        if self.coarse_solver is not None:
            _choice("AMGOptions.coarse_solver", self.coarse_solver,
                    ("splu", "pinv", "cholesky", "lu"))
        if self.max_coarse is not None:
            _int("AMGOptions.max_coarse", self.max_coarse, 1)
        _bool("AMGOptions.keep", self.keep)

    def replace(self, **changes) -> AMGOptions:
        """A copy with ``changes`` (validated again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class SolverOptions:
    """Tuning of the periodic cell solver (:func:`homogenize.cell.problem.homogenize_mesh`,
    ``options=``). The defaults are the measured choices cited per field; the results'
    ``settings`` record what was used.

    amg : :class:`AMGOptions` -- the smoothed aggregation of ``solver="fast"`` and of the
        matrix-free solver's assembled grid (the coarsest-level size, when None, scales with the
        grid: up to 4000 unknowns for "fast", measured at 64^3: 17-18 CG iterations against
        26-29 with 500; up to 600 blocks below the geometric levels)
    matfree_assembled_max : int >= 1 -- matrix-free geometric levels down to this many voxels
        per edge, the Galerkin matrix of that grid assembled for pyamg (128^3 -> 64^3;
        64^3 -> 32^3)
    matfree_coarse : {"amg", "lu"} -- the assembled grid's solver: pyamg smoothed aggregation,
        or exact ("lu": a diagnostic for small grids, results/cell/multigrid_robustness.py)
    matfree_sweeps : int >= 1 -- block Gauss-Seidel sweeps per side on every matrix-free level.
        Two were measured in session 10 (6 strains + the magnetic column at magnetic_tol, bench
        RVEs, idle machine): 19.6 s against 22.0 s at 64^3 (strain / magnetic iterations 26 / 36
        against 42 / 45) but 679 s against 604 s at 128^3 (108 / 189 against 127 / 221): the
        iterations fall by 0.6-0.85x while an iteration costs ~1.35x, so one stays
        (results/cell/README.md)
    matfree_interface_sweeps : int >= 0 -- further sweeps per side over the interface nodes only
        (own stencil row: next to a cut voxel or a phase boundary, grown by
        ``matfree_interface_halo`` nodes; ~24 % of the nodes of the 64^3 bench RVE). Measured in
        session 11 (results/cell/README.md, "Local sweeps at the interfaces"): they take the
        iterations where two full sweeps take them at a fraction of the cost
    matfree_interface_halo : int >= 0
    block_cg : {"coupled", "strains", "independent"} -- matrix-free solver: how the load cases'
        CGs share their search directions (:func:`homogenize.solvers.coupled_block_cg`):
        "coupled" -- one block CG, every column steps in the span of all the block's directions
        (the outlying eigenvalues the geometric V-cycle leaves are found by the whole block);
        "strains" -- the six strains coupled, the magnetic column on its own; "independent" --
        lock-step single-column CGs (:func:`homogenize.solvers.block_cg`). Measured in session 12
        (results/cell/block_cg_modes.py, results/cell/README.md "Coupled block CG"): at 128^3 the
        magnetic column converges more slowly once the strains have left a coupled block (220
        against 190 iterations): 591 s "strains", 662 s "coupled", 634 s "independent"; on
        mid-size RVEs "coupled" was as fast or faster (timings vary by 20 % between runs).
        ``solver="fast"`` keeps independent columns: its smoothed aggregation leaves no such
        outliers (the same iterations coupled, 64^3 bench RVE).
    patch_shell_voxels : float >= 0 or None -- matrix-free solver: particle patches
        (homogenize.solvers._patches): the fine nodes within r + this many voxels of each particle's
        centre solved exactly in the fine level of the V-cycle (None: never), built when
        :func:`homogenize.cell.problem.use_patches` says so. A 1-voxel shell took 188 s but 6.1 GB at
        128^3 (18 / 35 iterations), half a voxel 213-219 s and 5.8 GB (35 / 36)
    patch_min_particles : int >= 1, patch_small_radius_voxels : float >= 0 -- the patches are
        built for RVEs of at least this many particles, or whose particles' mean radius is below
        this [voxels]. Measured (results/cell/README.md "Particle patches in the solver",
        sessions 14-15; tol 1e-6, whole homogenize_rve, one process each): the bench RVEs of
        ~2.5-voxel particles, patches against none: 13 particles at 32^3 1.8 / 1.6 s, 42 at 48^3
        9.5 / 9.1 s, 100 at 64^3 22-23 / 18-19 s (the multigrid alone needs only 23 / 37
        iterations there), 338 at 96^3 81 / 99 s, 801 at 128^3 219 / 584 s; particles of ~1.25
        voxels: 100 at 32^3 ~1.2x faster, 801 at 64^3 ~2x faster with the patches
    patch_tol_factor : float in (0, 1] -- with particle patches the CG's relative residual is
        tol x this: their exact local solves leave little residual where much error is left, so
        at the same residual the error energy is up to ~1000x the default solver's; at tol / 100
        it is at most the default's at tol in every column of three RVEs
        (results/cell/patch_stopping.json; results/cell/README.md "Particle patches in the
        solver")
    krylov : callable or None -- experiments: a block Krylov driver with the signature and
        return value of :func:`homogenize.solvers.coupled_block_cg`, used in its place for the
        "coupled" and "strains" modes (None: coupled_block_cg)
    preconditioner : callable or None -- experiments, matrix-free solver: called once after
        the setup with a :class:`types.SimpleNamespace` (``vcycle``: the default V-cycle,
        ``operator``, ``field``, ``pin``, ``h``, ``mesh``, ``deflation_space(mask)``); returns
        the preconditioner CG uses (None: the default V-cycle). The returned object must offer
        what the default does to the cell solver (``@``, ``release()``, ``levels``,
        ``interface_sweeps``)
    """

    amg: AMGOptions = AMGOptions()
    matfree_assembled_max: int = 64
    matfree_coarse: str = "amg"
    matfree_sweeps: int = 1
    matfree_interface_sweeps: int = 1
    matfree_interface_halo: int = 1
    block_cg: str = "strains"
    patch_shell_voxels: float | None = 0.5
    patch_min_particles: int = 200
    patch_small_radius_voxels: float = 2.0
    patch_tol_factor: float = 1e-2
    krylov: Callable | None = None
    preconditioner: Callable | None = None

    def __post_init__(self):
        if not isinstance(self.amg, AMGOptions):
            raise InputError(f"amg must be an AMGOptions, got {self.amg!r}")
        _int("matfree_assembled_max", self.matfree_assembled_max, 1)
        _choice("matfree_coarse", self.matfree_coarse, MATFREE_COARSE_SOLVERS)
        _int("matfree_sweeps", self.matfree_sweeps, 1)
        _int("matfree_interface_sweeps", self.matfree_interface_sweeps, 0)
        _int("matfree_interface_halo", self.matfree_interface_halo, 0)
        _choice("block_cg", self.block_cg, BLOCK_CG_MODES)
        if self.patch_shell_voxels is not None:
            _real("patch_shell_voxels", self.patch_shell_voxels, 0.0, 1e3)
        _int("patch_min_particles", self.patch_min_particles, 1)
        _real("patch_small_radius_voxels", self.patch_small_radius_voxels, 0.0, 1e3)
        _real("patch_tol_factor", self.patch_tol_factor, 0.0, 1.0, lo_open=True)
        for name in ("krylov", "preconditioner"):
            v = getattr(self, name)
            if v is not None and not callable(v):
                raise InputError(f"{name} must be callable or None, got {v!r}")

    def replace(self, **changes) -> SolverOptions:
        """A copy with ``changes`` (validated again)."""
        return dataclasses.replace(self, **changes)
