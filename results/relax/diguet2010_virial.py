"""Cheap companion of diguet2010.py (no cell FEM): the mean magnetic stress of the relaxed RVE
against the affine one, at Diguet 2010 conditions. sigma = pairwise virial of the dipole forces
plus that of the contact forces (-(1/V) sum d_ij (x) F_ij), along the field."""
import json
import sys
from pathlib import Path

import numpy as np
from scipy.constants import mu_0 as MU0

sys.path.insert(0, str(Path(__file__).resolve().parent))
from diguet2010 import MATRIX, N_DEMAG, diguet_rve  # noqa: E402
from micro.dipoles import solve  # noqa: E402
from homogenize.cell import relax as R  # noqa: E402

if __name__ == "__main__":
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 1
    rve = diguet_rve(30, seed)
    B = [0.28, 0.56, 0.85, 1.13]
    res = R.relax(rve, B, matrix=MATRIX, voxels=None, demag_factor=N_DEMAG)
    g0 = 0.05 * float(rve.radii_m.mean())
    rows = []
    for s, r_rel in zip(res.steps, res.rves):
        vir = np.asarray(s["virial_stress_Pa"]).copy()
        for (_, _, dv, fv) in R.pair_contact_forces(r_rel.centers_m, rve.radii_m, rve.box_m, g0,
                                                    MATRIX, np.asarray(rve.centers_m)):
            vir -= np.outer(dv, fv) / rve.box_m ** 3
        st = solve(rve, [0, 0, s["B_T"]], 0.0, "regime", demag_factor=N_DEMAG)
        Ma, Mr = float(st.M_eff_A_per_m[2]), s["M_eff_A_per_m"]
        rows.append({"B_T": s["B_T"], "sigma_zz_relaxed_Pa": float(vir[2, 2]),
                     "sigma_zz_affine_Pa": float(st.virial_stress_Pa[2, 2]),
                     "M_relaxed_A_per_m": Mr, "M_affine_A_per_m": Ma,
                     "k_rve_affine": float(st.virial_stress_Pa[2, 2]) / (MU0 * Ma ** 2),
                     "k_rve_relaxed": float(vir[2, 2]) / (MU0 * Mr ** 2),
                     "displacement_rms_m": s["displacement_rms_m"],
                     "n_contacts": s["n_contacts"], "min_gap_m": s["min_gap_m"],
                     "pair_anisotropy_P2": s["microstructure"]["pair_anisotropy_P2"],
                     "chain_fraction": s["microstructure"]["chain_fraction"],
                     "iterations": s["iterations"]})
        print(json.dumps(rows[-1]), flush=True)
    out = Path(__file__).resolve().parent / f"diguet2010_virial_seed{seed}.json"
    out.write_text(json.dumps({"seed": seed, "n_particles": 30, "rows": rows,
                               "timings_s": res.timings_s}, indent=1))
