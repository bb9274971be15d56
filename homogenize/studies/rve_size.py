"""Representative volume: variance of an output against RVE volume (Kanit et al., 2003).

For each RVE size of the study's ``[rve_size]`` table, a batch of realizations is run at every
grid point; the sample variance of the chosen output is fitted by the power law
``D^2(V) = D^2_ref (V_ref / V)^alpha`` and, for each size, the number of realizations needed for
the target relative precision of the mean (Student-t half-width / |mean|) is reported, measured
(from that size's own sd) and from the fit.
"""
from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np

from micro.common.files import atomic_path, manifest, write_json
from micro.common.validate import InputError

from homogenize.tables._stats import fit_power_law, realizations_needed
from homogenize.tables._study import Study, load_study
from homogenize.tables.batch import dask_client, read_table, run_batch
from micro.common.files import atomic_write_text
import textwrap
from scipy import stats

__all__ = ["rve_size_study", "restrict_grid"]


def restrict_grid(study: Study, at: str | None) -> Study:
    """The study with some grid axes fixed to one of their values (``"phi=0.035,B_T=0.1"``)."""
    if not at:
        return study
    axes = dict(study.axes)
    for item in at.split(","):
        if "=" not in item:
            raise InputError(f"--at {at!r}: expected axis=value pairs separated by commas")
        a, v = (x.strip() for x in item.split("=", 1))
        if a not in axes:
            raise InputError(f"--at {at!r}: unknown axis {a!r}; axes: {', '.join(axes)}")
        hits = [g for g in axes[a] if (g == v if isinstance(g, str) else
                                       _isclose_text(g, v))]
        if not hits:
            raise InputError(f"--at {at!r}: {a} = {v} is not a grid value; values: "
                             f"{list(axes[a])}")
        axes[a] = (hits[0],)
    return study.replace(axes=tuple((a, axes[a]) for a, _ in study.axes))


def _isclose_text(g, v: str) -> bool:
    try:
        return math.isclose(float(v), g, rel_tol=1e-9)
    except ValueError:
        return False


def check_quantity(quantity: str, component: str | None) -> str:
    """The full name of ``quantity`` (a name or unique prefix of a table quantity), refusing
    an unknown one or a ``component`` its shape does not have (x, y, z or norm for vectors,
    xx..zz for tensors), before anything is computed."""
    from homogenize.tables._evaluate import QUANTITIES
    hits = [q for q in QUANTITIES if q == quantity or q.startswith(f"{quantity}_")]
    if quantity in QUANTITIES:
        hits = [quantity]
    if len(hits) != 1:
        raise InputError(f"quantity {quantity!r} must be one of (or a unique prefix of) "
                         f"{', '.join(QUANTITIES)}")
    q = hits[0]
    nd = len(QUANTITIES[q][1])
    if component not in (None, "") and nd:
        ok = (component == "norm" and nd == 1) or (
            len(component) == nd and all(c in "xyz" for c in component))
        if not ok:
            allowed = "x, y, z, norm" if nd == 1 else "xx, xy, ..., zz"
            raise InputError(f"component {component!r} of {q}: allowed {allowed}")
    return q


def rve_size_study(study, out_dir, *, evaluator=None, workers=None, scheduler=None,
                   processes=True, client=None, progress=True, quantity=None, component=None,
                   target=None, at: str | None = None) -> dict:
    """Run the ``[rve_size]`` batches of ``study`` into ``out_dir`` and analyse them.

    Returns a dict (also written as ``out_dir/rve_size.json``, with ``rve_size.md`` and the plot
    ``rve_size.png``): per grid point and size the mean volume, mean, sd, the realizations
    needed, and the fitted exponent alpha with its standard error.
    """
    if not isinstance(study, Study):
        study = load_study(study)
    spec = study.rve_size
    if spec is None:
        raise InputError(f"{study.path}: missing table [rve_size] (n_particles = [...], "
                         f"realizations, quantity, component, target_rel_precision)")
    study = restrict_grid(study, at)
    quantity = quantity or spec.quantity
    component = spec.component if component is None else component
    target = spec.target_rel_precision if target is None else target
    check_quantity(quantity, component)      # before any table is computed or written
    out_dir = Path(out_dir)
    tables = {}
    with contextlib.ExitStack() as stack:
        cl = client if client is not None else stack.enter_context(
            dask_client(scheduler, workers, processes))    # one cluster for all sizes
        for n in spec.n_particles:
            sub = study.replace(n_particles=n, realizations=spec.realizations)
            path = out_dir / f"rve_size_n{n}.h5"
            run_batch(sub, path, evaluator=evaluator, client=cl, progress=progress, clean=True)
            tables[n] = read_table(path)
    first = tables[spec.n_particles[0]]
    q = first.resolve_quantity(quantity)
    rows = []
    for p, point in enumerate(first.points):
        sizes = []
        for n, t in tables.items():
            x = t.component_values(q, component)[p]
            V = float(t.values["volume_m3"][p].mean())
            mean, sd = float(x.mean()), float(x.std(ddof=1))
            if mean == 0:
                raise InputError(f"{q} ({component}) has zero mean at grid point {p}: its "
                                 f"relative precision is undefined; choose another component")
            sizes.append({"n_particles": n, "volume_m3": V, "mean": mean, "sd": sd,
                          "rel_sd": sd / abs(mean),
                          "realizations_needed": realizations_needed(sd, mean, target,
                                                                     study.confidence)})
        V = [s["volume_m3"] for s in sizes]
        var = [s["sd"] ** 2 for s in sizes]
        fit = fit_power_law(V, var)
        for s in sizes:
            sd_fit = math.sqrt(float(fit.variance(s["volume_m3"])))
            s["realizations_needed_fit"] = realizations_needed(sd_fit, s["mean"], target,
                                                               study.confidence)
        rows.append({"point": point, "sizes": sizes, "alpha": fit.alpha,
                     "alpha_se": fit.alpha_se, "V_ref_m3": fit.V_ref_m3,
                     "variance_ref": fit.variance_ref})
    result = {"quantity": q, "component": component, "unit": first.units[q],
              "target_rel_precision": target, "confidence": study.confidence,
              "realizations_per_size": spec.realizations, "points": rows,
              "manifest": manifest(study.config(), study.seed)}
    write_json(out_dir / "rve_size.json", result)
    _write_markdown(out_dir / "rve_size.md", result)
    _plot(out_dir / "rve_size.png", result)
    return result


def _write_markdown(path: Path, res: dict) -> None:
    lines = [f"# RVE size: {res['quantity']} ({res['component']}) [{res['unit']}]", "",
             f"Realizations needed for a {100 * res['confidence']:g} % interval of half-width "
             f"{100 * res['target_rel_precision']:g} % of the mean (Student t), measured at "
             f"each size and from the power-law fit var ~ V^-alpha (Kanit et al. 2003).", ""]
    for row in res["points"]:
        pt = ", ".join(f"{k} = {v}" for k, v in row["point"].items())
        lines += [f"## {pt}", "",
                  f"alpha = {row['alpha']:.3f} +/- {row['alpha_se']:.3f} "
                  f"(1 = independent sub-volumes)", "",
                  "| particles | volume [m^3] | mean | sd | rel. sd | needed | needed (fit) |",
                  "|---:|---:|---:|---:|---:|---:|---:|"]
        for s in row["sizes"]:
            lines.append(f"| {s['n_particles']} | {s['volume_m3']:.3e} | {s['mean']:.5g} | "
                         f"{s['sd']:.3g} | {s['rel_sd']:.3g} | {s['realizations_needed']} | "
                         f"{s['realizations_needed_fit']} |")
        lines.append("")
    text = "\n".join(lines) + "\n"
    atomic_write_text(path, text)


def _plot(path: Path, res: dict) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter
    fig = Figure(figsize=(6.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    pts = [row["point"] for row in res["points"]]
    varying = [a for a in pts[0] if len({p[a] for p in pts}) > 1]
    R = res["realizations_per_size"]
    # 95 % interval of a sample variance of R normal realizations (chi-square)
    lo_f = (R - 1) / stats.chi2.ppf(0.975, R - 1)
    hi_f = (R - 1) / stats.chi2.ppf(0.025, R - 1)
    for row in res["points"]:
        V = np.array([s["volume_m3"] for s in row["sizes"]])
        var = np.array([s["sd"] ** 2 for s in row["sizes"]])
        label = ", ".join(f"{a}={row['point'][a]}" for a in varying)
        label = (label + ": " if label else "") + f"alpha = {row['alpha']:.2f} +/- {row['alpha_se']:.2f}"
        bars = ax.errorbar(V, var, yerr=[var * (1 - lo_f), var * (hi_f - 1)], fmt="o",
                           capsize=3, label=label)
        Vf = np.geomspace(V.min(), V.max(), 50)
        ax.plot(Vf, row["variance_ref"] * (row["V_ref_m3"] / Vf) ** row["alpha"], "-",
                color=bars[0].get_color())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("RVE volume V [m$^3$]")
    ax.set_ylabel(f"variance of {res['quantity']} ({res['component']}) [({res['unit']})$^2$]")
    fixed = ", ".join(f"{a}={v}" for a, v in pts[0].items() if a not in varying)
    ax.set_title(f"Variance across {R} realizations vs RVE volume (Kanit et al. 2003)\n"
                 + "\n".join(textwrap.wrap(fixed, 90)), fontsize=8)
    ax.legend(fontsize=7, title="fit var ~ V$^{-alpha}$; bars: 95 % interval", title_fontsize=7)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
