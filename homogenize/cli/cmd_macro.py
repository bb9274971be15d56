"""Commands of the macro layer: ``paper``, ``export``, ``beam``, ``channel``."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from micro.common.validate import InputError, check_positive

import numpy as np

from micro.demag import prism_demag_factors
from micro.materials import PDMS, POISSON_RANGE, SEED, matrix_preset, particle_preset

from homogenize.cli._pullin import GAP_HELP, gap_sweep, permanent_magnet
from homogenize.cli.cmd_channel_magnet import (CHANNEL_MAGNET_GROUP, CHANNEL_MAGNET_HELP,
                                               add_channel_magnet_options,
                                               channel_magnet_option_needs,
                                               run_channel_magnet)
from homogenize.cli._common import (add_magnet_options, add_material_options, check_memory,
                                    config_of,
                                    fill_from_preset, float_in, int_in, parse_at,
                                    write_snippet)
from homogenize.cli.cmd_tables import (add_beam_table_options, add_export_table_options,
                                   beam_from_table, wrap_export)
from homogenize.studies.paper import write_calculix_peer, write_paper
from homogenize.macro.exporters import (NLGEOM_FRACTION, NLGEOM_MODES, ExportSpec, export_text,
                                        magnet_body_force, write_deck)
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material
from homogenize.macro.channel import ChannelGeometry, solve_channel
from homogenize.macro.flow import (BLOOD_PLASMA, CeilingModel, Liquid, closure,
                                   field_for_target_gap,
                                   plot_channel_flow, solve_channel_flow)
from homogenize.macro.exporters import DIRECTIONS
from homogenize.macro.cantilever import MODELS
from homogenize.macro.convergence import converged_tip
from homogenize.macro.effective import magnetization_from_table, soft_sphere_magnetization
from homogenize.macro.magnets import Coil, PermanentMagnet, body_force_along_strip
from homogenize.tables.batch import body_force_from_table, read_table
from micro.common.files import atomic_path, manifest, write_json

__all__ = ["register"]

#: the strip length for which the converged 3D FEM bends 4 mm at the Abaqus value 40 kN/m^3
#: (``mapsim paper``; t = 1 mm, w = 5 mm assumed)
SEED_STRIP_LENGTH_M = 0.019369


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


def _paper_calculix(args) -> int:
    check_positive("width-m", args.width_m, "m")
    check_positive("thickness-m", args.thickness_m, "m")
    rep = write_calculix_peer(args.out, quick=args.quick, quiet=args.quiet,
                              width_m=args.width_m, thickness_m=args.thickness_m)
    worst = ", ".join(f"{e} {100 * v:.3f} %"
                      for e, v in rep["largest_relative_difference_by_element"].items())
    print(f"CalculiX against mapsim: {len(rep['twins'])} element/grid pairs; largest tip "
          f"difference by element: {worst}; results in {args.out}")
    return 0


def _export_magnet(args, geometry):
    """The magnet of ``export --deck cantilever --magnet ...``: (body force f(points), notes)."""
    if args.deck != "cantilever" or args.to != "abaqus":
        raise InputError("--magnet is written into the abaqus cantilever deck only (--to abaqus "
                         "--deck cantilever)")
    source = _magnet_source(args)
    bound = getattr(args, "bound", "mean")
    M_of_H, phi, law = _magnet_law(args, bound=bound)
    N = args.demag_factor if args.demag_factor is not None else \
        prism_demag_factors(geometry.length_m, geometry.width_m, geometry.thickness_m)[2]
    # checks the magnet against the strip (overlap) and the law's range along the strip
    bf = body_force_along_strip(source, geometry, M_of_H, n_points=21, demag_factor=N)
    notes = (f"magnet: {args.magnet} at {tuple(source.position_m)} m (strip frame [0, L] x "
             f"[0, w] x [0, t], clamp at x = 0); M_eff(H) from {law}, phi = {phi:g}, "
             f"demagnetizing factor N = {N:.4g}"
             + (f"; the {bound} end of the table's M_eff interval" if bound != "mean" else ""),
             f"net magnetic force on the undeformed strip {bf.total_force_N[2]:.6g} N along z "
             f"(cross-section average, Simpson on 21 stations)")
    return magnet_body_force(source, M_of_H, N), notes


def _export_run(args) -> int:
    """``export``: a magnet deck takes its law from --table itself; the rest as before. Without
    --table the --matrix-material fills E, nu and density not given; with it the table's E_eff,
    nu_eff and the mixture density come first (the matrix's where the table has none)."""
    if not getattr(args, "table", None) or getattr(args, "magnet", None) is not None:
        _fill_matrix(args)         # (a magnet deck takes only M_eff(H) from the table)
    if getattr(args, "magnet", None) is None:
        return wrap_export(_export)(args)
    if args.body_force_N_m3 is not None:
        raise InputError("give either --body-force-N-m3 or --magnet (its force varies over "
                         "the strip), not both")
    for dest, flag in (("B_T", "--B"), ("gradB_T_per_m", "--gradB")):
        if getattr(args, dest, None) is not None:
            raise InputError(f"{flag} is not used with --magnet (the magnet gives the field "
                             f"over the strip; --table is read at --phi along its B_T axis)")
    rc = _export(args)         # (--bound without --table is refused before, as for any export)
    if rc == 0 and args.table and args.bound == "mean" and args.deck is not None:
        print("the table's M_eff interval: write the decks at its ends with --bound low and "
              "--bound high (same options) and run all three")
    return rc


def _export(args) -> int:
    magnet = getattr(args, "magnet", None) is not None
    spec = ExportSpec(0.0 if magnet else args.body_force_N_m3, args.E_Pa, args.nu,
                      args.density_kg_m3, direction=args.direction,
                      gravity_m_s2=args.gravity_m_s2, name=args.name, elset=args.elset,
                      index=args.index)
    if args.deck is None:
        return write_snippet(export_text(spec, args.to), args.out, f"{args.to} snippet")
    if args.out == "-":
        raise InputError("--deck writes files: give --out FILE (.inp for abaqus, .sif for elmer)")
    if args.to == "elmer" and args.nlgeom == "on":
        raise InputError("--nlgeom on: the Elmer deck is linear (StressSolver); use --to abaqus")
    if args.deck == "cantilever":
        geometry = Strip(args.length_m, args.width_m, args.thickness_m)
    else:
        geometry = ChannelGeometry(args.a_m, args.b_m, args.c_m, args.d_m, args.wall_m)
    body_force, notes = _export_magnet(args, geometry) if magnet else (None, ())
    deck = write_deck(args.deck, args.to, spec, geometry, args.out, element=args.element,
                      nz=args.deck_nz, nlgeom=args.nlgeom, body_force=body_force,
                      notes=notes)
    for f in deck.files:
        print(f"wrote {f}")
    if args.to == "abaqus":
        print(f"{'geometrically nonlinear (NLGEOM)' if deck.nlgeom else 'linear'} step: linear "
              f"deflection estimate {deck.estimate_m:.4g} m (--nlgeom {args.nlgeom}; auto: "
              f"NLGEOM above {NLGEOM_FRACTION:g} of the thickness)")
        print(f"run it with CalculiX: ccx -i {Path(deck.path).with_suffix('')} "
              f"(tip node {deck.mesh.tip_node + 1}, set NTIP)")
    return 0


def _face_gap_m(source):
    """Gap between the strip's bottom face (z = 0) and the top face of a permanent magnet with
    its axis along z below it [m]; None for other sources."""
    if not isinstance(source, PermanentMagnet) or tuple(source.axis) != (0.0, 0.0, 1.0):
        return None
    half = 0.5 * (source.dimensions_m[2] if source.shape == "cuboid" else source.dimensions_m[1])
    top = source.position_m[2] + half
    return -top if top <= 0.0 else None


def _magnet_source(args):
    """The permanent magnet or coil of ``--magnet`` (None without it)."""
    if args.magnet is None:
        return None
    size = tuple(args.magnet_size or ())
    if args.magnet_position is None:
        raise InputError("--magnet needs --magnet-position X Y Z [m] (the strip occupies "
                         "[0, L] x [0, w] x [0, t])")
    if args.magnet == "coil":
        if len(size) != 2:
            raise InputError("--magnet coil needs --magnet-size RADIUS LENGTH [m]")
        if args.current_A is None or args.turns is None:
            raise InputError("--magnet coil needs --current-A and --turns")
        return Coil(size[0], size[1], args.turns, args.current_A, args.magnet_position,
                    tuple(args.magnet_axis))
    return permanent_magnet(args, args.magnet_position)


def _magnet_law(args, bound: str = "mean"):
    """M_eff(H) of the composite: from --table at --phi (``bound``: the mean or an end of the
    table's interval), or demagnetization-limited spheres."""
    phi = args.phi if args.phi is not None else SEED.c * SEED.d
    if args.table:
        return (magnetization_from_table(read_table(args.table), phi, bound=bound,
                                         **parse_at(args.table_at)), phi,
                "table" if bound == "mean" else f"table ({bound} end of its interval)")
    if args.particle_material == "seed-paper":
        return soft_sphere_magnetization(phi), phi, "soft spheres (dilute)"
    p = particle_preset(args.particle_material)
    return (soft_sphere_magnetization(phi, Ms_A_m=p.Ms_A_m), phi,
            f"soft spheres (dilute), {p.name} Ms {p.Ms_A_m:.4g} A/m")


def _fill_matrix(args) -> None:
    """--E-Pa, --nu, --density-kg-m3 not given: the --matrix-material's (the matrix alone:
    the particles' stiffening and weight come with --table, or give the composite's numbers)."""
    m = matrix_preset(args.matrix_material)
    fill_from_preset(args, {"E_Pa": m.E_Pa, "nu": m.nu, "density_kg_m3": m.density_kg_m3})


def _beam(args) -> int:
    _fill_matrix(args)
    _check_beam_size(args)
    if getattr(args, "table", None) and args.magnet is None:
        return beam_from_table(args)       # uniform force + interval from a batch table
    strip = Strip(args.length_m, args.width_m, args.thickness_m)
    mat = Material(args.E_Pa, args.nu, args.density_kg_m3)
    if args.gap_m is not None or args.gap_sweep_m is not None:
        if args.magnet is None:
            raise InputError("--gap-m / --gap-sweep-m need --magnet cuboid|cylinder (with "
                             "--magnet-size and --remanence-T)")
        M_of_H, phi, law = _magnet_law(args)
        N = args.demag_factor if args.demag_factor is not None else \
            prism_demag_factors(strip.length_m, strip.width_m, strip.thickness_m)[2]
        return gap_sweep(args, strip, mat, M_of_H, phi, law, N)
    source = _magnet_source(args)
    force, magnet = args.body_force_N_m3, None
    if source is not None:
        M_of_H, phi, law = _magnet_law(args)
        N = args.demag_factor if args.demag_factor is not None else \
            prism_demag_factors(strip.length_m, strip.width_m, strip.thickness_m)[2]
        bf = body_force_along_strip(source, strip, M_of_H, n_points=args.stations,
                                    demag_factor=N)
        force = bf.profile()
        magnet = {"source": vars(source) | {"kind": args.magnet}, "phi": phi,
                  "magnetization": law, "demag_factor": N, "x_m": bf.x_m,
                  "B_T": np.einsum("c,nci->ni", bf.weights, bf.B_T),
                  "body_force_N_m3": bf.transverse_N_m3, "total_force_N": bf.total_force_N}
        print(f"magnet: {args.magnet} at {tuple(source.position_m)} m; M_eff(H) from {law}, "
              f"phi = {phi:g}, strip demagnetizing factor N = {N:.4f}; body force "
              f"{bf.transverse_N_m3.min():.4g} .. {bf.transverse_N_m3.max():.4g} N/m^3 along the "
              f"strip, net {bf.total_force_N[2]:.4g} N along z")
    rows = []
    for model in args.model:
        if model == "fem" and args.nz is None:
            if source is not None:
                raise InputError("--magnet with --model fem needs --nz (the converged-mesh "
                                 "estimate takes a uniform force)")
            c = converged_tip(strip, mat, force, order=args.order, gravity_m_s2=args.gravity_m_s2)
            fine = c.meshes[-1]
            rows.append({"model": "fem", "tip_m": c.tip_m, "tip_horizontal_m": None,
                         "n_dof": fine[2], "divisions": list(fine[0]), "order": args.order,
                         "discretization_error_estimate_m": c.error_estimate_m,
                         "extrapolated_tip_m": c.extrapolated_m,
                         "meshes": [{"divisions": list(d), "tip_m": u, "n_dof": n}
                                    for d, u, n in c.meshes]})
            continue
        r = solve_cantilever(strip, mat, force, model=model, order=args.order,
                             nz=args.nz if args.nz is not None else 2,
                             gravity_m_s2=args.gravity_m_s2, n_steps=args.steps)
        rows.append(r.to_dict())
    if args.json:
        write_json(args.json, {"strip": vars(strip), "material": vars(mat), "results": rows,
                               "magnet": magnet,
                               "manifest": manifest(config_of(args), None)})
    face = _face_gap_m(source)
    if face is not None and any(r["tip_m"] >= face for r in rows):
        print(f"warning: a tip deflection reaches the magnet's face ({face:.4g} m below the "
              "strip): with the field of the undeformed strip (a dead load) the strip passes "
              "through the magnet; the real strip snaps to it -- use --gap-m / --gap-sweep-m "
              "(the field on the deformed strip, pull-in and contact)", file=sys.stderr)
    print(f"{'model':<12} {'tip [m]':>12} {'horizontal [m]':>15} {'dofs':>8}  mesh")
    for r in rows:
        mesh = "" if r.get("divisions") is None else f"{tuple(r['divisions'])} P{r['order']}"
        hor = "-" if r.get("tip_horizontal_m") is None else f"{r['tip_horizontal_m']:.6g}"
        print(f"{r['model']:<12} {r['tip_m']:12.6g} {hor:>15} {r['n_dof'] or 0:8d}  {mesh}"
              + (f"  (discretization error ~ {r['discretization_error_estimate_m']:+.2e} m, "
                 f"Richardson)" if "discretization_error_estimate_m" in r else ""))
    return 0


def _field_interval(table, phi, gradB, others, f_need, B_range, target):
    """The applied field that gives ``f_need`` at both ends of the table's force interval
    (the stronger force needs less field): ``(low, high)``, None for an end the table's B range
    does not reach."""
    from homogenize.macro.flow import _invert_field
    ends = []
    for end in ("ci_high", "ci_low"):
        try:
            ends.append(_invert_field(lambda B, end=end: getattr(body_force_from_table(
                table, phi, float(B), gradB, **others), end), f_need, B_range, "T", target))
        except InputError:
            ends.append(None)
    return tuple(ends)


def _table_field(args):
    """``(table, others, {body_force_of_field, field_range, field_unit})`` of --table."""
    for name, v in (("--phi", args.phi), ("--gradB", args.gradB_T_per_m)):
        if v is None:
            raise InputError(f"{name} is required with --table")
    table = read_table(args.table)
    B_axis = sorted(float(b) for b in table.axes.get("B_T", ()))
    if len(B_axis) < 2:
        raise InputError(f"{args.table}: needs at least two B_T values")
    others = parse_at(args.table_at)
    return table, others, {"body_force_of_field": lambda B: body_force_from_table(
        table, args.phi, float(B), args.gradB_T_per_m, **others).mean,
        "field_range": (B_axis[0], B_axis[-1]), "field_unit": "T"}


def _channel_closure(args, geo, mat) -> int:
    """``channel --close``: the body force (field) that shuts the channel, and where."""
    ceiling = CeilingModel.from_fem(geo, mat, nc=max(args.nc, 3), order=args.order)
    field = {}
    if args.table:
        table, others, field = _table_field(args)
    dp = args.pressure_drop_Pa or 0.0
    r = closure(ceiling, geo.d_m, pressure_drop_Pa=dp,
                outlet_pressure_Pa=args.outlet_pressure_Pa, **field)
    out = {"closure": r.to_dict()}
    interval = ""
    if r.field is not None:
        lo, hi = _field_interval(table, args.phi, args.gradB_T_per_m, others,
                                 r.body_force_N_m3, field["field_range"], 0.0)
        conf = body_force_from_table(table, args.phi, r.field, args.gradB_T_per_m,
                                     **others).confidence
        out["closure"]["field_interval_T"] = [lo, hi]
        out["closure"]["field_interval_confidence"] = conf
        interval = (f" = B {r.field:.4g} T ({100 * conf:g} % interval ["
                    + ", ".join("beyond the table's B range" if v is None else f"{v:.4g}"
                                for v in (lo, hi))
                    + f"] T, from the table's force interval) inside the polymer at phi "
                      f"{args.phi:g}, dB/dz {args.gradB_T_per_m:g} T/m")
    print(f"the channel shuts against {dp:.4g} Pa at body force {r.body_force_N_m3:.4g} N/m^3"
          f"{interval}: the ceiling touches the glass at the outlet (x = {r.x_contact_m:.4g} m), "
          f"y = {r.y_contact_m:.4g} m across the {geo.a_m:g} m channel")
    print(f"first contact (no pressure) at {r.body_force_first_contact_N_m3:.4g} N/m^3; a shut "
          f"channel holds {r.lift_off_Pa_per_N_m3:.4g} Pa more inlet pressure per extra N/m^3 "
          f"(ceiling model: {ceiling.source})")
    if args.json:
        out["manifest"] = manifest(config_of(args), None)
        write_json(args.json, out)
    return 0


def _channel(args) -> int:
    _fill_matrix(args)
    _check_channel_size(args)
    if getattr(args, "magnet", None) is not None:
        return run_channel_magnet(args)      # a real magnet below the glass (follower field)
    geo = ChannelGeometry(args.a_m, args.b_m, args.c_m, args.d_m, args.wall_m)
    mat = Material(args.E_Pa, args.nu, args.density_kg_m3)
    operating = (args.flow_rate_m3_s, args.pressure_drop_Pa)
    if args.target_gap_m is not None and operating == (None, None):
        raise InputError("--target-gap-m needs --flow-rate-m3-s or --pressure-drop-Pa")
    if args.close and (args.target_gap_m is not None or args.flow_rate_m3_s is not None
                       or args.png):
        raise InputError("--close takes --pressure-drop-Pa (the inlet pressure the shut channel "
                         "holds), not --target-gap-m, --png or --flow-rate-m3-s (a fixed flow "
                         "rate never shuts it: the inlet pressure rises to lift the ceiling)")
    if None not in operating:
        raise InputError("give either --flow-rate-m3-s or --pressure-drop-Pa, not both")
    out = {}
    if args.close:
        return _channel_closure(args, geo, mat)
    if operating == (None, None):        # the ceiling under the body force, no liquid
        r = solve_channel(geo, mat, args.body_force_N_m3, order=args.order, nc=args.nc,
                          gravity_m_s2=args.gravity_m_s2)
        out["result"] = r.to_dict()
        print(json.dumps({k: v for k, v in r.to_dict().items()
                          if not isinstance(v, (list, tuple))}, indent=1))
        if r.closes:
            print("note: the linear ceiling deflection exceeds the channel height b: the "
                  "channel closes (contact); the linear solution beyond contact is not "
                  "physical", file=sys.stderr)
    else:                                # what was asked: the flow (and the target gap)
        liquid = Liquid("given", args.viscosity_Pa_s, "--viscosity-Pa-s") \
            if args.viscosity_Pa_s is not None else BLOOD_PLASMA
        ceiling = CeilingModel.from_fem(geo, mat, nc=max(args.nc, 3), order=args.order)
        op = {"flow_rate_m3_s": args.flow_rate_m3_s, "pressure_drop_Pa": args.pressure_drop_Pa,
              "outlet_pressure_Pa": args.outlet_pressure_Pa, "liquid": liquid}
        if args.target_gap_m is not None:
            field = {}
            if args.table:         # the field B that gives the force, from the batch table
                table, others, field = _table_field(args)
            t = field_for_target_gap(ceiling, geo.d_m, args.target_gap_m, **op, **field)
            flow = t.flow
            out["target_gap"] = t.to_dict()
            interval = ""
            if t.field is not None:
                lo, hi = _field_interval(table, args.phi, args.gradB_T_per_m, others,
                                         t.body_force_N_m3, field["field_range"],
                                         args.target_gap_m)
                conf = body_force_from_table(table, args.phi, t.field, args.gradB_T_per_m,
                                             **others).confidence
                out["target_gap"]["field_interval_T"] = [lo, hi]
                out["target_gap"]["field_interval_confidence"] = conf
                interval = (f" ({100 * conf:g} % interval ["
                            + ", ".join("beyond the table's B range" if v is None
                                        else f"{v:.4g}" for v in (lo, hi))
                            + "] T, from the table's force interval)")
            print(f"target smallest gap {args.target_gap_m:.4g} m: body force "
                  f"{t.body_force_N_m3:.4g} N/m^3"
                  + ("" if t.field is None else
                     f" = B {t.field:.4g} T{interval} inside the polymer (the block's own "
                     f"demagnetization is not included) at phi {args.phi:g}, dB/dz "
                     f"{args.gradB_T_per_m:g} T/m (table {args.table})")
                  + f", reached at x = {t.x_target_m:.4g} m")
        else:
            flow = solve_channel_flow(ceiling, geo.d_m, body_force_N_m3=args.body_force_N_m3,
                                      **op)
        out["flow"] = flow.to_dict()
        print(f"flow: Q = {flow.flow_rate_m3_s:.4g} m^3/s at pressure drop "
              f"{flow.pressure_drop_Pa:.4g} Pa ({liquid.name}, {liquid.viscosity_Pa_s:g} Pa s); "
              f"rigid channel {flow.rigid_flow_rate_m3_s:.4g} m^3/s; smallest gap "
              f"{flow.min_gap_overall_m:.4g} m at x = {flow.x_min_gap_m:.4g} m"
              + ("; the channel CLOSES (contact)" if flow.closed else ""))
        if args.png:
            fig = plot_channel_flow(flow, target_gap_m=args.target_gap_m)
            with atomic_path(args.png) as tmp:
                fig.savefig(tmp, format="png", dpi=120)
    if args.json:
        out["manifest"] = manifest(config_of(args), None)
        write_json(args.json, out)
    return 0


# Ranges of the options (checked at parse time, exit 2): wide enough for any real specimen,
# narrow enough that nothing overflows or runs away (a 1e30 N/m^3 force is a typo).
_E = float_in("--E-Pa", 1e2, 1e13, "Pa")
_NU = POISSON_RANGE.arg("--nu")
_RHO = float_in("--density-kg-m3", 0.0, 3e4, "kg/m^3")
_G = float_in("--gravity-m-s2", 0.0, 1e4, "m/s^2")
_F = float_in("--body-force-N-m3", -1e9, 1e9, "N/m^3")
_F_EXPORT = float_in("--body-force-N-m3", 0.0, 1e9, "N/m^3")


def _length(opt: str, hi: float = 10.0):
    return float_in(opt, 0.0, hi, "m", lo_open=True)


#: memory of the FEM per degree of freedom [bytes]: measured peak RSS of `mapsim beam --model
#: fem` at nz = 2 and 4 (P2, direct solver) is 17-24 kB/DOF above the interpreter; 20 kB keeps
#: the estimate on the safe side for the AMG path too
_FEM_BYTES_PER_DOF = 20e3


def _check_beam_size(args) -> None:
    """Refuse a beam mesh whose memory estimate exceeds the machine, before meshing."""
    if args.nz is None or not {"fem", "neo-hookean"} & set(args.model or ()):
        return
    from homogenize.macro.cantilever import beam_divisions
    nx, ny, nz = beam_divisions(Strip(args.length_m, args.width_m, args.thickness_m), args.nz)
    dof = 3 * (args.order * nx + 1) * (args.order * ny + 1) * (args.order * nz + 1)
    check_memory(f"--nz {args.nz} ({nx} x {ny} x {nz} hexahedra, {dof:.3g} DOF)",
                 dof * _FEM_BYTES_PER_DOF, "use fewer layers --nz or a shorter strip")


def _check_channel_size(args) -> None:
    from homogenize.macro.channel import _divisions
    geo = ChannelGeometry(args.a_m, args.b_m, args.c_m, args.d_m, args.wall_m)
    nd, nw, na, nb, nc = _divisions(geo, args.nc, 4.0)
    dof = 3 * (args.order * nd + 1) * (args.order * (nw + na) + 1) * (args.order * (nb + nc) + 1)
    check_memory(f"--nc {args.nc} ({dof:.3g} DOF)", dof * _FEM_BYTES_PER_DOF,
                 "use fewer layers --nc")


def _channel_geometry_options(g) -> None:
    """The channel's geometry (the seed paper's Fig. 4 block; defaults its channel)."""
    g.add_argument("--a-m", dest="a_m", type=_length("--a-m", 1.0), default=5e-3,
                   help="channel width a [m]")
    g.add_argument("--b-m", dest="b_m", type=_length("--b-m", 1.0), default=50e-6,
                   help="channel height b [m]")
    g.add_argument("--c-m", dest="c_m", type=_length("--c-m", 1.0), default=0.5e-3,
                   help="polymer thickness above the channel c [m]")
    g.add_argument("--d-m", dest="d_m", type=_length("--d-m", 1.0), default=10e-3,
                   help="channel length d [m]")
    g.add_argument("--wall-m", dest="wall_m", type=_length("--wall-m", 1.0), default=None,
                   help="side-wall width [m] (default max(a/2, 2 (b + c)))")


def _material_options(p):
    p.add_argument("--E-Pa", dest="E_Pa", type=_E, default=None,
                   help="Young's modulus of the composite [Pa] (default: the "
                        f"--matrix-material's, seed-paper {PDMS.E_Pa:g})")
    p.add_argument("--nu", type=_NU, default=None,
                   help="Poisson ratio [-], in (-1, 0.5) (default: the --matrix-material's, "
                        f"seed-paper {PDMS.nu:g})")
    p.add_argument("--density-kg-m3", dest="density_kg_m3", type=_RHO, default=None,
                   help="mass density [kg/m^3] (self-weight, with --gravity-m-s2) (default: the "
                        f"--matrix-material's, seed-paper {PDMS.density_kg_m3:g})")
    p.add_argument("--gravity-m-s2", dest="gravity_m_s2", type=_G, default=0.0,
                   help="gravity along the body force [m/s^2]; 0 = no self-weight")


def _paper_options(p, out: str) -> None:
    """The options ``paper`` and ``paper-calculix`` share."""
    p.add_argument("--out", default=out, help="output directory")
    p.add_argument("--width-m", dest="width_m", type=_length("--width-m", 1.0), default=5e-3,
                   help="assumed strip width [m]")
    p.add_argument("--thickness-m", dest="thickness_m", type=_length("--thickness-m", 1.0),
                   default=1e-3, help="assumed strip thickness [m]")
    p.add_argument("--quick", action="store_true",
                   help="small meshes and sweeps (seconds; for tests, numbers indicative)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def register(sub, formatter) -> None:
    """Add the ``paper``, ``export``, ``beam`` and ``channel`` commands."""
    p = sub.add_parser(
        "paper", formatter_class=formatter, help="reproduce and examine the seed paper",
        description="Reproduce the seed paper (body force, cantilever, Abaqus/Elmer gap, large "
                    "deformation, self-weight, channel study). Writes summary.md, paper.json, "
                    "PNG figures and manifest.json to --out. Takes a few minutes.")
    p.add_argument("--json", default=None, help="also write the JSON results to this file")
    _paper_options(p, "results/paper")
    p.set_defaults(func=_paper, outputs=("json",), output_dirs=("out",))

    p = sub.add_parser(
        "paper-calculix", formatter_class=formatter,
        help="CalculiX's own elements against mapsim's on the paper's strip (optional peer)",
        description="The element study of `mapsim paper` with CalculiX's own elements (C3D8, "
                    "C3D8R, C3D8I, C3D20, C3D20R, C3D4, C3D10) on the same grids: each against "
                    "its scikit-fem twin. Needs CalculiX's ccx on the PATH (`make peers` "
                    "installs it and runs this command). Writes calculix.md, calculix.json and "
                    "manifest.json to --out.")
    _paper_options(p, "results/peers")
    p.set_defaults(func=_paper_calculix, output_dirs=("out",))

    p = sub.add_parser(
        "export", formatter_class=formatter,
        help="write an Elmer or Abaqus material + body-force snippet",
        description="Write the material (E, nu, density) and the magnetic body force as an Elmer "
                    ".sif Material/Body Force section or an Abaqus *MATERIAL/*DLOAD snippet. "
                    "SI units throughout.")
    p.add_argument("--to", required=True, choices=("elmer", "abaqus"), help="target solver")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=_F_EXPORT, required=True,
                   help="magnitude of the magnetic body force [N/m^3]")
    p.add_argument("--E-Pa", dest="E_Pa", type=_E, default=None,
                   help="Young's modulus of the composite [Pa] (default: the "
                        "--matrix-material's, the matrix alone)")
    p.add_argument("--nu", type=_NU, default=None,
                   help="Poisson ratio [-], in (-1, 0.5) (default: the --matrix-material's)")
    p.add_argument("--density-kg-m3", dest="density_kg_m3", type=_RHO, default=None,
                   help="mass density [kg/m^3] (default: the --matrix-material's)")
    p.add_argument("--direction", default="-z", choices=tuple(DIRECTIONS),
                   help="direction of the body force (and of gravity)")
    p.add_argument("--gravity-m-s2", dest="gravity_m_s2", type=_G, default=0.0,
                   help="self-weight acceleration [m/s^2]; Abaqus: GRAV line, Elmer: added to "
                        "the body force")
    p.add_argument("--name", default="MAP_PDMS", help="material name")
    p.add_argument("--elset", default="EALL", help="Abaqus element set of the *DLOAD")
    p.add_argument("--index", type=int_in("--index", 1, 10 ** 6), default=1,
                   help="Elmer Material / Body Force number")
    p.add_argument("--out", required=True, help="output file ('-' for stdout)")
    g = p.add_argument_group(
        "complete input deck",
        "With --deck, a runnable deck instead of a snippet: mesh, material, clamped end (the "
        "strip's root face, or the channel block on glass), static step with the body force "
        "and gravity, nodal displacements U requested (*NODE FILE/*NODE PRINT). abaqus: one "
        ".inp that CalculiX runs (ccx -i STEM; checked against mapsim beam --model fem on the "
        "same mesh to 1e-8); elmer: .sif plus an ElmerGrid mesh directory (checked against "
        "Elmer's documented keywords only: ElmerSolver is not installable here).")
    g.add_argument("--deck", choices=("cantilever", "channel"), default=None,
                   help="write a complete deck of this model (default: none, a snippet)")
    g.add_argument("--element", choices=("C3D10", "C3D20R"), default=None,
                   help="abaqus element type of the deck (default: C3D20R for the cantilever, "
                        "within 1 %% of the converged tip at the default mesh; C3D10 for the "
                        "channel and for elmer)")
    g.add_argument("--deck-nz", dest="deck_nz", type=int_in("--deck-nz", 1, 16), default=None,
                   help="element layers through the strip thickness (default 2, elements as "
                        "long as a layer is high)")
    g.add_argument("--nlgeom", choices=NLGEOM_MODES, default="auto",
                   help="geometric nonlinearity of the abaqus step (*STEP, NLGEOM): auto = on "
                        f"when the linear estimate of the deflection exceeds "
                        f"{NLGEOM_FRACTION:g} of the thickness (strip t, channel ceiling c); "
                        "elmer decks are linear")
    g.add_argument("--length-m", dest="length_m", type=_length("--length-m"),
                   default=SEED_STRIP_LENGTH_M, help="cantilever free length [m]")
    g.add_argument("--width-m", dest="width_m", type=_length("--width-m", 1.0), default=5e-3,
                   help="cantilever width [m]")
    g.add_argument("--thickness-m", dest="thickness_m", type=_length("--thickness-m", 1.0),
                   default=1e-3,
                   help="cantilever thickness [m]")
    _channel_geometry_options(g)
    g = p.add_argument_group(
        "a real magnet in the cantilever deck (magpylib)",
        "With --deck cantilever --to abaqus: the body force f = (M . grad) B = M_eff(H_in) "
        "grad|B_a| of the magnet, evaluated at each element's centroid of the UNDEFORMED strip "
        "and written per element (*DLOAD BX/BY/BZ): a dead load, no follower field and no "
        "pull-in (mapsim beam --gap-m takes the field on the deformed strip). M_eff(H) from "
        "--table at --phi (interpolated, never extrapolated) or demagnetization-limited soft "
        "spheres (--particle-material); the magnet options as in mapsim beam.")
    add_magnet_options(g)
    add_export_table_options(p)
    add_material_options(p, what="--matrix-material fills --E-Pa, --nu, --density-kg-m3 not "
                                 "given (the matrix alone: give the composite's numbers for "
                                 "the particles' stiffening and weight); --particle-material "
                                 "sets the saturation of the soft spheres of --magnet without "
                                 "--table.")
    p.set_defaults(func=_export_run, outputs=("out",), inputs=("table",),
                   option_needs={**{d: "table" for d in ("B_T", "gradB_T_per_m", "bound")},
                                 "phi": ("table", "magnet"), "table_at": ("table", "magnet"),
                                 **{d: "deck" for d in (
                                     "element", "deck_nz", "length_m", "width_m",
                                     "thickness_m", "a_m", "b_m", "c_m", "d_m", "wall_m",
                                     "nlgeom", "magnet")},
                                 **{d: "magnet" for d in (
                                     "magnet_size", "magnet_position", "magnet_direction",
                                     "magnet_axis", "remanence_T", "current_A", "turns",
                                     "demag_factor", "particle_material")}})

    p = sub.add_parser(
        "beam", formatter_class=formatter, help="tip deflection of a clamped strip",
        description="Tip deflection of a strip clamped at one end under a uniform transverse "
                    "body force: Euler-Bernoulli ('eb', 'eb-plate'), Timoshenko, elastica "
                    "(large deflection, 1D), 3D linear FEM ('fem') and 3D neo-Hookean FEM.")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=_F, default=40e3,
                   help="transverse body force [N/m^3]")
    p.add_argument("--length-m", dest="length_m", type=_length("--length-m"), default=20e-3,
                   help="free length [m]")
    p.add_argument("--width-m", dest="width_m", type=_length("--width-m", 1.0), default=5e-3,
                   help="width [m]")
    p.add_argument("--thickness-m", dest="thickness_m", type=_length("--thickness-m", 1.0),
                   default=1e-3, help="thickness, along the force [m]")
    _material_options(p)
    p.add_argument("--model", nargs="+", default=["eb", "timoshenko", "elastica", "fem"],
                   choices=MODELS, help="models to evaluate")
    p.add_argument("--order", type=int, default=2, choices=(1, 2),
                   help="tetrahedron degree of the FEM models")
    p.add_argument("--nz", type=int_in("--nz", 1, 128), default=None,
                   help="element layers through the thickness (FEM models). Default: 'fem' "
                        "runs two nested meshes (P2: 31x4x2 and 62x8x4 on the half width for "
                        "the seed strip), reports the fine one (within 0.5 %% of converged) and "
                        "a Richardson estimate of its discretization error; 'neo-hookean' uses 2")
    p.add_argument("--steps", type=int_in("--steps", 1, 200), default=4,
                   help="load increments (neo-hookean)")
    p.add_argument("--json", default=None, help="write the results to this JSON file")
    add_beam_table_options(p)
    g = p.add_argument_group(
        "a real magnet (magpylib)",
        "The body force f(x) = mu0 M_eff(H_in) grad|H_a| varies along the strip: B and "
        "grad|B| of the source are sampled over the strip (strip frame: [0, L] x [0, w] x "
        "[0, t], clamp at x = 0), H_in = H_a - N M with the strip's demagnetizing factor N. "
        "M_eff(H) comes from --table at --phi (interpolated along B_T, never extrapolated) or, "
        "without a table, from demagnetization-limited soft spheres.")
    add_magnet_options(g)
    g.add_argument("--stations", type=int_in("--stations", 3, 2001), default=101,
                   help="stations along the strip where the field is sampled")
    g.add_argument("--gap-m", dest="gap_m", type=float_in("--gap-m", 0.0, 1.0, "m"),
                   default=None, help="one magnet gap: " + GAP_HELP + ". The field is taken on "
                   "the DEFORMED strip (follower elastica), traced from a far gap down to this "
                   "one: pull-in, contact and the contact force are reported; --model is not "
                   "used")
    g.add_argument("--gap-sweep-m", dest="gap_sweep_m", default=None, metavar="START:STOP:COUNT",
                   help="a sweep of magnet gaps [m], closing then opening again (the device's "
                        "hysteresis): pull-in and release gaps, deflection against gap "
                        "(--png); with --table the pull-in gap's interval from the table's "
                        "M_eff interval")
    g.add_argument("--png", default=None, help="with --gap-m/--gap-sweep-m: tip deflection "
                   "against gap, stable/unstable/contact branches, pull-in and release marked")
    g.add_argument("--follower-fem", dest="follower_fem", action="store_true",
                   help="with --gap-m: the 3D neo-Hookean FEM (--order, --nz layers, default 2) "
                        "with the field on the DEFORMED body, continued from a far gap: its tip "
                        "deflection, or, below its pull-in bracket, that the strip has snapped "
                        "(no contact in the FEM)")
    add_material_options(p, what="--matrix-material fills --E-Pa, --nu, --density-kg-m3 (the "
                                 "matrix's: with --table the force and, with --E-from-table, E "
                                 "come from the table); --particle-material sets the saturation "
                                 "of the soft spheres of --magnet without --table.")
    p.set_defaults(func=_beam, outputs=("json", "png"), inputs=("table",),
                   option_needs={"E_from_table": "table", "table_at": "table",
                                 "B_T": "table", "gradB_T_per_m": "table",
                                 "phi": ("table", "magnet"),
                                 **{d: "magnet" for d in (
                                     "magnet_size", "magnet_position", "magnet_direction",
                                     "magnet_axis", "remanence_T", "current_A", "turns",
                                     "demag_factor", "stations", "gap_m", "gap_sweep_m",
                                     "png")}, "follower_fem": "gap_m"})

    p = sub.add_parser(
        "channel", formatter_class=formatter, help="ceiling deflection of a microchannel",
        description="A PDMS block bonded to glass with a channel (width a, height b, ceiling "
                    "thickness c, length d) under a body force towards the glass: maximum "
                    "ceiling deflection and relative cross-section reduction (3D linear FEM).")
    p.add_argument("--body-force-N-m3", dest="body_force_N_m3", type=_F, default=40e3,
                   help="body force towards the glass [N/m^3]")
    _channel_geometry_options(p)
    _material_options(p)
    p.add_argument("--order", type=int, default=2, choices=(1, 2), help="tetrahedron degree")
    p.add_argument("--nc", type=int_in("--nc", 1, 64), default=2,
                   help="element layers through the ceiling")
    g = p.add_argument_group(
        "flow through the deformed channel",
        "Lubrication along the channel, the liquid's pressure lifting the ceiling while the "
        "body force pulls it down (Gervais et al. 2006, Lab Chip 6, 500); the section's "
        "conductance from the 2D Poiseuille problem on the deformed cross-section (scikit-fem); "
        "the ceiling's compliances from the 3D FEM. A gap that closes is reported as closure.")
    g.add_argument("--flow-rate-m3-s", dest="flow_rate_m3_s",
                   type=float_in("--flow-rate-m3-s", 0.0, 1.0, "m^3/s", lo_open=True),
                   default=None, help="imposed flow rate [m^3/s] (default: none)")
    g.add_argument("--pressure-drop-Pa", dest="pressure_drop_Pa",
                   type=float_in("--pressure-drop-Pa", 0.0, 1e8, "Pa", lo_open=True),
                   default=None, help="imposed pressure drop inlet - outlet [Pa] (default: none)")
    g.add_argument("--outlet-pressure-Pa", dest="outlet_pressure_Pa",
                   type=float_in("--outlet-pressure-Pa", -1e5, 1e8, "Pa"), default=0.0,
                   help="gauge pressure at the outlet [Pa]")
    g.add_argument("--viscosity-Pa-s", dest="viscosity_Pa_s",
                   type=float_in("--viscosity-Pa-s", 0.0, 1e3, "Pa s", lo_open=True),
                   default=None, help="liquid viscosity [Pa s] (default: blood plasma at 37 C, "
                                      "1.2e-3 Pa s)")
    g.add_argument("--target-gap-m", dest="target_gap_m",
                   type=float_in("--target-gap-m", 0.0, 1.0, "m", lo_open=True), default=None,
                   help="find the body force that brings the smallest gap to this height [m] "
                        "(e.g. 10e-6 to 20e-6 to hold back cells) (default: none)")
    g.add_argument("--close", action="store_true",
                   help="find the body force (with --table: the field) at which the ceiling "
                        "shuts the channel against --pressure-drop-Pa (default 0: the first "
                        "contact), where the contact starts, and the pressure a shut channel "
                        "holds per extra N/m^3")
    g.add_argument("--png", default=None, help="plot of gap and pressure along the channel")
    g.add_argument("--table", default=None,
                   help="with --target-gap-m or --close: batch table whose body force(B) at "
                        "--phi and --gradB gives the applied field needed (default: none, body "
                        "force only)")
    g.add_argument("--phi", type=float_in("--phi", 0.0, 0.74, lo_open=True), default=None,
                   help="particle volume fraction for --table [-]")
    g.add_argument("--gradB", dest="gradB_T_per_m",
                   type=float_in("--gradB", -1e4, 1e4, "T/m"), default=None,
                   help="field gradient d|B|/dz for --table [T/m]")
    g.add_argument("--at", dest="table_at", default=None, metavar="AXIS=VALUE,...",
                   help="values of other grid axes of --table (default: none)")
    p.add_argument("--json", default=None, help="write the result to this JSON file")
    add_material_options(p, particle=False,
                         what="--matrix-material fills --E-Pa, --nu, --density-kg-m3.")
    p.set_defaults(func=_channel, outputs=("json", "png"), inputs=("table",),
                   option_needs={"table": ("target_gap_m", "close"), "phi": "table",
                                 "gradB_T_per_m": "table", "table_at": "table",
                                 "outlet_pressure_Pa": ("flow_rate_m3_s", "pressure_drop_Pa",
                                                        "close"),
                                 **{d: ("flow_rate_m3_s", "pressure_drop_Pa") for d in (
                                     "viscosity_Pa_s", "png")}})
    add_channel_magnet_options(p.add_argument_group(CHANNEL_MAGNET_GROUP, CHANNEL_MAGNET_HELP))
    p.set_defaults(option_needs=channel_magnet_option_needs(p.get_default("option_needs")))
