"""Where one CG iteration of solver="matrix-free" spends its time: the numbers behind "Session 8"
in results/cell/README.md (section "Matrix-free solver: what was tried ...").

The bench RVE of `mapsim bench` (homogenize.bench.cell._rve) at 64^3 (100 particles, mean radius
~2.5 voxels, composite voxels), the solver built exactly as homogenize_mesh builds it; for
k = 1..8 right-hand sides (random, fixed seed) the median of 5 timings of: the fine-level product
K u, one 8-colour block Gauss-Seidel sweep on the fine level, one sweep over the interface nodes
only (since session 11, homogenize.cell.MATFREE_INTERFACE_SWEEPS), and one whole V-cycle (all
sweeps, the residual, the transfers and the assembled 32^3 grid's AMG cycle). Also the share of
fine nodes that read their own stencil row (next to a cut voxel or a phase boundary) and the
share of interface nodes (those grown by MATFREE_INTERFACE_HALO nodes).
The committed JSON is session 8's: no interface sweeps then (no interface_sweep_s column, the
V-cycle without them). A run in session 11 on a machine ~1.6x slower than in session 8 (k = 7:
product 0.091 s, full sweep 0.125 s, interface sweep 0.049 s, V-cycle 0.59 s) was not committed
(results/cell/README.md, "Local sweeps at the interfaces").

Timings depend on the machine's load: run it alone.
Run: .venv/bin/python results/cell/per_iteration_costs.py [--voxels 64] [--out F]   (~1 min)
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from homogenize import cell
from homogenize.bench.cell import _rve
from homogenize.mesh import voxelize
from micro.materials import FE, PDMS, elastic

HERE = Path(__file__).resolve().parent


def _median_time(f, reps=5):
    f()                                   # compile / warm the caches
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxels", type=int, default=64)
    ap.add_argument("--out", type=Path, default=HERE / "per_iteration_costs.json")
    args = ap.parse_args()
    n = args.voxels
    mesh = voxelize(_rve(n), n, method="composite")
    lam, mu, comp = cell._composite_fields(mesh, elastic(PDMS), elastic(FE))
    s = cell._CellSolver(mesh, lam, mu, deflate=True, stiff_mask=mesh.fraction >= 0.5, tol=1e-6,
                         maxiter=2000, solver="matrix-free", composite=comp)
    op, M = s.matvec, s.M
    fine = M.levels[0]
    rng = np.random.default_rng(0)
    rows = []
    for k in range(1, 9):
        B = rng.normal(size=(3 * n ** 3, k))
        X = np.zeros_like(B)
        row = {"k": k,
               "product_s": _median_time(lambda: op @ B),
               "gauss_seidel_sweep_s": _median_time(lambda: op.gauss_seidel(X, B, fine.colours)),
               "interface_sweep_s": _median_time(
                   lambda: op.gauss_seidel(X, B, fine.interface_colours)),
               "v_cycle_s": _median_time(lambda: M @ B)}
        row["v_cycle_per_column_s"] = row["v_cycle_s"] / k
        rows.append(row)
        print(" ".join(f"{key} {v:.4f}" if isinstance(v, float) else f"{key} {v}"
                       for key, v in row.items()), flush=True)
    out = {"voxels": n, "n_particles": int(mesh.n_particles),
           "own_stencil_row_share": op.own_share,
           "interface_share": fine.interface_share,
           "interface_sweeps_per_side": cell.MATFREE_INTERFACE_SWEEPS, "rows": rows,
           "command": "results/cell/per_iteration_costs.py --voxels %d" % n,
           "note": "medians of 5; random right-hand sides; run alone (timings follow the load)"}
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
