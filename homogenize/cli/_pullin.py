"""``mapsim beam --magnet ... --gap-m G | --gap-sweep-m A:B:N``: the strip against the magnet
gap with the field on the DEFORMED strip (:func:`homogenize.macro.pullin.pullin_sweep`):
pull-in, contact and release, printed, in --json and --png."""
from __future__ import annotations

import math

import numpy as np

from homogenize.macro.effective import magnetization_from_table
from homogenize.macro.follower_fem import FollowerFEM, follower_fem_at_gap
from homogenize.macro.magnets import PermanentMagnet
from homogenize.macro.pullin import pullin_sweep, place_magnet
from homogenize.tables.batch import read_table
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


def _laws(args, phi, M_of_H):
    """The mean law, and with --table the ends of its confidence interval."""
    if not args.table:
        return {"mean": M_of_H}
    t = read_table(args.table)
    at = parse_at(args.table_at)
    return {b: magnetization_from_table(t, phi, bound=b, **at) for b in ("mean", "low", "high")}


def gap_sweep(args, strip, mat, M_of_H, phi, law_name, N) -> int:
    """The follower-field elastica against the gap (module docstring); exit 0 on success."""
    if args.gap_m is not None and args.gap_sweep_m is not None:
        raise InputError("give --gap-m or --gap-sweep-m, not both")
    if getattr(args, "follower_fem", False):
        return follower_fem_gap(args, strip, mat, M_of_H, phi, law_name, N)
    gaps = (np.array([args.gap_m]) if args.gap_m is not None
            else parse_gap_sweep(args.gap_sweep_m))
    magnet = _magnet_at(args, strip, float(gaps[0]))
    laws = _laws(args, phi, M_of_H)
    results = {}
    for bound, law in laws.items():
        results[bound] = pullin_sweep(strip, ElasticMaterial(mat.E_Pa, mat.nu,
                                                             mat.density_kg_m3),
                                      magnet, law, gap_sweep_m=gaps, round_trip=gaps.size > 1,
                                      demag_factor=N, gravity_m_s2=args.gravity_m_s2)
    r = results["mean"]
    lo_hi = {}
    if "low" in results:
        for key in ("pull_in_gap_m", "release_gap_m"):
            v = sorted(getattr(results[b], key) for b in ("low", "high"))
            lo_hi[key] = v
    print(f"magnet: {args.magnet} {tuple(args.magnet_size)} m, B_r {args.remanence_T:g} T, axis "
          f"at x = {magnet.position_m[0]:.4g} m, y = {magnet.position_m[1]:.4g} m; M_eff(H) from "
          f"{law_name}, phi = {phi:g}; strip demagnetizing factor N = {N:.4f}; field on the "
          f"DEFORMED strip (follower elastica, {r.n_segments} segments)")

    def iv(key):
        if key not in lo_hi:
            return ""
        a, b = lo_hi[key]
        return f" [{a:.4g}, {b:.4g}] (table's M_eff interval)"
    snap = "snaps to the magnet" if r.snap else "touches the magnet without a snap"
    print(f"pull-in gap {r.pull_in_gap_m:.4g} m{iv('pull_in_gap_m')} (tip deflection there "
          f"{r.pull_in_tip_deflection_m:.4g} m): closing the gap below it the strip {snap}")
    if math.isfinite(r.release_gap_m):
        jumps = (f"; opening from deep contact the strip snapped between contact states at "
                 + ", ".join(f"{g:.4g}" for g in r.contact_jumps_m) + " m"
                 if r.contact_jumps_m else "")
        print(f"release gap {r.release_gap_m:.4g} m{iv('release_gap_m')} ({r.release_by}); "
              f"snap back at {r.snap_back_gap_m:.4g} m{jumps}")
    else:
        print("release gap: not determined (no contact traced in the range, or the contact "
              "could not be followed: see the JSON's contact_end_gap_m)")
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
        "pullin": r.to_dict(),
        "interval": {k: v for k, v in lo_hi.items()} or None,
        "manifest": manifest(config_of(args), None)}
    if args.json:
        write_json(args.json, json_ready(out))
    if getattr(args, "png", None):
        _plot(args.png, r, lo_hi)
    return 0


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
    model = FollowerFEM(strip, ElasticMaterial(mat.E_Pa, mat.nu, mat.density_kg_m3), magnet,
                        M_of_H, nz=args.nz if args.nz is not None else 2, order=args.order,
                        demag_factor=N, gravity_m_s2=args.gravity_m_s2)
    r = follower_fem_at_gap(model, g)
    print(f"magnet: {args.magnet} {tuple(args.magnet_size)} m, B_r {args.remanence_T:g} T, axis "
          f"at x = {magnet.position_m[0]:.4g} m, y = {magnet.position_m[1]:.4g} m; M_eff(H) from "
          f"{law_name}, phi = {phi:g}; strip demagnetizing factor N = {N:.4f}; field on the "
          f"DEFORMED body (follower FEM: 3D neo-Hookean, P{r.order}, {r.divisions} hexahedra of "
          f"6 tetrahedra{' on the half width' if model.half else ''}, {r.n_dof} dofs), "
          f"continued from the gap {r.far_gap_m:.4g} m")
    if r.converged:
        print(f"gap {g:.4g} m: tip deflection {r.tip_deflection_m:.6g} m")
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
            "follower_fem": r.to_dict(), "manifest": manifest(config_of(args), None)}))
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
