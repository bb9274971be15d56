"""Does the second core pay? The cell FEM with NUMBA_NUM_THREADS=1 and 2, side by side.

Issue 37 item 2 asks for the cell solve at 64^3 and 128^3 at least 1.7x faster on 2 threads
than on 1, and the dipole solve (PME) at N = 1e5 likewise. This runs the command a user runs, ``mapsim homogenize RVE --voxels N`` (default
solver, all 7 load cases: six strains and the magnetic one with --B/--gradB), once per thread
count and grid, under ``/usr/bin/time -v`` (wall time and peak RSS of the whole process), and
reads the solver's own stage timings (assembly, AMG/multigrid set-up, deflation, solve) from
its JSON, so that the share of each stage and its own speed-up are on record. E_eff of the two
thread counts must be equal (the kernels are bitwise thread-independent; checked).

The dipole solve: ``micro.dipoles.solve`` on an RVE of 1e5 particles (phi 0.035, drawn once
beforehand by ``mapsim rve --out``, not timed), the self-consistent moments and forces by
particle-mesh Ewald, timed in its process after a warm-up; the whole process under
``/usr/bin/time -v``; the results of both thread counts compared bit for bit.

Run:  .venv/bin/python results/bench/threads.py              (every part below, the cells at
                                           64^3 and 128^3 in 3 pairs each; ~1.5 h on a slow machine)
      .venv/bin/python results/bench/threads.py --quick      (32^3 only, ~1 min)
      .venv/bin/python results/bench/threads.py --only cells     (~1 h: re-measure one part,
                                                                  keep the others from
                                                                  threads.json)
      .venv/bin/python results/bench/threads.py --only dipoles   (the same, ~8 min)
      .venv/bin/python results/bench/threads.py --only profile   (where the cell solve's time
                     goes at 64^3 and 128^3 on 1 and 2 threads: cProfile's own time per
                     kernel, ~20 min on a slow machine)
      .venv/bin/python results/bench/threads.py --only dipole-profile   (the same for the
                     dipole solve at N = 1e5, and its serial share, ~3 min)
Writes results/bench/threads.json and threads.md (--quick: a temporary directory).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
MAPSIM = str(Path(sys.executable).with_name("mapsim"))
#: grid -> particles of the RVE (phi 0.035, the seed's powder): the bench's RVE sizes
GRIDS = {64: 100, 128: 800}
QUICK = {32: 25}
#: particles of the dipole-solve RVE (quick: fewer)
DIPOLES, DIPOLES_QUICK = 100_000, 5_000
#: pairs of dipole runs (1, 2 threads) in turn; the median of each kept
DIPOLE_REPEATS = 5
#: pairs of cell runs per grid in turn (a 128^3 pair takes ~16 min on a slow 2-core machine;
#: single pairs there swing by ~20 %)
CELL_REPEATS = 3


def _machine() -> dict:
    """Where and when a part was measured (the parts of threads.json may come from different
    runs, --only, and machines: round-off and speed differ between CPUs)."""
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cpu_count": os.cpu_count(),
            "date_utc": time.strftime("%Y-%m-%d", time.gmtime()),
            "load_avg_1min_at_start": os.getloadavg()[0]}


def _measured_on(part: dict | None) -> str:
    m = (part or {}).get("machine")
    if not m:
        return "Machine not recorded (measured before threads.py recorded it)."
    return (f"Measured on {m['cpu']} ({m['cpu_count']} cores), {m['date_utc']}, load average "
            f"{m['load_avg_1min_at_start']:.2f} at the start.")


def _run(argv, env_threads: int, cwd: Path) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(env_threads), MPLBACKEND="Agg")
    p = subprocess.run(["/usr/bin/time", "-v", *argv], cwd=cwd, env=env, capture_output=True,
                       text=True, check=True)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", p.stderr).group(1)
    parts = [float(x) for x in wall.split(":")]
    seconds = sum(v * 60 ** i for i, v in enumerate(reversed(parts)))
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr).group(1))
    return {"wall_s": seconds, "peak_rss_GB": rss_kb * 1024 / 1e9}


def _draw_and_run(n_particles: int, name: str, argv, work: Path, read,
                  repeats: int = 1) -> dict:
    """Draw the RVE (phi 0.035, seed 1; not timed), then run ``argv + [RVE, "--json", OUT]``
    on 1 and 2 threads, the pair ``repeats`` times in turn (1, 2, 1, 2, ...): {1: run, 2: run}
    of median solve time (wall time without one), each ``_run``'s figures plus ``read(json)``;
    ``"pairs"`` every pair, ``"speedup_solve_per_pair"`` and ``"speedup_wall_per_pair"``."""
    rve = work / f"{name}.h5"
    subprocess.run([MAPSIM, "rve", "--phi", "0.035", "--n", str(n_particles), "--seed", "1",
                    "--out", str(rve)], check=True, capture_output=True)
    pairs = []
    for _ in range(int(repeats)):
        runs = {}
        for k in (1, 2):
            out = work / f"{name}_{k}.json"
            t = _run([*argv(rve), "--json", str(out)], k, work)
            runs[k] = {**t, **read(json.loads(out.read_text()))}
        pairs.append(runs)
    med = {k: sorted((p[k] for p in pairs),
                     key=lambda r: r.get("solve_s", r["wall_s"]))[len(pairs) // 2]
           for k in (1, 2)}
    return {**med, "pairs": pairs,
            "speedup_solve_per_pair": [p[1]["solve_s"] / p[2]["solve_s"] for p in pairs
                                       if "solve_s" in p[1]],
            "speedup_wall_per_pair": [p[1]["wall_s"] / p[2]["wall_s"] for p in pairs]}


def measure(grids: dict, work: Path, repeats: int = 1) -> list:
    """Each grid's homogenization on 1 and 2 threads, ``repeats`` pairs in turn: the run of
    median solve time of each thread count in the row, every pair's solve and wall speed-up
    listed."""
    rows = []
    for n, n_particles in grids.items():
        machine = _machine()
        runs = _draw_and_run(
            n_particles, f"h{n}",
            lambda rve: [MAPSIM, "homogenize", str(rve), "--voxels", str(n), "--B", "0.1",
                         "--gradB", "1.78", "--quiet"], work,
            lambda d: {"stages_s": d["timings_s"], "solve_s": d["timings_s"]["solve"],
                       "solver": d["settings"]["solver"],
                       "E_eff_Pa": d["E_eff_Pa"], "iterations": d["iterations"]},
            repeats=repeats)
        one, two, pairs = runs[1], runs[2], runs["pairs"]
        rows.append({
            "repeats": len(pairs),
            "speedup_solve_per_pair": runs["speedup_solve_per_pair"],
            "speedup_wall_per_pair": runs["speedup_wall_per_pair"],
            "voxels": n, "n_particles": n_particles, "solver": one["solver"],
            "machine": machine, "threads_1": one, "threads_2": two,
            "speedup_wall": one["wall_s"] / two["wall_s"],
            "speedup_by_stage": {s: one["stages_s"][s] / two["stages_s"][s]
                                 for s in one["stages_s"] if two["stages_s"].get(s)},
            "share_1_thread": {s: one["stages_s"][s] / one["wall_s"] for s in one["stages_s"]
                               if s != "total"},
            "E_eff_equal": all(p[1]["E_eff_Pa"] == p[2]["E_eff_Pa"] == one["E_eff_Pa"]
                               for p in pairs),
            "peak_bytes_per_voxel_2_threads": two["peak_rss_GB"] * 1e9 / n ** 3})
    return rows


DIPOLE_CODE = """
import json, sys, time
from micro import RVE, generate_rve
from micro.dipoles import solve
solve(generate_rve(0.035, 4000, 2), 0.1, 1.78)           # compile outside the timing (PME)
rve = RVE.load(sys.argv[1])                              # argv: RVE --json OUT
t0 = time.perf_counter()
st = solve(rve, 0.1, 1.78)
sec = time.perf_counter() - t0
json.dump({"solve_s": sec, "iterations": int(st.iterations),
           "M_eff_A_per_m": list(map(float, st.M_eff_A_per_m)),
           "f_eff_N_m3": list(map(float, st.f_eff_N_m3)),
           "moments_sum": float(abs(st.moments_Am2).sum()),
           "forces_sum": float(abs(st.total_force_N).sum())}, open(sys.argv[3], "w"))
"""


def measure_dipoles(n_particles: int, work: Path, repeats: int = 1) -> dict:
    """The self-consistent dipole solve (``micro.dipoles.solve``, default law and summation:
    PME above 3000 particles) of an RVE of ``n_particles`` on 1 and 2 threads: the solve alone
    timed in the process (after a warm-up that compiles the kernels), the whole process's wall
    time and peak RSS by ``/usr/bin/time -v``; the moments' and forces' sums compared bit for
    bit. ``repeats``: the pair of runs that many times in turn, the median solve of each thread
    count kept and every pair's speed-up recorded (the solve takes 20-40 s, and this machine's
    run-to-run spread is of the size of the gap to the 1.7x target)."""
    machine = _machine()
    runs = _draw_and_run(n_particles, f"dip{n_particles}",
                         lambda rve: [sys.executable, "-c", DIPOLE_CODE, str(rve)], work,
                         lambda d: d, repeats=repeats)
    one, two, pairs = runs[1], runs[2], runs["pairs"]
    keys = ("M_eff_A_per_m", "f_eff_N_m3", "moments_sum", "forces_sum", "iterations")
    return {"n_particles": n_particles, "machine": machine, "threads_1": one, "threads_2": two,
            "speedup_solve": one["solve_s"] / two["solve_s"],
            "speedup_wall": one["wall_s"] / two["wall_s"],
            "repeats": len(pairs),
            "speedup_solve_per_pair": runs["speedup_solve_per_pair"],
            "results_equal": all(p[1][q] == p[2][q] == one[q] for p in pairs for q in keys)}


PROFILE_CODE = """
import cProfile, json, pstats, sys
import numpy as np
from micro import generate_rve
from homogenize.cell.problem import homogenize_rve
rve = generate_rve(0.035, {n_particles}, 1)
F = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
homogenize_rve(rve, 16, forces_N=F)                      # compile outside the profile
pr = cProfile.Profile()
pr.enable()
r = homogenize_rve(rve, {n}, forces_N=F)
pr.disable()
st = pstats.Stats(pr).stats
own = {{f"{{k[0].split('/')[-1]}}:{{k[2]}}": v[2] for k, v in st.items()}}
json.dump({{"stages_s": r.timings_s, "own_s": own}}, open(sys.argv[1], "w"))
"""


def _functions(o1: dict, o2: dict, solve1: float) -> list:
    """The functions of >= 1 % of the 1-thread solve (own times ``o1``, ``o2`` on 1 and 2
    threads), largest first, with their share and speed-up."""
    big = sorted((f for f in o1 if o1[f] >= 0.01 * solve1), key=lambda f: -o1[f])
    return [{"function": f, "own_1_thread_s": o1[f], "own_2_threads_s": o2.get(f),
             "share_of_1_thread_solve": o1[f] / solve1,
             "speedup": o1[f] / o2[f] if o2.get(f) else None} for f in big]


def measure_profile(n: int, n_particles: int, work: Path) -> dict:
    """cProfile of the cell solve (in-process ``homogenize_rve``, 7 load cases) on 1 and 2
    threads: each function's own time, and the speed-up of the ones that take >= 1 % of the
    1-thread solve; ``rest_of_solve`` is the solve minus the matrix-free stencil kernel."""
    runs = {}
    machine = _machine()
    for k in (1, 2):
        out = work / f"prof{k}.json"
        env = dict(os.environ, NUMBA_NUM_THREADS=str(k))
        subprocess.run([sys.executable, "-c", PROFILE_CODE.format(n=n, n_particles=n_particles),
                        str(out)], env=env, check=True, capture_output=True)
        runs[k] = json.loads(out.read_text())
    solve1, solve2 = runs[1]["stages_s"]["solve"], runs[2]["stages_s"]["solve"]
    o1, o2 = runs[1]["own_s"], runs[2]["own_s"]
    kern = "_matfree.py:_node_op"
    return {"voxels": n, "n_particles": n_particles, "machine": machine,
            "stages_1_s": runs[1]["stages_s"], "stages_2_s": runs[2]["stages_s"],
            "functions": _functions(o1, o2, solve1),
            "stencil_kernel_speedup": o1[kern] / o2[kern] if o2.get(kern) else None,
            "rest_of_solve_speedup": ((solve1 - o1.get(kern, 0.0))
                                      / (solve2 - o2.get(kern, 0.0)))}


DIPOLE_PROFILE_CODE = """
import cProfile, json, pstats, sys, time
from micro import RVE, generate_rve
from micro.dipoles import solve
solve(generate_rve(0.035, 4000, 2), 0.1, 1.78)           # compile outside the profile (PME)
rve = RVE.load(sys.argv[1])
pr = cProfile.Profile()
t0 = time.perf_counter()
pr.enable()
solve(rve, 0.1, 1.78)
pr.disable()
sec = time.perf_counter() - t0
st = pstats.Stats(pr).stats
own = {}
for k, v in st.items():
    name = f"{k[0].split('/')[-1]}:{k[2]}"
    own[name] = own.get(name, 0.0) + v[2]
json.dump({"solve_s": sec, "own_s": own}, open(sys.argv[2], "w"))
"""

#: a function whose own time falls by less than this on 2 threads counts as serial
SERIAL_BELOW = 1.25


def measure_dipole_profile(n_particles: int, work: Path, repeats: int = 1) -> dict:
    """cProfile of the dipole solve (``micro.dipoles.solve``, default law, PME) on 1 and 2
    threads: each function's own time and speed-up for those >= 1 % of the 1-thread solve, and
    the share of the 1-thread solve in functions that do not scale (speed-up below
    :data:`SERIAL_BELOW`): what bounds the solve's speed-up. ``repeats``: the pair run that
    many times in turn, each time the median over the runs (one run's FFT once showed 1.07x
    where the others show 1.8x: this machine's noise)."""
    machine = _machine()
    rve = work / f"dipprof{n_particles}.h5"
    subprocess.run([MAPSIM, "rve", "--phi", "0.035", "--n", str(n_particles), "--seed", "1",
                    "--out", str(rve)], check=True, capture_output=True)
    runs = {1: [], 2: []}
    for _ in range(repeats):
        for k in (1, 2):
            out = work / f"dipprof{k}.json"
            env = dict(os.environ, NUMBA_NUM_THREADS=str(k))
            subprocess.run([sys.executable, "-c", DIPOLE_PROFILE_CODE, str(rve), str(out)],
                           env=env, check=True, capture_output=True)
            runs[k].append(json.loads(out.read_text()))

    def median(k, get):
        v = sorted(get(r) for r in runs[k])
        return v[len(v) // 2]
    solve1, solve2 = (median(k, lambda r: r["solve_s"]) for k in (1, 2))
    o1, o2 = ({f: median(k, lambda r, f=f: r["own_s"].get(f, 0.0)) for f in runs[k][0]["own_s"]}
              for k in (1, 2))
    serial = [f for f in o1 if not (o2.get(f) and o1[f] / o2[f] >= SERIAL_BELOW)]
    return {"n_particles": n_particles, "machine": machine, "repeats": repeats,
            "solve_1_s": solve1,
            "solve_2_s": solve2, "functions": _functions(o1, o2, solve1),
            "serial_share_of_1_thread_solve": sum(o1[f] for f in serial) / solve1}


def _function_table(prof: dict) -> list:
    """The lines of a profile's per-function table (own time on 1 and 2 threads, share of the
    1-thread solve, speed-up) and where it was measured."""
    lines = ["| function | own time 1 / 2 threads [s] | own time / 1-thread solve time | "
             "speed-up |", "|---|---|---|---|"]
    for f in prof["functions"]:
        sp = f"{f['speedup']:.2f}x" if f["speedup"] else "-"
        lines.append(f"| `{f['function']}` | {f['own_1_thread_s']:.2f} / "
                     f"{(f['own_2_threads_s'] or 0.0):.2f} | "
                     f"{100 * f['share_of_1_thread_solve']:.1f} % | {sp} |")
    return lines + ["", _measured_on(prof), ""]


def markdown(rows: list, dip: dict | None = None, prof: list | dict | None = None,
             dprof: dict | None = None) -> str:
    """threads.md from the parts; ``prof``: the cell profiles, one per grid (a single dict:
    threads.json before the profile covered every grid)."""
    prof = [prof] if isinstance(prof, dict) else list(prof or [])
    lines = ["# The cell FEM on 1 and 2 threads (`results/bench/threads.py`)", "",
             "`mapsim homogenize RVE --voxels N --B 0.1 --gradB 1.78` (7 load cases, default "
             "solver), NUMBA_NUM_THREADS=1 then 2, wall time and peak RSS by `/usr/bin/time -v`; "
             "stage times from the command's JSON.", "",
             "| grid | particles | solver | wall 1 / 2 threads [s] | speed-up | solve | "
             "set-up (AMG/multigrid) | assembly | peak RSS [GB] | bytes/voxel | E_eff equal |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        sp = r["speedup_by_stage"]
        lines.append(
            f"| {r['voxels']}^3 | {r['n_particles']} | {r['solver']} | "
            f"{r['threads_1']['wall_s']:.1f} / {r['threads_2']['wall_s']:.1f} | "
            f"{r['speedup_wall']:.2f}x | {sp.get('solve', float('nan')):.2f}x | "
            f"{sp.get('amg_setup', float('nan')):.2f}x | {sp.get('assembly', float('nan')):.2f}x | "
            f"{r['threads_2']['peak_rss_GB']:.2f} | {r['peak_bytes_per_voxel_2_threads']:.0f} | "
            f"{r['E_eff_equal']} |")
    lines += ["", "Shares of the 1-thread wall time: " + "; ".join(
        f"{r['voxels']}^3: " + ", ".join(f"{s} {100 * v:.0f} %"
                                         for s, v in r["share_1_thread"].items())
        for r in rows), ""]
    many = [r for r in rows if r.get("repeats", 1) > 1]
    if many:
        lines += [f"Each grid's pair run {many[0]['repeats']} times in turn (1, 2, 1, 2, ...), "
            "the run of median solve time of each thread count in the table; the solve's "
            "speed-up of every pair: " + "; ".join(
                f"{r['voxels']}^3: " + ", ".join(f"{v:.2f}x" for v in r["speedup_solve_per_pair"])
                for r in many) + ".", ""]
    where = list(dict.fromkeys(_measured_on(r) for r in rows))
    if len(where) > 1:            # each grid's run has its own start (load average)
        where = [f"{r['voxels']}^3: {_measured_on(r)}" for r in rows]
    lines += [" ".join(where), ""] if rows else []
    if dip:
        lines += ["## The dipole solve (particle-mesh Ewald)", "",
                  "`micro.dipoles.solve(rve, 0.1 T, 1.78 T/m)` (self-consistent moments and "
                  "forces, default law, PME), NUMBA_NUM_THREADS=1 then 2: the solve timed in the "
                  "process after a warm-up; the whole process (reading the RVE, the warm-up) "
                  "and its peak RSS by `/usr/bin/time -v`.", "",
                  "| particles | solve 1 / 2 threads [s] | speed-up | whole process 1 / 2 [s] "
                  "| peak RSS 1 / 2 [GB] | results equal |", "|---|---|---|---|---|---|",
                  f"| {dip['n_particles']} | {dip['threads_1']['solve_s']:.1f} / "
                  f"{dip['threads_2']['solve_s']:.1f} | {dip['speedup_solve']:.2f}x | "
                  f"{dip['threads_1']['wall_s']:.1f} / {dip['threads_2']['wall_s']:.1f} | "
                  f"{dip['threads_1']['peak_rss_GB']:.2f} / {dip['threads_2']['peak_rss_GB']:.2f} "
                  f"| {dip['results_equal']} |", ""]
        if dip.get("repeats", 1) > 1:
            lines += [f"The pair run {dip['repeats']} times in turn (1, 2, 1, 2, ...), the median "
                      "solve of each thread count in the table; the speed-up of every pair: "
                      + ", ".join(f"{v:.2f}x" for v in dip["speedup_solve_per_pair"]) + ".", ""]
        lines += [_measured_on(dip), ""]
    for pr in prof:
        s1, s2 = pr["stages_1_s"], pr["stages_2_s"]
        lines += [f"## Where the cell solve's time goes ({pr['voxels']}^3, "
                  f"{pr['n_particles']} particles, 7 load cases)", "",
                  "`results/bench/threads.py --only profile`: cProfile, each function's own "
                  f"time. Solve {s1['solve']:.1f} s on 1 thread, {s2['solve']:.1f} s on 2 "
                  f"({s1['solve'] / s2['solve']:.2f}x); whole homogenization "
                  f"{s1['total']:.1f} / {s2['total']:.1f} s "
                  f"({s1['total'] / s2['total']:.2f}x). The matrix-free stencil kernel "
                  f"(smoothing, residuals, products) {pr['stencil_kernel_speedup']:.2f}x; "
                  f"the rest of the solve {pr['rest_of_solve_speedup']:.2f}x.", "",
                  ]
        lines += _function_table(pr)
    if dprof:
        s1, s2 = dprof["solve_1_s"], dprof["solve_2_s"]
        ser = dprof["serial_share_of_1_thread_solve"]
        lines += [f"## Where the dipole solve's time goes (N = {dprof['n_particles']}, PME)", "",
                  "`results/bench/threads.py --only dipole-profile`: cProfile of "
                  "`micro.dipoles.solve(rve, 0.1 T, 1.78 T/m)`, each function's own time "
                  f"(median of {dprof.get('repeats', 1)} pairs of runs in turn). "
                  f"Solve {s1:.1f} s on 1 thread, {s2:.1f} s on 2 ({s1 / s2:.2f}x, under the "
                  f"profiler). Functions whose own time falls by less than {SERIAL_BELOW}x on 2 "
                  f"threads (serial numpy, scipy, Python) hold {100 * ser:.1f} % of the "
                  f"1-thread solve: with the rest perfectly parallel the bound is "
                  f"{1 / (ser + (1 - ser) / 2):.2f}x.", "",
                  ]
        lines += _function_table(dprof)
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("cells", "dipoles", "profile", "dipole-profile"),
                    default=None,
                    help="re-measure this part only; the others are kept from threads.json")
    a = ap.parse_args(argv)
    out = Path(tempfile.mkdtemp()) if a.quick else HERE
    old = (json.loads((HERE / "threads.json").read_text())
           if a.only and (HERE / "threads.json").exists() else {})
    with tempfile.TemporaryDirectory() as work:
        rows = (measure(QUICK if a.quick else GRIDS, Path(work),
                        repeats=1 if a.quick else CELL_REPEATS) if a.only in (None, "cells")
                else old.get("rows", []))
        dip = (measure_dipoles(DIPOLES_QUICK if a.quick else DIPOLES, Path(work),
                               repeats=1 if a.quick else DIPOLE_REPEATS)
               if a.only in (None, "dipoles") else old.get("dipoles"))
        prof = ([measure_profile(n, p, Path(work)) for n, p in
                 (QUICK if a.quick else GRIDS).items()] if a.only in (None, "profile")
                else old.get("profile"))
        dprof = (measure_dipole_profile(DIPOLES_QUICK if a.quick else DIPOLES, Path(work),
                                        repeats=1 if a.quick else DIPOLE_REPEATS)
                 if a.only in (None, "dipole-profile") else old.get("dipole_profile"))
    from importlib import metadata
    doc = {"rows": rows, "dipoles": dip, "profile": prof, "dipole_profile": dprof,
           "cpu_count": os.cpu_count(),
           "versions": {k: metadata.version(k) for k in ("numpy", "scipy", "numba", "pyamg")},
           "command": "results/bench/threads.py"}
    (out / "threads.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "threads.md").write_text(markdown(rows, dip, prof, dprof))
    print(markdown(rows, dip, prof, dprof))
    return 0


if __name__ == "__main__":
    sys.exit(main())
