"""How the matrix-free solver's load cases share their CG search directions
(homogenize.solvers.SolverOptions.block_cg): the numbers behind results/cell/block_cg_modes.json
and the "Coupled block CG" section of results/cell/README.md.

Bench RVEs (homogenize.bench.bench_cell.bench_rve: the seed paper's size distribution at 3.5 vol%), 6 unit
strains + random particle forces, the default tolerances (strains 1e-6, magnetic column
magnetic_tol = 1e-3), solver="matrix-free", each case in its OWN process (so that its peak RSS is
its own), the three modes of one RVE one after the other:

* "independent": lock-step single-column CGs (the default of session 11);
* "coupled": all seven columns in one block CG (homogenize.solvers.coupled_block_cg);
* "strains": the six strains coupled, the magnetic column on its own (the default since 12).

Iterations are deterministic; seconds and peak RSS are those of the machine at the time.
Run: .venv/bin/python results/cell/block_cg_modes.py --missing   (the three 128^3 cases ~32 min,
     the rest ~6 min, peak 5.3 GB); --out F writes the JSON to F instead of the committed file.
"""
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
JSON = HERE / "block_cg_modes.json"
MODES = ("independent", "coupled", "strains")
#: (rve_voxels, voxels): 100 / 801 particles of 1.25 voxels mean radius at 32^3 / 64^3, and
#: the bench RVEs of 338 particles at 96^3 and 801 at 128^3 (mean radius 2.5 voxels)
RVES = [(64, 32), (128, 64), (96, 96), (128, 128)]
PLAN = [(a, b, m) for a, b in RVES for m in MODES]


def one(rve_voxels: int, voxels: int, mode: str) -> dict:
    """One case, in this process."""
    import numpy as np

    import homogenize.cell.problem as cell
    from homogenize.bench.bench_cell import bench_rve
    from homogenize.solvers import SolverOptions
    rve = bench_rve(rve_voxels, 1)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    # no particle patches (session 14): the block CG modes as measured in session 12
    opts = SolverOptions(block_cg=mode, patch_shell_voxels=None)
    t0 = time.perf_counter()
    r = cell.homogenize_rve(rve, voxels, forces_N=forces, solver="matrix-free", options=opts)
    sec = time.perf_counter() - t0
    it = r.iterations
    return {"rve_voxels": rve_voxels, "voxels": voxels, "block_cg": r.settings["block_cg"],
            "n_particles": int(rve.n), "iterations": it,
            "max_strain_iterations": max(v for k, v in it.items() if k != "magnetic"),
            "magnetic_iterations": it["magnetic"], "seconds": sec,
            "timings_s": r.timings_s, "E_eff_Pa": r.E_eff_Pa,
            "peak_rss_GB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9}


def main() -> None:
    if sys.argv[1:2] == ["--one"]:              # the child process of one case
        a, b, mode = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
        print(json.dumps(one(a, b, mode)))
        return
    sys.path.insert(0, str(HERE))
    import resumable
    out, rows = resumable.parse(__doc__, JSON)
    key = ("rve_voxels", "voxels", "block_cg")
    have = {tuple(r[k] for k in key) for r in rows}
    for case in PLAN:
        if case in have:
            continue
        res = subprocess.run([sys.executable, __file__, "--one", *map(str, case)],
                             check=True, capture_output=True, text=True)
        rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print(rows[-1], flush=True)
        rows.sort(key=lambda r: PLAN.index(tuple(r[k] for k in key)))
        resumable.write(out, rows, "results/cell/block_cg_modes.py",
                         "each case in its own process, the three modes of one RVE one after "
                         "the other; seconds: wall time of homogenize_rve; peak_rss_GB: the "
                         "process's peak resident set size")


if __name__ == "__main__":
    main()
