"""The seed paper (Gusenbauer et al., EPJ Web Conf. 40, 02001, 2013) reproduced and examined.

``run_paper`` computes every number of ``mapsim paper``: the seed body force (Eqs. 1-3) and its
radius independence, the inferred cantilever length, the force needed for 4 mm with linear and
quadratic tetrahedra and on a converged mesh (the Abaqus/Elmer 25 % gap), linear versus
large-deformation tip deflection, self-weight, and the channel study of Section 3.2 / Fig. 4.
``write_paper`` writes ``paper.json``, ``summary.md``, PNG figures and a manifest.
"""
from __future__ import annotations

import functools
import math
import sys
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit, root_scalar

from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.channel import ChannelGeometry, solve_channel
from homogenize.macro.fem import Material
from micro._validate import check_positive, check_range
from micro._io import atomic_path
from pathlib import Path
from micro._io import atomic_write_text, manifest, write_json
from tqdm import tqdm

__all__ = ["SeedParameters", "seed_body_force", "run_paper", "write_paper", "GRAVITY_M_S2"]

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class SeedParameters:
    """The seed paper's parameters (Table 1 and Section 3.1), SI units."""
    c: float = 0.035                      # particle concentration in the polymer [-]
    d: float = 0.5                        # guessed powder packing density [-]
    radius_m: float = 25e-9               # mean particle radius [m]
    sigma_s_Am2_kg: float = 178.0         # specific saturation moment [A m^2/kg]
    particle_density_kg_m3: float = 7870.0
    gradB_T_per_m: float = 1.78           # field gradient [T/m]
    E_Pa: float = 2.0e6
    nu: float = 0.45
    pdms_density_kg_m3: float = 1210.0
    paper_body_force_N_m3: float = 43.79e3   # printed in the paper
    abaqus_force_N_m3: float = 40e3          # force giving 4 mm in Abaqus
    elmer_force_N_m3: float = 50e3           # force giving 4 mm in Elmer
    deflection_m: float = 4e-3               # measured tip deflection
    phi: float = 0.035                       # particle volume fraction for the self-weight


def seed_body_force(c, d, radius_m, sigma_s_Am2_kg, density_kg_m3, gradB_T_per_m,
                    control_volume_m3=1e-9) -> dict:
    """Body force of the seed paper, Eqs. (1)-(3), evaluated step by step.

    ``N = V c d / V_bead`` beads in the control volume ``V``, each saturated with moment
    ``m = sigma_s rho V_bead`` [A m^2] and pulled by ``F_g = m dB/dx`` [N]; ``F_b = N F_g / V``.
    Returns {N, V_bead_m3, m_Am2, F_g_N, F_b_N_m3}; ``F_b = c d rho sigma_s dB/dx`` exactly, the
    radius cancels.
    """
    c = check_range("c", c, 0.0, 1.0, "", lo_open=True)
    d = check_range("d", d, 0.0, 1.0, "", lo_open=True)
    r = check_positive("radius_m", radius_m, "m")
    s = check_positive("sigma_s_Am2_kg", sigma_s_Am2_kg, "A m^2/kg")
    rho = check_positive("density_kg_m3", density_kg_m3, "kg/m^3")
    g = check_positive("gradB_T_per_m", gradB_T_per_m, "T/m", allow_zero=True)
    V = check_positive("control_volume_m3", control_volume_m3, "m^3")
    v_bead = 4.0 / 3.0 * math.pi * r**3
    N = V * c * d / v_bead
    m = s * rho * v_bead
    F_g = m * g
    return {"radius_m": r, "N": N, "V_bead_m3": v_bead, "m_Am2": m, "F_g_N": F_g,
            "F_b_N_m3": N * F_g / V}


# --------------------------------------------------------------------------------------------
# beam

def _divisions(k: int, length_m: float, thickness_m: float, family: str = "uniform"):
    """Mesh family of the half strip: ``k`` layers through the thickness, elements about
    ``L / (7 k)`` long (aspect ~2.7 at L = 19 t); ``uniform``: k elements across the half
    width, ``thin``: one."""
    nx = max(2, round(7 * k * length_m / (19.0 * thickness_m)))
    return nx, (k if family == "uniform" else 1), k


def _tip(strip, mat, f, k, order, family="uniform", model="fem", **kw):
    return solve_cantilever(strip, mat, f, model=model, order=order,
                            divisions=_divisions(k, strip.length_m, strip.thickness_m, family),
                            **kw)


def _fit_rate(ks, tips):
    """Fit ``tip_k = tip_inf - C k^-p`` (h ~ 1/k); returns (tip_inf, p) and the polyfit rate."""
    ks = np.asarray(ks, float)
    tips = np.asarray(tips, float)
    p0 = (tips[-1] + (tips[-1] - tips[-2]), (tips[-1] - tips[0]) * ks[0], 2.0)
    with warnings.catch_warnings():
        # three levels determine the three parameters exactly: no covariance, which is fine
        warnings.simplefilter("ignore", OptimizeWarning)
        (t_inf, C, p), _ = curve_fit(lambda k, a, C, p: a - C * k**-p, ks, tips, p0=p0,
                                     maxfev=20000)
    err = np.abs(t_inf - tips)
    rate = np.polyfit(np.log(1.0 / ks), np.log(err), 1)[0]
    return float(t_inf), float(p), float(rate)


def _richardson(t_a, t_b, k_a, k_b, p):
    """Extrapolate two mesh levels with the measured order ``p``."""
    w = (k_b / k_a) ** p
    return (w * t_b - t_a) / (w - 1.0)


def _progress(total, quiet):
    if quiet:
        return None
    return tqdm(total=total, desc="mapsim paper", file=sys.stderr, unit="step")


def _beam_study(sp: SeedParameters, width_m, thickness_m, levels, bar):
    mat = Material(sp.E_Pa, sp.nu, sp.pdms_density_kg_m3)
    f0, target = sp.abaqus_force_N_m3, sp.deflection_m
    # Euler-Bernoulli length as starting guess
    L_eb = (target * 2.0 * sp.E_Pa * thickness_m**2 / (3.0 * f0)) ** 0.25
    strip0 = Strip(L_eb, width_m, thickness_m)

    def tick(msg):
        if bar is not None:
            bar.set_postfix_str(msg)
            bar.update(1)

    # mesh-convergence study at the EB length: P2 and P1 on the uniform family
    study = []
    for k in levels["p2"]:
        r = _tip(strip0, mat, f0, k, 2)
        study.append({"k": k, "order": 2, "divisions": r.divisions, "n_dof": r.n_dof,
                      "n_elements": r.n_elements, "tip_m": r.tip_m})
        tick(f"beam P2 k={k}")
    for k in levels["p1"]:
        r = _tip(strip0, mat, f0, k, 1)
        study.append({"k": k, "order": 1, "divisions": r.divisions, "n_dof": r.n_dof,
                      "n_elements": r.n_elements, "tip_m": r.tip_m})
        tick(f"beam P1 k={k}")
    p2 = [s for s in study if s["order"] == 2]
    ks = np.array([s["k"] for s in p2])
    tips = np.array([s["tip_m"] for s in p2])
    use = ks >= 2   # the single-layer mesh is outside the asymptotic range
    if use.sum() < 3:
        use[:] = True
    tip_inf, p_fit, rate = _fit_rate(ks[use], tips[use])
    p1 = [s for s in study if s["order"] == 1]
    fit_p1 = _fit_rate([s["k"] for s in p1[-4:]], [s["tip_m"] for s in p1[-4:]])

    # inferred length: converged = Richardson of the two finest P2 levels used in the search
    ka, kb = levels["search"]

    @functools.lru_cache(maxsize=None)
    def converged(L):
        s = Strip(L, width_m, thickness_m)
        ta = _tip(s, mat, f0, ka, 2).tip_m
        tb = _tip(s, mat, f0, kb, 2).tip_m
        tick(f"length search L={L * 1e3:.3f} mm")
        return _richardson(ta, tb, ka, kb, p_fit)

    d0 = converged(L_eb)
    L1 = L_eb * (target / d0) ** 0.25
    sol = root_scalar(lambda L: converged(L) / target - 1.0, x0=L_eb, x1=L1, method="secant",
                      xtol=1e-9, rtol=1e-7, maxiter=12)
    if not sol.converged:
        raise RuntimeError(f"length search did not converge: {sol.flag}")
    L_star = float(sol.root)
    strip = Strip(L_star, width_m, thickness_m)
    tip_conv = target  # by construction
    comp = tip_conv / f0   # compliance [m per N/m^3] of the converged linear model

    # finest P2 level at the inferred length: check of the extrapolation
    kf = max(levels["p2"])
    r_f = _tip(strip, mat, f0, kf, 2)
    tick("finest P2 at inferred length")

    # the 25 % gap: P1 on the thin family; pick the level closest to 1.25 x converged force
    gap_rows = []
    for k in levels["gap"]:
        r1 = _tip(strip, mat, f0, k, 1, family="thin")
        gap_rows.append({"k": k, "divisions": r1.divisions, "n_dof_P1": r1.n_dof,
                         "force_P1_N_m3": f0 * target / r1.tip_m})
        tick(f"gap P1 k={k}")
    ratios = np.array([g["force_P1_N_m3"] for g in gap_rows]) * comp / target
    paper_gap = sp.elmer_force_N_m3 / sp.abaqus_force_N_m3
    i_gap = int(np.argmin(np.abs(ratios - paper_gap)))
    k_gap = gap_rows[i_gap]["k"]
    r1 = _tip(strip, mat, f0, k_gap, 1, family="thin")
    r2 = _tip(strip, mat, f0, k_gap, 2, family="thin")
    tick("gap mesh P1/P2")
    # the same comparison on a typical coarse mesh (two layers, uniform family)
    c1 = _tip(strip, mat, f0, 2, 1)
    c2 = _tip(strip, mat, f0, 2, 2)
    tick("coarse mesh P1/P2")

    # which locking? the P1/P2 ratio on one mesh versus nu: shear locking alone at nu = 0,
    # growing with the volumetric constraint as nu -> 1/2
    kl = levels["locking"]
    locking = []
    for nu in (0.0, 0.3, 0.45, 0.49):
        m_nu = Material(sp.E_Pa, nu, sp.pdms_density_kg_m3)
        t1 = _tip(strip, m_nu, f0, kl, 1).tip_m
        t2 = _tip(strip, m_nu, f0, kl, 2).tip_m
        locking.append({"nu": nu, "tip_P1_m": t1, "tip_P2_m": t2, "P1_over_P2_force": t2 / t1})
    tick("locking versus nu")

    # large deformation at the inferred geometry, on the level-kn mesh, corrected by the same
    # mesh's linear discretisation factor (tip_conv / linear tip on that mesh)
    kn = levels["nl"]
    lin_k = _tip(strip, mat, f0, kn, 2).tip_m
    corr = tip_conv / lin_k
    nl = _tip(strip, mat, f0, kn, 2, model="neo-hookean", n_steps=4)
    tick("neo-Hookean at 40 kN/m^3")
    el_v, el_h = cf.elastica_tip_deflection(f0, L_star, width_m, thickness_m, sp.E_Pa)
    eb = cf.eb_tip_deflection_m(f0, L_star, width_m, thickness_m, sp.E_Pa)

    # gravity: composite density, self-weight, sag at zero field, field-on change
    rho_eff = (1 - sp.phi) * sp.pdms_density_kg_m3 + sp.phi * sp.particle_density_kg_m3
    w_grav = rho_eff * GRAVITY_M_S2
    mat_eff = Material(sp.E_Pa, sp.nu, rho_eff)
    sag_nl = _tip(strip, mat_eff, 0.0, kn, 2, model="neo-hookean", n_steps=2,
                  gravity_m_s2=GRAVITY_M_S2)
    tick("neo-Hookean self-weight")
    both_nl = _tip(strip, mat_eff, f0, kn, 2, model="neo-hookean", n_steps=5,
                   gravity_m_s2=GRAVITY_M_S2)
    tick("neo-Hookean self-weight + field")

    mesh_info = lambda r: {"divisions": list(r.divisions), "n_dof": r.n_dof,  # noqa: E731
                           "n_elements": r.n_elements, "order": r.order}
    beam = {
        "width_m": width_m, "thickness_m": thickness_m, "inferred_length_m": L_star,
        "eb_length_m": L_eb,
        "length_search": {"method": "secant on the Richardson-extrapolated P2 tip "
                                    f"(levels k={ka},{kb}, order p={p_fit:.3f})",
                          "iterations": sol.iterations, "function_calls": sol.function_calls},
        "finest_P2_tip_m": r_f.tip_m, "finest_P2_mesh": mesh_info(r_f),
        "eb_tip_m": eb, "timoshenko_tip_m": cf.timoshenko_tip_deflection_m(
            f0, L_star, width_m, thickness_m, sp.E_Pa, sp.nu),
        "eb_plate_tip_m": cf.eb_tip_deflection_m(f0, L_star, width_m, thickness_m, sp.E_Pa,
                                                 sp.nu, plate=True),
        "mesh_study": {"length_m": L_eb, "force_N_m3": f0, "rows": study,
                       "P2_extrapolated_tip_m": tip_inf, "P2_observed_order": p_fit,
                       "P2_polyfit_rate": rate, "P1_observed_order": fit_p1[1],
                       "P1_polyfit_rate": fit_p1[2],
                       "mesh_family": "half strip (mirror y = w/2), (nx, ny, nz) = "
                                      "(7k L/(19 t), k, k) hexahedra split in 6 tetrahedra"},
    }
    force = {
        "P1_coarse": f0 * target / r1.tip_m,
        "P2_coarse": f0 * target / r2.tip_m,
        "converged": f0 * target / tip_conv,
        "coarse_mesh": {**mesh_info(r2), "n_dof_P1": r1.n_dof, "family": "thin",
                        "layers_through_thickness": k_gap},
        "converged_mesh": {"method": f"Richardson extrapolation of P2 levels k={ka},{kb} "
                                     f"with the measured order {p_fit:.3f}",
                           "levels": [{"divisions": list(_divisions(k, L_star, thickness_m)),
                                       "order": 2} for k in (ka, kb)],
                           "finest_check": mesh_info(r_f),
                           "finest_check_force_N_m3": f0 * target / r_f.tip_m},
        "gap_P1_over_P2": r2.tip_m / r1.tip_m,
        "paper_gap_elmer_over_abaqus": paper_gap,
        "gap_scan_thin_family": [{**g, "ratio_to_converged": float(q)}
                                 for g, q in zip(gap_rows, ratios)],
        "locking_vs_nu": {"divisions": list(_divisions(kl, L_star, thickness_m)),
                          "rows": locking},
        "two_layer_mesh": {"divisions": list(c1.divisions), "P1_N_m3": f0 * target / c1.tip_m,
                           "P2_N_m3": f0 * target / c2.tip_m, "n_dof_P1": c1.n_dof,
                           "n_dof_P2": c2.n_dof},
    }
    nonlinear = {
        "tip_linear_m": tip_conv,
        "tip_nonlinear_m": nl.tip_m * corr,
        "tip_nonlinear_raw_m": nl.tip_m, "mesh_correction_factor": corr,
        "tip_nonlinear_horizontal_m": nl.tip_horizontal_m * corr,
        "nonlinear_over_linear": nl.tip_m / lin_k,
        "elastica_over_eb": el_v / eb, "elastica_tip_m": el_v, "elastica_horizontal_m": el_h,
        "newton_iterations": nl.iterations, "nonlinear_mesh": mesh_info(nl),
    }
    gravity = {
        "phi": sp.phi, "rho_eff_kg_m3": rho_eff, "self_weight_N_m3": w_grav,
        "self_weight_over_magnetic": w_grav / f0,
        "sag_linear_m": comp * w_grav, "sag_nonlinear_m": sag_nl.tip_m * corr,
        "field_on_change_nonlinear_m": (both_nl.tip_m - sag_nl.tip_m) * corr,
        "field_on_total_nonlinear_m": both_nl.tip_m * corr,
        "note": "self-weight acts along the magnetic force (magnet below the strip)",
    }
    return beam, force, nonlinear, gravity


# --------------------------------------------------------------------------------------------
# channel

def _channel_study(sp: SeedParameters, cfg, bar):
    mat = Material(sp.E_Pa, sp.nu, sp.pdms_density_kg_m3)
    f = sp.abaqus_force_N_m3
    rows, b_rows, d_rows = [], [], []
    b0, d0 = cfg["b_m"], cfg["d_m"]

    def one(a, b, c, d):
        r = solve_channel(ChannelGeometry(a, b, c, d), mat, f, nc=cfg["nc"])
        if bar is not None:
            bar.set_postfix_str(f"channel a={a * 1e3:g} c={c * 1e3:g} mm")
            bar.update(1)
        row = r.to_dict()
        row["plate_formula_m"] = cf.plate_clamped_strip_deflection_m(f, a, c, sp.E_Pa, sp.nu)
        return row

    for a in cfg["a_m"]:
        for c in cfg["c_m"]:
            rows.append(one(a, b0, c, d0))
    a_ref, c_ref = cfg["ref_a_m"], cfg["ref_c_m"]
    for b in cfg["b_sweep_m"]:
        b_rows.append(one(a_ref, b, c_ref, d0))
    for d in cfg["d_sweep_m"]:
        d_rows.append(one(a_ref, b0, c_ref, d))

    def spread(rs):
        v = np.array([r["max_deflection_m"] for r in rs])
        return float((v.max() - v.min()) / v.mean())

    return {"force_N_m3": f, "b_m": b0, "d_m": d0, "table": rows,
            "b_sweep": {"a_m": a_ref, "c_m": c_ref, "rows": b_rows,
                        "relative_spread": spread(b_rows)},
            "d_sweep": {"a_m": a_ref, "c_m": c_ref, "rows": d_rows,
                        "relative_spread": spread(d_rows)},
            "model": "quarter block by symmetry, P2 tetrahedra, bottom bonded to rigid glass, "
                     "channel through the full length, free end faces; linear elasticity "
                     "(cases with 'closes' true would touch the glass: contact not modelled)"}


FULL = {
    "beam": {"p2": (1, 2, 3, 4, 5), "p1": (1, 2, 3, 4, 6, 8), "search": (3, 4), "nl": 3,
             "locking": 4,
             "gap": (6, 7, 8, 9, 10, 11, 12, 14)},
    "channel": {"a_m": (0.5e-3, 1e-3, 2e-3, 5e-3, 10e-3), "c_m": (0.25e-3, 0.5e-3, 1e-3, 2e-3),
                "b_m": 50e-6, "d_m": 20e-3, "nc": 2, "ref_a_m": 5e-3, "ref_c_m": 0.5e-3,
                "b_sweep_m": (20e-6, 50e-6, 100e-6, 200e-6),
                "d_sweep_m": (5e-3, 10e-3, 20e-3, 40e-3)},
}
QUICK = {
    "beam": {"p2": (1, 2, 3), "p1": (1, 2, 3, 4), "search": (1, 2), "nl": 2, "locking": 2,
             "gap": (3, 4)},
    "channel": {"a_m": (1e-3, 5e-3), "c_m": (0.5e-3, 1e-3), "b_m": 50e-6, "d_m": 10e-3,
                "nc": 1, "ref_a_m": 5e-3, "ref_c_m": 0.5e-3, "b_sweep_m": (25e-6, 100e-6),
                "d_sweep_m": (5e-3, 20e-3)},
}


def run_paper(width_m=5e-3, thickness_m=1e-3, *, quick=False, quiet=False,
              params: SeedParameters | None = None) -> dict:
    """Every number of the paper reproduction as a JSON-ready dict (SI units).

    ``quick`` uses small meshes and sweeps (for tests); the full run takes a few minutes.
    """
    sp = params or SeedParameters()
    w = check_positive("width_m", width_m, "m")
    t = check_positive("thickness_m", thickness_m, "m")
    cfg = QUICK if quick else FULL
    bcfg = cfg["beam"]
    n_ch = (len(cfg["channel"]["a_m"]) * len(cfg["channel"]["c_m"])
            + len(cfg["channel"]["b_sweep_m"]) + len(cfg["channel"]["d_sweep_m"]))
    bar = _progress(len(bcfg["p2"]) + len(bcfg["p1"]) + len(bcfg["gap"]) + 12 + n_ch, quiet)

    seed = seed_body_force(sp.c, sp.d, sp.radius_m, sp.sigma_s_Am2_kg,
                           sp.particle_density_kg_m3, sp.gradB_T_per_m)
    radii = [seed_body_force(sp.c, sp.d, r, sp.sigma_s_Am2_kg, sp.particle_density_kg_m3,
                             sp.gradB_T_per_m) for r in (10e-9, 25e-9, 50e-9, 1e-6)]
    per_gradient = sp.c * sp.d * sp.particle_density_kg_m3 * sp.sigma_s_Am2_kg
    try:
        beam, force, nonlinear, gravity = _beam_study(sp, w, t, bcfg, bar)
        channel = _channel_study(sp, cfg["channel"], bar)
    finally:
        if bar is not None:
            bar.total = bar.n   # the root search takes a variable number of steps
            bar.refresh()
            bar.close()
    return {
        "body_force_seed_N_m3": seed["F_b_N_m3"],
        "body_force_paper_N_m3": sp.paper_body_force_N_m3,
        "gradient_reproducing_paper_T_per_m": sp.paper_body_force_N_m3 / per_gradient,
        "body_force_per_gradient_N_m3_per_T_per_m": per_gradient,
        "body_force_radius_check": radii,
        "body_force_if_c_is_particle_fraction_N_m3": seed["F_b_N_m3"] / sp.d,
        "beam": beam,
        "force_for_4mm_N_m3": force,
        "tip_linear_m": nonlinear["tip_linear_m"],
        "tip_nonlinear_m": nonlinear["tip_nonlinear_m"],
        "tip_ratio_nonlinear_over_linear": nonlinear["tip_nonlinear_m"]
        / nonlinear["tip_linear_m"],
        "nonlinear": nonlinear,
        "gravity": gravity,
        "channel": channel,
        "parameters": {k: getattr(sp, k) for k in SeedParameters.__dataclass_fields__},
        "quick": bool(quick),
    }


# --------------------------------------------------------------------------------------------
# output

def _figures(res: dict, out) -> list[str]:
    # matplotlib.figure.Figure needs no pyplot and no global backend state
    from matplotlib.figure import Figure


    names = []

    def save(fig, name):
        names.append(name)
        with atomic_path(out / name) as tmp:
            fig.savefig(tmp, dpi=120, format="png")

    beam = res["beam"]
    ms = beam["mesh_study"]
    rows = ms["rows"]
    fig = Figure(figsize=(10, 4))
    ax1, ax2 = fig.subplots(1, 2)
    for order, mk in ((1, "s-"), (2, "o-")):
        rr = [r for r in rows if r["order"] == order]
        ax1.semilogx([r["n_dof"] for r in rr], [r["tip_m"] * 1e3 for r in rr], mk,
                     label=f"P{order} tetrahedra")
    ax1.axhline(ms["P2_extrapolated_tip_m"] * 1e3, color="k", ls="--",
                label="converged (extrapolated)")
    eb = cf.eb_tip_deflection_m(ms["force_N_m3"], ms["length_m"], beam["width_m"],
                                beam["thickness_m"], res["parameters"]["E_Pa"])
    ax1.axhline(eb * 1e3, color="gray", ls=":", label="Euler-Bernoulli")
    ax1.set_xlabel("displacement dofs (half strip)")
    ax1.set_ylabel("tip deflection at 40 kN/m$^3$ [mm]")
    ax1.set_title(f"mesh convergence, L = {ms['length_m'] * 1e3:.2f} mm")
    ax1.legend(fontsize=8)
    p1 = {r["k"]: r for r in rows if r["order"] == 1}
    conv = ms["P2_extrapolated_tip_m"]
    ks = sorted(p1)
    ax2.plot(ks, [conv / p1[k]["tip_m"] for k in ks], "s-", label="P1, uniform family")
    p2 = {r["k"]: r for r in rows if r["order"] == 2}
    ax2.plot(sorted(p2), [conv / p2[k]["tip_m"] for k in sorted(p2)], "o-",
             label="P2, uniform family")
    gap = res["force_for_4mm_N_m3"]["gap_scan_thin_family"]
    ax2.plot([g["k"] for g in gap], [g["ratio_to_converged"] for g in gap], "^--",
             label="P1, one element across half width")
    ax2.axhline(1.25, color="r", ls=":", label="Elmer / Abaqus = 50 / 40")
    ax2.axhline(1.0, color="k", lw=0.8)
    ax2.set_yscale("log")
    ax2.set_xlabel("element layers through the thickness k")
    ax2.set_ylabel("force for 4 mm / converged force")
    ax2.set_title("the gap closes with refinement")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    save(fig, "beam_convergence.png")

    # nonlinear: elastica curve, EB line, FEM points
    nl, g = res["nonlinear"], res["gravity"]
    L, w, t = beam["inferred_length_m"], beam["width_m"], beam["thickness_m"]
    E = res["parameters"]["E_Pa"]
    f = np.linspace(0.0, 1.5 * res["parameters"]["abaqus_force_N_m3"], 31)
    el, _ = cf.elastica_tip_deflection(f, L, w, t, E)
    scale = nl["tip_linear_m"] / cf.eb_tip_deflection_m(f[-1] / 1.5, L, w, t, E)
    fig = Figure(figsize=(5.5, 4))
    ax = fig.subplots()
    ax.plot(f / 1e3, scale * cf.eb_tip_deflection_m(f, L, w, t, E) * 1e3, "k--",
            label="linear (3D FEM, converged)")
    ax.plot(f / 1e3, scale * el * 1e3, "b-", label="elastica x 3D factor")
    ax.plot([res["parameters"]["abaqus_force_N_m3"] / 1e3], [nl["tip_nonlinear_m"] * 1e3], "ro",
            label="neo-Hookean 3D FEM")
    ax.plot([g["self_weight_N_m3"] / 1e3], [g["sag_nonlinear_m"] * 1e3], "gs",
            label="self-weight only (FEM)")
    ax.plot([(g["self_weight_N_m3"] + res["parameters"]["abaqus_force_N_m3"]) / 1e3],
            [g["field_on_total_nonlinear_m"] * 1e3], "md", label="self-weight + 40 kN/m$^3$")
    ax.set_xlabel("transverse body force [kN/m$^3$]")
    ax.set_ylabel("tip deflection [mm]")
    ax.set_title(f"strip {L * 1e3:.1f} x {w * 1e3:g} x {t * 1e3:g} mm")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save(fig, "beam_nonlinear.png")

    # channel
    ch = res["channel"]
    fig = Figure(figsize=(11, 3.8))
    ax1, ax2, ax3 = fig.subplots(1, 3)
    cs = sorted({r["c_m"] for r in ch["table"]})
    for c in cs:
        rr = sorted((r for r in ch["table"] if r["c_m"] == c), key=lambda r: r["a_m"])
        a = np.array([r["a_m"] for r in rr])
        ln, = ax1.loglog(a * 1e3, [r["max_deflection_m"] * 1e6 for r in rr], "o-",
                         label=f"c = {c * 1e3:g} mm")
        ax1.loglog(a * 1e3, [r["plate_formula_m"] * 1e6 for r in rr], ":", color=ln.get_color())
        ax2.loglog(a * 1e3, [max(r["area_reduction"], 1e-9) * 100 for r in rr], "o-",
                   color=ln.get_color())
    ax1.axhline(ch["b_m"] * 1e6, color="r", lw=0.8, ls="--", label="channel height b")
    ax1.set_xlabel("channel width a [mm]")
    ax1.set_ylabel("max ceiling deflection [$\\mu$m]")
    ax1.set_title("dotted: clamped plate strip")
    ax1.legend(fontsize=7)
    ax2.set_xlabel("channel width a [mm]")
    ax2.set_ylabel("cross-section reduction [%]")
    ax2.set_title(f"f = {ch['force_N_m3'] / 1e3:g} kN/m$^3$, b = {ch['b_m'] * 1e6:g} $\\mu$m")
    bs, ds = ch["b_sweep"], ch["d_sweep"]
    ref = np.mean([r["max_deflection_m"] for r in ds["rows"]])
    ax3.semilogx([r["b_m"] / bs["a_m"] for r in bs["rows"]],
                 [r["max_deflection_m"] / ref for r in bs["rows"]], "o-", label="vary b (b/a)")
    ax3.semilogx([r["d_m"] / ds["a_m"] for r in ds["rows"]],
                 [r["max_deflection_m"] / ref for r in ds["rows"]], "s-", label="vary d (d/a)")
    ax3.set_ylim(0.0, 1.5)
    ax3.set_xlabel("b/a or d/a")
    ax3.set_ylabel("deflection / mean")
    ax3.set_title(f"a = {bs['a_m'] * 1e3:g} mm, c = {bs['c_m'] * 1e3:g} mm")
    ax3.legend(fontsize=8)
    fig.tight_layout()
    save(fig, "channel.png")
    return names


def _summary(res: dict, figures) -> str:
    p = res["parameters"]
    b, f, nl, g, ch = (res["beam"], res["force_for_4mm_N_m3"], res["nonlinear"], res["gravity"],
                       res["channel"])
    ms = b["mesh_study"]
    cm = f["coarse_mesh"]
    two = f["two_layer_mesh"]
    rad = "\n".join(f"| {r['radius_m'] * 1e9:g} | {r['N']:.4g} | {r['F_g_N']:.4g} | "
                    f"{r['F_b_N_m3']:.6g} |" for r in res["body_force_radius_check"])
    table = "\n".join(
        f"| {r['a_m'] * 1e3:g} | {r['c_m'] * 1e3:g} | {r['max_deflection_m'] * 1e6:.4g} | "
        f"{r['plate_formula_m'] * 1e6:.4g} | {100 * r['area_reduction']:.3g} | "
        f"{'yes' if r['closes'] else 'no'} |" for r in ch["table"])
    lock = ", ".join(f"{r['P1_over_P2_force']:.2f} at nu = {r['nu']:g}"
                     for r in f["locking_vs_nu"]["rows"])
    quick = ("\n> **Quick run** (reduced meshes and sweeps, for tests): numbers are indicative "
             "only.\n" if res["quick"] else "")
    return f"""# The seed paper reproduced and examined
{quick}
Gusenbauer et al., *Simulation of magnetic active polymers for versatile microfluidic devices*,
EPJ Web of Conferences 40, 02001 (2013). All numbers SI; `paper.json` holds every value.

## 1. Body force, Eqs. (1)-(3)

With c = {p['c']:g}, d = {p['d']:g}, 178 A m^2/kg, 7870 kg/m^3 and dB/dx = {p['gradB_T_per_m']:g} T/m
the formula gives **F_b = {res['body_force_seed_N_m3'] / 1e3:.3f} kN/m^3**; the paper prints
{res['body_force_paper_N_m3'] / 1e3:.2f} kN/m^3, which needs dB/dx =
{res['gradient_reproducing_paper_T_per_m']:.4f} T/m (a rounding of the gradient, 0.3 %).

N = V c d / V_bead and F_g = sigma_s rho V_bead dB/dx, so F_b = c d rho sigma_s dB/dx
= {res['body_force_per_gradient_N_m3_per_T_per_m']:.1f} N/m^3 per T/m: the radius cancels.

| radius [nm] | N in 1 mm^3 | F_g per bead [N] | F_b [N/m^3] |
|---|---|---|---|
{rad}

What this means for the packing-density guess: the particle size never mattered; the only
uncertain factor is the product c d, i.e. the true particle volume fraction phi = c d
= {p['c'] * p['d']:g}. The 50 % "sphere pack" guess therefore halves the force of a composite whose
3.5 vol% are true particle volume ({res['body_force_if_c_is_particle_fraction_N_m3'] / 1e3:.1f}
kN/m^3 without it); it is a calibration factor, not physics. The formula also assumes every
particle is saturated and feels only the applied gradient (no demagnetisation, no
particle-particle interaction), which is what the micro layer of mapsim replaces.

## 2. The cantilever

The paper gives no dimensions. A cast PDMS strip that visibly bends 4 mm under a hand-held coil
is a few centimetres long, millimetres wide and about a millimetre thick; we take
**width {b['width_m'] * 1e3:g} mm, thickness {b['thickness_m'] * 1e3:g} mm**. Euler-Bernoulli then
gives L = {b['eb_length_m'] * 1e3:.3f} mm for 4 mm at 40 kN/m^3; a secant root search on the
converged 3D solution (P2 tetrahedra, Richardson-extrapolated with the measured order) gives the
**inferred length L = {b['inferred_length_m'] * 1e3:.3f} mm**. The 3D strip is stiffer than
Euler-Bernoulli (EB {b['eb_tip_m'] * 1e3:.3f} mm, Timoshenko {b['timoshenko_tip_m'] * 1e3:.3f} mm,
plate limit {b['eb_plate_tip_m'] * 1e3:.3f} mm at that length) because the clamp suppresses the
anticlastic curvature near the root (width/length = {b['width_m'] / b['inferred_length_m']:.2f}).

Mesh study (half strip by symmetry, k layers through the thickness, see `beam_convergence.png`):
P2 converges with observed order p = {ms['P2_observed_order']:.2f} in h (polyfit rate
{ms['P2_polyfit_rate']:.2f}); the finest P2 mesh ({b['finest_P2_mesh']['n_dof']} dofs) is
{100 * (1 - b['finest_P2_tip_m'] / nl['tip_linear_m']):.2f} % below the extrapolated value.
P1 converges with order {ms['P1_observed_order']:.2f}.

### The 25 % Abaqus / Elmer gap

| mesh | P1 (linear tets) | P2 (quadratic tets) | converged |
|---|---|---|---|
| two layers, {two['divisions']} | {two['P1_N_m3'] / 1e3:.1f} kN/m^3 | {two['P2_N_m3'] / 1e3:.1f} kN/m^3 | {f['converged'] / 1e3:.1f} kN/m^3 |
| {cm['layers_through_thickness']} layers, {cm['divisions']} | **{f['P1_coarse'] / 1e3:.1f} kN/m^3** | **{f['P2_coarse'] / 1e3:.1f} kN/m^3** | {f['converged'] / 1e3:.1f} kN/m^3 |

Force needed for 4 mm. On the same mesh, linear tetrahedra need
{f['gap_P1_over_P2']:.2f} x the force of quadratic ones on the {cm['layers_through_thickness']}-layer
mesh (the paper: 50/40 = 1.25). Linear tetrahedra lock: their constant strain cannot represent
bending (shear locking), and near incompressibility (lambda = 9 mu at nu = 0.45) adds
volumetric locking. On the mesh {f['locking_vs_nu']['divisions']} the P1/P2 force ratio is
{lock}: most of the gap is shear locking, the volumetric part grows as nu -> 1/2. The gap is thus reproduced by *the same mesh with linear 4-node tetrahedra in one code (as
Elmer runs on a first-order mesh) and quadratic 10-node tetrahedra in the other (as Abaqus
C3D10)*; quadratic elements are within {100 * abs(f['P2_coarse'] / f['converged'] - 1):.1f} % of
the converged force on that mesh, so Abaqus' 40 kN/m^3 is the trustworthy number. A gap of
exactly 25 % needs a rather fine mesh ({cm['layers_through_thickness']} layers through the
thickness); on a typical two-layer mesh linear tetrahedra would need
{two['P1_N_m3'] / f['converged']:.1f} x the force, so the Elmer mesh was either fine or its
elements were not all linear. The gap closes under refinement (right panel of
`beam_convergence.png`): it is a discretisation error, not a difference between the codes.

### Large deformation

At L = {b['inferred_length_m'] * 1e3:.2f} mm and 40 kN/m^3: linear tip **{res['tip_linear_m'] * 1e3:.3f} mm**,
neo-Hookean total-Lagrangian (load stepping, Newton, {nl['newton_iterations']} iterations)
**{res['tip_nonlinear_m'] * 1e3:.3f} mm**, ratio {res['tip_ratio_nonlinear_over_linear']:.4f}
(elastica / Euler-Bernoulli: {nl['elastica_over_eb']:.4f}); the tip also moves
{nl['tip_nonlinear_horizontal_m'] * 1e3:.2f} mm towards the clamp. The paper's linear analysis
overestimates the deflection by {100 * (1 / res['tip_ratio_nonlinear_over_linear'] - 1):.1f} %.

### Self-weight

rho_eff = (1 - phi) 1210 + phi 7870 = {g['rho_eff_kg_m3']:.1f} kg/m^3 at phi = {g['phi']:g}:
rho_eff g = **{g['self_weight_N_m3'] / 1e3:.2f} kN/m^3**, {100 * g['self_weight_over_magnetic']:.0f} % of
the magnetic force. A horizontal strip already sags {g['sag_nonlinear_m'] * 1e3:.2f} mm at zero field
(linear {g['sag_linear_m'] * 1e3:.2f} mm); switching the field on moves the tip by a further
{g['field_on_change_nonlinear_m'] * 1e3:.2f} mm (large deformation). An experiment that reports the
deflection relative to the sagged state and a simulation that ignores gravity differ by this much.

## 3. The channel (Section 3.2, Fig. 4)

PDMS block bonded to rigid glass, channel width a, height b = {ch['b_m'] * 1e6:g} um, ceiling
thickness c, length d = {ch['d_m'] * 1e3:g} mm, body force {ch['force_N_m3'] / 1e3:g} kN/m^3
towards the glass; 3D linear elasticity, P2 tetrahedra, quarter model by symmetry.

| a [mm] | c [mm] | max deflection [um] | clamped plate strip [um] | area reduction [%] | closes |
|---|---|---|---|---|---|
{table}

The deflection grows like a^4 / c^2 for wide channels (the clamped-plate limit, approached from
above because the walls are elastic) and is negligible for narrow ones, where the compression of
the whole block dominates: Fig. 4's trend (wide a, thin c) holds. Varying b over
{', '.join(f"{r['b_m'] * 1e6:g}" for r in ch['b_sweep']['rows'])} um changes the deflection by
{100 * ch['b_sweep']['relative_spread']:.1f} % and varying d over
{', '.join(f"{r['d_m'] * 1e3:g}" for r in ch['d_sweep']['rows'])} mm by
{100 * ch['d_sweep']['relative_spread']:.1f} % (a = {ch['b_sweep']['a_m'] * 1e3:g} mm,
c = {ch['b_sweep']['c_m'] * 1e3:g} mm): b and d hardly matter for a >> b, as the paper says.
Cases marked "closes" would touch the glass; contact is not modelled.

Figures: {', '.join(figures)}.
"""


def write_paper(out_dir, json_path=None, *, quick=False, quiet=False, width_m=5e-3,
                thickness_m=1e-3) -> dict:
    """Run :func:`run_paper` and write ``paper.json``, ``summary.md``, figures and manifest."""


    out = Path(out_dir)
    res = run_paper(width_m, thickness_m, quick=quick, quiet=quiet)
    out.mkdir(parents=True, exist_ok=True)
    figs = _figures(res, out)
    write_json(out / "paper.json", res)
    if json_path is not None and Path(json_path).resolve() != (out / "paper.json").resolve():
        write_json(json_path, res)
    atomic_write_text(out / "summary.md", _summary(res, figs))
    write_json(out / "manifest.json", manifest(
        {"width_m": width_m, "thickness_m": thickness_m, "quick": quick,
         "parameters": res["parameters"]}, None, outputs=["paper.json", "summary.md", *figs]))
    return res
