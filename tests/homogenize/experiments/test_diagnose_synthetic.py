"""diagnose on synthetic data with hidden causes: each cause recovered, none on null data,
both in combined cases -- on a fixed set of seeds."""
import numpy as np
import pytest

from homogenize.experiments.causes import CAUSES, applicable
from homogenize.experiments.diagnose import diagnose, make_folds
from homogenize.experiments.synthetic import CASES, generate

# one fixed seed per case; every cause of the vocabulary appears in CASES
SEED = 11


def test_cases_cover_the_vocabulary_nulls_and_pairs():
    hidden = {c for h, _ in CASES for c in h}
    assert hidden == set(CAUSES)
    assert sum(1 for h, _ in CASES if not h) >= 3
    assert sum(1 for h, _ in CASES if len(h) == 2) >= 4


@pytest.mark.parametrize("hidden,kind", CASES, ids=[f"{k}:{'+'.join(h) or 'null'}" for h, k in CASES])
def test_diagnose_recovers_hidden_causes(hidden, kind):
    case = generate(hidden, kind, seed=SEED)
    missing = [c for c in case.expected
               if applicable(c, case.experiment)[1].startswith("unavailable")]
    if missing:
        pytest.skip(f"physics for {missing} has not landed: {applicable(missing[0], case.experiment)[1]}")
    res = diagnose(case.experiment).as_dict()
    assert set(res["causes"]) == set(case.expected), res["steps"]
    keys = {"kind", "n_rows", "baseline", "causes", "steps", "candidates", "final", "gain"}
    if kind == "magnetostriction":     # the coupled RVE's account (microstructure_evolution)
        keys.add("microstructure_evolution")
    assert set(res) == keys
    if case.expected:
        assert res["gain"] > 1.5
        assert res["final"]["cv_rmse"] < res["baseline"]["cv_rmse"]
    else:
        assert res["gain"] == 1.0 and res["steps"] == []


def test_generator_is_seeded_and_noisy_within_1_to_3_percent():
    a = generate(("gravity",), "deflection", seed=4)
    b = generate(("gravity",), "deflection", seed=4)
    np.testing.assert_array_equal(a.experiment.y, b.experiment.y)
    c = generate(("gravity",), "deflection", seed=5)
    assert not np.array_equal(a.experiment.y, c.experiment.y)
    for s in range(20):
        assert 0.01 <= generate((), "tensile", seed=s).noise <= 0.03
    # the noise is what it says: exact truth vs noisy data, relative scatter ~ noise
    exact = generate((), "tensile", seed=6, noise=0.0).experiment.y
    noisy = generate((), "tensile", seed=6, noise=0.02).experiment.y
    rel = (noisy - exact) / (np.abs(exact) + 0.02 * np.abs(exact).max())
    assert 0.01 < rel.std() < 0.03


def test_prerequisites_of_law_dependent_causes():
    assert generate(("demagnetization",), "magnetization", seed=1).expected == \
        {"demagnetization", "field_dependent_magnetization"}
    assert generate(("dipolar_interaction",), "magnetostriction", seed=1).expected == \
        {"dipolar_interaction"}
    assert generate(("gravity",), "deflection", seed=1).expected == {"gravity"}


def test_folds_hold_out_whole_specimens():
    exp = generate(("gravity",), "deflection", seed=2).experiment
    folds = make_folds(exp)
    assert sorted(np.concatenate(folds).tolist()) == list(range(exp.n_rows))
    for test in folds:
        train = np.setdiff1d(np.arange(exp.n_rows), test)
        assert not set(exp.specimen[test]) & set(exp.specimen[train])
    single = generate((), "magnetization", seed=2).experiment.subset(np.arange(10))
    assert len(make_folds(single)) == 5
    assert make_folds(single.subset([0, 1])) is None
