"""``mapsim specimen``: the change of length of a finite specimen (sphere, spheroid, cylinder)
in a uniform applied field, at finite strain (:func:`homogenize.macro.specimen.solve_specimen`)."""
from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from micro.common.files import atomic_path, manifest, write_json
from micro.common.validate import ConvergenceError, InputError
from micro.materials import POISSON_RANGE

from homogenize.cli._common import (check_input_file, config_of, float_in, int_in,
                                    json_ready, parse_at, parse_values)
from homogenize.experiments.rve_tables import affine_kappa
from homogenize.macro import finite_strain as fs
from homogenize.macro import magnetostatics as ms
from homogenize.macro._specimen_output import plot_specimen_strains, write_specimen_vtu
from homogenize.macro.specimen import GEOMETRIES, MODELS, SHAPES, SHAPES_3D, SUPPORTS, \
    Specimen, check_gaps, solve_specimen, solve_specimen_on_magnet
from homogenize.cli._pullin import MAX_GAPS, permanent_magnet
from homogenize.cli.cmd_relax import _steps as _field_steps   # the project's --B syntax

__all__ = ["register"]

_DOC = """\
The specimen in its field: what a magnetostriction experiment measures, the change of LENGTH
of a finite body between its end faces (or poles), not the volume-mean strain of an RVE. The
field in and around the body (axisymmetric FEM, exact exterior by the Kelvin transformation,
the composite's law M(H) by Newton) and the finite-strain, nearly incompressible neo-Hookean
body (Taylor-Hood u-p) are solved in turn on the DEFORMED body until the change of length
stops changing, field step after field step. Magnetic loads: Kelvin's, as the traction
[(mu0/2)(M.n)^2 + psi] n on the current surface plus the stress psi I, psi = mu0 int_0^H M dh.

Models: continuum -- the Kelvin loads only (the continuum models of Lefevre, Danas &
Lopez-Pamies 2017, Stewart & Anand 2025); affine -- plus the particles' microstructural stress
kappa mu0 |M|^2 (mm - I/3) of randomly dispersed particles moving with the matrix, kappa(phi,
m = |M|/(phi Ms)) from the project's cell FEM (needs --phi and --particle-Ms-A-per-m);
relaxed -- the same stress with the kappa of RVEs whose particles restructure in the field:
give it with --kappa; it must come from relax tables (`mapsim relax`), this command does not
compute it.

The law parameters (--chi, or --chi0 with --Ms-A-per-m) are those of the COMPOSITE (its M(H)
measured or from `mapsim homogenize`), not of the particles. Or the law from the project's own
RVEs: --law table (M_eff of a `mapsim batch` table at --phi against its B_T, the internal field
of the metallic-boundary RVE; --table-bound low/high for the ends of its interval; never
extrapolated: a field beyond the table is refused) or --law rve (self-consistent dipoles in 3
random RVEs of 100 particles of --particle-material at --phi, tabulated up to 1.5 x the largest
--B; about 10-30 s). The body's elasticity: its shear
modulus, or Young's modulus with Poisson's ratio (default 0.499: nearly incompressible,
K = 500 G; 0.5 itself is not accepted).

A cylinder's rim is rounded (--edge-radius-m, default 0.1 R): at a sharp edge the field and
the Kelvin loads are singular and the rubber strains without bound at finite field; a real
specimen's edge has some radius, and the results' sensitivity to it is part of their model
error.

Verification (tests/homogenize/macro/test_specimen.py): Lamb's sphere, pole strain 5/57 and
mean strain 1/15 of mu0 M^2/G within 1 %; a cylinder L/D = 0.8, mean strain against the
virtual work of its demagnetizing energy within 1.5 % at 128 boundary segments, converging at
first order in the field mesh. --geometry 3d (a cylinder or a box): the 3D cylinder agrees
with the axisymmetric solve within its discretization error (tests/homogenize/macro/
test_specimen.py); its --vtu holds the whole body (the octant mirrored, quadratic
tetrahedra).

In the field of a magnet (--magnet cylinder --magnet-size DIAMETER HEIGHT --remanence-T BR
--gap-m GAPS, instead of --B): a --shape cylinder (axisymmetric) resting on a rigid
frictionless plate (--support plate: u_z = 0 on its bottom face, u_r free; or free) above a
coaxial cylindrical permanent magnet magnetized along the axis (magpylib's field). The field
steps are the gaps between the magnet's top face and the specimen's bottom face, > 0 and
strictly decreasing (the magnet approached). The same Kelvin loads (f = mu0 (M.grad)H = grad
psi in any curl-free field with M parallel to H); per gap the JSON adds gap_m, B_applied_T and
gradB_applied_T_per_m (mu0 H_a,z and its axial gradient at the centre), reaction_N (the plate
on the body, > 0 up), kelvin_force_N and maxwell_force_N (the net magnetic force by the Kelvin
loads and by the Maxwell stress on a shell between the body and the magnet; null when no shell
fits) and a setup block (support, magnet). Verified (tests/homogenize/macro/
test_specimen_magnet.py): reaction against Maxwell within 0.6 %, the dipole limit of a small
weak specimen within 1.2 %.

Prints one line per field step and writes (each optional) --json (per step: B_applied_T,
M_mean_A_per_m, H_mean_A_per_m, demag_factor, changes of length and strains on the axis and
between the end-face means, diameter change and lateral strain, volume-mean axial strain,
staggered and Newton iterations, volume change; a manifest), --png (strains against B) and
--vtu (the deformed mechanics mesh of the last step with displacement and mean stress, for
ParaView)."""

_LAWS = ("linear", "froehlich-kennelly", "langevin", "tanh", "table", "rve")

# Ranges (exit 2 at parse time): wide enough for any real specimen and composite, narrow
# enough that a typo (a 1e30 Pa modulus, a 1 km specimen) is caught before meshing.
_SIZE = float_in("--radius-m", 0.0, 10.0, "m", lo_open=True)
_LEN = float_in("--length-m", 0.0, 10.0, "m", lo_open=True)
_EDGE = float_in("--edge-radius-m", 0.0, 10.0, "m")
_CHI = float_in("--chi", 0.0, 1e6)
_CHI0 = float_in("--chi0", 0.0, 1e6, lo_open=True)
_MS = float_in("--Ms-A-per-m", 0.0, 1e7, "A/m", lo_open=True)
_G = float_in("--shear-modulus-Pa", 1.0, 1e12, "Pa")
_E = float_in("--matrix-E-Pa", 1.0, 1e12, "Pa")
_NU = POISSON_RANGE.arg("--nu")
_PHI = float_in("--phi", 0.0, 0.74, lo_open=True)
_PMS = float_in("--particle-Ms-A-per-m", 0.0, 1e7, "A/m", lo_open=True)
_KAPPA = float_in("--kappa", -100.0, 100.0)
_TOL = float_in("--tol", 0.0, 0.1, lo_open=True)
_RELAX = float_in("--relaxation", 0.0, 1.0, lo_open=True)
#: the largest applied field accepted [T]: beyond any laboratory magnet; a larger value is a
#: typo (mT given as T)
_B_MAX_T = 50.0
#: the field steps without --B (and without --magnet)
_B_DEFAULT = "0:1.2:13"
_MAG = float_in("--magnet-size", 0.0, 10.0, "m", lo_open=True)
_BR = float_in("--remanence-T", 0.0, 3.0, "T", lo_open=True)


def _gaps(text: str) -> np.ndarray:
    """--gap-m (one value, START:STOP:COUNT or comma-separated) -> gaps [m], > 0, strictly
    decreasing."""
    g = parse_values(text, "--gap-m", "m", max_count=MAX_GAPS)
    try:
        return check_gaps(g)
    except InputError as exc:
        raise InputError(f"--gap-m: {exc}") from None


def _magnet(args):
    """--magnet cylinder with its size, remanence and --gap-m steps: (PermanentMagnet, gaps),
    or None (the uniform --B)."""
    if args.magnet is None:
        for flag, v in (("--magnet-size", args.magnet_size), ("--remanence-T", args.remanence_T),
                        ("--gap-m", args.gap_m), ("--support", args.support)):
            if v is not None:
                raise InputError(f"{flag} belongs to --magnet cylinder (a magnet below the "
                                 "specimen), not to the uniform --B")
        return None
    if args.B is not None:
        raise InputError("--B (a uniform applied field) and --magnet (the field of a magnet, "
                         "stepped by --gap-m) exclude each other")
    if args.geometry != "axisymmetric" or args.shape != "cylinder":
        raise InputError("--magnet: the specimen on a plate above a coaxial magnet is an "
                         f"axisymmetric --shape cylinder, not --geometry {args.geometry} "
                         f"--shape {args.shape}")
    if args.gap_m is None:
        raise InputError("--magnet cylinder needs --gap-m [m] (the gaps between the magnet's "
                         "top face and the specimen's bottom face, decreasing)")
    gaps = _gaps(args.gap_m)
    ns = argparse.Namespace(**vars(args))
    ns.magnet_direction = ns.magnet_axis = (0.0, 0.0, 1.0)
    magnet = permanent_magnet(ns, (0.0, 0.0, -1.0))
    if args.support is None:
        args.support = "plate"
    return magnet, gaps


def _magnet_B_max_T(magnet, gaps) -> float:
    """|B| [T] of the magnet at the specimen's bottom face at the smallest gap: the largest
    applied field the specimen sees (the range of a --law table or rve)."""
    from homogenize.macro.magnets import PermanentMagnet, sample_field
    m = PermanentMagnet("cylinder", magnet.dimensions_m, magnet.remanence_T,
                        (0.0, 0.0, -float(gaps[-1]) - 0.5 * magnet.dimensions_m[1]))
    return float(np.linalg.norm(sample_field(m, np.zeros((1, 3)))[0]))


def _steps(text: str) -> np.ndarray:
    """--B (one value or START:STOP:COUNT or comma-separated) -> increasing steps [T]."""
    B = _field_steps(text)
    if B.size > 1000:
        raise InputError(f"--B: at most 1000 field steps, got {B.size}")
    if not np.all(np.isfinite(B)) or B[0] < 0.0 or B[-1] > _B_MAX_T or np.any(np.diff(B) <= 0):
        raise InputError(f"--B: the applied field steps mu0 H0 must be finite, >= 0 T, at most "
                         f"{_B_MAX_T:g} T and increase strictly, got {text!r}")
    return B


def _law_from_data(args, B_max_T):
    """--law table (a batch table's M_eff at --phi) or rve (dipole RVEs of --particle-material
    at --phi): the composite's M(H_in) as a TableLaw, never extrapolated."""
    if args.phi is None:
        raise InputError(f"--law {args.law} needs --phi (the particle volume fraction)")
    if args.law == "table":
        if args.table is None:
            raise InputError("--law table needs --table T.h5 (a batch table with M_eff along "
                             "B_T)")
        from homogenize.macro.effective import magnetization_table_law
        from homogenize.tables.batch import read_table
        check_input_file("--table", args.table, 4 * 2 ** 30)
        return magnetization_table_law(read_table(args.table), args.phi,
                                       bound=args.table_bound, **parse_at(args.table_at))
    from homogenize.experiments.specimen_account import TABLE_HEADROOM, composite_law
    from micro.materials import particle_preset
    pre = particle_preset(args.particle_material or "seed-paper")
    sigma = pre.core_sigma_Am2_kg if pre.core_sigma_Am2_kg is not None \
        else pre.powder_sigma_Am2_kg

    class _Particles:              # what composite_law reads of a particle description
        density_kg_m3 = pre.density_kg_m3
        sigma_s_Am2_kg = sigma
        radius_mean_m = pre.mean_radius_m
    law, _, _ = composite_law(args.phi, _Particles, B_max_T=max(TABLE_HEADROOM * B_max_T, 0.1))
    return law


def _law(args, B_max_T=1.0):
    if args.law != "table" and (args.table is not None or args.table_bound != "mean"
                                or args.table_at is not None):
        raise InputError(f"--table, --table-bound and --at belong to --law table, not --law "
                         f"{args.law}")
    if args.law != "rve" and args.particle_material is not None:
        raise InputError(f"--particle-material belongs to --law rve, not --law {args.law}")
    if args.law in ("table", "rve"):
        extra = [k for k, v in (("--chi", args.chi), ("--chi0", args.chi0),
                                ("--Ms-A-per-m", args.Ms_A_per_m)) if v is not None]
        if extra:
            raise InputError(f"--law {args.law} takes its law from data, not {', '.join(extra)}")
        return _law_from_data(args, B_max_T)
    given = {"--chi": args.chi, "--chi0": args.chi0, "--Ms-A-per-m": args.Ms_A_per_m}
    need = ("--chi",) if args.law == "linear" else ("--chi0", "--Ms-A-per-m")
    missing = [k for k in need if given[k] is None]
    if missing:
        raise InputError(f"--law {args.law} needs {' and '.join(need)} (the composite's law "
                         f"parameters); missing {', '.join(missing)}")
    extra = [k for k, v in given.items() if v is not None and k not in need]
    if extra:
        raise InputError(f"--law {args.law} takes {' and '.join(need)}, not "
                         f"{', '.join(extra)}")
    if args.law == "linear":
        return ms.linear(args.chi)
    make = {"froehlich-kennelly": ms.froehlich_kennelly, "langevin": ms.langevin,
            "tanh": ms.tanh}[args.law]
    return make(args.chi0, args.Ms_A_per_m)


def _solid(args):
    if (args.shear_modulus_Pa is None) == (args.matrix_E_Pa is None):
        raise InputError("give the body's stiffness: --shear-modulus-Pa [Pa] or --matrix-E-Pa "
                         "[Pa] (with --nu), one of them")
    G = (args.shear_modulus_Pa if args.shear_modulus_Pa is not None
         else args.matrix_E_Pa / (2.0 * (1.0 + args.nu)))
    return fs.NeoHookeanSolid.from_poisson(G, args.nu)


def _kappa(args):
    if args.model != "affine" and args.particle_Ms_A_per_m is not None:
        raise InputError(f"--particle-Ms-A-per-m belongs to --model affine, not "
                         f"--model {args.model}")
    if args.model != "affine" and args.phi is not None and args.law not in ("table", "rve"):
        raise InputError(f"--phi belongs to --model affine or --law table/rve, not --model "
                         f"{args.model} with --law {args.law}")
    if args.model != "relaxed" and args.kappa is not None:
        raise InputError(f"--kappa belongs to --model relaxed, not --model {args.model}")
    if args.model == "affine":
        if args.phi is None or args.particle_Ms_A_per_m is None:
            raise InputError("--model affine needs --phi (particle volume fraction, (0, 0.74]) "
                             "and --particle-Ms-A-per-m (the particles' saturation, A/m)")
        return affine_kappa(args.phi, args.particle_Ms_A_per_m)
    if args.model == "relaxed":
        if args.kappa is None:
            raise InputError("--model relaxed needs --kappa [-], the microstructural stress "
                             "coefficient of relaxed RVEs: it must come from relax tables "
                             "(`mapsim relax`), this command does not compute it")
        return args.kappa
    return None


def _specimen(args):
    three_d = args.geometry == "3d"
    if three_d and args.shape not in SHAPES_3D:
        raise InputError(f"--geometry 3d takes --shape {' or '.join(SHAPES_3D)}, not "
                         f"{args.shape}")
    if not three_d and args.shape not in SHAPES:
        raise InputError(f"--shape {args.shape} is not a body of revolution: add --geometry 3d")
    if three_d and args.n_boundary is not None:
        raise InputError("--n-boundary belongs to the axisymmetric field mesh; the 3D field "
                         "mesh is built from the mechanics mesh (--n-mesh)")
    if args.shape == "sphere" and args.length_m is not None:
        raise InputError("--length-m is not taken for --shape sphere (its length is 2 R); use "
                         "--shape spheroid for another length")
    if args.shape != "sphere" and args.length_m is None:
        raise InputError(f"--shape {args.shape} needs --length-m [m] (its length along the "
                         "field)")
    if args.shape not in ("cylinder", "box") and args.edge_radius_m is not None:
        raise InputError(f"--edge-radius-m is for a cylinder's rim or a box's edges, not "
                         f"--shape {args.shape}")
    if args.edge_radius_m is not None and \
            args.edge_radius_m >= 0.5 * min(args.radius_m, 0.5 * args.length_m):
        raise InputError(f"--edge-radius-m must be in [0, {0.5 * args.radius_m:g}) m and below "
                         f"half the half-length ({0.25 * args.length_m:g} m), got "
                         f"{args.edge_radius_m:g}")
    if three_d:
        return Specimen(args.shape, args.radius_m, args.length_m, n_mesh=args.n_mesh,
                        edge_radius_m=args.edge_radius_m, geometry="3d")
    return Specimen(args.shape, args.radius_m, args.length_m, n_mesh=args.n_mesh,
                    n_boundary=48 if args.n_boundary is None else args.n_boundary,
                    edge_radius_m=args.edge_radius_m)


def _f(v, width: int) -> str:
    """``v`` in ``width`` columns, ``-`` where it is undefined (None, NaN)."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return format("-", f">{width}")
    return format(v, f"{width}.4e")


def _cmd(args) -> int:
    # everything checked before any work
    mag = _magnet(args)
    B = _steps(args.B if args.B is not None else _B_DEFAULT) if mag is None else None
    spec = _specimen(args)
    solid = _solid(args)
    kappa = _kappa(args)
    law = _law(args, float(B[-1]) if mag is None else _magnet_B_max_T(*mag))
    t0 = time.perf_counter()
    unit = "T" if mag is None else "m gap"

    def progress(i, n, b):
        if not args.quiet:
            print(f"[specimen] field step {i}/{n} at {b:.4g} {unit} done "
                  f"({time.perf_counter() - t0:.1f} s)", file=sys.stderr, flush=True)

    common = dict(model=args.model, kappa=kappa, tol=args.tol, max_stagger=args.max_stagger,
                  relaxation=args.relaxation, load_steps=args.load_steps, progress=progress)
    try:
        if mag is None:
            res = solve_specimen(spec, law, solid, B, **common)
        else:
            magnet, gaps = mag
            res = solve_specimen_on_magnet(spec, law, solid, *magnet.dimensions_m,
                                           magnet.remanence_T, gaps, support=args.support,
                                           **common)
    except ConvergenceError as exc:
        hist = ", ".join(f"{h:.3g}" for h in exc.residual_history) or "-"
        print(f"mapsim specimen: residual history (relative): {hist}", file=sys.stderr)
        done = getattr(exc, "steps_converged", ())
        if done:
            print("mapsim specimen: converged before it (not written): " + "; ".join(
                (f"gap {st.gap_m:g} m" if mag is not None else f"{st.B_applied_T:g} T")
                + f" axis strain {st.strain_axis:.4e}" for st in done),
                file=sys.stderr)
        raise
    seconds = time.perf_counter() - t0
    out = json_ready(res.to_dict())
    out["specimen"]["edge_radius_m"] = float(spec.edge_radius_m)
    out["solid"] = {"shear_modulus_Pa": solid.G_Pa, "bulk_modulus_Pa": solid.K_Pa,
                    "poisson_ratio": args.nu,
                    "from": "--shear-modulus-Pa" if args.shear_modulus_Pa is not None
                    else "--matrix-E-Pa"}
    if args.model == "relaxed":
        out["kappa"] = {"value": args.kappa, "source": "given (--kappa; from relax tables)"}
    elif args.model == "affine":
        out["kappa"] = {"phi": args.phi, "particle_Ms_A_per_m": args.particle_Ms_A_per_m,
                        "source": "affine_kappa: cell FEM of dispersed particles"}
    out["seconds"] = seconds
    out["manifest"] = manifest(config_of(args), None)
    written = []
    if args.json:
        write_json(args.json, out)
        written.append(args.json)
    if args.png:
        fig = plot_specimen_strains(out)
        with atomic_path(args.png) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
        written.append(args.png)
    if args.vtu:
        write_specimen_vtu(args.vtu, res)
        written.append(args.vtu)
    if mag is not None:
        return _print_magnet(args, spec, solid, res, out, seconds, written)
    print(f"{'B [T]':>8} {'<M> [A/m]':>11} {'axis strain':>12} {'end-mean':>11} "
          f"{'lateral':>11} {'mean e_zz':>11} {'stagger':>7} {'newton':>6}")
    for s in out["steps"]:
        print(f"{s['B_applied_T']:8.4g} {s['M_mean_A_per_m']:11.5g} "
              f"{_f(s['strain_axis'], 12)} {_f(s['strain_end_mean'], 11)} "
              f"{_f(s['lateral_strain'], 11)} {_f(s['mean_strain_zz'], 11)} "
              f"{s['stagger_iterations']:7d} {s['newton_iterations']:6d}")
    last = res.steps[-1]
    rim = (f", rim radius {spec.edge_radius_m:g} m" if spec.shape == "cylinder" else "")
    print(f"{spec.shape} L/D = {spec.aspect_ratio:.4g}{rim}, model {args.model}, {res.law}, "
          f"G = {solid.G_Pa:.4g} Pa, nu = {args.nu:g}: strain on the axis "
          f"{last.strain_axis:.4e} at {last.B_applied_T:g} T; {len(res.steps)} field steps in "
          f"{seconds:.1f} s" + (f"; wrote {', '.join(map(str, written))}" if written else ""))
    return 0


def _print_magnet(args, spec, solid, res, out, seconds, written) -> int:
    """The table of a --magnet run: per gap the applied field at the centre, the strains, the
    plate's reaction and the net magnetic force (Maxwell stress; Kelvin where no shell fits)."""
    print(f"{'gap [m]':>9} {'B_a [T]':>8} {'<M> [A/m]':>11} {'axis strain':>12} "
          f"{'lateral':>11} {'reaction [N]':>13} {'Maxwell [N]':>12} {'Kelvin [N]':>12} "
          f"{'stagger':>7}")
    for s in out["steps"]:
        print(f"{s['gap_m']:9.4g} {s['B_applied_T']:8.4g} {s['M_mean_A_per_m']:11.5g} "
              f"{_f(s['strain_axis'], 12)} {_f(s['lateral_strain'], 11)} "
              f"{_f(s['reaction_N'], 13)} {_f(s['maxwell_force_N'], 12)} "
              f"{_f(s['kelvin_force_N'], 12)} {s['stagger_iterations']:7d}")
    last = res.steps[-1]
    D, H = res.setup["magnet"]["diameter_m"], res.setup["magnet"]["height_m"]
    where = "on a plate" if args.support == "plate" else "free (no support)"
    print(f"cylinder L/D = {spec.aspect_ratio:.4g} {where} above a magnet "
          f"{D:g} x {H:g} m (B_r {args.remanence_T:g} T), model {args.model}, {res.law}, "
          f"G = {solid.G_Pa:.4g} Pa: at the gap {last.gap_m:g} m the magnet pulls with "
          f"{-last.kelvin_force_N:.4g} N, strain on the axis {last.strain_axis:.4e}; "
          f"{len(res.steps)} gaps in {seconds:.1f} s"
          + (f"; wrote {', '.join(map(str, written))}" if written else ""))
    return 0


def register(sub, formatter) -> None:
    """Add the ``specimen`` command."""
    p = sub.add_parser("specimen", formatter_class=formatter, description=_DOC,
                       help="change of length of a finite specimen in a uniform field "
                            "(finite strain, axisymmetric or 3D)")
    g = p.add_argument_group("specimen")
    g.add_argument("--shape", required=True, choices=tuple(dict.fromkeys(SHAPES + SHAPES_3D)),
                   help="body of revolution about the field axis, or (--geometry 3d) a "
                        "cylinder or a box (square cross-section of side 2 x --radius-m)")
    g.add_argument("--geometry", choices=GEOMETRIES, default="axisymmetric",
                   help="axisymmetric (meridian meshes, fast) or 3d (an eighth of the body and "
                        "of the space around it, three symmetry planes; minutes)")
    g.add_argument("--radius-m", dest="radius_m", type=_SIZE, required=True,
                   help="radius R (equatorial radius of a spheroid) [m]")
    g.add_argument("--length-m", dest="length_m", type=_LEN, default=None,
                   help="length along the field, end face to end face or pole to pole [m] "
                        "(spheroid, cylinder; not for a sphere)")
    g.add_argument("--edge-radius-m", dest="edge_radius_m", type=_EDGE, default=None,
                   help="a cylinder's rim rounded with this radius [m]; unset: 0.1 R; 0: a "
                        "sharp edge (its singular loads fail the mechanics at finite field on "
                        "fine meshes)")
    g = p.add_argument_group("material (the composite)")
    g.add_argument("--law", required=True, choices=_LAWS,
                   help="the composite's magnetization law M(H): a closed form with its "
                        "parameters, 'table' (M_eff of a batch table against its B_T = mu0 "
                        "H_in, at --phi; never extrapolated) or 'rve' (self-consistent dipoles "
                        "in 3 random RVEs of 100 particles of --particle-material at --phi)")
    g.add_argument("--table", default=None,
                   help="batch table (HDF5) with M_eff_A_per_m along B_T (--law table)")
    g.add_argument("--table-bound", dest="table_bound", choices=("mean", "low", "high"),
                   default="mean", help="which end of the table's confidence interval of "
                                        "M_eff (--law table; run low and high for the "
                                        "interval of the strains)")
    g.add_argument("--at", dest="table_at", default=None, metavar="AXIS=VALUE,...",
                   help="values of the table's other grid axes (--law table), e.g. "
                        "arrangement=dispersed")
    g.add_argument("--particle-material", dest="particle_material", default=None,
                   help="particle preset of micro.materials (--law rve; default seed-paper)")
    g.add_argument("--chi", type=_CHI, default=None,
                   help="susceptibility [-] of --law linear (M = chi H)")
    g.add_argument("--chi0", type=_CHI0, default=None,
                   help="initial susceptibility [-] of the saturating laws")
    g.add_argument("--Ms-A-per-m", dest="Ms_A_per_m", type=_MS, default=None,
                   help="saturation magnetization of the composite [A/m] (saturating laws)")
    g.add_argument("--shear-modulus-Pa", dest="shear_modulus_Pa", type=_G, default=None,
                   help="shear modulus G of the body [Pa]")
    g.add_argument("--matrix-E-Pa", dest="matrix_E_Pa", type=_E, default=None,
                   help="instead of G: Young's modulus of the body [Pa] (G = E / 2(1 + nu); "
                        "taken as the body's modulus, no stiffening by the particles is added)")
    g.add_argument("--nu", type=_NU, default=0.499,
                   help="Poisson's ratio [-] in (-1, 0.5); 0.499 = nearly incompressible "
                        "(K = 500 G)")
    g = p.add_argument_group("field and model")
    g.add_argument("--B", default=None,
                   help="applied field mu0 H0 along the axis [T]: one value, START:STOP:COUNT "
                        f"or comma-separated; >= 0 and strictly increasing (default "
                        f"{_B_DEFAULT}; not with --magnet)")
    g.add_argument("--magnet", choices=("cylinder",), default=None,
                   help="instead of the uniform --B: a cylindrical permanent magnet (e.g. "
                        "NdFeB) coaxial below the specimen (--shape cylinder, axisymmetric), "
                        "magnetized along the axis, approached in --gap-m steps; the specimen "
                        "rests on a plate (--support)")
    g.add_argument("--magnet-size", dest="magnet_size", type=_MAG, nargs="+", default=None,
                   metavar="M", help="the magnet's DIAMETER HEIGHT [m]")
    g.add_argument("--remanence-T", dest="remanence_T", type=_BR, default=None,
                   help="the magnet's remanent polarization B_r [T] (NdFeB ~1.2-1.4)")
    g.add_argument("--gap-m", dest="gap_m", default=None,
                   help="magnet gaps [m], the field steps of --magnet: from the magnet's top "
                        "face to the specimen's bottom face (the plate and spacers between "
                        "them); one value, START:STOP:COUNT or comma-separated; > 0 and "
                        "strictly decreasing (the magnet approached)")
    g.add_argument("--support", choices=SUPPORTS, default=None,
                   help="with --magnet: plate (default; the bottom face on a rigid "
                        "frictionless plate, u_z = 0, its reaction reported) or free (no "
                        "support: the net force balanced by a uniform d'Alembert body force)")
    g.add_argument("--model", choices=MODELS, default="continuum",
                   help="continuum (Kelvin loads only), affine (+ microstructural stress of "
                        "dispersed particles: --phi, --particle-Ms-A-per-m), relaxed (+ the "
                        "stress of relaxed RVEs: --kappa from relax tables)")
    g.add_argument("--phi", type=_PHI, default=None,
                   help="particle volume fraction [-] (--model affine)")
    g.add_argument("--particle-Ms-A-per-m", dest="particle_Ms_A_per_m", type=_PMS,
                   default=None, help="saturation magnetization of the particles [A/m] "
                                      "(--model affine: m = |M| / (phi Ms))")
    g.add_argument("--kappa", type=_KAPPA, default=None,
                   help="microstructural stress coefficient [-] of --model relaxed; must come "
                        "from relax tables (`mapsim relax`)")
    g = p.add_argument_group("discretization and iteration")
    g.add_argument("--n-mesh", dest="n_mesh", type=int_in("--n-mesh", 2, 64), default=8,
                   help="elements along the radius of the mechanics mesh (quarter section)")
    g.add_argument("--n-boundary", dest="n_boundary", type=int_in("--n-boundary", 16, 1024),
                   default=None, help="segments of the field mesh along the body's meridian "
                                      "profile (the Kelvin loads converge at first order in "
                                      "it); axisymmetric only (default: 48)")
    g.add_argument("--tol", type=_TOL, default=1e-4,
                   help="relative change of the change of length at which a field step's "
                        "field-mechanics iteration stops [-]")
    g.add_argument("--max-stagger", dest="max_stagger", type=int_in("--max-stagger", 1, 200),
                   default=30, help="field-mechanics iterations per field step before exit 3")
    g.add_argument("--relaxation", type=_RELAX, default=1.0,
                   help="under-relaxation of the magnetic loads between iterations, (0, 1]")
    g.add_argument("--load-steps", dest="load_steps", type=int_in("--load-steps", 1, 64),
                   default=2, help="load increments of each mechanics (Newton) solve")
    g = p.add_argument_group("output")
    g.add_argument("--json", default=None, help="results per field step and a manifest (JSON)")
    g.add_argument("--png", default=None, help="figure of the strains against the applied "
                                               "field")
    g.add_argument("--vtu", default=None, help="the deformed mechanics mesh of the last field "
                                               "step (VTU: displacement, mean stress)")
    g.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd, outputs=("json", "png", "vtu"), inputs=("table",))
