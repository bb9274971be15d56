"""Benchmarks of the FEM cell problems (``mapsim bench --only cell``).

* voxel assembly (one element matrix per phase, BLAS product into 3x3 BSR) against generic
  ``skfem.asm`` of the same periodic matrix (same matrix to round-off);
* the full homogenization (6 unit strains + magnetic case) of a 64^3 RVE against the 60 s budget;
* AMG-CG iterations against the particle/matrix stiffness contrast, with and without deflation of
  the particles' rigid-body modes.
"""
from __future__ import annotations

import resource
import time

import numpy as np
import os
from homogenize import _assembly as A
from homogenize.bench.reference import skfem_reference
from micro.particles import generate_rve
from homogenize.cell import homogenize_rve
from homogenize.cell import Material, homogenize_mesh
from homogenize.mesh import voxelize
import numba


SOLVER_CONFIG = ("CG, relative residual tol 1e-8, deflated by the 6 rigid-body modes of every stiff "
                 "particle; preconditioner: one symmetric AMG V-cycle on a pyamg smoothed-"
                 "aggregation hierarchy (rigid-body near-nullspace, max_coarse 300, splu coarse "
                 "solve); fine level: 1 symmetric multicolour block Gauss-Seidel sweep (numba) "
                 "before and after, numba BSR products; coarse levels: pyamg symmetric block "
                 "Gauss-Seidel; numba assembly")


def _machine() -> dict:

    return {"load_average_1_5_15min": list(os.getloadavg()), "cpu_count": os.cpu_count(),
            "numba_threads": numba.get_num_threads()}


def _peak_rss_GB() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6   # kB on Linux


def _assembly_record(n: int) -> dict:

    rng = np.random.default_rng(0)
    h = 1e-8
    phase = rng.random((n, n, n)) < 0.1
    lam = np.where(phase, 1.2e11, 6.2e6)
    mu = np.where(phase, 8.2e10, 6.9e5)
    A.assemble_bsr(lam, mu, h)      # warm caches (reference matrices, pattern, numba) once
    A.assemble_bsr(lam, mu, h, method="blas")
    A._pattern.cache_clear()
    t0 = time.perf_counter()
    K = A.assemble_bsr(lam, mu, h)
    t_vox = time.perf_counter() - t0
    t0 = time.perf_counter()
    A.assemble_bsr(lam, mu, h, method="blas")
    t_blas = time.perf_counter() - t0

    t0 = time.perf_counter()
    P, Ks, _mesh = skfem_reference(lam, mu, h, sri=True)
    Kref = (P.T @ Ks @ P).tocsr()
    t_ref = time.perf_counter() - t0
    err = abs(K.tocsr() - Kref).max() / abs(Kref).max()
    return {"name": f"cell/assembly voxel-BSR {n}^3", "n": 3 * n ** 3, "seconds": t_vox,
            "reference": "skfem.asm generic (Q1 hex, SRI) + periodic fold", "reference_seconds": t_ref,
            "ratio": t_ref / t_vox, "max_rel_error": float(err),
            "dof_per_s": 3 * n ** 3 / t_vox, "reference_dof_per_s": 3 * n ** 3 / t_ref,
            "blas_path_seconds": t_blas, "blas_path_dof_per_s": 3 * n ** 3 / t_blas,
            **_machine()}


def _rve(voxels: int, seed: int = 1):
    # seed-paper distribution (mean 25 nm in [10, 50] nm) at 3.5 vol%; the number of particles
    # is chosen so that the mean particle radius is ~2.5 voxels
    n_part = max(8, int(round(0.035 * (voxels / 2.5) ** 3 / (4.0 / 3.0 * np.pi) / 1.4)))
    return generate_rve(0.035, n_part, seed)


def _full_record(voxels: int) -> dict:
    rve = _rve(voxels)
    rng = np.random.default_rng(2)
    forces = None
    virial = None
    try:
        from micro.dipoles import solve
        st = solve(rve, 0.1, 1.78, "frohlich-kennelly")
        forces = st.total_force_N
        virial = np.asarray(st.virial_stress_Pa)
    except ModuleNotFoundError:
        forces = rng.normal(size=(rve.n, 3)) * 1e-15
    t0 = time.perf_counter()
    r = homogenize_rve(rve, voxels, forces_N=forces, virial_stress_Pa=virial)
    sec = time.perf_counter() - t0
    return {"name": f"cell/homogenize {voxels}^3 (6 strains + magnetic)", "n": r.n_dof,
            "seconds": sec, "reference": "60 s budget (issue 5)", "reference_seconds": 60.0,
            "ratio": 60.0 / sec, "max_rel_error": max(r.residuals.values()),
            "peak_rss_GB": _peak_rss_GB(), "iterations": r.iterations,
            "timings_s": r.timings_s, "n_particles": r.n_particles,
            "n_unresolved": r.n_unresolved, "phi_voxel": r.phi_voxel,
            "E_eff_Pa": r.E_eff_Pa, "anisotropy_index": r.anisotropy_index,
            "solver_configuration": SOLVER_CONFIG, **_machine()}


def _contrast_records(voxels: int) -> list[dict]:
    rve = _rve(voxels, seed=3)
    mesh = voxelize(rve, voxels)
    out = []
    base = None
    for contrast in (1.0, 1e1, 1e2, 1e3, 1e4, 1e5):
        rec = {}
        for deflate in (True, False):
            t0 = time.perf_counter()
            r = homogenize_mesh(mesh, particle=Material(2e6 * contrast, 0.29), deflate=deflate,
                                cases=("e11", "g12"), tol=1e-8)
            rec[deflate] = (time.perf_counter() - t0, r)
        (s1, r1), (s0, r0) = rec[True], rec[False]
        it1, it0 = max(r1.iterations.values()), max(r0.iterations.values())
        base = it1 if base is None else base
        out.append({"name": f"cell/AMG-CG iterations contrast {contrast:.0e} {voxels}^3",
                    "n": r1.n_dof, "seconds": s1, "reference": "same without deflation",
                    "reference_seconds": s0, "ratio": s0 / s1,
                    "max_rel_error": float(abs(r1.C_eff_Pa[0, 0] - r0.C_eff_Pa[0, 0])
                                           / r0.C_eff_Pa[0, 0]),
                    "contrast": contrast, "iterations_deflated": it1, "iterations_plain": it0,
                    "iterations_growth_vs_contrast_1": it1 / base})
    return out


def bench_records(quick: bool) -> list[dict]:
    recs = [_assembly_record(12 if quick else 32)]
    recs += _contrast_records(12 if quick else 24)
    recs.append(_full_record(16 if quick else 64))
    return recs
