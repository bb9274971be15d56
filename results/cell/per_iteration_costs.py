"""Where one CG iteration of solver="matrix-free" spends its time: the numbers behind "Session 8"
in results/cell/README.md (section "Matrix-free solver: what was tried ...").

The bench RVE of `mapsim bench` (homogenize.bench.bench_cell.bench_rve) at 64^3 (100 particles, mean radius
~2.5 voxels, composite voxels), the solver built exactly as homogenize_mesh builds it; for
k = 1..8 right-hand sides (random, fixed seed) the median of 5 timings of: the fine-level product
K u, one 8-colour block Gauss-Seidel sweep on the fine level, one sweep over the interface nodes
only (since session 11, homogenize.solvers.SolverOptions.matfree_interface_sweeps), and one
whole V-cycle (all sweeps, the residual, the transfers and the assembled 32^3 grid's AMG
cycle). Also the share of fine nodes that read their own stencil row (next to a cut voxel or a phase boundary) and the
share of interface nodes (those grown by SolverOptions.matfree_interface_halo nodes).
Since session 13 also the pre-smoothing sweep from zero, plain and skipping the neighbours that
are still zero (``MatFreeOperator.gauss_seidel_from_zero``, both after zeroing the block), and the
V-cycle with the plain first sweep (as before session 13) next to the present one; these two
pairs are timed alternately, medians of 9 each.
Before session 13 the committed JSON was session 8's (no interface sweeps then).

Timings depend on the machine's load: run it alone.
Run: .venv/bin/python results/cell/per_iteration_costs.py [--voxels 64] [--out F]   (~1 min)
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from homogenize.cell import problem as cell
from homogenize.bench.bench_cell import bench_rve
from homogenize.solvers import SolverOptions
from homogenize.voxels.mesh import voxelize
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


def _paired_medians(f, g, reps=9):
    """Medians of f's and g's timings taken alternately (f, g, f, g, ...), so that both see
    the same machine state."""
    f(), g()
    tf, tg = [], []
    for _ in range(reps):
        for fun, ts in ((f, tf), (g, tg)):
            t0 = time.perf_counter()
            fun()
            ts.append(time.perf_counter() - t0)
    return float(np.median(tf)), float(np.median(tg))


def plain_first_sweep(op):
    """A stand-in for ``op.gauss_seidel_from_zero`` that runs the plain sweep (the V-cycle as
    before session 13)."""
    return lambda X, B, colours: op.gauss_seidel(X, B, colours)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxels", type=int, default=64)
    ap.add_argument("--out", type=Path, default=HERE / "per_iteration_costs.json")
    args = ap.parse_args()
    n = args.voxels
    # the V-cycle of session 13, without particle patches (the default since session 14)
    opts = SolverOptions(patch_shell_voxels=None)
    mesh = voxelize(bench_rve(n), n, method="composite")
    s = cell.cell_solver(mesh, matrix=elastic(PDMS), particle=elastic(FE), tol=1e-6,
                         maxiter=2000, solver="matrix-free", options=opts)
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
               # the V-cycle's pre-smoothing sweep from zero: X zeroed, then the plain sweep or
               # the one that skips the neighbours still zero (session 13)
               }
        row["zero_then_sweep_s"], row["zero_then_sweep_from_zero_s"] = _paired_medians(
            lambda: (X.fill(0.0), op.gauss_seidel(X, B, fine.colours)),
            lambda: (X.fill(0.0), op.gauss_seidel_from_zero(X, B, fine.colours)))
        from_zero, plain = op.gauss_seidel_from_zero, plain_first_sweep(op)

        def cycle(first):
            op.gauss_seidel_from_zero = first
            return M @ B
        row["v_cycle_s"], row["v_cycle_plain_first_sweep_s"] = _paired_medians(
            lambda: cycle(from_zero), lambda: cycle(plain))
        del op.gauss_seidel_from_zero
        row["v_cycle_per_column_s"] = row["v_cycle_s"] / k
        rows.append(row)
        print(" ".join(f"{key} {v:.4f}" if isinstance(v, float) else f"{key} {v}"
                       for key, v in row.items()), flush=True)
    out = {"voxels": n, "n_particles": int(mesh.n_particles),
           "own_stencil_row_share": op.own_share,
           "interface_share": fine.interface_share,
           "interface_sweeps_per_side": opts.matfree_interface_sweeps, "rows": rows,
           "command": "results/cell/per_iteration_costs.py --voxels %d" % n,
           "note": "medians of 5; random right-hand sides; run alone (timings follow the load)"}
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
