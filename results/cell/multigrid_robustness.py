"""Why the matrix-free solver's iterations grow with the RVE, and why solver="fast" stays the
default: the numbers behind results/cell/multigrid_robustness.json and the "multigrid
robustness" section of results/cell/README.md.

Same RVE family and load as `mapsim bench` (homogenize.bench.bench_cell.bench_rve: the seed paper's size
distribution at 3.5 vol%, particle count chosen for a mean radius of 2.5 voxels at `rve_voxels`;
6 unit strains + random particle forces, tol 1e-6 for every column: the magnetic one too, as
when the JSON was made, although since session 10 it stops at homogenize.cell.problem.magnetic_tol by
default), solved on `voxels` per edge:

* fixed resolution (rve_voxels == voxels, mean radius 2.5 voxels), growing particle count;
* particles at half the resolution (rve_voxels == 2 voxels, mean radius 1.25 voxels);
* the matrix-free V-cycle with its assembled coarse grid solved EXACTLY (sparse LU,
  SolverOptions.matfree_coarse = "lu"): if the iterations stay, the geometric (trilinear)
  level limits convergence, not the AMG below it;
* the matrix-free cases again with one more Gauss-Seidel sweep per side over the interface
  nodes (interface_sweeps 1, the default since session 11; the rows with 0 are the V-cycle
  before it);
* the matrix-free cases with the load cases in one coupled block CG (block_cg "coupled",
  SolverOptions.block_cg, the default since session 12; rows without the key, or
  with "independent", ran lock-step independent CGs).

Iteration counts are deterministic; seconds are wall times on whatever else the machine ran.
Run: .venv/bin/python results/cell/multigrid_robustness.py          (~25 min, ~3 GB)
     --out F writes the JSON to F instead of the committed file; --missing runs only the cases
     that file does not hold yet (the JSON is rewritten after every case).
"""
import time
from pathlib import Path

import numpy as np

import homogenize.cell.problem as cell
from homogenize.solvers import SolverOptions
from homogenize.bench.bench_cell import bench_rve

import resumable

HERE = Path(__file__).resolve().parent
JSON = HERE / "multigrid_robustness.json"
#: (rve_voxels, voxels, solver, coarse, interface_sweeps, block_cg); the rows with
#: interface_sweeps 0 are the matrix-free V-cycle before session 11, those with 1 and
#: "independent" the default of session 11 (SolverOptions.matfree_interface_sweeps: one more
#: sweep per side over the interface nodes), those with "coupled" the present default
#: (SolverOptions.block_cg: one block Krylov space for all load cases)
_MF = [(32, 32), (48, 48), (64, 64), (96, 96), (64, 32), (96, 48), (128, 64)]
_I, _C = "independent", "coupled"
PLAN = ([(32, 32, "matrix-free", "amg", 0, _I), (48, 48, "matrix-free", "amg", 0, _I),
         (64, 64, "matrix-free", "amg", 0, _I), (96, 96, "matrix-free", "amg", 0, _I),
         (32, 32, "fast", None, 0, _I), (48, 48, "fast", None, 0, _I),
         (64, 64, "fast", None, 0, _I),
         (64, 32, "matrix-free", "amg", 0, _I), (64, 32, "fast", None, 0, _I),
         (96, 48, "matrix-free", "amg", 0, _I), (96, 48, "fast", None, 0, _I),
         (128, 64, "matrix-free", "amg", 0, _I), (128, 64, "fast", None, 0, _I),
         (64, 32, "matrix-free", "lu", 0, _I), (96, 48, "matrix-free", "lu", 0, _I)]
        + [(a, b, "matrix-free", "amg", 1, _I) for a, b in _MF]
        + [(64, 32, "matrix-free", "lu", 1, _I), (96, 48, "matrix-free", "lu", 1, _I)]
        + [(a, b, "matrix-free", "amg", 1, _C) for a, b in _MF])


def run(rve_voxels: int, voxels: int, solver: str, coarse, interface_sweeps: int,
        block_cg: str) -> dict:
    rve = bench_rve(rve_voxels, 1)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    opts = SolverOptions(matfree_coarse=coarse or "amg",
                         matfree_interface_sweeps=interface_sweeps, block_cg=block_cg,
                         # no particle patches (session 14): the multigrid as measured here
                         patch_shell_voxels=None)
    t0 = time.perf_counter()
    r = cell.homogenize_rve(rve, voxels, forces_N=forces, solver=solver, tol_magnetic=1e-6,
                            options=opts)
    sec = time.perf_counter() - t0
    it = r.iterations
    return {"rve_voxels": rve_voxels, "voxels": voxels, "n_particles": int(rve.n),
            "mean_radius_voxels": 2.5 * voxels / rve_voxels, "solver": solver,
            "coarse": coarse, "interface_sweeps": interface_sweeps,
            "block_cg": r.settings["block_cg"], "iterations": it,
            "max_strain_iterations": max(v for k, v in it.items() if k != "magnetic"),
            "magnetic_iterations": it["magnetic"], "seconds": sec,
            "E_eff_Pa": r.E_eff_Pa}


def main() -> None:
    out, rows = resumable.parse(__doc__, JSON)
    for r in rows:      # rows made before session 11: no interface sweeps; before 12: independent
        r.setdefault("interface_sweeps", 0)
        r.setdefault("block_cg", "independent")
    key = ("rve_voxels", "voxels", "solver", "coarse", "interface_sweeps", "block_cg")
    have = {tuple(r[k] for k in key) for r in rows}
    for case in PLAN:
        if case in have:
            continue
        rows.append(run(*case))
        print(rows[-1], flush=True)
        rows.sort(key=lambda r: [PLAN.index(tuple(r[k] for k in key))])
        resumable.write(out, rows, "results/cell/multigrid_robustness.py",
                         "iterations of the deflated block CG to relative residual 1e-6; seconds: "
                         "wall time, not a benchmark (see results/bench/cell.json for timed runs)")


if __name__ == "__main__":
    main()
