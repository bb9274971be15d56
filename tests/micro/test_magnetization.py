"""Magnetization laws: limits, caps, derivatives and the co-energy used for forces."""
import math

import numpy as np
import pytest
from scipy.constants import k as KB
from scipy.constants import mu_0 as MU0

from micro import InputError
from micro.magnetization import get_law

V = 4 / 3 * math.pi * (25e-9) ** 3          # 25 nm sphere [m^3]
MS = 7870 * 178 * V                         # its saturation moment [A m^2]


def test_linear_sphere_and_cap():
    h = np.array([1e2, 1e4, 1e7])
    law = get_law("linear")                 # chi = inf: m = 3 V H
    m = law.magnitude(h, MS, V)
    assert m[0] == pytest.approx(3 * V * 1e2, rel=1e-15)
    assert m[2] == MS                       # far above M_s / 3: capped exactly
    law10 = get_law("linear", chi=10.0)
    assert law10.magnitude(1e2, MS, V) == pytest.approx(V * 30 / 13 * 1e2, rel=1e-15)


def test_frohlich_kennelly_limits():
    law = get_law("frohlich-kennelly", chi0=3.0)
    # initial slope chi0 V (relative deviation ~ chi0 V h / m_s = 2e-7 at h = 1e-1)
    assert law.magnitude(1e-1, MS, V) / 1e-1 == pytest.approx(3 * V, rel=1e-6)
    # approach to saturation: m_s (1 - m_s/(chi0 V h)) to first order
    h = 1e12
    assert law.magnitude(h, MS, V) == pytest.approx(MS * (1 - MS / (3 * V * h)), rel=1e-9)


def test_langevin_limits():
    law = get_law("langevin", T_K=300.0)
    h = 1e-3
    slope = MU0 * MS ** 2 / (3 * KB * 300.0)        # Curie law, x ~ 2e-5 here
    assert law.magnitude(h, MS, V) / h == pytest.approx(slope, rel=1e-9)
    x = 50.0
    hx = x * KB * 300 / (MU0 * MS)
    assert law.magnitude(hx, MS, V) == pytest.approx(MS * (1 / math.tanh(x) - 1 / x), rel=1e-14)


@pytest.mark.parametrize("name,params", [("linear", {}), ("linear", {"chi": 5.0}),
                                         ("frohlich-kennelly", {}), ("langevin", {}),
                                         ("saturated", {})])
def test_coenergy_derivative_and_slope(name, params):
    """d(coenergy)/dh = mu0 |m| and slope = d|m|/dh, by central differences (rel. step 1e-6:
    truncation ~1e-12, rounding ~1e-10, so 1e-6 relative is a safe bound)."""
    law = get_law(name, **params)
    for h in (3e3, 1e5, 2e6):
        dh = 1e-6 * h
        d = (law.coenergy_J(h + dh, MS, V) - law.coenergy_J(h - dh, MS, V)) / (2 * dh)
        assert d == pytest.approx(MU0 * law.magnitude(h, MS, V), rel=1e-6)
        if name != "linear" or abs(3 * V * h - MS) > 0.01 * MS:    # kink of the cap
            s = (law.magnitude(h + dh, MS, V) - law.magnitude(h - dh, MS, V)) / (2 * dh)
            assert law.slope(h, MS, V) == pytest.approx(s, rel=1e-5, abs=1e-12 * V)


def test_moment_vectorised_along_field_core_shell():
    rng = np.random.default_rng(1)
    H = rng.normal(size=(7, 3)) * 1e4
    ms = MS * rng.uniform(0.3, 1.0, 7)       # core-shell: own m_sat per particle
    vol = np.full(7, V)
    for name in ("saturated", "linear", "frohlich-kennelly", "langevin"):
        law = get_law(name)
        m = law.moment(H, ms, vol)
        h = np.linalg.norm(H, axis=1)
        np.testing.assert_allclose(np.cross(m, H), 0, atol=1e-12 * np.abs(m).max() * h.max())
        np.testing.assert_allclose(np.linalg.norm(m, axis=1), law.magnitude(h, ms, vol),
                                   rtol=1e-14)
        assert np.all(np.einsum("ij,ij->i", m, H) > 0)
        assert np.all(np.linalg.norm(m, axis=1) <= ms * (1 + 1e-14))


def test_bad_input():
    with pytest.raises(InputError, match="law must be one of"):
        get_law("ising")
    with pytest.raises(InputError, match="chi0"):
        get_law("frohlich-kennelly", chi0=-1)
    with pytest.raises(InputError, match="unexpected"):
        get_law("linear", T_K=3)
    with pytest.raises(InputError, match="T_K"):
        get_law("langevin", T_K=0)
    with pytest.raises(InputError, match="direction is undefined"):
        get_law("saturated").moment(np.zeros((2, 3)), np.ones(2), np.ones(2))
    with pytest.raises(InputError, match="shape"):
        get_law("linear").moment(np.zeros(3), 1.0, 1.0)
    # zero field, soft laws: zero moment (no NaN)
    m = get_law("linear").moment(np.zeros((2, 3)), np.ones(2), np.ones(2))
    assert np.all(m == 0)
