"""Human report of a diagnosis: Markdown plus PNG plots (data, seed and extended model,
held-out residuals against every covariate before and after)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from micro.common.files import atomic_path, atomic_write_text

from homogenize.experiments.causes import DESCRIPTIONS
from homogenize.experiments.diagnose import Diagnosis, covariates, residual_correlations

__all__ = ["write_report", "UNITS", "X_AXIS"]

UNITS = {"deflection": "m", "magnetization": "A/m", "magnetostriction": "-", "tensile": "Pa"}
X_AXIS = {"deflection": ("gradB_T_per_m", "dB/dz [T/m]"), "magnetization": ("H_A_per_m", "H [A/m]"),
          "magnetostriction": ("B_T", "mu0 H [T]"), "tensile": ("strain", "engineering strain [-]")}


#: axis labels of the columns and covariates: quantity name and unit, never a raw column name
LABELS = {"deflection_m": "tip deflection [m]", "stress_Pa": "nominal tensile stress [Pa]",
          "M_A_per_m": "magnetization M [A/m]", "strain_mag": "magnetostrictive strain [-]",
          "B_T": "applied flux density mu0 H [T]", "gradB_T_per_m": "field gradient dB/dz [T/m]",
          "phi": "particle volume fraction phi [-]", "length_m": "strip length [m]",
          "width_m": "strip width [m]", "thickness_m": "strip thickness [m]",
          "radius_mean_m": "mean particle radius [m]", "H_A_per_m": "applied field H [A/m]",
          "aspect_ratio": "specimen aspect ratio [-]", "strain": "engineering strain [-]",
          "deflection/length": "tip deflection / length [-]",
          "L^4/t^2 [m^2]": "L^4 / t^2 [m^2]", "branch (down=1)": "branch (0 rising, 1 falling)",
          "prediction": "prediction"}


def _label(name: str, unit: str | None = None) -> str:
    """A readable axis label with its unit for a column or covariate name."""
    if name in LABELS:
        return LABELS[name]
    return f"{name.replace('_', ' ')}" + (f" [{unit}]" if unit else "")


def _fmt(v):
    if isinstance(v, str):
        return v
    if v == 0 or not math.isfinite(v):
        return f"{v}"
    return f"{v:.4g}"


def _params_table(params: dict) -> str:
    names = [k for k in params if not k.endswith("_sd")]
    if not names:
        return "(no fitted parameter)"
    rows = ["| parameter | value | standard error |", "|---|---|---|"]
    for k in names:
        sd = params.get(k + "_sd")
        rows.append(f"| `{k}` | {_fmt(params[k])} | {_fmt(sd) if sd is not None else '-'} |")
    return "\n".join(rows)


def _plot_single_point(d: Diagnosis, path: Path):
    """One measured point: what it can show is the measurement against each model's value."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    exp = d.exp
    unit = UNITS[exp.kind]
    vals = [("measured", float(exp.y[0]), "k")]
    vals.append(("seed model", float(d.baseline.fit.prediction[0]), "C3"))
    for c in d.rounds[0] if d.rounds else ():
        vals.append((f"+ {c.cause.replace('_', ' ')}", float(c.cv_pred[0]), "C0"))
    fig = Figure(figsize=(7.5, 0.45 * len(vals) + 1.4))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    y = np.arange(len(vals))[::-1]
    ax.barh(y, [v for _, v, _c in vals], color=[c for _n, _v, c in vals], height=0.6)
    ax.set_yticks(y, [n for n, _v, _c in vals], fontsize=8)
    ax.axvline(vals[0][1], color="k", lw=0.8, ls="--")
    ax.set_xlabel(_label(exp.measured_name, unit))
    ax.set_title("one measured point: the measurement and what each model predicts for it "
                 "(nothing fitted)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def _plot_data(d: Diagnosis, path: Path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    exp = d.exp
    if exp.n_rows == 1:
        return _plot_single_point(d, path)
    xname, xlabel = X_AXIS[exp.kind]
    x = exp.columns[xname]
    fig = Figure(figsize=(11, 4.5))
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(1, 2)
    groups = exp.groups
    colors = [f"C{i % 10}" for i in range(int(groups.max()) + 1)]
    for g in range(int(groups.max()) + 1):
        for down in (False, True):
            m = (groups == g) & (exp.down == down)
            if not m.any():
                continue
            o = np.argsort(x[m])
            lab = f"{exp.specimen[m][0]}{' down' if down else ''}"
            ax1.plot(x[m][o], exp.y[m][o], "o", color=colors[g], ms=4, mfc="none" if down else None,
                     label=lab if g < 8 else None)
            ax1.plot(x[m][o], d.baseline.fit.prediction[m][o], ":", color=colors[g], lw=1)
            ax1.plot(x[m][o], d.final.fit.prediction[m][o], "-", color=colors[g], lw=1.2)
    ms = d.microstructure
    title = "data (o), seed model (dotted), extended model (solid)"
    if ms and ms.get("available") and "rows" in ms and int(groups.max()) < 8:
        up = ~exp.down
        o = np.argsort(x[up])
        ax1.plot(x[up][o], np.asarray(ms["rows"]["predicted_coupled_rve"])[up][o], "--",
                 color="k", lw=1, label="coupled RVE, no fitted stress")
        title += ",\ncoupled RVE (particles move) without kappa_extra (dashed)"
    ax1.set_xlabel(xlabel)
    ax1.set_ylabel(_label(exp.measured_name, UNITS[exp.kind]))
    ax1.set_title(title, fontsize=9)
    if int(groups.max()) < 8:
        ax1.legend(fontsize=7)
    lo = float(min(exp.y.min(), d.baseline.cv_pred.min(), d.final.cv_pred.min()))
    hi = float(max(exp.y.max(), d.baseline.cv_pred.max(), d.final.cv_pred.max()))
    ax2.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax2.plot(exp.y, d.baseline.cv_pred, "s", ms=4, mfc="none", color="C3",
             label=f"seed (cv_rmse {d.baseline.cv_rmse:.3g})")
    ax2.plot(exp.y, d.final.cv_pred, "o", ms=4, color="C0",
             label=f"extended (cv_rmse {d.final.cv_rmse:.3g})")
    ax2.set_xlabel(f"measured {_label(exp.measured_name, UNITS[exp.kind])}")
    ax2.set_ylabel(f"held-out prediction [{UNITS[exp.kind]}]")
    ax2.legend(fontsize=8)
    ax2.set_title("held-out predictions against data", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def _plot_residuals(d: Diagnosis, path: Path):
    from matplotlib.figure import Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    exp = d.exp
    cov = {k: v for k, v in covariates(exp).items() if np.unique(v).size >= 2}
    if not cov:
        cov = {"row": np.arange(exp.n_rows, dtype=float)}
    n = len(cov)
    ncol = min(3, n)
    nrow = int(math.ceil(n / ncol))
    fig = Figure(figsize=(4 * ncol, 3.2 * nrow))
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(nrow, ncol)).ravel()
    r0 = d.baseline.cv_pred - exp.y
    r1 = d.final.cv_pred - exp.y
    for ax, (name, v) in zip(axes, cov.items()):
        ax.axhline(0, color="k", lw=0.6)
        ax.plot(v, r0, "s", ms=3.5, mfc="none", color="C3", label="seed")
        ax.plot(v, r1, "o", ms=3.5, color="C0", label="extended")
        ax.set_xlabel(_label(name))
        ax.set_ylabel(f"held-out residual [{UNITS[exp.kind]}]", fontsize=8)
    axes[0].legend(fontsize=8)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def write_report(d: Diagnosis, out_dir, *, discussion: str | None = None) -> Path:
    """Write ``report.md``, ``data.png`` and ``residuals.png`` into ``out_dir``; returns the
    Markdown path. ``discussion`` (Markdown) is inserted verbatim as its own section."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    exp = d.exp
    res = d.as_dict()
    _plot_data(d, out / "data.png")
    single = exp.n_rows == 1
    if single:                 # a residual plot of one point says nothing: none is drawn
        (out / "residuals.png").unlink(missing_ok=True)
    else:
        _plot_residuals(d, out / "residuals.png")
    unit = UNITS[exp.kind]
    lines = [f"# Diagnosis: {exp.title or exp.kind}", ""]
    src = f"`{Path(exp.toml_path).name}`" if exp.toml_path else "in-memory experiment"
    n_spec = int(exp.groups.max()) + 1
    lines += [f"Experiment {src}: kind **{exp.kind}**, {exp.n_rows} rows, {n_spec} specimen(s); "
              f"measured column `{exp.measured_name}` [{unit}].", ""]
    if d.folds is None:
        lines += ["Too few rows to hold any out: the 'held-out' prediction is the a priori model "
                  "(scale 1, the file's E, nothing fitted), and no cause can be accepted.", ""]
    elif n_spec >= 3:
        lines += [f"Cross-validation: {len(d.folds)} folds of whole specimens.", ""]
    else:
        lines += [f"Cross-validation: {len(d.folds)} random folds of rows (fewer than 3 "
                  "specimens).", ""]
    lines += ["## Verdict", ""]
    if res["causes"]:
        lines += ["The seed model misses: " + "; then ".join(
            f"**{c}** ({DESCRIPTIONS[c]})" for c in res["causes"]) + ".", "",
            f"Held-out RMSE: seed {res['baseline']['cv_rmse']:.4g} {unit} -> extended "
            f"{res['final']['cv_rmse']:.4g} {unit}; gain **{res['gain']:.3g}**.", ""]
    elif d.folds is None:
        lines += ["With this few rows no cause can be tested: the table of candidates below only "
                  "shows how the parameter-free extensions would move the a priori prediction "
                  f"(seed model: error {res['baseline']['cv_rmse']:.4g} {unit}).", ""]
    else:
        lines += ["No extension lowers the held-out error significantly: the seed model explains "
                  f"these data within what they can tell (held-out RMSE "
                  f"{res['baseline']['cv_rmse']:.4g} {unit}).", ""]
    lines += ["Acceptance criterion: a candidate must lower the cross-validated RMSE by "
              "at least 10 % AND a one-sided Wilcoxon signed-rank test on the paired held-out "
              "squared errors must give p < 0.01; the passing candidate with the lowest error is accepted, and pairs of the three best candidates are tried when no single one passes.", ""]
    lines += ["## Seed model", "", f"Held-out RMSE {res['baseline']['cv_rmse']:.4g} {unit}.", "",
              _params_table(res["baseline"]["params"]), ""]
    for i, s in enumerate(res["steps"]):
        lines += [f"## Step {i + 1}: {s['cause']}", "", DESCRIPTIONS[s["cause"]] + ".", "",
                  f"Evidence: {s['evidence']}.", "", "Parameters this step added (standard errors from the Jacobian at the optimum):", "",
                  _params_table(s["params"]), ""]
    lines += ["## Candidates tried", ""]
    for r, tried in enumerate(d.rounds):
        base = d.round_bases[r] if r < len(d.round_bases) else "?"
        lines += [f"Round {r + 1} (on top of: {base}):", "",
                  "| cause | cv_rmse | forms tried |", "|---|---|---|"]
        for c in sorted(tried, key=lambda c: c.cv_rmse):
            forms = ", ".join(f"{k}: {v:.3g}" for k, v in c.variants.items()) or "-"
            lines.append(f"| {c.cause} | {c.cv_rmse:.4g} | {forms} |")
        lines.append("")
    if d.skipped:
        lines += ["Not tried (the data cannot show them, or the physics is not available):", ""]
        lines += [f"- `{c}`: {why}" for c, why in d.skipped.items()]
        lines.append("")
    lines += ["## Final model", "", f"Held-out RMSE {res['final']['cv_rmse']:.4g} {unit}.", "",
              _params_table(res["final"]["params"]), ""]
    if any(k.endswith("_predicted") for k in res["final"]["params"]):
        lines += ["Entries ending in `_predicted` are not fitted: they are the project's physics "
                  "at the final fit (row means), shown next to the fitted parameters.", ""]
    lines += _microstructure_section(d.microstructure)
    if d.specimen is not None and d.specimen.get("available"):
        _plot_specimen(d, out / "specimen.png")
        lines += _specimen_section(d.specimen)
    else:
        (out / "specimen.png").unlink(missing_ok=True)
    c0 = residual_correlations(exp, d.baseline.cv_pred - exp.y)
    c1 = residual_correlations(exp, d.final.cv_pred - exp.y)
    if c0:
        lines += ["## Residuals against covariates (Spearman rank correlation of held-out "
                  "residuals)", "", "| covariate | seed | extended |", "|---|---|---|"]
        for k in c0:
            lines.append(f"| {k} | {c0[k]:+.2f} | {c1.get(k, float('nan')):+.2f} |")
        lines.append("")
    if single:
        lines += ["![the measured point and each model's prediction](data.png)", "",
                  "(One point: no residual plot; residuals against covariates need several "
                  "rows.)", ""]
    else:
        lines += ["![data, seed and extended model](data.png)", "",
                  "![held-out residuals against every covariate](residuals.png)", ""]
    if discussion:
        lines += ["## Discussion", "", discussion.strip(), ""]
    md = out / "report.md"
    atomic_write_text(md, "\n".join(lines))
    return md


def _microstructure_section(ms: dict | None) -> list:
    """The coupled RVE's account of a magnetostriction experiment (``microstructure_evolution``)."""
    if ms is None:
        return []
    lines = ["## Particles that move: the coupled RVE (`microstructure_evolution`)", ""]
    if not ms.get("available"):
        return lines + [f"Not evaluated: {ms.get('why')}", ""]
    p = ms["relax_table"]
    at = ms["at"]
    cv = ms["cv_rmse"]
    lo, hi = ms["predicted_coupled_rve_ci95"]
    lines += [
        f"Coupled RVE from `{p['table']}` (study `{p['study']}`, evaluator `{p['evaluator']}`, "
        f"{p['realizations']} random RVEs of {p['n_particles']} particles, {p['voxels']}^3 "
        f"voxels; made by `mapsim batch {p['study_toml']}`).", "",
        f"At B = {at['B_T']:.3g} T ({at['branch']} branch), phi = {at['phi']:g}, with NO "
        f"fitted stress (no `kappa_extra`); magnetization of the final model "
        f"(`{ms['magnetization_model']}`, "
        + ", ".join(f"{k} = {v:.4g}" for k, v in ms["magnetization_params"].items()) + "):",
        "",
        "| | axial strain | over mu0 M^2 / E |", "|---|---|---|",
        f"| measured | {ms['measured']:.4g} | {ms['kappa_measured']:.4g} |",
        f"| affine prediction (particles fixed) | {ms['predicted_affine']:.3g} | "
        f"{ms['kappa_affine']:.4g} |",
        f"| coupled RVE prediction (particles move) | {ms['predicted_coupled_rve']:.3g} "
        f"(95 % interval over RVEs [{lo:.3g}, {hi:.3g}]) | {ms['kappa_coupled_rve']:.4g} |",
        f"| of which restructuring (relaxed - affine) | {ms['restructuring_strain']:.3g} | |",
        "",
        f"The coupled RVE explains {100 * ms['fraction_explained']:.2g} % of the measured "
        f"strain; unexplained: {ms['unexplained']:.4g}.", "",
        "Held-out RMSE (same folds):", "",
        "| model | cv_rmse | fitted |", "|---|---|---|",
        f"| seed (no strain) | {cv['seed']:.4g} | - |",
        f"| coupled RVE, no fitted stress | {cv['coupled_rve_no_fitted_stress']:.4g} | "
        f"(M law only) |",
        f"| affine dipoles + fitted kappa_extra | "
        f"{cv['dipolar_interaction_kappa_extra_fitted']:.4g} | kappa_extra |",
        f"| coupled RVE + fitted kappa_extra | "
        f"{cv['dipolar_plus_coupled_rve_kappa_extra_fitted']:.4g} | kappa_extra = "
        f"{ms['kappa_extra_fitted_with_coupled_rve']:.4g} +- "
        f"{ms['kappa_extra_fitted_with_coupled_rve_sd']:.2g} |",
        f"| affine dipoles + fitted kappa_extra + fitted restructuring c x | "
        f"{cv['dipolar_plus_fitted_restructuring']:.4g} | kappa_extra, c_restructure = "
        f"{ms['c_restructure_fitted']:.4g} +- {ms['c_restructure_fitted_sd']:.2g} |", "",
        f"Held-out gain of the coupled RVE: {ms['gain_coupled_rve_over_seed']:.4g} over the "
        f"seed with no fitted stress (the fitted kappa_extra alone: "
        f"{ms['gain_fitted_kappa_extra_over_seed']:.4g}), "
        f"{ms['gain_coupled_rve_on_top_of_dipolar']:.4g} on top of "
        f"the fitted kappa_extra. `microstructure_evolution` "
        + ("was accepted in the selection (form "
           f"`{ms['accepted_form']}`{', a FITTED constant' if ms['accepted_form'] == 'fitted' else ''})."
           if ms["accepted"] else "was not accepted in the selection."), ""]
    return lines


_MODEL_TEXT = {"continuum": "continuum (Kelvin loads only, no microstructural stress)",
               "affine": "affine (plus the particles' interaction stress, particles fixed)",
               "relaxed": "relaxed (plus what particles that move add: relax table)"}


def _specimen_section(sp: dict) -> list:
    """The specimen solver's account: the measured change of length predicted, three models."""
    lines = ["## The specimen predicted as measured: change of length, nothing fitted", "",
             "Specimen solver (`homogenize.macro.specimen`): the field in and around the "
             "deforming cylinder, Kelvin tractions and magnetic pressure, a finite-strain "
             "nearly incompressible neo-Hookean body; measured quantity: "
             f"{sp['measured_quantity']}. Nothing fitted: {sp['nothing_fitted']}.", ""]
    for g in sp["groups"]:
        lo, hi = g["composite_E_Pa_ci95"]
        lines += [f"- L/D = {g['aspect_ratio_L_over_D']:g}, phi = {g['phi']:g} "
                  f"({g['rows']} rows): matrix E = {g['matrix_E_Pa'] / 1e6:.4g} MPa (the "
                  f"TOML's), filler stiffening {g['filler_stiffness_ratio']:.3f} +- "
                  f"{g['filler_stiffness_ratio_se']:.3f} (cell FEM) -> composite E = "
                  f"{g['composite_E_Pa'] / 1e6:.4g} MPa (95 %: [{lo / 1e6:.4g}, "
                  f"{hi / 1e6:.4g}]); M(H_in) of {g['composite_law']['realizations']} random "
                  f"RVEs of {g['composite_law']['n_particles']} particles (initial "
                  f"susceptibility {g['composite_law']['chi_initial']:.3g}); mesh "
                  f"{g['specimen']['mesh']}."]
        rt = g["relax_table"]
        if isinstance(rt, dict) and rt.get("available") is False:
            lines.append(f"  Relaxed model not evaluated: {rt['why']}")
        elif rt:
            lines.append(f"  Relax table `{rt.get('table')}` ({rt.get('realizations')} RVEs of "
                         f"{rt.get('n_particles')} particles, {rt.get('voxels')}^3 voxels).")
            stf = rt.get("stiffening")
            if stf:
                lo_s, hi_s = stf["E_parallel_ratio_range_at_last_step"]
                lines.append(f"  The relaxed RVEs are {stf['E_parallel_ratio_mean'][-1]:.3g}x "
                             f"({lo_s:.3g}-{hi_s:.3g}x) stiffer along the field at "
                             f"{stf['B_T'][-1]:.3g} T than at zero field; the relaxed specimen "
                             f"model keeps the zero-field composite modulus, so it "
                             f"overestimates the elongation.")
        for m, r in g["models"].items():
            if r.get("available") and r.get("failed"):
                lines.append(f"  {m}: stopped after B = "
                             f"{(r['B_applied_T'] or [0.0])[-1]:.3g} T: {r['failed']}")
    lines += ["", "| model | at B [T] | measured | predicted (end faces' mean) | 95 % "
              "(modulus, linearized) | on the axis | mean strain | share explained | RMSE, "
              "nothing fitted | kappa_extra still FITTED | held-out RMSE with it | held-out "
              "gain over the diagnosis |", "|---|---:|---:|---:|---|---:|---:|---:|---:|---|"
              "---:|---:|"]
    for m, r in sp["models"].items():
        if not r.get("available"):
            lines.append(f"| {m} | - | - | not evaluated: {r.get('why', '')[:80]} | | | | | | "
                         f"| | |")
            continue
        f = r.get("fitted", {})
        lo, hi = r["predicted_end_mean_ci95_modulus_linearized"]
        kx = (f"{f['kappa_extra']:.3g} +- {f['kappa_extra_se']:.2g}" if f else "-")
        gain = r.get("heldout_gain_with_fitted_kappa")
        lines.append(
            f"| {_MODEL_TEXT[m]} | {r['at']['B_T']:.3g} | {r['measured']:.4g} | "
            f"{r['predicted_end_mean']:.4g} | [{lo:.4g}, {hi:.4g}] | {r['predicted_axis']:.4g} "
            f"| {r['predicted_mean_strain']:.4g} | {100 * r['fraction_explained']:.3g} % | "
            f"{r['rmse_nothing_fitted']:.4g} | {kx} | "
            f"{f.get('heldout_rmse', math.nan):.4g} | "
            f"{'-' if gain is None else f'{gain:.3g}'} |")
    rs = sp["models"].get("relaxed", {}).get("with_relaxed_stiffening_linearized")
    if rs:
        lines += ["", f"Relaxed model with the relaxed RVEs' stiffening carried into the body by "
                      f"linear scaling (an estimate, not a solve): E x "
                      f"{rs['E_parallel_ratio']:.3g} gives {rs['predicted_end_mean']:.4g} "
                      f"({100 * rs['fraction_explained']:.3g} % of the measured change of "
                      f"length)."]
    lines += ["", "The held-out gain compares the diagnosis's final model (mean strain, its own "
              "fitted parameters) with the specimen prediction plus one fitted kappa_extra "
              "(leave-one-out), on the same rows. Model error: "
              + "; ".join(sp["model_error"]) + ".", "",
              "![the specimen's predicted change of length against the measured one]"
              "(specimen.png)", ""]
    return lines


def _plot_specimen(d: Diagnosis, path: Path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    exp, sp = d.exp, d.specimen
    fig = Figure(figsize=(7.5, 4.8))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    B = np.asarray(exp.columns["B_T"], float)
    for down, mk, lab in ((False, "o", "measured, rising field"),
                          (True, "^", "measured, falling field")):
        m = exp.down == down
        if m.any():
            ax.plot(B[m], 100 * exp.y[m], mk, color="k", mfc="none", label=lab)
    colors = {"continuum": "C3", "affine": "C0", "relaxed": "C2"}
    for g in sp["groups"]:
        for m, r in g["models"].items():
            if not r.get("available") or not r["B_applied_T"]:
                continue
            Bs = [0.0] + list(r["B_applied_T"])
            lab = f"{m}" + (f", L/D {g['aspect_ratio_L_over_D']:g}" if len(sp["groups"]) > 1
                            else "")
            ax.plot(Bs, [0.0] + [100 * v for v in r["strain_end_mean"]], "-",
                    color=colors[m], label=f"{lab}: end faces' mean")
            ax.plot(Bs, [0.0] + [100 * v for v in r["strain_axis"]], "--", color=colors[m],
                    lw=0.9, label=f"{lab}: on the axis")
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.set_xlabel("applied field mu0 H0 [T]")
    ax.set_ylabel("axial strain: change of length / length [%]")
    ax.set_title("specimen solver, nothing fitted, against the measured change of length",
                 fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
