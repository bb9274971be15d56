"""examples/cantilever_seed.py runs and its numbers are consistent."""
from pathlib import Path

import pytest

from homogenize.macro import closed_form as cf


@pytest.fixture(scope="module")
def ex(load_script):
    path = Path(__file__).resolve().parents[3] / "examples" / "cantilever_seed.py"
    return load_script(path)


def test_example_numbers(ex):
    # Eqs. (1)-(3): F_b = c d rho sigma_s dB/dx
    assert ex.BODY_FORCE_N_M3 == pytest.approx(0.035 * 0.5 * 7870 * 178 * 1.78, rel=1e-12)
    eb = cf.eb_tip_deflection_m(ex.BODY_FORCE_N_M3, 20e-3, 5e-3, 1e-3, 2e6)
    assert ex.TIP_M["eb"] == pytest.approx(eb, rel=1e-12)
    # ordering demanded by the physics: shear softens, large rotation and the 3D clamp stiffen
    assert ex.TIP_M["timoshenko"] > ex.TIP_M["eb"] > ex.TIP_M["elastica"]
    assert ex.TIP_M["fem"] > ex.TIP_M["neo-hookean"]
    # the 3D strip (w/L = 0.25) lies between the beam and the plate limits
    assert eb * (1 - 0.45**2) < ex.TIP_M["fem"] < eb
    # large deformation lowers the tip by about as much as in the elastica (within 1 %)
    assert ex.TIP_M["neo-hookean"] / ex.TIP_M["fem"] == pytest.approx(
        ex.TIP_M["elastica"] / eb, rel=0.01)
