"""``mapsim channel --magnet cuboid|cylinder --magnet-size ... --remanence-T ... --close |
--gap-sweep-m A:B:N``: the channel ceiling under a real magnet below the glass with the field
on the DEFORMED ceiling (:func:`homogenize.macro.channel_magnet.channel_magnet_sweep`): its
deflection against the magnet gap, the closure (contact) or pull-in (snap-down) gap and where,
and with ``--pressure-drop-Pa`` the gap that holds the shut channel against it; printed and in
``--json``.

Wired into ``mapsim channel`` by ``homogenize/cli/cmd_macro.py`` (``--magnet`` dispatches here).
"""
from __future__ import annotations

import numpy as np

from homogenize.macro.channel import ChannelGeometry
from homogenize.macro.channel_magnet import (channel_demag_factor, channel_magnet_sweep,
                                             place_channel_magnet)
from homogenize.macro.effective import magnetization_from_table, soft_sphere_magnetization
from homogenize.macro.fem import Material
from homogenize.macro.flow import CeilingModel
from homogenize.tables.batch import read_table
from micro.common.files import manifest, write_json
from micro.common.validate import InputError
from micro.materials import SEED

from homogenize.cli._common import (add_magnet_options, config_of, int_in, json_ready, parse_at,
                                    parse_values)
from homogenize.cli._pullin import permanent_magnet

__all__ = ["CHANNEL_MAGNET_GROUP", "CHANNEL_MAGNET_HELP", "CHANNEL_GAP_HELP",
           "add_channel_magnet_options", "channel_magnet_option_needs", "run_channel_magnet"]

CHANNEL_GAP_HELP = ("the magnet gap: from the magnet's top face to the channel floor (the top "
                    "of the glass; the glass thickness is part of it) [m], >= 0; the magnet's "
                    "axis along z, under the middle of the channel unless --magnet-position "
                    "gives its X and Y (channel frame: x along the channel from the inlet, y "
                    "across it from a side wall; Z is ignored)")
CHANNEL_MAGNET_GROUP = "a real magnet below the channel (magpylib)"
CHANNEL_MAGNET_HELP = (
    "With --magnet cuboid|cylinder: the body force f = M_eff(H_in) d|B|/dz towards the magnet "
    "varies along and across the channel and grows as the ceiling comes down; it is sampled on "
    "the DEFORMED ceiling (sections along x, Gauss columns across, each at its deflected "
    "height), with the block's thin-plate demagnetizing factor (--demag-factor to override), "
    "the ceiling's FEM compliance projected on one mode per section, the sections coupled by "
    "the ceiling's bending along the channel, followed in the gap through a fold. "
    "--gap-sweep-m A:B:N prints the deflection against the gap; "
    "--close (or the sweep) reports the gap where the ceiling first touches the glass or snaps "
    "down (pull-in), and with --pressure-drop-Pa the gap that holds the shut channel against "
    "it. M_eff(H) from --table at --phi, else demagnetization-limited soft spheres (--phi, "
    "default the seed's).")

#: the largest number of gaps of a sweep
MAX_GAPS = 200


def add_channel_magnet_options(group) -> None:
    """The magnet options of ``mapsim beam`` (the same names: ``--magnet``, ``--magnet-size``,
    ``--remanence-T``, ``--magnet-position``, ``--magnet-direction``, ``--magnet-axis``,
    ``--demag-factor``, ... from :func:`homogenize.cli._common.add_magnet_options`) and the
    channel's own: ``--gap-sweep-m``, ``--sections``."""
    add_magnet_options(group)
    group.add_argument("--gap-sweep-m", dest="gap_sweep_m", default=None,
                       metavar="START:STOP:COUNT",
                       help="magnet gaps [m]: " + CHANNEL_GAP_HELP + ". Traced from a far gap; "
                            "the deflection at each, closure / pull-in marked")
    group.add_argument("--sections", type=int_in("--sections", 3, 201), default=21,
                       help="sections along the channel where the field is sampled, coupled by "
                            "the ceiling's bending along it (ends included; default 21)")


def channel_magnet_option_needs(needs: dict | None) -> dict:
    """The channel command's ``option_needs`` with the magnet's options added."""
    out = dict(needs or {})
    out["table"] = tuple(_as_tuple(out.get("table", ()))) + ("magnet",)
    out["phi"] = tuple(_as_tuple(out.get("phi", ()))) + ("magnet",)
    out["outlet_pressure_Pa"] = tuple(_as_tuple(out.get("outlet_pressure_Pa", ()))) + ("magnet",)
    for d in ("magnet_size", "magnet_position", "magnet_direction", "magnet_axis",
              "remanence_T", "current_A", "turns", "demag_factor", "gap_sweep_m", "sections"):
        out[d] = "magnet"
    return out


def _as_tuple(v):
    return (v,) if isinstance(v, str) else tuple(v)


def _parse_sweep(text) -> np.ndarray:
    if ":" not in str(text):
        raise InputError(f"--gap-sweep-m: expected START:STOP:COUNT [m], e.g. 0.008:0:17, got "
                         f"{text!r}")
    g = parse_values(text, "--gap-sweep-m", "m", max_count=MAX_GAPS, min_count=2)
    if min(g[0], g[-1]) < 0 or g[0] == g[-1]:
        raise InputError(f"--gap-sweep-m: START and STOP must be >= 0 m and differ, got {text!r} "
                         f"(a gap below zero puts the magnet into the glass and the channel)")
    return g


def _law(args):
    """``(M_of_H, phi, name, bounds)``: the composite's law, and with --table the laws of the
    two ends of the table's M_eff interval (``{"low": law, "high": law}``, else None)."""
    phi = args.phi if getattr(args, "phi", None) is not None else SEED.c * SEED.d
    if getattr(args, "table", None):
        if args.phi is None:
            raise InputError("--phi is required with --table")
        t = read_table(args.table)
        at = parse_at(getattr(args, "table_at", None))
        bounds = {b: magnetization_from_table(t, phi, bound=b, **at) for b in ("low", "high")}
        return magnetization_from_table(t, phi, **at), phi, f"table {args.table}", bounds
    return soft_sphere_magnetization(phi), phi, "soft spheres (dilute), the seed's Ms", None


def run_channel_magnet(args) -> int:
    """``mapsim channel --magnet ... --close | --gap-sweep-m A:B:N`` (module docstring);
    exit 0. InputError (exit 2) for options that do not go with a magnet."""
    if args.magnet not in ("cuboid", "cylinder"):
        raise InputError("channel --magnet: a permanent magnet below the glass (cuboid or "
                         "cylinder); a coil has no face to measure the gap to")
    if not getattr(args, "close", False) and args.gap_sweep_m is None:
        raise InputError("channel --magnet needs --close (the closing gap) or --gap-sweep-m "
                         "START:STOP:COUNT (the deflection against the gap)")
    for dest, opt in (("flow_rate_m3_s", "--flow-rate-m3-s"), ("target_gap_m", "--target-gap-m"),
                      ("png", "--png"), ("gradB_T_per_m", "--gradB")):
        if getattr(args, dest, None) is not None:
            raise InputError(f"{opt} is not used with --magnet (the magnet gives the field and "
                             f"its gradient; the flow is not coupled here): leave it out")
    if tuple(args.magnet_axis) != (0.0, 0.0, 1.0) or tuple(args.magnet_direction) not in (
            (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)):
        raise InputError("channel --magnet: the magnet's axis and magnetization must be along z "
                         "(a magnet below the glass, facing the channel)")
    geo = ChannelGeometry(args.a_m, args.b_m, args.c_m, args.d_m, args.wall_m)
    mat = Material(args.E_Pa, args.nu, args.density_kg_m3)
    gaps = (_parse_sweep(args.gap_sweep_m) if args.gap_sweep_m is not None else None)
    m0 = permanent_magnet(args, (0.0, 0.0, 0.0))
    if gaps is None:          # --close alone: from the magnet's size down to contact
        gaps = np.linspace(max(m0.dimensions_m), 0.0, 11)
    xy = (None, None) if args.magnet_position is None else tuple(args.magnet_position[:2])
    magnet = place_channel_magnet(m0, geo, float(gaps[0]), x_axis_m=xy[0], y_axis_m=xy[1])
    M_of_H, phi, law, bounds = _law(args)
    N = args.demag_factor if args.demag_factor is not None else channel_demag_factor(geo)
    ceiling = CeilingModel.from_fem(geo, mat, nc=max(getattr(args, "nc", 3), 3),
                                    order=getattr(args, "order", 2))
    dp = args.pressure_drop_Pa or 0.0
    kw = dict(pressure_drop_Pa=dp, outlet_pressure_Pa=args.outlet_pressure_Pa,
              demag_factor=N, n_x=args.sections,
              self_weight_N_m3=mat.density_kg_m3 * (getattr(args, "gravity_m_s2", 0.0) or 0.0),
              plate_rigidity_N_m=mat.E_Pa * geo.c_m ** 3 / (12.0 * (1.0 - mat.nu ** 2)))
    r = channel_magnet_sweep(geo, ceiling, magnet, M_of_H, gaps, **kw)
    # the table's M_eff interval: the weaker magnetization closes at the smaller gap
    ends = ({b: channel_magnet_sweep(geo, ceiling, magnet, law_b, gaps, **kw)
             for b, law_b in bounds.items()} if bounds else {})
    interval = {}
    if ends:
        for key in ("closure_gap_m", "hold_gap_m"):
            v = [getattr(ends[b], key) for b in ("low", "high")]
            interval[key] = [None if not np.isfinite(x) else float(x) for x in v]
    print(f"magnet: {args.magnet} {tuple(args.magnet_size)} m, B_r {args.remanence_T:g} T, axis "
          f"at x = {magnet.position_m[0]:.4g} m, y = {magnet.position_m[1]:.4g} m under the "
          f"{geo.a_m:g} x {geo.d_m:g} m channel; M_eff(H) from {law}, phi = {phi:g}; block "
          f"demagnetizing factor N = {N:.4f}; field on the DEFORMED ceiling ({args.sections} "
          f"sections, one mode each, coupled by the ceiling's bending along the channel; "
          f"ceiling compliance: {ceiling.source}); E = {mat.E_Pa:.6g} Pa")
    print("gap: " + CHANNEL_GAP_HELP)

    def xs(v):
        return ", ".join(f"{x:.4g}" for x in v) + " m"
    def iv(key):
        if key not in interval:
            return ""
        return (" [" + ", ".join("none in the range" if v is None else f"{v:.4g}"
                                 for v in interval[key]) + "] (table's M_eff interval)")
    if r.event == "none":
        print(f"no closure down to the gap {gaps.min():.4g} m: the ceiling stays open "
              f"(largest deflection there {np.nanmax(r.sweep_max_deflection_m):.4g} m of "
              f"b = {geo.b_m:g} m)")
    elif r.event == "contact":
        print(f"closure gap {r.closure_gap_m:.4g} m{iv('closure_gap_m')}: the ceiling touches "
              f"the glass (no snap) at x = {xs(r.x_event_m)}, y = {r.y_event_m:.4g} m; the dead "
              f"load (field of the undeformed ceiling) gives "
              f"{r.event_dead_load_deflection_m:.4g} m there instead of "
              f"{r.event_deflection_m:.4g} m")
    else:
        print(f"pull-in gap {r.closure_gap_m:.4g} m{iv('closure_gap_m')}: the ceiling snaps "
              f"down onto the glass at x = {xs(r.x_event_m)}, y = {r.y_event_m:.4g} m, from a "
              f"deflection of {r.event_deflection_m:.4g} m (the glass is "
              f"{r.contact_deflection_m:.4g} m away)")
    if dp > 0:
        if r.hold_event == "none":
            print(f"against {dp:.4g} Pa: not shut down to the gap {gaps.min():.4g} m")
        else:
            print(f"against {dp:.4g} Pa (inlet {r.outlet_pressure_Pa + dp:.4g} Pa): the channel "
                  f"holds shut below the gap {r.hold_gap_m:.4g} m{iv('hold_gap_m')} "
                  f"({r.hold_event} at x = {xs(r.x_hold_m)})")
    print(f"{'gap [m]':>10} {'deflection [m]':>15} {'smallest gap [m]':>17} {'at x [m]':>9} "
          f"{'dead load [m]':>14} {'f centre [N/m^3]':>17}  state")
    marked = r.event == "none"
    for g, q, h, x, dl, f, s in zip(r.sweep_gap_m, r.sweep_max_deflection_m, r.sweep_min_gap_m,
                                    r.sweep_x_max_m, r.sweep_dead_load_max_deflection_m,
                                    r.sweep_centre_force_N_m3, r.sweep_state):
        closing = r.sweep_gap_m[0] > r.sweep_gap_m[-1]
        if not marked and ((closing and g <= r.closure_gap_m)
                           or (not closing and g > r.closure_gap_m)):
            print(f"{r.closure_gap_m:10.4g} {r.event_deflection_m:15.6g} "
                  f"{0.0:17.4g} "
                  f"{r.x_event_m[0]:9.4g} {r.event_dead_load_deflection_m:14.6g} {'':>17}  "
                  f"<- {'closure (contact)' if r.event == 'contact' else 'pull-in (snap-down)'}")
            marked = True
        if s == "open":
            print(f"{g:10.4g} {q:15.6g} {h:17.4g} {x:9.4g} {dl:14.6g} {f:17.4g}  open")
        else:
            print(f"{g:10.4g} {'-':>15} {0.0:17.4g} {'-':>9} {dl:14.6g} {'-':>17}  closed")
    if args.json:
        out = {"geometry": vars(geo), "material": vars(mat), "gap_definition": CHANNEL_GAP_HELP,
               "magnet": {"kind": args.magnet, "size_m": list(args.magnet_size),
                          "remanence_T": args.remanence_T, "axis_x_m": magnet.position_m[0],
                          "axis_y_m": magnet.position_m[1]},
               "magnetization": law, "phi": phi, "demag_factor": N,
               "channel_magnet": r.to_dict(),
               "interval": dict(interval, **{"from": "table's M_eff interval"})
               if interval else None,
               "interval_ends": {b: e.to_dict() for b, e in ends.items()} or None,
               "manifest": manifest(config_of(args), None)}
        write_json(args.json, json_ready(out))
    return 0
