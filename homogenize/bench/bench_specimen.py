"""Benchmark of the specimen in its field (:func:`homogenize.macro.specimen.solve_specimen`,
``mapsim bench --only specimen``).

Records (``bench_records(quick)``, format of :mod:`homogenize.bench`):

* ``specimen/cylinder ...``: an axisymmetric cylinder of L/D = 0.8 (R = 1 mm, its rim rounded
  with the library's default radius 0.1 R), Froehlich-Kennelly composite (chi0 = 2,
  Ms = 2e5 A/m), neo-Hookean G = 1e5 Pa, nu = 0.499, through the 13 field steps 0:1.2:13 T at
  finite strain (about 2 % strain on the axis at 1.2 T), at three mesh sizes (n_mesh,
  n_boundary) = (4, 24), (8, 48), (12, 96) (quick: the first two). Each size runs in its own
  process (after a warm-up solve on a tiny mesh, timed apart, so imports and compilation are
  not counted); a run under the target is repeated once and the faster kept (the shared
  machine's load only ever adds time): wall time of the 13 steps (and CPU time, less
  sensitive to the load), peak RSS of the process (``getrusage`` maxrss: interpreter and
  imports included), their growth against the previous size, staggered and Newton
  iterations. ``reference`` is the issue's target "13 field steps in at most 1 min"
  (``reference_seconds`` 60, ``ratio`` > 1: met; ``target_met``); ``max_rel_error`` is the
  relative difference of the strain on the axis at 1.2 T from the finest size's (the
  discretization, not an error against an exact value).
* ``specimen/3D cylinder ...``: the same cylinder, material and 13 field steps as a 3D
  specimen (``Specimen(..., geometry="3d")``: the octant on P2/P1 tetrahedra, the field on the
  mechanics mesh plus extruded air and its Kelvin image, AMG-CG field solves, SuperLU
  mechanics), at n_mesh 4 and 6 (quick: 4), one run per size in its own process with one
  BLAS thread (each run lasts minutes: the load it meets is averaged over it; on this shared
  machine the multithreaded BLAS spins on a loaded core). ``reference`` is the issue's 3D
  target "13 field steps in at most 10 min" (``reference_seconds`` 600); ``max_rel_error``
  is the strain on the axis at 1.2 T against the finest AXISYMMETRIC size's (the same body:
  the 3D discretization error); time, CPU time, peak RSS and their growth against the
  previous size; ``field_dof`` (also in the axisymmetric records) counts the potential's
  unknowns with the Kelvin exterior.

Committed run (``mapsim bench --only specimen --json results/bench/specimen.json``, 2 cores
shared with other jobs: load average 15-22 during the whole run, so wall times are 2-4x the
CPU times; the CPU times are the figures to compare between runs):

==================  =========  ==========  =======  ========  ===========  ============
size                mech. DOF  field DOF   wall s   CPU s     peak RSS GB  axis strain
==================  =========  ==========  =======  ========  ===========  ============
axi (4, 24)         146        7306        11.7     6.6       0.22         2.128 %
axi (8, 48)         505        14650       49.4     19.3      0.26         2.124 %
axi (12, 96)        1193       38804       229.4    69.3      0.40         2.122 %
3D n_mesh 4         1910       5428        64.9     18.8      0.26         2.183 % (+2.9 %)
3D n_mesh 6         5937       15954       268.3    82.9      0.47         2.136 % (+0.6 %)
==================  =========  ==========  =======  ========  ===========  ============

The 3D target (10 min) is met at both sizes, even under that load (ratio 9.3 and 2.2); from
n_mesh 4 to 6 (x3.1 mechanics DOF, x2.9 field DOF) time grows x4.1 (CPU x4.4: the sparse
direct mechanics solve and the P2 tetrahedra's assembly dominate) and peak memory x1.8. The
3D cylinder's strains at 1.2 T are within 0.6 % (axis), 1.2 % (end-face mean) and 0.2 %
(lateral) of the finest axisymmetric solve at n_mesh 6, 2.9 %, 4.7 % and 4.4 % at 4. The
axisymmetric rows of this run, made under that load, are slower in wall time than the
previous quiet-machine figures below (6.0 s / 14.2 s / 63.6 s) at nearly the same CPU time;
the 1 min target is met at the two smaller sizes by the best-of-two wall times, not at
(12, 96).

Each axisymmetric record also holds ``one_blas_thread``: the same run in a process with
OPENBLAS_NUM_THREADS (and OMP, MKL) = 1. The first version of the field mesh's motion
(scipy's ``LinearNDInterpolator``, one LAPACK call per simplex) made the default-threaded runs
up to 7x slower than the single-threaded ones; since the motion is plain numpy both agree:
previous committed run (quiet machine) 6.0 s / 14.2 s / 63.6 s with the default threads,
6.2 s / 14.6 s / 57.1 s with one (the strains equal), so the 1 min target is met at the two
smaller sizes.

A SHARP rim (``edge_radius_m = 0``) used to stop these runs (the mechanics Newton exhausted its
step cuts at 1.0-1.1 T): the frozen Kelvin traction carried the uniform part of the magnetic
pressure, which is no load but gave the Newton a false stiffness. With it taken out (the
volume mean of psi, :mod:`homogenize.macro.specimen`) the sharp-rim runs converge to 1.2 T:
end-face mean 2.434 % on (8, 48) and 2.386 % on (12, 96), against 2.338 % with the default
rim rounded by 0.1 R (the edge's singular loads make the sharp rim converge slowly with the
mesh); the record ``limit_note`` says so.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from homogenize.macro import finite_strain as fs
from homogenize.macro import magnetostatics as ms
from homogenize.macro.specimen import Specimen, solve_specimen

__all__ = ["bench_records", "CASE"]

#: the benchmarked specimen and material (SI)
CASE = {"shape": "cylinder", "radius_m": 1e-3, "length_m": 1.6e-3, "law": "froehlich-kennelly",
        "chi0": 2.0, "Ms_A_per_m": 2e5, "G_Pa": 1e5, "nu": 0.499,
        "B_applied_T": "0:1.2:13", "model": "continuum", "load_steps": 2, "tol": 1e-4}
SIZES = ((4, 24), (8, 48), (12, 96))
QUICK_SIZES = SIZES[:2]
TARGET_SECONDS = 60.0


#: the 3D runs: the same cylinder and material as an octant on tetrahedra, at these n_mesh
SIZES_3D = (4, 6)
QUICK_SIZES_3D = (4,)
TARGET_SECONDS_3D = 600.0


def _solve(n_mesh: int, n_boundary: int | None, B):
    if n_boundary is None:                      # the 3D specimen
        spec = Specimen(CASE["shape"], CASE["radius_m"], CASE["length_m"], n_mesh=n_mesh,
                        geometry="3d")
    else:
        spec = Specimen(CASE["shape"], CASE["radius_m"], CASE["length_m"], n_mesh=n_mesh,
                        n_boundary=n_boundary)
    return solve_specimen(spec, ms.froehlich_kennelly(CASE["chi0"], CASE["Ms_A_per_m"]),
                          fs.NeoHookeanSolid.from_poisson(CASE["G_Pa"], CASE["nu"]), B,
                          model=CASE["model"], tol=CASE["tol"], load_steps=CASE["load_steps"])


def _worker(n_mesh: int, n_boundary: int | None, out: str) -> None:
    """One size in this (child) process: warm-up, then the 13 timed steps; JSON to ``out``
    (``n_boundary`` None: the 3D specimen)."""
    import resource
    t0 = time.perf_counter()
    # imports, numba and skfem set-up, not timed
    _solve(2, None, [0.1]) if n_boundary is None else _solve(4, 16, [0.1])
    warm = time.perf_counter() - t0
    B = np.linspace(0.0, 1.2, 13)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = _solve(n_mesh, n_boundary, B)
    except Exception as exc:                    # recorded, not raised: the other sizes go on
        rec = {"error": f"{type(exc).__name__}: {exc}",
               "seconds_to_failure": time.perf_counter() - t0}
    else:
        sec = time.perf_counter() - t0
        cpu = time.process_time() - c0
        sol, fr = res.solution, res.field_result
        last = res.steps[-1]
        rec = {"seconds": sec, "cpu_seconds": cpu, "warmup_seconds": warm,
               # the rim: 0 = sharp (a Specimen without edge_radius_m has a sharp rim)
               "edge_radius_m": float(getattr(res.specimen, "edge_radius_m", 0.0) or 0.0),
               "mechanics_dof": int(sol.u_m.size + sol.p_Pa.size),
               "mechanics_elements": int(sol.body.mesh.t.shape[1]),
               "field_nodes": int(fr.mesh.p.shape[1]),
               "field_dof": int(fr.basis.N + (0 if fr.phi_exterior_A is None else
                                              fr.phi_exterior_A.size)),
               "stagger_iterations": [s.stagger_iterations for s in res.steps],
               "newton_iterations_total": int(sum(s.newton_iterations for s in res.steps)),
               "strain_axis_at_1p2T": last.strain_axis,
               "strain_end_mean_at_1p2T": last.strain_end_mean,
               "lateral_strain_at_1p2T": last.lateral_strain,
               "M_mean_at_1p2T_A_per_m": last.M_mean_A_per_m}
    rec["peak_rss_GB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6   # kB
    with open(out, "w") as fh:
        json.dump(rec, fh)


#: the environment that limits BLAS/LAPACK (OpenBLAS, MKL, OpenMP) to one thread
ONE_THREAD = {k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


def _run(n_mesh: int, n_boundary: int | None, env: dict | None = None) -> dict:
    """:func:`_worker` in a fresh process (its own peak memory), with ``env`` added to the
    environment; its JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "specimen.json")
        code = (f"from homogenize.bench.bench_specimen import _worker; "
                f"_worker({n_mesh}, {n_boundary}, {out!r})")
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env={**os.environ, **(env or {})})
        if p.returncode != 0 or not os.path.exists(out):
            tail = p.stderr.strip().splitlines()
            return {"error": tail[-1] if tail else f"exit {p.returncode}"}
        with open(out) as fh:
            return json.load(fh)


def _best_of(n_mesh: int, n_boundary: int, repeats: int) -> dict:
    """The fastest of up to ``repeats`` runs (each in its own process; the shared machine's
    load only ever adds time; a run over the target is not repeated), with all their wall
    times and the largest peak RSS."""
    runs = [_run(n_mesh, n_boundary)]
    while len(runs) < repeats and runs[-1].get("seconds", math.inf) <= TARGET_SECONDS:
        runs.append(_run(n_mesh, n_boundary))
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return runs[-1]
    best = dict(min(ok, key=lambda r: r["seconds"]))
    best["seconds_all_runs"] = [r.get("seconds") for r in runs]
    best["peak_rss_GB"] = max(r["peak_rss_GB"] for r in ok)
    return best


def bench_records(quick: bool) -> list[dict]:
    """The specimen records (see the module docstring)."""
    sizes = QUICK_SIZES if quick else SIZES
    runs = [(nm, nb, _best_of(nm, nb, 1 if quick else 2)) for nm, nb in sizes]
    ok = [r for _, _, r in runs if "error" not in r]
    finest = ok[-1]["strain_axis_at_1p2T"] if ok else None
    out, prev = [], None
    for nm, nb, r in runs:
        rec = {"name": f"specimen/cylinder L/D 0.8, 13 field steps, n_mesh {nm} n_boundary {nb}",
               "n": r.get("mechanics_dof"), "seconds": r.get("seconds"),
               "reference": "issue target: 13 field steps in at most 1 min",
               "reference_seconds": TARGET_SECONDS,
               "ratio": TARGET_SECONDS / r["seconds"] if "seconds" in r else None,
               "target_met": bool(r["seconds"] <= TARGET_SECONDS) if "seconds" in r else False,
               "max_rel_error": (abs(r["strain_axis_at_1p2T"] / finest - 1.0)
                                 if "seconds" in r and finest else None),
               "max_rel_error_means": "strain on the axis at 1.2 T against the finest size's",
               "n_mesh": nm, "n_boundary": nb, "case": CASE, **r,
               "load_average_1_5_15min": list(os.getloadavg()), "cpu_count": os.cpu_count()}
        one = _run(nm, nb, ONE_THREAD)
        rec["one_blas_thread"] = {k: one.get(k) for k in ("seconds", "cpu_seconds",
                                                          "peak_rss_GB", "error")}
        rec["one_blas_thread"]["target_met"] = bool(one.get("seconds", math.inf)
                                                    <= TARGET_SECONDS)
        rec["one_blas_thread"]["same_strain_axis"] = (one.get("strain_axis_at_1p2T")
                                                      == r.get("strain_axis_at_1p2T"))
        if "seconds" in r:
            if prev is not None:
                rec["growth_vs"] = (f"n_mesh {prev['n_mesh']} n_boundary {prev['n_boundary']} "
                                    f"(x{r['mechanics_dof'] / prev['mechanics_dof']:.3g} "
                                    f"mechanics DOF)")
                rec["time_growth"] = r["seconds"] / prev["seconds"]
                rec["memory_growth"] = r["peak_rss_GB"] / prev["peak_rss_GB"]
            prev = {"n_mesh": nm, "n_boundary": nb, **r}
        out.append(rec)
    out.extend(_records_3d(quick, finest))
    out[0]["limit_note"] = (
        "a SHARP rim (edge_radius_m = 0) converges to 1.2 T too since the uniform magnetic "
        "pressure is taken out of the frozen loads (end-face mean 2.434 % on (8, 48), 2.386 % "
        "on (12, 96), measured once); before, the mechanics Newton exhausted its step cuts at "
        "1.0-1.1 T. The rim stays rounded by default (0.1 R): the edge's singular loads make "
        "the sharp rim converge slowly with the mesh")
    return out


def _records_3d(quick: bool, axi_finest: float | None) -> list[dict]:
    """The 3D cylinder (octant) at ``SIZES_3D``, one run per size (each over a minute, so the
    machine's load is averaged over it), each in its own process with one BLAS thread (see
    the module docstring)."""
    out, prev = [], None
    for nm in (QUICK_SIZES_3D if quick else SIZES_3D):
        r = _run(nm, None, ONE_THREAD)
        rec = {"name": f"specimen/3D cylinder L/D 0.8 (octant), 13 field steps, n_mesh {nm}",
               "n": r.get("mechanics_dof"), "seconds": r.get("seconds"),
               "reference": "issue target: 3D, 13 field steps in at most 10 min",
               "reference_seconds": TARGET_SECONDS_3D,
               "ratio": TARGET_SECONDS_3D / r["seconds"] if "seconds" in r else None,
               "target_met": bool(r["seconds"] <= TARGET_SECONDS_3D) if "seconds" in r
               else False,
               "max_rel_error": (abs(r["strain_axis_at_1p2T"] / axi_finest - 1.0)
                                 if "seconds" in r and axi_finest else None),
               "max_rel_error_means": "strain on the axis at 1.2 T against the finest "
                                      "axisymmetric size's (same body and material)",
               "n_mesh": nm, "geometry": "3d", "blas_threads": 1, "case": CASE, **r,
               "load_average_1_5_15min": list(os.getloadavg()), "cpu_count": os.cpu_count()}
        if "seconds" in r:
            if prev is not None:
                rec["growth_vs"] = (f"n_mesh {prev['n_mesh']} "
                                    f"(x{r['mechanics_dof'] / prev['mechanics_dof']:.3g} "
                                    f"mechanics DOF, x{r['field_dof'] / prev['field_dof']:.3g} "
                                    "field DOF)")
                rec["time_growth"] = r["seconds"] / prev["seconds"]
                rec["memory_growth"] = r["peak_rss_GB"] / prev["peak_rss_GB"]
            prev = {"n_mesh": nm, **r}
        out.append(rec)
    return out
