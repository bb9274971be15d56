"""``diagnose``: what the seed model gets wrong, which cause, which extension, and the gain.

Procedure (spec section 5)
--------------------------
1. **Cross-validation.** Rows are split into folds by specimen when there are at least three
   specimens (leave-one-specimen-out, or specimens dealt round-robin into at most
   ``max_folds`` folds); otherwise into 5 seeded random folds of rows. Every model is fitted
   (non-linear least squares, ``scipy.optimize.least_squares``) on the training folds and
   predicts the held-out fold; ``cv_rmse`` is the RMS of all held-out errors, in the unit of
   the measured column.
2. **Seed model** (baseline): one fitted scale (``scale``; tensile: ``E_Pa``).
3. **Forward selection.** Every applicable cause not yet accepted is added to the current model
   (causes with several physical forms -- magnetization law, hyperelastic law -- try each form
   and keep the one with the lowest ``cv_rmse``). A candidate passes if

   * its ``cv_rmse`` is at least ``min_gain`` (10 %) below the current one, AND
   * a one-sided Wilcoxon signed-rank test on the paired held-out squared errors (current minus
     candidate, one pair per row) gives ``p < alpha`` (0.01);

   the passing candidate with the lowest ``cv_rmse`` is accepted and the search repeats on top
   of it. If none passes, pairs of the three best candidates are tried together (two causes
   can be needed at once: self-weight makes a linear beam worse until the large-deflection
   solution is there too); a pair passing the same criterion is accepted, both causes named.
   The search stops when nothing passes.
4. **Parameters** of the accepted model are fitted on all rows; their standard errors come from
   the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1`` with ``s^2`` the residual variance.

With fewer than 3 rows nothing can be held out: the "held-out" prediction is then the a priori
model (scale 1, the TOML's E, no fitted parameter), only parameter-free extensions are tried,
and none is accepted (a significance test needs data).
"""
from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from homogenize.experiments.causes import (CAUSES, REQUIRES, VARIANTS, ModelSpec, Param, applicable,
                     coupled_rve_available, forms, parameters, predict)
from homogenize.experiments.io import Experiment
from homogenize.experiments.causes import composite_magnetization_A_per_m, predicted_stress_coefficients
from dataclasses import replace as _replace
from dataclasses import replace
from homogenize.experiments.causes import default_params
from micro.common.progress import progress_bar

__all__ = ["Diagnosis", "FitResult", "diagnose", "make_folds", "fit", "cross_validate",
           "covariates", "MIN_GAIN", "ALPHA"]

MIN_GAIN = 0.10
ALPHA = 0.01


@dataclass
class FitResult:
    spec: ModelSpec
    params: dict
    sd: dict
    x: np.ndarray
    prediction: np.ndarray


@dataclass
class Candidate:
    spec: ModelSpec
    cause: str
    cv_rmse: float
    cv_pred: np.ndarray
    fit: FitResult
    variants: dict = field(default_factory=dict)   # variant -> cv_rmse


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`as_dict` is the spec's JSON."""
    exp: Experiment
    baseline: Candidate
    final: Candidate
    steps: list
    rounds: list                       # per round: list of Candidate tried
    skipped: dict                      # cause -> why it was not tried
    folds: list | None
    round_bases: list = field(default_factory=list)   # model each round started from
    microstructure: dict | None = None    # magnetostriction: the coupled RVE's account
    specimen: dict | None = None          # magnetostriction: the specimen solver's account

    @property
    def gain(self) -> float:
        if self.final.cv_rmse == 0.0:
            return 1.0 if self.baseline.cv_rmse == 0.0 else math.inf
        return self.baseline.cv_rmse / self.final.cv_rmse

    def as_dict(self) -> dict:
        first = self.rounds[0] if self.rounds else []
        return {
            "kind": self.exp.kind,
            "n_rows": self.exp.n_rows,
            "baseline": {"cv_rmse": self.baseline.cv_rmse, "params": _params_out(self.baseline)},
            "causes": [s["cause"] for s in self.steps],
            "steps": [{"cause": s["cause"], "cv_rmse": s["cv_rmse"], "params": s["params"],
                       "evidence": s["evidence"]} for s in self.steps],
            "candidates": [{"cause": c.cause, "cv_rmse": c.cv_rmse}
                           for c in sorted(first, key=lambda c: c.cv_rmse)],
            "final": {"cv_rmse": self.final.cv_rmse,
                      "params": {**_params_out(self.final), **_predicted_out(self.exp, self.final)}},
            "gain": self.gain if self.steps else 1.0,
            **({"microstructure_evolution": self.microstructure}
               if self.microstructure is not None else {}),
            **({"specimen": self.specimen} if self.specimen is not None else {}),
        }


def _params_out(c: Candidate) -> dict:
    out = {}
    for k, v in c.fit.params.items():
        out[k] = float(v)
        if k in c.fit.sd and np.isfinite(c.fit.sd[k]):
            out[k + "_sd"] = float(c.fit.sd[k])
    if c.spec.law:
        out["law"] = c.spec.law
    if c.spec.hyper:
        out["hyperelastic_law"] = c.spec.hyper
    if c.spec.restructure:
        out["restructure_form"] = c.spec.restructure
    if c.spec.kind == "magnetostriction" and "scale" not in out:
        out["scale"] = 1.0            # not identifiable in magnetostriction (absorbed in E)
    return out


def _predicted_out(exp: Experiment, c: Candidate) -> dict:
    """Predicted (not fitted) physics of the final model worth reporting next to the fitted
    parameters: for magnetostriction, the row-mean shape and RVE stress coefficients."""
    if c.spec.kind != "magnetostriction" or not c.spec.has("dipolar_interaction"):
        return {}
    M = composite_magnetization_A_per_m(c.spec, exp, c.fit.params)
    k_shape, k_rve = predicted_stress_coefficients(exp, M)
    return {"kappa_shape_predicted": float(np.mean(k_shape)),
            "kappa_rve_predicted": float(np.mean(k_rve)),
            "kappa_predicted": float(np.mean(k_shape - k_rve))}


# ------------------------------------------------------------------------------------------
# folds

def make_folds(exp: Experiment, max_folds: int = 8, k_rows: int = 5, seed: int = 0):
    """Held-out index sets: by specimen when there are >= 3 specimens, else K random folds.

    Returns None when there are fewer than 3 rows (nothing can be held out).
    """
    n = exp.n_rows
    if n < 3:
        return None
    g = exp.groups
    n_spec = int(g.max()) + 1
    if n_spec >= 3:
        nf = min(n_spec, max_folds)
        fold_of = np.arange(n_spec) % nf
        return [np.flatnonzero(fold_of[g] == k) for k in range(nf)]
    k = min(k_rows, n)
    perm = np.random.default_rng(seed).permutation(n)
    return [np.sort(part) for part in np.array_split(perm, k)]


# ------------------------------------------------------------------------------------------
# fitting

def _to_params(ps: list[Param], x) -> dict:
    return {q.name: (math.exp(v) if q.log else float(v)) for q, v in zip(ps, x)}


def _bounds(ps):
    lo = np.array([math.log(q.lo) if q.log else q.lo for q in ps])
    hi = np.array([math.log(q.hi) if q.log else q.hi for q in ps])
    return lo, hi


def _x_of(q: Param, v):
    return math.log(v) if q.log else float(v)


def _residual_fn(spec, exp, ps, y, w):
    def fun(x):
        pred = predict(spec, exp, _to_params(ps, x))
        r = (pred - y) / w
        return np.where(np.isfinite(r), r, 1e6)
    return fun


def _weights(exp):
    y = exp.y
    sd = exp.sd
    if sd is not None:
        return sd
    s = float(np.sqrt(np.mean(y ** 2)))
    return np.full(y.shape, s if s > 0 else 1.0)


def _amplitude_solve(spec, exp, ps, x, y, w):
    """Closed-form least-squares amplitude (prediction ~ amplitude) given the other params."""
    k = next((i for i, q in enumerate(ps) if q.amplitude), None)
    if k is None:
        return x
    x = x.copy()
    q = ps[k]
    x[k] = _x_of(q, 1.0)
    p1 = predict(spec, exp, _to_params(ps, x)) / w
    yy = y / w
    den = float(p1 @ p1)
    if not np.isfinite(den) or den <= 0:
        x[k] = _x_of(q, q.starts[0])
        return x
    a = float(p1 @ yy) / den
    if q.log:
        a = a if a > 0 else q.starts[0]
    a = min(max(a, q.lo), q.hi)
    x[k] = _x_of(q, a)
    return x


def _sse(fun, x):
    r = fun(x)
    return float(r @ r)


def fit(spec: ModelSpec, exp: Experiment, x0=None) -> FitResult:
    """Least-squares fit of ``spec`` to all rows of ``exp`` (starts: grid, or ``x0``)."""
    ps = parameters(spec, exp)
    y = exp.y
    if not ps:
        pred = predict(spec, exp, {})
        return FitResult(spec, {}, {}, np.zeros(0), pred)
    w = _weights(exp)
    fun = _residual_fn(spec, exp, ps, y, w)
    lo, hi = _bounds(ps)
    if x0 is None:
        x = np.array([_x_of(q, q.starts[0]) for q in ps])
        x = _amplitude_solve(spec, exp, ps, x, y, w)
        # coordinate-wise choice of the start of every shape parameter
        for i, q in enumerate(ps):
            if q.amplitude or len(q.starts) < 2:
                continue
            best = (math.inf, x)
            for s in q.starts:
                xt = x.copy()
                xt[i] = _x_of(q, s)
                xt = _amplitude_solve(spec, exp, ps, xt, y, w)
                e = _sse(fun, xt)
                if e < best[0]:
                    best = (e, xt)
            x = best[1]
    else:
        x = np.asarray(x0, dtype=float).copy()
    x = np.clip(x, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi))
    x = np.minimum(np.maximum(x, lo), hi)
    res = optimize.least_squares(fun, x, bounds=(lo, hi), method="trf", x_scale=1.0,
                                 max_nfev=60 * (len(ps) + 1), xtol=1e-10, ftol=1e-10)
    x = res.x
    params = _to_params(ps, x)
    sd = _uncertainty(res, ps, params, y.size)
    return FitResult(spec, params, sd, x, predict(spec, exp, params))


def _uncertainty(res, ps, params, n):
    p = len(ps)
    dof = n - p
    if dof <= 0:
        return {q.name: math.nan for q in ps}
    J = res.jac
    s2 = float(res.fun @ res.fun) / dof
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        return {q.name: math.nan for q in ps}
    out = {}
    for i, q in enumerate(ps):
        sx = math.sqrt(max(cov[i, i], 0.0))
        out[q.name] = params[q.name] * sx if q.log else sx
    return out


def cross_validate(spec: ModelSpec, exp: Experiment, folds, full: FitResult | None = None):
    """Held-out predictions of every row, and the full-data fit."""
    full = full or fit(spec, exp)
    if folds is None:
        return predict(spec, exp, default_params(spec, exp)), full
    pred = np.empty(exp.n_rows)
    all_idx = np.arange(exp.n_rows)
    for test in folds:
        train = np.setdiff1d(all_idx, test)
        if full.x.size == 0:
            pred[test] = predict(spec, exp.subset(test), {})
            continue
        ft = fit(spec, exp.subset(train), x0=full.x)
        pred[test] = predict(spec, exp.subset(test), ft.params)
    return pred, full


def _rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def _candidate(spec, cause, exp, folds):
    full = fit(spec, exp)
    cvp, full = cross_validate(spec, exp, folds, full)
    return Candidate(spec, cause, _rmse(cvp, exp.y), cvp, full)


# ------------------------------------------------------------------------------------------
# covariates of the residuals

def covariates(exp: Experiment, prediction: np.ndarray | None = None) -> dict:
    """Covariates to inspect residuals against (name -> values), per kind."""
    c = exp.columns
    out = {}
    names = {"deflection": ("B_T", "gradB_T_per_m", "phi", "length_m", "width_m",
                            "thickness_m", "radius_mean_m"),
             "magnetization": ("H_A_per_m", "phi", "radius_mean_m", "aspect_ratio"),
             "magnetostriction": ("B_T", "phi", "aspect_ratio", "radius_mean_m"),
             "tensile": ("strain", "phi")}[exp.kind]
    for n in names:
        if n in c:
            out[n] = np.asarray(c[n])
    if exp.kind == "deflection":
        out["deflection/length"] = c["deflection_m"] / c["length_m"]
        out["L^4/t^2 [m^2]"] = c["length_m"] ** 4 / c["thickness_m"] ** 2
    if exp.down.any():
        out["branch (down=1)"] = exp.down.astype(float)
    if prediction is not None:
        out["prediction"] = np.asarray(prediction)
    return out


def residual_correlations(exp, residual) -> dict:
    """Spearman rank correlation of the residual with every covariate that varies."""
    out = {}
    for name, v in covariates(exp).items():
        if np.unique(v).size < 2 or np.unique(residual).size < 2:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rho = stats.spearmanr(v, residual).statistic
        if np.isfinite(rho):
            out[name] = float(rho)
    return out


def _paired_p(e_cur, e_new):
    d = e_cur ** 2 - e_new ** 2
    if np.all(d == 0):
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return float(stats.wilcoxon(d, alternative="greater").pvalue)
        except ValueError:
            return 1.0


# ------------------------------------------------------------------------------------------
# the diagnosis

def diagnose(exp: Experiment, *, min_gain: float = MIN_GAIN, alpha: float = ALPHA,
             max_folds: int = 8, progress: bool = False,
             specimen_mesh: str | None = None) -> Diagnosis:
    """Cross-validated forward selection of causes on top of the seed model (module doc).

    specimen_mesh : for a magnetostriction experiment, also predict the measured change of
        length through the specimen solver, three models, nothing fitted
        (:func:`homogenize.experiments.specimen_account.specimen_account`, a minute or two);
        "coarse" | "normal", or None: not done
    """
    if specimen_mesh is not None:
        from homogenize.experiments.specimen_account import MESHES
        if specimen_mesh not in MESHES:
            from micro.common.validate import InputError
            raise InputError(f"specimen_mesh must be one of {sorted(MESHES)} or None, got "
                             f"{specimen_mesh!r}")
    folds = make_folds(exp, max_folds=max_folds)
    seed = ModelSpec(exp.kind)
    current = _candidate(seed, "seed", exp, folds)
    baseline = current
    skipped = {}
    for cause in CAUSES:
        ok, why = applicable(cause, exp)
        if not ok and "not a cause for kind" not in why:
            skipped[cause] = why
    steps, rounds, round_bases = [], [], []
    bar = None
    if progress:
        bar = progress_bar(desc=f"diagnose {exp.kind}", unit="model", file=sys.stderr, leave=False)
    remaining = [c for c in CAUSES if applicable(c, exp)[0]]
    if folds is None:
        n_seed = len(parameters(seed, exp))
        remaining = [c for c in remaining
                     if len(parameters(seed.plus(c, (VARIANTS.get(c) or (None,))[0]), exp)) == n_seed]
    while remaining:
        tried = []
        # a cause that extends another (REQUIRES) waits until that one is accepted
        eligible = [c for c in remaining if c not in REQUIRES or current.spec.has(REQUIRES[c])]
        if not eligible:
            break
        for cause in eligible:
            best = None
            variants = {}
            for spec, v in _specs_with(current.spec, cause, exp):
                cand = _candidate(spec, cause, exp, folds)
                if bar is not None:
                    bar.update(1)
                if v is not None:
                    variants[v] = cand.cv_rmse
                if best is None or cand.cv_rmse < best.cv_rmse:
                    best = cand
            if best is None:               # no form of this cause can run on this model
                continue
            best.variants = variants
            tried.append(best)
        rounds.append(tried)
        round_bases.append(current.spec.label())
        e_cur = current.cv_pred - exp.y
        # the candidate with the lowest cv_rmse among those that pass the criterion
        passing = []
        if folds is not None:
            for c in tried:
                pc = _paired_p(e_cur, c.cv_pred - exp.y)
                if _passes(current, c, pc, min_gain, alpha):
                    passing.append((c.cv_rmse, pc, c))
        if passing:
            _, p, top = min(passing, key=lambda t: t[0])
            corr = residual_correlations(exp, e_cur)
            steps.append({"cause": top.cause, "cv_rmse": top.cv_rmse,
                          "params": _step_params(current, top),
                          "evidence": _evidence(exp, current, top, p, corr),
                          "p_value": p, "correlations": corr})
            current = top
            remaining = [c for c in remaining if c != top.cause]
            continue
        if folds is None:
            break
        # look-ahead: two causes that only help together (e.g. large deflection AND
        # self-weight, where self-weight alone makes a linear beam worse). Pairs of the three
        # best candidates that changed the prediction at all.
        helping = sorted((c for c in tried if not np.array_equal(c.cv_pred, current.cv_pred)),
                         key=lambda c: c.cv_rmse)[:3]
        pairs = [(helping[i], helping[j]) for i in range(len(helping))
                 for j in range(i + 1, len(helping))]
        if exp.kind == "magnetostriction" and not current.spec.has("dipolar_interaction"):
            # causes acting through M (its law, shell, demagnetization, hysteresis) show in a
            # strain only together with the stress that makes it: pair them with that one
            dip = [c for c in helping if c.cause == "dipolar_interaction"]
            silent = [c for c in tried if np.array_equal(c.cv_pred, current.cv_pred)]
            pairs += [(d, c) for d in dip for c in silent]
        best_pair = None
        for a, b in pairs:
            spec_b = b.spec
            var_b = None
            if b.cause in VARIANTS:
                var_b = {"field_dependent_magnetization": spec_b.law,
                         "microstructure_evolution": spec_b.restructure}.get(b.cause,
                                                                             spec_b.hyper)
            spec = a.spec.plus(b.cause, var_b)
            if b.spec.law and not a.spec.law:
                spec = _replace(spec, law=b.spec.law)
            if b.spec.hyper and not a.spec.hyper:
                spec = _replace(spec, hyper=b.spec.hyper)
            pair = _candidate(spec, b.cause, exp, folds)
            if bar is not None:
                bar.update(1)
            if best_pair is None or pair.cv_rmse < best_pair[2].cv_rmse:
                best_pair = (a, b, pair)
        if best_pair is None:
            break
        a, b, pair = best_pair
        p = _paired_p(e_cur, pair.cv_pred - exp.y)
        if not _passes(current, pair, p, min_gain, alpha):
            break
        corr = residual_correlations(exp, e_cur)
        p_a = _paired_p(e_cur, a.cv_pred - exp.y)
        steps.append({"cause": a.cause, "cv_rmse": a.cv_rmse, "params": _step_params(current, a),
                      "evidence": _evidence(exp, current, a, p_a, corr)
                      + f"; not significant alone, accepted jointly with {b.cause}",
                      "p_value": p_a, "correlations": corr})
        corr2 = residual_correlations(exp, a.cv_pred - exp.y)
        p_b = _paired_p(a.cv_pred - exp.y, pair.cv_pred - exp.y)
        steps.append({"cause": b.cause, "cv_rmse": pair.cv_rmse, "params": _step_params(a, pair),
                      "evidence": _evidence(exp, a, pair, p_b, corr2)
                      + f"; accepted jointly with {a.cause}: together {current.cv_rmse:.3g} -> "
                        f"{pair.cv_rmse:.3g}, paired test p = {p:.2g}",
                      "p_value": p, "correlations": corr2})
        current = pair
        remaining = [c for c in remaining if c not in (a.cause, b.cause)]
    if bar is not None:
        bar.close()
    ms = microstructure_account(exp, folds, baseline, current) \
        if exp.kind == "magnetostriction" else None
    sp = None
    if exp.kind == "magnetostriction" and specimen_mesh is not None:
        from homogenize.experiments.specimen_account import specimen_account
        say = (lambda text: print(text, file=sys.stderr)) if progress else None
        sp = specimen_account(exp, final_cv_pred=current.cv_pred, mesh=specimen_mesh,
                              progress=say)
    return Diagnosis(exp, baseline, current, steps, rounds, skipped, folds, round_bases, ms, sp)


def microstructure_account(exp: Experiment, folds, baseline: Candidate,
                           final: Candidate) -> dict:
    """What the coupled RVE (particles that move) predicts for a magnetostriction experiment,
    WITHOUT any fitted stress, next to the measurement; the held-out gain of its extension;
    what remains unexplained (the fitted ``kappa_extra`` still needed, named as fitted).

    All models share the final model's magnetization (its law and parameters when it has
    ``field_dependent_magnetization`` etc.: M is not what is in question); none of the
    "predicted" numbers has a fitted stress. Numbers at the row of the largest |B| (the rising
    branch when there is one): ``measured``, ``predicted_affine`` (particles fixed: shape
    stress minus the RVE's virial stress), ``predicted_coupled_rve`` (plus the relax table's
    restructuring strain, with the Student-t interval over its realizations),
    ``fraction_explained``, ``unexplained``.
    """
    ok, why = coupled_rve_available(exp)
    if not ok:
        return {"available": False, "why": why}
    from homogenize.tables._stats import t_half_width
    from homogenize.experiments.causes import predicted_stress_coefficients, composite_magnetization_A_per_m
    from homogenize.experiments.rve_tables import restructuring_table
    from homogenize.experiments import _physics as P
    # the final model's magnetization (law, shell, demagnetization, hysteresis), no stress
    mag = ModelSpec(exp.kind, tuple(c for c in final.spec.causes
                                    if c not in ("dipolar_interaction", "microstructure_evolution")),
                    final.spec.law, final.spec.hyper)
    p_mag = {k: v for k, v in final.fit.params.items() if k not in ("kappa_extra", "c_restructure")}
    dip = mag.plus("dipolar_interaction")
    coupled = mag.plus("microstructure_evolution", "coupled_rve")    # no fitted stress
    c_coupled = _candidate(coupled, "microstructure_evolution", exp, folds)
    c_dip = _candidate(dip, "dipolar_interaction", exp, folds)
    c_dip_coupled = _candidate(dip.plus("microstructure_evolution", "coupled_rve"),
                               "microstructure_evolution", exp, folds)
    c_dip_fitted = _candidate(dip.plus("microstructure_evolution", "fitted"),
                              "microstructure_evolution", exp, folds)
    y = exp.y
    B = np.abs(exp.columns["B_T"])
    up = ~exp.down
    pool = np.flatnonzero(up) if up.any() else np.arange(exp.n_rows)
    i = int(pool[np.argmax(B[pool])])
    affine = predict(dip, exp, {**p_mag, "kappa_extra": 0.0})
    pred = predict(coupled, exp, p_mag)
    phi = float(exp.columns["phi"][i])
    tab = restructuring_table(phi, float(exp.matrix.E_Pa))
    k_shape = float(np.asarray(P.shape_stress_coefficient(exp.columns["aspect_ratio"][i])))
    d_r = tab.delta_strain_realizations(B[i], k_shape)
    R = d_r.size
    half = t_half_width(float(np.std(d_r, ddof=1)) / math.sqrt(R), R - 1, 0.95) if R > 1 \
        else math.nan
    M = composite_magnetization_A_per_m(dip, exp, p_mag)
    x = P.mu_0 * M[i] ** 2 / exp.matrix.E_Pa
    k_sh, k_rve = predicted_stress_coefficients(exp, M)

    def cv(c):
        return float(c.cv_rmse)

    def gain(a, b):
        return float(a / b) if b > 0 else math.inf

    kx = c_dip_coupled.fit.params.get("kappa_extra")
    cr = c_dip_fitted.fit.params.get("c_restructure")
    return {
        "available": True,
        "relax_table": tab.provenance,
        "at": {"B_T": float(exp.columns["B_T"][i]), "phi": phi,
               "branch": "down" if exp.down[i] else "up"},
        "measured": float(y[i]),
        "predicted_affine": float(affine[i]),
        "predicted_coupled_rve": float(pred[i]),
        "predicted_coupled_rve_ci95": [float(pred[i] - half), float(pred[i] + half)],
        "restructuring_strain": float(pred[i] - affine[i]),
        "fraction_explained": float(pred[i] / y[i]) if y[i] != 0 else math.nan,
        "unexplained": float(y[i] - pred[i]),
        "kappa_affine": float(k_sh[i] - k_rve[i]),
        "kappa_coupled_rve": float(pred[i] / x) if x > 0 else math.nan,
        "kappa_measured": float(y[i] / x) if x > 0 else math.nan,
        "cv_rmse": {"seed": cv(baseline), "coupled_rve_no_fitted_stress": cv(c_coupled),
                    "dipolar_interaction_kappa_extra_fitted": cv(c_dip),
                    "dipolar_plus_coupled_rve_kappa_extra_fitted": cv(c_dip_coupled),
                    "dipolar_plus_fitted_restructuring": cv(c_dip_fitted)},
        "gain_coupled_rve_over_seed": gain(cv(baseline), cv(c_coupled)),
        "gain_fitted_kappa_extra_over_seed": gain(cv(baseline), cv(c_dip)),
        "gain_coupled_rve_on_top_of_dipolar": gain(cv(c_dip), cv(c_dip_coupled)),
        "gain_fitted_restructuring_on_top_of_dipolar": gain(cv(c_dip), cv(c_dip_fitted)),
        "kappa_extra_fitted_with_coupled_rve": None if kx is None else float(kx),
        "kappa_extra_fitted_with_coupled_rve_sd": float(c_dip_coupled.fit.sd.get("kappa_extra",
                                                                               math.nan)),
        "c_restructure_fitted": None if cr is None else float(cr),
        "c_restructure_fitted_sd": float(c_dip_fitted.fit.sd.get("c_restructure", math.nan)),
        "rows": {"B_T": [float(b) for b in exp.columns["B_T"]],
                 "predicted_affine": [float(v) for v in affine],
                 "predicted_coupled_rve": [float(v) for v in pred]},
        "magnetization_model": mag.label(),
        "magnetization_params": {k: float(v) for k, v in p_mag.items()},
        "accepted": final.spec.has("microstructure_evolution"),
        "accepted_form": final.spec.restructure,
    }


def _passes(current: Candidate, cand: Candidate, p: float, min_gain: float, alpha: float) -> bool:
    """The acceptance criterion: >= min_gain lower cv_rmse AND paired test p < alpha."""
    return cand.cv_rmse <= (1.0 - min_gain) * current.cv_rmse and p < alpha


def _specs_with(spec: ModelSpec, cause: str, exp: Experiment | None = None):
    """``spec`` plus ``cause``, in every physical form: the new cause's own forms (those that
    can run on ``exp``), and -- since an added cause changes which law fits best -- every form
    of a law already in the model. Yields (spec, label of the form or None)."""
    fs = forms(cause, exp, spec) if exp is not None else VARIANTS.get(cause)
    if cause in VARIANTS and not fs:
        return                        # no form of it can run here (table missing, ...)
    if fs:
        for v in fs:
            yield spec.plus(cause, v), v
        return
    if spec.law is not None:
        for law in VARIANTS["field_dependent_magnetization"]:
            yield replace(spec, law=law).plus(cause), f"law {law}"
        return
    if spec.hyper is not None:
        for h in VARIANTS["hyperelasticity"]:
            yield replace(spec, hyper=h).plus(cause), f"hyperelastic law {h}"
        return
    yield spec.plus(cause), None


def _step_params(before: Candidate, after: Candidate) -> dict:
    """Parameters the accepted extension added, with their standard errors (``_sd``), and the
    physical form chosen (``law`` / ``hyperelastic_law``) when the step chose or changed it."""
    new = _params_out(after)
    old = _params_out(before)
    out = {k: v for k, v in new.items()
           if k not in old and k not in ("law", "hyperelastic_law") and not k.endswith("_sd")}
    for k in list(out):
        if k + "_sd" in new:
            out[k + "_sd"] = new[k + "_sd"]
    for k in ("law", "hyperelastic_law"):
        if k in new and new.get(k) != old.get(k):
            out[k] = new[k]
    return out


def _evidence(exp, cur: Candidate, new: Candidate, p, corr) -> str:
    unit = {"deflection": "m", "magnetization": "A/m", "magnetostriction": "",
            "tensile": "Pa"}[exp.kind]
    u = f" {unit}" if unit else ""
    pct = 100.0 * (1.0 - new.cv_rmse / cur.cv_rmse) if cur.cv_rmse > 0 else 0.0
    text = (f"held-out RMSE {cur.cv_rmse:.3g}{u} -> {new.cv_rmse:.3g}{u} ({pct:.0f} % lower); "
            f"one-sided Wilcoxon signed-rank test on {exp.n_rows} paired held-out squared "
            f"errors p = {p:.2g}")
    if corr:
        name, rho = max(corr.items(), key=lambda kv: abs(kv[1]))
        text += f"; before it the residuals followed {name} (Spearman rho = {rho:+.2f})"
    if new.variants:
        alts = ", ".join(f"{k} {v:.3g}" for k, v in sorted(new.variants.items(), key=lambda kv: kv[1]))
        text += f"; form chosen by cross-validation among: {alts}"
    return text
