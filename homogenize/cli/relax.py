"""``mapsim relax``: particles that move -- the coupled magneto-mechanical equilibrium of an RVE
through increasing field steps (:func:`homogenize.relax.relax`)."""
from __future__ import annotations

import sys

import numpy as np

from micro._io import atomic_path, manifest, write_json
from micro._validate import InputError
from micro.magnetization import DEFAULT_LAW, LAW_NAMES
from micro.materials import PDMS, ElasticMaterial
from micro.rve import RVE

from homogenize.cli._common import config_of, float_in, int_in
from homogenize.relax import relax

_DOC = """\
Coupled magneto-mechanics of an RVE (HDF5 from `mapsim rve`): rigid particles in the elastic
matrix move under their magnetic forces, which are re-solved at the new positions, field step
by field step (Newton on the particle displacements, contact penalty), with the matrix response
from the periodic elastic Green's function of rigid spheres (fast) or the voxel FEM; then the
cell FEM on the relaxed RVE gives the free magnetostriction and the stiffness along and across
the field. The JSON has per field step B_T, strain_mag (3x3), M_eff_A_per_m,
E_eff_parallel_Pa, E_eff_perpendicular_Pa, min_gap_m, displacement_rms_m, iterations and the
microstructure descriptors. Not modelled: particle rotation, near-field forces beyond point
dipoles (--near-field on is refused)."""


def _steps(text: str) -> np.ndarray:
    """``"0:1.2:13"`` (start:stop:count) or ``"0,0.1,0.5"`` -> field steps [T]."""
    try:
        if ":" in text:
            a, b, n = text.split(":")
            n = int(n)
            if n < 1:
                raise ValueError
            return np.linspace(float(a), float(b), n)
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise InputError(f"--B must be START:STOP:COUNT or comma-separated values [T], got "
                         f"{text!r}") from None


def _cmd(args) -> int:
    steps = _steps(args.B)
    if args.near_field == "on":
        raise InputError("--near-field on: near-field forces beyond point dipoles are not "
                         "implemented (use off)")
    matrix = ElasticMaterial(args.matrix_E, args.matrix_nu)
    rve = RVE.load(args.rve)
    res = relax(rve, steps, law=args.law, matrix=matrix, boundary=args.boundary,
                voxels=args.voxels, elastic_model=args.elastic_model,
                progress=not args.quiet)
    out = res.to_dict()
    out["rve_file"] = str(args.rve)
    out["manifest"] = manifest(config_of(args), getattr(rve, "seed", None))
    write_json(args.json, out)
    if args.out:
        res.rve.save(args.out)
    if args.png:
        _plot(args.png, out)
    print(f"{'B [T]':>8} {'strain_zz':>11} {'M_eff [A/m]':>12} {'E_par [Pa]':>11} "
          f"{'E_perp [Pa]':>11} {'min gap [m]':>11} {'u_rms [m]':>10} {'it':>3}")
    for s in out["steps"]:
        sz = s["strain_mag"][2][2] if s.get("strain_mag") is not None else float("nan")
        print(f"{s['B_T']:8.3g} {sz:11.3e} {s['M_eff_A_per_m']:12.4g} "
              f"{(s.get('E_eff_parallel_Pa') or float('nan')):11.4g} "
              f"{(s.get('E_eff_perpendicular_Pa') or float('nan')):11.4g} "
              f"{s['min_gap_m']:11.3e} {s['displacement_rms_m']:10.3e} {s['iterations']:3d}")
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
                   type=float_in("--matrix-E", 1e2, 1e10, "Pa"), default=PDMS.E_Pa,
                   help="matrix Young's modulus [Pa]")
    p.add_argument("--matrix-nu", dest="matrix_nu",
                   type=float_in("--matrix-nu", -1.0, 0.5, "", lo_open=True, hi_open=True),
                   default=PDMS.nu, help="matrix Poisson's ratio [-]")
    p.add_argument("--boundary", choices=("free", "strain"), default="free",
                   help="zero mean stress (free magnetostriction) or zero mean strain")
    p.add_argument("--voxels", type=int_in("--voxels", 8, 96), default=32,
                   help="voxels per edge of the cell FEM on the relaxed RVE")
    p.add_argument("--elastic-model", dest="elastic_model", choices=("green", "fem"),
                   default="green", help="matrix response: periodic Green's function (fast) or "
                                         "voxel FEM")
    p.add_argument("--near-field", dest="near_field", choices=("on", "off"), default="off",
                   help="near-field magnetic forces beyond point dipoles (not implemented)")
    p.add_argument("--json", required=True, help="result JSON file")
    p.add_argument("--out", default=None, help="write the relaxed RVE (HDF5) here")
    p.add_argument("--png", default=None, help="plot of strain and displacement against B")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=_cmd, outputs=("json", "out", "png"), inputs=("rve",))
