"""The cause `microstructure_evolution` (particles that move): vocabulary, detection on a
synthetic case built to need it and not on cases that do not, its forms, the coupled-RVE
restructuring strain read from the relax table (zero at zero field, the affine model plus it),
and the Diguet 2010 diagnosis end to end with the coupled RVE's prediction reported."""
from pathlib import Path

import numpy as np
import pytest

from homogenize.experiments import causes as C
from homogenize.experiments.diagnose import diagnose
from homogenize.experiments.io import load_experiment
from homogenize.experiments.synthetic import generate
from homogenize.experiments.rve_tables import Unavailable, relax_tables, restructuring_table

ROOT = Path(__file__).resolve().parents[3]
DIGUET = ROOT / "examples" / "data" / "diguet2010_magnetostriction.toml"
ME = "microstructure_evolution"
# fixed seeds (the synthetic generator is seeded): a case built to need the cause (recovered
# exactly in 8 of seeds 0-7) and one that does not (saturated particles)
SEED_NEEDS, SEED_DIPOLAR = 1, 0


def test_vocabulary_format_document_and_help():
    assert ME in C.CAUSES and ME in C.DESCRIPTIONS and C.REQUIRES[ME] == "dipolar_interaction"
    doc = (ROOT / "examples" / "data" / "EXPERIMENT_FORMAT.md").read_text()
    row = [line for line in doc.splitlines() if line.startswith(f"| `{ME}`")]
    assert len(row) == 1 and "faster than M^2" in row[0]
    from homogenize.cli.cmd_experiments import _DIAGNOSE_DOC
    assert ME in _DIAGNOSE_DOC and "EXPERIMENT_FORMAT.md" in _DIAGNOSE_DOC


def test_detected_on_a_case_built_to_need_it():
    case = generate((ME,), "magnetostriction", seed=SEED_NEEDS)
    assert case.expected == {ME, "dipolar_interaction", "field_dependent_magnetization"}
    res = diagnose(case.experiment).as_dict()
    assert set(res["causes"]) == set(case.expected), res["steps"]
    step = next(s for s in res["steps"] if s["cause"] == ME)
    # the synthetic truth has no relax table: the form is the fitted one, and named so
    assert step["params"]["restructure_form"] == "fitted"
    assert step["params"]["c_restructure"] > 0          # the strain grows faster than M^2
    assert res["gain"] > 5


def test_not_detected_where_the_particles_need_not_move():
    """Saturated particles, a phi-dependent extra stress (kappa0 (1 + phi)) that is not a
    restructuring: not named (0 of seeds 0-7 when this was written)."""
    case = generate(("dipolar_interaction",), "magnetostriction", seed=SEED_DIPOLAR)
    res = diagnose(case.experiment).as_dict()
    assert ME not in res["causes"], res["steps"]
    assert set(res["causes"]) == set(case.expected)


@pytest.mark.xfail(reason="known weakness: with a field-dependent magnetization the fitted "
                          "M^4 form absorbs the misfit between the truth's tanh law and the "
                          "fitted laws; microstructure_evolution is falsely named in 5 of "
                          "seeds 0-7 (this seed is one of them); see results/diagnose/README.md. "
                          "strict: a fix of the weakness turns this into a failure to update",
                   strict=True)
def test_not_detected_with_a_field_dependent_magnetization_alone():
    case = generate(("field_dependent_magnetization",), "magnetostriction", seed=1)
    res = diagnose(case.experiment).as_dict()
    assert ME not in res["causes"], res["steps"]


def test_forms_follow_the_data_and_the_tables():
    case = generate(("dipolar_interaction",), "magnetostriction", seed=SEED_DIPOLAR)
    exp = case.experiment
    dip = C.ModelSpec("magnetostriction").plus("dipolar_interaction")
    # saturated particles: M is constant per specimen, an M^4 term cannot be told apart
    assert "fitted" not in C.forms(ME, exp, dip)
    assert "fitted" in C.forms(ME, exp, dip.plus("field_dependent_magnetization", "langevin"))
    # no relax table at the synthetic specimens' phi and E: no coupled_rve form, and why
    ok, why = C.coupled_rve_available(exp)
    assert not ok and "no coupled-RVE (relax) table" in why and "mapsim batch" in why
    with pytest.raises(Unavailable):
        restructuring_table(0.123, 2e6)


needs_table = pytest.mark.skipif(not relax_tables(), reason="no relax table committed")


def _diguet_at_table_modulus():
    """The Diguet data with the matrix modulus of the 0.69 MPa relax table (the value Stewart &
    Anand fitted; the data set's TOML says the independent E0 = 0.14 MPa, whose table
    data/relax_diguet2010_E0.h5 is checked below): these tests check the restructuring
    machinery on that table."""
    from dataclasses import replace
    exp = load_experiment(DIGUET)
    return replace(exp, matrix=replace(exp.matrix, E_Pa=0.69e6))


def test_diguet_at_its_independent_modulus_uses_the_E0_relax_table():
    """The data set's own modulus E0 = 0.14 MPa finds the table made at E0 (not the 0.69 MPa
    one); a modulus with no table is refused naming what exists and the command that makes
    one."""
    from dataclasses import replace
    exp = load_experiment(DIGUET)
    assert exp.matrix.E_Pa == 140e3
    ok, why = C.coupled_rve_available(exp)
    assert ok, why
    tab = restructuring_table(0.261, 140e3)
    assert tab.provenance["table"].endswith("homogenize/experiments/data/relax_diguet2010_E0.h5")
    assert tab.E_Pa == pytest.approx(140e3)
    # zero field: nothing moves; at the top field the restructuring relieves most of the affine
    # RVE's contraction in both realizations
    assert np.all(tab.d_eps_rve[0] == 0.0)
    assert np.all(tab.d_eps_rve[-1] > 0.5 * np.abs(tab.eps_rve_affine[-1]))
    other = replace(exp, matrix=replace(exp.matrix, E_Pa=0.3e6))
    ok, why = C.coupled_rve_available(other)
    assert not ok and "E = 300000 Pa" in why and "mapsim batch" in why


@needs_table
def test_restructuring_strain_is_zero_at_zero_field_and_adds_to_the_affine_model():
    exp = _diguet_at_table_modulus()
    tab = restructuring_table(0.261, exp.matrix.E_Pa)
    assert tab.B_T[0] == 0.0
    # zero field: no force, no displacement: relaxed == affine for every realization
    assert np.all(tab.d_eps_rve[0] == 0.0) and np.all(tab.d_x[0] == 0.0)
    assert tab.delta_strain(0.0, 0.17) == 0.0
    # the relaxed and affine values are those stored in the table
    assert np.allclose(tab.d_eps_rve, tab.eps_rve_relaxed - tab.eps_rve_affine)
    # the coupled_rve form = the affine model (no kappa_extra) + the restructuring strain
    seed = C.ModelSpec("magnetostriction")
    aff = C.predict(seed.plus("dipolar_interaction"), exp, {"kappa_extra": 0.0})
    cpl = C.predict(seed.plus(ME, "coupled_rve"), exp, {})
    assert np.allclose(cpl - aff, C.restructuring_strain(exp), rtol=1e-12, atol=1e-15)
    # provenance of the tabulated extension
    p = tab.provenance
    assert p["evaluator"].startswith("relax-1-fem-") and p["realizations"] >= 2
    assert p["study_toml"].endswith("homogenize/experiments/data/relax_diguet2010.toml")
    assert p["table"].endswith("homogenize/experiments/data/relax_diguet2010.h5")


@needs_table
def test_diguet_diagnosis_reports_the_coupled_rve_prediction():
    res = diagnose(_diguet_at_table_modulus()).as_dict()
    ms = res["microstructure_evolution"]
    assert ms["available"]
    assert ms["at"]["B_T"] == pytest.approx(1.129, abs=1e-3) and ms["at"]["branch"] == "up"
    assert ms["measured"] == pytest.approx(0.0593, abs=1e-4)
    lo, hi = ms["predicted_coupled_rve_ci95"]
    assert lo <= ms["predicted_coupled_rve"] <= hi
    # the arithmetic of the account
    assert ms["fraction_explained"] == pytest.approx(ms["predicted_coupled_rve"] / ms["measured"])
    assert ms["unexplained"] == pytest.approx(ms["measured"] - ms["predicted_coupled_rve"])
    assert ms["restructuring_strain"] == pytest.approx(ms["predicted_coupled_rve"]
                                                       - ms["predicted_affine"])
    cv = ms["cv_rmse"]
    assert ms["gain_coupled_rve_over_seed"] == pytest.approx(
        cv["seed"] / cv["coupled_rve_no_fitted_stress"])
    # the model with a fitted kappa_extra on top is at least as good held out as the affine one
    # would be with it (kappa_extra absorbs whatever the coupled RVE leaves)
    assert ms["kappa_extra_fitted_with_coupled_rve"] is not None
    assert ms["accepted"] == (ME in res["causes"])
