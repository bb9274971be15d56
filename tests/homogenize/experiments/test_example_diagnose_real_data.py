"""The real-data example: its numbers (what results/diagnose/ reports).

The committed reports use the specimen solver's "normal" mesh (2 min for the Diguet account);
CI runs the "coarse" one (40 s), MAPSIM_FULL=1 the normal one. The assertions hold for both:
the specimen's change of length moves by ~1 % between them (results/diagnose)."""
import os
import types
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "diagnose_real_data.py"
FULL = os.environ.get("MAPSIM_FULL") == "1"


@pytest.fixture(scope="module")
def ex(load_script):
    d = load_script(EXAMPLE).diagnose_all("normal" if FULL else "coarse")
    return types.SimpleNamespace(seed_point=d["seed_paper_cantilever"].as_dict(),
                                 diguet=d["diguet2010_magnetostriction"].as_dict(),
                                 rtv615=d["rtv615_tensile"].as_dict())


def test_seed_point(ex):
    r = ex.seed_point
    assert r["causes"] == [] and r["n_rows"] == 1
    # a priori seed model 4.356 mm against 4 mm (assumed geometry, see PROVENANCE.md)
    assert r["baseline"]["cv_rmse"] == pytest.approx(0.356e-3, rel=5e-3)
    assert r["baseline"]["params"]["scale"] == pytest.approx(4.0 / 4.3556, rel=1e-3)


def test_diguet(ex):
    r = ex.diguet
    assert r["causes"] == ["dipolar_interaction", "field_dependent_magnetization"]
    assert r["gain"] > 6
    assert r["final"]["params"]["law"] == "langevin"
    # predicted (not fitted) stresses over mu0 M^2: the L/D = 0.8 cylinder's shape (Maxwell)
    # stress 0.174 (cylinder demagnetizing factor) and the random RVE's stress ~0.17 (virial
    # ~0.2 times the FEM share 0.86) nearly cancel; on the independent matrix modulus
    # E0 = 0.14 MPa the data need a fitted extra ~0.04 (0.22 on the fitted 0.69 MPa: kappa / E
    # is what the data fix; values as committed in results/diagnose)
    p = r["final"]["params"]
    assert p["kappa_shape_predicted"] == pytest.approx(0.1741, abs=2e-4)
    assert 0.15 < p["kappa_rve_predicted"] < 0.2
    assert abs(p["kappa_predicted"]) < 0.05
    assert 0.03 < p["kappa_extra"] < 0.05 and p["kappa_extra_sd"] < 0.005


def test_diguet_specimen_predicted_as_measured(ex):
    """The change of length through the specimen solver, nothing fitted (results/diagnose):
    the continuum model overshoots about 2x, the affine model cancels the end faces' mean;
    the measured curve lies between. The relaxed model (the relax table at E0) overshoots
    further than the continuum: the restructuring relieves the affine model's contraction,
    while the body keeps the zero-field modulus although the relaxed RVEs are ~2x stiffer
    (stated in the account)."""
    sp = ex.diguet["specimen"]
    assert sp["available"]
    g = sp["groups"][0]
    assert g["matrix_E_Pa"] == 140e3 and 1.9 < g["filler_stiffness_ratio"] < 2.1
    c, a = sp["models"]["continuum"], sp["models"]["affine"]
    assert 1.8 < c["fraction_explained"] < 2.6
    assert abs(a["fraction_explained"]) < 0.2
    assert a["predicted_end_mean"] < a["measured"] < c["predicted_end_mean"]
    # what still has to be fitted, named as such, with opposite signs for the two models
    assert c["fitted"]["kappa_extra"] < 0 < a["fitted"]["kappa_extra"]
    r = sp["models"]["relaxed"]
    assert r["available"] and r["predicted_end_mean"] > c["predicted_end_mean"] > r["measured"]
    stf = g["relax_table"]["stiffening"]
    assert 1.5 < stf["E_parallel_ratio_mean"][-1] < 2.5 and stf["E_parallel_ratio_mean"][0] == 1
    assert any("overestimates" in e for e in sp["model_error"])
    # that stiffening carried into the body by linear scaling (an estimate): less elongation
    rs = r["with_relaxed_stiffening_linearized"]
    assert rs["predicted_end_mean"] == pytest.approx(r["predicted_end_mean"]
                                                     / rs["E_parallel_ratio"], rel=1e-12)
    assert rs["predicted_end_mean"] < r["predicted_end_mean"]


def test_rtv615(ex):
    r = ex.rtv615
    assert r["causes"] == ["hyperelasticity"]
    assert r["final"]["params"]["hyperelastic_law"] == "gent"
    assert r["final"]["params"]["E_Pa"] == pytest.approx(1.16e6, rel=0.03)
    assert r["gain"] > 3
