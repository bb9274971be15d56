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

from micro._io import atomic_path, atomic_write_text, manifest, write_json
from micro._validate import InputError, check_positive

from homogenize._study import load_study
from homogenize.tables import body_force_from_table, modulus_from_table, read_table, run_batch
from homogenize.macro.closed_form import eb_tip_deflection_m, elastica_tip_deflection

__all__ = ["run_chain", "seed_strip", "DEFAULT_STUDY", "SEED"]

DEFAULT_STUDY = Path(__file__).resolve().parent / "default_study.toml"

#: The seed paper's numbers (Table 1 and Sec. 3.1).
SEED = {
    "deflection_m": 4e-3,          # measured tip deflection
    "f_paper_N_m3": 43.79e3,       # N F_g / V with c = 3.5 vol%, d = 0.5, saturated particles
    "f_abaqus_N_m3": 40e3,         # body force reproducing 4 mm in Abaqus
    "f_elmer_N_m3": 50e3,          # ... and in Elmer
    "gradB_T_per_m": 1.78,
    "E_Pa": 2e6,
    "nu": 0.45,
    "c_powder": 0.035,
    "d_packing": 0.5,
}


def seed_strip(thickness_m: float = 1e-3, width_m: float = 5e-3) -> dict:
    """The strip on which the paper's premise holds: EB deflection 4 mm at 43.79 kN/m^3.

    ``delta = 3 f L^4 / (2 E t^2)`` gives ``L = (2 E t^2 delta / (3 f))^(1/4)``.
    """
    t = check_positive("thickness_m", thickness_m, "m")
    w = check_positive("width_m", width_m, "m")
    L = (2 * SEED["E_Pa"] * t ** 2 * SEED["deflection_m"] / (3 * SEED["f_paper_N_m3"])) ** 0.25
    return {"length_m": L, "width_m": w, "thickness_m": t, "E_Pa": SEED["E_Pa"],
            "nu": SEED["nu"]}


def _deflections(f, strip, E):
    f = np.clip(np.asarray(f, dtype=float), 0.0, None)
    eb = eb_tip_deflection_m(f, strip["length_m"], strip["width_m"], strip["thickness_m"], E)
    el, _h = elastica_tip_deflection(f, strip["length_m"], strip["width_m"],
                                     strip["thickness_m"], E)
    return np.asarray(eb, dtype=float), np.asarray(el, dtype=float)


def run_chain(study=None, out_dir="results/chain", *, workers=None, scheduler=None,
              progress=True, keep_parts=False, thickness_m=1e-3, width_m=5e-3,
              n_fine=61) -> dict:
    """Run the study, write the table and the seed cantilever prediction under ``out_dir``.

    Writes ``table.h5`` (+ ``table.manifest.json``), ``chain.json`` (every number),
    ``summary.md`` and ``deflection_vs_B.png``. Returns the content of ``chain.json``.
    """
    study = load_study(DEFAULT_STUDY if study is None else study)
    for req in ("phi", "B_T", "gradB_T_per_m"):
        if req not in study.axis_names:
            raise InputError(f"{study.path}: the chain needs the grid axis {req}")
    out_dir = Path(out_dir)
    table_path = run_batch(study, out_dir / "table.h5", workers=workers, scheduler=scheduler,
                           progress=progress, clean=not keep_parts)
    table = read_table(table_path)
    strip = seed_strip(thickness_m, width_m)
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
        eb_mean, el_mean = _deflections(f_mean, strip, E)
        eb_lo, el_lo = _deflections(f_lo, strip, E)
        eb_hi, el_hi = _deflections(f_hi, strip, E)
        if E_est is not None:
            # deflection ~ f / E: the modulus interval widens the band (relative errors in
            # quadrature, an approximation good while both are small)
            for lo, hi, mid in ((eb_lo, eb_hi, eb_mean), (el_lo, el_hi, el_mean)):
                lo[:], hi[:] = widen_in_quadrature(mid, lo, hi, E_est.rel_half_width)
        # the field at which the strip bends by the measured 4 mm (elastica, mean and band)
        B4 = {k: _crossing(B_fine, y, SEED["deflection_m"])
              for k, y in (("mean", el_mean), ("low_force", el_lo), ("high_force", el_hi))}
        grid_rows = []
        for i, B in enumerate(B_grid):
            p = table.select(",".join([f"phi={float(phi)!r}", f"B_T={float(B)!r}"]
                                      + ([f"gradB_T_per_m={table.axes['gradB_T_per_m'][0]!r}"]
                                         if len(table.axes["gradB_T_per_m"]) > 1 else [])))
            vals = table.values["d_eff"][p] if "d_eff" in table.values else None
            j = int(np.searchsorted(B_fine, B))
            grid_rows.append({"B_T": float(B), "f_eff_N_m3": float(f_mean[j]),
                              "f_ci_N_m3": [float(f_lo[j]), float(f_hi[j])],
                              "d_eff_mean": None if vals is None else float(vals.mean()),
                              "deflection_eb_m": float(eb_mean[j]),
                              "deflection_elastica_m": float(el_mean[j]),
                              "deflection_elastica_ci_m": [float(el_lo[j]), float(el_hi[j])]})
        curves.append({"phi": phi, "E_Pa": E, "E_from_table": E_est is not None,
                       "B_T": B_fine, "f_mean_N_m3": f_mean, "f_ci_low_N_m3": f_lo,
                       "f_ci_high_N_m3": f_hi, "deflection_eb_m": eb_mean,
                       "deflection_elastica_m": el_mean, "deflection_ci_low_m": el_lo,
                       "deflection_ci_high_m": el_hi, "B_for_4mm_T": B4, "grid": grid_rows})
    res = {"seed": SEED, "strip": strip, "gradB_T_per_m": g, "confidence": table.confidence,
           "realizations": study.realizations, "n_particles": study.n_particles,
           "fixed_axes": others, "curves": curves, "table": str(table_path),
           "manifest": manifest(study.config(), study.seed)}
    write_json(out_dir / "chain.json", res)
    _plot(out_dir / "deflection_vs_B.png", res)
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


def _plot(path: Path, res: dict) -> None:
    from matplotlib.figure import Figure
    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    ax = fig.add_subplot()
    for c in res["curves"]:
        B = np.asarray(c["B_T"])
        line, = ax.plot(B, 1e3 * np.asarray(c["deflection_elastica_m"]), "-",
                        label=f"phi = {c['phi']:g}: elastica, {100 * res['confidence']:g} % band")
        ax.fill_between(B, 1e3 * np.asarray(c["deflection_ci_low_m"]),
                        1e3 * np.asarray(c["deflection_ci_high_m"]), color=line.get_color(),
                        alpha=0.25, lw=0)
        ax.plot(B, 1e3 * np.asarray(c["deflection_eb_m"]), ":", color=line.get_color(),
                label=f"phi = {c['phi']:g}: Euler-Bernoulli")
        ax.plot([g["B_T"] for g in c["grid"]], [1e3 * g["deflection_elastica_m"] for g in c["grid"]],
                "o", ms=3, color=line.get_color())
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
                 f"dB/dz = {res['gradB_T_per_m']} T/m", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(True, which="both", alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


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
    lines = [
        "# The chain: random RVEs -> body force -> the seed paper's cantilever", "",
        f"Study `{_display_path(study.path)}` ({study.name}): {study.n_points} grid points x "
        f"{study.realizations} random RVEs of {study.n_particles} particles, seed {study.seed}, "
        f"evaluator `{study.evaluator}`, FEM {'on' if study.fem else 'off'}; fixed axes "
        f"{res['fixed_axes'] or 'none'}. Table: `{Path(res['table']).name}` "
        f"(mean, sd, n, {lvl} Student-t interval per grid point; open with xarray).", "",
        "Seed paper: body force N F_g / V = 43.79 kN/m^3 from c = 3.5 vol% powder with a "
        "guessed packing density d = 0.5 and saturated particles; measured tip deflection "
        "4 mm at dB/dz = 1.78 T/m (reproduced with 40 kN/m^3 in Abaqus, 50 kN/m^3 in Elmer). "
        "Neither the strip's dimensions nor B at the strip are given.", "",
        f"Strip used: E = {s['E_Pa'] / 1e6:g} MPa (PDMS{'' if not any(c['E_from_table'] for c in res['curves']) else ', or E_eff from the table'}), "
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
                  f"Field needed for the measured 4 mm (elastica): {_fmt_B(b4['mean'])}"
                  + ("" if b4["mean"] is None else
                     f" (from the interval of the force: {_fmt_B(b4['high_force'])} to "
                     f"{_fmt_B(b4['low_force'])})")
                  + f". At the largest field of the table, "
                  f"B = {top['B_T']:g} T, the tip deflection is "
                  f"{1e3 * top['deflection_elastica_m']:.2f} mm and the body force "
                  f"{top['f_eff_N_m3'] / 1e3:.1f} kN/m^3 "
                  f"({100 * top['f_eff_N_m3'] / (c['phi'] * 7870 * 178 * res['gradB_T_per_m']):.0f} % "
                  f"of the saturated value phi rho sigma_s dB/dz).", "",
                  f"| B [T] | f_eff [kN/m^3] | {lvl} interval | d_eff | EB [mm] | "
                  f"elastica [mm] | {lvl} interval [mm] |",
                  "|---:|---:|---:|---:|---:|---:|---:|"]
        for g in c["grid"]:
            d = "-" if g["d_eff_mean"] is None else f"{g['d_eff_mean']:.3f}"
            lines.append(
                f"| {g['B_T']:g} | {g['f_eff_N_m3'] / 1e3:.3f} | "
                f"[{g['f_ci_N_m3'][0] / 1e3:.3f}, {g['f_ci_N_m3'][1] / 1e3:.3f}] | {d} | "
                f"{1e3 * g['deflection_eb_m']:.3f} | {1e3 * g['deflection_elastica_m']:.3f} | "
                f"[{1e3 * g['deflection_elastica_ci_m'][0]:.3f}, "
                f"{1e3 * g['deflection_elastica_ci_m'][1]:.3f}] |")
        lines.append("")
    lines += [
        "d_eff is the packing density the seed's formula would have needed (with saturated "
        "particles) to give the computed force: the seed's d = 0.5 stands for the combined "
        "effect of packing and incomplete magnetization.", "",
        "Limits: the interval is the statistical one of the random RVEs (interpolation in B "
        "between grid points and model error are not included); the matrix modulus is the "
        "PDMS value unless the study ran the FEM step; the gradient is taken uniform "
        "(1.78 T/m) whatever B.", "",
        "Files: `table.h5` (+ `table.manifest.json`), `chain.json` (all numbers), "
        "`deflection_vs_B.png`.", ""]
    return "\n".join(lines)
