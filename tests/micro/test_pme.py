"""Particle-mesh Ewald against the plain Ewald reference on random RVEs with clusters."""
import numpy as np
import pytest

from micro import DipoleSum, RVE
from micro.particles import generate_rve


@pytest.fixture(scope="module")
def clustered():
    rve = generate_rve(0.05, 400, 7, arrangement="clusters", cluster_size=10)
    rng = np.random.default_rng(0)
    mom = rng.normal(size=(rve.n, 3)) * rve.m_sat_Am2[:, None] * 0.3 + [0, 0, 1e-17]
    return rve, mom


@pytest.mark.parametrize("accuracy", [1e-4, 1e-6])
def test_pme_field_matches_ewald(clustered, accuracy):
    rve, mom = clustered
    ref = DipoleSum(rve.box_m, rve.centers_m, accuracy=1e-10, summation="ewald").field_A_m(mom)
    ds = DipoleSum(rve.box_m, rve.centers_m, accuracy=accuracy, summation="pme")
    h = ds.field_A_m(mom)
    # requested accuracy is relative to the rms field; the grid rule keeps a margin of ~5
    err = np.sqrt(np.mean((h - ref) ** 2)) / np.sqrt(np.mean(ref ** 2))
    assert err < accuracy, err
    assert ds.parameters["pme_grid"] >= 2 * ds.parameters["pme_order"]


def test_pme_forces_energy_virial_match_ewald(clustered):
    rve, mom = clustered
    H0, F0, U0, S0 = DipoleSum(rve.box_m, rve.centers_m, accuracy=1e-10,
                               summation="ewald").interactions(mom)
    H1, F1, U1, S1 = DipoleSum(rve.box_m, rve.centers_m, accuracy=1e-7,
                               summation="pme").interactions(mom)
    # forces and stresses are derivatives: one order of the grid less accurate than the field,
    # so 1e-7 requested gives ~1e-5 relative (rms) -- bound at 1e-4
    rms = lambda a: np.sqrt(np.mean(a ** 2))      # noqa: E731
    assert rms(F1 - F0) / rms(F0) < 1e-4
    assert np.abs(S1 - S0).max() / np.abs(S0).max() < 1e-4
    assert U1 == pytest.approx(U0, rel=1e-5)
    assert np.linalg.norm(F1.sum(0)) < 1e-4 * np.abs(F1).sum()


def test_pme_permutation_and_translation(clustered):
    rve, mom = clustered
    h = DipoleSum(rve.box_m, rve.centers_m, accuracy=1e-6, summation="pme").field_A_m(mom)
    perm = np.random.default_rng(1).permutation(rve.n)
    hp = DipoleSum(rve.box_m, rve.centers_m[perm], accuracy=1e-6, summation="pme").field_A_m(mom[perm])
    np.testing.assert_allclose(hp, h[perm], rtol=1e-12, atol=1e-12 * np.abs(h).max())
    # translation by a non-grid vector changes only the (bounded) discretisation error
    c2 = np.mod(rve.centers_m + 0.123456 * rve.box_m, rve.box_m)
    h2 = DipoleSum(rve.box_m, c2, accuracy=1e-6, summation="pme").field_A_m(mom)
    assert np.sqrt(np.mean((h2 - h) ** 2)) / np.sqrt(np.mean(h ** 2)) < 2e-6
    assert isinstance(rve, RVE)
