"""Plain Ewald sum for point dipoles: against brute-force image sums, independence of the
splitting parameter, the Lorentz cavity field, and virial identities."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from micro import DipoleSum, InputError

L = 1e-6                               # box edge [m]; results scale as m / L^3


def _random(n, seed):
    rng = np.random.default_rng(seed)
    return rng.random((n, 3)) * L, rng.normal(size=(n, 3)) * 1e-16


def _brute_sphere(pos, mom, R):
    """Bare dipole sum over all images with |n| <= R (box units): a sphere in vacuum."""
    r = np.arange(-R, R + 1)
    sh = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
    sh = sh[np.einsum("ij,ij->i", sh, sh) <= R * R] * L
    H = np.zeros_like(pos)
    for i in range(len(pos)):
        d = (pos[i] - pos[None] - sh[:, None]).reshape(-1, 3)
        m = np.tile(mom, (len(sh), 1))
        r2 = np.einsum("ij,ij->i", d, d)
        ok = r2 > 0
        d, m, r2 = d[ok], m[ok], r2[ok]
        mr = np.einsum("ij,ij->i", d, m)
        H[i] = ((3 * mr / r2)[:, None] * d - m).T @ r2 ** -1.5 / (4 * math.pi)
    return H


def test_spherical_image_sum_converges_to_ewald_with_surface_term():
    pos, mom = _random(12, 0)
    ref = DipoleSum(L, pos, accuracy=1e-10, summation="ewald", demag_factor=1 / 3).field_A_m(mom)
    radii = np.array([3, 6, 12])
    err = np.array([np.linalg.norm(_brute_sphere(pos, mom, R) - ref) / np.linalg.norm(ref)
                    for R in radii])
    # the shell sum approaches the Ewald sum with a sphere's surface term N = 1/3 like
    # 1/R^2..1/R^3 (surface roughness of the lattice sphere): require a rate of at least 2
    rate = -np.polyfit(np.log(radii), np.log(err), 1)[0]
    assert rate > 2.0, (err, rate)
    assert err[-1] < 1e-5
    # and without the surface term the two differ by exactly M/3 in every particle
    tin = DipoleSum(L, pos, accuracy=1e-10, summation="ewald").field_A_m(mom)
    np.testing.assert_allclose(tin - ref, np.broadcast_to(mom.sum(0) / (3 * L ** 3), ref.shape),
                               rtol=1e-9)


@pytest.mark.parametrize("accuracy", [1e-4, 1e-6, 1e-8])
def test_independent_of_splitting_parameter(accuracy):
    pos, mom = _random(40, 1)
    ref = DipoleSum(L, pos, accuracy=1e-12, summation="ewald").field_A_m(mom)
    nref = np.sqrt(np.mean(ref ** 2))
    for alpha in (4.0 / L, 7.0 / L, 11.0 / L):
        h = DipoleSum(L, pos, accuracy=accuracy, summation="ewald", alpha_per_m=alpha).field_A_m(mom)
        # the requested accuracy is relative to the rms field; allow the estimate a factor 3
        assert np.sqrt(np.mean((h - ref) ** 2)) / nref < 3 * accuracy


def test_lorentz_cavity_field_simple_cubic():
    n = 4
    g = (np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * L / n
    m0 = 1e-16
    mom = np.tile([0.0, 0.0, m0], (n ** 3, 1))
    H = DipoleSum(L, g, accuracy=1e-10, summation="ewald").field_A_m(mom)
    M = n ** 3 * m0 / L ** 3
    # cubic symmetry: the lattice sum inside a sphere vanishes, leaving M/3 (accuracy 1e-10)
    np.testing.assert_allclose(H[:, 2], M / 3, rtol=1e-8)
    np.testing.assert_allclose(H[:, :2], 0, atol=1e-8 * M)
    # demagnetizing factor 1/3 (a sphere in vacuum): the cavity and surface fields cancel
    H = DipoleSum(L, g, accuracy=1e-10, summation="ewald", demag_factor=1 / 3).field_A_m(mom)
    np.testing.assert_allclose(H, 0, atol=1e-8 * M)


def test_virial_forces_energy_consistency():
    pos, mom = _random(30, 2)
    out = [DipoleSum(L, pos, accuracy=1e-10, summation="ewald", alpha_per_m=a / L).interactions(mom)
           for a in (5.0, 9.0)]
    (H1, F1, U1, S1), (H2, F2, U2, S2) = out
    # different splits, same physics (accuracy 1e-10, compared at 1e-8 of the scale)
    np.testing.assert_allclose(F1, F2, atol=1e-8 * np.abs(F1).max())
    np.testing.assert_allclose(S1, S2, atol=1e-8 * np.abs(S1).max())
    assert U1 == pytest.approx(U2, rel=1e-8)
    # Newton III over the periodic lattice sum
    assert np.linalg.norm(F1.sum(0)) < 1e-10 * np.abs(F1).sum()
    # the dipolar energy is homogeneous of degree -3 in lengths: tr(sigma) = -3 U / V
    # (U = -(mu0/2) sum m.H; an independent route to the virial's trace)
    assert np.trace(S1) == pytest.approx(-3 * U1 / L ** 3, rel=1e-8)
    # energy by a finite difference of a particle displacement equals -F (step 1e-5 L:
    # central difference error ~1e-8 relative)
    h = 1e-5 * L
    for ax in range(3):
        pp, pm = pos.copy(), pos.copy()
        pp[3, ax] += h
        pm[3, ax] -= h
        Up = DipoleSum(L, pp, accuracy=1e-12, summation="ewald").interactions(mom)[2]
        Um = DipoleSum(L, pm, accuracy=1e-12, summation="ewald").interactions(mom)[2]
        assert -(Up - Um) / (2 * h) == pytest.approx(F1[3, ax], rel=1e-5, abs=1e-6 * np.abs(F1).max())


def test_virial_against_lattice_pair_sum():
    """sigma = -(1/V) sum_pairs r (x) F against the explicit pair sum over a sphere of images.

    The lattice sum is conditionally convergent; its shape-dependent surface part involves the
    net moment only, so with moments summing to zero the sphere sum must approach Ewald."""
    pos, mom = _random(6, 5)
    mom = mom - mom.mean(0)
    H, F, U, S = DipoleSum(L, pos, accuracy=1e-12, summation="ewald").interactions(mom)
    R = 10
    r = np.arange(-R, R + 1)
    sh = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
    sh = sh[np.einsum("ij,ij->i", sh, sh) <= R * R] * L
    W = np.zeros((3, 3))
    for i in range(6):
        d = (pos[i] - pos[None] - sh[:, None]).reshape(-1, 3)
        mj = np.tile(mom, (len(sh), 1))
        r2 = np.einsum("ij,ij->i", d, d)
        ok = r2 > 0
        d, mj, r2 = d[ok], mj[ok], r2[ok]
        rn = np.sqrt(r2)
        n = d / rn[:, None]
        mi = mom[i]
        a, b = n @ mi, np.einsum("ij,ij->i", n, mj)
        Fp = 3 * MU0 / (4 * math.pi * r2 ** 2)[:, None] * (a[:, None] * mj + b[:, None] * mi
                                                           + (mj @ mi)[:, None] * n
                                                           - 5 * (a * b)[:, None] * n)
        W += 0.5 * d.T @ Fp
    S_pairs = -W / L ** 3
    # truncation at R = 10 with zero net moment: tail ~ 1/R^2 relative; 2e-2 is a safe bound
    np.testing.assert_allclose(S_pairs, S, atol=2e-2 * np.abs(S).max())


def test_translation_invariance_and_errors():
    pos, mom = _random(25, 3)
    H = DipoleSum(L, pos, accuracy=1e-9, summation="ewald").field_A_m(mom)
    shift = np.array([0.31, -0.77, 0.5]) * L
    H2 = DipoleSum(L, np.mod(pos + shift, L), accuracy=1e-9, summation="ewald").field_A_m(mom)
    np.testing.assert_allclose(H2, H, atol=1e-8 * np.abs(H).max())
    with pytest.raises(InputError, match="accuracy"):
        DipoleSum(L, pos, accuracy=0.5)
    with pytest.raises(InputError, match="demag_factor"):
        DipoleSum(L, pos, demag_factor=1.5)
    with pytest.raises(InputError, match="summation"):
        DipoleSum(L, pos, summation="fmm")
