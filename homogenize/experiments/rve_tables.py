"""Precomputed RVE physics the extensions interpolate in: made by the project's own solvers.

Three tables live in ``homogenize/experiments/data/``, each with a provenance JSON beside it
(command, git revision, resolution, seeds, versions, run time). All are re-made by
``mapsim diagnose-tables`` (or :func:`build_stiffness_table`, :func:`build_stress_table`,
:func:`build_cell_stress_table`).

``filler_stiffness.csv`` -- ``filler_stiffening``
    Effective Young's modulus and Poisson's ratio of random RVEs of Fe spheres (211 GPa, 0.29)
    in PDMS (2 MPa, 0.45) by the periodic voxel FEM ``homogenize.cell.problem.homogenize_rve``,
    isotropic projection of ``C_eff``, several random RVEs per volume fraction. The modulus
    contrast (1e5) makes the ratio ``E_eff / E_matrix`` that of rigid spheres, independent of
    the matrix modulus. Particles are monodisperse, dispersed (``micro.particles.generate_rve``)
    with a surface gap of at least ``GAP_VOXELS`` = 1.8 voxels (> sqrt 3) of the 24^3 grid
    (~0.36 radii, a matrix shell of ~4.5 nm on 25 nm particles, about a surfactant or polymer
    layer; the same physical gap at other resolutions): the voxels of two particles then never
    share a face, an edge or a node. Without it, near-contacts become rigid voxel bridges that
    real, matrix-coated particles do not have (a 1-voxel gap still gave E_eff / E_m = 6.1 with
    anisotropy index 0.86 for one RVE at phi = 0.3). The number of particles per RVE grows
    with phi so that every sphere keeps a radius of about ``RADIUS_VOXELS`` voxels at 24^3 (1
    at low phi: the dilute limit, where positions do not matter, and a single sphere is ~10
    voxels from its own images); other resolutions refine the same particle numbers. The table
    is indexed by ``phi_voxel``, the particle fraction of the FE model itself.

    Discretization (``filler_stiffness_resolution.json``, one sphere at phi = 0.02): voxel
    spheres are stiffer than spheres; the stiffening per unit phi exceeds Eshelby's dilute
    value by +52 % at 2 voxels' radius, +28 % at 4, +20 % at 5.4 and +18.5 % at 6.7 (part of
    the last is the cubic array's own interaction). At 24^3 the table's ``E_ratio - 1`` is
    therefore ~20-30 % high; re-make it at higher resolution when the FEM allows
    (``mapsim diagnose-tables --only stiffness --voxels 40``).

``dipolar_stress.csv`` -- ``dipolar_interaction`` in magnetostriction
    The magnetic virial stress of random dispersed RVEs from ``micro.dipoles.solve`` (periodic
    Ewald sums, tin-foil boundary), as ``kappa_dev = (sigma_zz - (sigma_xx + sigma_yy) / 2) /
    (mu0 M^2)`` (M the RVE's magnetization along the field z), for saturated particles and for
    soft spheres (Froehlich-Kennelly, chi0 = 3) at several reduced fields, indexed by phi and
    the reduced magnetization ``m = M / (phi Ms)``. It is the axial stress an incompressible
    matrix feels from the particles' interactions under an affine deformation; the mean-field
    value (Lorentz cavity turned into a spheroid) is 1/5.

``dipolar_cell_stress.csv`` -- its share that reaches the matrix
    Point forces in a homogeneous matrix pass the whole virial on; stiff particles carry part
    of the pair forces themselves (a correction of order (a / r)^3). For a few RVEs per phi
    (8 saturated Fe particles, 32^3 voxels, matrix nu = 0.49) ``homogenize.cell.problem`` solves the
    cell problem with the dipole forces and gives ``stress_mag`` = mean elastic stress +
    virial; ``factor = dev(stress_mag) / dev(virial)`` multiplies the virial table.

The filler and cell tables run the FEM at modest resolution (see the discretization note
above); all three are statistics of a few random RVEs, stored with their spread.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import functools
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.constants import mu_0
import inspect
from homogenize.cell.problem import homogenize_rve
from micro.materials import FE, PDMS, SEED
from micro.particles import Monodisperse, generate_rve
from types import SimpleNamespace
from homogenize.cell.problem import bulk_shear, eshelby_dilute, young_poisson
from micro.dipoles import solve
from micro.common.validate import InputError, check_positive
from micro.common.files import atomic_write_text, manifest, write_json
from micro.common.progress import progress_bar
from scipy.interpolate import PchipInterpolator

__all__ = ["STIFFNESS_PHIS", "STIFFNESS_SEEDS", "STIFFNESS_VOXELS", "RADIUS_VOXELS", "GAP_VOXELS",
           "stiffness_point", "build_stiffness_table", "stiffness_resolution_study", "stiffness_table",
           "filler_stiffness_ratio", "stiffness_table_path",
           "STRESS_PHIS", "STRESS_SEEDS", "STRESS_N", "STRESS_FIELDS", "stress_point",
           "build_stress_table", "stress_table", "stress_table_path",
           "microstructure_stress_coefficient", "affine_kappa", "LORENTZ_STRESS",
           "cell_stress_point",
           "build_cell_stress_table", "cell_stress_factor", "cell_factor_nodes", "cell_stress_path"]


class Unavailable(RuntimeError):
    """A precomputed table an extension needs is missing (run ``mapsim diagnose-tables``)."""

DATA_DIR = Path(__file__).resolve().parent / "data"
_RADIUS_M = 25e-9                 # monodisperse; only ratios of lengths enter either table

# ------------------------------------------------------------------------------------------
# filler stiffness: voxel FEM of random RVEs

STIFFNESS_PHIS = (0.005, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3)
STIFFNESS_SEEDS = (1, 2, 3)
STIFFNESS_VOXELS = 24
RADIUS_VOXELS = 5.0
GAP_VOXELS = 1.8
MATRIX_E_PA, MATRIX_NU = PDMS.E_Pa, PDMS.nu
PARTICLE_E_PA, PARTICLE_NU = FE.E_Pa, FE.nu


def _cell_tol() -> float:

    return float(inspect.signature(homogenize_rve).parameters["tol"].default)


def stiffness_table_path() -> Path:
    return DATA_DIR / "filler_stiffness.csv"


def _n_particles(phi: float, voxels: int) -> int:
    # N spheres of radius RADIUS_VOXELS h in a cube of STIFFNESS_VOXELS h; the same N at any
    # resolution, so that --voxels refines the same microstructure (radius scales with it)
    n = phi * STIFFNESS_VOXELS ** 3 / (4.0 / 3.0 * math.pi * RADIUS_VOXELS ** 3)
    return int(min(max(round(n), 1), 30))


def stiffness_point(phi: float, seed: int, voxels: int = STIFFNESS_VOXELS) -> dict:
    """E_eff / E_matrix and nu_eff of one random RVE by the voxel FEM (see module doc)."""

    n = _n_particles(phi, voxels)
    box = (n * 4.0 / 3.0 * math.pi * _RADIUS_M ** 3 / phi) ** (1.0 / 3.0)
    # the gap is GAP_VOXELS voxels of the reference resolution STIFFNESS_VOXELS: other
    # resolutions refine the same microstructure
    gap = GAP_VOXELS * box / STIFFNESS_VOXELS
    rve = generate_rve(float(phi), n, int(seed), distribution=Monodisperse(_RADIUS_M),
                       gap_m=gap if n > 1 else 0.0)
    t0 = time.perf_counter()
    r = homogenize_rve(rve, int(voxels), matrix_E_Pa=MATRIX_E_PA, matrix_nu=MATRIX_NU,
                       particle_E_Pa=PARTICLE_E_PA, particle_nu=PARTICLE_NU)
    return {"phi": float(phi), "seed": int(seed), "n_particles": n, "voxels": int(voxels),
            "phi_voxel": r.phi_voxel, "E_ratio": r.E_eff_Pa / MATRIX_E_PA, "nu_eff": r.nu_eff,
            "anisotropy_index": r.anisotropy_index, "seconds": time.perf_counter() - t0}


def build_stiffness_table(phis=STIFFNESS_PHIS, seeds=STIFFNESS_SEEDS, voxels=STIFFNESS_VOXELS,
                          path=None, progress: bool = True, argv=None) -> Path:
    """Run :func:`stiffness_point` for every (phi, seed); write the CSV and its provenance."""
    path = Path(path) if path is not None else stiffness_table_path()
    jobs = [(p, s) for p in phis for s in seeds]
    rows = []
    it = jobs
    if progress:
        it = progress_bar(jobs, desc="stiffness table (FEM)", unit="RVE", file=sys.stderr)
    t0 = time.perf_counter()
    for p, s in it:
        rows.append(stiffness_point(p, s, voxels))
    cols = ("phi", "seed", "n_particles", "voxels", "phi_voxel", "E_ratio", "nu_eff",
            "anisotropy_index")
    _write_table(path, cols, rows, "filler stiffness of random RVEs, voxel FEM", {
        "function": "homogenize.experiments.rve_tables.build_stiffness_table",
        "phis": list(phis), "seeds": list(seeds), "voxels": int(voxels),
        "radius_voxels": RADIUS_VOXELS, "particles": f"monodisperse 25 nm, dispersed, surface gap >= {GAP_VOXELS} voxels "
                     f"of the {STIFFNESS_VOXELS}^3 grid",
        "matrix": {"E_Pa": MATRIX_E_PA, "nu": MATRIX_NU},
        "particle": {"E_Pa": PARTICLE_E_PA, "nu": PARTICLE_NU},
        "solver": f"homogenize.cell.problem.homogenize_rve (method 'composite', default tol {_cell_tol():g})",
    }, time.perf_counter() - t0, argv)
    stiffness_table.cache_clear()
    return path


def stiffness_resolution_study(phi: float = 0.02, voxels=(12, 16, 24, 32, 40), path=None,
                               argv=None) -> dict:
    """Discretization error of the table: one sphere (the dilute limit, where Eshelby is exact
    to O(phi)) at increasing resolution; the stiffening per unit ``phi_voxel`` against the
    voxel size, and its fitted convergence rate. Written to ``path`` (JSON) if given."""

    a = (3.0 * phi / (4.0 * math.pi)) ** (1.0 / 3.0)
    rve = SimpleNamespace(box_m=1e-6, centers_m=np.full((1, 3), 0.5e-6),
                          radii_m=np.array([a * 1e-6]))
    Km, Gm = bulk_shear(MATRIX_E_PA, MATRIX_NU)
    Kp, Gp = bulk_shear(PARTICLE_E_PA, PARTICLE_NU)
    rows = []
    for n in voxels:
        r = homogenize_rve(rve, int(n), matrix_E_Pa=MATRIX_E_PA, matrix_nu=MATRIX_NU,
                           particle_E_Pa=PARTICLE_E_PA, particle_nu=PARTICLE_NU)
        e_esh = young_poisson(*eshelby_dilute(r.phi_voxel, Km, Gm, Kp, Gp))[0] / MATRIX_E_PA
        rows.append({"voxels": int(n), "radius_voxels": a * n, "phi_voxel": r.phi_voxel,
                     "E_ratio": r.E_eff_Pa / MATRIX_E_PA,
                     "slope": (r.E_eff_Pa / MATRIX_E_PA - 1.0) / r.phi_voxel,
                     "slope_eshelby": (e_esh - 1.0) / r.phi_voxel})
    h = np.array([1.0 / r["voxels"] for r in rows])
    rel = np.array([r["slope"] / r["slope_eshelby"] - 1.0 for r in rows])
    out = {"phi": phi, "rows": rows,
           "rate_of_relative_excess_vs_h": float(np.polyfit(np.log(h), np.log(np.abs(rel)), 1)[0])}
    if path is not None:
        out["manifest"] = manifest({"function": "homogenize.experiments.rve_tables."
                                    "stiffness_resolution_study", "phi": phi,
                                    "voxels": list(voxels)}, None,
                                   command=" ".join(argv) if argv else None)
        write_json(path, out)
    return out


@functools.lru_cache(maxsize=1)
def stiffness_table() -> dict:
    """Per nominal phi: mean phi_voxel, mean and standard error of E_ratio and nu_eff."""
    rows = _read_table(stiffness_table_path())
    out = {k: [] for k in ("phi", "phi_voxel", "E_ratio", "E_ratio_se", "nu_eff", "nu_eff_se", "n")}
    for p in sorted({r["phi"] for r in rows}):
        sel = [r for r in rows if r["phi"] == p]
        e = np.array([r["E_ratio"] for r in sel])
        nu = np.array([r["nu_eff"] for r in sel])
        out["phi"].append(p)
        out["phi_voxel"].append(float(np.mean([r["phi_voxel"] for r in sel])))
        out["E_ratio"].append(float(e.mean()))
        out["E_ratio_se"].append(float(e.std(ddof=1) / math.sqrt(e.size)) if e.size > 1 else math.nan)
        out["nu_eff"].append(float(nu.mean()))
        out["nu_eff_se"].append(float(nu.std(ddof=1) / math.sqrt(nu.size)) if nu.size > 1 else math.nan)
        out["n"].append(len(sel))
    return {k: np.array(v) for k, v in out.items()}


def filler_stiffness_ratio(phi):
    """E_eff / E_matrix of Fe (rigid) spheres in the matrix at particle volume fraction phi [-].

    Interpolated in the FEM table (:func:`stiffness_table`) against its ``phi_voxel``:
    monotone cubic (PCHIP) through ``(0, 1)`` and the table's means; beyond the last node
    (phi ~ 0.3) the last segment's slope is continued (the diagnosis warns nowhere; phi of
    magnetic elastomers rarely exceeds 0.3). Computed at matrix nu = 0.45: for rigid spheres
    the dilute slope is 2.32 there against Einstein's 2.5 at nu = 0.5 (Eshelby), so other
    matrix Poisson's ratios are affected at the ~8 % level of ``E_ratio - 1``.
    """
    x, y = _stiffness_interp_nodes()
    p = np.asarray(phi, dtype=float)
    f = PchipInterpolator(x, y, extrapolate=False)
    out = np.where(p <= x[-1], f(np.clip(p, 0.0, x[-1])), 0.0)
    slope = (y[-1] - y[-2]) / (x[-1] - x[-2])
    out = np.where(p > x[-1], y[-1] + slope * (p - x[-1]), out)
    return out


@functools.lru_cache(maxsize=1)
def _stiffness_interp_nodes():
    t = stiffness_table()
    x = np.concatenate(([0.0], t["phi_voxel"]))
    y = np.concatenate(([1.0], t["E_ratio"]))
    order = np.argsort(x)
    return x[order], y[order]


# ------------------------------------------------------------------------------------------
# magnetic virial stress of random RVEs: micro.dipoles

STRESS_PHIS = (0.02, 0.05, 0.1, 0.2, 0.3, 0.4)
STRESS_SEEDS = (1, 2, 3)
STRESS_N = 200
#: reduced applied fields H / Ms of the soft-sphere runs; None = saturated particles
STRESS_FIELDS = (0.003, 0.03, 0.3, 3.0, None)
_STRESS_CHI0 = 3.0
_MS_A_PER_M = SEED.Ms_A_m
#: mean-field value of kappa_dev: an affinely stretched Lorentz sphere (N = 1/3 - (2/5) eps)
LORENTZ_STRESS = 0.2


def stress_table_path() -> Path:
    return DATA_DIR / "dipolar_stress.csv"


def stress_point(phi: float, seed: int, h: float | None) -> dict:
    """Virial stress coefficients of one random RVE (see module doc); ``h = H / Ms`` or None."""
    rve = generate_rve(float(phi), STRESS_N, int(seed), distribution=Monodisperse(_RADIUS_M))
    if h is None:
        st = solve(rve, 1.0, 0.0, "saturated")
    else:
        st = solve(rve, mu_0 * h * _MS_A_PER_M, 0.0, "frohlich-kennelly", chi0=_STRESS_CHI0)
    s = st.virial_stress_Pa
    M = float(st.M_eff_A_per_m[2])
    Ms_c = float(np.sum(rve.m_sat_Am2)) / rve.volume_m3
    q = mu_0 * M * M
    return {"phi": float(phi), "seed": int(seed), "law": "saturated" if h is None else "frohlich-kennelly",
            "h": math.nan if h is None else float(h), "m_reduced": M / Ms_c,
            "kappa_zz": float(s[2, 2]) / q,
            "kappa_dev": float(s[2, 2] - 0.5 * (s[0, 0] + s[1, 1])) / q}


def build_stress_table(phis=STRESS_PHIS, seeds=STRESS_SEEDS, fields=STRESS_FIELDS, path=None,
                       progress: bool = True, argv=None) -> Path:
    """Run :func:`stress_point` for every (phi, seed, field); write the CSV and its provenance."""
    path = Path(path) if path is not None else stress_table_path()
    jobs = [(p, s, h) for p in phis for s in seeds for h in fields]
    it = jobs
    if progress:
        it = progress_bar(jobs, desc="dipolar stress table", unit="RVE", file=sys.stderr)
    t0 = time.perf_counter()
    rows = [stress_point(p, s, h) for p, s, h in it]
    cols = ("phi", "seed", "law", "h", "m_reduced", "kappa_zz", "kappa_dev")
    _write_table(path, cols, rows, "magnetic virial stress of random RVEs, micro.dipoles", {
        "function": "homogenize.experiments.rve_tables.build_stress_table",
        "phis": list(phis), "seeds": list(seeds), "n_particles": STRESS_N,
        "fields_H_over_Ms": [None if h is None else h for h in fields],
        "particles": "monodisperse 25 nm, dispersed (micro.particles.generate_rve)",
        "laws": f"saturated; frohlich-kennelly chi0 = {_STRESS_CHI0}",
        "solver": "micro.dipoles.solve (Ewald, tin-foil, tol 1e-8)",
        "definition": "kappa_dev = (s_zz - (s_xx + s_yy)/2) / (mu0 M^2), s = virial_stress_Pa",
    }, time.perf_counter() - t0, argv)
    stress_table.cache_clear()
    return path


@functools.lru_cache(maxsize=1)
def stress_table() -> dict:
    """Per phi: nodes of kappa_dev against the reduced magnetization (mean over seeds)."""
    rows = _read_table(stress_table_path())
    out = {}
    for p in sorted({r["phi"] for r in rows}):
        sel = [r for r in rows if r["phi"] == p]
        hs = sorted({r["h"] for r in sel if not math.isnan(r["h"])})
        m, k, se = [], [], []
        for h in hs + [math.nan]:
            g = [r for r in sel if (math.isnan(r["h"]) if math.isnan(h) else r["h"] == h)]
            kd = np.array([r["kappa_dev"] for r in g])
            m.append(float(np.mean([r["m_reduced"] for r in g])))
            k.append(float(kd.mean()))
            se.append(float(kd.std(ddof=1) / math.sqrt(kd.size)) if kd.size > 1 else math.nan)
        order = np.argsort(m)
        out[p] = (np.array(m)[order], np.array(k)[order], np.array(se)[order])
    return out


def microstructure_stress_coefficient(phi, m_reduced, cell: bool = True):
    """kappa_dev(phi, m) of random dispersed particles [-]: axial magnetic stress of the
    particles' interactions over ``mu0 M^2`` (positive: tensile along the field, i.e. the
    matrix is pulled together along it).

    The dipole virial (``dipolar_stress.csv``): linear interpolation in the reduced
    magnetization ``m = M / (phi Ms)`` (clipped to the table's range) at each tabulated phi,
    then linear in phi (held constant outside). With ``cell`` (default) times
    :func:`cell_stress_factor`, the share of it the stiff particles pass on to the matrix
    (``homogenize.cell.problem``'s ``stress_mag`` over the virial, ``dipolar_cell_stress.csv``).
    """
    t = stress_table()
    phis = np.array(sorted(t))
    p = np.atleast_1d(np.asarray(phi, dtype=float))
    m = np.broadcast_to(np.atleast_1d(np.asarray(m_reduced, dtype=float)), p.shape)
    at = np.array([np.interp(np.abs(m), t[q][0], t[q][1]) for q in phis])   # (n_phi, n)
    out = np.empty(p.shape)
    for i in range(p.size):
        out.flat[i] = np.interp(p.flat[i], phis, at[:, i])
    if cell:
        out = out * cell_stress_factor(p)
    return out if np.ndim(phi) or np.ndim(m_reduced) else float(out[0])


def affine_kappa(phi: float, Ms_particle_A_per_m: float):
    """``kappa(|M|)`` [-] of the affine specimen model (:mod:`homogenize.macro.specimen`): the
    microstructural stress coefficient of randomly dispersed particles at volume fraction
    ``phi`` [-] (:func:`microstructure_stress_coefficient`, the dipole virial times the cell
    FEM's share), as a function of the composite's magnetization ``|M|`` [A/m] through
    ``m = |M| / (phi Ms)`` (clipped to [0, 1])."""
    phi = check_positive("phi", phi)
    Ms = check_positive("Ms_particle_A_per_m", Ms_particle_A_per_m, "A/m")

    def kappa(M_abs):
        m = np.clip(np.asarray(M_abs, float) / (phi * Ms), 0.0, 1.0)
        return np.asarray(microstructure_stress_coefficient(np.full(m.size, phi), m.ravel()),
                          float).reshape(m.shape)
    return kappa


# ------------------------------------------------------------------------------------------
# stiff particles carry part of the interaction stress: homogenize.cell.problem's stress_mag

CELL_PHIS = (0.05, 0.1, 0.2, 0.3)
CELL_SEEDS = (1, 2, 3, 4)          # tried in order; a seed whose placement jams is skipped
CELL_PER_PHI = 2
CELL_N = 8
CELL_VOXELS = 32


def cell_stress_path() -> Path:
    return DATA_DIR / "dipolar_cell_stress.csv"


def cell_stress_point(phi: float, seed: int, voxels: int = CELL_VOXELS) -> dict:
    """Deviatoric magnetic stress of one RVE with Fe particles in the matrix (nu = 0.49), by
    ``homogenize.cell.problem.homogenize_rve`` with the dipole forces and the dipole virial: the
    virial alone (point forces in a homogeneous matrix) and the cell's ``stress_mag`` (the
    stiff particles carry part of it), in units of mu0 M^2. Saturated particles."""

    box = (CELL_N * 4.0 / 3.0 * math.pi * _RADIUS_M ** 3 / phi) ** (1.0 / 3.0)
    rve = generate_rve(float(phi), CELL_N, int(seed), distribution=Monodisperse(_RADIUS_M),
                       gap_m=GAP_VOXELS * box / voxels)
    st = solve(rve, 1.0, 0.0, "saturated")
    q = mu_0 * float(st.M_eff_A_per_m[2]) ** 2
    r = homogenize_rve(rve, int(voxels), forces_N=st.force_dd_N,
                       virial_stress_Pa=st.virial_stress_Pa, matrix_E_Pa=MATRIX_E_PA,
                       matrix_nu=0.49, particle_E_Pa=PARTICLE_E_PA, particle_nu=PARTICLE_NU)

    def dev(t):
        return float(t[2, 2] - 0.5 * (t[0, 0] + t[1, 1])) / q
    v, c = dev(st.virial_stress_Pa), dev(r.stress_mag_Pa)
    return {"phi": float(phi), "seed": int(seed), "n_particles": CELL_N, "voxels": int(voxels),
            "phi_voxel": r.phi_voxel, "virial_dev": v, "cell_dev": c, "factor": c / v,
            "E_ratio": r.E_eff_Pa / MATRIX_E_PA}


def build_cell_stress_table(phis=CELL_PHIS, voxels=CELL_VOXELS, path=None, progress=True,
                            argv=None) -> Path:
    """:func:`cell_stress_point` for ``CELL_PER_PHI`` placeable seeds per phi; CSV + provenance."""
    path = Path(path) if path is not None else cell_stress_path()
    rows, skipped = [], []
    t0 = time.perf_counter()
    bar = None
    if progress:
        bar = progress_bar(total=len(phis) * CELL_PER_PHI, desc="cell magnetic stress (FEM)",
                   unit="RVE", file=sys.stderr)
    for p in phis:
        done = 0
        for s in CELL_SEEDS:
            if done == CELL_PER_PHI:
                break
            try:
                rows.append(cell_stress_point(p, s, voxels))
            except InputError as exc:          # placement jammed for this seed: recorded
                skipped.append({"phi": p, "seed": s, "why": str(exc)})
                continue
            done += 1
            if bar is not None:
                bar.update()
    if bar is not None:
        bar.close()
    cols = ("phi", "seed", "n_particles", "voxels", "phi_voxel", "virial_dev", "cell_dev",
            "factor", "E_ratio")
    _write_table(path, cols, rows, "deviatoric magnetic stress, dipole virial vs FEM cell", {
        "function": "homogenize.experiments.rve_tables.build_cell_stress_table",
        "phis": list(phis), "seeds_tried": list(CELL_SEEDS), "per_phi": CELL_PER_PHI,
        "n_particles": CELL_N, "voxels": int(voxels), "skipped": skipped,
        "particles": f"monodisperse 25 nm, saturated, surface gap >= {GAP_VOXELS} voxels",
        "matrix": {"E_Pa": MATRIX_E_PA, "nu": 0.49},
        "particle": {"E_Pa": PARTICLE_E_PA, "nu": PARTICLE_NU},
        "solver": "micro.dipoles.solve + homogenize.cell.problem.homogenize_rve(forces_N, "
                  f"virial_stress_Pa), default tol {_cell_tol():g}",
        "definition": "factor = dev(stress_mag) / dev(virial), dev(s) = s_zz - (s_xx + s_yy)/2",
    }, time.perf_counter() - t0, argv)
    cell_factor_nodes.cache_clear()
    return path


@functools.lru_cache(maxsize=1)
def cell_factor_nodes():
    """(phi nodes, mean factor, standard error) with the exact dilute node (0, 1)."""
    rows = _read_table(cell_stress_path())
    phis = sorted({r["phi"] for r in rows})
    f = [np.array([r["factor"] for r in rows if r["phi"] == p]) for p in phis]
    mean = np.array([1.0] + [x.mean() for x in f])
    se = np.array([0.0] + [x.std(ddof=1) / math.sqrt(x.size) if x.size > 1 else math.nan
                           for x in f])
    return np.array([0.0] + phis), mean, se


def cell_stress_factor(phi):
    """dev(stress_mag) / dev(virial) of Fe particles in the matrix at volume fraction phi:
    the share of the particles' interaction stress that reaches the matrix [-]. 1 for dilute
    particles (the correction is of order (a / r)^3); linear in phi between the FEM nodes,
    held constant beyond the last."""
    x, y, _ = cell_factor_nodes()
    return np.interp(np.asarray(phi, dtype=float), x, y)


# ------------------------------------------------------------------------------------------
# CSV + provenance

def _write_table(path: Path, cols, rows, what, config, seconds, argv):
    lines = [f"# {what}; made by {config['function']} (provenance: {path.stem}.provenance.json)",
             ",".join(cols)]
    for r in rows:
        lines.append(",".join(repr(float(r[c])) if isinstance(r[c], float) else str(r[c])
                              for c in cols))
    atomic_write_text(path, "\n".join(lines) + "\n")
    prov = manifest(config, None, command=" ".join(argv) if argv else None,
                    cpu_seconds_wall=round(seconds, 1), rows=len(rows))
    write_json(path.with_name(path.stem + ".provenance.json"), prov)


def _read_table(path: Path) -> list[dict]:
    if not path.exists():
        raise Unavailable(f"{path.name} is missing: run `mapsim diagnose-tables`")
    lines = [l for l in path.read_text().splitlines() if l and not l.startswith("#")]
    rows = []
    for r in csv.DictReader(lines):
        rows.append({k: (v if k == "law" else float(v)) for k, v in r.items()})
    return rows


# ------------------------------------------------------------------------------------------
# restructuring: the coupled RVE (particles that move) from relax tables

#: relax tables the cause ``microstructure_evolution`` reads (``mapsim batch`` with
#: ``evaluator = "relax"``, ``fem = true``; each made from the study TOML beside it)
RELAX_TABLE_GLOB = "relax_*.h5"
_RELAX_NEEDS = ("strain_parallel", "strain_affine_parallel", "M_eff_A_per_m",
                "M_eff_affine_A_per_m", "E_eff_parallel_Pa")


@dataclass(frozen=True, eq=False)
class Restructuring:
    """What the coupled RVE adds to the affine (particles fixed) magnetostriction.

    Per field step ``B_T`` (K,) and realization (R): the relaxed-minus-affine free strain of
    the RVE along the field ``d_eps_rve`` and the relaxed-minus-affine ``mu0 M^2 / E_parallel``
    ``d_x`` (the specimen's shape stress acts on it), plus the raw relaxed and affine values;
    ``provenance``: table path, study, evaluator id (code hash), seeds, manifest.
    """

    path: str
    phi: float
    E_Pa: float
    B_T: np.ndarray
    d_eps_rve: np.ndarray
    d_x: np.ndarray
    eps_rve_relaxed: np.ndarray
    eps_rve_affine: np.ndarray
    x_relaxed: np.ndarray
    x_affine: np.ndarray
    provenance: dict
    M_relaxed_A_per_m: np.ndarray | None = None     # (K, R) the relaxed RVEs' M_eff along B
    E_parallel_Pa: np.ndarray | None = None         # (K, R) their E along the field

    def delta_strain(self, B_T, k_shape) -> np.ndarray:
        """Mean over realizations of the restructuring strain ``d_eps_rve + k_shape d_x`` at
        ``|B_T|`` (linear in B between the table's steps; held constant beyond its last)."""
        b = np.abs(np.asarray(B_T, dtype=float))
        d = self.d_eps_rve.mean(axis=1)
        dx = self.d_x.mean(axis=1)
        return np.interp(b, self.B_T, d) + np.asarray(k_shape) * np.interp(b, self.B_T, dx)

    def delta_strain_realizations(self, B_T: float, k_shape: float) -> np.ndarray:
        """The restructuring strain of every realization at one field (R,)."""
        b = abs(float(B_T))
        return np.array([np.interp(b, self.B_T, self.d_eps_rve[:, r])
                         + k_shape * np.interp(b, self.B_T, self.d_x[:, r])
                         for r in range(self.d_eps_rve.shape[1])])


def relax_tables() -> list[Path]:
    return sorted(DATA_DIR.glob(RELAX_TABLE_GLOB))


def _restructuring_from(path: Path, phi: float, E_Pa: float, rtol: float):
    from homogenize.tables.batch import read_table
    import json as _json
    import tomllib
    t = read_table(path)
    if any(q not in t.values for q in _RELAX_NEEDS):
        return None, f"{path.name}: not a relax table with fem = true"
    study = tomllib.loads(t.attrs.get("study_toml", "")) if t.attrs.get("study_toml") else {}
    E_fixed = study.get("relax", {}).get("matrix_E_Pa", PDMS.E_Pa)
    B = np.asarray(t.axes.get("B_T", ()), dtype=float)
    if B.size < 2 or B[0] != 0.0:
        return None, f"{path.name}: needs B_T steps starting at 0 T"
    hits = []
    for i, p in enumerate(t.points):
        E = float(p.get("matrix_E_Pa", E_fixed))
        if abs(p["phi"] - phi) <= rtol * phi and abs(E - E_Pa) <= rtol * E_Pa:
            hits.append(i)
    if len(hits) != B.size:
        axes = {a: list(v) for a, v in t.axes.items() if a in ("phi", "matrix_E_Pa")}
        return None, (f"{path.name} holds {axes or {'phi': list(t.axes['phi'])}} "
                      f"(E {E_fixed:g} Pa unless an axis), not phi = {phi:g}, E = {E_Pa:g} Pa")
    hits.sort(key=lambda i: t.points[i]["B_T"])

    def q(name, comp=None):
        return t.component_values(name, comp)[hits]           # (K, R)

    M_r, M_a = q("M_eff_A_per_m", "z"), q("M_eff_affine_A_per_m")
    E_r = q("E_eff_parallel_Pa")
    E_a = np.broadcast_to(E_r[0], E_r.shape)                   # as placed = the B = 0 state
    x_r, x_a = mu_0 * M_r ** 2 / E_r, mu_0 * M_a ** 2 / E_a
    eps_r, eps_a = q("strain_parallel"), q("strain_affine_parallel")
    man = t.attrs.get("manifest")
    prov = {"table": str(path.relative_to(DATA_DIR.parents[2])
                         if path.is_relative_to(DATA_DIR.parents[2]) else path),
            "study": t.attrs.get("study_name"), "evaluator": t.attrs.get("evaluator"),
            "realizations": int(eps_r.shape[1]), "n_particles": study.get("study", {})
            .get("n_particles"), "voxels": study.get("study", {}).get("voxels"),
            "study_toml": (path.with_suffix(".toml").relative_to(DATA_DIR.parents[2]).as_posix()
                           if path.is_relative_to(DATA_DIR.parents[2])
                           else str(path.with_suffix(".toml"))),
            "git_revision": (_json.loads(man).get("git_revision") if man else None)}
    return Restructuring(path=str(path), phi=phi, E_Pa=E_Pa, B_T=B, d_eps_rve=eps_r - eps_a,
                         d_x=x_r - x_a, eps_rve_relaxed=eps_r, eps_rve_affine=eps_a,
                         x_relaxed=x_r, x_affine=x_a, provenance=prov,
                         M_relaxed_A_per_m=M_r, E_parallel_Pa=E_r), ""


def _shown(path: Path) -> str:
    """A path inside the project as a project-relative POSIX path (reports carry no machine's
    directory); others as given."""
    root = DATA_DIR.parents[2]
    return path.relative_to(root).as_posix() if path.is_relative_to(root) else str(path)


@functools.lru_cache(maxsize=16)
def restructuring_table(phi: float, E_Pa: float, rtol: float = 0.02) -> Restructuring:
    """The relax table computed at this phi and matrix modulus (within ``rtol``).

    Raises :class:`Unavailable` naming the tables found and what they hold, and the command
    that makes one (a study TOML like ``data/relax_diguet2010.toml``).
    """
    why = []
    for path in relax_tables():
        try:
            r, reason = _restructuring_from(path, float(phi), float(E_Pa), rtol)
        except (OSError, KeyError, ValueError, InputError) as exc:
            r, reason = None, f"{path.name}: unreadable ({exc})"
        if r is not None:
            return r
        why.append(reason)
    raise Unavailable(f"no coupled-RVE (relax) table at phi = {phi:g}, E = {E_Pa:g} Pa in "
                      f"{_shown(DATA_DIR)}" + (f" ({'; '.join(why)})" if why else "")
                      + "; make one with `mapsim batch STUDY.toml --out "
                        "homogenize/experiments/data/relax_NAME.h5` (evaluator = \"relax\", "
                        "fem = true; see data/relax_diguet2010.toml)")
