"""Periodic cell problems on a voxel mesh: effective stiffness, effective body force, magnetic stress.

Displacement ``u = E x + w`` with the fluctuation ``w`` periodic (node index mod n, see
:mod:`homogenize.voxels._assembly`) and the mean strain ``E`` prescribed. The rigid translation is
fixed by pinning one matrix node (the loads are balanced, so the pin carries no force).

* Stiffness: six unit mean strains (Voigt order 11, 22, 33, 23, 13, 12; engineering shear);
  ``C_eff`` from the energy of the solutions (variational, error ~ the squared solution error;
  the plain volume-averaged stress is kept as an error indicator).
* Magnetic case (zero mean strain): the force ``F_i`` on particle ``i`` is spread as a uniform body
  force over its voxels; ``f_eff = sum F_i / V`` is balanced by the uniform counter-load ``-f_eff``
  (on the macro scale it is carried by the macroscopic stress gradient). The macroscopic stress at
  zero macroscopic strain (Hill-Mandel / virtual work with the unit-strain fields) is

      stress_mag = <sigma(w_mag)> - (1/V) sym( int x (x) b dV ),

  the mean FE stress plus the first moment of the applied forces. For pair forces the second
  term is exactly the virial ``-(1/V) sum_pairs r_ij (x) F_ij``; in a homogeneous matrix the first
  term vanishes identically, and stiff inclusions add a correction of relative order
  ``(a / r)^3``. Because net forces on particles of a PERIODIC system do not tell which image a
  partner sits at, pass the dipole solver's pairwise ``virial_stress_Pa`` when you have it; it
  replaces the first-moment term (whose cell-cut choice is then irrelevant). Its elastic part
  is variational in the strain and magnetic solutions (error = the product of their errors),
  so the magnetic column stops at :func:`magnetic_tol` (sqrt(tol)) unless its field is kept.

Solver (``solver="auto"``, the default, picks ``"matrix-free"`` on even grids of dilute RVEs, with
a particle patch on every particle beyond them and for rigid particles up to phi 0.15, and
``"fast"`` otherwise: :func:`_auto_solver`). ``solver="fast"``: all load cases in one block
(:mod:`homogenize.solvers`): lock-step CG
preconditioned by a block V-cycle on a pyamg smoothed-aggregation hierarchy (rigid-body near-nullspace, built once),
DEFLATED by the six rigid-body modes of every stiff particle. Plain AMG-CG needs ~4x more
iterations at Fe/PDMS contrast (1e5) than at contrast 1, because each stiff particle adds six
near-zero modes (its rigid motions in the soft matrix); deflation removes exactly those (Vuik,
Segal & Meijerink 1999). ``solver="matrix-free"`` replaces the assembled fine matrix and its AMG
by the matrix-free operator and geometric multigrid of :mod:`homogenize.solvers._matfree`, and couples
the six strain cases in one deflated block CG (:attr:`SolverOptions.block_cg`): every strain column
steps in the span of all their search directions; the magnetic column keeps its own recursion.
On RVEs of many or small particles (:func:`use_patches`) its V-cycle also solves every particle
with a shell of matrix exactly in the fine level (:attr:`SolverOptions.patch_shell_voxels`,
:mod:`homogenize.solvers._patches`). Every solver setting is a field of the frozen
:class:`homogenize.solvers.SolverOptions` passed as ``options=``.
"""
from __future__ import annotations

import time
import types
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from micro.common.jit import one_blas_thread
from micro.common.progress import progress_bar

from micro.common.validate import ConvergenceError, InputError, Range, check_finite
from micro.materials import FE, PDMS, POISSON_RANGE, ElasticMaterial, elastic
from micro.box import PeriodicBox

from homogenize.voxels import _assembly as asm
from homogenize.voxels import _budget
from homogenize.voxels._assembly import isotropic_voigt, laminate_voigt   # public here: the phases' stiffness
from homogenize.solvers import _matfree as mf
from homogenize.solvers._patches import ParticlePatches, patch_nodes, select_patches
from homogenize.cell._effective_media import (bulk_shear, eshelby_dilute, guth_gold, hashin_shtrikman_bounds,
                               isotropic_stiffness_voigt, lame, mori_tanaka, young_poisson)
from homogenize.voxels.mesh import METHODS, VoxelMesh, voxelize
from homogenize.solvers import (AMGOptions, BlockVCycle, BSROp, Deflation, SolverOptions, block_cg,
                      coupled_block_cg, grid_colours, grid_node_coordinates, rigid_body_modes,
                      smoothed_aggregation)
from homogenize.solvers.krylov import CG_CHUNK, block_directions, colnorms, gram
from homogenize.solvers.krylov import _pinv_spd as pinv_spd
from scipy.sparse.linalg import splu

__all__ = ["Material", "CellConfig", "homogenize_cell", "CellResult", "homogenize_rve", "homogenize_mesh", "magnetic_tol", "isotropic_projection",
           "anisotropy_index", "voigt_to_tensor", "tensor_to_voigt",
           "hashin_shtrikman_bounds", "eshelby_dilute", "mori_tanaka", "guth_gold",
           "bulk_shear", "young_poisson", "lame", "isotropic_stiffness_voigt", "FE_PDMS_CONTRAST",
           "cell_solver", "isotropic_voigt", "laminate_voigt", "CELL_RANGES"]

VOIGT = asm.VOIGT
CASES = ("e11", "e22", "e33", "g23", "g13", "g12")
FE_PDMS_CONTRAST = FE.E_Pa / PDMS.E_Pa

#: The allowed values of the cell stage's numeric settings, defined once: CellConfig,
#: homogenize_rve / homogenize_mesh, the study files' rules (homogenize.tables._study) and the
#: CLI options (``CELL_RANGES["voxels"].arg("--voxels")``) all check these objects.
#: tol: a CG residual above 1e-2 returns meaningless moduli (tol 2 gave E_eff 1600x too high),
#: below 1e-14 it is not reachable in double precision. E_Pa: from soft gels to diamond, so
#: that no stiffness contrast overflows the solver (1e300 Pa did).
CELL_RANGES = {
    "voxels": Range(4, 256, "(voxels per cube edge)", integer=True),
    "tol": Range(1e-14, 1e-2, "(relative residual)"),
    "tol_magnetic": Range(1e-14, 1e-2, "(relative residual of the magnetic column)"),
    "maxiter": Range(1, 10 ** 6, integer=True),
    "E_Pa": Range(1e2, 1e13, "Pa"),
    "nu": POISSON_RANGE,                    # micro.materials' own, that of ElasticMaterial
}


#: The elastic material of the cell problems (one class for every elastic solver).
Material = ElasticMaterial


@dataclass(frozen=True, eq=False)
class CellResult:
    """Result of :func:`homogenize_rve`. Units: Pa, N/m^3, m; strains dimensionless.

    C_eff_Pa : (6, 6) effective stiffness, Voigt order 11, 22, 33, 23, 13, 12, engineering shear
    E_eff_Pa, nu_eff, K_eff_Pa, G_eff_Pa : isotropic projection of C_eff
    anisotropy_index : universal anisotropy index A^U (0 for isotropic)
    f_eff_N_m3 : (3,) effective body force = sum of particle forces / cell volume
    stress_mag_Pa : (3, 3) macroscopic magnetic stress at zero mean strain (None without forces)
    stress_mag_elastic_Pa, stress_mag_moment_Pa : its two parts (mean FE stress, force moment)
    strain_mag : (3, 3) strain of a stress-free sample, ``-C_eff^-1 stress_mag``
    n_dof, voxels, h_m : mesh size
    phi_voxel : particle volume fraction of the stiffness field (composite voxels: the exact mean
        fraction; centre/fraction: voxels with fraction >= 0.5)
    iterations, residuals : per load case, CG iterations and final relative residual
    timings_s : seconds per stage
    settings : the solver and its settings; ``settings["solver"]`` the one that ran,
        ``"solver_requested"`` and ``"solver_reason"`` why (``solver="auto"``, memory fallback)
    """

    C_eff_Pa: np.ndarray
    E_eff_Pa: float
    nu_eff: float
    K_eff_Pa: float
    G_eff_Pa: float
    anisotropy_index: float
    f_eff_N_m3: np.ndarray
    stress_mag_Pa: np.ndarray | None
    stress_mag_elastic_Pa: np.ndarray | None
    stress_mag_moment_Pa: np.ndarray | None
    strain_mag: np.ndarray | None
    n_dof: int
    voxels: int
    h_m: float
    phi_voxel: float
    n_particles: int
    n_unresolved: int
    iterations: dict
    residuals: dict
    residual_history: dict
    timings_s: dict
    settings: dict
    mesh: VoxelMesh = field(repr=False)
    fields: dict = field(repr=False, default_factory=dict)
    #: the solutions (n_dof, k) of the load cases in ``iterations`` order (``keep_solution``):
    #: an ``initial_guess`` for a neighbouring problem
    solution: np.ndarray | None = field(repr=False, default=None)

    def summary(self) -> dict:
        """JSON-ready dictionary of the scalar and tensor results (no fields, no mesh)."""
        out = {
            "C_eff_Pa": self.C_eff_Pa, "E_eff_Pa": self.E_eff_Pa, "nu_eff": self.nu_eff,
            "K_eff_Pa": self.K_eff_Pa, "G_eff_Pa": self.G_eff_Pa,
            "anisotropy_index": self.anisotropy_index, "f_eff_N_m3": self.f_eff_N_m3,
            "stress_mag_Pa": self.stress_mag_Pa, "stress_mag_elastic_Pa": self.stress_mag_elastic_Pa,
            "stress_mag_moment_Pa": self.stress_mag_moment_Pa, "strain_mag": self.strain_mag,
            "n_dof": self.n_dof, "voxels": self.voxels, "h_m": self.h_m,
            "phi_voxel": self.phi_voxel, "n_particles": self.n_particles,
            "n_unresolved": self.n_unresolved, "iterations": self.iterations,
            "residuals": self.residuals, "timings_s": self.timings_s, "settings": self.settings,
        }
        return out


# ------------------------------------------------------------------------------------------------
# tensor helpers
# ------------------------------------------------------------------------------------------------

def voigt_to_tensor(v, engineering: bool = False) -> np.ndarray:
    """(6,) Voigt vector -> symmetric (3, 3); ``engineering`` halves the shear entries (strain)."""
    v = np.asarray(v, dtype=float)
    T = np.zeros((3, 3))
    for a, (r, c) in enumerate(VOIGT):
        val = v[a] / 2.0 if (engineering and r != c) else v[a]
        T[r, c] = T[c, r] = val
    return T


def tensor_to_voigt(T, engineering: bool = False) -> np.ndarray:
    """Symmetric (3, 3) -> (6,) Voigt; ``engineering`` doubles the shear entries (strain)."""
    T = np.asarray(T, dtype=float)
    return np.array([T[r, c] * (2.0 if (engineering and r != c) else 1.0) for r, c in VOIGT])


def isotropic_projection(C) -> tuple[float, float, float, float]:
    """Closest isotropic stiffness (Voigt-average formulas): (E, nu, K, G) [Pa, 1, Pa, Pa]."""
    C = np.asarray(C, dtype=float)
    K = (C[0, 0] + C[1, 1] + C[2, 2] + 2.0 * (C[0, 1] + C[0, 2] + C[1, 2])) / 9.0
    G = ((C[0, 0] + C[1, 1] + C[2, 2]) - (C[0, 1] + C[0, 2] + C[1, 2])
         + 3.0 * (C[3, 3] + C[4, 4] + C[5, 5])) / 15.0
    E, nu = young_poisson(K, G)
    return float(E), float(nu), float(K), float(G)


def anisotropy_index(C) -> float:
    """Universal anisotropy index ``A^U = 5 G_V / G_R + K_V / K_R - 6`` (Ranganathan & Ostoja-
    Starzewski 2008): 0 for an isotropic stiffness, > 0 otherwise."""
    C = np.asarray(C, dtype=float)
    S = np.linalg.inv(C)
    _, _, KV, GV = isotropic_projection(C)
    KR = 1.0 / (S[0, 0] + S[1, 1] + S[2, 2] + 2.0 * (S[0, 1] + S[0, 2] + S[1, 2]))
    GR = 15.0 / (4.0 * (S[0, 0] + S[1, 1] + S[2, 2]) - 4.0 * (S[0, 1] + S[0, 2] + S[1, 2])
                 + 3.0 * (S[3, 3] + S[4, 4] + S[5, 5]))
    return float(5.0 * GV / GR + KV / KR - 6.0)


# ------------------------------------------------------------------------------------------------
# the solver
# ------------------------------------------------------------------------------------------------

class _CellSolver:
    """Stiffness matrix, AMG hierarchy and particle deflation space of one voxel mesh.

    ``solver="fast"``: numba assembly; pyamg smoothed aggregation with a strength threshold (see
    :class:`homogenize.solvers.AMGOptions`) and our block V-cycle (multicolour Gauss-Seidel on
    every level, all load cases in one block). ``solver="reference"``: the independent path -- BLAS assembly,
    pyamg's default hierarchy and its own V-cycle, scipy products, one load case after another.
    """

    def __init__(self, mesh: VoxelMesh, lam, mu, *, deflate: bool, stiff_mask, tol: float,
                 maxiter: int, solver: str = "fast", composite: _Composite | None = None,
                 options: SolverOptions | None = None, rigid: bool = False,
                 every_particle: bool = False):
        if solver not in SOLVERS:
            raise InputError(f"solver must be one of {SOLVERS}, got {solver!r}")
        if solver == "auto":
            phi, plain = float(mesh.fraction.mean()), _plain_particles(mesh, _options(options), rigid)
            solver = _auto_solver(mesh.n, phi, plain, rigid)[0]
            every_particle = every_particle or (solver == "matrix-free"
                                                and _auto_patches_every_particle(phi, plain, rigid))
        self.options = _options(options)
        # a particle patch on every particle (rigid ones always), not only where use_patches says
        self.every_particle = bool(rigid or every_particle)
        self.mesh, self.lam, self.mu = mesh, lam, mu
        self.n, self.h = mesh.n, mesh.h_m
        self.tol, self.maxiter = tol, maxiter
        self.kind = solver
        if solver == "matrix-free":
            self._init_matrix_free(lam, mu, composite, stiff_mask if deflate else None)
            return
        fast = solver == "fast"
        t = {}
        t0 = time.perf_counter()
        K = asm.assemble_bsr(lam, mu, self.h, method="numba" if fast else "blas")
        if composite is not None:
            composite.add_to(K)
        t["assembly"] = time.perf_counter() - t0
        # pin one node surrounded by matrix voxels only (rigid translation; loads are balanced)
        soft = (mu <= mu.min() * (1.0 + 1e-12))
        if composite is not None:
            soft &= ~composite.mask
        node_soft = np.all(asm.node_coefficients(soft.astype(np.float64)) > 0.5, axis=1)
        cand = np.flatnonzero(node_soft)
        self.pin = int(cand[0]) if cand.size else 0
        ptr, ind = K.indptr, K.indices
        K.data[ind == self.pin] = 0.0
        K.data[ptr[self.pin]:ptr[self.pin + 1]] = 0.0
        diag_scale = float(np.mean(K.diagonal()))
        row = np.arange(ptr[self.pin], ptr[self.pin + 1])
        K.data[row[ind[row] == self.pin][0]] = diag_scale * np.eye(3)
        self.K = K
        t0 = time.perf_counter()
        B = rigid_body_modes(grid_node_coordinates(self.n))
        if fast:
            # coarsest level: up to 4000 unknowns on large grids (solved exactly, a dense
            # Cholesky; measured at 64^3: 17-18 CG iterations against 26-29 with 500), few
            # enough on small grids that the V-cycle stays a multigrid cycle
            opts = self.options.amg
            if opts.max_coarse is None:
                opts = opts.replace(max_coarse=max(300, min(4000, K.shape[0] // 20)))
            self.ml = smoothed_aggregation(K, B, opts)
            self.M = BlockVCycle(self.ml, fine_colours=grid_colours(self.n))
            self.matvec = BSROp(K)
        else:
            # pyamg's own hierarchy, with the project's repeatable smoother weights
            self.ml = smoothed_aggregation(K, B, _REFERENCE_AMG)
            pre = self.ml.aspreconditioner(cycle="V")
            self.M = lambda R: np.stack([pre @ R[:, c] for c in range(R.shape[1])], axis=1)
            self.matvec = K.__matmul__
        t["amg_setup"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.Z = self._deflation_space(stiff_mask) if deflate else None
        self.deflation = self._deflation(K @ self.Z if self.Z is not None else None)
        t["deflation_setup"] = time.perf_counter() - t0
        self.timings = t

    def _init_matrix_free(self, lam, mu, composite, stiff_mask):
        """``solver="matrix-free"``: stencil-row operator, geometric multigrid down to the
        assembled (n/2)^3 (or coarser) grid with pyamg below it (:mod:`homogenize.solvers._matfree`)."""
        n = self.n
        if n % 2 or n < 8:
            raise InputError(f"solver='matrix-free' needs an even number of voxels >= 8 per edge "
                             f"(geometric multigrid), got voxels={n}")
        t = {}
        t0 = time.perf_counter()
        field = mf.element_field(lam, mu, self.h, composite)
        t["assembly"] = time.perf_counter() - t0
        # the pin: a node surrounded by matrix voxels only, at coordinates divisible by the
        # coarsening factor of every matrix-free level (so it is a node of each coarse grid)
        o = self.options
        levels = 1
        nc = n // 2
        while nc > o.matfree_assembled_max and nc % 2 == 0 and nc >= 16:
            levels, nc = levels + 1, nc // 2
        step = 2 ** levels
        soft = (mu <= mu.min() * (1.0 + 1e-12))
        if composite is not None:
            soft &= ~composite.mask
        good = np.ones((n, n, n), dtype=bool)
        for ax, ay, az in asm.CORNERS:
            good &= np.roll(soft, shift=(az, ay, ax), axis=(0, 1, 2))
        lat = np.zeros((n, n, n), dtype=bool)
        lat[::step, ::step, ::step] = True
        cand = np.flatnonzero((good & lat).reshape(-1))
        self.pin = int(cand[0]) if cand.size else 0
        t0 = time.perf_counter()
        op = mf.MatFreeOperator(field, self.pin)
        t["amg_setup"] = time.perf_counter() - t0
        # the deflation space first (its K Z needs the element field), then the hierarchy (the
        # last user of the field, freed before the patches' factors come)
        t0 = time.perf_counter()
        self.Z = self._deflation_space(stiff_mask) if stiff_mask is not None else None
        self.deflation = self._deflation(
            mf.stiffness_times_sparse(field, self.Z, pin=self.pin) if self.Z is not None else None)
        t["deflation_setup"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.M = mf.GeometricVCycle(field, pin=self.pin, pin_scale=op.pin_scale, h=self.h,
                                    amg_options=o.amg, fine_op=op,
                                    assembled_max=o.matfree_assembled_max,
                                    coarse=o.matfree_coarse, sweeps=o.matfree_sweeps,
                                    interface_sweeps=o.matfree_interface_sweeps,
                                    interface_halo=o.matfree_interface_halo)
        self.ml = self.M.ml
        self.matvec = op
        self.K = None
        t["amg_setup"] += time.perf_counter() - t0
        if o.preconditioner is None:
            del field
        if use_patches(self.mesh.n_particles, self.mesh.radii_m / self.h, o,
                       self.every_particle):
            # after the hierarchy: its setup's temporaries are gone before the factors come
            t0 = time.perf_counter()
            self.M.patches = ParticlePatches(op, self.mesh.centers_m / self.h,
                                             self.mesh.radii_m / self.h, o.patch_shell_voxels)
            t["patch_setup"] = time.perf_counter() - t0
        self.timings = {k: t[k] for k in ("assembly", "amg_setup", "patch_setup",
                                          "deflation_setup") if k in t}
        if o.preconditioner is not None:      # an experiment's own preconditioner
            self.M = o.preconditioner(types.SimpleNamespace(
                vcycle=self.M, operator=op, field=field, pin=self.pin, h=self.h, mesh=self.mesh,
                deflation_space=self._deflation_space))

    def _deflation(self, KZ):
        """The deflated CG's coarse space (:class:`homogenize.solvers.Deflation`) from ``self.Z``
        and ``KZ = K Z`` (None without deflation)."""
        if self.Z is None:
            return None
        KZ = sp.csc_matrix(KZ)
        return Deflation(self.Z, KZ, splu((self.Z.T @ KZ).tocsc()).solve)

    def _deflation_space(self, stiff_mask):
        """Rigid-body modes (3 translations, 3 rotations) of every stiff particle, at the nodes of
        its voxels, as a sparse (3N, 6 P) matrix. Rotations about the particle centre, scaled by
        the radius so all columns are O(1)."""
        mesh, n, h = self.mesh, self.n, self.h
        owner = np.where(stiff_mask, mesh.owner, -1)
        parts = np.unique(owner[owner >= 0])
        if parts.size == 0:
            return None
        rows, cols, vals = [], [], []
        vox = np.argwhere(owner >= 0)                       # (m, 3) as (k, j, i)
        pid = owner[owner >= 0]
        col_of = {p: c for c, p in enumerate(parts)}
        nodes_all, pid_all = [], []
        for ax, ay, az in asm.CORNERS:
            k, j, i = vox[:, 0] + az, vox[:, 1] + ay, vox[:, 2] + ax
            nodes_all.append(np.stack([i, j, k], axis=1))    # unwrapped node (i, j, k)
            pid_all.append(pid)
        nodes = np.concatenate(nodes_all)
        pids = np.concatenate(pid_all)
        flat = (nodes[:, 0] % n) + n * ((nodes[:, 1] % n) + n * (nodes[:, 2] % n))
        # each node belongs to ONE body (touching particles: the first owner), so that the rigid
        # motions of a cluster of touching particles lie in the span of the particle modes
        _, first = np.unique(flat, return_index=True)
        nodes, pids, flat = nodes[first], pids[first], flat[first]
        keep = flat != self.pin
        nodes, pids, flat = nodes[keep], pids[keep], flat[keep]
        c = mesh.centers_m[pids]
        x = nodes * h
        d = x - c
        d = PeriodicBox(mesh.box_m).minimum_image(d)   # unwrap around the particle centre
        d /= mesh.radii_m[pids][:, None]
        pc = np.array([col_of[p] for p in pids], dtype=np.int64) if pids.size else pids
        base = 6 * pc
        B = rigid_body_modes(d).reshape(-1, 3, 6)
        # the nonzero (component, mode) pairs: translations, then the rotations about x, y, z
        for comp, col in ((0, 0), (1, 1), (2, 2), (1, 3), (2, 3), (0, 4), (2, 4), (0, 5), (1, 5)):
            rows.append(3 * flat + comp); cols.append(base + col); vals.append(B[:, comp, col])
        Z = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(3 * n ** 3, 6 * parts.size))
        return Z

    # one BLAS thread while the numba kernels run the iterations on all cores: the BLAS calls
    # in the loop are small (the coarsest level's dense Cholesky solve, the block's Gram
    # matrices)
    @one_blas_thread
    def solve(self, F: np.ndarray, callback=None, tols=None, magnetic: bool = False, x0=None):
        """Solve K W = F (pinned node) for the columns of F (n_dof, k), deflated AMG-CG.

        ``tols``: one relative residual per column (default: the solver's ``tol`` for all).
        Returns (W, histories): zero-mean periodic fluctuations and the relative residual history
        of every column. The fast path solves all columns in one block; the reference path one
        after another. ``magnetic``: the last column is the magnetic load (its own group of the
        block CG with ``SolverOptions.block_cg = "strains"``). ``x0``: an initial guess
        (n_dof, m), e.g. the solutions of a neighbouring problem (the previous field step of
        :func:`homogenize.cell.relax.relax`); the start of every column is the better (smaller
        residual) of its own column of ``x0`` (if m = k) and the combination of all columns of
        ``x0`` of least energy error (Galerkin, :meth:`initial_guess`); None: the usual start.
        """
        # the pinned node's rows are zeroed in F itself for the solve and restored after it (no
        # copy of the load block: one block of memory less at 128^3)
        if not (isinstance(F, np.ndarray) and F.dtype == np.float64 and F.flags.c_contiguous
                and F.flags.writeable):
            F = np.array(F, dtype=np.float64, order="C")
        rows = slice(3 * self.pin, 3 * self.pin + 3)
        pinned = F[rows].copy()
        F[rows] = 0.0
        tols = [self.tol] * F.shape[1] if tols is None else list(tols)
        X0 = None if x0 is None else self.initial_guess(F, x0)
        try:
            if self.kind == "reference":
                cols = [block_cg(self.matvec, self.M, F[:, [c]], tol=tols[c],
                                 maxiter=self.maxiter, deflation=self.deflation, callback=callback,
                                 x0=None if X0 is None else X0[:, [c]])
                        for c in range(F.shape[1])]
                W = np.concatenate([c[0] for c in cols], axis=1)
                hist = [c[1][0] for c in cols]
            else:
                mode = self.options.block_cg if self.kind == "matrix-free" else "independent"
                self.block_cg = mode
                kw = dict(tol=tols, maxiter=self.maxiter, deflation=self.deflation,
                          callback=callback)
                if X0 is not None:       # (an experiment's options.krylov need not take x0)
                    kw["x0"] = X0
                if mode == "independent":
                    W, hist = block_cg(self.matvec, self.M, F, **kw)
                else:
                    k = F.shape[1]
                    groups = ([0] * (k - 1) + [1] if mode == "strains" and magnetic
                              else [0] * k)
                    krylov = self.options.krylov or coupled_block_cg
                    W, hist = krylov(self.matvec, self.M, F, groups=groups, **kw)
        finally:
            F[rows] = pinned
        if self.kind == "matrix-free":
            self.M.release()
        W[3 * self.pin:3 * self.pin + 3] = 0.0
        Wn = W.reshape(-1, 3, W.shape[1])
        Wn -= Wn.mean(axis=0)     # zero-mean fluctuation (the pin only fixed the translation)
        return W, hist

    def initial_guess(self, F: np.ndarray, x0) -> np.ndarray:
        """The start of :meth:`solve` from the guess ``x0`` (n_dof, m) for the loads F (n_dof, k)
        (pinned rows zero): ``x0`` translated so that the pinned node is at rest (translations
        cost no energy), then per column the better of its own guess (m = k) and the Galerkin
        combination ``x0 (x0^T K x0)^+ x0^T f``, by the residual norm. Reductions with the
        deterministic chunked kernels (independent of the thread count)."""
        X = np.array(x0, dtype=np.float64, order="C")
        if X.ndim != 2 or X.shape[0] != F.shape[0]:
            raise InputError(f"initial guess must have shape ({F.shape[0]}, m), got {X.shape}")
        Xn = X.reshape(-1, 3, X.shape[1])
        Xn -= Xn[self.pin].copy()
        KX = np.ascontiguousarray(self.matvec(X))
        G = gram(X, KX)
        coef = np.ascontiguousarray(pinv_spd(G) @ gram(X, F))
        # X0 = X coef and R = F - K X coef, row by row (numba: the same sums on any thread count)
        X0 = np.empty(F.shape)
        block_directions(X, np.zeros(F.shape), coef, CG_CHUNK, X0)
        R = np.empty(F.shape)
        block_directions(KX, np.ascontiguousarray(F), np.ascontiguousarray(-coef), CG_CHUNK, R)
        if X.shape[1] == F.shape[1]:
            own = np.ascontiguousarray(F - KX)
            mine = colnorms(own) < colnorms(R)
            X0[:, mine] = X[:, mine]
        return X0

    def energy_products(self, U: np.ndarray, V: np.ndarray) -> np.ndarray:
        """U^T K V with the periodic stiffness (singular: rigid translations), (k_U, k_V) [N m].

        Both sides are first translated so that the pinned node is at rest; translations do not
        change the energy of the periodic K, and on such vectors the pinned matrix equals K.
        """
        def at_rest(X):
            Xn = X.reshape(-1, 3, X.shape[1])
            return np.ascontiguousarray((Xn - Xn[self.pin]).reshape(X.shape))
        return at_rest(U).T @ self.matvec(at_rest(V))


SOLVERS = ("auto", "fast", "reference", "matrix-free")
#: what ``solver="auto"`` (the default) picks on even grids of dilute RVEs: the matrix-free
#: geometric multigrid, with as many CG iterations as "fast" there (strains 16-18 at 32^3, phi
#: 0.01-0.05), cheaper ones and half the memory (the "cell/solver choice ..." records of
#: results/bench/cell.json: 16^3-64^3, phi 0.01-0.3, monodisperse and lognormal radii, same
#: RVE and tolerance; results/cell/README.md "Solver choice")
AUTO_SOLVER = "matrix-free"
#: ... up to this particle volume fraction of the mesh; above it "auto" picks "fast": dense
#: stiff particles defeat the trilinear coarse grid of the geometric multigrid (strain /
#: magnetic CG iterations, matrix-free against fast, particles of ~2.5 voxels: 24^3 phi 0.15
#: 28 / 58 against 16 / 15, phi 0.2 45 / 126 against 35 / 36, 32^3 phi 0.3 104 / 181-200
#: against 29-45 / 30-49; rigid particles at phi 0.1, the relaxation bench RVE at 48^3 (100
#: particles of 6.4 voxels): 53 / 186 against 22 / 55); measured alike up to phi 0.05
AUTO_MAX_PHI = 0.06
#: ... and with at most this many particles unless the matrix-free solver builds particle
#: patches for them (:func:`use_patches`: >= 200 particles or small ones): without patches
#: its iterations grow with the number of particles (64^3, phi 0.05, particles of ~2.5 voxels:
#: 100 lognormal 23 / 37 against 18 / 33 for "fast", 143 lognormal 55 / 130 against 39 / 40;
#: 200 monodisperse with patches 25 / 40 against 37 / 40)
AUTO_MAX_PLAIN_PARTICLES = 100
#: ... and above those (phi > AUTO_MAX_PHI, or more particles without patches), and for rigid
#: particles (``rigid=True``, the relaxed RVEs of :func:`homogenize.cell.relax.relax`) always,
#: "auto" picks the matrix-free solver with a particle patch on EVERY particle (each particle
#: and its shell of matrix solved exactly in the fine level) up to this particle volume
#: fraction, "fast" above it (and for rigid particles where one gets no patch). Measured on the
#: idle machine, fast / matrix-free with patches on every particle: the solver-choice records
#: of results/bench/cell.json (Fe, 6 strains + random forces, each run in its own process) 64^3
#: phi 0.05 lognormal (143 particles) 1.8x (25/37 iterations against 39/40; without patches
#: 55/130), phi 0.1 2.5x / 1.4x, 32^3 phi 0.1 3.2x / 2.9x; results/cell/rigid_solver_choice.json
#: (as-placed RVEs, dipole forces at 0.6 T, cold start) rigid 1.8-5.5x up to phi 0.1 (48^3 phi
#: 0.1: 25/56 against 14/42 iterations), Fe 1.4-4x; at phi 0.2 0.97x rigid / 0.88x Fe; at
#: phi 0.3 even or better in time but with 2-6x the iterations (32^3: 115/344 against 50/86
#: rigid), so "fast" keeps phi > 0.15. C_eff of the solvers within 6e-6 (rigid) / 1e-6 (Fe).
AUTO_MAX_PHI_PATCHED = 0.15
#: the smoothed aggregation of ``solver="reference"``: pyamg's own hierarchy (default strength
#: and candidate smoothing), the project's repeatable smoother, sparse LU on <= 300 unknowns
_REFERENCE_AMG = AMGOptions(strength_theta=None, improve_candidates=True, coarse_solver="splu",
                            max_coarse=300)


def _options(options) -> SolverOptions:
    if options is None:
        return SolverOptions()
    if not isinstance(options, SolverOptions):
        raise InputError(f"options must be a homogenize.solvers.SolverOptions, got {options!r}")
    return options


def magnetic_tol(tol: float) -> float:
    """Relative residual at which the magnetic column stops when only its mean stress is wanted.

    The elastic magnetic stress is computed variationally with the six unit-strain solutions
    (:func:`homogenize_mesh`): its error is the energy product ``e_a . K e_m / V`` of the strain
    and magnetic solution errors, so the magnetic column needs about the square root of the
    strain columns' residual for a stress error far below the effective stiffness's
    (results/cell/README.md, "Magnetic column tolerance": at the default 1e-6, stopping it at
    1e-3 changes the elastic magnetic stress by 8e-9 to 8e-6 of itself on 32^3 and 64^3 bench
    RVEs, results/cell/magnetic_tolerance.json). Never tighter than ``tol`` (tol <= 1e-2), never looser than 1e-2."""
    return float(min(np.sqrt(tol), 1e-2))


def _plain_particles(mesh: VoxelMesh, options: SolverOptions, rigid: bool = False) -> int:
    """The particles the matrix-free solver would face without patches: 0 where it builds
    them (:func:`use_patches`), else all of the mesh's. ``rigid``: the particles left without
    one where it builds them (too many nodes or beyond the factors' memory share,
    :func:`homogenize.solvers._patches.select_patches`)."""
    o = _options(options)
    if not use_patches(mesh.n_particles, mesh.radii_m / mesh.h_m, o, rigid):
        return int(mesh.n_particles)
    if not rigid:
        return 0
    ptr, _ = patch_nodes(mesh.centers_m / mesh.h_m, mesh.radii_m / mesh.h_m, mesh.n,
                         o.patch_shell_voxels)
    return int(mesh.n_particles - select_patches(ptr, mesh.n ** 3).size)


def use_patches(n_particles: int, radii_voxels, options: SolverOptions | None = None,
                every_particle: bool = False) -> bool:
    """Whether the matrix-free solver builds particle patches for an RVE of ``n_particles``
    particles of radii ``radii_voxels`` [voxels] (``options``, default
    :class:`homogenize.solvers.SolverOptions`: ``patch_shell_voxels``, ``patch_min_particles``,
    ``patch_small_radius_voxels``); ``every_particle`` (rigid particles, and "auto" beyond the
    plain matrix-free range: :data:`AUTO_MAX_PHI_PATCHED`): always, while
    ``patch_shell_voxels`` is set."""
    o = _options(options)
    if o.patch_shell_voxels is None or n_particles == 0:
        return False
    return (every_particle or n_particles >= o.patch_min_particles
            or float(np.mean(radii_voxels)) < o.patch_small_radius_voxels)


def _matfree_grid(voxels: int) -> bool:
    """Whether the matrix-free solver's geometric multigrid runs on ``voxels`` per edge."""
    return voxels % 2 == 0 and voxels >= 8


def _auto_patches_every_particle(phi: float, plain_particles: int, rigid: bool) -> bool:
    """Whether "auto"'s matrix-free solver puts a particle patch on every particle (rather than
    where :func:`use_patches` says): rigid particles always, and RVEs beyond the plain
    matrix-free range (phi > :data:`AUTO_MAX_PHI` or more than
    :data:`AUTO_MAX_PLAIN_PARTICLES` particles without patches)."""
    return bool(rigid or phi > AUTO_MAX_PHI or plain_particles > AUTO_MAX_PLAIN_PARTICLES)


def _auto_solver(voxels: int, phi: float, plain_particles: int = 0,
                 rigid: bool = False) -> tuple[str, str]:
    """``solver="auto"``: (solver, reason) for a grid of ``voxels`` per edge whose particle
    volume fraction is ``phi``, with ``plain_particles`` particles the matrix-free solver would
    face without patches (0 where it builds them; rigid particles: those too large for one),
    before memory (:data:`AUTO_SOLVER`, :data:`AUTO_MAX_PHI`, :data:`AUTO_MAX_PLAIN_PARTICLES`,
    :data:`AUTO_MAX_PHI_PATCHED`; :func:`_auto_patches_every_particle`)."""
    if not _matfree_grid(voxels):
        return "fast", (f"auto: fast, voxels={voxels} is odd or below 8 (the matrix-free "
                        f"geometric multigrid needs an even voxel count >= 8)")
    if rigid and plain_particles:
        return "fast", (f"auto: fast, {plain_particles} rigid particles without a particle "
                        f"patch (too large, or beyond the factors' memory share; the "
                        f"matrix-free multigrid needs one on every rigid particle, "
                        f"homogenize.cell.problem.AUTO_MAX_PHI_PATCHED)")
    if not _auto_patches_every_particle(phi, plain_particles, rigid):
        return AUTO_SOLVER, (f"auto: matrix-free, even grid, particle volume fraction "
                             f"{phi:.3g} <= {AUTO_MAX_PHI:g}, particles with patches or at most "
                             f"{AUTO_MAX_PLAIN_PARTICLES} (measured as fast or faster than "
                             f"'fast' with less memory, results/bench/cell.json, solver choice)")
    if phi > AUTO_MAX_PHI_PATCHED:
        return "fast", (f"auto: fast, particle volume fraction {phi:.3g} > "
                        f"{AUTO_MAX_PHI_PATCHED:g} (dense stiff particles: the matrix-free "
                        f"multigrid needs many more iterations even with particle patches, "
                        f"results/bench/cell.json, solver choice; "
                        f"homogenize.cell.problem.AUTO_MAX_PHI_PATCHED)")
    why = ("rigid particles" if rigid else
           f"particle volume fraction {phi:.3g} > {AUTO_MAX_PHI:g}" if phi > AUTO_MAX_PHI else
           f"{plain_particles} particles > {AUTO_MAX_PLAIN_PARTICLES} without patches")
    return AUTO_SOLVER, (f"auto: matrix-free with a patch on every particle, {why}, volume "
                         f"fraction <= {AUTO_MAX_PHI_PATCHED:g} (measured 1.4-5.5x faster than "
                         f"'fast', homogenize.cell.problem.AUTO_MAX_PHI_PATCHED)")


def _choose_solver(solver: str, voxels: int, n_cases: int, reason: bool = False,
                   phi: float | None = None, plain_particles: int = 0, rigid: bool = False):
    """Validate ``solver``, resolve ``"auto"`` (:func:`_auto_solver`, with the mesh's particle
    volume fraction ``phi``) and refuse a grid whose memory estimate exceeds the machine (before
    allocating). ``"fast"`` falls back to ``"matrix-free"`` when the assembled matrix does not
    fit but the matrix-free solver does (even voxel counts). Returns the solver, or (solver,
    reason) with ``reason=True``: why this one (recorded in the result's
    ``settings["solver_reason"]``). ``"auto"`` without ``phi`` (before the mesh exists, e.g.
    the command line's memory check) stays ``"auto"`` when both solvers fit the memory
    (checked against the larger estimate), else becomes the one that fits."""
    if solver not in SOLVERS:
        raise InputError(f"solver must be one of {SOLVERS}, got {solver!r}")
    why = "requested"
    if solver == "auto" and phi is None:
        if not _matfree_grid(voxels):
            solver, why = _auto_solver(voxels, 0.0)
        else:
            try:
                _budget.check_cell_memory(voxels, "fast", n_cases)
            except InputError:
                solver, why = "matrix-free", "auto: only matrix-free fits the memory"
            else:
                return ("auto", "auto: resolved on the mesh") if reason else "auto"
    if solver == "auto":
        solver, why = _auto_solver(voxels, phi, plain_particles, rigid)
    share = _budget.MEMORY_SHARE * _budget.machine_memory_bytes()
    if (solver == "fast" and _matfree_grid(voxels)
            and _budget.cell_memory_bytes(voxels, "fast", n_cases) > share
            and _budget.cell_memory_bytes(voxels, "matrix-free", n_cases) <= share):
        solver, why = "matrix-free", (f"{why}; the assembled matrix of 'fast' does not fit in "
                                      f"memory, matrix-free does")
    _budget.check_cell_memory(voxels, solver, n_cases)
    return (solver, why) if reason else solver


def _material_fields(mesh: VoxelMesh, matrix: Material, particle: Material):
    lm, mm = matrix.lame_Pa
    lp, mp = particle.lame_Pa
    # stiffness by majority phase: mixing the stiffness of mixed voxels (Voigt) turns a voxel with
    # 10 % Fe into a rigid one at Fe/PDMS contrast and doubled the stiffening of a dilute sphere;
    # the volume fractions of method="fraction" weight the particle forces instead.
    f = (mesh.fraction >= 0.5).astype(np.float64)
    return (1.0 - f) * lm + f * lp, (1.0 - f) * mm + f * mp


class _Composite:
    """Cut voxels (0 < fraction < 1) of a ``method="composite"`` or ``"laminate"`` mesh.

    ``"composite"``: the Reuss (harmonic) average of particle and matrix stiffness at the exact
    volume fraction. ``"laminate"``: the rank-one laminate along the sphere normal (Kabel,
    Merkert & Schneider 2015: Voigt in the tangential strains, Reuss in the normal tractions).
    Both on the same SRI element as the pure voxels (:func:`asm.anisotropic_element_matrices`).
    Measured against Eshelby, Mori-Tanaka and conforming P2 meshes (results/cell/): with nodal
    trilinear elements the laminate's tangential Voigt stiffness makes every cut voxel rigid at
    Fe/PDMS contrast (a thin Fe cap stiffens the whole voxel through its nodes), overshooting the
    dilute shear coefficient by 80 % at 8.6 voxels per diameter; the Reuss voxel converges to
    within 2 %. The isotropic fields carry the matrix in the cut voxels; this object adds the
    difference (cut-voxel element - matrix element) to the stiffness matrix, the affine loads and
    the affine energy, in chunks of voxels.
    """

    CHUNK = 16384

    def __init__(self, mesh: VoxelMesh, matrix: Material, particle: Material, lam, mu):
        f = mesh.fraction.reshape(-1)
        self.mask = (mesh.fraction > 0.0) & (mesh.fraction < 1.0)
        self.vox = np.flatnonzero(self.mask.reshape(-1))
        Cm = asm.isotropic_voigt(*matrix.lame_Pa)
        Cp = asm.isotropic_voigt(*particle.lame_Pa)
        fv = f[self.vox]
        if mesh.method == "laminate":
            self.C = asm.laminate_voigt(Cp, Cm, fv, mesh.normal.reshape(-1, 3)[self.vox])
        else:
            w = fv[:, None, None]
            self.C = np.linalg.inv(w * np.linalg.inv(Cp) + (1.0 - w) * np.linalg.inv(Cm))
        self.Cbase = asm.isotropic_voigt(lam.reshape(-1)[self.vox], mu.reshape(-1)[self.vox])
        self.n, self.h = mesh.n, mesh.h_m

    def _chunks(self):
        for s in range(0, self.vox.size, self.CHUNK):
            sl = slice(s, s + self.CHUNK)
            Ke = (asm.anisotropic_element_matrices(self.C[sl], self.h)
                  - asm.anisotropic_element_matrices(self.Cbase[sl], self.h))
            yield sl, Ke

    def add_to(self, K) -> None:
        for sl, Ke in self._chunks():
            asm.add_voxel_matrices(K, self.n, self.vox[sl], Ke)

    def loads(self, Es) -> list[np.ndarray]:
        """Extra right-hand sides ``-dK (E x)`` for the mean strains Es."""
        ues = [(asm._corner_coords(self.h) @ E.T).ravel() for E in Es]
        out = [np.zeros(3 * self.n ** 3) for _ in Es]
        for sl, Ke in self._chunks():
            for o, ue in zip(out, ues):
                o += asm.voxel_matrix_load(self.n, self.vox[sl], Ke, ue)
        return out

    def energy(self, Ea, Eb) -> float:
        """Extra ``mean(E_a : (C - C_base) : E_b)`` over all voxels [Pa]."""
        a = tensor_to_voigt(Ea, engineering=True)
        b = tensor_to_voigt(Eb, engineering=True)
        return float(np.einsum("i,mij,j->", a, self.C - self.Cbase, b)) / self.n ** 3


def _composite_fields(mesh: VoxelMesh, matrix: Material, particle: Material):
    """(lam, mu, composite): particle only in voxels entirely inside a particle, matrix elsewhere;
    the cut voxels' laminates in ``composite``."""
    lm, mm = matrix.lame_Pa
    lp, mp = particle.lame_Pa
    full = (mesh.fraction >= 1.0).astype(np.float64)
    lam, mu = (1.0 - full) * lm + full * lp, (1.0 - full) * mm + full * mp
    return lam, mu, _Composite(mesh, matrix, particle, lam, mu)


def cell_solver(mesh: VoxelMesh, *, matrix: Material = elastic(PDMS),
                particle: Material = elastic(FE), tol: float = 1e-6, maxiter: int = 2000,
                solver: str = "auto", options: SolverOptions | None = None):
    """The solver :func:`homogenize_mesh` builds for ``mesh`` (its phases' fields, the composite
    voxels' laminates, the stiff particles' rigid modes deflated), for experiments on the solver
    itself: ``.matvec`` is the stiffness operator, ``.M`` the preconditioner (the matrix-free
    solver's :class:`homogenize.solvers.matfree.GeometricVCycle`, or the one that
    ``options.preconditioner`` makes), ``.solve(F)`` the deflated block CG on load columns F."""
    options = _options(options)
    composite = None
    if mesh.method in ("composite", "laminate"):
        lam, mu, composite = _composite_fields(mesh, matrix, particle)
    else:
        lam, mu = _material_fields(mesh, matrix, particle)
    return _CellSolver(mesh, lam, mu, deflate=particle.E_Pa > 10.0 * matrix.E_Pa,
                       stiff_mask=mesh.fraction >= 0.5, tol=tol, maxiter=maxiter, solver=solver,
                       composite=composite, options=options)


def _force_density(mesh: VoxelMesh, forces_N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body force per voxel [N/m^3], shape (n, n, n, 3), and first moment sum x (x) F [N m]."""
    n, h, L = mesh.n, mesh.h_m, mesh.box_m
    b = np.zeros((n ** 3, 3))
    moment = np.zeros((3, 3))
    ptr, vox, wts = mesh.force_ptr, mesh.force_voxels, mesh.force_weights
    centres = mesh.voxel_centres_m().reshape(-1, 3)
    for p in range(mesh.n_particles):
        sl = slice(ptr[p], ptr[p + 1])
        v, w = vox[sl], wts[sl]
        wn = w / w.sum()
        np.add.at(b, v, wn[:, None] * forces_N[p][None, :] / h ** 3)
        d = centres[v] - mesh.centers_m[p]
        d = PeriodicBox(L).minimum_image(d)   # the particle's voxels, unwrapped around its centre
        xbar = mesh.centers_m[p] + wn @ d
        moment += np.outer(xbar - 0.5 * L, forces_N[p])
    f_eff = forces_N.sum(axis=0) / L ** 3
    b -= f_eff                            # uniform counter-load: zero net force on the cell
    # (its first moment about the cell centre is zero, so `moment` is already the full moment)
    return b.reshape(n, n, n, 3), moment


def homogenize_mesh(mesh: VoxelMesh, *, forces_N=None, virial_stress_Pa=None,
                    matrix: Material = elastic(PDMS), particle: Material = elastic(FE),
                    rigid: bool = False, deflate: bool = True, tol: float = 1e-6,
                    maxiter: int = 2000, keep_fields: bool = False, cases=CASES,
                    progress: bool = False, solver: str = "auto",
                    tol_magnetic: float | None = None,
                    options: SolverOptions | None = None, initial_guess=None,
                    keep_solution: bool = False) -> CellResult:
    """Solve the periodic cell problems on a prepared voxel mesh. See :func:`homogenize_rve`.

    ``tol_magnetic``: relative residual of the magnetic column, in [1e-14, 1e-2]; default
    :func:`magnetic_tol` of ``tol`` where only its variational stress is used (all six strain
    cases, no fields kept), else ``tol``.

    ``initial_guess``: (n_dof, m) displacement fluctuations to start the CG from (warm start),
    e.g. the ``solution`` of the same cell problems on a slightly different mesh (the previous
    field step of :func:`homogenize.cell.relax.relax`); each load case starts from the better of its
    own column (m = number of load cases) and the least-energy-error combination of all columns
    (:meth:`_CellSolver.initial_guess`). Same stopping rule (relative residual against the
    load), so the results agree with a cold start to the solver tolerance.
    ``keep_solution``: keep the solutions in ``CellResult.solution``."""
    CELL_RANGES["tol"].check("tol", tol)
    CELL_RANGES["maxiter"].check("maxiter", maxiter)
    if tol_magnetic is not None:
        CELL_RANGES["tol_magnetic"].check("tol_magnetic", tol_magnetic)
    options = _options(options)
    requested = solver
    phi_mesh, plain = float(mesh.fraction.mean()), _plain_particles(mesh, options, rigid)
    solver, solver_reason = _choose_solver(solver, mesh.n, len(cases) + (forces_N is not None),
                                           reason=True, phi=phi_mesh, plain_particles=plain,
                                           rigid=rigid)
    # "auto" beyond the plain matrix-free range: a particle patch on every particle
    every_particle = (requested == "auto" and solver == "matrix-free"
                      and _auto_patches_every_particle(phi_mesh, plain, rigid))
    t_start = time.perf_counter()
    if rigid:
        # rigid particles as the stiff limit: 1e6 x the matrix modulus, same Poisson's ratio as
        # the particle; deflation makes the iteration count independent of this contrast and the
        # relative error of the rigid limit is O(1e-6) (tested against increasing contrast).
        particle = Material(matrix.E_Pa * 1e6, particle.nu, particle.density_kg_m3)
    composite = None
    if mesh.method in ("composite", "laminate"):
        lam, mu, composite = _composite_fields(mesh, matrix, particle)
    else:
        lam, mu = _material_fields(mesh, matrix, particle)
    stiff = particle.E_Pa > 10.0 * matrix.E_Pa
    solver = _CellSolver(mesh, lam, mu, deflate=deflate and stiff,
                         stiff_mask=mesh.fraction >= 0.5, tol=tol, maxiter=maxiter,
                         solver=solver, composite=composite, options=options, rigid=rigid,
                         every_particle=every_particle)
    iters, resid, hist, fields = {}, {}, {}, {}
    t_solve = time.perf_counter()
    L = mesh.box_m
    V = L ** 3
    # every load case in one block: the unit mean strains, then the magnetic load
    Es = [voigt_to_tensor(np.eye(6)[CASES.index(c)], engineering=True) for c in cases]
    loads = [asm.affine_load(lam, mu, mesh.h_m, E) for E in Es]
    if composite is not None:
        for ld, extra in zip(loads, composite.loads(Es)):
            ld += extra
        ld = extra = None      # (the loop's names would keep two load vectors through the solve)
    f_eff = np.zeros(3)
    b = moment = None
    if forces_N is not None:
        forces_N = np.asarray(check_finite("forces_N", forces_N, "N"), dtype=float)
        if forces_N.shape != (mesh.n_particles, 3):
            raise InputError(f"forces_N must have shape ({mesh.n_particles}, 3) [N], got "
                             f"{forces_N.shape}")
        b, moment = _force_density(mesh, forces_N)
        f_eff = forces_N.sum(axis=0) / V
        loads.append(asm.body_force_load(b, mesh.h_m))
    names = list(cases) + (["magnetic"] if forces_N is not None else [])
    F = np.stack(loads, axis=1)
    del loads
    if not keep_fields:
        b = None               # the force density is kept only as a field
    bar = callback = None
    if progress:
        # the bar counts converged load cases; its text shows the CG iteration and the worst
        # residual against the tolerance, so it moves with the work
        bar = progress_bar(total=len(names), desc="cell problems (block CG)", unit="case",
                           leave=False)

        def callback(it, n_done, worst):
            bar.n = min(n_done, len(names))
            bar.set_postfix_str(f"CG it {it}, worst residual {worst:.1e} -> {tol:.0e}",
                                refresh=True)
    # the magnetic column stops at magnetic_tol(tol) when only its variational mean stress is
    # used (all six strain solutions at hand, no fields kept); otherwise at tol like the strains
    # with particle patches the CG runs to tol * patch_tol_factor (and the magnetic column to
    # magnetic_tol of that): same error as without them at tol (SolverOptions.patch_tol_factor)
    patches = getattr(solver.M, "patches", None)
    f_cg = options.patch_tol_factor if patches is not None else 1.0

    def magnetic_column_tol(factor):
        if tol_magnetic is not None:
            return float(tol_magnetic) * factor
        t = tol * factor
        return magnetic_tol(t) if len(cases) == 6 and not keep_fields else t
    tol_mag = magnetic_column_tol(1.0)
    tols = [tol * f_cg] * len(cases) + ([magnetic_column_tol(f_cg)]
                                        if forces_N is not None else [])
    W, histories = solver.solve(F, callback=callback, tols=tols, magnetic=forces_N is not None,
                                x0=initial_guess)
    if bar is not None:
        bar.close()
    for c, name in enumerate(names):
        h = histories[c]
        iters[name], resid[name], hist[name] = len(h) - 1, h[-1], h
    bad = [nm for nm, t in zip(names, tols) if resid[nm] > t]
    if bad:
        raise ConvergenceError("cell problem(s) " + ", ".join(
            f"{nm} (residual {resid[nm]:.2e}, history ... "
            + ", ".join(f"{v:.1e}" for v in hist[nm][-4:]) + ")" for nm in bad)
            + f" did not converge to {tols[names.index(bad[0])]:.0e} in {maxiter} iterations",
            hist[bad[0]])
    ns = len(cases)
    # Products of the solutions: f_a . w_b and w_a . K w_b. With them the effective stiffness
    # is VARIATIONAL (energy of the approximate fields, error quadratic in the solution error):
    #   V C_ab = V <E_a : C : E_b> - f_a . w_b - f_b . w_a + w_a . K w_b,
    # while the mean stress is linear in it: V C_ab = V <E_a : C : E_b> - f_b . w_a. Their
    # difference estimates the error of the linear form; the variational one is far smaller.
    FW = F.T @ W                                   # FW[a, b] = f_a . w_b
    WKW = solver.energy_products(W[:, :ns], W) if ns else None   # (ns, ns + magnetic)
    C = np.zeros((6, 6))
    lin = np.zeros((6, 6))
    idx = [CASES.index(c) for c in cases]
    for a, ia in enumerate(idx):
        for bb, ib in enumerate(idx):
            aff = float(np.mean(lam * np.trace(Es[a]) * np.trace(Es[bb])
                                + 2.0 * mu * np.tensordot(Es[a], Es[bb])))
            if composite is not None:
                aff += composite.energy(Es[a], Es[bb])
            C[ia, ib] = aff - (FW[a, bb] + FW[bb, a] - WKW[a, bb]) / V
            lin[ib, ia] = aff - FW[bb, a] / V
    if keep_fields:
        for c, name in enumerate(names):
            fields[name] = W[:, c].reshape(mesh.n, mesh.n, mesh.n, 3)
    full = len(cases) == 6
    # relative size of the error of the linear (mean-stress) estimate: the solution error made
    # visible; the variational C's own error is of its square order
    sel = np.ix_(idx, idx)
    err_lin = float(np.abs(lin[sel] - C[sel]).max() / np.abs(C[sel]).max()) if ns else None
    err_stress = None        # (JSON has no NaN: None where not applicable)
    if full:
        C = 0.5 * (C + C.T)
        E_eff, nu_eff, K_eff, G_eff = isotropic_projection(C)
        AU = anisotropy_index(C)
    else:
        E_eff = nu_eff = K_eff = G_eff = AU = float("nan")

    stress = stress_el = stress_mo = strain = None
    if forces_N is not None:
        m = ns
        # mean stress of the magnetic fluctuation, <sigma(w_m)> : E_a = -(f_a . w_m) / V, made
        # variational with the unit-strain solutions (Betti: f_a . w_m = w_a . b):
        #   -(f_a . w_m + b . w_a - w_a . K w_m) / V
        sv = np.zeros(6)
        sv_lin = np.zeros(6)
        wm = W[:, m]
        for ia in range(6):
            if ia in idx:
                a = idx.index(ia)
                sv[ia] = -(FW[a, m] + FW[m, a] - WKW[a, m]) / V
                sv_lin[ia] = -FW[a, m] / V
            else:   # unit-strain case not solved: the mean stress (linear in the error) only
                E = voigt_to_tensor(np.eye(6)[ia], engineering=True)
                fa = asm.affine_load(lam, mu, mesh.h_m, E)
                if composite is not None:
                    fa += composite.loads([E])[0]
                sv[ia] = sv_lin[ia] = -float(fa @ wm) / V
        stress_el = voigt_to_tensor(sv)
        if virial_stress_Pa is not None:
            Vr = np.asarray(check_finite("virial_stress_Pa", virial_stress_Pa, "Pa"), dtype=float)
            if Vr.shape != (3, 3):
                raise InputError(f"virial_stress_Pa must have shape (3, 3) [Pa], got {Vr.shape}")
            stress_mo = 0.5 * (Vr + Vr.T)
        else:
            stress_mo = -0.5 * (moment + moment.T) / V
        stress = stress_el + stress_mo
        err_stress = float(np.abs(sv - sv_lin).max() / max(np.abs(tensor_to_voigt(stress)).max(),
                                                              1e-300))
        if full:
            strain = voigt_to_tensor(-np.linalg.solve(C, tensor_to_voigt(stress)), engineering=True)
        if keep_fields:
            fields["magnetic_body_force_N_m3"] = b
    if keep_fields:
        fields["lambda_Pa"], fields["mu_Pa"] = lam, mu
        if composite is not None:     # the cut voxels' own stiffness (Voigt, engineering shear)
            fields["cut_voxels"], fields["cut_voxel_C_Pa"] = composite.vox, composite.C
    timings = dict(solver.timings)
    timings["solve"] = time.perf_counter() - t_solve
    timings["total"] = time.perf_counter() - t_start
    settings = {"matrix_E_Pa": matrix.E_Pa, "matrix_nu": matrix.nu,
                "particle_E_Pa": particle.E_Pa, "particle_nu": particle.nu, "rigid": rigid,
                "deflate": solver.Z is not None, "tol": tol,
                "tol_magnetic": tol_mag if forces_N is not None else None,
                # the relative residuals the CG ran to (tighter than tol with particle patches)
                "tol_cg": tols[0] if cases else None,
                "tol_magnetic_cg": tols[-1] if forces_N is not None else None,
                "method": mesh.method,
                "solver": solver.kind,
                # what was asked for ("auto" by default) and why solver.kind was chosen
                "solver_requested": requested, "solver_reason": solver_reason,
                # no AMG below the geometric levels with matfree_coarse = "lu" (a diagnostic)
                "amg_levels": len(solver.ml.levels) if solver.ml is not None else 0,
                "amg_operator_complexity": (float(solver.ml.operator_complexity())
                                            if solver.ml is not None else None),
                "geometric_levels": (len(solver.M.levels) if solver.kind == "matrix-free"
                                     else 0),
                # local Gauss-Seidel sweeps per side over the interface nodes (matrix-free)
                "interface_sweeps": (solver.M.interface_sweeps if solver.kind == "matrix-free"
                                     else 0),
                # the load cases' CG (options.block_cg for the matrix-free solver): "coupled",
                # "strains" or "independent" (lock-step single-column CGs)
                "block_cg": getattr(solver, "block_cg", "independent"),
                # particle patches (matrix-free): the matrix shell around each particle [voxels],
                # the particles with a patch, and the share of the grid nodes in a patch
                "patch_shell_voxels": patches.shell_voxels if patches is not None else None,
                "patched_particles": int(patches.particles.size) if patches is not None else 0,
                "patch_node_share": patches.node_share if patches is not None else None,
                "warm_start": initial_guess is not None,
                "C_linear_error_rel": err_lin, "stress_mag_linear_error_rel": err_stress,
                "virial_from_dipoles": virial_stress_Pa is not None}
    return CellResult(
        C_eff_Pa=C, E_eff_Pa=E_eff, nu_eff=nu_eff, K_eff_Pa=K_eff, G_eff_Pa=G_eff,
        anisotropy_index=AU, f_eff_N_m3=f_eff, stress_mag_Pa=stress,
        stress_mag_elastic_Pa=stress_el, stress_mag_moment_Pa=stress_mo, strain_mag=strain,
        n_dof=mesh.n_dof, voxels=mesh.n, h_m=mesh.h_m,
        phi_voxel=float(mesh.fraction.mean() if composite is not None
                        else (mesh.fraction >= 0.5).mean()),
        n_particles=mesh.n_particles, n_unresolved=int((~mesh.resolved).sum()),
        iterations=iters, residuals=resid, residual_history=hist, timings_s=timings,
        settings=settings, mesh=mesh, fields=fields, solution=W if keep_solution else None)


def homogenize_rve(rve, voxels: int, *, forces_N=None, virial_stress_Pa=None,
                   matrix_E_Pa: float = PDMS.E_Pa, matrix_nu: float = PDMS.nu,
                   particle_E_Pa: float = FE.E_Pa, particle_nu: float = FE.nu,
                   rigid: bool = False,
                   method: str = "composite", deflate: bool = True, tol: float = 1e-6,
                   maxiter: int = 2000, keep_fields: bool = False, progress: bool = False,
                   solver: str = "auto", tol_magnetic: float | None = None,
                   options: SolverOptions | None = None) -> CellResult:
    """Effective stiffness, body force and magnetic stress of an RVE by periodic voxel FEM.

    Parameters
    ----------
    rve : RVE -- (or any object with ``box_m``, ``centers_m`` (N, 3), ``radii_m`` (N,) in m)
    voxels : int -- voxels per cube edge, in CELL_RANGES["voxels"] ([4, 256])
    forces_N : ndarray, shape (N, 3), optional -- force on each particle [N] (external gradient
        plus dipole-dipole); enables the magnetic load case
    virial_stress_Pa : ndarray, shape (3, 3), optional -- pairwise virial stress from the dipole
        solver [Pa]; replaces the force first moment in ``stress_mag`` (needed for periodic RVEs
        with interacting pairs across the cell boundary)
    matrix_E_Pa, matrix_nu : matrix Young's modulus [Pa] (> 0) and Poisson's ratio (-1, 0.5)
    particle_E_Pa, particle_nu : particle material (default Fe: 211 GPa, 0.29)
    rigid : bool -- particles as rigid bodies (stiff limit, 1e6 x matrix modulus)
    method : {"composite", "centre", "fraction", "laminate"} -- voxel phase assignment (see
        :func:`homogenize.voxels.mesh.voxelize`); "composite" (default): exact volume fraction of the
        spheres in every cut voxel, Reuss stiffness there, forces spread by fraction
        (results/cell/: random Fe/PDMS RVEs self-converged to 0.1-0.6 % at 24^3 and within 2 %
        of conforming P2 meshes; one dilute Fe sphere keeps a +1.6-2.2 % bias in its shear
        coefficient from 11 to 34 voxels per diameter, first order asymptotically: the part that
        depends on the sphere's position against the grid decays at second order or faster,
        the systematic part does not); "centre": the staircase of earlier versions (first order, 20-50 % high
        at Fe/PDMS contrast and 2-4 voxels per radius)
    deflate : bool -- deflate the rigid-body modes of stiff particles in CG (default True)
    tol : float -- relative residual of CG per load case (default 1e-6). C_eff and the elastic part
        of stress_mag are computed from the energy of the solutions (variational), so their error
        is of the order of the SQUARED solution error: 1e-6 gives them to ~1e-8 relative
        (tests/homogenize/test_cell_solver.py); ``settings["C_linear_error_rel"]`` reports the
        (much larger) error of the plain mean-stress formula as a bound. The magnetic column
        stops at :func:`magnetic_tol` (sqrt(tol): 1e-3 at the default) unless its field is
        kept: the variational stress's error is the product of the strain and magnetic
        solution errors (``settings["tol_magnetic"]``; ``settings["stress_mag_linear_error_rel"]``,
        the error of the formula linear in the magnetic solution, was 16-8300 x larger than it
        where measured: results/cell/magnetic_tolerance.json). ``tol_magnetic`` sets it
        explicitly, in [1e-14, 1e-2]. With particle patches (matrix-free solver) the CG runs to
        ``options.patch_tol_factor`` x these (``settings["tol_cg"]``), which gives the error
        of the solver without patches at ``tol``.
    keep_fields : bool -- keep the displacement fields (for VTU/PNG output)
    solver : {"auto", "fast", "reference", "matrix-free"} -- "auto" (default): "matrix-free" on
        even voxel counts >= 8 where the mesh's particle volume fraction is at most
        :data:`AUTO_MAX_PHI` (0.06) and the particles are at most
        :data:`AUTO_MAX_PLAIN_PARTICLES` (100) or get particle patches (:func:`use_patches`),
        beyond that (and always for ``rigid`` particles) "matrix-free" with a particle patch on
        every particle up to :data:`AUTO_MAX_PHI_PATCHED` (0.15), else "fast" (odd grids; dense
        stiff particles, where the geometric multigrid needs 2-6x the iterations even with the
        patches; rigid particles too large for a patch); the solver that ran and why are in
        ``settings["solver"]``, ``["solver_reason"]`` (results/cell/README.md "Solver
        choice"). "fast": numba assembly, all load
        cases in one block (CG in lock-step, block V-cycle with parallel multicolour Gauss-Seidel
        on every level, numba BSR products); "reference": BLAS assembly, pyamg's default
        hierarchy and own V-cycle, scipy products, one load case after another;
        "matrix-free" (even voxel counts >= 8): no assembled fine matrix -- products from one
        27-block stencil row per node (shared by the nodes inside one phase), geometric
        multigrid (trilinear transfer, element-wise Galerkin coarse operators) down to <= 64^3,
        pyamg below (:mod:`homogenize.solvers._matfree`); a fraction of the memory, for grids whose
        assembled matrix does not fit ("fast" switches to it then).
        Same C_eff to the solver tolerance. The iteration count of "fast" does not depend on
        the microstructure, while the trilinear coarse level of "matrix-free" needs 2-4x more
        iterations with many or small particles (results/cell/multigrid_robustness.json; the
        cause, its first coarse space: results/cell/coarse_space_experiments.json; the
        particle patches recover most of it) and with dense particles (hence "auto").
    options : :class:`homogenize.solvers.SolverOptions`, optional -- the solver's settings
        (AMG, matrix-free multigrid, particle patches, block CG); default ``SolverOptions()``

    Returns
    -------
    CellResult
    """
    CELL_RANGES["voxels"].check("voxels", voxels)
    CELL_RANGES["tol"].check("tol", tol)
    matrix = Material(matrix_E_Pa, matrix_nu)
    particle = Material(particle_E_Pa, particle_nu)
    for name, v in (("matrix_E_Pa", matrix_E_Pa), ("particle_E_Pa", particle_E_Pa)):
        CELL_RANGES["E_Pa"].check(name, v)
    mesh = voxelize(rve, voxels, method=method)
    return homogenize_mesh(mesh, forces_N=forces_N, virial_stress_Pa=virial_stress_Pa,
                           matrix=matrix, particle=particle, rigid=rigid, deflate=deflate,
                           tol=tol, maxiter=maxiter, keep_fields=keep_fields, progress=progress,
                           solver=solver, tol_magnetic=tol_magnetic, options=options)


# ------------------------------------------------------------------------------------------
# The stage: RVE (+ magnetic state) + cell configuration -> CellResult
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CellConfig:
    """Everything the cell stage needs besides the RVE (frozen; SI units).

    See :func:`homogenize_rve` for the meaning of each field. ``tol`` is the relative CG
    residual per load case. The numeric fields are checked against :data:`CELL_RANGES` (tol
    in [1e-14, 1e-2]: larger values return meaningless moduli).
    """

    voxels: int = 32
    matrix: ElasticMaterial = elastic(PDMS)
    particle: ElasticMaterial = elastic(FE)
    rigid: bool = False
    method: str = "composite"
    tol: float = 1e-6
    maxiter: int = 2000
    solver: str = "auto"

    def __post_init__(self):
        for key in ("voxels", "tol", "maxiter"):
            CELL_RANGES[key].check(key, getattr(self, key))
        for name, mat in (("matrix", self.matrix), ("particle", self.particle)):
            CELL_RANGES["E_Pa"].check(f"{name}.E_Pa", getattr(mat, "E_Pa", None))
        if self.solver not in SOLVERS:
            raise InputError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.method not in METHODS:
            raise InputError(f"method must be one of {METHODS}, got {self.method!r}")


def homogenize_cell(rve, state=None, config: CellConfig = CellConfig(), *, keep_fields=False,
               progress=False) -> CellResult:
    """The cell stage: effective stiffness and, given the magnetic ``state``
    (:class:`micro.dipoles.MagneticState`), the magnetic load case of ``rve``."""
    forces = None if state is None else state.total_force_N
    virial = None if state is None else np.asarray(state.virial_stress_Pa)
    mesh = voxelize(rve, int(config.voxels), method=config.method)
    return homogenize_mesh(mesh, forces_N=forces, virial_stress_Pa=virial,
                           matrix=config.matrix, particle=config.particle, rigid=config.rigid,
                           tol=config.tol, maxiter=config.maxiter, keep_fields=keep_fields,
                           progress=progress, solver=config.solver)
