"""Which cell solver for rigid particles (issue 37, session 22): the numbers behind
``homogenize.cell.problem.AUTO_MAX_PHI_PATCHED`` and "Rigid particles" under "Solver choice" in
results/cell/README.md.

On as-placed RVEs (Fe 25 nm monodisperse, the dipole forces of a 0.6 T field along z with the
linear law, tol 1e-6, cold start, six strains + the magnetic column) it times, one after the
other in this process, ``solver="fast"`` against ``solver="matrix-free"`` with a particle patch on
every particle (``SolverOptions(patch_min_particles=1)``), for rigid particles (``rigid=True``,
what "auto" decides for) and, for comparison, for Fe particles. Each record: seconds, the largest
strain iteration count and the magnetic one of each, the ratio fast / matrix-free, and the largest
relative difference of C_eff and of the magnetic stress between the two.

Writes rigid_solver_choice.json next to this file.
Run: .venv/bin/python results/cell/rigid_solver_choice.py [--quick]   (~8 min; quick: 2 RVEs)
"""
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from micro import Monodisperse, generate_rve, write_json
from micro.dipoles import solve as solve_dipoles
from micro.materials import PDMS, elastic
from homogenize.cell.problem import homogenize_mesh
from homogenize.solvers import SolverOptions
from homogenize.voxels import voxelize

HERE = Path(__file__).resolve().parent
JSON = HERE / "rigid_solver_choice.json"
#: (particle volume fraction, particles, voxels per edge)
RVES = [(0.1, 30, 24), (0.02, 20, 32), (0.05, 50, 48), (0.1, 100, 48), (0.2, 200, 48),
        (0.3, 150, 32)]
RADIUS_M = 25e-9
B_T = 0.6


def _one(mesh, forces, virial, rigid: bool, solver: str) -> dict:
    opts = SolverOptions().replace(patch_min_particles=1) if solver == "matrix-free" else None
    t0 = time.perf_counter()
    r = homogenize_mesh(mesh, forces_N=forces, virial_stress_Pa=virial, matrix=elastic(PDMS),
                        rigid=rigid, solver=solver, options=opts)
    dt = time.perf_counter() - t0
    return {"seconds": dt,
            "strain_iterations": max(v for k, v in r.iterations.items() if k != "magnetic"),
            "magnetic_iterations": r.iterations["magnetic"],
            "patched_particles": r.settings.get("patched_particles", 0),
            "C_eff_Pa": np.asarray(r.C_eff_Pa), "stress_mag_Pa": np.asarray(r.stress_mag_Pa)}


def main(quick: bool = False) -> list:
    out = []
    for phi, n, vox in (RVES[:2] if quick else RVES):
        rve = generate_rve(phi, n, 7, distribution=Monodisperse(RADIUS_M))
        st = solve_dipoles(rve, np.array([0.0, 0.0, B_T]), 0.0, "linear")
        mesh = voxelize(rve, vox)
        for rigid in (True, False):
            f = _one(mesh, st.total_force_N, st.virial_stress_Pa, rigid, "fast")
            m = _one(mesh, st.total_force_N, st.virial_stress_Pa, rigid, "matrix-free")
            rec = {"phi": phi, "particles": n, "voxels": vox,
                   "radius_voxels": RADIUS_M / mesh.h_m, "phi_voxel": float(mesh.fraction.mean()),
                   "rigid": rigid, "fast_seconds": f["seconds"],
                   "matrix_free_patches_seconds": m["seconds"],
                   "ratio_fast_over_matrix_free": f["seconds"] / m["seconds"],
                   "fast_iterations_strain_magnetic": [f["strain_iterations"],
                                                       f["magnetic_iterations"]],
                   "matrix_free_iterations_strain_magnetic": [m["strain_iterations"],
                                                              m["magnetic_iterations"]],
                   "patched_particles": m["patched_particles"],
                   "C_eff_rel_diff": float(np.abs(f["C_eff_Pa"] - m["C_eff_Pa"]).max()
                                           / np.abs(f["C_eff_Pa"]).max()),
                   "stress_mag_rel_diff": float(np.abs(f["stress_mag_Pa"] - m["stress_mag_Pa"])
                                                .max() / np.abs(f["stress_mag_Pa"]).max())}
            out.append(rec)
            print(json.dumps({k: v for k, v in rec.items()}), flush=True)
    return out


if __name__ == "__main__":
    quick = "--quick" in sys.argv[1:]
    recs = main(quick)
    if not quick:
        write_json(JSON, {"records": recs, "load_average_1_5_15min_after": list(os.getloadavg()),
                          "note": "one process, both solvers one after the other per RVE; tol 1e-6"})
