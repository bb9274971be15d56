"""Effective Young's modulus against particle volume fraction: voxel FEM vs closed forms.

One sphere in the periodic cube (simple cubic array) at volume fractions up to 30 %, compared
with Eshelby's dilute estimate, Mori-Tanaka (= lower Hashin-Shtrikman bound for stiff spheres),
Guth-Gold and the upper HS bound. Shows where the estimates part.
"""
from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
from micro.common.progress import progress_bar

from homogenize.cell._effective_media import (bulk_shear, eshelby_dilute, guth_gold,
                                         hashin_shtrikman_bounds, mori_tanaka, young_poisson)
from homogenize.cell.problem import Material, homogenize_mesh, homogenize_rve, isotropic_projection
from homogenize.cell.cut import homogenize_cut
from homogenize.voxels.mesh import voxelize
from micro.common.files import atomic_path
from micro.materials import FE, PDMS

__all__ = ["phi_study", "plot_phi_study", "dilute_convergence_study", "plot_dilute_convergence",
           "inside_spheres", "composite_accuracy_study", "plot_composite_accuracy"]


def phi_study(phis=(0.01, 0.05, 0.1, 0.2, 0.3), voxels: int = 24, *, matrix_E_Pa=PDMS.E_Pa,
              matrix_nu=PDMS.nu, particle_E_Pa=FE.E_Pa, particle_nu=FE.nu, progress=False,
              method: str = "composite") -> dict:
    """E_eff [Pa] of a simple cubic array of spheres by FEM and by the closed forms, per phi."""
    Km, Gm = bulk_shear(matrix_E_Pa, matrix_nu)
    Kp, Gp = bulk_shear(particle_E_Pa, particle_nu)
    rows = []
    it = phis
    if progress:
        it = progress_bar(phis, desc="phi study", unit="phi", leave=False)
    for phi in it:
        a = (3.0 * phi / (4.0 * np.pi)) ** (1.0 / 3.0)
        rve = SimpleNamespace(box_m=1e-6, centers_m=np.full((1, 3), 0.5e-6), radii_m=np.array([a * 1e-6]))
        r = homogenize_rve(rve, voxels, matrix_E_Pa=matrix_E_Pa, matrix_nu=matrix_nu,
                           particle_E_Pa=particle_E_Pa, particle_nu=particle_nu, method=method)
        pv = r.phi_voxel
        hs = hashin_shtrikman_bounds(pv, Km, Gm, Kp, Gp)
        rows.append({
            "phi": phi, "phi_voxel": pv, "E_fem_Pa": r.E_eff_Pa, "anisotropy_index": r.anisotropy_index,
            "E_dilute_Pa": young_poisson(*eshelby_dilute(pv, Km, Gm, Kp, Gp))[0],
            "E_mori_tanaka_Pa": young_poisson(*mori_tanaka(pv, Km, Gm, Kp, Gp))[0],
            "E_guth_gold_Pa": float(guth_gold(pv, matrix_E_Pa)),
            "E_hs_upper_Pa": float(hs["E_upper_Pa"]), "iterations": r.iterations,
        })
    return {"voxels": voxels, "method": method, "matrix_E_Pa": matrix_E_Pa, "matrix_nu": matrix_nu,
            "particle_E_Pa": particle_E_Pa, "particle_nu": particle_nu, "rows": rows}


def plot_phi_study(path, study: dict) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = study["rows"]
    pv = np.array([r["phi_voxel"] for r in rows])
    Em = study["matrix_E_Pa"]
    fig = Figure(figsize=(6, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for key, lab, st in (("E_fem_Pa", f"voxel FEM ({study['voxels']}^3, SC array)", "ko-"),
                         ("E_dilute_Pa", "Eshelby dilute", "b--"),
                         ("E_mori_tanaka_Pa", "Mori-Tanaka = HS lower", "g-"),
                         ("E_guth_gold_Pa", "Guth-Gold", "r-.")):
        ax.plot(pv, np.array([r[key] for r in rows]) / Em, st, label=lab)
    ax.set_xlabel("particle volume fraction phi [1]")
    ax.set_ylabel("E_eff / E_matrix [1]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")


def dilute_convergence_study(voxels=(8, 16, 24, 32, 48, 64), phi: float = 0.01, *,
                             matrix_E_Pa=PDMS.E_Pa, matrix_nu=PDMS.nu, particle_E_Pa=FE.E_Pa,
                             particle_nu=FE.nu, progress=False, method: str = "composite") -> dict:
    """One sphere at dilute phi, refined: the shear stiffening coefficient against Eshelby.

    The coefficient ``c = (G_eff / G_m - 1) / phi_voxel`` (per unit VOXEL volume fraction, so the
    staircase volume error is divided out) tends to Eshelby's dilute value plus the O(phi)
    interaction of the periodic images (Mori-Tanaka estimates it). Reports the error per
    resolution, the observed rate ``p`` of ``|c - c_dilute|`` between the finest grids, and a
    Richardson extrapolation ``c_inf`` from the three finest with that rate. Once the grid error
    falls below the O(phi) image interaction (composite voxels) ``|c - c_dilute|`` levels off, so
    the self-convergence rate is reported too: ``polyfit(log h, log |c_n - c_finest|)`` over the
    grids with at least 6 voxels per diameter.

    ``method``: a voxelization of :func:`homogenize.voxels.mesh.voxelize`, or ``"cut"``: the Nitsche
    cut voxels of :func:`homogenize.cell.cut.homogenize_cut` (two displacement fields per cut voxel,
    volume-matched sphere; second order, see its docstring).
    """
    mat, par = Material(matrix_E_Pa, matrix_nu), Material(particle_E_Pa, particle_nu)
    Km, Gm = mat.bulk_shear_Pa
    Kp, Gp = par.bulk_shear_Pa
    c_dil = (eshelby_dilute(phi, Km, Gm, Kp, Gp)[1] / Gm - 1.0) / phi
    c_mt = (mori_tanaka(phi, Km, Gm, Kp, Gp)[1] / Gm - 1.0) / phi
    a = (3.0 * phi / (4.0 * np.pi)) ** (1.0 / 3.0)
    rows = []
    it = voxels
    if progress:
        it = progress_bar(voxels, desc="dilute sphere refinement", unit="grid", leave=False)
    for n in it:
        # centre slightly off the grid symmetry so no voxel face cuts the sphere symmetrically
        rve = SimpleNamespace(box_m=1e-6, centers_m=np.full((1, 3), (0.5 + 0.1 / n) * 1e-6),
                              radii_m=np.array([a * 1e-6]))
        if method == "cut":
            t0 = time.perf_counter()
            r = homogenize_cut(rve, n, matrix=mat, particle=par, cases=(5,))
            phi_h, sec = r.phi_discrete, time.perf_counter() - t0
        else:
            r = homogenize_mesh(voxelize(rve, n, method=method), matrix=mat, particle=par,
                                cases=("g12",))
            phi_h, sec = r.phi_voxel, r.timings_s["total"]
        c = (r.C_eff_Pa[5, 5] / Gm - 1.0) / phi_h
        rows.append({"voxels": int(n), "radius_voxels": a * n, "diameter_voxels": 2.0 * a * n,
                     "phi_voxel": phi_h,
                     "coefficient": c, "error_vs_dilute": abs(c - c_dil) / c_dil,
                     "error_vs_mori_tanaka": abs(c - c_mt) / c_mt,
                     "iterations": r.iterations["g12"], "seconds": sec})
    ns = np.array([r["voxels"] for r in rows], dtype=float)
    err = np.array([r["error_vs_dilute"] for r in rows])
    fine = slice(max(0, len(rows) - 3), None)
    rate = float(-np.polyfit(np.log(ns[fine]), np.log(err[fine]), 1)[0]) if len(rows) >= 2 else None
    c_inf = None
    if len(rows) >= 3 and rate and rate > 0:
        # c(n) = c_inf + A n^-p through the two finest grids with the observed p
        c1, c2 = rows[-2]["coefficient"], rows[-1]["coefficient"]
        q = (ns[-1] / ns[-2]) ** rate
        c_inf = float((q * c2 - c1) / (q - 1.0))
    cs = np.array([r["coefficient"] for r in rows])
    sel = np.flatnonzero((2.0 * a * ns >= 6.0) & (ns < ns[-1]))
    self_rate = None
    if sel.size >= 2:
        d = np.abs(cs[sel] - cs[-1])
        if np.all(d > 0):
            self_rate = float(-np.polyfit(np.log(ns[sel]), np.log(d), 1)[0])
    return {"phi": phi, "method": method, "matrix_E_Pa": matrix_E_Pa, "matrix_nu": matrix_nu,
            "self_convergence_rate": self_rate,
            "particle_E_Pa": particle_E_Pa, "particle_nu": particle_nu,
            "coefficient_dilute": c_dil, "coefficient_mori_tanaka": c_mt,
            "observed_rate": rate, "coefficient_extrapolated": c_inf,
            "extrapolated_error_vs_dilute": None if c_inf is None else abs(c_inf - c_dil) / c_dil,
            "extrapolated_error_vs_mori_tanaka": None if c_inf is None else abs(c_inf - c_mt) / c_mt,
            "rows": rows}


def plot_dilute_convergence(path, study: dict) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = study["rows"]
    ns = np.array([r["voxels"] for r in rows], dtype=float)
    fig = Figure(figsize=(10, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(ns, [r["coefficient"] for r in rows], "ko-", label="voxel FEM")
    ax.axhline(study["coefficient_dilute"], color="b", ls="--", label="Eshelby dilute")
    ax.axhline(study["coefficient_mori_tanaka"], color="g", ls="-", label="Mori-Tanaka")
    ax.set_xlabel("voxels per edge")
    ax.set_ylabel("(G_eff / G_m - 1) / phi [1]")
    ax.set_title(f"one sphere, phi = {study['phi']:g}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = fig.add_subplot(1, 2, 2)
    # measured errors only: the composite-voxel error oscillates with the sphere's position
    # against the grid, so no asymptotic rate or Richardson limit is drawn (results/cell/README.md)
    c = np.array([r["coefficient"] for r in rows])
    for ref, style, label in ((study["coefficient_dilute"], "ko-", "vs Eshelby dilute"),
                              (study["coefficient_mori_tanaka"], "gs--", "vs Mori-Tanaka")):
        ax.plot(ns, 100.0 * (c / ref - 1.0), style, label=label)
    ax.axhspan(-2.0, 2.0, color="0.9", label="+-2 % target")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("voxels per edge")
    ax.set_ylabel("signed relative error of the coefficient [%]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")


def inside_spheres(phi: float, n_particles: int, seed: int, *, spread: float = 0.15,
                   gap: float = 0.03) -> SimpleNamespace:
    """Random non-overlapping spheres in the unit cube (box 1e-6 m), none cutting a face (so the
    conforming periodic mesh can hold them): radii uniform within +-``spread`` of the mean,
    scaled to the exact ``phi``; random sequential addition with a surface gap ``gap`` [box]."""
    rng = np.random.default_rng(seed)
    r0 = (3.0 * phi / (4.0 * np.pi * n_particles)) ** (1.0 / 3.0)
    radii = np.sort(r0 * (1.0 + spread * rng.uniform(-1.0, 1.0, n_particles)))[::-1]
    radii *= (phi / (4.0 / 3.0 * np.pi * np.sum(radii ** 3))) ** (1.0 / 3.0)
    centres = []
    for tries in range(200000):
        i = len(centres)
        if i == n_particles:
            break
        p = rng.uniform(radii[i] + gap, 1.0 - radii[i] - gap, 3)
        if all(np.linalg.norm(p - q) > radii[i] + radii[j] + gap for j, q in enumerate(centres)):
            centres.append(p)
    else:
        raise RuntimeError("inside_spheres: could not place the particles")
    return SimpleNamespace(box_m=1e-6, centers_m=np.array(centres) * 1e-6, radii_m=radii * 1e-6)


def composite_accuracy_study(phi: float, n_particles: int, seed: int = 7,
                             voxels=(16, 24, 32, 48, 64), methods=("composite", "centre"),
                             p2_mesh_sizes=(0.25, 0.2), p2_curvature_elements: int = 24,
                             p2_geometry_order: int = 2, p2_solver: str = "cg",
                             progress=False) -> dict:
    """E_eff of one random Fe/PDMS RVE: voxel FEM (per method, refined) against the conforming
    P2 tetrahedral mesh (gmsh) on the same particles. Self-convergence of the voxel FEM by
    Richardson extrapolation of the three finest grids (observed rate). The reference is the
    finest P2 mesh; the change between the two P2 meshes is its own uncertainty
    (``p2_change_rel``). ``p2_geometry_order=2`` (default): isoparametric P2 on curved sphere
    surfaces (the faceted order-1 spheres lose ~10 % of their volume at practical mesh sizes).
    ``p2_solver``: "cg" (default: deflated block CG, memory like the matrix) or "direct" (sparse
    LU, ~1e5 DOF at most here)."""
    from homogenize.cell._conforming import homogenize_conforming
    rve = inside_spheres(phi, n_particles, seed)
    Em = PDMS.E_Pa
    out = {"phi": phi, "n_particles": n_particles, "seed": seed,
           "p2_curvature_elements": p2_curvature_elements,
           "p2_geometry_order": p2_geometry_order, "p2_solver": p2_solver,
           "radii_box": (rve.radii_m / rve.box_m).tolist(),
           "centres_box": (rve.centers_m / rve.box_m).tolist(), "voxel": {}, "p2": []}
    for m in methods:
        rows = []
        for n in voxels:
            t0 = time.perf_counter()
            r = homogenize_rve(rve, n, method=m)
            rows.append({"voxels": int(n), "E_eff_Pa": r.E_eff_Pa,
                         "stiffening": r.E_eff_Pa / Em - 1.0, "phi_voxel": r.phi_voxel,
                         "min_radius_voxels": float(rve.radii_m.min() / r.h_m),
                         "iterations": max(r.iterations.values()),
                         "seconds": time.perf_counter() - t0})
            if progress:
                print(m, rows[-1], flush=True)
        E = np.array([x["E_eff_Pa"] for x in rows])
        ns = np.array(voxels, dtype=float)
        rate = E_inf = None
        if len(rows) >= 3:
            d1, d2 = E[-2] - E[-3], E[-1] - E[-2]
            if d1 * d2 > 0 and abs(d2) < abs(d1):
                # E(n) = E_inf + A n^-p through the three finest grids
                from scipy.optimize import brentq
                f = lambda p: ((ns[-2] ** -p - ns[-1] ** -p) / (ns[-3] ** -p - ns[-2] ** -p)
                               - d2 / d1)
                try:
                    rate = float(brentq(f, 0.05, 8.0))
                    E_inf = float(E[-1] + d2 / ((ns[-1] / ns[-2]) ** rate - 1.0))
                except ValueError:
                    rate = None
        for x in rows:
            x["error_vs_extrapolated"] = None if E_inf is None else x["E_eff_Pa"] / E_inf - 1.0
        out["voxel"][m] = {"rows": rows, "observed_rate": rate, "E_extrapolated_Pa": E_inf}
    for hs in p2_mesh_sizes:
        t0 = time.perf_counter()
        c = homogenize_conforming(1.0, rve.centers_m / rve.box_m, rve.radii_m / rve.box_m, hs,
                                  matrix=(PDMS.E_Pa, PDMS.nu), particle=(FE.E_Pa, FE.nu),
                                  curvature_elements=p2_curvature_elements,
                                  geometry_order=p2_geometry_order, solver=p2_solver)
        E = isotropic_projection(c["C_eff_Pa"])[0]
        out["p2"].append({"mesh_size_box": hs, "E_eff_Pa": E, "stiffening": E / Em - 1.0,
                          "n_dof": c["n_dof"], "phi_mesh": c["phi_mesh"],
                          "seconds": time.perf_counter() - t0})
        if progress:
            print("p2", out["p2"][-1], flush=True)
    if len(out["p2"]) >= 2:
        out["p2_change_rel"] = out["p2"][-1]["E_eff_Pa"] / out["p2"][-2]["E_eff_Pa"] - 1.0
    ref = out["p2"][-1]["E_eff_Pa"]
    for m in methods:
        for x in out["voxel"][m]["rows"]:
            x["error_vs_p2"] = x["E_eff_Pa"] / ref - 1.0
    return out


def plot_composite_accuracy(path, doc: dict) -> None:
    """E_eff / E_m of each RVE of a composite-accuracy document (``results/cell/
    composite_accuracy.json``) against (degrees of freedom)^(-1/3), a common mesh-size measure
    for voxels (3 n^3 DOF) and P2 tetrahedra: composite voxels and the curved (isoparametric)
    P2 meshes, measured values only."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cases = doc["cases"]
    fig = Figure(figsize=(5.2 * len(cases), 4.2))
    FigureCanvasAgg(fig)
    for i, case in enumerate(cases):
        ax = fig.add_subplot(1, len(cases), i + 1)
        # the staircase (in the document too) is left out: 10-60 % above, it would flatten the rest
        for method, style, label in (("composite", "ko-", "composite voxels"),):
            rows = sorted(case["voxel"].get(method, {}).get("rows", []), key=lambda r: r["voxels"])
            if rows:
                x = [(3.0 * r["voxels"] ** 3) ** (-1.0 / 3.0) for r in rows]
                ax.plot(x, [1.0 + r["stiffening"] for r in rows], style, label=label)
        p2 = sorted((q for q in case["p2"] if q.get("geometry_order") == 2),
                    key=lambda q: q["n_dof"])
        if p2:
            ax.plot([q["n_dof"] ** (-1.0 / 3.0) for q in p2], [q["E_ratio"] for q in p2], "b^-",
                    label="conforming P2, curved (gmsh)")
            fin = p2[-1]["E_ratio"]
            ax.axhspan(0.98 * fin, 1.02 * fin, color="0.92", zorder=0,
                       label="+-2 % of the finest P2")
        ax.set_xlim(left=0.0)
        ax.set_xlabel("(degrees of freedom)^(-1/3) [1]")
        ax.set_ylabel("E_eff / E_matrix [1]")
        ax.set_title(f"6 Fe spheres in PDMS, phi = {case['phi']:g}")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
