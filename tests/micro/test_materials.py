"""The one module of material constants: derived values against hand calculations, validation."""
import math

import pytest
from scipy.constants import mu_0

from micro import InputError
from micro.materials import FE, FE3O4, PDMS, SEED, Constituent, ElasticMaterial, elastic, \
    mixture_density_kg_m3


def test_derived_values():
    # Ms = rho sigma_s: 7870 x 218 = 1.71566e6 A/m (handbook value of Fe: 1.71e6 A/m)
    assert FE.Ms_A_m == pytest.approx(1.71566e6, rel=1e-12)
    assert FE3O4.Ms_A_m == pytest.approx(5170 * 92.0, rel=1e-12)
    # exchange length of Fe sqrt(2A / mu0 Ms^2) = 3.3 nm (Coey 2010, Table 7.1: 3.3 nm)
    assert FE.exchange_length_m == pytest.approx(math.sqrt(2 * 2.1e-11 / (mu_0 * FE.Ms_A_m ** 2)))
    assert 3.2e-9 < FE.exchange_length_m < 3.5e-9
    assert math.isnan(PDMS.exchange_length_m)
    # the seed powder: 178 A m^2/kg at 7870 kg/m^3
    assert SEED.Ms_A_m == pytest.approx(7870 * 178.0)
    assert mixture_density_kg_m3(0.0) == PDMS.density_kg_m3
    assert mixture_density_kg_m3(1.0) == FE.density_kg_m3
    assert elastic(FE) == ElasticMaterial(211e9, 0.29, 7870.0)


def test_lame_and_bulk_shear_are_consistent():
    m = ElasticMaterial(2e6, 0.45)
    lam, mu = m.lame_Pa
    K, G = m.bulk_shear_Pa
    assert G == pytest.approx(mu) and K == pytest.approx(lam + 2 * mu / 3, rel=1e-12)


@pytest.mark.parametrize("kw, words", [
    (dict(density_kg_m3=-1.0), "density_kg_m3"),
    (dict(density_kg_m3=7870.0, sigma_s_Am2_kg=1e4), "sigma_s_Am2_kg"),
    (dict(density_kg_m3=7870.0, nu=0.5), "nu"),
    (dict(density_kg_m3=7870.0, anisotropy="hexagonal"), "anisotropy"),
])
def test_unphysical_constants_are_refused(kw, words):
    with pytest.raises(InputError, match=words):
        Constituent(name="x", **kw)
    with pytest.raises(InputError, match="Young"):
        ElasticMaterial(-2e6, 0.45)
