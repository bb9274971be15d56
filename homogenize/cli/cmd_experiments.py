"""``mapsim diagnose`` and ``mapsim diagnose-study``."""
from __future__ import annotations

import sys
from pathlib import Path

from micro.common.files import manifest, protect_inputs, write_json
from micro.common.validate import InputError

from homogenize.cli._common import (check_input_file, check_output_dir, check_outputs, int_in,
                                    one_line_errors)
from homogenize.experiments.diagnose import diagnose
from homogenize.experiments.io import load_experiment
from homogenize.experiments.study import run_study, summarize, write_study
from homogenize.experiments import rve_tables as T
from homogenize.experiments.report import write_report

__all__ = ["register"]

_DIAGNOSE_DOC = """\
Compare a measured experiment (TOML + CSV, see examples/data/EXPERIMENT_FORMAT.md) with the seed
model, name what it gets wrong from the causes' vocabulary, extend the model and measure the
gain. Criterion: a cause is accepted only if it lowers the cross-validated RMSE (folds of whole
specimens when there are >= 3) by >= 10 % AND a one-sided Wilcoxon signed-rank test on the
paired held-out squared errors gives p < 0.01 (the passing candidate with the lowest error is
accepted; if none passes, pairs of the three best are tried together); repeated until nothing
more helps.
Causes (the vocabulary of examples/data/EXPERIMENT_FORMAT.md, section 4):
field_dependent_magnetization, dipolar_interaction, oxide_shell, filler_stiffening,
geometric_nonlinearity, hyperelasticity, gravity, hysteresis, demagnetization,
microstructure_evolution (magnetostriction, on top of dipolar_interaction: particles that move
in the matrix; form coupled_rve reads a relax table made by `mapsim batch` with evaluator =
"relax", homogenize/experiments/data/relax_*.h5, at the specimen's phi and E; form fitted
fits a stress growing as M^4, needs a field-dependent M). For magnetostriction the JSON and
the report add "microstructure_evolution": the coupled RVE's predicted strain WITHOUT any
fitted stress next to the measured one, the held-out gains, and what remains unexplained;
and "specimen" (report section and specimen.png): the measured change of LENGTH of the
cylinder predicted through the specimen solver (field in and around the deforming body,
finite strain) for three models -- continuum, affine, relaxed -- with nothing fitted, the share
of the amplitude explained, what still has to be fitted and the held-out gain
(--specimen-mesh; a minute or two per specimen geometry).
Exit code 0 when the analysis ran (whatever it found), 2 for unusable input."""

_STUDY_DOC = """\
Run diagnose on N synthetic experiments with hidden causes (seeded; truths built independently
of the diagnosis model, 1-3 % noise) and report the confusion matrix, the false-cause rate and
the median gain (study.json, confusion.csv, confusion.png, manifest.json in --out)."""


#: what ``--report DIR`` writes into DIR (an input there under one of these names is refused)
_REPORT_FILES = ("report.md", "data.png", "residuals.png", "specimen.png", "diagnosis.json",
                 "manifest.json", ".*.tmp")


def _diagnose(args) -> int:
    if args.discussion and not args.report:
        raise InputError("--discussion is appended to the report: give --report DIR too")
    check_input_file("--discussion", args.discussion, 4 * 2 ** 20)
    exp = load_experiment(args.experiment)
    check_outputs([("--json", args.json)], [exp.data_path, args.experiment])
    # the data file named inside the experiment is an input too
    check_output_dir("--report", args.report, [exp.data_path], _REPORT_FILES)
    protect_inputs([exp.data_path])
    d = diagnose(exp, progress=not args.quiet,
                 specimen_mesh=None if args.specimen_mesh == "none" else args.specimen_mesh)
    res = d.as_dict()
    if args.json:
        out = Path(args.json)
        write_json(out, res)
        write_json(out.with_name(out.stem + ".manifest.json"),
                   manifest({"experiment": str(args.experiment), "command": "diagnose"}, None))
    if args.report:
        discussion = None
        if args.discussion:
            try:
                discussion = Path(args.discussion).read_text(encoding="utf-8")
            except OSError as exc:
                raise InputError(f"--discussion {args.discussion}: cannot read ({exc})") from None
        md = write_report(d, args.report, discussion=discussion)
        write_json(Path(args.report) / "diagnosis.json", res)
        write_json(Path(args.report) / "manifest.json",
                   manifest({"experiment": str(args.experiment), "command": "diagnose"}, None))
        if not args.quiet:
            print(f"report: {md}", file=sys.stderr)
    unit = {"deflection": "m", "magnetization": "A/m", "magnetostriction": "",
            "tensile": "Pa"}[exp.kind]
    print(f"{exp.kind}: {exp.n_rows} rows; seed cv_rmse {res['baseline']['cv_rmse']:.4g} {unit}")
    for s in res["steps"]:
        print(f"  + {s['cause']}: cv_rmse {s['cv_rmse']:.4g} {unit}")
    print(f"causes: {', '.join(res['causes']) or 'none'}; gain {res['gain']:.3g}")
    for c, why in d.skipped.items():
        if why.startswith("unavailable"):
            print(f"note: {c} not tried ({why})", file=sys.stderr)
    return 0


def _study(args) -> int:
    records = run_study(args.n, seed=args.seed, progress=not args.quiet)
    summary = summarize(records)
    config = {"command": "diagnose-study", "n": args.n, "seed": args.seed}
    write_study(records, summary, args.out, config)
    if args.json:
        write_json(args.json, {"summary": summary, "cases": records})
    def f(v, spec):
        return "n/a" if v is None else format(v, spec)
    print(f"{summary['n_used']} cases used ({summary['n_unavailable']} with an unavailable "
          f"cause): exact recovery {f(summary['exact_recovery_rate'], '.1%')}, false-cause rate "
          f"{f(summary['false_cause_rate'], '.1%')}, median gain {f(summary['median_gain'], '.3g')}")
    return 0


_TABLES_DOC = """\
Re-make the RVE tables the diagnosis interpolates in (homogenize/experiments/data/, each with a
.provenance.json): filler_stiffness.csv (E_eff / E_matrix and nu_eff of random RVEs of Fe
spheres in PDMS by the voxel FEM, several seeds per phi), filler_stiffness_resolution.json
(its discretization check), dipolar_stress.csv (magnetic virial stress of random RVEs from
micro.dipoles over phi and field) and dipolar_cell_stress.csv (the share of it that stiff
particles pass on to the matrix, homogenize.cell.problem's stress_mag, 32^3 voxels). On 2 cores:
stiffness ~3-8 min at 24^3 voxels, resolution ~3 min, stress < 1 min, cell-stress ~5-10 min."""


def _tables(args) -> int:
    argv = ["mapsim", "diagnose-tables", "--only", args.only]
    if args.only in ("stiffness", "all"):
        argv += ["--voxels", str(args.voxels)]
    if args.only in ("stiffness", "all"):
        out = T.build_stiffness_table(voxels=args.voxels, progress=not args.quiet, argv=argv)
        print(f"wrote {out}")
    if args.only in ("resolution", "all"):
        out = T.DATA_DIR / "filler_stiffness_resolution.json"
        T.stiffness_resolution_study(path=out, argv=argv)
        print(f"wrote {out}")
    if args.only in ("stress", "all"):
        out = T.build_stress_table(progress=not args.quiet, argv=argv)
        print(f"wrote {out}")
    if args.only in ("cell-stress", "all"):
        out = T.build_cell_stress_table(progress=not args.quiet, argv=argv)
        print(f"wrote {out}")
    return 0


def register(sub, formatter):
    p = sub.add_parser("diagnose", formatter_class=formatter, description=_DIAGNOSE_DOC,
                       help="name what the seed model gets wrong in measured data, and the gain")
    p.add_argument("experiment", help="experiment TOML file (its 'data' key names the CSV)")
    p.add_argument("--json", default=None,
                   help="write the spec's JSON result here (and a .manifest.json beside it)")
    p.add_argument("--report", default=None,
                   help="write report.md, data.png, residuals.png, diagnosis.json, manifest.json "
                        "into this directory")
    p.add_argument("--discussion", default=None,
                   help="Markdown file appended to the report as its Discussion section")
    p.add_argument("--specimen-mesh", choices=("normal", "coarse", "none"), default="normal",
                   help="magnetostriction: mesh of the specimen solver that predicts the "
                        "measured change of length (normal: 8 elements along the radius, 48 "
                        "segments of the field mesh's profile; coarse: 4 / 24; none: skip)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_diagnose, outputs=("json",), output_dirs=("report",),
                   output_dir_writes={"report": _REPORT_FILES}, sidecar_outputs=("json",),
                   inputs=("experiment", "discussion"))

    q = sub.add_parser("diagnose-study", formatter_class=formatter, description=_STUDY_DOC,
                       help="recovery of hidden causes on synthetic experiments")
    q.add_argument("--n", type=int_in("--n", 1, 100_000), default=200,
                   help="number of synthetic cases (-)")
    q.add_argument("--seed", type=int_in("--seed", 0, 2 ** 63 - 100_001), default=0,
                   help="seed of the first case; case i uses seed+i")
    q.add_argument("--out", default="results/diagnose/study",
                   help="output directory (study.json, confusion.csv/.png, manifest.json)")
    q.add_argument("--json", default=None, help="also write the study JSON to this file")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    q.set_defaults(func=_study, outputs=("json",), output_dirs=("out",))

    t = sub.add_parser("diagnose-tables", formatter_class=formatter, description=_TABLES_DOC,
                       help="re-make the RVE tables (FEM stiffness, dipolar stress) of diagnose")
    t.add_argument("--only", choices=("all", "stiffness", "resolution", "stress", "cell-stress"), default="all",
                   help="which table to re-make; 'resolution' is the stiffness table's "
                        "discretization check (one sphere at 12-40 voxels) (default: all)")
    t.add_argument("--voxels", type=int_in("--voxels", 8, 96), default=24,
                   help="voxels per RVE edge of the stiffness table (-, default 24)")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=_tables)
    one_line_errors(sub)
