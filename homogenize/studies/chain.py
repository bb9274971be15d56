"""The whole chain: default study -> effective table -> the seed paper's cantilever versus B.

The seed paper (Gusenbauer et al., EPJ Web Conf. 40, 02001, 2013) computed the body force as
``N F_g / V`` with a guessed powder packing density d = 0.5 and saturated particles,
43.79 kN/m^3, and reproduced the measured 4 mm tip deflection with 40 kN/m^3 (Abaqus) and
50 kN/m^3 (Elmer). It gives neither the strip's dimensions nor the field B at the strip.

Here the body force comes from the table of random RVEs (self-consistent dipoles with a
magnetization law, interactions, size distribution) as a function of B, and the tip deflection
of the seed's strip follows with its interval. The strip: PDMS E = 2 MPa, an assumed thickness
(1 mm) and width (5 mm), and the length for which the paper's own premise holds
(Euler-Bernoulli: 43.79 kN/m^3 bends it by 4 mm). In the linear (Euler-Bernoulli) regime the
prediction is then independent of the assumed thickness: ``delta = 4 mm f_eff / 43.79 kN/m^3``;
the large-deflection (elastica) value, which depends on L, is given as well.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from micro.common.files import (json_ready, atomic_write_text, data_digest, manifest, round_floats, save_png,
                       write_json)
from micro.common.validate import ConvergenceError, InputError, check_positive

from micro.demag import prism_demag_factors
from micro.magnetization import DEFAULT_LAW, get_law
from micro.materials import SEED as _SEED
from micro.materials import ElasticMaterial
from scipy.constants import mu_0 as MU0

from homogenize.tables._stats import widen_in_quadrature
from homogenize.tables._study import load_study
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.closed_form import eb_tip_deflection_m, elastica_tip_deflection
from homogenize.macro.effective import magnetization_from_table
from homogenize.macro.magnets import PermanentMagnet, body_force_along_strip
from homogenize.macro.pullin import place_magnet, pullin_sweep
from homogenize.tables.batch import (body_force_from_table, interpolate, modulus_from_table,
                               read_table, run_batch)

__all__ = ["run_chain", "seed_strip", "DEFAULT_STUDY", "SEED"]

DEFAULT_STUDY = Path(__file__).resolve().parent / "default_study.toml"

#: The seed paper's numbers (Table 1 and Sec. 3.1), from :data:`micro.materials.SEED`.
SEED = {
    "deflection_m": _SEED.deflection_m,            # measured tip deflection
    "f_paper_N_m3": _SEED.paper_body_force_N_m3,   # N F_g / V, c = 3.5 vol%, d = 0.5, saturated
    "f_abaqus_N_m3": _SEED.abaqus_force_N_m3,      # body force reproducing 4 mm in Abaqus
    "f_elmer_N_m3": _SEED.elmer_force_N_m3,        # ... and in Elmer
    "gradB_T_per_m": _SEED.gradB_T_per_m,
    "E_Pa": _SEED.E_Pa,
    "nu": _SEED.nu,
    "c_powder": _SEED.c,
    "d_packing": _SEED.d,
}

#: The magnet of the distance experiment: a common NdFeB cylinder (N42: B_r ~ 1.3 T) of 10 mm
#: diameter and 10 mm height, axis along z, centred under the strip's tip, magnetized along +z.
MAGNET = {"shape": "cylinder", "dimensions_m": (10e-3, 10e-3), "remanence_T": 1.3}
#: gaps between the strip's lower face and the magnet's top face [m]
MAGNET_GAPS_M = (2e-3, 3e-3, 4e-3, 5e-3, 6e-3, 8e-3, 10e-3, 12e-3, 15e-3, 20e-3, 25e-3, 30e-3)
#: segments of the follower elastica (its pull-in gap changes by < 0.1 % from 16 to 64:
#: tests/homogenize/macro/test_pullin.py)
PULLIN_SEGMENTS = 16


def seed_strip(thickness_m: float = 1e-3, width_m: float = 5e-3) -> dict:
    """The strip on which the paper's premise holds: EB deflection 4 mm at 43.79 kN/m^3.

    ``delta = 3 f L^4 / (2 E t^2)`` gives ``L = (2 E t^2 delta / (3 f))^(1/4)``.
    """
    t = check_positive("thickness_m", thickness_m, "m")
    w = check_positive("width_m", width_m, "m")
    L = (2 * SEED["E_Pa"] * t ** 2 * SEED["deflection_m"] / (3 * SEED["f_paper_N_m3"])) ** 0.25
    Strip(L, w, t)                       # the strip's slenderness (a thickness in metres?)
    return {"length_m": L, "width_m": w, "thickness_m": t, "E_Pa": SEED["E_Pa"],
            "nu": SEED["nu"]}


def _deflections(f, strip, E):
    f = np.clip(np.asarray(f, dtype=float), 0.0, None)
    eb = eb_tip_deflection_m(f, strip["length_m"], strip["width_m"], strip["thickness_m"], E)
    el, _h = elastica_tip_deflection(f, strip["length_m"], strip["width_m"],
                                     strip["thickness_m"], E)
    return np.asarray(eb, dtype=float), np.asarray(el, dtype=float)


def _applied_field(table, phi, B_in, N, others):
    """Applied flux density [T] that gives the internal ``B_in = mu0 H_in`` in a specimen of
    demagnetizing factor ``N``: ``B_a = B_in + mu0 N M_eff(B_in)`` (the table's RVEs have a
    metallic boundary: their B_T is the internal field)."""
    M = np.array([interpolate(table, "M_eff_A_per_m", component="z", phi=phi, B_T=float(b),
                              **others).mean for b in B_in])
    return B_in + MU0 * N * M, M


def _pullin(table, phi, strip, E, N, others, gaps_m=MAGNET_GAPS_M):
    """The same magnet with the field on the DEFORMED strip (follower elastica,
    :func:`homogenize.macro.pullin.pullin_sweep`): the gaps closed from the largest to the
    smallest and opened again; pull-in and release gaps, with the pull-in gap's interval from
    the ends of the table's M_eff interval (closing only)."""
    L, w, t = strip["length_m"], strip["width_m"], strip["thickness_m"]
    geo = Strip(L, w, t)
    mat = ElasticMaterial(E, SEED["nu"])
    gaps = np.array(sorted(gaps_m, reverse=True))
    magnet = place_magnet(PermanentMagnet("cylinder", MAGNET["dimensions_m"],
                                          MAGNET["remanence_T"]), geo, float(gaps[0]))
    out = {}
    try:
        for b in ("mean", "low", "high"):
            law = magnetization_from_table(table, phi, bound=b, **others)
            # the tip-only contact (lying=False): the strip lying on the face from 2 mm took
            # more than 5 min per sweep here; pullin_sweep's default traces it
            out[b] = pullin_sweep(geo, mat, magnet, law, gap_sweep_m=gaps,
                                  round_trip=(b == "mean"), n_segments=PULLIN_SEGMENTS,
                                  demag_factor=N, lying=False)
    except (InputError, ConvergenceError) as exc:    # beyond the table's B range / no path
        return {"available": False, "why": str(exc).splitlines()[0]}
    r = out["mean"]
    n = gaps.size
    return {"available": True, "n_segments": PULLIN_SEGMENTS,
            "pull_in_gap_m": r.pull_in_gap_m,
            "pull_in_gap_ci_m": sorted([out["low"].pull_in_gap_m, out["high"].pull_in_gap_m]),
            "pull_in_tip_deflection_m": r.pull_in_tip_deflection_m,
            "release_gap_m": r.release_gap_m, "release_by": r.release_by,
            "snap_back_gap_m": r.snap_back_gap_m, "contact_end_gap_m": r.contact_end_gap_m,
            "closing": [{"gap_m": float(g), "tip_m": float(d), "branch": str(br),
                         "contact_force_N": float(f)}
                        for g, d, br, f in zip(r.sweep_gap_m[:n], r.sweep_tip_deflection_m[:n],
                                               r.sweep_branch[:n], r.sweep_contact_force_N[:n])],
            "opening": [{"gap_m": float(g), "tip_m": float(d), "branch": str(br),
                         "contact_force_N": float(f)}
                        for g, d, br, f in zip(r.sweep_gap_m[n:], r.sweep_tip_deflection_m[n:],
                                               r.sweep_branch[n:], r.sweep_contact_force_N[n:])]}


def _magnet_sweep(table, phi, strip, E, N, others, gaps_m=MAGNET_GAPS_M):
    """Tip deflection against the gap to a permanent magnet under the tip (elastica with the
    body force that varies along the strip), at the mean and both ends of the M_eff interval."""
    L, w, t = strip["length_m"], strip["width_m"], strip["thickness_m"]
    geo = Strip(L, w, t)
    laws = {b: magnetization_from_table(table, phi, bound=b, **others)
            for b in ("mean", "low", "high")}
    rows = []
    for gap in gaps_m:
        h = MAGNET["dimensions_m"][1]
        src = PermanentMagnet("cylinder", MAGNET["dimensions_m"], MAGNET["remanence_T"],
                              position_m=(L, w / 2, -gap - h / 2))
        tips, force = {}, None
        try:
            for b, law in laws.items():
                bf = body_force_along_strip(src, geo, law, n_points=81, demag_factor=N)
                r = solve_cantilever(geo, ElasticMaterial(E, SEED["nu"]), bf.profile(),
                                     model="elastica")
                tips[b] = r.tip_m
                if b == "mean":
                    force = bf
        except InputError as exc:     # the field leaves the table's B range: no extrapolation
            rows.append({"gap_m": gap, "outside_table": str(exc)})
            continue
        B_tip = float(np.linalg.norm(np.einsum("c,ci->i", force.weights, force.B_T[-1])))
        rows.append({"gap_m": gap, "B_tip_T": B_tip,
                     "f_tip_N_m3": float(force.transverse_N_m3[-1]),
                     "f_root_N_m3": float(force.transverse_N_m3[0]),
                     "net_force_N": float(-force.total_force_N[2]),
                     "deflection_elastica_m": tips["mean"],
                     "deflection_ci_m": [min(tips["low"], tips["high"]),
                                         max(tips["low"], tips["high"])]})
    return rows


def _check_chain_study(study) -> None:
    """Refuse a study the chain cannot use, before its table is computed."""
    for req in ("phi", "B_T", "gradB_T_per_m"):
        if req not in study.axis_names:
            raise InputError(f"{study.path}: the chain needs the grid axis {req}")
    if study.evaluator == "relax":
        raise InputError(f"{study.path}: the chain needs the body force f_eff_N_m3, which the "
                         f"relax evaluator does not compute; use evaluator = \"rve\"")
    axes = dict(study.axes)
    multi = [a for a, v in axes.items()
             if a not in ("phi", "B_T", "gradB_T_per_m") and len(v) > 1]
    if multi:
        raise InputError(f"{study.path}: the chain takes grid axes phi, B_T, gradB_T_per_m "
                         f"(one value for the others); {multi} have several")
    B = [float(b) for b in axes["B_T"]]
    if min(B) <= 0:
        raise InputError(f"{study.path}: the chain plots against log B: B_T values must be > 0")
    if len(B) < 2:
        raise InputError(f"{study.path}: the chain interpolates M_eff(H) along B_T: [grid] B_T "
                         f"needs at least two values, got {B}")


def run_chain(study=None, out_dir="results/chain", *, workers=None, scheduler=None,
              progress=True, keep_parts=False, thickness_m=1e-3, width_m=5e-3,
              n_fine=61, demagnetization=True) -> dict:
    """Run the study, write the table and the seed cantilever prediction under ``out_dir``.

    The strip's own demagnetization is included (Aharoni's prism factor through the
    thickness; ``demagnetization=False`` gives the metallic-boundary curve only). Writes
    ``table.h5`` (+ ``table.manifest.json``), ``chain.json`` (every number), ``summary.md``,
    ``deflection_vs_B.png`` and ``deflection_vs_magnet_gap.png``. Returns ``chain.json``.
    """
    study = load_study(DEFAULT_STUDY if study is None else study)
    # everything the chain needs of the study and the strip is checked before anything is
    # written (the table alone takes minutes, and a refused run leaves no directory behind)
    _check_chain_study(study)
    strip = seed_strip(thickness_m, width_m)
    out_dir = Path(out_dir)
    table_path = run_batch(study, out_dir / "table.h5", workers=workers, scheduler=scheduler,
                           progress=progress, clean=not keep_parts)
    table = read_table(table_path)
    N = prism_demag_factors(strip["length_m"], strip["width_m"], strip["thickness_m"])[2] \
        if demagnetization else 0.0
    g = SEED["gradB_T_per_m"]
    others = {a: v[0] for a, v in table.axes.items()
              if a not in ("phi", "B_T", "gradB_T_per_m") and len(v) == 1}
    multi = [a for a, v in table.axes.items()
             if a not in ("phi", "B_T", "gradB_T_per_m") and len(v) > 1]
    if multi:
        raise InputError(f"{study.path}: the chain takes grid axes phi, B_T, gradB_T_per_m "
                         f"(one value for the others); {multi} have several")
    B_grid = np.array(sorted(table.axes["B_T"]), dtype=float)
    if B_grid[0] <= 0:
        raise InputError(f"{study.path}: the chain plots against log B: B_T values must be > 0")
    B_fine = np.unique(np.concatenate([np.geomspace(B_grid[0], B_grid[-1], n_fine), B_grid]))
    curves = []
    for phi in sorted(table.axes["phi"]):
        E_est = modulus_from_table(table, phi, **others)
        E = SEED["E_Pa"] if E_est is None else E_est.mean
        rows = []
        for B in B_fine:
            est = body_force_from_table(table, phi, float(B), g, **others)
            rows.append((B, est.mean, est.ci_low, est.ci_high))
        arr = np.array(rows)
        f_mean, f_lo, f_hi = arr[:, 1], arr[:, 2], arr[:, 3]
        # B_fine is the field inside the strip (the RVE's metallic boundary); the applied
        # field that produces it in the strip of demagnetizing factor N is larger
        B_app, M_in = _applied_field(table, phi, B_fine, N, others)
        eb_mean, el_mean = _deflections(f_mean, strip, E)
        eb_lo, el_lo = _deflections(f_lo, strip, E)
        eb_hi, el_hi = _deflections(f_hi, strip, E)
        if E_est is not None:
            # deflection ~ f / E: the modulus interval (with its discretization error, where
            # the table has one) widens the band (relative errors in quadrature, an
            # approximation good while both are small)
            for lo, hi, mid in ((eb_lo, eb_hi, eb_mean), (el_lo, el_hi, el_mean)):
                lo[:], hi[:] = widen_in_quadrature(mid, lo, hi, E_est.total_rel_half_width)
        # the applied field at which the strip bends by the measured 4 mm (elastica)
        B4 = {k: _crossing(B_app, y, SEED["deflection_m"])
              for k, y in (("mean", el_mean), ("low_force", el_lo), ("high_force", el_hi))}
        B4_metallic = _crossing(B_fine, el_mean, SEED["deflection_m"])
        grid_rows = []
        for i, B in enumerate(B_grid):
            p = table.select(",".join([f"phi={float(phi)!r}", f"B_T={float(B)!r}"]
                                      + ([f"gradB_T_per_m={table.axes['gradB_T_per_m'][0]!r}"]
                                         if len(table.axes["gradB_T_per_m"]) > 1 else [])))
            vals = table.values["d_eff"][p] if "d_eff" in table.values else None
            j = int(np.searchsorted(B_fine, B))
            grid_rows.append({"B_internal_T": float(B), "B_applied_T": float(B_app[j]),
                              "M_eff_A_per_m": float(M_in[j]), "f_eff_N_m3": float(f_mean[j]),
                              "f_ci_N_m3": [float(f_lo[j]), float(f_hi[j])],
                              "d_eff_mean": None if vals is None else float(vals.mean()),
                              "deflection_eb_m": float(eb_mean[j]),
                              "deflection_elastica_m": float(el_mean[j]),
                              "deflection_elastica_ci_m": [float(el_lo[j]), float(el_hi[j])]})
        sweep = _magnet_sweep(table, phi, strip, E, N, others)
        pull = json_ready(_pullin(table, phi, strip, E, N, others))
        curves.append({"phi": phi, "E_Pa": E, "E_from_table": E_est is not None,
                       "B_internal_T": B_fine, "B_applied_T": B_app, "M_eff_A_per_m": M_in,
                       "f_mean_N_m3": f_mean, "f_ci_low_N_m3": f_lo,
                       "f_ci_high_N_m3": f_hi, "deflection_eb_m": eb_mean,
                       "deflection_elastica_m": el_mean, "deflection_ci_low_m": el_lo,
                       "deflection_ci_high_m": el_hi, "B_for_4mm_T": B4,
                       "B_for_4mm_metallic_boundary_T": B4_metallic, "grid": grid_rows,
                       "magnet_sweep": sweep, "pullin": pull})
    law_name = str(others.get("law", DEFAULT_LAW))
    res = {"seed": SEED, "strip": strip, "gradB_T_per_m": g, "confidence": table.confidence,
           "realizations": study.realizations, "n_particles": study.n_particles,
           "law": law_name, "law_parameters": {k: (v if not isinstance(v, float) or math.isfinite(v) else str(v))
                              for k, v in (dict(study.law) or get_law(law_name).params()).items()},
           "demag_factor": N,
           "demag_factor_source": "Aharoni (1998) prism, field through the thickness"
           if demagnetization else "none (metallic boundary)",
           "magnet": MAGNET, "fixed_axes": others, "curves": curves,
           "table": _display_path(table_path),
           "manifest": manifest(study.config(), study.seed)}
    # every written number (JSON, summary, figures) from the same rounded results, so that the
    # last-digit round-off of another CPU does not rewrite them; a figure is redrawn only when
    # its rounded numbers or this drawing code change
    res = round_floats(res)
    write_json(out_dir / "chain.json", res)
    digest = data_digest(res, __file__)
    _plot(out_dir / "deflection_vs_B.png", res, digest)
    _plot_magnet(out_dir / "deflection_vs_magnet_gap.png", res, digest)
    atomic_write_text(out_dir / "summary.md", _summary(res, study))
    return res


def _crossing(x, y, level):
    """First x where the increasing curve y reaches ``level`` (log-linear), or None."""
    y = np.asarray(y)
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return None
    k = int(above[0])
    if k == 0:
        return float(x[0])
    lx0, lx1 = math.log(x[k - 1]), math.log(x[k])
    w = (level - y[k - 1]) / (y[k] - y[k - 1])
    return float(math.exp(lx0 + w * (lx1 - lx0)))


def _plot(path: Path, res: dict, digest: str) -> None:
    from matplotlib.figure import Figure      # lazy: 0.3 s import, only for plotting
    fig = Figure(figsize=(7.4, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for c in res["curves"]:
        B = np.asarray(c["B_applied_T"])
        line, = ax.plot(B, 1e3 * np.asarray(c["deflection_elastica_m"]), "-",
                        label=f"phi = {c['phi']:g}: elastica, strip demag N = "
                              f"{res['demag_factor']:.2f}")
        lo = 1e3 * np.asarray(c["deflection_ci_low_m"])
        hi = 1e3 * np.asarray(c["deflection_ci_high_m"])
        ax.fill_between(B, lo, hi, color=line.get_color(), alpha=0.3, lw=0)
        ax.plot(np.asarray(c["B_internal_T"]), 1e3 * np.asarray(c["deflection_elastica_m"]),
                "--", lw=0.9, color=line.get_color(),
                label=f"phi = {c['phi']:g}: same, metallic boundary (no demag)")
        ax.plot(B, 1e3 * np.asarray(c["deflection_eb_m"]), ":", color=line.get_color(),
                label=f"phi = {c['phi']:g}: Euler-Bernoulli")
        ax.plot([g["B_applied_T"] for g in c["grid"]],
                [1e3 * g["deflection_elastica_m"] for g in c["grid"]], "o", ms=3,
                color=line.get_color())
    rel = max(float(np.max((np.asarray(c["deflection_ci_high_m"]) - np.asarray(c["deflection_ci_low_m"]))
                           / np.maximum(2 * np.asarray(c["deflection_elastica_m"]), 1e-30)))
              for c in res["curves"])
    ax.axhline(1e3 * SEED["deflection_m"], color="k", lw=1.2, ls="--",
               label="seed paper: measured 4 mm")
    f_eq = SEED["f_paper_N_m3"]
    ax.axhspan(1e3 * SEED["deflection_m"] * SEED["f_abaqus_N_m3"] / f_eq,
               1e3 * SEED["deflection_m"] * SEED["f_elmer_N_m3"] / f_eq, color="0.85",
               zorder=0, label="seed: 40-50 kN/m$^3$ (Abaqus/Elmer), EB scaled")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("applied flux density B at the strip [T]")
    ax.set_ylabel("tip deflection [mm]")
    s = res["strip"]
    ax.set_title(f"Seed cantilever (L = {1e3 * s['length_m']:.1f} mm, t = "
                 f"{1e3 * s['thickness_m']:.1f} mm, E = {s['E_Pa'] / 1e6:g} MPa), "
                 f"dB/dz = {res['gradB_T_per_m']} T/m, law {res['law']}\n"
                 f"shaded: {100 * res['confidence']:g} % interval of the random RVEs, at most "
                 f"+-{100 * rel:.1f} % (thinner than the line where it is not visible)",
                 fontsize=8)
    ax.legend(fontsize=6.5, loc="upper left")
    ax.grid(True, which="both", alpha=0.3)
    save_png(fig, path, digest, dpi=120)


def _plot_magnet(path: Path, res: dict, digest: str) -> None:
    from matplotlib.figure import Figure      # lazy: 0.3 s import, only for plotting
    fig = Figure(figsize=(7.0, 4.4), layout="constrained")
    ax = fig.add_subplot()
    for c in res["curves"]:
        sw = [r for r in c["magnet_sweep"] if "outside_table" not in r]
        if not sw:
            continue
        gap = 1e3 * np.array([r["gap_m"] for r in sw])
        d = 1e3 * np.array([r["deflection_elastica_m"] for r in sw])
        lo = 1e3 * np.array([r["deflection_ci_m"][0] for r in sw])
        hi = 1e3 * np.array([r["deflection_ci_m"][1] for r in sw])
        line, = ax.plot(gap, d, "o--", ms=3, lw=0.8,
                        label=f"phi = {c['phi']:g}: dead load (field of the straight strip)")
        ax.fill_between(gap, lo, hi, color=line.get_color(), alpha=0.3, lw=0)
        p = c.get("pullin") or {}
        if p.get("available"):
            for br, mk, what in (("free", "s-", "free"), ("contact", "D-", "tip on the magnet")):
                cl = [r for r in p["closing"] if r["branch"] == br and r["tip_m"] is not None]
                if cl:
                    ax.plot([1e3 * r["gap_m"] for r in cl], [1e3 * r["tip_m"] for r in cl], mk,
                            ms=3, color=line.get_color(),
                            label=f"phi = {c['phi']:g}: follower field, closing, {what}")
            ax.axvline(1e3 * p["pull_in_gap_m"], color=line.get_color(), lw=0.8, ls=":",
                       label=f"phi = {c['phi']:g}: pull-in {1e3 * p['pull_in_gap_m']:.1f} mm")
    ax.axhline(1e3 * SEED["deflection_m"], color="k", lw=1.0, ls="--",
               label="seed paper: measured 4 mm")
    m = res["magnet"]
    ax.set_xlabel("gap between strip and magnet [mm]")
    ax.set_ylabel("tip deflection [mm]")
    ax.set_yscale("log")
    ax.set_title(f"NdFeB cylinder {1e3 * m['dimensions_m'][0]:g} x {1e3 * m['dimensions_m'][1]:g} "
                 f"mm, B_r = {m['remanence_T']:g} T, under the tip; body force varies along the "
                 f"strip; band: M_eff interval", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    save_png(fig, path, digest, dpi=120)


def _pullin_lines(p) -> list:
    if not p:
        return []
    if not p.get("available"):
        return [f"Follower elastica not evaluated: {p.get('why')}", ""]
    lo, hi = p["pull_in_gap_ci_m"]
    lines = [f"**Pull-in gap {1e3 * p['pull_in_gap_m']:.2f} mm** (interval from the table's "
             f"M_eff: [{1e3 * lo:.2f}, {1e3 * hi:.2f}] mm; tip deflection there "
             f"{1e3 * p['pull_in_tip_deflection_m']:.2f} mm): closing the gap below it the strip "
             "snaps to the magnet."]
    rel = p["release_gap_m"]
    if rel is not None and math.isfinite(rel) and p["release_by"] == "contact force zero":
        lines.append(f"Release (lift-off) at {1e3 * rel:.2f} mm on the way back.")
    else:
        lines.append("Release on the way back: not determined -- after the snap the strip does "
                     "not rest on the magnet with its tip alone (it touches beside the magnet's "
                     "rim or lies on it over a length, which the model does not include).")
    lines += ["", "| gap [mm] | closing: tip [mm] | branch | opening: tip [mm] | branch |",
              "|---:|---:|---|---:|---|"]
    opening = {round(r["gap_m"], 9): r for r in p["opening"]}

    def tip(r):
        return "-" if r is None or r["tip_m"] is None or not math.isfinite(r["tip_m"]) \
            else f"{1e3 * r['tip_m']:.3f}"
    for r in p["closing"]:
        o = opening.get(round(r["gap_m"], 9))
        lines.append(f"| {1e3 * r['gap_m']:g} | {tip(r)} | {r['branch']} | {tip(o)} | "
                     f"{o['branch'] if o else '-'} |")
    return lines + [""]


def _display_path(path) -> str:
    """``path`` relative to the repository (or the working directory) when inside it."""
    p = Path(path).resolve()
    for base in (DEFAULT_STUDY.parent.parent, Path.cwd()):
        try:
            return str(p.relative_to(base))
        except ValueError:
            continue
    return str(path)


def _fmt_B(v):
    return "not reached in the table's range" if v is None else f"{v:.3g} T"


def _summary(res: dict, study) -> str:
    s = res["strip"]
    lvl = f"{100 * res['confidence']:g} %"
    Ms = _SEED.Ms_A_m
    lines = [
        "# The chain: random RVEs -> body force -> the seed paper's cantilever", "",
        f"Study `{_display_path(study.path)}` ({study.name}): {study.n_points} grid points x "
        f"{study.realizations} random RVEs of {study.n_particles} particles, seed {study.seed}, "
        f"evaluator `{study.evaluator}`, FEM {'on' if study.fem else 'off'}; fixed axes "
        f"{res['fixed_axes'] or 'none'}. Table: `{Path(res['table']).name}` "
        f"(mean, sd, n, {lvl} Student-t interval per grid point; open with xarray).", "",
        f"Magnetization law `{res['law']}` (parameters {res['law_parameters'] or 'default'}): "
        "each particle follows the intrinsic law of its regime behind its own demagnetization "
        "(the seed's 25 nm Fe cores are multi-domain: M = 3 H0 up to about 0.5 T, then the "
        "anisotropy approach to saturation; `micro.magnetization`).", "",
        f"Specimen demagnetization: the RVEs have a metallic boundary (their B is the field "
        f"inside the strip); the strip's own demagnetizing factor through its thickness, "
        f"N = {res['demag_factor']:.4f} ({res['demag_factor_source']}), turns it into the "
        "applied field B_a = B_in + mu0 N M_eff(B_in).", "",
        "Seed paper: body force N F_g / V = 43.79 kN/m^3 from c = 3.5 vol% powder with a "
        "guessed packing density d = 0.5 and saturated particles; measured tip deflection "
        "4 mm at dB/dz = 1.78 T/m (reproduced with 40 kN/m^3 in Abaqus, 50 kN/m^3 in Elmer). "
        "Neither the strip's dimensions nor B at the strip are given.", "",
        f"Strip used: E = {s['E_Pa'] / 1e6:g} MPa (PDMS"
        f"{'' if not any(c['E_from_table'] for c in res['curves']) else ', or E_eff from the table'}), "
        f"t = {1e3 * s['thickness_m']:g} mm and w = {1e3 * s['width_m']:g} mm (assumed), "
        f"L = {1e3 * s['length_m']:.2f} mm, the length for which the paper's premise holds "
        "(Euler-Bernoulli: 43.79 kN/m^3 -> 4 mm). In the linear regime the prediction does not "
        "depend on the assumed t: delta = 4 mm x f_eff / 43.79 kN/m^3.", "",
        "phi is the true particle volume fraction of the RVE. The paper's N = V c d / V_bead "
        "means phi = c d: 0.0175 with its guessed d = 0.5, at most 0.035 (d = 1, if 3.5 vol% "
        "already is the solid fraction).", "",
    ]
    for c in res["curves"]:
        b4 = c["B_for_4mm_T"]
        top = c["grid"][-1]
        lines += [f"## phi = {c['phi']:g}", "",
                  f"Applied field needed for the measured 4 mm (elastica): {_fmt_B(b4['mean'])}"
                  + ("" if b4["mean"] is None else
                     f" (from the interval of the force: {_fmt_B(b4['high_force'])} to "
                     f"{_fmt_B(b4['low_force'])})")
                  + f"; without the strip's demagnetization (metallic boundary): "
                  f"{_fmt_B(c['B_for_4mm_metallic_boundary_T'])}. At the largest field of the "
                  f"table, B_in = {top['B_internal_T']:g} T (B_a = {top['B_applied_T']:.3g} T), "
                  f"the tip deflection is {1e3 * top['deflection_elastica_m']:.2f} mm and the "
                  f"body force {top['f_eff_N_m3'] / 1e3:.1f} kN/m^3 "
                  f"({100 * top['f_eff_N_m3'] / (c['phi'] * Ms * res['gradB_T_per_m']):.0f} % "
                  f"of the saturated value phi rho sigma_s dB/dz).", "",
                  f"| B_applied [T] | B_internal [T] | M_eff [kA/m] | f_eff [kN/m^3] | "
                  f"{lvl} interval | d_eff | EB [mm] | elastica [mm] | {lvl} interval [mm] |",
                  "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for g in c["grid"]:
            d = "-" if g["d_eff_mean"] is None else f"{g['d_eff_mean']:.3f}"
            lines.append(
                f"| {g['B_applied_T']:.4g} | {g['B_internal_T']:g} | "
                f"{g['M_eff_A_per_m'] / 1e3:.2f} | {g['f_eff_N_m3'] / 1e3:.3f} | "
                f"[{g['f_ci_N_m3'][0] / 1e3:.3f}, {g['f_ci_N_m3'][1] / 1e3:.3f}] | {d} | "
                f"{1e3 * g['deflection_eb_m']:.3f} | {1e3 * g['deflection_elastica_m']:.3f} | "
                f"[{1e3 * g['deflection_elastica_ci_m'][0]:.3f}, "
                f"{1e3 * g['deflection_elastica_ci_m'][1]:.3f}] |")
        m = res["magnet"]
        lines += ["", f"A real magnet: NdFeB cylinder {1e3 * m['dimensions_m'][0]:g} mm x "
                  f"{1e3 * m['dimensions_m'][1]:g} mm, B_r = {m['remanence_T']:g} T, axis along z, "
                  "centred under the strip's tip; field and grad|B| from magpylib over the strip, "
                  "M_eff(H_in) from the table, the body force varying along the strip "
                  "(`deflection_vs_magnet_gap.png`):", "",
                  "| gap [mm] | B at the tip [T] | f at the tip [kN/m^3] | f at the root "
                  "[kN/m^3] | elastica tip [mm] | interval (M_eff) [mm] |",
                  "|---:|---:|---:|---:|---:|---:|"]
        for r in c["magnet_sweep"]:
            if "outside_table" in r:
                lines.append(f"| {1e3 * r['gap_m']:g} | field beyond the table's B range "
                             "(not extrapolated) | | | | |")
                continue
            touch = " (reaches the magnet)" if r["deflection_elastica_m"] >= r["gap_m"] else ""
            lines.append(f"| {1e3 * r['gap_m']:g} | {r['B_tip_T']:.3f} | "
                         f"{r['f_tip_N_m3'] / 1e3:.2f} | {r['f_root_N_m3'] / 1e3:.3f} | "
                         f"{1e3 * r['deflection_elastica_m']:.3f}{touch} | "
                         f"[{1e3 * r['deflection_ci_m'][0]:.3f}, "
                         f"{1e3 * r['deflection_ci_m'][1]:.3f}] |")
        lines += ["", "The elastica tip above is the DEAD load (the field of the undeformed "
                  "strip): a tip that bends towards the magnet meets a stronger field, and a "
                  "deflection larger than the gap goes through the magnet. The strip as it is "
                  "-- the field taken where the strip is (follower elastica, "
                  "`homogenize.macro.pullin`), gaps closed from 30 mm and opened again:", ""]
        lines += _pullin_lines(c.get("pullin"))
    lines += [
        "d_eff is the packing density the seed's formula would have needed (with saturated "
        "particles) to give the computed force: the seed's d = 0.5 stands for the combined "
        "effect of packing and incomplete magnetization.", "",
        "Limits: the interval is the statistical one of the random RVEs (interpolation in B "
        "between grid points and model error are not included); the matrix modulus is the "
        "PDMS value unless the study ran the FEM step; in the B sweep the gradient is taken "
        "uniform (1.78 T/m) whatever B; the particles do not move in the matrix (no "
        "restructuring); the strip's demagnetization uses one factor for the whole strip.", "",
        "Files: `table.h5` (+ `table.manifest.json`), `chain.json` (all numbers), "
        "`deflection_vs_B.png`, `deflection_vs_magnet_gap.png`.", ""]
    return "\n".join(lines)
