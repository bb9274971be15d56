"""Statistics of random-RVE studies: summaries with Student-t intervals, two-sample tests,
and the representative-volume power law of Kanit et al. (2003).

References
----------
T. Kanit, S. Forest, I. Galliet, V. Mounoury, D. Jeulin, "Determination of the size of the
representative volume element for random composites: statistical and numerical approach",
Int. J. Solids Struct. 40 (2003) 3647-3679: the variance of an apparent property over
realizations of volume V follows ``D^2(V) = D^2_ref (V_ref / V)^alpha`` (alpha = 1 for a
property that averages like independent sub-volumes); the absolute error of the mean of n
realizations at ~95 % is ``2 D(V) / sqrt(n)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from micro.common.validate import InputError
import dataclasses

__all__ = ["summarize", "welch_permutation", "fit_power_law", "realizations_needed",
           "TwoSampleResult", "PowerLaw"]


def t_half_width(se, dof, confidence: float):
    """Half-width of the two-sided Student-t interval: ``t_{(1+c)/2}(dof) * se`` (arrays
    broadcast; a float for scalar input)."""
    h = stats.t.ppf(0.5 + confidence / 2.0, dof) * np.asarray(se, dtype=float)
    return float(h) if np.ndim(h) == 0 else h


def widen_in_quadrature(mid, lo, hi, rel):
    """Widen the interval ``[lo, hi]`` around ``mid`` by an independent relative error ``rel``.

    The relative half-widths add in quadrature (first-order propagation of independent errors,
    an approximation good while both are small): ``mid (1 -+ hypot(rel_side, rel))``. Arrays
    broadcast; where ``mid`` is 0 the interval is returned unchanged.
    """
    mid, lo, hi = (np.asarray(x, dtype=float) for x in (mid, lo, hi))
    safe = np.where(mid != 0, mid, 1.0)
    new_lo = np.where(mid != 0, mid * (1 - np.hypot(1 - lo / safe, rel)), lo)
    new_hi = np.where(mid != 0, mid * (1 + np.hypot(hi / safe - 1, rel)), hi)
    if new_lo.ndim == 0:
        return float(new_lo), float(new_hi)
    return new_lo, new_hi


def summarize(values, confidence: float = 0.95) -> dict:
    """Mean, sample standard deviation, n and the Student-t confidence interval of the mean.

    Parameters
    ----------
    values : array_like, shape (n, ...)
        Realizations along axis 0 (n >= 2).
    confidence : float
        Two-sided level of the interval.

    Returns
    -------
    dict with ``mean``, ``sd`` (ddof = 1), ``n``, ``ci_low``, ``ci_high`` (arrays of shape ...).
    """
    x = np.asarray(values, dtype=np.float64)
    n = x.shape[0]
    if n < 2:
        raise InputError(f"a confidence interval needs at least 2 realizations, got {n}")
    mean = x.mean(axis=0)
    sd = x.std(axis=0, ddof=1)
    half = t_half_width(sd / math.sqrt(n), n - 1, confidence)
    return {"mean": mean, "sd": sd, "n": n, "ci_low": mean - half, "ci_high": mean + half}


@dataclass(frozen=True)
class TwoSampleResult:
    """Welch t-test and permutation test of the difference of two means (b - a)."""

    n_a: int
    n_b: int
    mean_a: float
    mean_b: float
    difference: float
    ci_low: float          # Welch interval of the difference at ``confidence``
    ci_high: float
    t: float
    dof: float
    p_welch: float
    p_permutation: float
    n_resamples: int
    hedges_g: float        # standardized effect size (pooled sd, small-sample corrected)
    confidence: float

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def welch_permutation(a, b, *, confidence: float = 0.95, n_resamples: int = 9999,
                      seed: int = 0) -> TwoSampleResult:
    """Compare two samples of realizations: Welch's t-test, a permutation test on the
    difference of means (exact when all splits fit in ``n_resamples``), Hedges' g.
    """
    a = np.asarray(a, dtype=np.float64).ravel()
    b = np.asarray(b, dtype=np.float64).ravel()
    if a.size < 2 or b.size < 2:
        raise InputError(f"each sample needs at least 2 realizations, got {a.size} and {b.size}")
    na, nb = a.size, b.size
    va, vb = a.var(ddof=1), b.var(ddof=1)
    diff = b.mean() - a.mean()
    se2 = va / na + vb / nb
    if se2 == 0:
        # Identical constant samples carry no evidence either way; a difference between two
        # constants is certain. Report it without dividing by zero.
        t = 0.0 if diff == 0 else math.copysign(math.inf, diff)
        dof = float(na + nb - 2)
        p_w = 1.0 if diff == 0 else 0.0
        half = 0.0
    else:
        t = diff / math.sqrt(se2)
        dof = se2 ** 2 / ((va / na) ** 2 / (na - 1) + (vb / nb) ** 2 / (nb - 1))
        p_w = float(2 * stats.t.sf(abs(t), dof))
        half = t_half_width(math.sqrt(se2), dof, confidence)

    def stat(x, y, axis=-1):
        return np.mean(y, axis=axis) - np.mean(x, axis=axis)

    perm = stats.permutation_test((a, b), stat, permutation_type="independent",
                                  vectorized=True, n_resamples=n_resamples,
                                  alternative="two-sided", rng=np.random.default_rng(seed))
    sp2 = ((na - 1) * va + (nb - 1) * vb) / (na + nb - 2)
    if sp2 > 0:
        g = diff / math.sqrt(sp2) * (1 - 3 / (4 * (na + nb) - 9))
    else:
        g = 0.0 if diff == 0 else math.copysign(math.inf, diff)
    return TwoSampleResult(n_a=na, n_b=nb, mean_a=float(a.mean()), mean_b=float(b.mean()),
                           difference=float(diff), ci_low=float(diff - half),
                           ci_high=float(diff + half), t=float(t), dof=float(dof),
                           p_welch=p_w, p_permutation=float(perm.pvalue),
                           n_resamples=int(n_resamples), hedges_g=float(g),
                           confidence=confidence)


@dataclass(frozen=True)
class PowerLaw:
    """``variance(V) = variance_ref * (V_ref / V)^alpha`` fitted in log-log space."""

    alpha: float
    alpha_se: float
    V_ref_m3: float
    variance_ref: float

    def variance(self, V_m3):
        return self.variance_ref * (self.V_ref_m3 / np.asarray(V_m3, dtype=float)) ** self.alpha


def fit_power_law(volumes_m3, variances) -> PowerLaw:
    """Least-squares fit of ``log var = log var_ref - alpha log(V / V_ref)``.

    ``V_ref`` is the geometric mean of the volumes (decorrelates the two fitted parameters).
    """
    V = np.asarray(volumes_m3, dtype=float)
    var = np.asarray(variances, dtype=float)
    if V.size < 2:
        raise InputError("a power-law fit needs at least two RVE sizes")
    if np.any(V <= 0) or np.any(var <= 0):
        raise InputError("a power-law fit needs positive volumes and variances (a quantity "
                         "with zero variance across realizations has no RVE-size effect)")
    x = np.log(V)
    V_ref = float(np.exp(x.mean()))
    xc = x - x.mean()
    y = np.log(var)
    slope, intercept = np.polyfit(xc, y, 1)
    if V.size > 2:
        resid = y - (slope * xc + intercept)
        se = math.sqrt(resid @ resid / (V.size - 2) / (xc @ xc))
    else:
        se = math.nan
    return PowerLaw(alpha=float(-slope), alpha_se=se, V_ref_m3=V_ref,
                    variance_ref=float(math.exp(intercept)))


def realizations_needed(sd, mean, rel_precision: float, confidence: float = 0.95,
                        n_max: int = 10 ** 7) -> int:
    """Smallest n with ``t_{n-1} sd / sqrt(n) <= rel_precision |mean|`` (n >= 2).

    The Student-t form of Kanit's ``2 D / sqrt(n)`` criterion: the half-width of the
    ``confidence`` interval of the mean of n realizations is at most ``rel_precision`` of the
    mean.
    """
    sd = float(sd)
    target = rel_precision * abs(float(mean))
    if target == 0:
        raise InputError("the relative precision of a quantity with zero mean is undefined")
    if sd == 0:
        return 2
    q = 0.5 + confidence / 2
    # Normal approximation as a start, then walk up (t_{n-1} > z, so the answer is >= start).
    n = max(2, int(math.ceil((stats.norm.ppf(q) * sd / target) ** 2)))
    while n < n_max and stats.t.ppf(q, n - 1) * sd / math.sqrt(n) > target:
        n = max(n + 1, int(n * 1.01))
    # back off to the smallest n (the t criterion is monotone in n)
    while n > 2 and stats.t.ppf(q, n - 2) * sd / math.sqrt(n - 1) <= target:
        n -= 1
    return n
