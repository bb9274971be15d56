"""Why the matrix-free solver's magnetic column needs more iterations than the strains, and four
ways of giving it more search directions that were measured and NOT kept (session 13): the
numbers behind "Session 13" in results/cell/README.md.

The magnetic column (random particle forces, stopped at magnetic_tol = 1e-3) needs 1.6-2x the
iterations of the six strains (stopped at 1e-6) on the bench RVEs, and runs on alone after
them (128^3: strains 70-94, magnetic 190). Its residual history has a long plateau (`history`
rows: every column to 1e-6, 100 particles of 1.25 voxels at 32^3). Variants of the block CG
(homogenize.solvers.coupled_block_cg), each as a drop-in for it (SolverOptions.krylov):

* "strains": the default (six strains coupled, the magnetic column on its own recursion);
* "coupled": all seven columns in one block that shrinks as columns converge;
* "keep": one block of all seven that never shrinks -- converged columns keep contributing
  search directions (and keep improving) until the last one has converged;
* "coupled+scaled": "coupled" with every load column scaled to unit norm first (the magnetic
  load is ~1e-12 of the strains' in absolute terms);
* "coupled+restart": "coupled" restarted (P = Z) whenever columns leave the block;
* "split3" / "split6": the magnetic load split into 3 columns (its x, y, z components) or 6
  (each component on the two halves x < L/2, x >= L/2 of the cell, every column balanced),
  coupled among themselves, the strains as in "strains"; the solutions summed.

Iterations are deterministic (max over the strains / the magnetic column); seconds are those of
the machine at the time (each case in its own process). RVEs: homogenize.bench.bench_cell.bench_rve with
(rve_voxels, voxels) = (64, 32): 100 particles of 1.25 voxels mean radius at 32^3, (128, 64): 801
at 64^3, (128, 128): the 128^3 bench RVE (~10-14 min per case: only with --full).

Run: .venv/bin/python results/cell/magnetic_column_experiments.py [--missing] [--full]
     (~10 min without --full; --full adds "keep" at 128^3, ~14 min, peak 5.1 GB)
"""
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
JSON = HERE / "magnetic_column_experiments.json"
VARIANTS = ("strains", "coupled", "keep", "coupled+scaled", "coupled+restart", "split3", "split6")
PLAN = ([("history", 64, 32)] + [(v, 64, 32) for v in VARIANTS]
        + [(v, 128, 64) for v in VARIANTS])
FULL_PLAN = [("keep", 128, 128)]


def _keep_block_cg(A, M, F, *, tol, maxiter, deflation=None, callback=None, groups=None):
    """Block CG over all columns that never shrinks (O'Leary's, as coupled_block_cg)."""
    import numpy as np

    from homogenize.solvers.krylov import (CG_CHUNK, block_directions, block_step, cg_start,
                                           colnorms, gram, group_pinv, own)
    k = F.shape[1]
    X, Xa, R, hist, idx, fa, tols = cg_start(A, F, tol, deflation)
    if idx.size != k:
        raise ValueError("every column must be active at the start")
    g = np.zeros(k, np.int64) if groups is None else np.asarray(groups)
    same = g[:, None] == g[None, :]
    P = own(M(R), R)
    if deflation is not None:
        deflation.project(P)
    conv = np.zeros(k, bool)
    it = 0
    while not conv.all() and it < maxiter:
        Q = own(A(P), P)
        Gi = group_pinv(gram(P, Q), g)
        block_step(Xa, R, P, Q, np.ascontiguousarray(Gi @ (gram(P, R) * same)))
        if deflation is not None:
            deflation.correct(Xa, R)
        it += 1
        res = colnorms(R) / fa
        for c in np.flatnonzero(~conv):
            hist[c].append(float(res[c]))
        conv |= res <= tols
        Z = own(M(R), R)
        if deflation is not None:
            deflation.project(Z)
        beta = np.ascontiguousarray(-(Gi @ (gram(Q, Z) * same)))
        del Q
        block_directions(P, Z, beta, CG_CHUNK, P)
    return Xa, hist


def _restart_block_cg(A, M, F, *, tol, maxiter, deflation=None, callback=None, groups=None):
    """coupled_block_cg restarted (P = Z) whenever columns leave the block."""
    import numpy as np

    from homogenize.solvers.krylov import (CG_CHUNK, block_directions, block_step, cg_start,
                                           colnorms, gram, group_pinv, own, record_step)
    k = F.shape[1]
    X, Xa, R, hist, idx, fa, tols = cg_start(A, F, tol, deflation)
    labels = np.zeros(k, np.int64) if groups is None else np.asarray(groups)
    P = own(M(R), R)
    if deflation is not None:
        deflation.project(P)
    it = 0
    while idx.size and it < maxiter:
        g = labels[idx]
        Q = own(A(P), P)
        Gi = group_pinv(gram(P, Q), g)
        block_step(Xa, R, P, Q,
                      np.ascontiguousarray(Gi @ (gram(P, R) * (g[:, None] == g[None, :]))))
        if deflation is not None:
            deflation.correct(Xa, R)
        it += 1
        done = record_step(hist, idx, colnorms(R) / fa, tols, k, it, callback)
        if done.any():
            X[:, idx[done]] = Xa[:, done]
            idx, fa = idx[~done], fa[~done]
            if idx.size == 0:
                break
            Xa = np.ascontiguousarray(Xa[:, ~done])
            R = np.ascontiguousarray(R[:, ~done])
        Z = own(M(R), R)
        if deflation is not None:
            deflation.project(Z)
        if done.any():
            P = Z
            continue
        beta = np.ascontiguousarray(-(Gi @ (gram(Q, Z) * (g[:, None] == labels[idx][None, :]))))
        del Q
        block_directions(P, Z, beta, CG_CHUNK, P)
    if idx.size:
        X[:, idx] = Xa
    return X, hist


def _split_block_cg(nsplit: int):
    """The magnetic column (the 7th) split into 3 or 6 balanced columns coupled among
    themselves, the strains coupled as in "strains"; solutions summed, the magnetic history is
    the slowest part's."""
    import numpy as np

    from homogenize.solvers import coupled_block_cg

    def solve(A, M, F, *, tol, groups=None, **kw):
        if F.shape[1] != 7:
            return coupled_block_cg(A, M, F, tol=tol, groups=groups, **kw)
        b = F[:, 6]
        parts = []
        for c in range(3):
            bc = np.zeros_like(b)
            bc[c::3] = b[c::3]
            parts.append(bc)
        if nsplit == 6:
            n = round((b.size // 3) ** (1 / 3))
            half = (np.arange(b.size) // 3) % n < n // 2
            parts = [p * h for p in parts for h in (half, ~half)]
            for p in parts:                      # every column balanced: zero net force
                for d in range(3):
                    p[d::3] -= p[d::3].mean()
        t = np.broadcast_to(np.asarray(tol, float), (7,))
        X, h = coupled_block_cg(A, M, np.column_stack([F[:, :6]] + parts),
                                tol=np.concatenate([t[:6], np.full(len(parts), t[6])]),
                                groups=[0] * 6 + [1] * len(parts), **kw)
        return (np.column_stack([X[:, :6], X[:, 6:].sum(axis=1)]),
                h[:6] + [max(h[6:], key=len)])
    return solve


def _scaled_block_cg(A, M, F, **kw):
    import numpy as np

    from homogenize.solvers import coupled_block_cg
    s = np.linalg.norm(F, axis=0)
    s[s == 0.0] = 1.0
    X, h = coupled_block_cg(A, M, F / s, **kw)
    return X * s, h


def one(variant: str, rve_voxels: int, voxels: int) -> dict:
    import numpy as np

    import homogenize.cell.problem as cell
    from homogenize.bench.bench_cell import bench_rve
    from homogenize.solvers import SolverOptions, coupled_block_cg
    rve = bench_rve(rve_voxels, 1)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    mode = "strains" if variant in ("strains", "history", "split3", "split6") else "coupled"
    solver = {"keep": _keep_block_cg, "coupled+restart": _restart_block_cg,
              "coupled+scaled": _scaled_block_cg, "split3": _split_block_cg(3),
              "split6": _split_block_cg(6)}.get(variant, coupled_block_cg)
    seen = {}

    def spy(*a, **kw):
        X, h = solver(*a, **kw)
        seen["hist"] = h
        return X, h
    # the solver of session 13: no particle patches (the default since session 14)
    opts = SolverOptions(block_cg=mode, krylov=spy, patch_shell_voxels=None)
    # "history": every column to 1e-6 (the default tol), the magnetic one too
    tol_magnetic = 1e-6 if variant == "history" else None
    t0 = time.perf_counter()
    r = cell.homogenize_rve(rve, voxels, forces_N=forces, solver="matrix-free", options=opts,
                            tol_magnetic=tol_magnetic)
    sec = time.perf_counter() - t0
    it = r.iterations
    row = {"variant": variant, "rve_voxels": rve_voxels, "voxels": voxels,
           "n_particles": int(rve.n), "iterations": it,
           "max_strain_iterations": max(v for k, v in it.items() if k != "magnetic"),
           "magnetic_iterations": it["magnetic"], "seconds": sec, "E_eff_Pa": r.E_eff_Pa,
           "stress_mag_Pa": np.asarray(r.stress_mag_Pa).tolist(),
           "peak_rss_GB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9}
    if variant == "history":
        row["residual_histories"] = {name: [float(v) for v in h]
                                     for name, h in zip(list(it), seen["hist"])}
    return row


def main() -> None:
    if sys.argv[1:2] == ["--one"]:
        print(json.dumps(one(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))))
        return
    sys.path.insert(0, str(HERE))
    import resumable
    out, rows, full = resumable.parse(__doc__, JSON, with_full=True)
    key = ("variant", "rve_voxels", "voxels")
    plan = PLAN + (FULL_PLAN if full else [])
    have = {tuple(r[k] for k in key) for r in rows}
    order = PLAN + FULL_PLAN
    for case in plan:
        if case in have:
            continue
        res = subprocess.run([sys.executable, __file__, "--one", *map(str, case)],
                             check=True, capture_output=True, text=True)
        rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print({k: v for k, v in rows[-1].items() if k != "residual_histories"}, flush=True)
        rows.sort(key=lambda r: order.index(tuple(r[k] for k in key)))
        resumable.write(out, rows, "results/cell/magnetic_column_experiments.py"
                         + (" --full" if full else ""),
                         "each case in its own process; iterations deterministic, seconds "
                         "the machine's at the time; variants are drop-ins for "
                         "homogenize.solvers.coupled_block_cg defined in the script")


if __name__ == "__main__":
    main()
