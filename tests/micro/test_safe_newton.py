"""The vectorised safeguarded Newton behind the intrinsic and Stoner-Wohlfarth laws: roots
against brentq, each element solved as if alone, the ``where`` mask, and termination at the
double roots of the Stoner-Wohlfarth minima at their switching fields; the numba kernel of the
Stoner-Wohlfarth average against the same average in numpy."""
import math

import numba
import numpy as np
import pytest
from scipy.optimize import brentq

from micro import ConvergenceError
from micro.magnetization import (_axes, _safe_newton, _sw_anhysteretic, _sw_reversed, _sw_stable,
                                 get_law, switching_field)


def _cubic(x, a, r):
    """Monotone residual with a root at r: a (x - r) + (x - r)^3 (a = 0: a triple root)."""
    d = x - r
    return a * d + d ** 3, a + 3 * d ** 2


def test_roots_exact_and_against_brentq():
    rng = np.random.default_rng(4)
    r = rng.uniform(-0.9, 0.9, 200)
    a = np.where(np.arange(200) % 4 == 0, 0.0, rng.uniform(1e-6, 2.0, 200))
    x = _safe_newton(_cubic, -1.0, 1.0, rng.uniform(-1, 1, 200), 1e-13, args=(a, r))
    # the exact root r: simple roots to the tolerance; a triple root (a = 0, where Newton
    # converges linearly and bisection takes over) to the cube root of round-off in F
    simple = a > 0
    np.testing.assert_allclose(x[simple], r[simple], rtol=0, atol=1e-12)
    np.testing.assert_allclose(x[~simple], r[~simple], rtol=0, atol=1e-5)
    # a transcendental residual against brentq: x = cos(x) / c
    c = np.linspace(0.5, 5.0, 50)
    y = _safe_newton(lambda t, c: (c * t - np.cos(t), c + np.sin(t)), 0.0, 2.0, 1.0, 1e-14,
                     args=(c,))
    ref = [brentq(lambda t, ci=ci: ci * t - math.cos(t), 0.0, 2.0, xtol=1e-15) for ci in c]
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-13)


def test_each_element_as_if_alone_and_where():
    rng = np.random.default_rng(5)
    r = rng.uniform(-0.9, 0.9, 64)
    a = rng.uniform(0.0, 2.0, 64)
    x0 = rng.uniform(-1, 1, 64)
    whole = _safe_newton(_cubic, -1.0, 1.0, x0, 1e-13, args=(a, r))
    alone = [_safe_newton(_cubic, -1.0, 1.0, x0[i], 1e-13, args=(a[i], r[i])) for i in range(64)]
    assert np.array_equal(whole, np.array(alone))
    # where: the masked elements are solved exactly as in the whole array, the others keep x0
    mask = np.arange(64) % 3 == 0
    part = _safe_newton(_cubic, -1.0, 1.0, x0, 1e-13, args=(a, r), where=mask)
    assert np.array_equal(part[mask], whole[mask])
    assert np.array_equal(part[~mask], x0[~mask])
    # broadcast shapes come back in the broadcast shape
    out = _safe_newton(_cubic, -1.0, 1.0, 0.0, 1e-13, args=(a[:4, None], r[None, :3]))
    assert out.shape == (4, 3)


def test_unconverged_is_an_error_not_a_value():
    with pytest.raises(ConvergenceError, match="did not converge"):
        # a residual that never resolves (NaN) and xtol 0: bisection cannot reach a zero-width
        # bracket in 20 steps, so maxit ends the solve with an error
        _safe_newton(lambda x: (np.full_like(x, math.nan), np.ones_like(x)), 0.0, 1.0, 0.5,
                     0.0, maxit=20)


def test_reversed_minimum_at_its_switching_field_terminates():
    """Fields a few ulps to 1e-6 below each axis' switching field: the reversed minimum merges
    with the maximum there (a double root of dE/dtheta), where round-off in F sent the former
    Newton back and forth between two points 1.2e-13 apart (xtol 1e-13) until maxit."""
    psi, _ = _axes()
    eps = np.concatenate([[1e-16, 3e-16, 1e-15], np.logspace(-14, -6, 33)])
    h = switching_field(psi)[None, :] * (1.0 - eps[:, None])
    psi2 = np.broadcast_to(psi, h.shape)
    phi, exists = _sw_reversed(h, psi2)
    assert exists.all()
    # a stationary point of e(theta) = sin^2 theta + 2 h cos(theta - psi) within its bracket:
    # dE/dtheta = 0 to round-off (|d2E| -> 0 there, so the angle itself is only good to
    # sqrt(eps) of the distance to the switching field)
    F = np.sin(2 * phi) - 2 * h * np.sin(phi - psi2)
    assert np.max(np.abs(F)) < 1e-9
    tc = -np.arctan(np.tan(psi2) ** (1.0 / 3.0))
    assert np.all((phi >= tc) & (phi <= 0))
    # the ensemble average over these fields is finite and between the branches' bounds
    m = _sw_anhysteretic(h[:, 0], np.inf)
    assert np.all(np.isfinite(m)) and np.all((m > 0) & (m <= 1))


def test_stoner_wohlfarth_law_on_many_fields_near_switching():
    """The law as the dipole solver calls it, on reduced fields that sweep every axis'
    switching field (the set that stalled the former iteration on an RVE of 1e5 particles)."""
    law = get_law("stoner-wohlfarth", T_K=300.0)
    V = 4 / 3 * math.pi * 10e-9 ** 3
    msat = 1.7e6 * V
    HK = 2 * law.K_J_m3 * V / (4e-7 * math.pi * msat)
    hr = np.sort(np.concatenate([switching_field(_axes()[0]) * (1 + d) for d in
                                 (-1e-12, -1e-14, 0.0, 1e-14)]))
    m = law.magnitude(hr * HK, msat, V)
    assert np.all(np.isfinite(m)) and np.all(np.diff(m) >= -1e-12 * msat)


def _sw_average_numpy(h, kap):
    """The random-axis two-state average and its slope from the vectorised numpy roots (the
    former implementation of ``_sw_anhysteretic``): the reference of the numba kernel."""
    psi, w = _axes()
    h, kap = h[:, None], kap[:, None]
    tp = _sw_stable(h, psi)
    phi, ex = _sw_reversed(h, psi)
    cp, cm = np.cos(tp - psi), -np.cos(phi - psi)
    de = (np.sin(phi) ** 2 + 2 * h * np.cos(phi - psi)) - (np.sin(tp) ** 2 - 2 * h * cp)
    with np.errstate(invalid="ignore", over="ignore"):
        beta = np.where(np.isinf(kap), np.where(de > 0, np.inf, 0.0), kap * de)
        pp = np.where(ex, 1.0 / (1.0 + np.exp(-beta)), 1.0)
    m = (w * (pp * cp + (1 - pp) * cm)).sum(axis=-1)
    epp = 2 * np.cos(2 * tp) + 2 * h * cp
    epm = 2 * np.cos(2 * phi) - 2 * h * np.cos(phi - psi)
    with np.errstate(divide="ignore", invalid="ignore"):
        dcm = np.where(ex & (epm > 0), 2 * np.sin(phi - psi) ** 2 / epm, 0.0)
        dbeta = np.where(np.isinf(kap), 0.0, kap * 2 * (cp - cm))
    dpp = np.where(ex, pp * (1 - pp) * dbeta, 0.0)
    dm = (w * (pp * 2 * np.sin(tp - psi) ** 2 / epp + np.where(pp < 1, (1 - pp) * dcm, 0.0)
               + (cp - cm) * dpp)).sum(axis=-1)
    return m, dm


@pytest.mark.parametrize("kappa", [math.inf, 3.0, 50.0, 760.0])
def test_sw_kernel_against_numpy_and_thread_count(kappa):
    """The numba average equals the numpy one to round-off (only the summation order
    differs), on random fields, every axis' switching field and h = 0; and is bitwise the same
    on one thread and on all."""
    rng = np.random.default_rng(7)
    h = np.concatenate([rng.uniform(0.0, 2.0, 500), switching_field(_axes()[0]) * (1 - 1e-12),
                        [0.0, 1e-300, 5.0]])
    kap = np.full_like(h, kappa)
    m_ref, dm_ref = _sw_average_numpy(h, kap)
    before = numba.get_num_threads()
    try:
        runs = []
        for nt in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(nt)
            runs.append(_sw_anhysteretic(h, kap, with_slope=True))
    finally:
        numba.set_num_threads(before)
    (m, dm), (m2, dm2) = runs
    assert np.array_equal(m, m2) and np.array_equal(dm, dm2)
    assert np.max(np.abs(m - m_ref)) < 4e-15
    assert np.max(np.abs(dm - dm_ref) / np.maximum(1.0, np.abs(dm_ref))) < 4e-15
    # broadcast shapes come back as given
    assert _sw_anhysteretic(h[:6].reshape(2, 3), kappa).shape == (2, 3)
