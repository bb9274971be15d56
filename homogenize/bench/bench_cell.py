"""Benchmarks of the FEM cell problems (``mapsim bench --only cell``).

* voxel assembly (one element matrix per phase, BLAS product into 3x3 BSR) against generic
  ``skfem.asm`` of the same periodic matrix (same matrix to round-off);
* the full homogenization (6 unit strains + magnetic case) of a 64^3 RVE against the 60 s budget;
* AMG-CG iterations against the particle/matrix stiffness contrast, with and without deflation of
  the particles' rigid-body modes;
* the matrix-free solver (geometric multigrid) against the assembled one at 32^3-128^3: time,
  peak memory, iterations, E_eff agreement.
"""
from __future__ import annotations

import resource
import time

import numpy as np
import os
from homogenize.voxels import _assembly as A
from homogenize.voxels import _budget
from homogenize.bench.reference import skfem_reference
from micro.materials import FE, PDMS
from micro.particles import generate_rve
from homogenize.cell.problem import homogenize_rve, isotropic_projection
from homogenize.cell.problem import Material, homogenize_mesh
from homogenize.voxels.mesh import voxelize
import numba

__all__ = ["bench_records", "bench_rve", "SOLVER_CONFIG"]

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


def _residual_fields(r) -> dict:
    """The final relative residuals of a cell result: the strains' largest, and the magnetic
    column's with the tolerance it stopped at (sqrt(tol), homogenize.cell.problem.magnetic_tol)."""
    return {"max_residual": max(v for k, v in r.residuals.items() if k != "magnetic"),
            "magnetic_residual": r.residuals.get("magnetic"),
            "tol_magnetic": r.settings["tol_magnetic"]}


def bench_rve(voxels: int, seed: int = 1):
    """The benchmark RVE of ``mapsim bench`` (and of the solver studies in ``results/cell``): the
    seed paper's size distribution (mean 25 nm in [10, 50] nm) at 3.5 vol%, with the number of
    particles chosen so that the mean particle radius is ~2.5 voxels on a ``voxels``^3 grid;
    ``seed``: the placement's random seed. Returns a :class:`micro.RVE`."""
    n_part = max(8, int(round(0.035 * (voxels / 2.5) ** 3 / (4.0 / 3.0 * np.pi) / 1.4)))
    return generate_rve(0.035, n_part, seed)


def _full_record(voxels: int) -> dict:
    rve = bench_rve(voxels)
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
    res = _residual_fields(r)
    return {"name": f"cell/homogenize {voxels}^3 (6 strains + magnetic)", "n": r.n_dof,
            "seconds": sec, "reference": "60 s budget (issue 5)", "reference_seconds": 60.0,
            "ratio": 60.0 / sec,
            "max_rel_error": res.pop("max_residual"), **res,
            "peak_rss_GB": _peak_rss_GB(), "iterations": r.iterations,
            "timings_s": r.timings_s, "n_particles": r.n_particles,
            "n_unresolved": r.n_unresolved, "phi_voxel": r.phi_voxel,
            "E_eff_Pa": r.E_eff_Pa, "anisotropy_index": r.anisotropy_index,
            "solver_configuration": SOLVER_CONFIG, **_machine()}


def _contrast_records(voxels: int) -> list[dict]:
    rve = bench_rve(voxels, seed=3)
    mesh = voxelize(rve, voxels)
    out = []
    base = None
    for contrast in (1.0, 1e1, 1e2, 1e3, 1e4, 1e5):
        rec = {}
        for deflate in (True, False):
            t0 = time.perf_counter()
            r = homogenize_mesh(mesh, particle=Material(PDMS.E_Pa * contrast, FE.nu),
                                deflate=deflate,
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


def _add_growth(rec: dict, prev: dict | None, n: int, run: dict) -> dict:
    """Add to ``rec`` how time and peak memory of ``run`` grew against the previous grid
    ``prev``; returns this grid's entry for the next call."""
    if prev is not None:
        rec["growth_vs"] = f"{prev['n_vox']}^3 (x{(n / prev['n_vox']) ** 3:g} voxels)"
        rec["time_growth"] = run["seconds"] / prev["seconds"]
        rec["memory_growth"] = run["peak_rss_GB"] / prev["peak_rss_GB"]
    return {"n_vox": n, "seconds": run["seconds"], "peak_rss_GB": run["peak_rss_GB"]}


def _method_records(sizes) -> list[dict]:
    """Composite voxels against the staircase (the reference path) on the same RVE: time and
    peak memory (each run in its own process under /usr/bin/time), and their growth with size."""
    out, prev = [], None
    for n in sizes:
        comp = _run_peer("full-composite", n, 1, None)
        cent = _run_peer("full-centre", n, 1, None)
        if "error" in comp or "error" in cent:
            out.append({"name": f"cell/homogenize {n}^3 composite vs centre", "n": 3 * n ** 3,
                        "seconds": None, "reference": "method=centre", "reference_seconds": None,
                        "ratio": None, "max_rel_error": None,
                        "skipped": comp.get("error") or cent.get("error")})
            continue
        rec = {"name": f"cell/homogenize {n}^3 (6 strains + magnetic) composite vs centre",
               "n": 3 * n ** 3, "seconds": comp["seconds"], "reference": "method=centre "
               "(staircase), same RVE and solver", "reference_seconds": cent["seconds"],
               "ratio": cent["seconds"] / comp["seconds"],
               "max_rel_error": None, "E_eff_Pa": comp["E_eff_Pa"],
               "E_eff_centre_Pa": cent["E_eff_Pa"],
               "peak_rss_GB": comp["peak_rss_GB"], "reference_peak_rss_GB": cent["peak_rss_GB"],
               "memory_ratio": cent["peak_rss_GB"] / comp["peak_rss_GB"],
               "iterations": comp["iterations"], "timings_s": comp["timings_s"],
               "memory_estimate_GB": _budget.assembled_cell_bytes(n) / 1e9, **_machine()}
        prev = _add_growth(rec, prev, n, comp)
        out.append(rec)
    return out


#: issue 15 targets of the matrix-free solver (6 strains + magnetic, this 2-core machine)
MATFREE_TARGETS = {64: (20.0, None), 128: (300.0, 6.0)}     # voxels: (seconds, GB)
#: largest grid on which the assembled solver is run next to the matrix-free one
ASSEMBLED_MAX_VOXELS = 64


def _matfree_records(sizes) -> list[dict]:
    """solver="matrix-free" against the assembled solver ("fast") on the same RVE (6 strains +
    magnetic, tol 1e-6), each run in its own process: seconds, peak RSS, iterations, E_eff
    agreement, and the growth of time and memory with the grid. Above
    :data:`ASSEMBLED_MAX_VOXELS`, where the assembled matrix does not fit, the reference is the
    matrix-free solver without particle patches (``SolverOptions(patch_shell_voxels=None)``,
    the solver of session 13), which the patches are built for there."""
    out, prev = [], None
    for n in sizes:
        m = _run_peer("solver-matrix-free", n, 1, None)
        assembled = n <= ASSEMBLED_MAX_VOXELS
        a = _run_peer("solver-fast" if assembled else "solver-matrix-free-nopatch", n, 1, None)
        name = (f"cell/matrix-free {n}^3 (6 strains + magnetic) vs "
                + ("assembled" if assembled else "matrix-free without particle patches"))
        if "error" in m:
            out.append({"name": name, "n": 3 * n ** 3, "seconds": None,
                        "reference": "solver=fast", "reference_seconds": None, "ratio": None,
                        "max_rel_error": None, "skipped": m["error"], **_machine()})
            continue
        t_target, gb_target = MATFREE_TARGETS.get(n, (None, None))
        rec = {"name": name, "n": 3 * n ** 3, "seconds": m["seconds"],
               "reference": ("solver=fast (assembled BSR, pyamg SA), same RVE" if assembled else
                             "solver=matrix-free without particle patches, same RVE"),
               "reference_seconds": a.get("seconds"),
               "ratio": a["seconds"] / m["seconds"] if "seconds" in a else None,
               "max_rel_error": (abs(m["E_eff_Pa"] - a["E_eff_Pa"]) / a["E_eff_Pa"]
                                 if "E_eff_Pa" in a else None),
               "E_eff_Pa": m["E_eff_Pa"], "reference_E_eff_Pa": a.get("E_eff_Pa"),
               "peak_rss_GB": m["peak_rss_GB"], "reference_peak_rss_GB": a.get("peak_rss_GB"),
               "iterations": m["iterations"], "reference_iterations": a.get("iterations"),
               "timings_s": m["timings_s"], "reference_timings_s": a.get("timings_s"),
               "max_residual": m["max_residual"],
               "magnetic_residual": m.get("magnetic_residual"),
               "tol_magnetic": m.get("tol_magnetic"), "n_particles": m["n_particles"],
               "patch_shell_voxels": m.get("patch_shell_voxels"),
               "patched_particles": m.get("patched_particles"), "tol_cg": m.get("tol_cg"),
               "memory_estimate_GB": _budget.cell_memory_bytes(n, "matrix-free", 7) / 1e9,
               "target_seconds": t_target, "target_peak_rss_GB": gb_target,
               **({"reference_skipped": a["error"]} if "error" in a else {}), **_machine()}
        prev = _add_growth(rec, prev, n, m)
        out.append(rec)
    return out


def choice_rve(voxels: int, phi: float, dispersity: str, seed: int = 1):
    """The RVEs of :func:`_solver_choice_records`: volume fraction ``phi``, radii monodisperse
    (25 nm) or the seed's lognormal (mean 25 nm in [10, 50] nm, gsd 1.4), as many particles as
    give a mean radius of ~2.5 voxels on a ``voxels``^3 grid (at least 8)."""
    from micro.particles import Monodisperse, default_distribution
    mono = dispersity == "monodisperse"
    dist = Monodisperse(25e-9) if mono else default_distribution()
    # <r^3> / <r>^3: 1 monodisperse, ~1.4 for the seed's lognormal (as bench_rve)
    n_part = max(8, int(round(phi * (voxels / 2.5) ** 3 / (4.0 / 3.0 * np.pi)
                              / (1.0 if mono else 1.4))))
    return generate_rve(phi, n_part, seed, distribution=dist)


#: the grids, volume fractions and radius distributions of the solver choice (issue 37)
CHOICE_SIZES, CHOICE_PHIS = (16, 32, 64), (0.01, 0.05, 0.1, 0.3)
CHOICE_DISPERSITIES = ("monodisperse", "lognormal")


def _solver_choice_records(sizes=CHOICE_SIZES, phis=CHOICE_PHIS,
                           dispersities=CHOICE_DISPERSITIES, matfree_only=(),
                           patches: bool = False) -> list[dict]:
    """solver="matrix-free" against solver="fast" (the assembled BSR + pyamg SA) on the same RVE
    (:func:`choice_rve`; 6 strains + random particle forces, tol 1e-6), each run in its own
    process (peak RSS): what ``solver="auto"`` picks (homogenize.cell.problem._choose_solver) rests on
    these. ``ratio`` = fast seconds / matrix-free seconds; ``max_rel_error`` = the largest
    C_eff difference over max |C_eff|; ``stress_mag_rel_diff`` likewise for the magnetic stress
    (its column stops at sqrt(tol)). Grids in ``matfree_only`` run the matrix-free solver alone
    (the assembled one may not fit). ``patches``: also the matrix-free solver with a particle
    patch on every particle (keys ``patches_*``; ``patches_ratio`` = fast seconds / its
    seconds)."""
    from homogenize.cell.problem import _choose_solver, _plain_particles, _options
    from micro import InputError
    out = []
    for n in sizes:
        for phi in phis:
            for disp in dispersities:
                name = f"cell/solver choice {n}^3 phi {phi:g} {disp} (6 strains + magnetic)"
                m = _run_peer(f"choice|matrix-free|{phi!r}|{disp}", n, 1, None)
                a = ({"error": "not run (matrix-free only at this grid)"} if n in matfree_only
                     else _run_peer(f"choice|fast|{phi!r}|{disp}", n, 1, None))
                try:        # what solver="auto" picks for this RVE (none if it cannot be placed)
                    mesh = voxelize(choice_rve(n, phi, disp), n)
                    auto, reason = _choose_solver(
                        "auto", n, 7, reason=True, phi=float(mesh.fraction.mean()),
                        plain_particles=_plain_particles(mesh, _options(None)))
                except InputError as exc:
                    auto, reason = None, f"placement: {exc}"
                    m = {"error": reason}
                rec = {"name": name, "n": 3 * n ** 3, "voxels": n, "phi": phi,
                       "dispersity": disp, "seconds": m.get("seconds"),
                       "reference": "solver=fast (assembled BSR, pyamg SA), same RVE and tol",
                       "reference_seconds": a.get("seconds"),
                       "ratio": (a["seconds"] / m["seconds"]
                                 if "seconds" in a and "seconds" in m else None),
                       "max_rel_error": None, "auto_choice": auto, "auto_reason": reason,
                       **_machine()}
                if "error" in m:
                    rec["skipped"] = m["error"]
                    out.append(rec)
                    continue
                if "C_eff_Pa" in a:
                    Cm, Ca = np.array(m["C_eff_Pa"]), np.array(a["C_eff_Pa"])
                    Sm, Sa = np.array(m["stress_mag_Pa"]), np.array(a["stress_mag_Pa"])
                    rec["max_rel_error"] = float(np.abs(Cm - Ca).max() / np.abs(Ca).max())
                    rec["stress_mag_rel_diff"] = float(np.abs(Sm - Sa).max() / np.abs(Sa).max())
                rec.update({
                    "peak_rss_GB": m["peak_rss_GB"], "reference_peak_rss_GB": a.get("peak_rss_GB"),
                    "memory_ratio": (a["peak_rss_GB"] / m["peak_rss_GB"]
                                     if a.get("peak_rss_GB") and m["peak_rss_GB"] else None),
                    "E_eff_Pa": m["E_eff_Pa"], "reference_E_eff_Pa": a.get("E_eff_Pa"),
                    "iterations": m["iterations"], "reference_iterations": a.get("iterations"),
                    "timings_s": m["timings_s"], "reference_timings_s": a.get("timings_s"),
                    "max_residual": m["max_residual"], "tol_cg": m.get("tol_cg"),
                    "reference_max_residual": a.get("max_residual"),
                    "n_particles": m["n_particles"], "phi_voxel": m["phi_voxel"],
                    "mean_radius_voxels": m["mean_radius_voxels"],
                    "patched_particles": m.get("patched_particles"),
                    **({"reference_skipped": a["error"]} if "error" in a else {})})
                if patches:
                    q = _run_peer(f"choice|matrix-free-patches|{phi!r}|{disp}", n, 1, None)
                    if "error" in q:
                        rec["patches_skipped"] = q["error"]
                    else:
                        Cq = np.array(q["C_eff_Pa"])
                        rec.update({
                            "patches_seconds": q["seconds"],
                            "patches_ratio": (a["seconds"] / q["seconds"]
                                              if "seconds" in a else None),
                            "patches_peak_rss_GB": q["peak_rss_GB"],
                            "patches_iterations": q["iterations"],
                            "patches_patched_particles": q.get("patched_particles"),
                            "patches_max_rel_error": (
                                float(np.abs(Cq - Ca).max() / np.abs(Ca).max())
                                if "C_eff_Pa" in a else None)})
                out.append(rec)
    return out


def bench_records(quick: bool) -> list[dict]:
    recs = [_assembly_record(12 if quick else 32)]
    recs += _contrast_records(12 if quick else 24)
    recs.append(_full_record(16 if quick else 64))
    recs += _method_records((12, 16) if quick else (32, 64))
    recs += _matfree_records((12, 16) if quick else (32, 64, 128))
    recs += _peer_records(15 if quick else 33)
    recs += (_solver_choice_records((12, 16), (0.05,), patches=True) if quick
             else _solver_choice_records(patches=True))
    return recs


# ------------------------------------------------------------------------------------------------
# muSpectre peer (FFT-based homogenization) on the same voxel microstructure
# ------------------------------------------------------------------------------------------------

PEER_TOL = 1e-8


def _voxel_moduli(voxels: int, seed: int, rve_voxels: int | None = None):
    """(E [Pa], nu) per voxel, shape (n, n, n) indexed [k, j, i], of the composite-voxel model
    mapsim solves: particle / matrix, and in cut voxels the Reuss average (isotropic: harmonic
    bulk and shear moduli) -- exactly the stiffness field of ``method="composite"``.
    ``rve_voxels``: the grid the RVE is drawn for (:func:`bench_rve`; default ``voxels``), so
    that neighbouring grids (64^3 and 65^3) voxelize the same particles."""
    from micro.materials import FE, PDMS, elastic
    from homogenize.cell._effective_media import bulk_shear
    mesh = voxelize(bench_rve(rve_voxels or voxels, seed), voxels, method="composite")
    f = mesh.fraction
    Km, Gm = bulk_shear(*(elastic(PDMS).E_Pa, elastic(PDMS).nu))
    Kp, Gp = bulk_shear(*(elastic(FE).E_Pa, elastic(FE).nu))
    K = 1.0 / (f / Kp + (1.0 - f) / Km)
    G = 1.0 / (f / Gp + (1.0 - f) / Gm)
    E = 9.0 * K * G / (3.0 * K + G)
    nu = (3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G))
    return mesh, E, nu


def _near_contacts(mesh) -> dict:
    """Voxel pairs of two different particles (fraction >= 0.5) that touch: through a face, or
    only through an edge or a corner node (which a nodal FE bonds and a voxel-centred FFT
    strain field barely does)."""
    own = np.where(mesh.fraction >= 0.5, mesh.owner, -1)
    face = other = 0
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if (dz, dy, dx) <= (0, 0, 0):
                    continue
                nb = np.roll(own, shift=(-dz, -dy, -dx), axis=(0, 1, 2))
                c = int(np.sum((own >= 0) & (nb >= 0) & (own != nb)))
                if abs(dz) + abs(dy) + abs(dx) == 1:
                    face += c
                else:
                    other += c
    return {"face_contacts": face, "edge_or_corner_contacts": other}


def _peer_worker(tool: str, voxels: int, seed: int, out: str) -> None:
    """Run one tool on the shared microstructure (in a child process, for its peak memory)."""
    import json
    mesh, E, nu = _voxel_moduli(voxels, seed)
    t0 = time.perf_counter()
    extra = {}
    if tool.startswith("solver-"):               # 6 strains + magnetic load, given solver
        solver = tool[7:]
        options = None
        if solver == "matrix-free-nopatch":      # the matrix-free solver of session 13
            from homogenize.solvers import SolverOptions
            options = SolverOptions(patch_shell_voxels=None)
            solver = "matrix-free"
        rve = bench_rve(voxels, seed)
        forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
        t0 = time.perf_counter()
        r = homogenize_rve(rve, voxels, forces_N=forces, solver=solver, options=options)
        C = r.C_eff_Pa
        extra = {"iterations": r.iterations, "E_eff_Pa": r.E_eff_Pa, "timings_s": r.timings_s,
                 "n_particles": r.n_particles, "solver": r.settings["solver"],
                 **{k: r.settings.get(k) for k in ("patch_shell_voxels", "patched_particles",
                                                   "tol_cg")},
                 **_residual_fields(r)}
    elif tool.startswith("choice|"):             # solver choice: "choice|solver|phi|dispersity"
        _, solver, phi, dispersity = tool.split("|")
        rve = choice_rve(voxels, float(phi), dispersity, seed)
        forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
        opts = None
        if solver == "matrix-free-patches":     # a particle patch on every particle
            from homogenize.solvers import SolverOptions
            solver, opts = "matrix-free", SolverOptions().replace(patch_min_particles=1)
        t0 = time.perf_counter()
        r = homogenize_rve(rve, voxels, forces_N=forces, solver=solver, options=opts)
        C = r.C_eff_Pa
        extra = {"iterations": r.iterations, "E_eff_Pa": r.E_eff_Pa, "timings_s": r.timings_s,
                 "n_particles": r.n_particles, "phi_voxel": r.phi_voxel,
                 "stress_mag_Pa": np.asarray(r.stress_mag_Pa).tolist(),
                 "mean_radius_voxels": float(np.mean(rve.radii_m) / rve.box_m * voxels),
                 **{k: r.settings.get(k) for k in ("solver", "solver_reason", "patched_particles",
                                                   "tol_cg")},
                 **_residual_fields(r)}
    elif tool.startswith("full-"):               # 6 strains + magnetic load, given method
        rve = bench_rve(voxels, seed)
        forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
        t0 = time.perf_counter()
        r = homogenize_rve(rve, voxels, forces_N=forces, method=tool[5:])
        C = r.C_eff_Pa
        extra = {"iterations": max(r.iterations.values()), "E_eff_Pa": r.E_eff_Pa,
                 "timings_s": r.timings_s}
    elif tool == "mapsim":
        r = homogenize_mesh(mesh, tol=PEER_TOL)
        C = r.C_eff_Pa
        extra = {"iterations": max(r.iterations.values())}
    else:
        C, fev, _ = muspectre_stiffness(E, nu, tool.split("-")[1], PEER_TOL)
        extra = {"cg_matvecs_total": fev}
    sec = time.perf_counter() - t0
    with open(out, "w") as fh:
        json.dump({"C_eff_Pa": C.tolist(), "seconds": sec, **extra}, fh)


def muspectre_stiffness(E, nu, gradient: str, tol: float, maxiter: int = 20000,
                        cases: int = 6, timings: dict | None = None):
    """muSpectre 0.27 on the voxel moduli ``E`` [Pa], ``nu`` (n, n, n; [k, j, i], odd n): small
    strain, strain control, ``gradient`` "central" (finite-difference stencil) or "fourier"; the
    first ``cases`` unit strains (e11, e22, e33, 2 e23, 2 e13, 2 e12) as successive load steps of
    one Newton-CG solver, CG to the relative residual ``tol`` in at most ``maxiter`` iterations.
    Returns (C [Pa] (6, 6), columns beyond ``cases`` zero; CG matrix-vector products in all;
    seconds of the set-up (cell, material, solver)). ``timings``: a dict that gets "setup" [s]
    before the solve starts (kept when a capped CG raises)."""
    import muFFT
    import muSpectre as msp
    t0 = time.perf_counter()
    n = E.shape[0]
    cell = msp.cell.CellData.make([n, n, n], [1.0, 1.0, 1.0])
    cell.nb_quad_pts = 1
    mat = msp.material.MaterialLinearElastic4_3d.make(cell, "voxels")
    for i, px in cell.pixels.enumerate():       # px = (x, y, z); our arrays are [z, y, x]
        mat.add_pixel(i, float(E[px[2], px[1], px[0]]), float(nu[px[2], px[1], px[0]]))
    krylov = msp.solvers.KrylovSolverCG(tol, maxiter, msp.Verbosity.Silent)
    grad = list(muFFT.Stencils3D.central) if gradient == "central" else None
    args = (cell, krylov, msp.Verbosity.Silent, tol, tol, maxiter)
    solver = (msp.solvers.SolverNewtonCG(*args, grad, [1.0]) if grad
              else msp.solvers.SolverNewtonCG(*args))
    solver.formulation = msp.Formulation.small_strain
    solver.initialise_cell()
    setup = time.perf_counter() - t0
    if timings is not None:
        timings["setup"] = setup
    V = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
    C = np.zeros((6, 6))
    fev = 0
    for b, (i, j) in enumerate(V[:cases]):
        eps = np.zeros((3, 3))
        eps[i, j] = eps[j, i] = 1e-3 if i == j else 0.5e-3     # engineering shear 1e-3
        res = solver.solve_load_increment(eps)
        sig = np.asarray(res.stress).reshape(3, 3, -1).mean(axis=-1)
        for a, (p, q) in enumerate(V):
            C[a, b] = sig[p, q] / 1e-3
        fev = int(res.nb_fev)
    if cases == 6:
        C = 0.5 * (C + C.T)
    return C, fev, setup


def _run_peer(tool: str, voxels: int, seed: int, threads: int | None,
              worker: str = "homogenize.bench.bench_cell:_peer_worker") -> dict:
    """Run ``worker`` (default :func:`_peer_worker`; "module:function" taking (tool, voxels,
    seed, out)) under ``/usr/bin/time -v`` in a child process: result, seconds, peak RSS [GB]."""
    import json
    import subprocess
    import sys
    import tempfile
    env = dict(os.environ)
    if threads:
        env.update(NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads),
                   OPENBLAS_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "peer.json")
        module, func = worker.split(":")
        code = (f"from {module} import {func}; "
                f"{func}({tool!r}, {voxels}, {seed}, {out!r})")
        p = subprocess.run(["/usr/bin/time", "-v", sys.executable, "-c", code], env=env,
                           capture_output=True, text=True)
        if p.returncode != 0:
            # the child's last line before /usr/bin/time's report (its exception)
            lines = p.stderr.strip().splitlines()
            cut = [i for i, ln in enumerate(lines) if "Command being timed" in ln]
            lines = lines[:cut[0]] if cut else lines
            return {"error": lines[-1].strip() if lines else "failed"}
        rss = [ln for ln in p.stderr.splitlines() if "Maximum resident set size" in ln]
        with open(out) as fh:
            res = json.load(fh)
    res["peak_rss_GB"] = float(rss[0].split(":")[1]) / 1e6 if rss else None
    return res


def _peer_records(voxels: int, seed: int = 1) -> list[dict]:
    """muSpectre 0.27.0 (FFT, small strain, CG; serial PocketFFT wheel) against mapsim on the
    same composite-voxel moduli, odd grid (muSpectre's stencils need one)."""
    try:
        import muSpectre  # noqa: F401
    except ImportError as exc:
        return [{"name": f"cell/peer muSpectre {voxels}^3", "n": 3 * voxels ** 3,
                 "seconds": None, "reference": "muSpectre", "reference_seconds": None,
                 "ratio": None, "max_rel_error": None,
                 "skipped": f"muSpectre not installed ({exc}); pip install .[peers]"}]
    mesh, _, _ = _voxel_moduli(voxels, seed)
    contacts = _near_contacts(mesh)
    ours = {t: _run_peer("mapsim", voxels, seed, t) for t in (1, None)}
    recs = []
    for tool in ("muspectre-central", "muspectre-fourier"):
        peer = _run_peer(tool, voxels, seed, 1)
        for threads, me in ours.items():
            name = (f"cell/peer {tool} vs mapsim ({'1 thread' if threads else 'default threads'}) "
                    f"{voxels}^3 composite voxels")
            if "error" in peer or "error" in me:
                recs.append({"name": name, "n": 3 * voxels ** 3, "seconds": None,
                             "reference": tool, "reference_seconds": None, "ratio": None,
                             "max_rel_error": None,
                             "skipped": peer.get("error") or me.get("error")})
                continue
            Cm, Cp = np.array(me["C_eff_Pa"]), np.array(peer["C_eff_Pa"])
            Em, Ep = isotropic_projection(Cm)[0], isotropic_projection(Cp)[0]
            recs.append({
                "name": name, "n": 3 * voxels ** 3, "seconds": me["seconds"],
                "reference": f"muSpectre 0.27.0 {tool.split('-')[1]} gradient, serial",
                "reference_seconds": peer["seconds"], "ratio": peer["seconds"] / me["seconds"],
                "max_rel_error": float(np.abs(Cm - Cp).max() / np.abs(Cp).max()),
                "E_eff_Pa": Em, "E_eff_peer_Pa": Ep, "E_eff_rel_diff": Em / Ep - 1.0,
                "peak_rss_GB": me["peak_rss_GB"], "peer_peak_rss_GB": peer["peak_rss_GB"],
                "memory_ratio": peer["peak_rss_GB"] / me["peak_rss_GB"],
                "tolerance": f"both CG relative residual {PEER_TOL:g}; mapsim C_eff variational "
                             "(error ~ residual^2), muSpectre C_eff from the mean stress "
                             "(error ~ residual)",
                "peer_cg_matvecs": peer.get("cg_matvecs_total"),
                "mapsim_iterations": me.get("iterations"), **contacts,
                "note": "same voxel moduli; the difference is discretization (nodal trilinear "
                        "FE vs voxel-centred FFT strain), not the solver", **_machine()})
    return recs
