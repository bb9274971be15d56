"""Effect of the near-field forces on a relaxed RVE: mapsim relax with --near-field off and on.

20 Fe spheres (25 nm, default 'regime' law), phi = 0.05, seed 3, soft matrix (E = 0.5 MPa,
nu = 0.49), field steps 0.1 .. 1.0 T, free boundary, cell FEM at 20^3 voxels. A run that does
not converge is recorded with its error. Writes
results/relax/nearfield_rve.json (per step: strain along the field, M_eff, u_rms, min gap,
contacts, Newton iterations, near-field pairs and force ratio; wall times with the load
average). Run: .venv/bin/python results/relax/nearfield_rve.py
"""
import json
import os
import time
from pathlib import Path


from micro import ConvergenceError
from micro.materials import ElasticMaterial
from micro.particles import Monodisperse, generate_rve
from homogenize.cell.relax import relax

HERE = Path(__file__).resolve().parent


def main():
    rve = generate_rve(0.05, 20, 3, distribution=Monodisperse(25e-9))
    B = [0.1, 0.2, 0.4, 0.7, 1.0]
    out = {"description": __doc__.strip().splitlines()[0], "n_particles": rve.n,
           "phi": rve.phi, "seed": 3, "B_T": B, "runs": {}}
    for nf in (False, True):
        load0 = os.getloadavg()[0]
        t = time.perf_counter()
        try:
            r = relax(rve, B, matrix=ElasticMaterial(0.5e6, 0.49), voxels=20, near_field=nf)
        except ConvergenceError as exc:
            out["runs"]["on" if nf else "off"] = {"error": str(exc),
                                                   "seconds": time.perf_counter() - t}
            continue
        dt = time.perf_counter() - t
        steps = []
        for s in r.steps:
            steps.append({k: s.get(k) for k in (
                "B_T", "M_eff_A_per_m", "displacement_rms_m", "min_gap_m", "n_contacts",
                "iterations", "E_eff_parallel_Pa", "E_eff_perpendicular_Pa", "near_field_pairs",
                "near_field_force_max_N", "point_dipole_force_max_N")}
                         | {"strain_along_field": (s["strain_mag"][2][2]
                                                   if s.get("strain_mag") else None)})
        out["runs"]["on" if nf else "off"] = {"steps": steps, "seconds": dt,
                                               "load_average_start_end": [load0,
                                                                          os.getloadavg()[0]]}
        print("near field", nf, f"{dt:.1f} s", flush=True)
    (HERE / "nearfield_rve.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
