"""Refinement of composite voxels against curved P2 meshes: the numbers behind
results/cell/composite_accuracy.{json,png} and the P2 table of results/cell/README.md.

Six Fe spheres in PDMS (homogenize.studies.cell_studies.inside_spheres(phi, 6, 7)) at phi 0.05 and
0.2: curved (isoparametric) P2 meshes solved by the deflated block CG
(homogenize.homogenize_conforming(..., geometry_order=2, solver="cg")), and composite
voxels refined to 64^3 / 96^3 (homogenize.cell.problem.homogenize_rve, matrix-free solver). Each result is
merged into the JSON (an entry with the same mesh or voxel count is replaced), the comparison
against the finest curved P2 is recomputed, and the figure is redrawn from the JSON.

Run: .venv/bin/python results/cell/composite_accuracy.py            (all, ~30 min, ~6 GB)
     .venv/bin/python results/cell/composite_accuracy.py --plot-only (redraw the figure)
     --out F writes the JSON to F instead of updating the committed one.
"""
import argparse
import json
import time
from pathlib import Path

from homogenize import homogenize_conforming
from homogenize.cell.problem import homogenize_rve, isotropic_projection
from homogenize.studies.cell_studies import inside_spheres, plot_composite_accuracy
from micro.materials import FE, PDMS

HERE = Path(__file__).resolve().parent
JSON = HERE / "composite_accuracy.json"
#: phi -> curved P2 meshes (mesh size [box], elements per 2 pi of curvature), composite voxels
PLAN = {0.2: {"p2": [(0.2, 24), (0.15, 32), (0.1, 48)], "voxels": [64, 96]},
        0.05: {"p2": [(0.2, 24), (0.15, 32)], "voxels": [64]}}


def _replace(items, new, key):
    return [x for x in items if not all(x.get(k) == new[k] for k in key)] + [new]


def run_case(case: dict, plan: dict) -> None:
    phi = case["phi"]
    rve = inside_spheres(phi, 6, 7)
    c, r = rve.centers_m / rve.box_m, rve.radii_m / rve.box_m
    for hs, ce in plan["p2"]:
        t0 = time.perf_counter()
        got = homogenize_conforming(1.0, c, r, hs, matrix=(PDMS.E_Pa, PDMS.nu),
                                    particle=(FE.E_Pa, FE.nu), curvature_elements=ce,
                                    geometry_order=2, solver="cg")
        E = isotropic_projection(got["C_eff_Pa"])[0]
        entry = {"mesh_size_box": hs, "curvature_elements": ce, "E_eff_Pa": E,
                 "n_dof": got["n_dof"], "phi_mesh": got["phi_mesh"], "radii": "nominal",
                 "geometry_order": 2, "E_ratio": E / PDMS.E_Pa, "solver": "cg",
                 "iterations": got["iterations"], "seconds": time.perf_counter() - t0,
                 "note": "results/cell/composite_accuracy.py"}
        case["p2"] = _replace(case["p2"], entry, ("mesh_size_box", "curvature_elements",
                                                  "geometry_order"))
        print(phi, entry, flush=True)
    rows = case["voxel"]["composite"]["rows"]
    for n in plan["voxels"]:
        t0 = time.perf_counter()
        res = homogenize_rve(rve, n, method="composite", solver="matrix-free")
        row = {"voxels": n, "E_eff_Pa": res.E_eff_Pa, "stiffening": res.E_eff_Pa / PDMS.E_Pa - 1,
               "phi_voxel": res.phi_voxel, "iterations": max(res.iterations.values()),
               "seconds": time.perf_counter() - t0, "solver": "matrix-free",
               "note": "results/cell/composite_accuracy.py"}
        rows = _replace(rows, row, ("voxels",))
        print(phi, row, flush=True)
    case["voxel"]["composite"]["rows"] = sorted(rows, key=lambda x: x["voxels"])


def compare(case: dict) -> None:
    """Composite voxels against the finest curved P2 of the same RVE."""
    curved = sorted((q for q in case["p2"] if q.get("geometry_order") == 2),
                    key=lambda q: q["n_dof"])
    if not curved:
        return
    fin = curved[-1]["E_ratio"]
    case["finest_curved_p2"] = {"n_dof": curved[-1]["n_dof"], "E_ratio": fin}
    case["composite_vs_finest_curved_p2"] = {
        str(x["voxels"]): (1.0 + x["stiffening"]) / fin - 1.0
        for x in case["voxel"]["composite"]["rows"]}
    if len(curved) >= 2:
        case["curved_p2_last_change"] = curved[-1]["E_ratio"] / curved[-2]["E_ratio"] - 1.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot-only", action="store_true")
    ap.add_argument("--out", type=Path, default=JSON)
    args = ap.parse_args()
    doc = json.loads(JSON.read_text())
    if not args.plot_only:
        for case in doc["cases"]:
            run_case(case, PLAN[case["phi"]])
            compare(case)
        args.out.write_text(json.dumps(doc, indent=1))
    plot_composite_accuracy(HERE / "composite_accuracy.png" if args.out == JSON
                            else args.out.with_suffix(".png"), doc)


if __name__ == "__main__":
    main()
