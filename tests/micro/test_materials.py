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


# --------------------------------------------------------------------------- presets (issue 36)
def test_seed_paper_presets_are_the_old_defaults_bit_for_bit():
    from micro.materials import (DEFAULT_PRESET, MATRIX_PRESETS, PARTICLE_PRESETS,
                                 matrix_preset, particle_preset, radius_bounds_m)
    assert DEFAULT_PRESET == "seed-paper"
    p, m = particle_preset(), matrix_preset()
    assert p is PARTICLE_PRESETS["seed-paper"] and m is MATRIX_PRESETS["seed-paper"]
    assert (p.density_kg_m3, p.powder_sigma_Am2_kg, p.core_sigma_Am2_kg) == (7870.0, 178.0, None)
    assert (p.E_Pa, p.nu, p.shell_m, p.calibrate_sigma_Am2_kg) == (211e9, 0.29, 0.0, None)
    assert (p.mean_radius_m, p.gsd) == (25e-9, 1.4)
    assert p.radius_bounds_m == (10e-9, 50e-9)           # exactly the former [10, 50] nm
    assert radius_bounds_m(25e-9) == (10e-9, 50e-9)
    assert p.Ms_A_m == SEED.Ms_A_m
    assert (m.E_Pa, m.nu, m.density_kg_m3) == (2e6, 0.45, 1210.0)
    assert m.elastic == ElasticMaterial() == elastic(PDMS)


def test_every_preset_is_consistent():
    from micro.materials import MATRIX_PRESETS, PARTICLE_PRESETS, radius_bounds_m
    assert {"seed-paper", "nanofer", "carbonyl-iron", "magnetite"} <= set(PARTICLE_PRESETS)
    assert {"seed-paper", "sylgard184-10to1", "sylgard184-20to1", "ecoflex-00-30",
            "rtv615"} <= set(MATRIX_PRESETS)
    for name, p in PARTICLE_PRESETS.items():
        assert p.name == name and len(p.sources) > 80
        # iron-based powders between magnetite and pure iron; moments below iron's 218
        assert FE3O4.density_kg_m3 <= p.density_kg_m3 <= FE.density_kg_m3
        assert FE3O4.sigma_s_Am2_kg <= p.powder_sigma_Am2_kg <= FE.sigma_s_Am2_kg
        assert 1e5 < p.Ms_A_m <= FE.Ms_A_m
        lo, hi = p.radius_bounds_m
        assert lo < p.mean_radius_m < hi and (lo, hi) == radius_bounds_m(p.mean_radius_m)
        assert hi / lo == pytest.approx(5.0)
        assert 100e9 < p.E_Pa < 300e9 and 0.2 < p.nu < 0.35
    for name, m in MATRIX_PRESETS.items():
        assert m.name == name and len(m.sources) > 60
        assert 5e4 < m.E_Pa < 5e6 and 0.45 <= m.nu < 0.5
        assert 1000.0 <= m.density_kg_m3 <= 1250.0
    # what the names promise
    assert MATRIX_PRESETS["sylgard184-10to1"].density_kg_m3 == 1030.0
    assert MATRIX_PRESETS["sylgard184-20to1"].E_Pa < MATRIX_PRESETS["sylgard184-10to1"].E_Pa
    assert MATRIX_PRESETS["ecoflex-00-30"].E_Pa < MATRIX_PRESETS["sylgard184-20to1"].E_Pa
    ci = PARTICLE_PRESETS["carbonyl-iron"]
    assert ci.mean_radius_m == 1e-6 and ci.radius_bounds_m == pytest.approx((0.4e-6, 2e-6))
    assert PARTICLE_PRESETS["magnetite"].core is FE3O4
    assert PARTICLE_PRESETS["nanofer"].calibrate_sigma_Am2_kg == SEED.sigma_s_Am2_kg


def test_nanofer_preset_calibrates_a_core_below_iron():
    from micro.materials import PARTICLE_PRESETS
    from micro.particles import CoreShell, LogNormal
    p = PARTICLE_PRESETS["nanofer"]
    dist = LogNormal.from_mean(p.mean_radius_m, p.gsd, *p.radius_bounds_m)
    comp = CoreShell(shell_m=p.shell_m, calibrate_sigma_Am2_kg=p.calibrate_sigma_Am2_kg)
    assert SEED.sigma_s_Am2_kg < comp.core_sigma(dist) < FE.sigma_s_Am2_kg


def test_unknown_preset_names_are_refused():
    from micro.materials import matrix_preset, particle_preset
    with pytest.raises(InputError, match="particle material must be one of"):
        particle_preset("unobtainium")
    with pytest.raises(InputError, match="matrix material must be one of .*sylgard184-10to1"):
        matrix_preset("jelly")
