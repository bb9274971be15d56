"""Commands of the macro layer: ``paper``, ``export``, ``beam``, ``channel``."""
from __future__ import annotations

import json
import sys

from micro._validate import InputError, check_positive

from homogenize.cli._common import write_snippet
from homogenize.cli.tables import (add_beam_table_options, add_export_table_options,
                                   beam_from_table, wrap_export)
from homogenize.studies.paper import write_paper
from homogenize.macro.exporters import ExportSpec, export_text
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material
from homogenize.macro.channel import ChannelGeometry, solve_channel
from homogenize.macro.exporters import DIRECTIONS
from homogenize.macro.cantilever import MODELS
from micro._io import manifest, write_json

__all__ = ["register"]


def _paper(args) -> int:
    check_positive("width-m", args.width_m, "m")
    check_positive("thickness-m", args.thickness_m, "m")
    res = write_paper(args.out, args.json, quick=args.quick, quiet=args.quiet,
                      width_m=args.width_m, thickness_m=args.thickness_m)
    print(f"seed body force {res['body_force_seed_N_m3'] / 1e3:.3f} kN/m^3; inferred length "
          f"{res['beam']['inferred_length_m'] * 1e3:.3f} mm; force for 4 mm P1/P2/converged "
          f"{res['force_for_4mm_N_m3']['P1_coarse'] / 1e3:.1f}/"
          f"{res['force_for_4mm_N_m3']['P2_coarse'] / 1e3:.1f}/"
          f"{res['force_for_4mm_N_m3']['converged'] / 1e3:.1f} kN/m^3; results in {args.out}")
    return 0


def _export(args) -> int:
    spec = ExportSpec(args.body_force_N_m3, args.E_Pa, args.nu, args.density_kg_m3,
                      direction=args.direction, gravity_m_s2=args.gravity_m_s2, name=args.name,
                      elset=args.elset, index=args.index)
    return write_snippet(export_text(spec, args.to), args.out, f"{args.to} snippet")


def _beam(args) -> int:
    if getattr(args, "table", None):   # --table: force + interval from a batch table (tables)
        return beam_from_table(args)
    strip = Strip(args.length_m, args.width_m, args.thickness_m)
    mat = Material(args.E_Pa, args.nu, args.density_kg_m3)
    check_positive("nz", args.nz, "")
    rows = []
    for model in args.model:
        r = solve_cantilever(strip, mat, args.body_force_N_m3, model=model, order=args.order,
                             nz=args.nz, gravity_m_s2=args.gravity_m_s2, n_steps=args.steps)
        rows.append(r.to_dict())
    if args.json:
        write_json(args.json, {"strip": vars(strip), "material": vars(mat), "results": rows,
                               "manifest": manifest(vars(args) | {"func": None}, None)})
    print(f"{'model':<12} {'tip [m]':>12} {'horizontal [m]':>15} {'dofs':>8}  mesh")
    for r in rows:
        mesh = "" if r["divisions"] is None else f"{r['divisions']} P{r['order']}"
        print(f"{r['model']:<12} {r['tip_m']:12.6g} {r['tip_horizontal_m']:15.6g} "
              f"{r['n_dof']:8d}  {mesh}")
    return 0


def _channel(args) -> int:
    geo = ChannelGeometry(args.a_m, args.b_m, args.c_m, args.d_m, args.wall_m)
    mat = Material(args.E_Pa, args.nu, args.density_kg_m3)
    check_positive("nc", args.nc, "")
    r = solve_channel(geo, mat, args.body_force_N_m3, order=args.order, nc=args.nc,
                      gravity_m_s2=args.gravity_m_s2)
    if args.json:
        write_json(args.json, {"result": r.to_dict(),
                               "manifest": manifest(vars(args) | {"func": None}, None)})
    print(json.dumps({k: v for k, v in r.to_dict().items()}, indent=1))
    if r.closes:
        print("warning: the linear deflection exceeds the channel height b; the channel would "
              "close (contact is not modelled)", file=sys.stderr)
    return 0


def _material_options(p):
    p.add_argument("--E-Pa", dest="E_Pa", type=float, default=2.0e6,
                   help="Young's modulus of the composite [Pa]")
    p.add_argument("--nu", type=float, default=0.45, help="Poisson ratio [-], in (-1, 0.5)")
    p.add_argument("--density-kg-m3", dest="density_kg_m3", type=float, default=1210.0,
                   help="mass density [kg/m^3] (self-weight, with --gravity-m-s2)")
    p.add_argument("--gravity-m-s2", dest="gravity_m_s2", type=float, default=0.0,
                   help="gravity along the body force [m/s^2]; 0 = no self-weight")


def register(sub, formatter) -> None:
    """Add the ``paper``, ``export``, ``beam`` and ``channel`` commands."""
    p = sub.add_parser(
        "paper", formatter_class=formatter, help="reproduce and examine the seed paper",
        description="Reproduce the seed paper (body force, cantilever, Abaqus/Elmer gap, large "
                    "deformation, self-weight, channel study). Writes summary.md, paper.json, "
                    "PNG figures and manifest.json to --out. Takes a few minutes.")
    p.add_argument("--out", default="results/paper", help="output directory")
    p.add_argument("--json", default=None, help="also write the JSON results to this file")
    p.add_argument("--width-m", dest="width_m", type=float, default=5e-3,
                   help="assumed strip width [m]")
    p.add_argument("--thickness-m", dest="thickness_m", type=float, default=1e-3,
                   help="assumed strip thickness [m]")
    p.add_argument("--quick", action="store_true",
                   help="small meshes and sweeps (seconds; for tests, numbers indicative)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_paper, outputs=("json",), output_dirs=("out",))

    p = sub.add_parser(
        "export", formatter_class=formatter,
        help="write an Elmer or Abaqus material + body-force snippet",
        description="Write the material (E, nu, density) and the magnetic body force as an Elmer "
                    ".sif Material/Body Force section or an Abaqus *MATERIAL/*DLOAD snippet. "
                    "SI units throughout.")
    p.add_argument("--to", required=True, choices=("elmer", "abaqus"), help="target solver")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=float, required=True,
                   help="magnitude of the magnetic body force [N/m^3]")
    p.add_argument("--E-Pa", dest="E_Pa", type=float, required=True,
                   help="Young's modulus [Pa]")
    p.add_argument("--nu", type=float, required=True, help="Poisson ratio [-], in (-1, 0.5)")
    p.add_argument("--density-kg-m3", dest="density_kg_m3", type=float, required=True,
                   help="mass density [kg/m^3]")
    p.add_argument("--direction", default="-z", choices=tuple(DIRECTIONS),
                   help="direction of the body force (and of gravity)")
    p.add_argument("--gravity-m-s2", dest="gravity_m_s2", type=float, default=0.0,
                   help="self-weight acceleration [m/s^2]; Abaqus: GRAV line, Elmer: added to "
                        "the body force")
    p.add_argument("--name", default="MAP_PDMS", help="material name")
    p.add_argument("--elset", default="EALL", help="Abaqus element set of the *DLOAD")
    p.add_argument("--index", type=int, default=1, help="Elmer Material / Body Force number")
    p.add_argument("--out", required=True, help="output file ('-' for stdout)")
    add_export_table_options(p)
    p.set_defaults(func=wrap_export(_export), outputs=("out",), inputs=("table",))

    p = sub.add_parser(
        "beam", formatter_class=formatter, help="tip deflection of a clamped strip",
        description="Tip deflection of a strip clamped at one end under a uniform transverse "
                    "body force: Euler-Bernoulli ('eb', 'eb-plate'), Timoshenko, elastica "
                    "(large deflection, 1D), 3D linear FEM ('fem') and 3D neo-Hookean FEM.")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=float, default=40e3,
                   help="transverse body force [N/m^3]")
    p.add_argument("--length-m", dest="length_m", type=float, default=20e-3,
                   help="free length [m]")
    p.add_argument("--width-m", dest="width_m", type=float, default=5e-3, help="width [m]")
    p.add_argument("--thickness-m", dest="thickness_m", type=float, default=1e-3,
                   help="thickness, along the force [m]")
    _material_options(p)
    p.add_argument("--model", nargs="+", default=["eb", "timoshenko", "elastica", "fem"],
                   choices=MODELS, help="models to evaluate")
    p.add_argument("--order", type=int, default=2, choices=(1, 2),
                   help="tetrahedron degree of the FEM models")
    p.add_argument("--nz", type=int, default=3,
                   help="element layers through the thickness (FEM models)")
    p.add_argument("--steps", type=int, default=4, help="load increments (neo-hookean)")
    p.add_argument("--json", default=None, help="write the results to this JSON file")
    add_beam_table_options(p)
    p.set_defaults(func=_beam, outputs=("json",), inputs=("table",))

    p = sub.add_parser(
        "channel", formatter_class=formatter, help="ceiling deflection of a microchannel",
        description="A PDMS block bonded to glass with a channel (width a, height b, ceiling "
                    "thickness c, length d) under a body force towards the glass: maximum "
                    "ceiling deflection and relative cross-section reduction (3D linear FEM).")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=float, default=40e3,
                   help="body force towards the glass [N/m^3]")
    p.add_argument("--a-m", dest="a_m", type=float, default=5e-3, help="channel width a [m]")
    p.add_argument("--b-m", dest="b_m", type=float, default=50e-6, help="channel height b [m]")
    p.add_argument("--c-m", dest="c_m", type=float, default=0.5e-3,
                   help="polymer thickness above the channel c [m]")
    p.add_argument("--d-m", dest="d_m", type=float, default=10e-3, help="channel length d [m]")
    p.add_argument("--wall-m", dest="wall_m", type=float, default=None,
                   help="side-wall width [m] (default max(a/2, 2 (b + c)))")
    _material_options(p)
    p.add_argument("--order", type=int, default=2, choices=(1, 2), help="tetrahedron degree")
    p.add_argument("--nc", type=int, default=2, help="element layers through the ceiling")
    p.add_argument("--json", default=None, help="write the result to this JSON file")
    p.set_defaults(func=_channel, outputs=("json",))
