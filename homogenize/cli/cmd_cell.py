"""``mapsim homogenize``: FEM homogenization of one RVE file."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from micro.common.files import manifest, write_json
from micro.common.validate import InputError, check_finite, check_positive
from micro.dipoles import solve
from micro.magnetization import DEFAULT_LAW, LAW_NAMES, get_law
from micro.materials import FE, PDMS, matrix_preset, particle_preset
from micro.materials import ElasticMaterial as Material
from micro.rve import RVE

from homogenize.voxels._budget import check_cheapest_cell_memory
from homogenize.tables.resolution import resolution_warning, voxels_per_radius
from homogenize.cell._output import plot_slice, write_pvd
from homogenize.cell.problem import CELL_RANGES, CellConfig, _choose_solver, homogenize_cell
from homogenize.cell.cut import check_cut_memory
from homogenize.cli.cmd_rve import _core_law_params
from homogenize.cli._common import (add_field_options, add_material_options, config_of,
                                    field_vector,
                                    fill_from_preset, float_in)
from homogenize.studies.cell_studies import (dilute_convergence_study, phi_study,
                                             plot_dilute_convergence, plot_phi_study)

_DESCRIPTION = """\
Periodic voxel FEM of an RVE (HDF5 written by `mapsim rve`): effective stiffness C_eff (6x6
Voigt, Pa), its isotropic projection E_eff, nu_eff, and -- with --B -- the magnetic load case:
effective body force f_eff [N/m^3], magnetic stress at zero mean strain stress_mag [Pa] and the
free magnetostrictive strain strain_mag = -C_eff^-1 stress_mag. The particle forces and the
pairwise virial stress come from micro.dipoles.solve. A manifest is written next to the JSON.
"""


# Ranges of the options (parse time, exit 2): the cell's own (homogenize.cell.problem.
# CELL_RANGES: moduli from soft gels to diamond, voxels, tol), checked where they are defined.
_R = CELL_RANGES
_VECTOR_LIMITS = {"gradB": 1e4}


def _check_voxels(opt: str, n: int) -> None:
    """Refuse a voxel grid whose memory estimate exceeds the machine, before any work (the
    project's memory model, homogenize.voxels._budget)."""
    check_cheapest_cell_memory(n, what=f"{opt} {n} ({n ** 3:.3g} voxels)")


def _parse_vec(text: str | None, name: str, unit: str):
    if text is None:
        return None
    try:
        vals = [float(v) for v in str(text).replace(",", " ").split()]
    except ValueError:
        raise InputError(f"--{name} must be a number or 3 comma-separated numbers [{unit}], "
                         f"got {text!r}") from None
    lim = _VECTOR_LIMITS.get(name, float("inf"))
    if not all(abs(v) <= lim for v in vals):          # also catches nan
        raise InputError(f"--{name} entries must be finite and in [-{lim:g}, {lim:g}] {unit}, "
                         f"got {text!r}")
    if len(vals) == 1:
        return vals[0]
    if len(vals) in (3, 9):
        arr = np.array(vals)
        check_finite(f"--{name}", arr, unit)
        return arr if len(vals) == 3 else arr.reshape(3, 3)
    raise InputError(f"--{name} must have 1, 3 (vector) or 9 (3x3 tensor, row-major) numbers "
                     f"[{unit}], got {len(vals)}")


def _cmd(args) -> int:
    solver = getattr(args, "solver", "fast")
    if solver == "matrix-free" and args.voxels % 2:
        raise InputError(f"--solver matrix-free needs an even --voxels (geometric multigrid), "
                         f"got {args.voxels}")
    # the solver's own memory model (the matrix-free one has no assembled fine matrix; "fast"
    # becomes "matrix-free" where only that one fits)
    n_cases = 7 if args.B_T is not None else 6
    try:
        solver = _choose_solver(solver, args.voxels, n_cases)
    except InputError as exc:       # name the option the user gave
        raise InputError(f"--voxels {args.voxels}: {exc}") from None
    if solver != "matrix-free":
        _check_voxels("--voxels", args.voxels)
    p, m = particle_preset(args.particle_material), matrix_preset(args.matrix_material)
    fill_from_preset(args, {"matrix_E": m.E_Pa, "matrix_nu": m.nu, "particle_E": p.E_Pa,
                            "particle_nu": p.nu})
    cfg = CellConfig(voxels=args.voxels, matrix=Material(args.matrix_E, args.matrix_nu),
                     particle=Material(args.particle_E, args.particle_nu), rigid=args.rigid,
                     method=args.method, tol=args.tol, solver=solver)
    field = None
    if args.B_T is not None:
        B = field_vector(args.B_T, args.B_direction)
        G = _parse_vec(args.gradB if args.gradB is not None else "0", "gradB", "T/m")
        core = dict(_core_law_params(args))           # a non-iron preset's core material
        law = get_law(args.law, **core) if core else args.law
        get_law(law)
        field = (B, G)
    elif args.gradB is not None:
        raise InputError("--gradB needs --B (the applied flux density [T])")
    rve = RVE.load(args.rve)
    vpr = voxels_per_radius(float(np.mean(rve.radii_m)), rve.box_m, args.voxels)
    warning = resolution_warning(float(np.mean(rve.radii_m)), rve.box_m, args.voxels)
    state = mag = None
    if field is not None:
        B, G = field
        state = solve(rve, B, G, law)
        mag = {"B_T": B, "gradB_T_per_m": G, "law": state.law,
               "virial_stress_Pa": np.asarray(state.virial_stress_Pa),
               "f_eff_dipoles_N_m3": np.asarray(state.f_eff_N_m3),
               "dipole_iterations": state.iterations}
    res = homogenize_cell(rve, state, cfg, keep_fields=bool(args.vtu or args.png),
                     progress=not args.quiet)
    if warning:                  # after the solve: a refused input stays one line
        print(f"mapsim homogenize: {warning}", file=sys.stderr)
    out = res.summary()
    out["rve_file"] = str(args.rve)
    out["voxels_per_radius"] = vpr      # mean particle radius in voxels (homogenize.tables.resolution)
    out["phi_rve"] = float(rve.phi)
    if mag is not None:
        out["magnetics"] = mag
    out["manifest"] = manifest(config_of(args), getattr(rve, "seed", None))
    case = "magnetic" if state is not None else "e11"
    if args.vtu:
        extra = {} if mag is None else {"B_T": mag["B_T"], "gradB_T_per_m": mag["gradB_T_per_m"],
                                        "law": mag["law"]}
        for f in write_pvd(args.vtu, res, **extra):
            if not args.quiet:
                print(f"wrote {f}", file=sys.stderr)
    if args.png:
        plot_slice(args.png, res, case)
    write_json(args.json, out)
    write_json(Path(args.json).with_name(Path(args.json).stem + ".manifest.json"), out["manifest"])
    if not args.quiet:
        print(f"E_eff = {res.E_eff_Pa:.6g} Pa, nu_eff = {res.nu_eff:.4f}, A^U = "
              f"{res.anisotropy_index:.3g}, {res.n_dof} DOF, iterations {res.iterations}",
              file=sys.stderr)
    return 0


def _cmd_phi_study(args) -> int:
    try:
        phis = [float(v) for v in args.phi.split(",")]
    except ValueError:
        raise InputError(f"--phi must be comma-separated numbers, got {args.phi!r}") from None
    for v in phis:
        if not 0.0 < v <= 0.45:
            raise InputError(f"--phi values must be in (0, 0.45] (volume fraction), got {v:g}")
    _check_voxels("--voxels", args.voxels)
    study = phi_study(phis, args.voxels, progress=not args.quiet, method=args.method)
    study["manifest"] = manifest({"phi": phis, "voxels": args.voxels})
    if args.png:
        plot_phi_study(args.png, study)
    write_json(args.json, study)
    return 0


def _cmd_dilute_study(args) -> int:
    try:
        ns = [int(v) for v in args.voxels.split(",")]
    except ValueError:
        raise InputError(f"--voxels must be comma-separated integers, got {args.voxels!r}") from None
    for n in ns:
        _R["voxels"].check("--voxels", n)
    if args.method == "cut":
        check_cut_memory(max(ns), f"--voxels {max(ns)} with --method cut")
    else:
        _check_voxels("--voxels", max(ns))
    if not 0.0 < args.phi <= 0.05:
        raise InputError(f"--phi must be in (0, 0.05] (a dilute volume fraction), got {args.phi:g}")
    check_positive("--particle-E", args.particle_E, "Pa")
    study = dilute_convergence_study(ns, args.phi, particle_E_Pa=args.particle_E,
                                     progress=not args.quiet, method=args.method)
    study["manifest"] = manifest({"voxels": ns, "phi": args.phi, "particle_E_Pa": args.particle_E,
                                  "method": args.method})
    if args.png:
        plot_dilute_convergence(args.png, study)
    write_json(args.json, study)
    if not args.quiet:
        print(f"observed rate {study['observed_rate']:.2f}, finest error vs dilute "
              f"{study['rows'][-1]['error_vs_dilute']:.3%}", file=sys.stderr)
    return 0


def register(sub, formatter):
    d = sub.add_parser("cell-dilute-study", formatter_class=formatter,
                       help="one dilute sphere refined: voxel FEM -> Eshelby, with the rate",
                       description="Shear stiffening coefficient (G_eff/G_m - 1)/phi of one sphere "
                                   "at dilute phi on refined voxel grids, against Eshelby's dilute "
                                   "result and Mori-Tanaka; observed rate and Richardson limit.")
    d.add_argument("--voxels", default="8,16,24,32,48,64",
                   help="comma-separated voxels per cube edge (default 8,16,24,32,48,64)")
    d.add_argument("--phi", type=float_in("--phi", 0.0, 0.05, lo_open=True), default=0.01,
                   help="particle volume fraction [1] (default 0.01)")
    d.add_argument("--particle-E", dest="particle_E",
                   type=_R["E_Pa"].arg("--particle-E"),
                   default=FE.E_Pa, help="particle Young's modulus [Pa] (default: Fe)")
    d.add_argument("--method", default="composite",
                   choices=("composite", "laminate", "centre", "fraction", "cut"),
                   help="voxels cut by the sphere surface (see mapsim homogenize --help); "
                        "'cut': Nitsche cut voxels, two displacement fields per cut voxel "
                        "(homogenize.cell.cut; second order; its memory grows ~13.5 kB per "
                        "node: 3.6 GB at 64^3)")
    d.add_argument("--json", required=True, type=Path, help="result JSON file")
    d.add_argument("--png", type=Path, default=None, help="plot file (PNG)")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    d.set_defaults(func=_cmd_dilute_study, outputs=("json", "png"))

    q = sub.add_parser("cell-phi-study", formatter_class=formatter,
                       help="E_eff vs phi: voxel FEM against dilute, Mori-Tanaka, Guth-Gold",
                       description="Simple cubic array of Fe spheres in PDMS: effective Young's "
                                   "modulus [Pa] from the voxel FEM and from closed forms.")
    q.add_argument("--phi", default="0.01,0.05,0.1,0.2,0.3",
                   help="comma-separated particle volume fractions [1]")
    q.add_argument("--voxels", type=_R["voxels"].arg("--voxels"),
                   default=24, help="voxels per cube edge")
    q.add_argument("--method", default="composite",
                   choices=("composite", "laminate", "centre", "fraction"),
                   help="voxels cut by a sphere surface (see mapsim homogenize --help)")
    q.add_argument("--json", required=True, type=Path, help="result JSON file")
    q.add_argument("--png", type=Path, default=None, help="plot file (PNG)")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    q.set_defaults(func=_cmd_phi_study, outputs=("json", "png"))

    p = sub.add_parser("homogenize", formatter_class=formatter, description=_DESCRIPTION,
                       help="FEM homogenization of an RVE: C_eff, E_eff, f_eff, magnetic stress")
    p.add_argument("rve", type=Path, help="RVE file (HDF5, from `mapsim rve`)")
    p.add_argument("--voxels", type=_R["voxels"].arg("--voxels"),
                   default=64, help=_R["voxels"].describe())
    add_field_options(p, help_B="applied flux density mu0 |H| [T], along --B-direction; enables "
                                "the magnetic load case (default: none)")
    p.add_argument("--gradB", default=None,
                   help="field gradient [T/m]: d|B|/dz scalar or 9 numbers dB_a/dx_b row-major "
                        "(default: 0 when --B is given)")
    p.add_argument("--law", default=DEFAULT_LAW, choices=LAW_NAMES,
                   help="magnetization law of one particle")
    p.add_argument("--matrix-E", dest="matrix_E", type=_R["E_Pa"].arg("--matrix-E"),
                   default=None,
                   help="matrix Young's modulus [Pa] (default: the --matrix-material's, "
                        f"seed-paper {PDMS.E_Pa:g})")
    p.add_argument("--matrix-nu", dest="matrix_nu",
                   type=_R["nu"].arg("--matrix-nu"),
                   default=None,
                   help="matrix Poisson's ratio [1], in (-1, 0.5) (default: the "
                        f"--matrix-material's, seed-paper {PDMS.nu:g})")
    p.add_argument("--particle-E", dest="particle_E",
                   type=_R["E_Pa"].arg("--particle-E"),
                   default=None,
                   help="particle Young's modulus [Pa] (default: the --particle-material's, "
                        f"seed-paper Fe {FE.E_Pa:g})")
    p.add_argument("--particle-nu", dest="particle_nu",
                   type=_R["nu"].arg("--particle-nu"),
                   default=None,
                   help="particle Poisson's ratio [1] (default: the --particle-material's, "
                        f"seed-paper Fe {FE.nu:g})")
    p.add_argument("--rigid", action="store_true", help="rigid particles (stiff limit)")
    p.add_argument("--method", default="composite",
                   choices=("composite", "laminate", "centre", "fraction"),
                   help="voxels cut by a particle surface: 'composite' (exact volume fraction, "
                        "Reuss average of Fe and PDMS: E_eff self-converged to 0.1-0.6 %% at "
                        "24^3, the default), 'laminate' (Kabel-Merkert-Schneider laminate along "
                        "the normal; overshoots with nodal elements), 'centre' (staircase: "
                        "voxel is particle if its centre is), 'fraction' (staircase from 4^3 "
                        "sub-samples)")
    p.add_argument("--tol", type=_R["tol"].arg("--tol"), default=1e-6,
                   help="CG relative residual per load case [1] (default 1e-6; C_eff and "
                        "stress_mag are variational: C_eff's error is ~ tol^2; the magnetic "
                        "case stops at sqrt(tol) unless --vtu/--png keep its field, stress_mag's "
                        "error is the product of the two: see results/cell/README.md)")
    p.add_argument("--solver", default="auto",
                   choices=("auto", "fast", "reference", "matrix-free"),
                   help="cell solver: 'auto' (default: 'matrix-free' on even --voxels for "
                        "dilute RVEs: particle volume fraction <= 0.06 and <= 100 particles or "
                        "particle patches; beyond them up to 0.15 with a patch on every "
                        "particle; else 'fast'; the choice and its reason are in the "
                        "result's settings), 'fast' (assembled matrix, AMG; switches "
                        "to matrix-free when the assembled matrix does not fit in memory), "
                        "'reference' (assembled, one load case at a time), 'matrix-free' (no "
                        "assembled fine matrix, geometric multigrid; even --voxels)")
    p.add_argument("--json", required=True, type=Path, help="result JSON file (written atomically)")
    p.add_argument("--vtu", type=Path, default=None,
                   help="write the local fields (displacement, stress in VTK order XX YY ZZ XY "
                        "YZ XZ, von Mises, phase) of every load case: FILE.pvd (a ParaView "
                        "collection, one step per load case) and FILE_<case>.vtu beside it")
    p.add_argument("--png", type=Path, default=None, help="write a slice figure (PNG)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and summary on stderr")
    add_material_options(p, what="--particle-material fills --particle-E, --particle-nu and "
                                  "the core material of the intrinsic magnetization laws (the "
                                  "particles' sizes and moments come with the RVE file); "
                                  "--matrix-material fills --matrix-E, --matrix-nu.")
    p.set_defaults(func=_cmd, outputs=("json", "vtu", "png"), inputs=("rve",))
