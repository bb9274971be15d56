"""``mapsim beam --magnet ... --gap-m G | --gap-sweep-m A:B:N``: the strip against the magnet
gap with the field on the DEFORMED strip (:func:`homogenize.macro.pullin.pullin_sweep`):
pull-in, contact and release, printed, in --json and --png."""
from __future__ import annotations

import math

import numpy as np

from homogenize.macro.effective import magnetization_from_table
from homogenize.macro.follower_fem import FollowerFEM, follower_fem_at_gap
from homogenize.macro.magnets import PermanentMagnet
from homogenize.macro.pullin import (ON_FACE_AT_END, PathFollowingError, interval_ends,
                                     place_magnet, pullin_sweep)
from homogenize.tables.batch import modulus_from_table, read_table
from micro.common.files import atomic_path, manifest, write_json
from micro.common.validate import InputError
from micro.materials import ElasticMaterial

from homogenize.cli._common import config_of, json_ready, parse_at, parse_values

__all__ = ["gap_sweep", "parse_gap_sweep", "permanent_magnet", "GAP_HELP"]

GAP_HELP = ("the magnet gap as a user measures it: from the strip's bottom face at the tip to "
            "the magnet's top face [m] (the magnet's axis along z, centred under the tip end "
            "unless --magnet-position gives its X and Y)")

#: the largest number of gaps of a sweep (each gap is a point on a traced path)
MAX_GAPS = 200


def parse_gap_sweep(text: str) -> np.ndarray:
    """``A:B:N`` -> N gaps from A to B [m] (strictly monotonic, >= 0)."""
    if ":" not in str(text):
        raise InputError(f"--gap-sweep-m: expected START:STOP:COUNT [m], e.g. 0.02:0.005:16, "
                         f"got {text!r}")
    g = parse_values(text, "--gap-sweep-m", "m", max_count=MAX_GAPS, min_count=2)
    a, b, n = float(g[0]), float(g[-1]), g.size
    if not (math.isfinite(a) and math.isfinite(b)) or min(a, b) < 0 or a == b:
        raise InputError(f"--gap-sweep-m: START and STOP must be finite, >= 0 m and differ, got "
                         f"{text!r} (a gap below zero puts the magnet inside the strip)")
    return g


def permanent_magnet(args, position_m) -> PermanentMagnet:
    """The --magnet cuboid|cylinder of the options, at ``position_m`` (its size and remanence
    checked: one message naming the missing option)."""
    size = tuple(args.magnet_size or ())
    want = 3 if args.magnet == "cuboid" else 2
    if len(size) != want:
        what = "A B C (edges)" if want == 3 else "DIAMETER HEIGHT"
        raise InputError(f"--magnet {args.magnet} needs --magnet-size {what} [m]")
    if args.remanence_T is None:
        raise InputError(f"--magnet {args.magnet} needs --remanence-T [T]")
    return PermanentMagnet(args.magnet, size, args.remanence_T, position_m,
                           tuple(args.magnet_direction), tuple(args.magnet_axis))


def _magnet_at(args, strip, gap):
    if args.magnet not in ("cuboid", "cylinder"):
        raise InputError("--gap-m / --gap-sweep-m need a permanent magnet (--magnet cuboid or "
                         "cylinder) below the tip; a coil has no face to measure a gap to")
    if tuple(args.magnet_axis) != (0.0, 0.0, 1.0) or tuple(args.magnet_direction) not in (
            (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)):
        raise InputError("--gap-m / --gap-sweep-m: the magnet's axis and magnetization must be "
                         "along z (a magnet below the strip, facing it)")
    m = permanent_magnet(args, (0.0, 0.0, -1.0))
    if args.magnet_position is None:
        return place_magnet(m, strip, gap)
    x, y, _ = args.magnet_position
    return place_magnet(m, strip, gap, tip_offset_m=strip.length_m - x,
                        lateral_offset_m=y - 0.5 * strip.width_m)


def _ends(args, phi, mat, M_of_H):
    """``(ends, what)``: the (modulus, law) pairs of the mean and, with --table, of the two ends
    of the interval (:func:`homogenize.macro.pullin.interval_ends`: the ends of the table's
    M_eff interval and, with --E-from-table, of its E_eff interval widened by the
    discretization error), and the words that name what the interval carries."""
    if not args.table:
        return interval_ends(mat.E_Pa, M_of_H), None
    t = read_table(args.table)
    at = parse_at(args.table_at)
    bounds = {b: magnetization_from_table(t, phi, bound=b, **at) for b in ("low", "high")}
    E_est, E = None, mat.E_Pa
    if getattr(args, "E_from_table", False):
        mech = {k: v for k, v in at.items() if k not in ("B_T", "gradB_T_per_m")}
        E_est = modulus_from_table(t, phi, **mech)
        if E_est is None:
            raise InputError(f"--E-from-table: {args.table} has no E_eff (the study ran without "
                             f"fem = true)")
        E = E_est.mean
    what = ("table's M_eff and E_eff intervals" if E_est is not None
            else "table's M_eff interval")
    return interval_ends(E, M_of_H, E_est, bounds), what


def gap_sweep(args, strip, mat, M_of_H, phi, law_name, N) -> int:
    """The follower-field elastica against the gap (module docstring); exit 0 on success."""
    if args.gap_m is not None and args.gap_sweep_m is not None:
        raise InputError("give --gap-m or --gap-sweep-m, not both")
    if getattr(args, "follower_fem", False):
        return follower_fem_gap(args, strip, mat, M_of_H, phi, law_name, N)
    gaps = (np.array([args.gap_m]) if args.gap_m is not None
            else parse_gap_sweep(args.gap_sweep_m))
    magnet = _magnet_at(args, strip, float(gaps[0]))
    ends, what = _ends(args, phi, mat, M_of_H)
    results = {}
    for bound, (E, law) in ends.items():
        try:
            results[bound] = pullin_sweep(strip, ElasticMaterial(E, mat.nu, mat.density_kg_m3),
                                          magnet, law, gap_sweep_m=gaps,
                                          round_trip=gaps.size > 1, demag_factor=N,
                                          gravity_m_s2=args.gravity_m_s2)
        except PathFollowingError as exc:
            # exit 3 (the caller): the last converged state written, named as such
            if args.json:
                write_json(args.json, json_ready({
                    "status": "did not converge", "error": str(exc),
                    "interval_end": bound, "E_Pa": E, "strip": vars(strip),
                    "gap_definition": GAP_HELP, "gap_sweep_m": gaps.tolist(),
                    "last_converged": {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                       for k, v in exc.last_converged.items()},
                    "manifest": manifest(config_of(args), None)}))
                print(f"the path could not be followed ({bound} end); its last converged "
                      f"state is written to {args.json} as 'last_converged'")
            raise
    r = results["mean"]
    lo_hi = {}
    if "low" in results:
        for key in ("pull_in_gap_m", "release_gap_m"):
            v = sorted(getattr(results[b], key) for b in ("low", "high"))
            lo_hi[key] = v
    print(f"magnet: {args.magnet} {tuple(args.magnet_size)} m, B_r {args.remanence_T:g} T, axis "
          f"at x = {magnet.position_m[0]:.4g} m, y = {magnet.position_m[1]:.4g} m; M_eff(H) from "
          f"{law_name}, phi = {phi:g}; strip demagnetizing factor N = {N:.4f}; field on the "
          f"DEFORMED strip (follower elastica, {r.n_segments} segments); E = "
          f"{ends['mean'][0]:.6g} Pa")

    def iv(key):
        if key not in lo_hi:
            return ""
        a, b = lo_hi[key]
        return f" [{a:.4g}, {b:.4g}] ({what})"
    words = describe(r, iv, float(gaps.max()))
    for line in words:
        print(line)
    print(f"{'gap [m]':>10} {'tip deflection [m]':>19} {'tip gap [m]':>12} "
          f"{'contact force [N]':>18} {'nodes on face':>13} {'contact length [m]':>18}  branch")
    for g, d, tg, fc, nc, cl, b in zip(r.sweep_gap_m, r.sweep_tip_deflection_m,
                                       r.sweep_tip_gap_m, r.sweep_contact_force_N,
                                       r.sweep_n_contact, r.sweep_contact_length_m,
                                       r.sweep_branch):
        # on contact the tip gap is zero to round-off (its sign is noise): printed as 0
        tg = 0.0 if abs(tg) < 1e-9 * strip.length_m else tg
        print(f"{g:10.4g} {d:19.6g} {tg:12.4g} {fc:18.4g} {nc:13d} {cl:18.4g}  {b}")
    out = {"strip": vars(strip), "gap_definition": GAP_HELP, "magnet": {
        "kind": args.magnet, "size_m": list(args.magnet_size), "remanence_T": args.remanence_T,
        "axis_x_m": magnet.position_m[0], "axis_y_m": magnet.position_m[1]},
        "magnetization": law_name, "phi": phi, "demag_factor": N,
        "pullin": r.to_dict(), "what_happens": words,
        "E_Pa": ends["mean"][0],
        "interval": {k: v for k, v in lo_hi.items()} or None, "interval_from": what,
        "interval_ends": {b: {"E_Pa": E, "M_eff": "low" if b == "low" else "high"}
                          for b, (E, _) in ends.items() if b != "mean"} or None,
        "manifest": manifest(config_of(args), None)}
    if args.json:
        write_json(args.json, json_ready(out))
    if getattr(args, "png", None):
        _plot(args.png, r, lo_hi)
    return 0


def describe(r, iv=lambda key: "", largest_gap_m=math.nan) -> list:
    """What the strip does, in words (printed and in the JSON's ``what_happens``): the state it
    snaps into at pull-in (:attr:`PullInResult.pull_in_lands_on`), where it touches, how it lets
    go on the way back and where it returns to the small deflection. ``iv(key)``: the interval
    text of a result key."""
    lines = []
    if not math.isfinite(r.pull_in_gap_m):
        lines.append("pull-in gap: not reached in the range of gaps (no fold, no touch)")
    elif not r.snap:
        lines.append(f"pull-in gap {r.pull_in_gap_m:.4g} m{iv('pull_in_gap_m')}: the tip "
                     f"touches the magnet's face without a snap (tip deflection "
                     f"{r.pull_in_tip_deflection_m:.4g} m)")
    else:
        head = (f"pull-in gap {r.pull_in_gap_m:.4g} m{iv('pull_in_gap_m')} (tip deflection "
                f"there {r.pull_in_tip_deflection_m:.4g} m): closing the gap below it the strip ")
        if r.pull_in_lands_on == "free":
            text = (f"snaps to a large deflection WITHOUT touching the magnet (tip deflection "
                    f"{r.landing_tip_deflection_m:.4g} m, its tip {r.landing_tip_gap_m:.3g} m "
                    f"above the plane of the face)")
            if math.isfinite(r.touch_gap_m) and r.touch_gap_m < r.pull_in_gap_m:
                text += (f"; closing further, its tip touches the face at {r.touch_gap_m:.4g} m "
                         f"without a snap")
        elif r.pull_in_lands_on == "tip contact":
            text = (f"snaps onto the magnet: its tip on the face (contact force "
                    f"{r.landing_contact_force_N:.3g} N)")
        elif r.pull_in_lands_on == "lying on the face":
            text = (f"snaps onto the magnet, lying on the face ({r.landing_n_contact} nodes, "
                    f"contact force {r.landing_contact_force_N:.3g} N)")
        else:
            text = "snaps (the state it lands in is not on the traced path)"
        lines.append(head + text)
    jumps = ("it jumps between contact states at "
             + ", ".join(f"{g:.4g}" for g in r.contact_jumps_m) + " m, then "
             if r.contact_jumps_m else "")
    back = ""
    if math.isfinite(r.snap_back_gap_m) and math.isfinite(r.release_gap_m):
        if r.snap_back_gap_m > r.release_gap_m * (1 + 1e-9):
            back = (f"; it stays bent without contact and snaps back to the small deflection "
                    f"at {r.snap_back_gap_m:.4g} m")
        else:
            back = "; it is back on the small-deflection branch"
        if math.isfinite(r.pull_in_gap_m) and r.snap:
            back += (f" (hysteresis: pull-in at {r.pull_in_gap_m:.4g} m, return at "
                     f"{max(r.snap_back_gap_m, r.release_gap_m):.4g} m)")
    if r.release_by == "contact force zero" and math.isfinite(r.release_gap_m):
        lines.append(f"opening the gap: {jumps}the strip lifts off the face where its contact "
                     f"force vanishes, release gap {r.release_gap_m:.4g} m"
                     f"{iv('release_gap_m')}{back}")
    elif r.release_by == "fold of the contact branch" and math.isfinite(r.release_gap_m):
        lines.append(f"opening the gap: {jumps}the strip snaps off the face (the contact state "
                     f"ends), release gap {r.release_gap_m:.4g} m{iv('release_gap_m')}{back}")
    elif r.release_by == ON_FACE_AT_END:
        lines.append(f"opening the gap: {jumps}the strip is still on the face at the largest "
                     f"gap of the sweep ({largest_gap_m:.4g} m): no release within the sweep")
    else:
        lines.append("release gap: not determined (no contact traced in the range, or the "
                     "contact could not be followed: see the JSON's contact_end_gap_m)")
    return lines


def follower_fem_gap(args, strip, mat, M_of_H, phi, law_name, N) -> int:
    """``--gap-m G --follower-fem``: the 3D neo-Hookean FEM with the field on the deformed
    body (:func:`homogenize.macro.follower_fem.follower_fem_at_gap`), continued from a far gap
    to G: its tip deflection, or (G below its pull-in bracket) that the strip has snapped."""
    if args.gap_m is None:
        raise InputError("--follower-fem takes one gap, --gap-m G (not --gap-sweep-m)")
    if getattr(args, "png", None):
        raise InputError("--png draws the elastica's path (--gap-sweep-m); not with "
                         "--follower-fem")
    g = float(args.gap_m)
    magnet = _magnet_at(args, strip, g)
    ends, what = _ends(args, phi, mat, M_of_H)
    runs, models = {}, {}
    for bound, (E, law) in ends.items():
        models[bound] = FollowerFEM(strip, ElasticMaterial(E, mat.nu, mat.density_kg_m3), magnet,
                                    law, nz=args.nz if args.nz is not None else 2,
                                    order=args.order, demag_factor=N,
                                    gravity_m_s2=args.gravity_m_s2)
        runs[bound] = follower_fem_at_gap(models[bound], g)
    r, model = runs["mean"], models["mean"]
    print(f"magnet: {args.magnet} {tuple(args.magnet_size)} m, B_r {args.remanence_T:g} T, axis "
          f"at x = {magnet.position_m[0]:.4g} m, y = {magnet.position_m[1]:.4g} m; M_eff(H) from "
          f"{law_name}, phi = {phi:g}; strip demagnetizing factor N = {N:.4f}; field on the "
          f"DEFORMED body (follower FEM: 3D neo-Hookean, P{r.order}, {r.divisions} hexahedra of "
          f"6 tetrahedra{' on the half width' if model.half else ''}, {r.n_dof} dofs), "
          f"continued from the gap {r.far_gap_m:.4g} m")
    interval = None
    if len(runs) > 1:
        ends_ok = [runs[b] for b in ("low", "high")]
        # an end without equilibrium at this gap has snapped: the interval is open there
        interval = {"tip_deflection_m": [x.tip_deflection_m if x.converged else None
                                         for x in ends_ok],
                    "snapped": [not x.converged for x in ends_ok], "from": what}
    if r.converged:
        iv = ""
        if interval is not None:
            lo, hi = interval["tip_deflection_m"]
            iv = (f" [{lo:.6g}, " + (f"{hi:.6g}]" if hi is not None else "snapped]")
                  + f" ({what})") if lo is not None else f" (the end of the {what} snaps)"
        print(f"gap {g:.4g} m: tip deflection {r.tip_deflection_m:.6g} m{iv}")
    else:
        lo, hi = r.pull_in_bracket_m
        print(f"gap {g:.4g} m: below the FEM's pull-in bracket [{lo:.5g}, {hi:.5g}] m (no "
              f"equilibrium below {lo:.5g} m, tip deflection {r.pull_in_tip_deflection_m:.4g} m "
              f"at {hi:.5g} m): the strip has snapped to the magnet (no contact in the FEM: "
              f"--gap-m without --follower-fem models it)")
    if args.json:
        write_json(args.json, json_ready({
            "strip": vars(strip), "gap_definition": GAP_HELP, "magnet": {
                "kind": args.magnet, "size_m": list(args.magnet_size),
                "remanence_T": args.remanence_T, "axis_x_m": magnet.position_m[0],
                "axis_y_m": magnet.position_m[1]},
            "magnetization": law_name, "phi": phi, "demag_factor": N,
            "E_Pa": ends["mean"][0], "follower_fem": r.to_dict(), "interval": interval,
            "interval_ends": {b: x.to_dict() for b, x in runs.items() if b != "mean"} or None,
            "manifest": manifest(config_of(args), None)}))
    return 0


def _plot(path, r, lo_hi):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(7.5, 4.8))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    g, d = 1e3 * np.asarray(r.gap_m), 1e3 * np.asarray(r.tip_deflection_m)
    stable = np.asarray(r.stable, bool)
    contact = np.asarray(r.branch) == "contact"
    for sel, style, lab in ((stable & ~contact, "-", "free, stable"),
                            (~stable & ~contact, ":", "free, unstable"),
                            (contact, "-", "on the magnet")):
        if sel.any():
            ax.plot(np.where(sel, g, np.nan), np.where(sel, d, np.nan), style,
                    color="C3" if lab.startswith("on") else "C0", label=lab)
    if math.isfinite(r.pull_in_gap_m):
        ax.axvline(1e3 * r.pull_in_gap_m, color="k", ls="--", lw=0.8,
                   label=f"pull-in {1e3 * r.pull_in_gap_m:.3g} mm")
    if math.isfinite(r.release_gap_m):
        ax.axvline(1e3 * r.release_gap_m, color="C2", ls="--", lw=0.8,
                   label=f"release {1e3 * r.release_gap_m:.3g} mm")
    if "pull_in_gap_m" in lo_hi:
        a, b = lo_hi["pull_in_gap_m"]
        ax.axvspan(1e3 * a, 1e3 * b, color="0.85", label="pull-in, table's interval")
    ax.plot(1e3 * np.asarray(r.sweep_gap_m), 1e3 * np.asarray(r.sweep_tip_deflection_m), "o",
            ms=3, color="k", mfc="none", label="sweep (quasi-static)")
    ax.set_xlabel("magnet gap: strip face to magnet face [mm]")
    ax.set_ylabel("tip deflection towards the magnet [mm]")
    ax.set_title("strip against magnet gap, field on the deformed strip", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
