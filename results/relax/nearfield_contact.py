"""Near-field magnetic force of two spheres against point dipoles, at and near contact.

Writes results/relax/nearfield_contact.json and .png: the ratio of the exact two-sphere force
(micro.nearfield, two-centre multipole expansion) to the point-dipole pair force (same spheres,
mutually self-consistent dipoles) against gap/a, for the pair along the field (attraction) and
across it (repulsion), at relative permeabilities 10, 100, 1000 and for the saturating Fe law
(25 nm Fe spheres, default 'regime' law -> 'approach') through its chord permeability at
several applied fields; plus the independent axisymmetric FEM checks and the transverse
contact value. Run: .venv/bin/python results/relax/nearfield_contact.py
"""
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from scipy.constants import mu_0 as MU0

from micro.magnetization import get_law
from micro.materials import FE
from micro.nearfield import (MU_MAX, chord_permeability, fem_axial_polarizability,
                             multipole_order, pair_polarizabilities,
                             point_dipole_polarizabilities)

HERE = Path(__file__).resolve().parent
GAPS = np.geomspace(1e-3, 3.0, 28)          # surface gap / radius


def ratios(mu):
    par, perp, L = [], [], []
    for g in GAPS:
        R = 2.0 + g
        ex = pair_polarizabilities(R, 1.0, 1.0, mu, mu)
        pd = point_dipole_polarizabilities(R, 1.0, 1.0, mu, mu)
        par.append(ex[2] / pd[2])
        perp.append(ex[3] / pd[3])
        L.append(multipole_order(R, 1.0, 1.0, mu, mu))
    return par, perp, L


def fe_chord(B_T, a_m=25e-9):
    """Chord permeability of an isolated 25 nm Fe sphere (default law) at applied B."""
    law = get_law("regime")
    V = 4.0 / 3.0 * math.pi * a_m ** 3
    m_sat = FE.Ms_A_m * V
    H = np.array([[0.0, 0.0, B_T / MU0]])
    try:
        from micro.rve import RVE
        rve = RVE.from_spheres(1e-6, [[5e-7, 5e-7, 5e-7]], [a_m])
        law = law.bind(rve) if getattr(law, "bind", None) else law
        m_sat = float(rve.m_sat_Am2[0])
    except Exception:       # pragma: no cover - the unbound law works for plain Fe
        pass
    m = law.moment(H, np.array([m_sat]), V)
    return float(chord_permeability(m, H, V, mu_max=math.inf)[0]), float(np.linalg.norm(m)) / m_sat


def main():
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    out = {"description": __doc__.strip().splitlines()[0],
           "gap_over_a": GAPS.tolist(), "mu_r": {}, "fe_law": {}, "fem_checks": [],
           "mu_max_cap": MU_MAX}
    for mu in (10.0, 100.0, 1000.0):
        par, perp, L = ratios(mu)
        out["mu_r"][f"{mu:g}"] = {"ratio_along_field": par, "ratio_across_field": perp,
                                  "multipole_orders": L}
    for B in (0.1, 0.3, 0.6, 1.0):
        mu_c, MoMs = fe_chord(B)
        mu_used = min(mu_c, MU_MAX)
        par, perp, _ = ratios(mu_used)
        out["fe_law"][f"{B:g}"] = {"B_T": B, "chord_mu_r": mu_c if math.isfinite(mu_c) else "inf",
                                   "mu_r_used": mu_used, "m_over_m_sat": MoMs,
                                   "ratio_along_field": par, "ratio_across_field": perp}
    # independent check: axisymmetric FEM (moment and force along the line of centres)
    for mu, g, hs in ((10.0, 0.5, 0.05), (100.0, 0.1, 0.05), (1000.0, 0.1, 0.05),
                      (1000.0, 0.03, 0.05), (1000.0, 0.03, 0.025)):
        R = 2.0 + g
        ap, _, dap, _ = pair_polarizabilities(R, 1.0, 1.0, mu, mu)
        pd = point_dipole_polarizabilities(R, 1.0, 1.0, mu, mu)[2]
        h = 0.02 * g
        al = fem_axial_polarizability(R, 1.0, mu, h_surface=hs)
        dal = (fem_axial_polarizability(R, 1.0, mu, h_surface=hs, morph_m=h)
               - fem_axial_polarizability(R, 1.0, mu, h_surface=hs, morph_m=-h)) / (2 * h)
        out["fem_checks"].append({"mu_r": mu, "gap_over_a": g, "h_surface_over_a": hs,
                                  "alpha_rel_error": al / ap - 1.0,
                                  "force_rel_error": dal / dap - 1.0,
                                  "exact_over_point_dipole": dap / pd})
    vals = {g: pair_polarizabilities(2 + g, 1, 1, math.inf, math.inf, tol=1e-8)[1] / (4 * math.pi)
            for g in (1e-2, 3e-3, 1e-3)}
    out["transverse_contact"] = {"published_3zeta3_over_2": 1.5 * 1.2020569031595942,
                                 "alpha_perp_over_4pi_a3_at_gap": {f"{g:g}": v
                                                                   for g, v in vals.items()}}
    # contact ratios at gap 0.01 a and 0.05 a (the relax contact layer)
    summ = {}
    for key, d in list(out["mu_r"].items()) + [(f"Fe {k} T", v) for k, v in out["fe_law"].items()]:
        summ[key] = {f"along_at_gap_{g:g}a": float(np.interp(math.log(g), np.log(GAPS),
                                                             d["ratio_along_field"]))
                     for g in (0.01, 0.05, 0.2, 1.0)}
    out["summary"] = summ
    out["seconds"] = time.perf_counter() - t0
    out["load_average_start_end"] = [load0[0], os.getloadavg()[0]]
    (HERE / "nearfield_contact.json").write_text(json.dumps(out, indent=1))
    plot(out)


def plot(out):
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    ax = fig.add_subplot()
    g = np.asarray(out["gap_over_a"])
    for i, (mu, d) in enumerate(out["mu_r"].items()):
        ax.loglog(g, d["ratio_along_field"], "-", color=f"C{i}", label=f"mu_r = {mu}, along B")
        ax.loglog(g, d["ratio_across_field"], "--", color=f"C{i}", label=f"mu_r = {mu}, across B")
    for j, (B, d) in enumerate(out["fe_law"].items()):
        if B in ("0.6", "1"):
            ax.loglog(g, d["ratio_along_field"], ":", color=f"C{3 + j}", lw=2,
                      label=f"Fe law at B = {B} T (chord mu_r {d['mu_r_used']:.3g}), along B")
    for c in out["fem_checks"]:
        ax.plot(c["gap_over_a"], c["exact_over_point_dipole"] * (1 + c["force_rel_error"]),
                "kx", ms=8)
    ax.plot([], [], "kx", label="axisymmetric FEM (along B)")
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_xlabel("surface gap / sphere radius [-]")
    ax.set_ylabel("exact two-sphere force / point-dipole force [-]")
    ax.set_title("Near-field force of two equal magnetizable spheres (multipole expansion)")
    ax.legend(fontsize=7, loc="upper right")
    fig.savefig(HERE / "nearfield_contact.png", dpi=120)


if __name__ == "__main__":
    main()
