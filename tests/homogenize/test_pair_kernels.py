"""The numba pair sums of the magnetic stiffness against their numpy twin, and the symmetries
they must have (homogenize/cell/_pair_kernels.py)."""
import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from homogenize.cell._pair_kernels import pair_sums, pair_sums_reference


def _case(N=7, seed=3):
    rng = np.random.default_rng(seed)
    L = 1e-6
    x = rng.uniform(0, L, size=(N, 3))
    m = rng.normal(size=(N, 3)) * 1e-17
    r = np.arange(-1, 2)
    imgs = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3) * L
    return x, m, imgs, 1.4 * L


def test_kernel_equals_numpy_twin():
    x, m, imgs, rc = _case()
    got = pair_sums(x, m, imgs, rc, MU0)
    ref = pair_sums_reference(x, m, imgs, rc, MU0)
    for g, r in zip(got, ref):
        assert np.abs(g - r).max() <= 1e-12 * np.abs(r).max()


def test_pair_symmetries():
    """T_ij = T_ji (the dipole tensor is even in d, symmetric in its indices); the force
    stiffness at frozen moments conserves momentum (each block column of Fx sums to zero:
    a rigid translation of all particles changes no force) and is symmetric (Fx_ij = Fx_ji^T:
    the forces derive from one pair energy)."""
    x, m, imgs, rc = _case()
    T, Hx, Fx, Fm = pair_sums(x, m, imgs, rc, MU0)
    assert np.allclose(T, T.transpose(1, 0, 2, 3), rtol=0, atol=1e-12 * np.abs(T).max())
    assert np.allclose(T, T.transpose(0, 1, 3, 2), rtol=0, atol=1e-12 * np.abs(T).max())
    scale = np.abs(Fx).max()
    assert np.abs(Fx.sum(axis=1)).max() <= 1e-10 * scale
    dense = Fx.transpose(0, 2, 1, 3).reshape(3 * len(x), 3 * len(x))
    assert np.abs(dense - dense.T).max() <= 1e-10 * scale


def test_one_pair_analytic():
    """Two dipoles along z at distance r (no images): T_zz = 2 / (4 pi r^3), and the axial
    force stiffness of the pair energy U(r) = -mu0 m^2 / (2 pi r^3): F_0 = U'(r) on the
    particle at the origin, dF_0/dz_0 = -U''(r) = +6 mu0 m^2 / (pi r^5) (the attraction grows
    as they approach: a negative stiffness of the gap)."""
    r, mz = 2e-7, 3e-17
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, r]])
    m = np.array([[0.0, 0.0, mz], [0.0, 0.0, mz]])
    T, Hx, Fx, Fm = pair_sums(x, m, np.zeros((1, 3)), 10 * r, MU0)
    assert T[0, 1, 2, 2] == pytest.approx(2.0 / (4 * np.pi * r ** 3), rel=1e-13)
    assert T[0, 1, 0, 0] == pytest.approx(-1.0 / (4 * np.pi * r ** 3), rel=1e-13)
    assert Fx[0, 0, 2, 2] == pytest.approx(6.0 * MU0 * mz ** 2 / (np.pi * r ** 5), rel=1e-12)
