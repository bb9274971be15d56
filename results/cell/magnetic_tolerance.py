"""How loosely the magnetic column of the cell problem may be solved: the numbers behind
results/cell/magnetic_tolerance.json and the "Magnetic column tolerance" section of
results/cell/README.md (homogenize.cell.problem.magnetic_tol).

The elastic magnetic stress is variational in the six unit-strain solutions w_a and the
magnetic one w_m, -(f_a . w_m + b . w_a - w_a . K w_m) / V, so its error is the energy product
e_a . K e_m / V of the two solution errors: with the strains at the default relative residual
1e-6, the magnetic column can stop much earlier. For each RVE and load, against a reference with
every column at 1e-9, the relative error of the elastic magnetic stress (of its largest
component), of the total magnetic stress (elastic + force moment) and of C_eff, the iterations
and the wall time, for magnetic tolerances 1e-6 (every column alike, the solver before
2026-11-24 session 10) to 1e-2; also the error of the formula linear in the magnetic solution,
settings["stress_mag_linear_error_rel"], which the solver reports (relative to the largest
component of the total magnetic stress, like "stress_error_rel").

RVEs: the bench family (homogenize.bench.bench_cell.bench_rve: seed-paper sizes at 3.5 vol%, mean radius
~2.5 voxels) at 32^3 and 64^3, solver="matrix-free"; loads: the dipole forces of the seed
paper's field (micro.dipoles.solve at 0.1 T, 1.78 T/m gradient, Froehlich-Kennelly Fe) with
their virial stress, and random particle forces (the bench's load).

Run: .venv/bin/python results/cell/magnetic_tolerance.py          (~6 min, ~1.5 GB)
     --quick: 16^3 and 24^3 only, into --out (default: the committed JSON).
"""
import argparse
import time
from pathlib import Path

import numpy as np

from homogenize.bench.bench_cell import bench_rve
from homogenize.cell.problem import homogenize_rve, tensor_to_voigt
from homogenize.solvers import SolverOptions
from micro.dipoles import solve

import resumable

HERE = Path(__file__).resolve().parent
JSON = HERE / "magnetic_tolerance.json"
TOLS_MAGNETIC = (1e-6, 1e-4, 1e-3, 1e-2)


def _rel(a, b, scale) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / scale)


#: the matrix-free V-cycle as when the JSON was made (session 10): no interface sweeps
#: (SolverOptions.matfree_interface_sweeps, session 11), independent CG columns
#: (SolverOptions.block_cg, session 12) and no particle patches (SolverOptions.patch_shell_voxels,
#: session 14)
OPTIONS = SolverOptions(matfree_interface_sweeps=0, block_cg="independent",
                        patch_shell_voxels=None)


def study(voxels: int, solver: str = "matrix-free") -> list[dict]:
    rve = bench_rve(voxels)
    st = solve(rve, 0.1, 1.78, "frohlich-kennelly")
    loads = {"dipole": (st.total_force_N, np.asarray(st.virial_stress_Pa)),
             "random": (np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15, None)}
    rows = []
    for load, (forces, virial) in loads.items():
        kw = dict(forces_N=forces, virial_stress_Pa=virial, solver=solver, options=OPTIONS)
        ref = homogenize_rve(rve, voxels, tol=1e-9, tol_magnetic=1e-9, **kw)
        s_el = tensor_to_voigt(ref.stress_mag_elastic_Pa)
        s_tot = tensor_to_voigt(ref.stress_mag_Pa)
        for tm in TOLS_MAGNETIC:
            t0 = time.perf_counter()
            r = homogenize_rve(rve, voxels, tol=1e-6, tol_magnetic=tm, **kw)
            sec = time.perf_counter() - t0
            it = r.iterations
            rows.append({
                "voxels": voxels, "n_particles": int(rve.n), "load": load, "solver": solver,
                "tol": 1e-6, "tol_magnetic": tm, "seconds": sec,
                "max_strain_iterations": max(v for k, v in it.items() if k != "magnetic"),
                "magnetic_iterations": it["magnetic"],
                "stress_elastic_error_rel": _rel(tensor_to_voigt(r.stress_mag_elastic_Pa), s_el,
                                                 np.abs(s_el).max()),
                "stress_error_rel": _rel(tensor_to_voigt(r.stress_mag_Pa), s_tot,
                                         np.abs(s_tot).max()),
                "stress_linear_error_estimate_rel": r.settings["stress_mag_linear_error_rel"],
                "C_error_rel": _rel(r.C_eff_Pa, ref.C_eff_Pa, np.abs(ref.C_eff_Pa).max())})
            print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=JSON)
    ap.add_argument("--quick", action="store_true", help="16^3 and 24^3 only")
    args = ap.parse_args()
    rows = []
    for n in ((16, 24) if args.quick else (32, 64)):
        rows += study(n)
        # rewritten after every grid: an interrupted study keeps the grids done
        resumable.write(args.out, rows, "results/cell/magnetic_tolerance.py"
                         + (" --quick" if args.quick else ""),
                         "strain columns at relative residual 1e-6, the magnetic column at "
                         "tol_magnetic; errors relative to the largest component of the "
                         "reference (every column at 1e-9); seconds: wall time, not a benchmark")


if __name__ == "__main__":
    main()
