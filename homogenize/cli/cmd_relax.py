"""``mapsim relax``: particles that move -- the coupled magneto-mechanical equilibrium of an RVE
through increasing field steps (:func:`homogenize.cell.relax.relax`)."""
from __future__ import annotations

import sys

import numpy as np

from micro.common.files import atomic_path, manifest, write_json
from micro.common.validate import InputError
from micro.magnetization import DEFAULT_LAW, LAW_NAMES
from micro.materials import PDMS, POISSON_RANGE, ElasticMaterial, matrix_preset
from micro.rve import RVE

from homogenize.cli._common import (add_material_options, config_of, fill_from_preset,
                                    float_in, int_in, parse_values)
from homogenize.cell.relax import relax

_DOC = """\
Coupled magneto-mechanics of an RVE (HDF5 from `mapsim rve`): rigid particles in the elastic
matrix move under their magnetic forces, which are re-solved at the new positions, field step
by field step (Newton on the particle displacements, contact penalty), with the matrix response
from the periodic elastic Green's function of rigid spheres (fast) or the voxel FEM; then the
cell FEM on the relaxed RVE gives the free magnetostriction and the stiffness along and across
the field. The JSON has per field step B_T, strain_mag (3x3), M_eff_A_per_m,
E_eff_parallel_Pa, E_eff_perpendicular_Pa, min_gap_m, displacement_rms_m, iterations, the
mean strain and mean stress of the cell and the microstructure descriptors.

--boundary free: zero mean stress (free magnetostriction). --boundary strain: the prescribed
mean strain --mean-strain (default zero: a clamped cell); the mean stress C_eff : E + the
magnetic stress is reported (the strain is not fed back into the particle positions).

--near-field on: close pairs (surface gap below two mean radii) get the exact force of two
magnetizable spheres (two-centre multipole expansion, converged in the number of multipoles;
checked against an axisymmetric FEM to 0.15 %) minus the point-dipole force, on top of the
periodic point dipoles. Limits: pairwise additive (no three-body near field), linear spheres
with the chord permeability of their law at their local field (so near contact it overrates
saturating particles, whose gap region saturates), permeability capped at 1000, gaps inside
the contact layer (5 % of a radius) held at the layer's edge, where the contact penalty takes
over. Not modelled: particle rotation.

Field sub-stepping: a field step that does not converge (or ends with overlapping particles,
e.g. a pair snapping through the contact penalty in one large step) is retried from the last
converged state with the field increment halved, up to --max-substep-halvings times (default
5, increments down to 1/32); the JSON reports per step `substeps`, `substep_B_T` and
`failed_attempts`, the table the sub-steps (column `sub`). If even that fails: exit 3 with
the residuals of every attempt.

Model error of the fast elastic path (--elastic-model green, Rotne-Prager level): see
results/relax/green_vs_fem.md; it grows for pairs closer than about one radius."""


def _steps(text: str) -> np.ndarray:
    """``"0:1.2:13"`` (start:stop:count) or ``"0,0.1,0.5"`` -> field steps [T]."""
    return parse_values(text, "--B", "T")


def _mean_strain(text, boundary):
    """``"xx,yy,zz,yz,xz,xy"`` (tensor components) -> symmetric 3x3 strain, or None."""
    if text is None:
        return None
    if boundary != "strain":
        raise InputError("--mean-strain needs --boundary strain (--boundary free has zero "
                         "mean stress)")
    try:
        v = [float(t) for t in text.split(",")]
        if len(v) != 6:
            raise ValueError
    except ValueError:
        raise InputError(f"--mean-strain must be six comma-separated strain components "
                         f"xx,yy,zz,yz,xz,xy [-], got {text!r}") from None
    xx, yy, zz, yz, xz, xy = v
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def _cmd(args) -> int:
    steps = _steps(args.B)
    E = _mean_strain(args.mean_strain, args.boundary)
    m = matrix_preset(args.matrix_material)
    fill_from_preset(args, {"matrix_E": m.E_Pa, "matrix_nu": m.nu})
    matrix = ElasticMaterial(args.matrix_E, args.matrix_nu)
    rve = RVE.load(args.rve)
    res = relax(rve, steps, law=args.law, matrix=matrix, boundary=args.boundary,
                voxels=args.voxels, elastic_model=args.elastic_model,
                near_field=args.near_field == "on", mean_strain=E,
                max_substep_halvings=args.max_substep_halvings, progress=not args.quiet)
    out = res.to_dict()
    out["rve_file"] = str(args.rve)
    out["manifest"] = manifest(config_of(args), getattr(rve, "seed", None))
    write_json(args.json, out)
    if args.out:
        res.rve.save(args.out)
    if args.png:
        _plot(args.png, out)
    print(f"{'B [T]':>8} {'strain_zz':>11} {'stress_zz':>11} {'M_eff [A/m]':>12} "
          f"{'E_par [Pa]':>11} {'E_perp [Pa]':>11} {'min gap [m]':>11} {'u_rms [m]':>10} "
          f"{'it':>3} {'sub':>3}")
    for s in out["steps"]:
        sz = s["strain_mag"][2][2] if s.get("strain_mag") is not None else float("nan")
        tz = (s["mean_stress_Pa"][2][2] if s.get("mean_stress_Pa") is not None
              else float("nan"))
        print(f"{s['B_T']:8.3g} {sz:11.3e} {tz:11.3e} {s['M_eff_A_per_m']:12.4g} "
              f"{(s.get('E_eff_parallel_Pa') or float('nan')):11.4g} "
              f"{(s.get('E_eff_perpendicular_Pa') or float('nan')):11.4g} "
              f"{s['min_gap_m']:11.3e} {s['displacement_rms_m']:10.3e} {s['iterations']:3d} "
              f"{s.get('substeps', 1):3d}")
    if not args.quiet:
        print(f"wrote {args.json}" + (f", {args.out}" if args.out else ""), file=sys.stderr)
    return 0


def _plot(path, out) -> None:
    from matplotlib.figure import Figure      # lazy: 0.3 s import, only for plotting
    B = np.array([s["B_T"] for s in out["steps"]])
    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    ezz = [s["strain_mag"][2][2] if s.get("strain_mag") is not None else np.nan
           for s in out["steps"]]
    ax.plot(B, ezz, "o-", label="free magnetostriction along the field")
    ax.set_xlabel("applied flux density B [T]")
    ax.set_ylabel("strain along the field [-]")
    ax2 = ax.twinx()
    ax2.plot(B, [1e9 * s["displacement_rms_m"] for s in out["steps"]], "s--", color="C1",
             label="particle displacement (rms)")
    ax2.set_ylabel("particle displacement rms [nm]")
    ax.legend(loc="upper left", fontsize=8)
    ax2.legend(loc="lower right", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


def register(sub, formatter):
    p = sub.add_parser("relax", formatter_class=formatter, description=_DOC,
                       help="particles that move: coupled magneto-mechanics of an RVE vs B")
    p.add_argument("rve", help="RVE file (HDF5, from `mapsim rve`)")
    p.add_argument("--B", default="0:1.2:13",
                   help="applied field steps [T]: START:STOP:COUNT or comma-separated, "
                        "increasing")
    p.add_argument("--law", default=DEFAULT_LAW, choices=LAW_NAMES,
                   help="magnetization law of one particle")
    p.add_argument("--matrix-E", dest="matrix_E",
                   type=float_in("--matrix-E", 1e2, 1e10, "Pa"), default=None,
                   help="matrix Young's modulus [Pa] (default: the --matrix-material's, "
                        f"seed-paper {PDMS.E_Pa:g})")
    p.add_argument("--matrix-nu", dest="matrix_nu",
                   type=POISSON_RANGE.arg("--matrix-nu"),
                   default=None, help="matrix Poisson's ratio [-] (default: the "
                                      f"--matrix-material's, seed-paper {PDMS.nu:g})")
    p.add_argument("--boundary", choices=("free", "strain"), default="free",
                   help="zero mean stress (free magnetostriction) or the prescribed mean "
                        "strain --mean-strain (default zero: clamped)")
    p.add_argument("--mean-strain", dest="mean_strain", default=None,
                   help="with --boundary strain: prescribed mean strain xx,yy,zz,yz,xz,xy "
                        "(tensor components, |each| <= 0.1) [-]; unset: zero")
    p.add_argument("--voxels", type=int_in("--voxels", 8, 96), default=32,
                   help="voxels per edge of the cell FEM on the relaxed RVE")
    p.add_argument("--elastic-model", dest="elastic_model", choices=("green", "fem"),
                   default="green", help="matrix response: periodic Green's function (fast) or "
                                         "voxel FEM")
    p.add_argument("--near-field", dest="near_field", choices=("on", "off"), default="off",
                   help="near-field magnetic forces beyond point dipoles: exact two-sphere "
                        "(multipole) force minus the point-dipole force for pairs closer than "
                        "two mean radii; pairwise, chord permeability of the law (capped at "
                        "1000), so it overrates saturating particles near contact")
    p.add_argument("--max-substep-halvings", dest="max_substep_halvings",
                   type=int_in("--max-substep-halvings", 0, 20), default=5,
                   help="halvings of the field increment allowed per step when a step does "
                        "not converge (0: no sub-stepping)")
    p.add_argument("--json", required=True, help="result JSON file")
    p.add_argument("--out", default=None, help="write the relaxed RVE (HDF5) here")
    p.add_argument("--png", default=None, help="plot of strain and displacement against B")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_material_options(p, particle=False,
                         what="--matrix-material fills --matrix-E, --matrix-nu (the particles "
                              "come with the RVE file).")
    p.set_defaults(func=_cmd, outputs=("json", "out", "png"), inputs=("rve",))
