"""Does the tables' discretization-error estimate cover the error? (homogenize.tables.resolution)

The batch tables estimate the discretization error of every cell-FEM quantity from the same RVEs
on two grids, n and n_c = coarse_voxels(n) ~ 2/3 n (first order, with a floor of 2.2 % of the
filler's contribution). This script checks the estimate against the error itself: for random
RVEs of two populations it computes E_eff on a ladder of grids up to a fine reference, and for
every grid n of the ladder compares

* the estimate e(n) that a table at n would carry (the same formula, the same realizations), with
* the actual error of the mean |mean E(n) - mean E(n_ref)| against the finest grid n_ref, whose
  own estimated error e(n_ref) is reported next to it (the reference is not exact).

"covered" means |mean E(n) - mean E(n_ref)| <= e(n) + e(n_ref). The populations:

* ``tutorial``: the README tutorial's composite (carbonyl iron in Sylgard 184, phi 0.05,
  8 monodisperse-like particles per RVE: the lognormal preset), 3 RVEs;
* ``dense``: the seed's powder (lognormal, gsd 1.4) at phi 0.2, 12 particles, 3 RVEs.

Run:  .venv/bin/python results/cell/resolution_error.py           (~10 min on 2 cores)
      .venv/bin/python results/cell/resolution_error.py --quick   (< 1 min, the test's run)
      --out F  (default results/cell/resolution_error.json; --quick: a temporary file); the
      figure goes next to the JSON with suffix .png.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from micro import materials
from micro.particles import LogNormal, generate_rve
from homogenize.cell.problem import homogenize_rve
from homogenize.tables.resolution import (coarse_voxels, discretization_error, voxels_per_radius)

HERE = Path(__file__).resolve().parent

POPULATIONS = {
    "tutorial": {"phi": 0.05, "n": 8, "particle": "carbonyl-iron", "matrix": "sylgard184-10to1",
                 "ladder": [12, 18, 24, 36, 48, 72], "quick": [12, 18, 24]},
    "dense": {"phi": 0.2, "n": 12, "particle": "seed-paper", "matrix": "seed-paper",
              "ladder": [12, 18, 24, 36, 48, 72], "quick": [12, 18, 24]},
}
SEEDS = (11, 12, 13)


def _rve(pop: dict, seed: int):
    p = materials.particle_preset(pop["particle"])
    dist = LogNormal.from_mean(p.mean_radius_m, p.gsd, *p.radius_bounds_m)
    return generate_rve(pop["phi"], pop["n"], seed, distribution=dist)


def _E(rve, n: int, pop: dict) -> float:
    m = materials.matrix_preset(pop["matrix"])
    p = materials.particle_preset(pop["particle"])
    solver = "matrix-free" if n % 2 == 0 and n >= 8 else "fast"
    return float(homogenize_rve(rve, n, matrix_E_Pa=m.E_Pa, matrix_nu=m.nu,
                                particle_E_Pa=p.E_Pa, particle_nu=p.nu,
                                solver=solver).E_eff_Pa)


def run(quick: bool) -> dict:
    out = {"populations": {}}
    for name, pop in POPULATIONS.items():
        ladder = pop["quick"] if quick else pop["ladder"]
        rves = [_rve(pop, s) for s in SEEDS]
        m = materials.matrix_preset(pop["matrix"])
        grids = sorted(set(ladder) | {coarse_voxels(n) for n in ladder})
        t0 = time.perf_counter()
        E = {n: [_E(r, n, pop) for r in rves] for n in grids}
        rows = []
        est = {n: discretization_error(np.array(E[n]), np.array(E[coarse_voxels(n)]), n,
                                       coarse_voxels(n), 0.95, matrix_value=m.E_Pa)
               for n in ladder}
        ref = ladder[-1]
        for n in ladder[:-1]:
            actual = abs(np.mean(E[n]) - np.mean(E[ref]))
            e = float(est[n]["err"])
            rows.append({"voxels": n, "coarse_voxels": coarse_voxels(n),
                         "voxels_per_radius": float(np.mean(
                             [voxels_per_radius(r.radii_m.mean(), r.box_m, n) for r in rves])),
                         "E_mean_Pa": float(np.mean(E[n])), "estimate_Pa": e,
                         "two_grid_Pa": float(est[n]["two_grid"]),
                         "floor_Pa": float(est[n]["floor"]),
                         "actual_vs_ref_Pa": float(actual),
                         "covered": bool(actual <= e + float(est[ref]["err"])),
                         "ratio_estimate_to_actual": float(e / actual) if actual else None})
        out["populations"][name] = {
            **{k: v for k, v in pop.items() if k not in ("ladder", "quick")},
            "seeds": list(SEEDS), "ladder": ladder, "reference_voxels": ref,
            "reference_E_mean_Pa": float(np.mean(E[ref])),
            "reference_estimate_Pa": float(est[ref]["err"]),
            "E_per_grid_Pa": {str(n): E[n] for n in grids}, "rows": rows,
            "seconds": time.perf_counter() - t0}
    out["all_covered"] = all(r["covered"] for p in out["populations"].values()
                             for r in p["rows"])
    return out


def plot(doc: dict, png: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(doc["populations"]), figsize=(11, 4.2))
    for ax, (name, p) in zip(np.atleast_1d(axes), doc["populations"].items()):
        r = p["rows"]
        vpr = [x["voxels_per_radius"] for x in r]
        ax.loglog(vpr, [x["actual_vs_ref_Pa"] / 1e3 for x in r], "o-",
                  label=f"|E(n) - E({p['reference_voxels']})| (actual)")
        ax.loglog(vpr, [x["estimate_Pa"] / 1e3 for x in r], "s--",
                  label="table's estimate e(n)")
        ax.loglog(vpr, [x["floor_Pa"] / 1e3 for x in r], ":", color="grey",
                  label="floor (2.2 % of filler's part)")
        ax.axhline(p["reference_estimate_Pa"] / 1e3, color="k", lw=0.8,
                   label=f"estimate at the reference ({p['reference_voxels']})")
        ax.set_xlabel("mean radius [voxels]")
        ax.set_ylabel("error of mean E_eff [kPa]")
        ax.set_title(f"{name}: phi {p['phi']}, {p['n']} particles, {len(p['seeds'])} RVEs")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Discretization error of E_eff: the two-grid estimate against a fine grid")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    out = a.out or (Path(tempfile.mkdtemp()) / "resolution_error.json" if a.quick
                    else HERE / "resolution_error.json")
    doc = run(a.quick)
    from importlib import metadata
    doc["manifest"] = {"quick": a.quick, "script": "results/cell/resolution_error.py",
                       "versions": {k: metadata.version(k) for k in
                                    ("numpy", "scipy", "numba", "scikit-fem", "pyamg")}}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    plot(doc, out.with_suffix(".png"))
    for name, p in doc["populations"].items():
        for r in p["rows"]:
            print(f"{name:9s} n={r['voxels']:3d} r/h={r['voxels_per_radius']:5.2f} "
                  f"E={r['E_mean_Pa']:.6g} est={r['estimate_Pa']:.3g} "
                  f"actual={r['actual_vs_ref_Pa']:.3g} covered={r['covered']}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
