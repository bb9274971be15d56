"""Every example under examples/ is imported and run by a test (scikit-fem's habit)."""
from pathlib import Path

import numpy as np

from micro.materials import PDMS, SEED

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_every_example_has_a_test_that_runs_it():
    tests = "\n".join(p.read_text() for p in Path(__file__).resolve().parent.rglob("test_*.py"))
    for ex in sorted(EXAMPLES.glob("*.py")):
        assert f'"{ex.stem}"' in tests or f"{ex.stem}.py" in tests, \
            f"examples/{ex.name} is not run by any test"


def test_python_api_chain(load_script):
    ex = load_script(EXAMPLES / "python_api.py")
    # the effective body force is the Kelvin force of the RVE's magnetization: for a uniform
    # applied gradient, f_eff = M_eff dB/dz exactly (sum of G m_i over the volume); the FEM
    # reproduces it as the mean of the spread particle forces (to the Ewald accuracy 1e-6)
    assert np.isclose(ex.cell.f_eff_N_m3[2], ex.state.M_eff_A_per_m[2] * SEED.gradB_T_per_m,
                      rtol=1e-5)
    # demagnetization-limited spheres below saturation: M_eff ~ 3 phi H / (1 - phi) within the
    # interaction corrections of a random dispersion (a few % at phi = 0.035)
    M_cm = 3 * ex.rve.phi / (1 - ex.rve.phi) * 0.3 / 4e-7 / np.pi
    assert 0.9 < ex.state.M_eff_A_per_m[2] / M_cm < 1.1
    # stiff particles stiffen the matrix (above the PDMS value, below Hashin-Shtrikman's
    # upper bound, which for rigid spheres at 3.5 % is ~ +10 %)
    assert PDMS.E_Pa < ex.cell.E_eff_Pa < 1.2 * PDMS.E_Pa
    assert 0 < ex.beam.tip_m < 0.0194
