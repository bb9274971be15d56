"""Statistics: interval coverage on outputs of known distribution, two-sample tests against
independent computations, the Kanit power law, and table interpolation with propagated CIs."""
import math

import numpy as np
import pytest
from scipy import stats

from homogenize.tables._evaluate import SyntheticEvaluator, synthetic_truth
from homogenize.tables._stats import (fit_power_law, realizations_needed, summarize,
                               welch_permutation)
from homogenize.tables._study import parse_study
from homogenize.tables.batch import Table, body_force_from_table, interpolate
from micro.common.validate import InputError

STUDY = """
[study]
seed = {seed}
realizations = {n}
n_particles = 100
evaluator = "synthetic"
[grid]
phi = [{phis}]
B_T = [0.05, 0.2]
gradB_T_per_m = 1.78
"""


def _binomial_band(p, trials, z=3.5):
    # 3.5 sigma of the binomial count: a correct interval fails this with probability ~5e-4
    half = z * math.sqrt(p * (1 - p) / trials)
    return p - half, p + half


def test_student_t_interval_covers_true_mean_at_stated_rate():
    """Synthetic evaluator outputs are normal with a known mean: the 95 % (and 80 %)
    intervals of n = 4 realizations must contain it in 95 % (80 %) of the grid points."""
    phis = ", ".join(f"{0.01 + 0.0001 * k:.4f}" for k in range(200))
    study = parse_study(STUDY.format(seed=5, n=4, phis=phis))
    ev = SyntheticEvaluator()
    tasks = study.tasks()
    R = study.realizations
    for level in (0.95, 0.80):
        hits = total = 0
        for g, point in enumerate(study.points()):
            vals = np.array([ev(t)["f_eff_N_m3"] for t in tasks[g * R:(g + 1) * R]])
            s = summarize(vals, level)
            mu = synthetic_truth(point, study.settings())["f_eff_N_m3"][0]
            inside = (s["ci_low"] <= mu) & (mu <= s["ci_high"])
            hits += int(inside.sum())
            total += inside.size
        lo, hi = _binomial_band(level, total)
        assert lo <= hits / total <= hi, (level, hits / total)


def test_summarize_against_scipy():
    x = np.random.default_rng(1).normal(3.0, 2.0, size=(7, 2))
    s = summarize(x, 0.9)
    lo, hi = stats.t.interval(0.9, 6, loc=x.mean(0), scale=stats.sem(x, axis=0))
    assert np.allclose(s["ci_low"], lo) and np.allclose(s["ci_high"], hi)
    assert s["n"] == 7 and np.allclose(s["sd"], x.std(0, ddof=1))
    with pytest.raises(InputError, match="at least 2"):
        summarize(x[:1])


def test_welch_matches_scipy_and_permutation_is_exact_for_small_samples():
    rng = np.random.default_rng(3)
    a = rng.normal(0.0, 1.0, 6)
    b = rng.normal(1.5, 2.0, 5)
    r = welch_permutation(a, b, n_resamples=9999)
    ref = stats.ttest_ind(b, a, equal_var=False)
    assert math.isclose(r.t, ref.statistic, rel_tol=1e-12)
    assert math.isclose(r.p_welch, ref.pvalue, rel_tol=1e-10)
    assert math.isclose(r.dof, ref.df, rel_tol=1e-12)
    # exact permutation p-value by brute force over all C(11, 5) = 462 splits; two-sided as
    # twice the smaller tail (the null distribution is not symmetric for unequal sizes)
    from itertools import combinations
    pooled = np.concatenate([a, b])
    obs = b.mean() - a.mean()
    null = []
    for idx in combinations(range(11), 5):
        mask = np.zeros(11, bool)
        mask[list(idx)] = True
        null.append(pooled[mask].mean() - pooled[~mask].mean())
    null = np.array(null)
    eps = 1e-12 * abs(obs)        # ties of the observed split itself, up to rounding
    p_exact = min(1.0, 2 * min(np.mean(null >= obs - eps), np.mean(null <= obs + eps)))
    assert math.isclose(r.p_permutation, p_exact, rel_tol=1e-9)
    # Hedges' g from its definition
    sp = math.sqrt((5 * a.var(ddof=1) + 4 * b.var(ddof=1)) / 9)
    assert math.isclose(r.hedges_g, (b.mean() - a.mean()) / sp * (1 - 3 / (4 * 11 - 9)))
    assert r.ci_low < r.difference < r.ci_high


def test_tests_detect_a_real_difference_and_not_a_null_one():
    """Dispersed vs clustered points of the synthetic model differ by 10 % in f_eff."""
    study = parse_study(STUDY.format(seed=2, n=12, phis="0.035").replace(
        "gradB_T_per_m = 1.78", 'gradB_T_per_m = 1.78\narrangement = ["dispersed", "clusters"]'))
    ev = SyntheticEvaluator()
    tasks = study.tasks()
    by_point = {}
    for t in tasks:
        by_point.setdefault(t.grid_index, []).append(ev(t)["f_eff_N_m3"][2])
    pts = study.points()
    i_d = next(i for i, p in enumerate(pts) if p["arrangement"] == "dispersed" and p["B_T"] == 0.2)
    i_c = next(i for i, p in enumerate(pts) if p["arrangement"] == "clusters" and p["B_T"] == 0.2)
    r = welch_permutation(by_point[i_d], by_point[i_c], n_resamples=1999)
    assert r.p_welch < 1e-3 and r.p_permutation < 1e-2 and r.hedges_g > 1
    # two independent samples of the same distribution: no significant difference (this seed)
    a = np.random.default_rng(8).normal(size=12)
    b = np.random.default_rng(9).normal(size=12)
    r0 = welch_permutation(a, b, n_resamples=1999)
    assert r0.p_welch > 0.05 and r0.p_permutation > 0.05


def test_power_law_fit_recovers_exponent():
    V = np.geomspace(1e-21, 1e-19, 5)
    var = 3.0 * (1e-20 / V) ** 0.8
    fit = fit_power_law(V, var)
    assert math.isclose(fit.alpha, 0.8, rel_tol=1e-10)
    assert np.allclose(fit.variance(V), var, rtol=1e-10)
    assert fit.alpha_se < 1e-8
    with pytest.raises(InputError, match="positive"):
        fit_power_law(V, np.zeros(5))


def test_power_law_on_synthetic_realizations():
    """Synthetic f_eff has variance ~ 1/n_particles ~ 1/V: the fitted alpha is 1 within its
    sampling error (sd of log s^2 with 40 realizations ~ sqrt(2/39) = 0.23 per size)."""
    sizes = (25, 50, 100, 200, 400)
    ev = SyntheticEvaluator()
    V, var = [], []
    for n in sizes:
        s = parse_study(STUDY.format(seed=4, n=40, phis="0.035").replace(
            "n_particles = 100", f"n_particles = {n}").replace("B_T = [0.05, 0.2]", "B_T = 0.2"))
        out = [ev(t) for t in s.tasks()]
        V.append(np.mean([o["volume_m3"] for o in out]))
        var.append(np.var([o["f_eff_N_m3"][2] for o in out], ddof=1))
    fit = fit_power_law(V, var)
    # slope over a factor 16 in V (ln 16 = 2.8): se ~ 0.23 / 2.8 * sqrt(...) ~ 0.1; 4 se
    assert abs(fit.alpha - 1.0) < 0.4, fit


def test_realizations_needed():
    # sd/mean = 0.1, 2 % precision: normal approximation (1.96 * 5)^2 = 96; t adds a little
    n = realizations_needed(0.1, 1.0, 0.02)
    assert stats.t.ppf(0.975, n - 1) * 0.1 / math.sqrt(n) <= 0.02
    assert stats.t.ppf(0.975, n - 2) * 0.1 / math.sqrt(n - 1) > 0.02
    assert 96 <= n <= 100
    assert realizations_needed(0.0, 1.0, 0.01) == 2
    assert realizations_needed(0.01, 1.0, 0.5) == 2
    with pytest.raises(InputError, match="zero mean"):
        realizations_needed(1.0, 0.0, 0.1)


def _synthetic_table(seed, n, phis=(0.02, 0.04), B=(0.05, 0.2)):
    study = parse_study(STUDY.format(seed=seed, n=n, phis=", ".join(map(str, phis))).replace(
        "B_T = [0.05, 0.2]", f"B_T = [{', '.join(map(str, B))}]"))
    ev = SyntheticEvaluator()
    R = study.realizations
    vals = np.array([ev(t)["f_eff_N_m3"] for t in study.tasks()]).reshape(study.n_points, R, 3)
    return study, Table(path="mem", axes=dict(study.axes), points=tuple(study.points()),
                        confidence=0.95, n=np.full(study.n_points, R),
                        values={"f_eff_N_m3": vals}, units={"f_eff_N_m3": "N/m^3"}, attrs={})


def test_interpolation_at_grid_point_and_gradient_scaling():
    study, table = _synthetic_table(1, 5)
    x = table.values["f_eff_N_m3"][3, :, 2]
    e = interpolate(table, "f_eff", phi=0.04, B_T=0.2, gradB_T_per_m=1.78)
    s = summarize(x)
    assert table.points[3] == {"phi": 0.04, "B_T": 0.2, "gradB_T_per_m": 1.78}
    assert math.isclose(e.mean, s["mean"]) and math.isclose(e.ci_low, s["ci_low"])
    assert math.isclose(e.dof, 4)
    # one gradient in the table: the force scales linearly with the asked gradient
    e2 = body_force_from_table(table, 0.04, 0.2, 2 * 1.78)
    assert math.isclose(e2.mean, 2 * e.mean) and math.isclose(e2.ci_high, 2 * e.ci_high)
    with pytest.raises(InputError, match="outside the table's range"):
        interpolate(table, "f_eff", phi=0.05, B_T=0.2)
    with pytest.raises(InputError, match="give B_T"):
        interpolate(table, "f_eff", phi=0.03)
    with pytest.raises(InputError, match="no quantity"):
        interpolate(table, "E_eff", phi=0.03, B_T=0.1)


def test_interpolated_interval_covers_truth_at_stated_rate():
    """f_eff of the synthetic model is exactly linear in phi: halfway between the phi grid
    values the true mean is the average of the two, and the propagated Welch interval must
    cover it at 95 %."""
    trials = 300
    hits = 0
    for k in range(trials):
        study, table = _synthetic_table(1000 + k, 4, B=(0.2,))
        e = body_force_from_table(table, 0.03, 0.2, 1.78)
        mu = synthetic_truth({"phi": 0.03, "B_T": 0.2, "gradB_T_per_m": 1.78},
                             study.settings())["f_eff_N_m3"][0][2]
        hits += e.ci_low <= mu <= e.ci_high
    lo, hi = _binomial_band(0.95, trials)
    assert lo <= hits / trials <= hi, hits / trials


def test_tip_deflection_from_table_propagates_the_force_interval():
    from homogenize.macro.effective import tip_deflection_from_table
    study, table = _synthetic_table(2, 5)
    L, w, t = 0.0187, 5e-3, 1e-3
    r = tip_deflection_from_table(table, 0.02, 0.05, 1.78, L, w, t, model="eb")
    f = r.force
    # Euler-Bernoulli closed form, delta = 3 f L^4 / (2 E t^2), at the mean and at both ends
    for defl, force in ((r.deflection_m, f.mean), (r.ci_low_m, f.ci_low), (r.ci_high_m, f.ci_high)):
        assert math.isclose(defl, 1.5 * force * L ** 4 / (2e6 * t ** 2), rel_tol=1e-12)
    assert r.E_Pa == 2e6 and r.E_estimate is None and not r.large_deflection
    # large load: the elastica (dead load) bends less than linear theory, and it is flagged
    big = tip_deflection_from_table(table, 0.04, 0.2, 1.78, 0.05, w, t)
    assert big.deflection_m < big.deflection_eb_m and big.large_deflection
    assert big.ci_low_m < big.deflection_m < big.ci_high_m
    # a stiffer matrix given explicitly scales the linear deflection down exactly
    r2 = tip_deflection_from_table(table, 0.02, 0.05, 1.78, L, w, t, model="eb", E_Pa=4e6)
    assert math.isclose(r2.deflection_m, r.deflection_m / 2, rel_tol=1e-12)
