"""Two point dipoles: field, force and torque against the analytic formulas; open-boundary
direct sum against magpylib."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from micro import InputError, dipole_field_direct, dipole_pair_interactions


def _analytic(r, m1, m2):
    """Field of m2 at m1, force and torque on m1 (r = x1 - x2), textbook formulas."""
    d = np.linalg.norm(r)
    n = r / d
    H = (3 * n * (m2 @ n) - m2) / (4 * math.pi * d ** 3)
    F = 3 * MU0 / (4 * math.pi * d ** 4) * ((m1 @ n) * m2 + (m2 @ n) * m1 + (m1 @ m2) * n
                                              - 5 * (m1 @ n) * (m2 @ n) * n)
    return H, F, MU0 * np.cross(m1, H)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pair_field_force_torque(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(2, 3)) * 50e-9
    m = rng.normal(size=(2, 3)) * 1e-16
    H, F, T = dipole_pair_interactions(x, m)
    Ha, Fa, Ta = _analytic(x[0] - x[1], m[0], m[1])
    # identical formulas in another arrangement: rounding only (1e-12 relative)
    np.testing.assert_allclose(H[0], Ha, rtol=1e-12, atol=1e-12 * np.abs(Ha).max())
    np.testing.assert_allclose(F[0], Fa, rtol=1e-12, atol=1e-12 * np.abs(Fa).max())
    np.testing.assert_allclose(T[0], Ta, rtol=1e-12, atol=1e-12 * np.abs(Ta).max())
    np.testing.assert_allclose(F[1], -F[0], atol=1e-13 * np.abs(Fa).max())   # Newton III
    # angular momentum balance: the pair torques plus r x F sum to zero
    tot = T.sum(axis=0) + np.cross(x[0], F[0]) + np.cross(x[1], F[1])
    assert np.linalg.norm(tot) < 1e-12 * np.abs(Ta).max()


def test_coaxial_and_side_by_side_values():
    """Head-to-tail parallel dipoles attract with 6 mu0 m^2/(4 pi d^4), side by side they repel
    with 3 mu0 m^2/(4 pi d^4); the field on the axis is 2 m/(4 pi d^3)."""
    d, m0 = 60e-9, 2e-16
    mz = np.array([[0, 0, m0], [0, 0, m0]])
    H, F, _ = dipole_pair_interactions(np.array([[0, 0, 0], [0, 0, d]]), mz)
    assert H[0, 2] == pytest.approx(2 * m0 / (4 * math.pi * d ** 3), rel=1e-13)
    assert F[0, 2] == pytest.approx(6 * MU0 * m0 ** 2 / (4 * math.pi * d ** 4), rel=1e-13)
    H, F, _ = dipole_pair_interactions(np.array([[0, 0, 0], [d, 0, 0]]), mz)
    assert H[0, 2] == pytest.approx(-m0 / (4 * math.pi * d ** 3), rel=1e-13)
    assert F[0, 0] == pytest.approx(-3 * MU0 * m0 ** 2 / (4 * math.pi * d ** 4), rel=1e-13)


def test_direct_field_against_magpylib():
    magpy = pytest.importorskip("magpylib")
    rng = np.random.default_rng(3)
    src = rng.random((40, 3)) * 1e-6
    mom = rng.normal(size=(40, 3)) * 1e-16
    obs = rng.random((50, 3)) * 1e-6 + 2e-6          # away from the sources
    H = dipole_field_direct(src, mom, obs)
    ref = np.zeros_like(H)
    for s, m in zip(src, mom):
        ref += magpy.misc.Dipole(position=s, moment=m).getH(obs)
    # independent implementation in float64: agreement to rounding (1e-10 relative)
    np.testing.assert_allclose(H, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_direct_scale_invariance_and_errors():
    rng = np.random.default_rng(4)
    src = rng.normal(size=(10, 3))
    mom = rng.normal(size=(10, 3))
    obs = rng.normal(size=(8, 3)) + 5
    h1 = dipole_field_direct(src, mom, obs)
    h2 = dipole_field_direct(src * 1e-8, mom, obs * 1e-8)     # H ~ m / L^3
    np.testing.assert_allclose(h2 * 1e-24, h1, rtol=1e-12)
    np.testing.assert_allclose(dipole_field_direct(src, mom, obs, parallel=False), h1, rtol=1e-14)
    with pytest.raises(InputError, match="shape"):
        dipole_field_direct(src, mom[:3], obs)
