"""Does the second core pay? The cell FEM with NUMBA_NUM_THREADS=1 and 2, side by side.

Issue 37 item 2 asks for the cell solve at 64^3 and 128^3 at least 1.7x faster on 2 threads
than on 1, and the dipole solve (PME) at N = 1e5 likewise. This runs the command a user runs, ``mapsim homogenize RVE --voxels N`` (default
solver, all 7 load cases: six strains and the magnetic one with --B/--gradB), once per thread
count and grid, under ``/usr/bin/time -v`` (wall time and peak RSS of the whole process), and
reads the solver's own stage timings (assembly, AMG/multigrid set-up, deflation, solve) from
its JSON, so that the share of each stage and its own speed-up are on record. E_eff of the two
thread counts must be equal (the kernels are bitwise thread-independent; checked).

The dipole solve: ``mapsim rve --load RVE --B 0.1 --gradB 1.78`` on an RVE of 1e5 particles
(phi 0.035, drawn once beforehand by ``mapsim rve --out``, not timed): the self-consistent
moments and forces by particle-mesh Ewald, whole command under ``/usr/bin/time -v`` (reading
the RVE file is part of it), M_eff of both thread counts compared bit for bit.

Run:  .venv/bin/python results/bench/threads.py              (64^3 and 128^3, ~12 min)
      .venv/bin/python results/bench/threads.py --quick      (32^3 only, ~1 min)
      .venv/bin/python results/bench/threads.py --only dipoles   (re-measure one part, keep
                                                                  the other from threads.json)
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
from pathlib import Path

HERE = Path(__file__).resolve().parent
MAPSIM = str(Path(sys.executable).with_name("mapsim"))
#: grid -> particles of the RVE (phi 0.035, the seed's powder): the bench's RVE sizes
GRIDS = {64: 100, 128: 800}
QUICK = {32: 25}
#: particles of the dipole-solve RVE (quick: fewer)
DIPOLES, DIPOLES_QUICK = 100_000, 5_000


def _run(argv, env_threads: int, cwd: Path) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(env_threads), MPLBACKEND="Agg")
    p = subprocess.run(["/usr/bin/time", "-v", *argv], cwd=cwd, env=env, capture_output=True,
                       text=True, check=True)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", p.stderr).group(1)
    parts = [float(x) for x in wall.split(":")]
    seconds = sum(v * 60 ** i for i, v in enumerate(reversed(parts)))
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr).group(1))
    return {"wall_s": seconds, "peak_rss_GB": rss_kb * 1024 / 1e9}


def _draw_and_run(n_particles: int, name: str, argv, work: Path, read) -> dict:
    """Draw the RVE (phi 0.035, seed 1; not timed), then run ``argv + [RVE, "--json", OUT]``
    on 1 and 2 threads: {1: run, 2: run}, each ``_run``'s figures plus ``read(json)``."""
    rve = work / f"{name}.h5"
    subprocess.run([MAPSIM, "rve", "--phi", "0.035", "--n", str(n_particles), "--seed", "1",
                    "--out", str(rve)], check=True, capture_output=True)
    runs = {}
    for k in (1, 2):
        out = work / f"{name}_{k}.json"
        t = _run([*argv(rve), "--json", str(out)], k, work)
        runs[k] = {**t, **read(json.loads(out.read_text()))}
    return runs


def measure(grids: dict, work: Path) -> list:
    rows = []
    for n, n_particles in grids.items():
        runs = _draw_and_run(
            n_particles, f"h{n}",
            lambda rve: [MAPSIM, "homogenize", str(rve), "--voxels", str(n), "--B", "0.1",
                         "--gradB", "1.78", "--quiet"], work,
            lambda d: {"stages_s": d["timings_s"], "solver": d["settings"]["solver"],
                       "E_eff_Pa": d["E_eff_Pa"], "iterations": d["iterations"]})
        one, two = runs[1], runs[2]
        rows.append({
            "voxels": n, "n_particles": n_particles, "solver": one["solver"],
            "threads_1": one, "threads_2": two,
            "speedup_wall": one["wall_s"] / two["wall_s"],
            "speedup_by_stage": {s: one["stages_s"][s] / two["stages_s"][s]
                                 for s in one["stages_s"] if two["stages_s"].get(s)},
            "share_1_thread": {s: one["stages_s"][s] / one["wall_s"] for s in one["stages_s"]
                               if s != "total"},
            "E_eff_equal": one["E_eff_Pa"] == two["E_eff_Pa"],
            "peak_bytes_per_voxel_2_threads": two["peak_rss_GB"] * 1e9 / n ** 3})
    return rows


def measure_dipoles(n_particles: int, work: Path) -> dict:
    runs = _draw_and_run(
        n_particles, f"dip{n_particles}",
        lambda rve: [MAPSIM, "rve", "--load", str(rve), "--B", "0.1", "--gradB", "1.78"], work,
        lambda d: {"magnetics": d["summary"]["magnetics"]})
    one, two = runs[1], runs[2]
    return {"n_particles": n_particles, "threads_1": one, "threads_2": two,
            "speedup_wall": one["wall_s"] / two["wall_s"],
            "results_equal": one["magnetics"] == two["magnetics"]}


def markdown(rows: list, dip: dict | None = None) -> str:
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
    if dip:
        lines += ["## The dipole solve (particle-mesh Ewald)", "",
                  "`mapsim rve --load RVE --B 0.1 --gradB 1.78` (self-consistent moments and "
                  "forces), NUMBA_NUM_THREADS=1 then 2, whole command by `/usr/bin/time -v`.", "",
                  "| particles | wall 1 / 2 threads [s] | speed-up | peak RSS 1 / 2 [GB] | "
                  "magnetics equal |", "|---|---|---|---|---|",
                  f"| {dip['n_particles']} | {dip['threads_1']['wall_s']:.1f} / "
                  f"{dip['threads_2']['wall_s']:.1f} | {dip['speedup_wall']:.2f}x | "
                  f"{dip['threads_1']['peak_rss_GB']:.2f} / {dip['threads_2']['peak_rss_GB']:.2f} "
                  f"| {dip['results_equal']} |", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("cells", "dipoles"), default=None,
                    help="re-measure this part only; the other is kept from threads.json")
    a = ap.parse_args(argv)
    out = Path(tempfile.mkdtemp()) if a.quick else HERE
    old = (json.loads((HERE / "threads.json").read_text())
           if a.only and (HERE / "threads.json").exists() else {})
    with tempfile.TemporaryDirectory() as work:
        rows = (measure(QUICK if a.quick else GRIDS, Path(work)) if a.only != "dipoles"
                else old.get("rows", []))
        dip = (measure_dipoles(DIPOLES_QUICK if a.quick else DIPOLES, Path(work))
               if a.only != "cells" else old.get("dipoles"))
    from importlib import metadata
    doc = {"rows": rows, "dipoles": dip, "cpu_count": os.cpu_count(),
           "versions": {k: metadata.version(k) for k in ("numpy", "scipy", "numba", "pyamg")},
           "command": "results/bench/threads.py"}
    (out / "threads.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "threads.md").write_text(markdown(rows, dip))
    print(markdown(rows, dip))
    return 0


if __name__ == "__main__":
    sys.exit(main())
