"""``mapsim rve``: generate a periodic RVE of core-shell particles and summarise it.

Draws particles from a size distribution, gives them an Fe core and an Fe3O4 shell, places
them without overlap in a periodic cube (dispersed, compact clusters or chains) and prints the
particle count, box edge, achieved volume fraction, size and cluster statistics. Writes the
RVE to HDF5 (``--out``, with a run manifest beside it), the summary to JSON (``--json``), the
particle surfaces to PLY/GLB (``--ply``/``--glb``) and a picture (``--png``).

With ``--B`` the magnetic stage (:func:`micro.dipoles.magnetize`) runs on the RVE and its
summary is printed and stored under the key ``"magnetics"``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from micro.common.files import manifest, write_json
from homogenize.cli._common import (add_field_options, add_material_options, check_input_file,
                                    check_memory, config_of, field_vector, fill_from_preset,
                                    float_in, int_in, one_line_errors)
from micro.common.validate import InputError
from micro.dipoles import FIELD_RANGES, METHODS, PME_ABOVE_N, SUMMATIONS, FieldConfig, magnetize
from micro.magnetization import DEFAULT_LAW, LAW_NAMES, get_law
from micro.materials import FE, FE3O4, SEED, particle_preset, radius_bounds_m
from micro import particles as P
from micro.particles import describe, generate_rve
from micro.rve import RVE, check_sidecar_manifest, sidecar_path
from micro._viz import export_mesh
from micro._viz import save_picture

_DESCRIPTION = __doc__

# Ranges of the options, checked at parse time (exit 2): particles from atoms to the largest
# fillers of magnetic elastomers (1 mm), densities and specific moments of real materials
# (Fe: 218 A m^2/kg, the largest of the common ferromagnets).
_R_MAX = 1e-3
_SIGMA_MAX = 300.0


def _radius(opt):
    return float_in(opt, 1e-10, _R_MAX, "m")


def _DENSITY(opt):
    return float_in(opt, 0.0, 3e4, "kg/m^3", lo_open=True)


def _SIGMA(opt):
    return float_in(opt, 0.0, _SIGMA_MAX, "A m^2/kg", lo_open=True)


#: peak memory per particle [bytes]: measured `mapsim rve` peak RSS 0.28 GB at 1e5 and
#: 0.76 GB at 1e6 particles (0.53 kB/particle); x1.5 margin, x3 with the dipole solve
_RVE_BYTES_PER_PARTICLE = 800.0


def check_rve_size(args) -> None:
    """Refuse an RVE whose memory estimate exceeds the machine, before drawing particles."""
    per = _RVE_BYTES_PER_PARTICLE * (3 if getattr(args, "B_T", None) is not None else 1)
    check_memory(f"--n {args.n}", 0.3e9 + per * args.n, "use fewer particles --n")


_LOGNORMAL_ONLY = ("!radius", "!histogram", "!distribution=monodisperse",
                   "!distribution=histogram", "!load")
#: options of ``mapsim rve`` that mean nothing without another one (or with another one):
#: refused by the CLI instead of being silently ignored (``--radius`` without ``--distribution
#: monodisperse``, ``--cluster-size`` without ``--arrangement clusters``, generation options
#: with ``--load``, ``--mean-radius`` and ``--median-radius`` together)
_RVE_OPTION_NEEDS = {
    "radius": ("distribution=monodisperse", "!load"),
    "mean_radius": ("!median_radius", *_LOGNORMAL_ONLY),
    "median_radius": _LOGNORMAL_ONLY,
    **{d: _LOGNORMAL_ONLY for d in ("gsd", "r_min", "r_max")},
    **{d: ("arrangement=clusters", "!load") for d in ("cluster_size", "cluster_density")},
    **{d: ("arrangement=chains", "!load") for d in ("chain_length", "chain_direction",
                                                    "chain_spread")},
    "agglomerated_fraction": ("arrangement=clusters", "arrangement=chains", "!load"),
    **{d: ("!load",) for d in ("phi", "n", "seed", "distribution", "histogram", "shell",
                               "core_density", "core_sigma", "shell_density", "shell_sigma",
                               "calibrate_sigma", "arrangement", "gap", "max_attempts",
                               "placement")},
}


def register(sub, formatter):
    p = sub.add_parser("rve", formatter_class=formatter, description=_DESCRIPTION,
                       help="generate a periodic particle RVE and summarise it")
    g = p.add_argument_group("RVE size and seed")
    g.add_argument("--phi", type=float_in("--phi", 0.0, 0.6, lo_open=True), default=0.0175,
                   help="particle volume fraction [1] (outer volumes / box volume), met exactly "
                        "by choosing the box edge")
    g.add_argument("--n", type=int_in("--n", 1, 5 * 10 ** 7),
                   default=2000, help="number of particles [1]")
    g.add_argument("--seed", type=int_in("--seed", 0, 2 ** 63 - 1),
                   default=0, help="random seed (same seed, same RVE)")
    g.add_argument("--load", default=None, metavar="H5",
                   help="summarise/export an RVE file written by --out instead of generating "
                        "one (generator options are then ignored)")

    g = p.add_argument_group("size distribution of the outer radius")
    g.add_argument("--distribution", choices=("lognormal", "monodisperse", "histogram"),
                   default="lognormal", help="kind of radius distribution")
    g.add_argument("--mean-radius", type=_radius("--mean-radius"), default=None,
                   help="lognormal: mean radius of the truncated distribution [m]; the "
                        "--particle-material's unless given, seed-paper's "
                        f"(default: {SEED.radius_m:g})")
    g.add_argument("--median-radius", type=_radius("--median-radius"), default=None,
                   help="lognormal: median of the parent lognormal [m] (replaces --mean-radius)")
    g.add_argument("--gsd", type=float_in("--gsd", 1.0, 10.0, lo_open=True), default=None,
                   help="lognormal: geometric standard deviation [1], > 1 (default: the "
                        "--particle-material's, seed-paper 1.4)")
    g.add_argument("--r-min", type=_radius("--r-min"), default=None,
                   help="lognormal: smallest radius [m] (default: 0.4 x the mean radius, or "
                        "the median with --median-radius: the seed's 10 nm at 25 nm)")
    g.add_argument("--r-max", type=_radius("--r-max"), default=None,
                   help="lognormal: largest radius [m] (default: 2 x the mean or median "
                        "radius: the seed's 50 nm at 25 nm)")
    g.add_argument("--radius", type=_radius("--radius"), default=None,
                   help="monodisperse: radius [m] (default: the --particle-material's mean "
                        "radius, seed-paper 25e-9)")
    g.add_argument("--histogram", default=None, metavar="CSV",
                   help="histogram: CSV file with columns radius_m and count (number) or "
                        "weight (mass fraction); implies --distribution histogram")

    g = p.add_argument_group("core-shell composition")
    g.add_argument("--shell", type=float_in("--shell", 0.0, _R_MAX, "m"), default=None,
                   help="Fe3O4 shell thickness [m]; 0 = homogeneous particles with the seed's "
                        f"{SEED.sigma_s_Am2_kg:g} A m^2/kg (default: the --particle-material's, "
                        "seed-paper 0)")
    g.add_argument("--core-density", type=_DENSITY("--core-density"), default=None,
                   help="core density [kg/m^3] (default: the --particle-material's, seed-paper "
                        f"{FE.density_kg_m3:g})")
    g.add_argument("--core-sigma", type=_SIGMA("--core-sigma"), default=None,
                   help="core specific saturation moment [A m^2/kg] (default: the "
                        "--particle-material's; seed-paper: "
                        f"{FE.sigma_s_Am2_kg:g} with a shell, {SEED.sigma_s_Am2_kg:g} without)")
    g.add_argument("--shell-density", type=_DENSITY("--shell-density"),
                   default=FE3O4.density_kg_m3, help="shell density [kg/m^3]")
    g.add_argument("--shell-sigma", type=float_in("--shell-sigma", 0.0, _SIGMA_MAX, "A m^2/kg"),
                   default=FE3O4.sigma_s_Am2_kg,
                   help="shell specific saturation moment [A m^2/kg]")
    g.add_argument("--calibrate-sigma", type=_SIGMA("--calibrate-sigma"), default=None,
                   help="measured mass-averaged specific moment of the powder [A m^2/kg]: "
                        "the core moment is calibrated to reproduce it (default: the "
                        "--particle-material's; none for seed-paper)")

    g = p.add_argument_group("arrangement")
    g.add_argument("--arrangement", choices=("dispersed", "clusters", "chains"),
                   default="dispersed", help="isolated particles, compact clusters or chains")
    g.add_argument("--gap", type=float_in("--gap", 0.0, _R_MAX, "m"), default=0.0,
                   help="minimum surface-to-surface distance between particles [m]")
    g.add_argument("--cluster-size", type=int_in("--cluster-size", 2, 5000), default=20,
                   help="clusters: particles per cluster [1]")
    g.add_argument("--cluster-density", type=float_in("--cluster-density", 0.0, 0.6, lo_open=True),
                   default=0.5,
                   help="clusters: internal packing density [1] (solid volume / "
                        "gyration-equivalent sphere)")
    g.add_argument("--chain-length", type=float_in("--chain-length", 2.0, 1e4), default=5.0,
                   help="chains: mean particles per chain [1] (geometric distribution)")
    g.add_argument("--chain-direction", type=float_in("--chain-direction", -1e6, 1e6), nargs=3,
                   default=(0.0, 0.0, 1.0),
                   metavar=("X", "Y", "Z"), help="chains: axis direction [1]")
    g.add_argument("--chain-spread", type=float_in("--chain-spread", 0.0, 90.0, "deg"),
                   default=0.0,
                   help="chains: RMS misalignment of the chain axes [deg] (Fisher distribution)")
    g.add_argument("--agglomerated-fraction", type=float_in("--agglomerated-fraction", 0.0, 1.0),
                   default=1.0,
                   help="clusters/chains: fraction of particles that are agglomerated [1]")
    g.add_argument("--max-attempts", type=int_in("--max-attempts", 1, 10 ** 9), default=200_000,
                   help="random positions tried per body before declaring a jam [1]")
    g.add_argument("--placement", choices=("auto", "rsa", "compress"), default="auto",
                   help="rsa: random sequential addition; compress: grow and relax (dispersed "
                        "only, reaches denser packings); auto: rsa, compress if rsa jams")

    g = p.add_argument_group("output")
    g.add_argument("--out", default=None, metavar="H5",
                   help="write the RVE to this HDF5 file (and a manifest <name>.manifest.json)")
    g.add_argument("--json", default=None, metavar="FILE", help="write the summary as JSON")
    g.add_argument("--ply", default=None, metavar="FILE",
                   help="write particle surfaces as PLY [m] (colours: clusters)")
    g.add_argument("--glb", default=None, metavar="FILE",
                   help="write particle surfaces as binary glTF [m]")
    g.add_argument("--png", default=None, metavar="FILE",
                   help="write a picture: 3D view, mid-plane slice, radius histogram")
    g.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: on for n >= 20000)")

    _add_magnetics_options(p)
    add_material_options(p, matrix=False,
                         what="--particle-material fills --mean-radius, --gsd, --radius, "
                              "--shell, --core-density, --core-sigma, --calibrate-sigma, "
                              "--rho-particle, --sigma-s and the core material of the "
                              "intrinsic magnetization laws; --r-min/--r-max follow the "
                              "radius.")
    p.set_defaults(func=_cmd, outputs=("out", "json", "ply", "glb", "png"),
                   inputs=("load", "histogram"), sidecar_outputs=("out",),
                   option_needs=_RVE_OPTION_NEEDS)
    one_line_errors(sub)


def apply_particle_preset(args) -> None:
    """Fill the particle options not given from ``--particle-material`` (the defaults of
    ``seed-paper`` are the former fixed defaults, bit for bit) and the lognormal's bounds from
    the mean (or median) radius (:func:`micro.materials.radius_bounds_m`)."""
    p = particle_preset(getattr(args, "particle_material", "seed-paper"))
    fill_from_preset(args, {
        "mean_radius": p.mean_radius_m, "gsd": p.gsd, "radius": p.mean_radius_m,
        "shell": p.shell_m, "core_density": p.density_kg_m3, "core_sigma": p.core_sigma_Am2_kg,
        "calibrate_sigma": p.calibrate_sigma_Am2_kg, "rho_kg_m3": p.density_kg_m3,
        "sigma_s_Am2_kg": p.powder_sigma_Am2_kg})
    lo, hi = radius_bounds_m(args.median_radius if args.median_radius is not None
                             else args.mean_radius)
    fill_from_preset(args, {"r_min": lo, "r_max": hi})


def generator_kwargs(args) -> dict:
    """Keyword arguments of :func:`micro.particles.generate_rve` from parsed CLI options."""
    apply_particle_preset(args)

    kind = "histogram" if args.histogram else args.distribution
    if kind == "histogram":
        if not args.histogram:
            raise InputError("--distribution histogram needs --histogram CSV")
        check_input_file("--histogram", args.histogram)
        dist = P.Histogram.from_csv(args.histogram)
    elif kind == "monodisperse":
        dist = P.Monodisperse(args.radius)
    elif args.median_radius is not None:
        dist = P.LogNormal(args.median_radius, args.gsd, args.r_min, args.r_max)
    else:
        dist = P.LogNormal.from_mean(args.mean_radius, args.gsd, args.r_min, args.r_max)
    comp = P.CoreShell(shell_m=args.shell, core_density_kg_m3=args.core_density,
                       core_sigma_Am2_kg=args.core_sigma, shell_density_kg_m3=args.shell_density,
                       shell_sigma_Am2_kg=args.shell_sigma,
                       calibrate_sigma_Am2_kg=args.calibrate_sigma)
    return dict(distribution=dist, composition=comp, arrangement=args.arrangement,
                gap_m=args.gap, cluster_size=args.cluster_size,
                cluster_density=args.cluster_density, chain_length=args.chain_length,
                chain_direction=tuple(args.chain_direction), chain_spread_deg=args.chain_spread,
                agglomerated_fraction=args.agglomerated_fraction, max_attempts=args.max_attempts,
                placement=args.placement)


def _check_outputs(args):
    """Refuse bad output names before any work is done."""
    for opt, suffixes in (("out", (".h5", ".hdf5")), ("ply", (".ply",)), ("glb", (".glb",)),
                          ("png", (".png",)), ("json", (".json",))):
        val = getattr(args, opt)
        if val is not None and Path(val).suffix.lower() not in suffixes:
            raise InputError(f"--{opt} {val}: file name must end in {' or '.join(suffixes)}")


def _fmt_summary(s: dict) -> str:
    nm = 1e9
    r = s["radius_m"]
    lines = [
        f"particles            {s['n']}",
        f"box edge             {s['box_m']:.6g} m ({s['box_m'] * nm:.1f} nm)",
        f"volume fraction      {s['phi']:.6g}" + (
            f" (target {s['phi_target']:g}, relative error {s['phi_rel_error']:.1e})"
            if s.get("phi_target") else ""),
        f"radius [nm]          mean {r['mean'] * nm:.2f}  std {r['std'] * nm:.2f}  "
        f"min {r['min'] * nm:.2f}  median {r['median'] * nm:.2f}  max {r['max'] * nm:.2f}  "
        f"volume-weighted mean {r['volume_weighted_mean'] * nm:.2f}",
        f"core radius mean     {s['core_radius_mean_m'] * nm:.2f} nm",
        f"specific moment      {s['specific_moment_Am2_kg']:.5g} A m^2/kg (mass average); "
        f"composite M_sat {s['M_sat_composite_A_m']:.5g} A/m",
        f"smallest gap         {s['min_gap_m'] * nm:.4g} nm" + (
            f" (required {s['gap_m'] * nm:g} nm)" if s.get("gap_m") is not None else ""),
    ]
    c = s["clusters"]
    if c["n_clusters"]:
        kind = s["arrangement"] or "clusters"
        line = (f"{kind:<20} {c['n_clusters']} with {c['size_mean']:.2f} particles on "
                f"average ({c['size_min']}-{c['size_max']}), agglomerated fraction "
                f"{c['agglomerated_fraction']:.3f}")
        if "packing_density_mean" in c:
            line += (f", packing density {c['packing_density_mean']:.4f} "
                     f"({c['packing_density_min']:.4f}-{c['packing_density_max']:.4f})")
        if "alignment_order_parameter" in c:
            line += (f", alignment S = {c['alignment_order_parameter']:.4f} (expected "
                     f"{c['alignment_order_parameter_expected']:.4f})")
        lines.append(line)
    else:
        lines.append("clusters             none (all particles isolated)")
    return "\n".join(lines)


def _cmd(args) -> int:

    _check_outputs(args)
    apply_particle_preset(args)          # the manifest records the numbers used
    if args.load:
        rve = RVE.load(args.load)
        note = check_sidecar_manifest(args.load)
        if note:
            print(f"note: {note}", file=sys.stderr)
        dist = None
    else:
        check_rve_size(args)
        kw = generator_kwargs(args)
        dist = kw["distribution"]
        progress = args.progress if args.progress is not None else args.n >= 20000
        rve = generate_rve(args.phi, args.n, args.seed, progress=progress, **kw)
    summary = describe(rve)

    mag_summary = _magnetics_summary(args, rve)
    if mag_summary:
        summary["magnetics"] = mag_summary

    print(_fmt_summary(summary))
    if "magnetics" in summary:
        print("magnetics            " + json.dumps(summary["magnetics"], default=str))

    config = config_of(args)
    if args.out:
        man = manifest(config, rve.seed)
        rve.save(args.out, manifest=man)          # the copy inside the file is authoritative
        write_json(sidecar_path(args.out), man)
        print(f"wrote {args.out}")
    if args.ply or args.glb:
        for f in (args.ply, args.glb):
            if f:
                export_mesh(rve, f)
                print(f"wrote {f}")
    if args.png:
        save_picture(rve, args.png, dist)
        print(f"wrote {args.png}")
    if args.json:
        write_json(args.json, {"summary": summary, "manifest": manifest(config, rve.seed)})
        print(f"wrote {args.json}")
    return 0


def _add_magnetics_options(parser) -> None:
    """The magnetics options of ``mapsim rve``."""
    g = parser.add_argument_group("magnetics (self-consistent dipoles; active when --B is given)")
    add_field_options(g, help_B="applied flux density mu0 |H| [T], along --B-direction; enables "
                                "the magnetic solve (default: none, no magnetics)")
    g.add_argument("--gradB", dest="gradB_T_per_m", type=float_in("--gradB", -1e4, 1e4, "T/m"),
                   default=SEED.gradB_T_per_m,
                   help="gradient of |B| along z [T/m] (default: 1.78, the seed paper)")
    g.add_argument("--law", default=DEFAULT_LAW, choices=LAW_NAMES,
                   help=f"magnetization law of one particle (default: {DEFAULT_LAW}: each particle "
                        "the intrinsic law of its regime from its core radius -- Langevin "
                        "(superparamagnetic), Stoner-Wohlfarth (single-domain), soft ferromagnet "
                        "with the anisotropy approach to saturation (multi-domain), all behind "
                        "the sphere's demagnetization N = 1/3). 'apparent-fk' (alias "
                        "'frohlich-kennelly') is the former APPARENT law applied to the local "
                        "field: its chi0 = 3 also sets the approach to saturation, which halves "
                        "the force near 0.6 T; kept for comparison only")
    g.add_argument("--chi", type=float_in("--chi", 0.0, math.inf, lo_open=True), default=None,
                   help="linear law: intrinsic susceptibility [-] (default: inf, i.e. m = 3 V H)")
    g.add_argument("--chi0", type=float_in("--chi0", 0.0, 1e6, lo_open=True), default=None,
                   help="apparent-fk: initial apparent susceptibility [-] (default: 3)")
    g.add_argument("--chi-i", dest="chi_i", type=float_in("--chi-i", 0.0, math.inf, lo_open=True),
                   default=None,
                   help="regime, approach, soft-fk: intrinsic susceptibility of the particle "
                        "material [-] (default: inf for regime/approach, 1000 for soft-fk)")
    g.add_argument("--T", dest="T_K", type=float_in("--T", 0.0, 1e4, "K", lo_open=True),
                   default=None,
                   help="langevin, stoner-wohlfarth, regime: temperature [K] (default: 300)")
    g.add_argument("--measurement-time", dest="measurement_time_s",
                   type=float_in("--measurement-time", 0.0, 1e12, "s", lo_open=True),
                   default=None,
                   help="regime: measurement time of the Neel-Brown blocking criterion [s] "
                        "(default: 100)")
    g.add_argument("--demag-factor", dest="demag_factor",
                   type=FIELD_RANGES["demag_factor"].arg("--demag-factor"),
                   default=None,
                   help="specimen demagnetizing factor N in [0, 1] [-] (default: none = "
                        "metallic boundary, internal field = applied field)")
    g.add_argument("--tol", type=FIELD_RANGES["tol"].arg("--tol"), default=1e-8,
                   help="relative residual of the self-consistent moments [-] (default: 1e-8)")
    g.add_argument("--accuracy", type=FIELD_RANGES["accuracy"].arg("--accuracy"), default=1e-6,
                   help="relative accuracy of the periodic dipole sums [-] (default: 1e-6)")
    g.add_argument("--solver", dest="mag_method", default="anderson", choices=METHODS,
                   help="nonlinear solver for the moments (default: anderson)")
    g.add_argument("--summation", default="auto", choices=SUMMATIONS,
                   help="periodic sum: plain Ewald, particle-mesh Ewald, or auto (PME above "
                        f"{PME_ABOVE_N} particles) (default: auto)")
    g.add_argument("--c-powder", dest="c_powder",
                   type=FIELD_RANGES["c_powder"].arg("--c-powder"),
                   default=SEED.c,
                   help="the seed's powder concentration c for d_eff = phi_eff / c [-] "
                        "(default: 0.035)")
    g.add_argument("--rho-particle", dest="rho_kg_m3",
                   type=FIELD_RANGES["rho_kg_m3"].arg("--rho-particle"),
                   default=None,
                   help="density of the saturated reference material in phi_eff [kg/m^3] "
                        "(default: the --particle-material's, seed-paper "
                        f"{SEED.particle_density_kg_m3:g})")
    g.add_argument("--sigma-s", dest="sigma_s_Am2_kg",
                   type=FIELD_RANGES["sigma_s_Am2_kg"].arg("--sigma-s"),
                   default=None,
                   help="specific saturation moment of the reference material [A m^2/kg] "
                        "(default: the --particle-material's powder moment, seed-paper "
                        f"{SEED.sigma_s_Am2_kg:g})")


def _magnetics_summary(args, rve) -> dict:
    """Solve the magnetics for the options ``args``; the JSON summary entries ({} without --B)."""
    if getattr(args, "B_T", None) is None:
        return {}
    st = magnetize(rve, field_config(args))
    return {
        "B_applied_T": st.B_applied_T.tolist(),
        "gradB_T_per_m": float(args.gradB_T_per_m),
        "law": st.law,
        "M_eff_A_per_m": st.M_eff_A_per_m.tolist(),
        "f_eff_N_m3": st.f_eff_N_m3.tolist(),
        "phi_eff": st.phi_eff,
        "d_eff": st.d_eff,
        "virial_stress_Pa": st.virial_stress_Pa.tolist(),
        "iterations": st.iterations,
        "residual": st.residual,
        "field_evaluations": st.field_evaluations,
        "dd_force_sum_rel": st.dd_force_sum_rel,
        "summation": st.summation,
    }


def _core_law_params(args) -> tuple:
    """The core material of a non-iron --particle-material for the intrinsic laws that take
    one (regime: ``material``; approach: K1, Ms; stoner-wohlfarth: K); none for iron cores, so
    that the iron presets keep the laws' own defaults bit for bit."""
    core = particle_preset(getattr(args, "particle_material", "seed-paper")).core
    if core is FE:
        return ()
    law = {"frohlich-kennelly": "apparent-fk"}.get(args.law, args.law)
    return {"regime": (("material", core.name),),
            "approach": (("K1_J_m3", core.K1_J_m3), ("Ms_core_A_m", core.Ms_A_m)),
            "stoner-wohlfarth": (("K_J_m3", abs(core.K1_J_m3)),)}.get(law, ())


def field_config(args) -> FieldConfig:
    """The magnetic stage's configuration from the options of ``mapsim rve``."""
    apply_particle_preset(args)
    B = field_vector(args.B_T, getattr(args, "B_direction", None))
    B = B if isinstance(B, float) else tuple(B)
    params = tuple((k, v) for k, v in (("chi", args.chi), ("chi0", args.chi0), ("T_K", args.T_K),
                                       ("chi_i", args.chi_i),
                                       ("measurement_time_s", args.measurement_time_s))
                   if v is not None)
    params += _core_law_params(args)
    get_law(args.law, **dict(params))          # unknown law parameters fail here, before work
    return FieldConfig(B_T=B, gradB_T_per_m=args.gradB_T_per_m, law=args.law,
                       law_params=params, demag_factor=args.demag_factor, tol=args.tol,
                       accuracy=args.accuracy, method=args.mag_method, summation=args.summation,
                       c_powder=args.c_powder, rho_kg_m3=args.rho_kg_m3,
                       sigma_s_Am2_kg=args.sigma_s_Am2_kg)
