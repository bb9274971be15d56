"""What the block CG's stopping quantities say about the error, with and without particle patches
(session 14): the numbers behind "Stopping rule for the patches" in results/cell/README.md.

With particle patches (homogenize.solvers.matfree.ParticlePatches) the relative residual ||r|| / ||f|| stops the CG
while the error is still large (session 13: 5-6 iterations, E_eff 2e-5 off at tol 1e-6). This
study records, per CG iteration and load column, on the real cell problem of
homogenize.cell.problem.homogenize_rve (6 strains + the magnetic column, "strains" block CG, no column
leaves the block):
- ``residual``: ||r|| / ||f|| (today's stopping quantity);
- ``natural``: sqrt(r^T M r / f^T M f), M the preconditioner (the energy norm of the error as the
  preconditioner sees it; PETSc's "natural" norm);
- ``error``: the energy of the error over the energy of the solution, e^T K e / f^T x with
  e = x - x_ref (x_ref: the same problem solved to 1e-12). For a strain column this is the
  relative error of its diagonal effective modulus to first order (variational: dC_aa = e^T K e
  / V), since the fluctuation energy f^T x is below V C_aa.
for the default matrix-free solver and for the patches (shell MATFREE_PATCH_SHELL_STUDY voxels).

RVEs: homogenize.bench.bench_cell.bench_rve(rve_voxels) on `voxels`^3, random particle forces: (64, 32): 100
particles of 1.25 voxels mean radius; (128, 64): 801 of 1.25 voxels (the hard case); (64, 64):
the 64^3 bench RVE, 100 particles of ~2.5 voxels.

Run: .venv/bin/python results/cell/patch_stopping.py [--missing]   (~10 min)
"""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
JSON = HERE / "patch_stopping.json"
RVES = [(64, 32), (128, 64), (64, 64)]
MATFREE_PATCH_SHELL_STUDY = 0.5
ITERATIONS = {"default": 60, "patches": 35}


def run(rve_voxels: int, voxels: int, variant: str) -> dict:
    import homogenize.cell.problem as cell
    from homogenize.bench.bench_cell import bench_rve
    from homogenize.solvers import SolverOptions, coupled_block_cg
    rve = bench_rve(rve_voxels, 1)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    rec = {}
    orig = coupled_block_cg

    def instrumented(A, M, F, *, tol, maxiter, deflation=None, callback=None, groups=None):
        Xref, _ = orig(A, M, F, tol=1e-12, maxiter=400, deflation=deflation, groups=groups)
        fMf = np.einsum("ij,ij->j", F, M(F))
        fx = np.einsum("ij,ij->j", F, Xref)
        fn = np.linalg.norm(F, axis=0)
        res, nat, err = [], [], []

        def Mw(R):
            Z = M(R)
            nat.append(np.sqrt(np.abs(np.einsum("ij,ij->j", R, Z)) / fMf).tolist())
            return Z

        class Dw:
            def __getattr__(self, name):
                return getattr(deflation, name)

            def correct(self, X, R):
                deflation.correct(X, R)
                res.append((np.linalg.norm(R, axis=0) / fn).tolist())
                E = X - Xref
                err.append((np.einsum("ij,ij->j", E, A(E)) / fx).tolist())

        orig(A, Mw, F, tol=1e-30, maxiter=ITERATIONS[variant], deflation=Dw(), groups=groups)
        rec.update(residual=res, natural=nat[1:], error=err)
        return Xref, [[0.0]] * F.shape[1]

    # the instrumented block CG in place of the solver's (SolverOptions.krylov)
    opts = SolverOptions(krylov=instrumented, patch_shell_voxels=(
        MATFREE_PATCH_SHELL_STUDY if variant == "patches" else None))
    cell.homogenize_rve(rve, voxels, forces_N=forces, solver="matrix-free", tol=1e-6,
                        options=opts)
    return {"rve_voxels": rve_voxels, "voxels": voxels, "n_particles": int(rve.n),
            "variant": variant, "shell_voxels": (MATFREE_PATCH_SHELL_STUDY
                                                 if variant == "patches" else None),
            "columns": ["e11", "e22", "e33", "g23", "g13", "g12", "magnetic"], **rec}


def stop_table(row: dict, quantity: str, tol: float, tol_magnetic: float) -> dict:
    """Iteration at which each column first has ``quantity`` <= its tol, and its error there."""
    q = np.asarray(row[quantity])
    e = np.asarray(row["error"])
    tols = np.array([tol] * 6 + [tol_magnetic])
    its, errs = [], []
    for c in range(q.shape[1]):
        hit = np.flatnonzero(q[:, c] <= tols[c])
        j = int(hit[0]) if hit.size else q.shape[0] - 1
        its.append(j + 1)
        errs.append(float(e[j, c]))
    return {"iterations": its, "error": errs}


def main() -> None:
    if sys.argv[1:2] == ["--one"]:
        print(json.dumps(run(int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])))
        return
    sys.path.insert(0, str(HERE))
    import resumable
    out, rows = resumable.parse(__doc__, JSON)
    have = {(r["rve_voxels"], r["voxels"], r["variant"]) for r in rows}
    for a, b in RVES:
        for variant in ("default", "patches"):
            if (a, b, variant) in have:
                continue
            res = subprocess.run([sys.executable, __file__, "--one", str(a), str(b), variant],
                                 check=True, capture_output=True, text=True)
            row = json.loads(res.stdout.strip().splitlines()[-1])
            rows.append(row)
            for quantity, tol in (("residual", 1e-6), ("residual", 1e-8), ("natural", 1e-4),
                                  ("natural", 1e-5), ("natural", 1e-6)):
                t = stop_table(row, quantity, tol, np.sqrt(tol) if quantity == "residual"
                               else tol)
                print(a, b, variant, quantity, tol, max(t["iterations"][:6]),
                      t["iterations"][6], "%.1e %.1e" % (max(t["error"][:6]), t["error"][6]),
                      flush=True)
            resumable.write(out, rows, "results/cell/patch_stopping.py",
                             "per CG iteration and column: residual, natural norm, error energy")


if __name__ == "__main__":
    main()
