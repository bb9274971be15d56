"""The magnetostriction experiment predicted as it was measured: a change of LENGTH of a body.

A magnetostriction data set (``kind = "magnetostriction"``) measures the axial strain of a
specimen (column ``aspect_ratio`` = L/D of a cylinder, field along its axis). The causes of
:mod:`homogenize.experiments.causes` predict a volume-MEAN strain of a small-strain linear body
with a shape coefficient and, to reach the measured amplitude, a FITTED ``kappa_extra``. This
module predicts the measured quantity instead, with nothing fitted, through the specimen solver
(:mod:`homogenize.macro.specimen`: the field in and around the deforming cylinder, Kelvin
tractions and magnetic pressure, finite-strain neo-Hookean body), for three models of the
material's magnetic stress:

* ``continuum`` -- no microstructural stress (Lefevre, Danas & Lopez-Pamies 2017; Stewart &
  Anand 2025);
* ``affine`` -- plus the stress of the particles' interactions at fixed positions
  (:func:`homogenize.experiments.rve_tables.affine_kappa`: dipole virial x the cell FEM's share);
* ``relaxed`` -- the affine stress plus what the coupled RVE (particles that move,
  :mod:`homogenize.cell.relax`) adds, from a relax table at the experiment's phi and MATRIX modulus
  (:func:`relaxed_kappa`); offered only when such a table exists.

Independent inputs (none taken from the magnetostriction curve): the TOML's matrix modulus
``[matrix] E_Pa`` and ``nu``, times the project's filler stiffening (cell FEM,
:func:`homogenize.experiments.rve_tables.filler_stiffness_ratio`, with its standard error); the
composite's ``M(H_in)`` from self-consistent dipoles in random periodic RVEs of the TOML's
particles (:func:`composite_law`; the physical default law of :mod:`micro.magnetization`).

What is reported per model (:func:`specimen_account`): the predicted curve (end faces' mean
strain, axis strain, mean strain) at the measured fields of the rising branch; at the largest
field it reached the measured and predicted values and the share of the amplitude explained;
the RMSE with nothing fitted; what still has to be FITTED to match (one extra uniform stress
``kappa_extra mu0 <M>^2`` added in the small-strain way, ``eps += -(-kappa_extra) x``,
``x = mu0 <M>^2 / E``), with its leave-one-out held-out RMSE and the held-out gain over the
diagnosis's own final model on the same rows.

Model error stated in the output: the specimen mesh (``mesh`` option, the bench and
``results/specimen`` give its size), the rounded rim (0.1 R, the solver's default), the
monodisperse particles at the TOML's mean radius, the modulus interval (filler stiffening's
standard error; the matrix modulus' own uncertainty is what the TOML's source gives, none
when it gives none), applied to the prediction by linear scaling (strain ~ 1 / E at small
strain: approximate at finite strain, labelled so).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.constants import mu_0 as MU0

from homogenize.macro import finite_strain as fs
from homogenize.macro import magnetostatics as ms
from homogenize.macro.specimen import Specimen, solve_specimen
from micro.common.validate import ConvergenceError, InputError
from micro.dipoles import solve as solve_dipoles
from micro.magnetization import DEFAULT_LAW
from micro.particles import CoreShell, Monodisperse, generate_rve

from homogenize.experiments.io import Experiment
from homogenize.experiments.rve_tables import (Unavailable, affine_kappa, filler_stiffness_ratio, restructuring_table,
                     stiffness_table)

__all__ = ["MESHES", "MODELS", "composite_law", "relaxed_kappa", "relaxed_stiffening",
           "loo_fitted_kappa",
           "specimen_account", "SPECIMEN_RADIUS_M", "EDGE_FRACTION"]

#: specimen meshes: (elements along the radius, segments of the field mesh's profile)
MESHES = {"coarse": (4, 24), "normal": (8, 48)}
MODELS = ("continuum", "affine", "relaxed")
#: the cylinder's radius [m]: the problem is scale free (no gravity, no length in the laws),
#: so any radius gives the same strains; 5 mm is the size of Diguet's specimens
SPECIMEN_RADIUS_M = 5e-3
#: the rim's rounding over the radius (the solver's default; a sharp rim is singular)
EDGE_FRACTION = 0.1
#: fields below this [T] are not solved (the strain there is below 1e-4 of the amplitude)
B_MIN_T = 0.02
#: the internal field of the composite table reaches this multiple of the largest applied
#: field (the cylinder's rim sees more than the mean; the table is never extrapolated)
TABLE_HEADROOM = 1.5
CONFIDENCE_Z = 1.959963984540054      # two-sided 95 % of the normal law


def composite_law(phi: float, particles, *, B_max_T: float, seeds=(1, 2, 3), n: int = 100,
                  n_nodes: int = 14):
    """``M(H_in)`` of the composite from self-consistent dipoles in random periodic RVEs.

    phi : particle volume fraction [-]; particles : :class:`~homogenize.experiments.io.Particles`
    (density, specific saturation moment, mean radius: monodisperse spheres at the mean);
    B_max_T : the largest internal field ``mu0 H_in`` the table must reach [T]; seeds, n : the
    realizations and their particle count; n_nodes : internal fields, geometric from 0.02 T.

    The metallic (tin-foil) boundary of the Ewald sum makes the applied field of the RVE its
    internal field, so ``M_eff`` against ``B_T`` is the material law ``M(H_in)``.
    Returns ``(TableLaw of the mean over realizations, H nodes [A/m], M (seeds, nodes) [A/m])``.
    """
    if B_max_T <= 0.02:
        raise InputError(f"B_max_T must exceed 0.02 T, got {B_max_T!r}")
    comp = CoreShell(shell_m=0.0, core_density_kg_m3=float(particles.density_kg_m3),
                     core_sigma_Am2_kg=float(particles.sigma_s_Am2_kg))
    B_in = np.geomspace(0.02, float(B_max_T), int(n_nodes))
    M = []
    for seed in seeds:
        rve = generate_rve(float(phi), int(n), int(seed),
                           distribution=Monodisperse(float(particles.radius_mean_m)),
                           composition=comp)
        M.append([float(solve_dipoles(rve, b, 0.0, DEFAULT_LAW).M_eff_A_per_m[2])
                  for b in B_in])
    M = np.array(M)
    H = B_in / MU0
    law = ms.TableLaw(H, np.maximum.accumulate(M.mean(axis=0)),
                      source=f"M_eff of {len(seeds)} random RVEs of {n} particles "
                             f"(law {DEFAULT_LAW!r}, phi {phi:g})")
    return law, H, M


def relaxed_kappa(phi: float, Ms_particle_A_per_m: float, restructuring):
    """``kappa(|M|)`` [-] of the ``relaxed`` specimen model: the affine coefficient plus what
    the coupled RVE's restructuring adds.

    A uniform eigenstress ``kappa mu0 M^2 (m m - I/3)`` in an incompressible free body gives an
    axial strain ``-kappa mu0 M^2 / E`` (the sign convention of
    :func:`homogenize.macro.specimen.solve_specimen`). The relax table's relaxed-minus-affine
    free strain of the RVE along the field, ``d_eps``, at its relaxed ``M`` and
    ``E_parallel``, is therefore the coefficient change ``d_kappa = -d_eps E_par / (mu0 M^2)``
    (mean over realizations), tabulated against ``|M|`` with ``d_kappa(0) = 0`` (the
    restructuring strain grows as M^4, so ``d_kappa ~ M^2``) and held beyond the last node. Not
    included: the restructuring's change of ``M`` and of the modulus themselves (the table's
    ``d_x``). That is NOT second order at a soft matrix: at Diguet's E0 = 0.14 MPa the relaxed
    RVEs are 1.8-2.1x stiffer along the field at 1.13 T than at zero field
    (``relax_diguet2010_E0.h5``; chains of particles in near contact, resolved by 16^3 voxels),
    while ``d_kappa`` acts on the composite's zero-field modulus in the specimen: the relaxed
    model then overestimates the elongation (the account states the ratio,
    :func:`relaxed_stiffening`). The mean-strain path (``causes.restructuring_strain``)
    carries the change of ``mu0 M^2 / E`` through ``d_x``.
    """
    base = affine_kappa(phi, Ms_particle_A_per_m)
    r = restructuring
    if r.M_relaxed_A_per_m is None:
        raise InputError("the relax table's M_eff is missing; read it with "
                         "homogenize.experiments.rve_tables.restructuring_table")
    # x = mu0 M^2 / E_par of the relaxed RVE, so d_kappa = -d_eps / x
    with np.errstate(divide="ignore", invalid="ignore"):
        dk = np.where(r.x_relaxed > 0, -r.d_eps_rve / r.x_relaxed, 0.0).mean(axis=1)
    M_nodes = np.abs(np.asarray(r.M_relaxed_A_per_m, float)).mean(axis=1)
    order = np.argsort(M_nodes)
    M_nodes, dk = M_nodes[order], dk[order]
    if M_nodes[0] > 0.0:
        M_nodes, dk = np.concatenate(([0.0], M_nodes)), np.concatenate(([0.0], dk))
    dk[0] = 0.0

    def kappa(M_abs):
        M_abs = np.asarray(M_abs, float)
        return base(M_abs) + np.interp(M_abs, M_nodes, dk)
    kappa.nodes = (M_nodes, dk)
    return kappa


def relaxed_stiffening(restructuring) -> dict:
    """How much stiffer along the field the relaxed RVEs of a relax table are than at zero
    field (the ``E_parallel`` the relaxed model does not carry into the body): per field step
    the mean over realizations of ``E_par(B) / E_par(0)``, and its smallest and largest
    realization at the last step."""
    E = np.asarray(restructuring.E_parallel_Pa, float)
    r = E / E[0]
    return {"B_T": [float(b) for b in restructuring.B_T],
            "E_parallel_ratio_mean": [float(v) for v in r.mean(axis=1)],
            "E_parallel_ratio_range_at_last_step": [float(r[-1].min()), float(r[-1].max())],
            "meaning": "relaxed RVE's E along the field over its zero-field value; the relaxed "
                       "specimen model keeps the zero-field composite modulus"}


def loo_fitted_kappa(pred, measured, x):
    """One fitted coefficient on top of a prediction: ``measured ~ pred + k x``.

    Least squares ``k = sum(x r) / sum(x^2)`` with ``r = measured - pred``; the leave-one-out
    residuals of this one-parameter regression without intercept are ``e_i / (1 - h_i)``,
    ``h_i = x_i^2 / sum(x^2)`` (exact for linear least squares). Returns ``(k, standard error of
    k, in-sample RMSE, leave-one-out RMSE)``; fewer than 2 rows: the leave-one-out RMSE is NaN.
    """
    pred, y, x = (np.asarray(a, float) for a in (pred, measured, x))
    r = y - pred
    sxx = float(np.sum(x * x))
    if sxx <= 0.0:
        raise InputError("loo_fitted_kappa needs a row with x != 0")
    k = float(np.sum(x * r)) / sxx
    e = r - k * x
    n = y.size
    s2 = float(np.sum(e * e)) / (n - 1) if n > 1 else math.nan
    se = math.sqrt(s2 / sxx) if n > 1 else math.nan
    h = x * x / sxx
    loo = float(np.sqrt(np.mean((e / (1.0 - h)) ** 2))) if n > 1 and np.all(h < 1.0) \
        else math.nan
    return k, se, float(np.sqrt(np.mean(e * e))), loo


def _groups(exp: Experiment):
    """Rows grouped by (phi, aspect ratio): one specimen geometry and material each."""
    c = exp.columns
    keys = sorted({(float(p), float(a)) for p, a in zip(c["phi"], c["aspect_ratio"])})
    return [(p, a, np.flatnonzero((c["phi"] == p) & (c["aspect_ratio"] == a)))
            for p, a in keys]


def _solve(model, phi, aspect, law, solid, kappa, B, n_mesh, n_boundary):
    R = SPECIMEN_RADIUS_M
    spec = Specimen("cylinder", R, length_m=2.0 * R * aspect, n_mesh=n_mesh,
                    n_boundary=n_boundary, edge_radius_m=EDGE_FRACTION * R)
    try:
        res = solve_specimen(spec, law, solid, B, model=model, kappa=kappa, load_steps=3)
        return list(res.steps), None
    except ConvergenceError as exc:
        return list(exc.steps_converged or ()), str(exc).splitlines()[0][:300]


def specimen_account(exp: Experiment, *, final_cv_pred=None, mesh: str = "normal",
                     seeds=(1, 2, 3), n_particles: int = 100, progress=None) -> dict:
    """The specimen solver's prediction of a magnetostriction experiment, three models.

    exp : a magnetostriction :class:`~homogenize.experiments.io.Experiment` (columns ``phi``,
        ``aspect_ratio`` (L/D of a cylinder), ``B_T``, measured axial ``strain``)
    final_cv_pred : the diagnosis's held-out predictions of its final model (per row), for the
        held-out gain on the same rows; None: no gain reported
    mesh : "coarse" | "normal" (:data:`MESHES`)
    seeds, n_particles : the RVEs of :func:`composite_law`
    progress : callable ``progress(text)`` or None

    Returns the JSON-ready account (module docstring); ``available`` False with ``why`` when
    the experiment is not a magnetostriction one or lacks the columns.
    """
    if exp.kind != "magnetostriction":
        return {"available": False, "why": f"kind {exp.kind!r} is not magnetostriction"}
    if mesh not in MESHES:
        raise InputError(f"mesh must be one of {sorted(MESHES)}, got {mesh!r}")
    n_mesh, n_boundary = MESHES[mesh]
    c = exp.columns
    y = np.asarray(exp.y, float)
    B_abs = np.abs(np.asarray(c["B_T"], float))
    pred = {m: {k: np.full(exp.n_rows, np.nan) for k in ("end_mean", "axis", "mean", "x")}
            for m in MODELS}
    E_row = np.full((exp.n_rows, 3), np.nan)          # composite E, its 95 % interval [Pa]
    stiff_row = np.full(exp.n_rows, np.nan)           # relaxed RVEs' E_par(B) / E_par(0)
    groups_out = []
    E0, nu = float(exp.matrix.E_Pa), float(exp.matrix.nu)
    Ms_p = float(exp.particles.Ms_A_per_m)
    st = stiffness_table()
    for phi, aspect, rows in _groups(exp):
        up = rows[~exp.down[rows]] if (~exp.down[rows]).any() else rows
        B = np.unique(np.round(B_abs[up][B_abs[up] >= B_MIN_T], 12))
        ratio = float(filler_stiffness_ratio(phi))
        ratio_se = float(np.interp(phi, st["phi"], st["E_ratio_se"]))
        E = E0 * ratio
        E_lo, E_hi = E0 * (ratio - CONFIDENCE_Z * ratio_se), E0 * (ratio + CONFIDENCE_Z * ratio_se)
        E_row[rows] = (E, E_lo, E_hi)
        solid = fs.NeoHookeanSolid.from_poisson(E / (2.0 * (1.0 + nu)), nu)
        law, H_tab, M_tab = composite_law(phi, exp.particles,
                                          B_max_T=TABLE_HEADROOM * float(B.max(initial=0.1)),
                                          seeds=seeds, n=n_particles)
        kappas = {"continuum": None, "affine": affine_kappa(phi, Ms_p)}
        relax_note = None
        try:
            tab = restructuring_table(phi, E0)
            kappas["relaxed"] = relaxed_kappa(phi, Ms_p, tab)
            relax_note = {**tab.provenance, "stiffening": relaxed_stiffening(tab)}
            stf = relax_note["stiffening"]
            stiff_row[rows] = np.interp(B_abs[rows], stf["B_T"], stf["E_parallel_ratio_mean"])
        except Unavailable as exc:
            relax_note = {"available": False, "why": str(exc)}
        g = {"phi": phi, "aspect_ratio_L_over_D": aspect, "rows": int(rows.size),
             "specimen": {"shape": "cylinder", "radius_m": SPECIMEN_RADIUS_M,
                          "length_m": 2 * SPECIMEN_RADIUS_M * aspect,
                          "edge_radius_m": EDGE_FRACTION * SPECIMEN_RADIUS_M,
                          "mesh": mesh, "n_mesh": n_mesh, "n_boundary": n_boundary},
             "matrix_E_Pa": E0, "matrix_nu": nu,
             "filler_stiffness_ratio": ratio, "filler_stiffness_ratio_se": ratio_se,
             "composite_E_Pa": E, "composite_E_Pa_ci95": [E_lo, E_hi],
             "composite_law": {"H_nodes_A_per_m": list(H_tab),
                               "M_A_per_m_mean": list(law.M_nodes_A_per_m),
                               "realizations": len(seeds), "n_particles": int(n_particles),
                               "chi_initial": float(M_tab[:, 0].mean() / H_tab[0])},
             "relax_table": relax_note, "models": {}}
        for model in MODELS:
            if model == "relaxed" and "relaxed" not in kappas:
                g["models"][model] = {"available": False, "why": relax_note["why"]}
                continue
            if progress is not None:
                progress(f"specimen L/D {aspect:g}, phi {phi:g}: {model}")
            steps, failed = _solve(model, phi, aspect, law, solid, kappas[model], B,
                                   n_mesh, n_boundary)
            Bs = np.array([s.B_applied_T for s in steps])
            curves = {"end_mean": [s.strain_end_mean for s in steps],
                      "axis": [s.strain_axis for s in steps],
                      "mean": [s.mean_strain_zz for s in steps],
                      "x": [MU0 * s.M_mean_A_per_m ** 2 / E for s in steps]}
            if Bs.size:
                reach = B_abs[rows] <= Bs[-1] * (1 + 1e-9)
                for k, v in curves.items():
                    xs = np.concatenate(([0.0], Bs))
                    vs = np.concatenate(([0.0], np.asarray(v, float)))
                    pred[model][k][rows[reach]] = np.interp(B_abs[rows[reach]], xs, vs)
            g["models"][model] = {"available": True, "failed": failed,
                                  "B_applied_T": list(Bs),
                                  "strain_end_mean": curves["end_mean"],
                                  "strain_axis": curves["axis"],
                                  "mean_strain_zz": curves["mean"],
                                  "M_mean_A_per_m": [s.M_mean_A_per_m for s in steps]}
        groups_out.append(g)
    models_out = {}
    for model in MODELS:
        p = pred[model]["end_mean"]
        ok = np.isfinite(p)
        if not ok.any():
            whys = [g["models"][model].get("why") or g["models"][model].get("failed")
                    for g in groups_out]
            models_out[model] = {"available": False,
                                 "why": "; ".join(str(w) for w in whys if w)
                                 or "no field step converged"}
            continue
        pool = np.flatnonzero(ok & ~exp.down)
        pool = pool if pool.size else np.flatnonzero(ok)
        i = int(pool[np.argmax(B_abs[pool])])        # the largest field reached (rising branch)
        e = p[ok] - y[ok]
        out = {"available": True, "rows_predicted": int(ok.sum()), "rows": exp.n_rows,
               "at": {"B_T": float(c["B_T"][i]), "branch": "down" if exp.down[i] else "up"},
               "measured": float(y[i]), "predicted_end_mean": float(p[i]),
               "predicted_axis": float(pred[model]["axis"][i]),
               "predicted_mean_strain": float(pred[model]["mean"][i]),
               "predicted_end_mean_ci95_modulus_linearized": sorted(
                   [float(p[i] * E_row[i, 0] / E_row[i, j]) for j in (1, 2)]),
               "fraction_explained": float(p[i] / y[i]) if y[i] != 0 else math.nan,
               "rmse_nothing_fitted": float(np.sqrt(np.mean(e * e)))}
        if model == "relaxed" and np.isfinite(stiff_row[i]):
            # the relaxed RVEs' stiffening carried into the body by linear scaling (as the
            # modulus interval is): an estimate, not a solve on the stiffer body
            ps = float(p[i] / stiff_row[i])
            out["with_relaxed_stiffening_linearized"] = {
                "E_parallel_ratio": float(stiff_row[i]), "predicted_end_mean": ps,
                "fraction_explained": float(ps / y[i]) if y[i] != 0 else math.nan,
                "meaning": "predicted_end_mean / (E_par(B) / E_par(0)) of the relax table: the "
                           "body's modulus scaled with the relaxed RVEs' (linear estimate)"}
        x = pred[model]["x"][ok]
        if ok.sum() >= 2 and np.any(x > 0):
            k, se, rmse_fit, loo = loo_fitted_kappa(p[ok], y[ok], x)
            out["fitted"] = {"kappa_extra": k, "kappa_extra_se": se,
                             "meaning": "FITTED: an extra axial stress -kappa_extra mu0 <M>^2 "
                                        "added in small strain (strain += kappa_extra mu0 "
                                        "<M>^2 / E)",
                             "rmse": rmse_fit, "heldout_rmse": loo}
            if final_cv_pred is not None:
                f = np.asarray(final_cv_pred, float)[ok]
                ref = float(np.sqrt(np.mean((f - y[ok]) ** 2)))
                out["diagnosis_final_heldout_rmse_same_rows"] = ref
                out["heldout_gain_nothing_fitted"] = (ref / out["rmse_nothing_fitted"]
                                                      if out["rmse_nothing_fitted"] > 0
                                                      else math.inf)
                out["heldout_gain_with_fitted_kappa"] = ref / loo if loo > 0 else math.inf
        models_out[model] = out
    return {"available": True,
            "measured_quantity": "change of length between the end faces over the initial "
                                 "length (area mean of the end faces; the axis value next to "
                                 "it)",
            "nothing_fitted": "matrix modulus from the TOML, filler stiffening and M(H_in) "
                              "from the project's RVEs, kappa from the dipole virial and the "
                              "relax table",
            "groups": groups_out, "models": models_out,
            "model_error": ["specimen mesh " + mesh + f" {MESHES[mesh]}",
                            f"rim rounded with {EDGE_FRACTION:g} R",
                            "monodisperse particles at the TOML's mean radius",
                            "modulus interval applied by linear scaling",
                            "relaxed: the restructuring's change of M and of the modulus not "
                            "included (the relaxed RVEs' E along the field grows with the field: "
                            "groups[].relax_table.stiffening); it overestimates the elongation"]}
