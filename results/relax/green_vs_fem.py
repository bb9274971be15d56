"""Green's-function (Rotne-Prager, Ewald-periodic) displaceability against the voxel FEM with
rigid particles, at growing FEM resolution (issue 16, weakness 2).

Cases (box L = 200 nm, spheres a = 25 nm, matrix E = 1 MPa, nu = 0.45, as the bench record
``relax_green_vs_fem``):

* one sphere: self displaceability M_zz against the periodic Green's function (exact for one
  sphere up to the O(phi) convention difference, see ``fem_displaceability``) and the Kelvin
  value u/F = (5 - 6 nu) / (24 pi G a (1 - nu));
* a pair along z at surface gaps 0.6, 1.0, 1.4, 2.0 a: relative compliance
  D.M.D (D = e_0z - e_1z, equal and opposite forces) and the pair block M_{10,zz}.

FEM at 32, 48, 64 voxels per edge (a = 4, 6, 8 voxels); one cell solve per case (particle 0
loaded along z). Run: ``.venv/bin/python results/relax/green_vs_fem.py [--voxels 32 48 64]``;
writes green_vs_fem.json and green_vs_fem.png next to this file.
"""
import argparse
import json
import math
import os
import time

import numpy as np

from micro import RVE
from micro.materials import ElasticMaterial
from homogenize.cell.relax import (fem_displaceability, green_displaceability,
                              rigid_sphere_displaceability)

HERE = os.path.dirname(os.path.abspath(__file__))
L, A = 200e-9, 25e-9
MAT = ElasticMaterial(1.0e6, 0.45)
G = MAT.E_Pa / (2 * (1 + MAT.nu))
GAPS_A = (0.6, 1.0, 1.4, 2.0)


def pair_rve(gap_a):
    c = np.array([[L / 2, L / 2, L / 2 - (A + 0.5 * gap_a * A)],
                  [L / 2, L / 2, L / 2 + (A + 0.5 * gap_a * A)]])
    return RVE.from_spheres(L, c, [A, A])


def column(rve, vox):
    solver = "matrix-free" if vox >= 64 else "fast"
    return fem_displaceability(rve, vox, MAT, particles=[0], directions=[2], tol=1e-7,
                               solver=solver)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--voxels", type=int, nargs="+", default=[32, 48, 64])
    ap.add_argument("--gaps", type=float, nargs="*", default=list(GAPS_A),
                    help="surface gaps / radius of the FEM pair cases")
    ap.add_argument("--no-single", action="store_true", help="skip the single-sphere FEM")
    ap.add_argument("--json", default=os.path.join(HERE, "green_vs_fem.json"),
                    help="JSON to update (partial runs merge into it)")
    ap.add_argument("--merge", nargs="*", default=[],
                    help="partial JSON files whose FEM results join --json (no solves)")
    ap.add_argument("--plot-only", action="store_true", help="redraw the PNG from --json")
    args = ap.parse_args()
    if args.plot_only:
        plot(json.load(open(args.json)))
        return
    out_path = args.json
    out = json.load(open(out_path)) if os.path.exists(out_path) else {}
    for f in args.merge:
        part = json.load(open(f))
        for k in ("single_fem_m_per_N", "seconds", "pair_fem"):
            for vox, v in part.get(k, {}).items():
                if k == "pair_fem":
                    out.setdefault(k, {}).setdefault(vox, {}).update(v)
                else:
                    out.setdefault(k, {})[vox] = v
        out.setdefault("load_average_partials", []).append(part.get("load_average"))
    if args.merge:
        args.voxels = []
    out.update({"box_m": L, "radius_m": A, "E_Pa": MAT.E_Pa, "nu": MAT.nu,
                "kelvin_m_per_N": rigid_sphere_displaceability(A, G, MAT.nu)})
    one = RVE.from_spheres(L, [[L / 2] * 3], [A])
    out["single_green_m_per_N"] = float(green_displaceability(one, MAT)[2, 2])
    out.setdefault("single_fem_m_per_N", {})
    out["pair_green"] = {}
    for g in GAPS_A:
        Mg = green_displaceability(pair_rve(g), MAT)
        out["pair_green"][str(g)] = {"self_zz": Mg[2, 2], "pair_zz": Mg[5, 2],
                                     "relative": Mg[2, 2] + Mg[5, 5] - 2 * Mg[5, 2]}
    out.setdefault("pair_fem", {})
    out.setdefault("seconds", {})
    for vox in args.voxels:
        t0 = time.perf_counter()
        if not args.no_single:
            M1 = column(one, vox)
            out["single_fem_m_per_N"][str(vox)] = float(M1[2, 2])
        res = out["pair_fem"].setdefault(str(vox), {})
        for g in args.gaps:
            M = column(pair_rve(g), vox)
            res[str(g)] = {"self_zz": M[2, 2], "pair_zz": M[5, 2],
                           "relative": 2 * (M[2, 2] - M[5, 2])}
            print(vox, g, res[str(g)], flush=True)
        out["seconds"][str(vox)] = time.perf_counter() - t0
        out["load_average"] = os.getloadavg()
        json.dump(out, open(out_path, "w"), indent=1)
    json.dump(out, open(out_path, "w"), indent=1)
    plot(out)


def plot(out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    gaps = np.array(GAPS_A)
    u0 = out["kelvin_m_per_N"]
    gr = [out["pair_green"][str(g)]["relative"] / u0 for g in gaps]
    ax[0].plot(gaps, gr, "k-o", label="Green (Rotne-Prager, periodic)")
    for vox, res in sorted(out["pair_fem"].items(), key=lambda kv: int(kv[0])):
        gs = [g for g in gaps if str(g) in res]
        ax[0].plot(gs, [res[str(g)]["relative"] / u0 for g in gs], "--s",
                   label=f"voxel FEM {vox}^3 (a = {int(vox) * A / L:.0f} voxels)")
        ax[1].plot(gs, [out["pair_green"][str(g)]["relative"] / res[str(g)]["relative"] - 1
                        for g in gs], "--s", label=f"FEM {vox}^3")
        fs = out.get("single_fem_m_per_N", {}).get(vox)
        if fs:       # both normalized by their own single sphere: the FEM's voxel error drops
            ax[1].plot(gs, [out["pair_green"][str(g)]["relative"] / out["single_green_m_per_N"]
                            / (res[str(g)]["relative"] / fs) - 1 for g in gs], "-o",
                       color=ax[1].lines[-1].get_color(),
                       label=f"FEM {vox}^3, each normalized by its single sphere")
    ax[0].set_xlabel("surface gap / radius [-]")
    ax[0].set_ylabel("relative compliance D.M.D / Kelvin u/F of one sphere [-]")
    ax[0].legend(fontsize=8)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_xlabel("surface gap / radius [-]")
    ax[1].set_ylabel("Green / FEM - 1 (relative compliance) [-]")
    ax[1].legend(fontsize=8)
    fig.suptitle("Pair of rigid spheres a = 25 nm along z in a 200 nm periodic cell, "
                 "E = 1 MPa, nu = 0.45")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "green_vs_fem.png"), dpi=110)


if __name__ == "__main__":
    main()
