"""The cell FEM against muSpectre at the sizes users run (``mapsim bench --only peer``).

Issue 37 item 5: mapsim's default cell solver against muSpectre 0.27 (FFT, small strain, CG;
the PyPI wheel is serial: PocketFFT, no MPI or OpenMP) on the closest grids each supports:
mapsim's default on even grids (64^3, 128^3: the matrix-free multigrid) and on the odd grid
(65^3: the stated fall-back), muSpectre on odd grids only (65^3, 129^3; its stencils need
one). One RVE per pair (:func:`homogenize.bench.bench_cell.bench_rve` drawn for the even grid),
voxelized on both grids with composite voxels; the six unit strains; each tool in its own
child process under ``/usr/bin/time -v`` (wall time of the solve inside it, peak RSS of the
whole process); mapsim with ``NUMBA_NUM_THREADS=1`` and with its default threads.

Both CGs stop at the relative residual 1e-6 (mapsim's default). Their C_eff do not carry the
same error at the same residual: mapsim's is variational (error ~ residual^2), muSpectre's
comes from the mean stress (error ~ residual); ``peer_error_estimate`` gives muSpectre's from
the same solve at 1e-8 on the smallest grid of the run.

A full muSpectre solve at 129^3 takes hours on this wheel (about 7500 CG products of ~1 s), so
at the largest grid muSpectre runs ``CAPPED_ITERATIONS`` CG iterations of one load case: its
peak memory is measured (the fields are allocated at set-up), its time is PROJECTED as set-up
+ (CG products of the full solve on the next grid down, 65^3) x (seconds per product measured
at 129^3), and the record says so (``peer_seconds_projected``). The full mode runs about
35 min (33 min measured); ``--quick`` runs 16^3 / 17^3 in full.
"""
from __future__ import annotations

import time

import numpy as np

from homogenize.bench.bench_cell import (_machine, _run_peer, _voxel_moduli, bench_rve,
                                         muspectre_stiffness)
from homogenize.cell.problem import homogenize_mesh, isotropic_projection
from homogenize.voxels.mesh import voxelize

__all__ = ["bench_records", "PEER_TOL", "CAPPED_ITERATIONS"]

#: both CGs' relative residual (mapsim's default ``tol``)
PEER_TOL = 1e-6
#: CG iterations of muSpectre's one capped load case at the largest grid
CAPPED_ITERATIONS = 40
WORKER = "homogenize.bench.bench_peer:_worker"


def _worker(tool: str, voxels: int, seed: int, out: str) -> None:
    """One tool in a child process. ``tool``: "mapsim|R" (mapsim's default solver and tol on
    the grid ``voxels`` of bench_rve(R)), "muspectre|R|TOL" (six cases to TOL) or
    "muspectre-capped|R" (:data:`CAPPED_ITERATIONS` CG iterations of one case)."""
    import json
    kind, rve_voxels, *rest = tool.split("|")
    rve_voxels = int(rve_voxels)
    res = {}
    if kind == "mapsim":
        mesh = voxelize(bench_rve(rve_voxels, seed), voxels, method="composite")
        t0 = time.perf_counter()
        r = homogenize_mesh(mesh)
        res = {"seconds": time.perf_counter() - t0, "C_eff_Pa": r.C_eff_Pa.tolist(),
               "solver": r.settings["solver"], "solver_reason": r.settings.get("solver_reason"),
               "iterations": r.iterations, "timings_s": r.timings_s,
               "max_residual": max(r.residuals.values())}
    elif kind == "muspectre":
        _, E, nu = _voxel_moduli(voxels, seed, rve_voxels)
        t0 = time.perf_counter()
        C, fev, setup = muspectre_stiffness(E, nu, "fourier", float(rest[0]))
        res = {"seconds": time.perf_counter() - t0, "C_eff_Pa": C.tolist(),
               "cg_matvecs_total": fev, "setup_seconds": setup}
    elif kind == "muspectre-capped":
        _, E, nu = _voxel_moduli(voxels, seed, rve_voxels)
        t0 = time.perf_counter()
        tim = {}
        try:
            muspectre_stiffness(E, nu, "fourier", 1e-30, maxiter=CAPPED_ITERATIONS, cases=1,
                                timings=tim)
        except RuntimeError as exc:              # "Conjugate gradient has not converged"
            if "not converged" not in str(exc):
                raise
        total = time.perf_counter() - t0
        res = {"seconds": total, "setup_seconds": tim["setup"],
               "seconds_per_matvec": (total - tim["setup"]) / CAPPED_ITERATIONS}
    with open(out, "w") as fh:
        json.dump(res, fh)


def _E(C) -> float:
    return float(isotropic_projection(np.asarray(C))[0])


def _peer_error_record(rve_voxels: int, voxels: int, seed: int) -> dict:
    """muSpectre's own C_eff error at :data:`PEER_TOL`: the same solve to 1e-8, on a small odd
    grid of the same RVE (a full solve to 1e-8 on the large grids would take hours)."""
    at_tol = _run_peer(f"muspectre|{rve_voxels}|{PEER_TOL:g}", voxels, seed, 1, WORKER)
    tight = _run_peer(f"muspectre|{rve_voxels}|1e-8", voxels, seed, 1, WORKER)
    name = f"peer/muSpectre C_eff error at relative residual {PEER_TOL:g} ({voxels}^3)"
    if "error" in at_tol or "error" in tight:
        return {"name": name, "n": 3 * voxels ** 3, "seconds": None, "reference": "muSpectre",
                "reference_seconds": None, "ratio": None, "max_rel_error": None,
                "skipped": at_tol.get("error") or tight.get("error")}
    Ct, Ca = np.asarray(tight["C_eff_Pa"]), np.asarray(at_tol["C_eff_Pa"])
    return {"name": name, "n": 3 * voxels ** 3, "seconds": at_tol["seconds"],
            "reference": "the same muSpectre solve to relative residual 1e-8",
            "reference_seconds": tight["seconds"], "ratio": tight["seconds"] / at_tol["seconds"],
            "max_rel_error": float(np.abs(Ca - Ct).max() / np.abs(Ct).max()),
            "E_eff_rel_error": _E(Ca) / _E(Ct) - 1.0,
            "cg_matvecs": at_tol["cg_matvecs_total"],
            "reference_cg_matvecs": tight["cg_matvecs_total"]}


def bench_records(quick: bool) -> list[dict]:
    try:
        import muSpectre  # noqa: F401
    except ImportError as exc:
        return [{"name": "peer/muSpectre", "n": None, "seconds": None, "reference": "muSpectre",
                 "reference_seconds": None, "ratio": None, "max_rel_error": None,
                 "skipped": f"muSpectre not installed ({exc}); pip install .[peers]"}]
    pairs = [(16, 17, False), (20, 21, True)] if quick else [(64, 65, False), (128, 129, True)]
    seed = 1
    recs = []
    recs.append(_peer_error_record(pairs[0][0], 17 if quick else 33, seed))
    full_matvecs = None
    for even, odd, capped in pairs:
        ours = {t: _run_peer(f"mapsim|{even}", even, seed, t, WORKER) for t in (1, None)}
        # mapsim on muSpectre's odd grid (its fall-back solver): the same-voxel comparison
        odd_ours = (None if capped else _run_peer(f"mapsim|{even}", odd, seed, None, WORKER))
        if capped:
            peer = _run_peer(f"muspectre-capped|{even}", odd, seed, 1, WORKER)
        else:
            peer = _run_peer(f"muspectre|{even}|{PEER_TOL:g}", odd, seed, 1, WORKER)
        failed = [r.get("error") for r in (*ours.values(), odd_ours or {}, peer)
                  if "error" in r]
        if failed:
            recs.append({"name": f"peer/muSpectre {odd}^3 vs mapsim {even}^3", "n": 3 * even ** 3,
                         "seconds": None, "reference": "muSpectre 0.27.0",
                         "reference_seconds": None, "ratio": None, "max_rel_error": None,
                         "skipped": failed[0]})
            continue
        if capped:
            projected = (peer["setup_seconds"] + full_matvecs * peer["seconds_per_matvec"]
                         if full_matvecs else None)
            peer_seconds, peer_C = projected, None
        else:
            peer_seconds, peer_C = peer["seconds"], peer["C_eff_Pa"]
            full_matvecs = peer["cg_matvecs_total"]
        Eo = _E(odd_ours["C_eff_Pa"]) if odd_ours else None
        for threads, me in ours.items():
            Em = _E(me["C_eff_Pa"])
            rec = {
                "name": (f"peer/muSpectre {odd}^3 vs mapsim {even}^3 "
                         f"({'1 thread' if threads else 'default threads'})"),
                "n": 3 * even ** 3, "seconds": me["seconds"],
                "reference": "muSpectre 0.27.0, Fourier gradient, serial wheel (1 thread)",
                "reference_seconds": peer_seconds,
                "ratio": peer_seconds / me["seconds"] if peer_seconds else None,
                "max_rel_error": None,
                "threads": threads or "default", "solver": me["solver"],
                "solver_reason": me.get("solver_reason"), "iterations": me["iterations"],
                "timings_s": me["timings_s"],
                "peak_rss_GB": me["peak_rss_GB"], "peer_peak_rss_GB": peer["peak_rss_GB"],
                "memory_ratio": peer["peak_rss_GB"] / me["peak_rss_GB"],
                "bytes_per_voxel": me["peak_rss_GB"] * 1e9 / even ** 3,
                "peer_bytes_per_voxel": peer["peak_rss_GB"] * 1e9 / odd ** 3,
                "E_eff_Pa": Em,
                "mapsim_odd_grid": odd_ours and {
                    "voxels": odd, "solver": odd_ours["solver"],
                    "solver_reason": odd_ours.get("solver_reason"),
                    "seconds": odd_ours["seconds"], "peak_rss_GB": odd_ours["peak_rss_GB"],
                    "E_eff_Pa": Eo},
                "tolerance": (f"both CG relative residual {PEER_TOL:g}; mapsim C_eff "
                              "variational (error ~ residual^2), muSpectre from the mean stress "
                              "(error ~ residual)"), **_machine()}
            if peer_C is not None:
                Ep = _E(peer_C)
                rec.update(E_eff_peer_Pa=Ep, peer_cg_matvecs=peer["cg_matvecs_total"],
                           peer_setup_seconds=peer["setup_seconds"],
                           E_eff_rel_diff_same_voxels=Eo / Ep - 1.0,
                           max_rel_error=float(np.abs(np.asarray(odd_ours["C_eff_Pa"])
                                                      - np.asarray(peer_C)).max()
                                               / np.abs(np.asarray(peer_C)).max()),
                           E_eff_rel_diff_even_vs_odd=Em / Eo - 1.0)
            else:
                rec.update(peer_seconds_projected=True, peer_capped_iterations=CAPPED_ITERATIONS,
                           peer_seconds_capped_run=peer["seconds"],
                           peer_setup_seconds=peer["setup_seconds"],
                           peer_seconds_per_matvec=peer["seconds_per_matvec"],
                           peer_cg_matvecs_assumed=full_matvecs,
                           projection=(f"muSpectre's time at {odd}^3 = its set-up + the CG "
                                       f"products of its full solve at the next grid down "
                                       f"({full_matvecs}) x its seconds per product measured "
                                       f"here; not a full solve"))
            recs.append(rec)
    return recs
