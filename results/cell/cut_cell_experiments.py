"""Cut-cell experiments for issue 15's "dilute rate about second order": why composite voxels are
first order at Fe/PDMS contrast, and a discretization of the same voxel grid that is second order.

The Nitsche cut voxels, their geometry (Kuhn splitting, quadrature, volume matching) and the
cut-voxel cell solver now live in mapsim (homogenize.cell.cut, imported here); the ridge XFEM, the
experiments and their analysis stay in this script. All use the project's periodic Q1 voxel
grid (homogenize.cell.problem: node i + n (j + n k), SRI element in the voxels that no interface
cuts) and a nodal level set phi (< 0: iron, > 0: PDMS). A voxel is CUT when its corner values
change sign; its 6 Kuhn tetrahedra (all along the main diagonal, so the faces match between
voxels) are split exactly by the plane of the linear interpolant of phi, which gives the
discrete interface (planar facets, O(h^2) from the sphere).

Methods compared:
- "composite": the project's default, Reuss voxels at the exact cut fraction (homogenize.cell.problem).
- "xfem-ridge": Q1 + the ridge enrichment of Moes, Cloirec, Cartraud & Remacle (2003),
  psi = sum_a N_a |phi_a| - |phi_h|, 3 extra unknowns per node of a cut voxel.
- "nitsche": two Q1 copies in every cut voxel, one per phase, integrated over that phase's part
  (Hansbo & Hansbo 2002), glued on the facets by a symmetric Nitsche method with contrast-robust
  weights w_i = (V_i / E_i) / sum_j (V_j / E_j) (Annavarapu, Hautefeuille & Dolbow 2012) and a
  penalty 2 sum_i w_i^2 lambda_i per voxel, lambda_i the largest eigenvalue of the traction
  energy on the facets against the copy's bulk energy (the coercivity bound, computed per voxel).
  The volumetric term of each copy acts on its mean divergence over its part (B-bar: the cut
  voxel's analogue of the one-point volumetric rule of the full voxels; with the full rule the
  cut layer locks: +10.1 % instead of +0.9 % at 4.3 voxels per diameter, nominal radius, one
  offset, one-off). The level set of a sphere is the distance to its centre minus a radius
  chosen so that the discrete particle holds the exact particle volume ("volume-matched"; the
  nominal radius loses 11 % of the volume at 4.3 voxels per diameter and 2.7 % at 8.6, which
  hides part of the error: rows with volume_matched false in the JSON). This script computes
  C from the energy formula linear in the solution, as when its JSON was made
  (homogenize.cell.cut's public functions use the variational one).

Experiments:
1. Tilted periodic Fe/PDMS laminate, normal (1, 1, 1)/sqrt 3, Fe fraction 0.5, against the exact
   rank-one laminate (homogenize.cell.problem.laminate_voigt): the relative error of the energy of
   C_eff along each eigenvector of the exact one (3 soft modes, 3 stiff).
2. One dilute Fe sphere per periodic PDMS cell (phi 0.01, the cell of dilute_rate.py): the shear
   coefficient c = (G / G_m - 1) / phi against that study's curved-P2 limit 2.3408 +- 0.0056, at
   random sphere-centre offsets (dilute_rate.py's seed), and the observed order.

Run:  .venv/bin/python results/cell/cut_cell_experiments.py          (~25 min, peak ~5 GB)
      .venv/bin/python results/cell/cut_cell_experiments.py --quick  (~1 min; JSON to /tmp)
      --plot-only redraws cut_cell_experiments.png from the JSON.
"""
from __future__ import annotations

import argparse
import itertools
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from homogenize.cell import cut
from homogenize.cell.problem import homogenize_mesh, isotropic_voigt, laminate_voigt, voigt_to_tensor
from homogenize.cell.cut import (cut_pieces, isotropic_element_matrices, nitsche_matrices, nodal_phi,
                            side_integrals, sphere_fn)
from homogenize.voxels.mesh import VoxelMesh
from micro.materials import FE, PDMS, elastic

HERE = Path(__file__).resolve().parent
JSON = HERE / "cut_cell_experiments.json"
FE_EL, PDMS_EL = elastic(FE), elastic(PDMS)
PHI = 0.01
RADIUS = (3.0 * PHI / (4.0 * np.pi)) ** (1.0 / 3.0)         # [box]
P2_LIMIT, P2_ERR = 2.3408, 0.0056                            # dilute_rate.json
SEED = 20261124                                              # dilute_rate.py's offsets
LAMINATE_NORMAL = (1, 1, 1)
LAMINATE_F = 0.5
LAMINATE_SHIFT = 0.3    # [voxels along m . (i, j, k)]: keeps every node off the interfaces


# ------------------------------------------------------------------------------------------------
# the cut-voxel cell problem: the Nitsche cut voxels, their geometry and the cell solver live in
# homogenize.cell.cut; the ridge-enriched XFEM stays here (it locks at Fe/PDMS contrast)
# ------------------------------------------------------------------------------------------------


def xfem_ridge_matrices(phi_c, h, lames, Es):
    """Ridge-enriched Q1 (functions [N_a, N_a psi]): (m, 48, 48), loads, affine energy."""
    m = phi_c.shape[0]
    subs, sown, ssg, *_ = cut_pieces(phi_c)

    def grads(N, dN, ow, sg):
        ph = phi_c[ow]
        psi = np.einsum("sqa,sa->sq", N, np.abs(ph)) - sg[:, None] * np.einsum("sqa,sa->sq", N, ph)
        dpsi = (np.einsum("sqad,sa->sqd", dN, np.abs(ph))
                - sg[:, None, None] * np.einsum("sqad,sa->sqd", dN, ph))
        return np.concatenate([dN, psi[..., None, None] * dN + N[..., None] * dpsi[..., None, :]],
                              axis=-2)
    G, g1, vol = side_integrals(subs, sown, ssg, m, h, grads)
    K = isotropic_element_matrices(G[0], *lames[0]) + isotropic_element_matrices(G[1], *lames[1])
    loads = [np.zeros((m, 16, 3)) for _ in Es]
    for s in range(2):
        lam, mu = lames[s]
        for e, E in enumerate(Es):
            St = voigt_to_tensor(isotropic_voigt(lam, mu) @ E)
            loads[e] -= np.einsum("maj,ij->mai", g1[s], St)
    return K, [f.reshape(m, 48) for f in loads], vol


def cell_problem(phi_fn, n, method, cases=(3, 4, 5), particle=FE_EL, matrix=PDMS_EL,
                 tol=1e-10, safety=2.0):
    """C_eff entries (len(cases) x len(cases), Voigt, Pa) of the periodic cell [0, 1)^3 with the
    particle where phi_fn < 0, ``method`` "nitsche" (homogenize.cell.cut.nitsche_matrices) or
    "xfem-ridge", solved by homogenize.cell.cut's cut-voxel cell problem; also the discrete particle
    volume fraction, CG iterations and, for "nitsche", the penalty range alpha h / E_matrix."""
    h = 1.0 / n
    lames = (particle.lame_Pa, matrix.lame_Pa)
    phi, nodes = nodal_phi(phi_fn, n)
    if method == "nitsche":
        def cut_matrices(pc, h, Es):
            return nitsche_matrices(pc, h, lames, (particle.E_Pa, matrix.E_Pa), Es, safety)
    elif method == "xfem-ridge":
        def cut_matrices(pc, h, Es):
            return (*xfem_ridge_matrices(pc, h, lames, Es), None)
    else:
        raise ValueError(method)
    # energy "linear": the C formula this study's JSON was made with (homogenize.cell.cut's public
    # functions use the variational one, whose error is quadratic in the CG error)
    C, phi_h, its, _, _, alpha = cut.cut_cell_problem(
        phi, nodes, n, lames, list(cases), tol, cut_matrices, two_copies=method == "nitsche",
        energy="linear")
    extra = {}
    if method == "nitsche":
        extra["alpha_h_over_E_matrix"] = [float(np.min(alpha) * h / matrix.E_Pa),
                                          float(np.median(alpha) * h / matrix.E_Pa),
                                          float(np.max(alpha) * h / matrix.E_Pa)]
    return C, phi_h, its, extra


# ------------------------------------------------------------------------------------------------
# experiment 1: the tilted laminate
# ------------------------------------------------------------------------------------------------

def _cube_below(t, m):
    """Volume of {y in [0, 1]^3 : m . y <= t} for m > 0 componentwise (inclusion-exclusion)."""
    out = np.zeros_like(t)
    for v in itertools.product((0, 1), repeat=3):
        out += (-1) ** sum(v) * np.maximum(t - np.dot(m, v), 0.0) ** 3
    return out / (6.0 * m[0] * m[1] * m[2])


def laminate_fractions(n, m=LAMINATE_NORMAL, f=LAMINATE_F):
    """Exact Fe fraction per voxel (n, n, n) [k, j, i] of the periodic laminate Fe where
    (m . x / L - LAMINATE_SHIFT / n) mod 1 < f."""
    k, j, i = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    s0 = (m[0] * i + m[1] * j + m[2] * k).astype(float)
    frac = np.zeros((n, n, n))
    for layer in range(-1, int((s0.max() + sum(m)) // n) + 2):
        lo, hi = layer * n + LAMINATE_SHIFT, (layer + f) * n + LAMINATE_SHIFT
        frac += (_cube_below(np.clip(hi - s0, 0, None), m)
                 - _cube_below(np.clip(lo - s0, 0, None), m))
    return np.clip(frac, 0.0, 1.0)


def laminate_phi(n, m=LAMINATE_NORMAL, f=LAMINATE_F):
    """Signed distance [box] to the interfaces of the laminate of :func:`laminate_fractions`
    on the n^3 grid (negative in Fe)."""
    mm = np.asarray(m, dtype=float)

    def phi(x):
        u = np.mod(x @ mm - LAMINATE_SHIFT / n, 1.0)
        inside = np.minimum(u, f - u)
        outside = np.minimum(u - f, 1.0 - u)
        return np.where(u < f, -inside, outside) / np.linalg.norm(mm)
    return phi


def laminate_errors(C):
    """Relative energy error along each eigenvector of the exact laminate, soft modes first."""
    n = np.asarray(LAMINATE_NORMAL, float) / np.linalg.norm(LAMINATE_NORMAL)
    exact = laminate_voigt(isotropic_voigt(*FE_EL.lame_Pa), isotropic_voigt(*PDMS_EL.lame_Pa),
                           np.array([LAMINATE_F]), n[None])[0]
    lam, V = np.linalg.eigh(exact)
    return [float(V[:, a] @ C @ V[:, a] / lam[a] - 1.0) for a in range(6)], lam.tolist()


def laminate_run(n, method):
    t0 = time.perf_counter()
    if method in ("composite", "laminate"):
        fr = laminate_fractions(n)
        nrm = np.asarray(LAMINATE_NORMAL, float) / np.linalg.norm(LAMINATE_NORMAL)
        z = np.zeros(0)
        mesh = VoxelMesh(n=n, box_m=1e-6, fraction=fr, owner=np.where(fr >= 0.5, 0, -1),
                         centers_m=np.zeros((0, 3)), radii_m=z, force_ptr=np.zeros(1, np.int64),
                         force_voxels=np.zeros(0, np.int64), force_weights=z,
                         resolved=np.zeros(0, bool), method=method,
                         normal=np.broadcast_to(nrm, (n, n, n, 3)).copy())
        # no particle deflation: the layers are connected sheets, not floating particles
        r = homogenize_mesh(mesh, deflate=False, solver="matrix-free", maxiter=5000)
        C, its, phi_h = r.C_eff_Pa, list(r.iterations.values()), float(fr.mean())
    else:
        C, phi_h, its, _ = cell_problem(laminate_phi(n), n, method, cases=range(6))
    err, _ = laminate_errors(C)
    return {"method": method, "voxels": n, "layer_spacing_voxels": n / np.sqrt(3.0),
            "phi_h": phi_h, "energy_errors_soft_to_stiff": err, "cg_iterations": its,
            "seconds": time.perf_counter() - t0}


# ------------------------------------------------------------------------------------------------
# experiment 2: one dilute sphere
# ------------------------------------------------------------------------------------------------

def sphere_run(n, offset, method="nitsche", matched=True, safety=2.0):
    """Shear coefficients (C44, C55, C66 as (G/G_m - 1)/phi) of the sphere at centre
    0.5 + offset / n."""
    t0 = time.perf_counter()
    centre = 0.5 + np.asarray(offset) / n
    radius = cut.volume_matched_radius(centre, n, RADIUS) if matched else RADIUS
    C, phi_h, its, extra = cell_problem(sphere_fn(centre, radius), n, method, safety=safety)
    g_m = PDMS_EL.bulk_shear_Pa[1]
    c = [(C[a, a] / g_m - 1.0) / PHI for a in range(3)]
    return {"method": method, "voxels": n, "diameter_voxels": 2 * RADIUS * n,
            "offset_voxels": list(map(float, offset)), "volume_matched": matched,
            "radius_over_nominal": radius / RADIUS, "phi_h_over_phi": phi_h / PHI,
            "penalty_safety": safety, "c44_c55_c66": c, "coefficient": float(np.mean(c)),
            "error_vs_p2_limit": float(np.mean(c) / P2_LIMIT - 1.0), "cg_iterations": its,
            **extra, "seconds": time.perf_counter() - t0}


def analyse(doc):
    """Per resolution: mean error against the P2 limit over offsets; local and fitted orders."""
    rows = [r for r in doc["sphere"] if r["method"] == "nitsche" and r["volume_matched"]
            and r["penalty_safety"] == 2.0]
    table = []
    for n in sorted({r["voxels"] for r in rows}):
        rs = [r for r in rows if r["voxels"] == n]
        c = np.array([r["c44_c55_c66"] for r in rs])
        table.append({"voxels": n, "diameter_voxels": rs[0]["diameter_voxels"], "offsets": len(rs),
                      "mean_coefficient": float(c.mean()),
                      "mean_error": float(c.mean() / P2_LIMIT - 1.0),
                      "std_over_offsets_and_components": float(c.std(ddof=1) / c.mean())
                      if c.size > 1 else None})
    D = np.array([t["diameter_voxels"] for t in table])
    e = np.array([t["mean_error"] for t in table])
    out = {"table": table}
    if len(table) >= 2 and np.all(e > 0):
        out["local_orders"] = (-np.diff(np.log(e)) / np.diff(np.log(D))).tolist()
        A = np.stack([np.ones_like(D), np.log(D)], axis=1)
        coef, res, *_ = np.linalg.lstsq(A, np.log(e), rcond=None)
        out["fitted_order"] = float(-coef[1])
        if len(table) > 2:
            cov = (res[0] / (len(D) - 2)) * np.linalg.inv(A.T @ A) if res.size else None
            out["fitted_order_se"] = float(np.sqrt(cov[1, 1])) if cov is not None else None
        # Richardson at order 2 from successive resolutions: an estimate of the cell's exact
        # coefficient independent of the P2 reference
        c = np.array([t["mean_coefficient"] for t in table])
        out["richardson_order2"] = [
            {"diameters_voxels": [float(D[i]), float(D[i + 1])],
             "c_limit": float((D[i + 1] ** 2 * c[i + 1] - D[i] ** 2 * c[i])
                              / (D[i + 1] ** 2 - D[i] ** 2))} for i in range(len(D) - 1)]
        for r in out["richardson_order2"]:
            r["vs_p2_limit"] = r["c_limit"] / P2_LIMIT - 1.0
        # the same fit with the reference moved by its error estimate
        for sgn, key in ((1, "order_if_limit_plus_err"), (-1, "order_if_limit_minus_err")):
            ce = np.array([t["mean_coefficient"] for t in table]) / (P2_LIMIT + sgn * P2_ERR) - 1
            if np.all(ce > 0):
                out[key] = float(-np.polyfit(np.log(D), np.log(ce), 1)[0])
    doc["analysis"] = out
    return doc


def composite_reference():
    """Composite-voxel mean errors of dilute_rate.json (same cell, same reference)."""
    p = HERE / "dilute_rate.json"
    if not p.exists():
        return []
    d = json.loads(p.read_text())
    return [{"diameter_voxels": t["diameter_voxels"], "mean_error": t["mean_error"]}
            for t in d.get("table", [])]


def _log_axes(ax, xlabel, ylabel, title, xticks):
    import matplotlib.ticker
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xticks(xticks)


def plot(path, doc):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.3))
    comp = doc.get("composite_dilute_rate", [])
    if comp:
        ax.plot([t["diameter_voxels"] for t in comp], [100 * abs(t["mean_error"]) for t in comp],
                "s--", color="tab:blue", label="composite voxels (dilute_rate.json), |error|")
    tab = doc["analysis"]["table"]
    D = np.array([t["diameter_voxels"] for t in tab])
    ax.plot(D, [100 * t["mean_error"] for t in tab], "o-", color="tab:red",
            label="Nitsche cut voxels (volume-matched), error")
    xr = [r for r in doc["sphere"] if r["method"] == "xfem-ridge"]
    if xr:
        ax.plot([r["diameter_voxels"] for r in xr], [100 * r["error_vs_p2_limit"] for r in xr],
                "^:", color="tab:gray", label="ridge XFEM (locks at Fe contrast), error")
    ref = 100 * P2_ERR / P2_LIMIT
    ax.axhline(ref, color="k", lw=0.8, ls=":", label=f"P2 reference uncertainty ({ref:.2f} %)")
    Dg = np.array([D.min(), D.max()])
    ax.plot(Dg, 100 * tab[-1]["mean_error"] * (Dg / D[-1]) ** -2, color="tab:red", lw=0.6,
            alpha=0.6, label="slope -2")
    _log_axes(ax, "sphere diameter [voxels]", "error of c = (G/G_m - 1)/phi vs P2 limit [%]",
              "One dilute Fe sphere in PDMS (phi 0.01)", [4, 6, 8, 10, 16, 20, 30])
    lam = doc["laminate"]
    for meth, mk, col in (("composite", "s--", "tab:blue"), ("laminate", "d--", "tab:green")):
        rs = sorted((r for r in lam if r["method"] == meth), key=lambda r: r["voxels"])
        if rs:
            bx.plot([r["layer_spacing_voxels"] for r in rs],
                    [100 * max(r["energy_errors_soft_to_stiff"][:3]) for r in rs], mk, color=col,
                    label=f"{meth} voxels")
    for meth, mk, col in (("nitsche", "o", "tab:red"), ("xfem-ridge", "^", "tab:gray")):
        rs = [r for r in lam if r["method"] == meth]
        if rs:
            bx.plot([r["layer_spacing_voxels"] for r in rs],
                    [max(100 * max(abs(x) for x in r["energy_errors_soft_to_stiff"][:3]), 1e-7)
                     for r in rs], mk, color=col, ms=9, label=f"{meth} (exact to the solver)")
    _log_axes(bx, "laminate layer spacing [voxels]", "largest soft-mode energy error [%]",
              "Fe/PDMS laminate, normal (1,1,1), Fe 50 %", [10, 20, 40])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


FULL = {"laminate": [("composite", 18), ("composite", 36), ("composite", 72), ("laminate", 18),
                     ("laminate", 36), ("nitsche", 18), ("xfem-ridge", 18)],
        "sphere_voxels": {16: 4, 22: 4, 30: 4, 40: 4, 60: 2},
        "xfem_voxels": (16, 24), "nominal_voxels": (16, 32), "safety_voxels": 22}
QUICK = {"laminate": [("composite", 18), ("composite", 36), ("nitsche", 18)],
         "sphere_voxels": {16: 2, 22: 2}, "xfem_voxels": (16,), "nominal_voxels": (),
         "safety_voxels": None}


def run(plan):
    offsets = np.random.default_rng(SEED).random((max(plan["sphere_voxels"].values()), 3))
    doc = {"laminate": [], "sphere": []}
    for meth, n in plan["laminate"]:
        doc["laminate"].append(laminate_run(n, meth))
        print("laminate", meth, n, ["%+.2e" % x for x in doc["laminate"][-1][
            "energy_errors_soft_to_stiff"]], flush=True)
    for n, k in plan["sphere_voxels"].items():
        for o in offsets[:k]:
            doc["sphere"].append(sphere_run(n, o))
            print("sphere nitsche", n, "%+.3f %%" % (100 * doc["sphere"][-1]["error_vs_p2_limit"]),
                  flush=True)
    for n in plan["nominal_voxels"]:
        doc["sphere"].append(sphere_run(n, offsets[0], matched=False))
    if plan["safety_voxels"]:
        for sf in (1.1, 5.0):
            doc["sphere"].append(sphere_run(plan["safety_voxels"], offsets[0], safety=sf))
    for n in plan["xfem_voxels"]:
        doc["sphere"].append(sphere_run(n, offsets[0], method="xfem-ridge"))
        print("sphere xfem", n, "%+.1f %%" % (100 * doc["sphere"][-1]["error_vs_p2_limit"]),
              flush=True)
    doc["composite_dilute_rate"] = composite_reference()
    return analyse(doc)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--plot-only", action="store_true")
    ap.add_argument("--reanalyse", action="store_true",
                    help="recompute the analysis of the JSON's raw rows and redraw the figure")
    a = ap.parse_args(argv)
    out = a.out or (Path("/tmp/cut_cell_experiments_quick.json") if a.quick else JSON)
    if a.plot_only or a.reanalyse:
        doc = json.loads(out.read_text())
        if a.reanalyse:
            analyse(doc)
            out.write_text(json.dumps(doc, indent=1))
        plot(out.with_suffix(".png"), doc)
        return 0
    t0 = time.perf_counter()
    doc = run(QUICK if a.quick else FULL)
    doc["manifest"] = {
        "command": " ".join([".venv/bin/python", "results/cell/cut_cell_experiments.py"]
                            + (argv if argv is not None else sys.argv[1:])),
        "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=HERE).stdout.strip(),
        "python": platform.python_version(), "seconds": time.perf_counter() - t0,
        "reference": f"curved P2 limit {P2_LIMIT} +- {P2_ERR} (dilute_rate.json)",
        "materials": "Fe 211 GPa nu 0.29 in PDMS 2 MPa nu 0.45 (micro.materials)"}
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(out)
    plot(out.with_suffix(".png"), doc)
    print(json.dumps(doc["analysis"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
