"""Commands ``mapsim batch``, ``mapsim rve-size``, ``mapsim compare`` and ``mapsim chain``."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from micro.common.files import manifest, write_json
from micro.common.validate import InputError
from micro.materials import FE, PDMS, matrix_preset

from homogenize.cli._common import (config_of, float_in, int_in, one_line_errors, parse_at,
                                    scheduler_address, write_snippet)
from homogenize.macro.cantilever import Strip
from homogenize.macro.effective import beam_with_interval, effective_material_from_table
from homogenize.macro.exporters import ExportSpec, export_text
from homogenize.tables.batch import read_table
from homogenize.tables.batch import BatchError, run_batch
from homogenize.tables._study import load_study
from homogenize.tables._evaluate import COARSE, get_evaluator
from homogenize.tables._stats import summarize
from homogenize.studies.rve_size import rve_size_study
from homogenize.tables._stats import welch_permutation
from homogenize.studies.chain import run_chain

_BATCH_DOC = """\
Run a study (TOML file: grid of conditions x random realizations) on Dask and write the
effective-parameter table (HDF5; open with xarray.open_dataset(path, engine="h5netcdf")).

Each realization is stored as soon as it finishes in <out stem>.parts/; running the same
command again after an interruption (Ctrl-C, killed workers) resumes without recomputing.
The table is identical whatever the number of workers. Exit codes: 0 done, 1 some
realizations failed (the others are kept), 2 bad input, 130 interrupted.

Evaluators ([study] evaluator): "rve" (particles -> dipoles -> FEM, the default), "relax"
(particles that move: each realization one RVE relaxed through the B_T values as field steps;
magnetostriction along and across the field, M_eff, E along and across the field after
restructuring, smallest gap, rms displacement against B; example:
homogenize/studies/relax_example.toml) and "synthetic" (known answers, for tests)."""

_RVE_SIZE_DOC = """\
Representative volume (Kanit et al. 2003): run the study at each RVE size of its [rve_size]
table, fit variance ~ V^-alpha of the chosen output, and report the realizations needed for the
target relative precision of the mean at each size (rve_size.json, rve_size.md, rve_size.png)."""

_COMPARE_DOC = """\
Do two grid points of a table differ? Welch's t-test and a permutation test on the stored
per-realization values, with the difference, its interval and Hedges' g (effect size).
Points are given by index or as axis=value pairs, e.g. "arrangement=clusters,B_T=0.1"."""


def _add_cluster_options(p):
    p.add_argument("--workers", type=int_in("--workers", 1, 64), default=None,
                   help="worker processes of the local Dask cluster (default: min(2, cores))")
    p.add_argument("--scheduler", type=scheduler_address, default=None,
                   metavar="tcp://HOST:PORT",
                   help="address of an existing Dask scheduler to run on instead of a local "
                        "cluster (default: none, start a local cluster)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar on stderr (default: show it)")


def _check_workers(args):
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")


def _cmd_batch(args) -> int:
    study = load_study(args.study)          # all validation before anything is written
    evaluator = get_evaluator(study.evaluator, fem=study.fem)
    for w in getattr(evaluator, "resolution_warnings", lambda s: [])(study):
        print(f"mapsim batch: {w}", file=sys.stderr)
    try:
        out = run_batch(study, args.out, workers=args.workers, scheduler=args.scheduler,
                        retries=args.retries, progress=not args.no_progress, clean=args.clean)
    except BatchError as exc:
        print(f"mapsim batch: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({study.n_points} grid points x {study.realizations} realizations)")
    _print_summary(out)
    return 0


def _print_summary(path, max_rows: int = 40) -> None:
    """Every quantity of the table per grid point, its mean and interval (vectors: the z
    component, tensors: zz; all components through xarray or ``mapsim compare``); for the cell
    FEM's quantities also the discretization error and the interval widened by it
    (:mod:`homogenize.tables.resolution`). The coarse-grid values of the estimate are not printed."""
    t = read_table(path)
    if len(t.points) > max_rows:
        print(f"{len(t.points)} grid points: more than {max_rows}, no summary here (open the "
              f"table with xarray; `mapsim compare` for two points)")
        return
    varying = [a for a, v in t.axes.items() if len(v) > 1]
    lvl = f"{100 * t.confidence:g} %"
    for q in t.values:
        if q.endswith(COARSE):
            continue
        comp = {1: "_z", 2: "_zz"}.get(t.values[q].ndim - 2, "")
        vals = t.component_values(q)
        errs = t.component_disc_err(q)
        head = f"{q}{comp} [{t.units.get(q, '1')}]"
        w = max(15, len(head))
        extra = "" if errs is None else "  discretization  combined interval"
        print(f"{'point':>5}  {'  '.join(f'{a:>14}' for a in varying)}  {head:>{w}}  "
              f"{lvl} interval{extra}")
        for i, point in enumerate(t.points):
            s = summarize(vals[i], t.confidence)
            cols = "  ".join(f"{point[a]!s:>14}" for a in varying)
            line = f"{i:>5}  {cols}  {s['mean']:{w}.6g}  [{s['ci_low']:.6g}, {s['ci_high']:.6g}]"
            if errs is not None:
                e = float(errs[i])
                line += f"  +- {e:.2g}  [{s['ci_low'] - e:.6g}, {s['ci_high'] + e:.6g}]"
            print(line)
    if t.disc_err:
        d = json.loads(t.attrs.get("discretization", "{}"))
        print(f"discretization: the error of the mean at {d.get('voxels')} voxels per edge, "
              f"from the same RVEs at {d.get('coarse_voxels')} (first order, never below "
              f"{100 * d.get('floor_rel_of_filler_contribution', 0):g} % of the filler's "
              f"contribution); combined = the {lvl} interval widened by it on both sides "
              f"(homogenize/tables/resolution.py)")


def _cmd_rve_size(args) -> int:
    study = load_study(args.study)
    try:
        res = rve_size_study(study, args.out, workers=args.workers, scheduler=args.scheduler,
                             progress=not args.no_progress, quantity=args.quantity,
                             component=args.component, target=args.target, at=args.at)
    except BatchError as exc:
        print(f"mapsim rve-size: {exc}", file=sys.stderr)
        return 1
    print(Path(args.out, "rve_size.md").read_text(encoding="utf-8"))
    print(f"wrote {Path(args.out) / 'rve_size.json'}, rve_size.md, rve_size.png")
    del res
    return 0


def _cmd_compare(args) -> int:
    table = read_table(args.table)
    q = table.resolve_quantity(args.quantity)
    a = table.select(args.point_a)
    b = table.select(args.point_b)
    if a == b:
        raise InputError(f"POINT_A and POINT_B are the same grid point ({a})")
    vals = table.component_values(q, args.component)
    res = welch_permutation(vals[a], vals[b], confidence=args.confidence,
                            n_resamples=args.permutations, seed=args.seed)
    unit = table.units[q]
    comp = f" ({args.component or 'z'})" if table.values[q].ndim > 2 else ""
    fa = ", ".join(f"{k}={v}" for k, v in table.points[a].items())
    fb = ", ".join(f"{k}={v}" for k, v in table.points[b].items())
    print(f"{q}{comp} [{unit}]")
    print(f"  A = point {a} ({fa}): mean {res.mean_a:.6g}, n = {res.n_a}")
    print(f"  B = point {b} ({fb}): mean {res.mean_b:.6g}, n = {res.n_b}")
    print(f"  B - A = {res.difference:.6g} {unit}, {100 * res.confidence:g} % interval "
          f"[{res.ci_low:.6g}, {res.ci_high:.6g}]")
    print(f"  Welch t = {res.t:.4g}, dof = {res.dof:.3g}, p = {res.p_welch:.3g}")
    print(f"  permutation test ({res.n_resamples} resamples): p = {res.p_permutation:.3g}")
    print(f"  Hedges' g = {res.hedges_g:.3g}")
    if args.json:
        write_json(args.json, {"quantity": q, "component": args.component, "unit": unit,
                               "point_a": {"index": a, **table.points[a]},
                               "point_b": {"index": b, **table.points[b]},
                               **res.as_dict(),
                               "manifest": manifest({"table": str(args.table)}, args.seed)})
    return 0


def _cmd_chain(args) -> int:
    _check_workers(args)
    try:
        res = run_chain(args.study, args.out, workers=args.workers, scheduler=args.scheduler,
                        progress=not args.no_progress, keep_parts=args.keep_parts,
                        thickness_m=args.thickness, width_m=args.width)
    except BatchError as exc:
        print(f"mapsim chain: {exc}", file=sys.stderr)
        return 1
    for c in res["curves"]:
        b4 = c["B_for_4mm_T"]["mean"]
        where = "not within the table's B range" if b4 is None else f"at B = {b4:.3g} T"
        print(f"phi = {c['phi']:g}: the seed strip bends by the measured 4 mm {where}")
    out = Path(args.out)
    print(f"wrote {out / 'summary.md'}, {out / 'deflection_vs_B.png'}, {out / 'chain.json'}, "
          f"{out / 'table.h5'}")
    return 0


def _own_defaults(formatter):
    """The formatter, except that a help text stating its own default gets no second one."""
    class Formatter(formatter):
        def _get_help_string(self, action):
            if "(default" in (action.help or ""):
                return action.help
            return super()._get_help_string(action)
    return Formatter


def register(sub, formatter):
    formatter = _own_defaults(formatter)
    p = sub.add_parser("batch", formatter_class=formatter, description=_BATCH_DOC,
                       help="run a study of random RVEs on Dask -> effective-parameter table")
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--out", required=True, help="table file to write (HDF5) (default: none, required)")
    _add_cluster_options(p)
    p.add_argument("--retries", type=int_in("--retries", 0, 10), default=2,
                   help="resubmissions of a realization whose task raised a possibly transient "
                        "error (out of memory, I/O); deterministic errors are reported at once "
                        "(the same seed fails the same way), lost workers are recomputed by Dask")
    p.add_argument("--clean", action="store_true",
                   help="delete the per-realization parts once the table is written "
                        "(default: keep them, so that a changed study reuses them)")
    p.set_defaults(func=_cmd_batch, outputs=("out",), inputs=("study",),
                   sidecar_outputs=("out",))

    p = sub.add_parser("rve-size", formatter_class=formatter, description=_RVE_SIZE_DOC,
                       help="representative volume: variance vs RVE size, realizations needed")
    p.add_argument("study", help="study file (TOML) with an [rve_size] table")
    p.add_argument("--out", default="results/rve_size",
                   help="directory for the tables, rve_size.json/.md/.png")
    p.add_argument("--quantity", default=None,
                   help="output to analyse (default: [rve_size] quantity, else f_eff_N_m3)")
    p.add_argument("--component", default=None,
                   help="x, y, z or norm for vectors, xx..zz for tensors "
                        "(default: [rve_size] component, else z)")
    p.add_argument("--target", type=float_in("--target", 0.0, 1.0, lo_open=True, hi_open=True),
                   default=None,
                   help="target relative precision of the mean, e.g. 0.02 "
                        "(default: [rve_size] target_rel_precision, else 0.02)")
    p.add_argument("--at", default=None, metavar="AXIS=VALUE,...",
                   help="fix grid axes to one of their values, e.g. \"phi=0.035,B_T=0.1\" "
                        "(default: every grid point of the study)")
    _add_cluster_options(p)
    p.set_defaults(func=_cmd_rve_size, output_dirs=("out",), inputs=("study",),
                   output_dir_writes={"out": ("rve_size_n*", "rve_size.*", ".*")})

    p = sub.add_parser("compare", formatter_class=formatter, description=_COMPARE_DOC,
                       help="test whether two grid points of a table differ")
    p.add_argument("table", help="table file (HDF5) written by mapsim batch")
    p.add_argument("point_a", metavar="POINT_A", help="grid point index or axis=value,...")
    p.add_argument("point_b", metavar="POINT_B", help="grid point index or axis=value,...")
    p.add_argument("--quantity", default="f_eff",
                   help="quantity (name or prefix, e.g. f_eff, M_eff, E_eff, d_eff)")
    p.add_argument("--component", default=None,
                   help="x, y, z or norm for vectors, xx..zz for tensors (default: z / zz)")
    p.add_argument("--confidence", type=float_in("--confidence", 0.0, 1.0, lo_open=True,
                                                 hi_open=True), default=0.95,
                   help="level of the interval of the difference")
    p.add_argument("--permutations", type=int_in("--permutations", 99, 10 ** 7), default=9999,
                   help="resamples of the permutation test (exact test if all splits fit)")
    p.add_argument("--seed", type=int_in("--seed", 0, 2 ** 63 - 1), default=0,
                   help="seed of the permutation resampling")
    p.add_argument("--json", default=None, help="also write the result to this JSON file (default: none)")
    p.set_defaults(func=_cmd_compare, outputs=("json",), inputs=("table",))

    p = sub.add_parser("chain", formatter_class=formatter,
                       help="the whole chain: default study -> table -> seed cantilever vs B",
                       description="Run the default study (RVEs at the seed paper's conditions "
                                   "across applied fields), write the table, and predict the "
                                   "seed's cantilever tip deflection with its interval as a "
                                   "function of B, next to the measured 4 mm.")
    p.add_argument("study", nargs="?", default=None,
                   help="study file (default: the packaged homogenize/studies/default_study.toml)")
    p.add_argument("--out", default="results/chain", help="output directory")
    p.add_argument("--keep-parts", action="store_true",
                   help="keep the per-realization parts after the table is written (default: delete them)")
    p.add_argument("--thickness", type=float_in("--thickness", 0.0, 1.0, "m", lo_open=True),
                   default=1e-3,
                   help="assumed strip thickness [m] (the paper gives none; the length follows "
                        "from its premise, 43.79 kN/m^3 -> 4 mm)")
    p.add_argument("--width", type=float_in("--width", 0.0, 1.0, "m", lo_open=True),
                   default=5e-3, help="assumed strip width [m]")
    _add_cluster_options(p)
    p.set_defaults(func=_cmd_chain, output_dirs=("out",), inputs=("study",),
                   output_dir_writes={"out": ("table.*", "chain.json", "summary.md",
                                              "deflection_vs_*.png", ".*")})
    one_line_errors(sub)


# --------------------------------------------------------------------------- mapsim beam --table
def _add_table_point_options(g, without: str) -> None:
    """--table and the point (--phi, --B, --gradB, --at) at which it is interpolated."""
    g.add_argument("--table", default=None, help=f"effective-parameter table (HDF5) "
                                                 f"(default: none, {without})")
    g.add_argument("--phi", type=float_in("--phi", 0.0, 0.74, lo_open=True), default=None,
                   help="particle volume fraction [-] (default: none, required with --table)")
    g.add_argument("--B", dest="B_T", type=float_in("--B", 0.0, 50.0, "T"), default=None,
                   help="applied flux density at the strip [T] (default: none, required with "
                        "--table)")
    g.add_argument("--gradB", dest="gradB_T_per_m", type=float_in("--gradB", -1e4, 1e4, "T/m"),
                   default=None,
                   help="field gradient d|B|/dz [T/m] (default: none, required with --table)")
    g.add_argument("--at", dest="table_at", default=None, metavar="AXIS=VALUE,...",
                   help="values of other grid axes with several values, e.g. "
                        "arrangement=chains (default: none)")


def add_beam_table_options(p) -> None:
    """Options of ``mapsim beam`` that take the body force from a batch table."""
    p.formatter_class = _own_defaults(p.formatter_class)
    g = p.add_argument_group(
        "body force from a table (mapsim batch)",
        "With --table, the body force and its confidence interval are interpolated from the "
        "table at (--phi, --B, --gradB) and replace --body-force-N-m3; the interval is "
        "propagated to the tip deflection of every model.")
    _add_table_point_options(g, "use --body-force-N-m3")
    g.add_argument("--E-from-table", action="store_true",
                   help="use the table's E_eff (FEM) and its interval instead of --E-Pa")


def beam_from_table(args) -> int:
    """``mapsim beam --table``: tip deflection with the interval propagated from the table."""
    for name, v in (("--phi", args.phi), ("--B", args.B_T), ("--gradB", args.gradB_T_per_m)):
        if v is None:
            raise InputError(f"{name} is required with --table")
    others = parse_at(args.table_at)
    mat = effective_material_from_table(
        read_table(args.table), args.phi, args.B_T, args.gradB_T_per_m, other_axes=others,
        E_Pa=None if args.E_from_table else args.E_Pa, E_from_table=args.E_from_table,
        nu=args.nu, density_kg_m3=args.density_kg_m3)
    if args.E_from_table and mat.E_estimate is None:
        raise InputError(f"--E-from-table: {args.table} has no E_eff (the study ran without "
                         f"fem = true)")
    strip = Strip(args.length_m, args.width_m, args.thickness_m)
    rows = beam_with_interval(strip, mat, args.model, order=args.order, nz=args.nz,
                              gravity_m_s2=args.gravity_m_s2, n_steps=args.steps)
    force, E_est = mat.force, mat.E_estimate
    lvl = f"{100 * force.confidence:g} %"
    print(f"body force from {args.table} at phi = {args.phi:g}, B = {args.B_T:g} T, "
          f"dB/dz = {args.gradB_T_per_m:g} T/m: {force.mean:.6g} N/m^3, {lvl} interval "
          f"[{force.ci_low:.6g}, {force.ci_high:.6g}]")
    print(f"E = {mat.E_Pa:.6g} Pa" + ("" if E_est is None else
                                      f" (table, {lvl} interval {E_est.describe()})"))
    print(f"{'model':<12} {'tip [m]':>12} {lvl + ' interval [m]':>30}")
    for r in rows:
        print(f"{r['model']:<12} {r['tip_m']:12.6g}   [{r['ci_low_m']:.6g}, {r['ci_high_m']:.6g}]")
    small = {r["model"]: r["tip_m"] for r in rows}
    if "eb" in small and "elastica" in small and small["eb"] > 0 \
            and abs(small["elastica"] - small["eb"]) > 0.01 * small["eb"]:
        print(f"note: large deflection (tip/L = {small['elastica'] / args.length_m:.2f}): the "
              f"elastica differs from Euler-Bernoulli by "
              f"{100 * (small['elastica'] / small['eb'] - 1):+.1f} %; use it (or neo-hookean)")
    if args.json:
        write_json(args.json, {"table": str(args.table), "phi": args.phi, "B_T": args.B_T,
                               "gradB_T_per_m": args.gradB_T_per_m, "other_axes": others,
                               "force_N_m3": vars(force), "E_Pa": mat.E_Pa,
                               "E_estimate_Pa": None if E_est is None else vars(E_est),
                               "strip": vars(strip), "results": rows,
                               "manifest": manifest(config_of(args), None)})
    return 0


# --------------------------------------------------------------------------- mapsim export --table
_EXPORT_NEEDS = (("body_force_N_m3", "--body-force-N-m3"), ("E_Pa", "--E-Pa"), ("nu", "--nu"),
                 ("density_kg_m3", "--density-kg-m3"))


def add_export_table_options(p) -> None:
    """Options of ``mapsim export`` that take the material and force from a batch table.

    The material/force options of ``export`` stop being required: without --table they are
    checked by :func:`wrap_export` instead.
    """
    p.formatter_class = _own_defaults(p.formatter_class)
    for action in p._actions:                      # argparse has no public way to relax this
        if action.dest in dict(_EXPORT_NEEDS):
            action.required = False
    g = p.add_argument_group(
        "from a table (mapsim batch)",
        "With --table, the body force (and E, nu if the table holds FEM results) are "
        "interpolated at (--phi, --B, --gradB); explicit --E-Pa/--nu/--density-kg-m3 win. The "
        f"density defaults to the mixture (1 - phi) {PDMS.density_kg_m3:g} + phi "
        f"{FE.density_kg_m3:g} kg/m^3.")
    _add_table_point_options(g, "give the numbers")
    g.add_argument("--bound", default="mean", choices=("mean", "low", "high"),
                   help="export the mean force or an end of its confidence interval (run the "
                        "macro model at both ends to propagate the interval); with --magnet, "
                        "the deck's M_eff(H) at that end")


def wrap_export(func):
    """``export`` dispatcher: --table goes to :func:`export_from_table`, else ``func``."""
    def run(args):
        if getattr(args, "table", None):
            return export_from_table(args)
        for dest, flag in _EXPORT_NEEDS:
            if getattr(args, dest, None) is None:
                raise InputError(f"{flag} is required (or take the numbers from --table)")
        return func(args)
    return run


def export_from_table(args) -> int:
    for name, v in (("--phi", args.phi), ("--B", args.B_T), ("--gradB", args.gradB_T_per_m)):
        if v is None:
            raise InputError(f"{name} is required with --table")
    if args.body_force_N_m3 is not None:
        raise InputError("give either --table or --body-force-N-m3, not both")
    if getattr(args, "deck", None) is not None:
        raise InputError(f"--deck {args.deck} is not written from --table (only the material "
                         f"snippet is); give either --table or --deck, not both")
    others = parse_at(args.table_at)
    matrix = getattr(args, "matrix_material", None)
    mat = effective_material_from_table(read_table(args.table), args.phi, args.B_T,
                                        args.gradB_T_per_m, other_axes=others, E_Pa=args.E_Pa,
                                        nu=args.nu, density_kg_m3=args.density_kg_m3,
                                        matrix=None if matrix in (None, "seed-paper")
                                        else matrix_preset(matrix))
    f = mat.force
    force = {"mean": f.mean, "low": f.ci_low, "high": f.ci_high}[args.bound]
    if force < 0:
        raise InputError(f"the {args.bound} body force is negative ({force:g} N/m^3)")
    spec = ExportSpec(force, mat.E_Pa, mat.nu, mat.density_kg_m3, direction=args.direction,
                      gravity_m_s2=args.gravity_m_s2, name=args.name, elset=args.elset,
                      index=args.index)
    c = "!" if args.to == "elmer" else "**"
    lvl = f"{100 * f.confidence:g} %"
    head = [f"{c} mapsim export from table {args.table}: phi = {args.phi:g}, B = {args.B_T:g} T, "
            f"dB/dz = {args.gradB_T_per_m:g} T/m" + (f", {args.table_at}" if others else ""),
            f"{c} body force ({args.bound}) {force:.6g} N/m^3; mean {f.mean:.6g}, {lvl} interval "
            f"[{f.ci_low:.6g}, {f.ci_high:.6g}] N/m^3",
            f"{c} E = {mat.E_Pa:.6g} Pa ({mat.E_source}), nu = {mat.nu:.4g}, density = "
            f"{mat.density_kg_m3:.6g} kg/m^3"]
    text = "\n".join(head) + "\n" + export_text(spec, args.to)
    return write_snippet(text, args.out, f"{args.to} snippet")
