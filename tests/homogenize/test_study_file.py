"""Study files: parsing, validation messages, grid expansion, per-realization seeds."""
import numpy as np
import pytest

from homogenize.tables._study import AXIS_ORDER, load_study, parse_study
from micro.common.validate import InputError

GOOD = """
[study]
name = "t"
seed = 11
realizations = 3
n_particles = 50
evaluator = "synthetic"

[grid]
B_T = [0.01, 0.1, 0.5]
arrangement = ["dispersed", "clusters"]
phi = [0.0175, 0.035]
gradB_T_per_m = 1.78
"""


def test_grid_expansion_canonical_order_and_size():
    s = parse_study(GOOD, "good.toml")
    # axes sorted into the canonical order whatever the order in the file
    assert s.axis_names == ("phi", "arrangement", "B_T", "gradB_T_per_m")
    assert [AXIS_ORDER.index(a) for a in s.axis_names] == sorted(
        AXIS_ORDER.index(a) for a in s.axis_names)
    assert s.grid_shape == (2, 2, 3, 1)
    pts = s.points()
    assert len(pts) == s.n_points == 12
    # C order: the last axis with several values varies fastest
    assert [p["B_T"] for p in pts[:3]] == [0.01, 0.1, 0.5]
    assert pts[3]["arrangement"] == "clusters" and pts[6]["phi"] == 0.035
    assert len({tuple(p.values()) for p in pts}) == 12
    tasks = s.tasks()
    assert len(tasks) == 36
    assert [(t.grid_index, t.realization) for t in tasks[:4]] == [(0, 0), (0, 1), (0, 2), (1, 0)]


def test_order_of_keys_in_file_does_not_change_points_or_seeds():
    swapped = GOOD.replace('B_T = [0.01, 0.1, 0.5]\narrangement = ["dispersed", "clusters"]',
                           'arrangement = ["dispersed", "clusters"]\nB_T = [0.01, 0.1, 0.5]')
    assert swapped != GOOD
    a, b = parse_study(GOOD), parse_study(swapped)
    assert a.points() == b.points()
    assert [t.seed_int() for t in a.tasks()] == [t.seed_int() for t in b.tasks()]


def test_seeds_follow_seedsequence_spawn_key_and_are_distinct():
    s = parse_study(GOOD)
    t = s.tasks()[7]
    ref = np.random.SeedSequence(11, spawn_key=(t.grid_index, t.realization))
    assert np.array_equal(t.seed_sequence().generate_state(4), ref.generate_state(4))
    seeds = [t.seed_int() for t in s.tasks()]
    assert len(set(seeds)) == len(seeds)
    assert all(0 <= x < 2 ** 63 for x in seeds)
    # a different study seed gives different streams
    other = parse_study(GOOD.replace("seed = 11", "seed = 12"))
    assert not set(seeds) & {t.seed_int() for t in other.tasks()}


def test_task_key_changes_with_anything_that_changes_the_result():
    s = parse_study(GOOD)
    k = s.tasks()[0].key("e1")
    assert k == parse_study(GOOD).tasks()[0].key("e1")
    assert k != s.tasks()[0].key("e2")
    assert k != parse_study(GOOD.replace("n_particles = 50", "n_particles = 51")).tasks()[0].key("e1")
    assert k != parse_study(GOOD.replace("seed = 11", "seed = 3")).tasks()[0].key("e1")
    assert k != s.tasks()[1].key("e1")


def test_scalar_axis_and_defaults(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[study]\nseed = 0\nrealizations = 2\nevaluator = "synthetic"\n'
                 '[grid]\nB_T = 0.1\n')
    s = load_study(p)
    assert s.axes == (("B_T", (0.1,)),)
    assert s.n_points == 1 and s.confidence == 0.95 and s.fem is False
    assert s.name == "s" and s.text == p.read_text()


@pytest.mark.parametrize("text, words", [
    (GOOD.replace("n_particles = 50", "n_partcles = 50"), ["[study]", "n_partcles"]),
    (GOOD + "\n[rve_sise]\nx = 1\n", ["rve_sise"]),
    (GOOD.replace("gradB_T_per_m = 1.78", "gradB_T_per_m = 1.78\nphii = 0.1"),
     ["[grid]", "phii"]),
    (GOOD.replace("realizations = 3", "realizations = -3"), ["realizations", "-3"]),
    (GOOD.replace("n_particles = 50", "n_particles = -5"), ["n_particles", "-5"]),
    (GOOD.replace("seed = 11", "seed = -1"), ["seed", "-1"]),
    (GOOD.replace("realizations = 3", "realizations = 1"), ["realizations", ">= 2"]),
    (GOOD.replace("B_T = [0.01, 0.1, 0.5]", "B_T = []"), ["[grid] B_T", "empty"]),
    (GOOD.replace("B_T = [0.01, 0.1, 0.5]", "B_T = [-0.1]"), ["B_T", ">= 0 T"]),
    (GOOD.replace("phi = [0.0175, 0.035]", "phi = [1.5]"), ["phi", "(0, 0.6]"]),
    (GOOD.replace("phi = [0.0175, 0.035]", 'phi = ["a"]'), ["phi", "numbers"]),
    (GOOD.replace("B_T = [0.01, 0.1, 0.5]", "B_T = [0.1, 0.1]"), ["B_T", "repeated"]),
    (GOOD.replace("realizations = 3", 'realizations = "3"'), ["realizations", "integer"]),
    ('[study]\nseed = 1\nrealizations = 2\nevaluator = "synthetic"\n[grid]\n', ["[grid]", "empty"]),
    ('[study]\nseed = 1\nrealizations = 2\nevaluator = "synthetic"\n', ["[grid]"]),
    ('[grid]\nB_T = 0.1\n', ["[study]"]),
    (GOOD.replace('evaluator = "synthetic"', 'evaluator = "magic"'), ["evaluator", "magic"]),
    (GOOD.replace('"clusters"', '"stacked"'), ["arrangement", "stacked"]),
    ("[study\nseed = 1", ["not valid TOML"]),
    (GOOD + "\n[rve_size]\nn_particles = [10]\n", ["[rve_size]", "three sizes"]),
    (GOOD + "\n[rve_size]\nn_particles = [10, -20]\n", ["[rve_size]", "-20"]),
    (GOOD + "\n[rve_size]\nn_particles = [10, 20]\nfoo = 1\n", ["[rve_size]", "foo"]),
    (GOOD + "\n[synthetic]\nwork_seconds = -1\n", ["[synthetic] work_seconds", "-1"]),
    (GOOD + "\n[synthetic]\nsleep = 1\n", ["[synthetic]", "sleep"]),
    (GOOD.replace('evaluator = "synthetic"', 'evaluator = "rve"') + "\n[synthetic]\n"
     "work_seconds = 1\n", ["[synthetic]", "rve"]),
])
def test_bad_study_gives_one_clear_message(text, words):
    with pytest.raises(InputError) as exc:
        parse_study(text, "bad.toml")
    msg = str(exc.value)
    assert msg.startswith("bad.toml"), msg        # names the file
    assert "\n" not in msg                        # one line
    for w in words:
        assert w in msg, (w, msg)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_study(tmp_path / "nope.toml")


def test_rve_size_table():
    s = parse_study(GOOD + "\n[rve_size]\nn_particles = [200, 50, 100]\nrealizations = 5\n"
                           "target_rel_precision = 0.05\n")
    assert s.rve_size.n_particles == (50, 100, 200)
    assert s.rve_size.realizations == 5 and s.rve_size.quantity == "f_eff_N_m3"
    assert s.rve_size.target_rel_precision == 0.05


# --------------------------------------------------------------------------- presets (issue 36)
_RVE = """
[study]
seed = 1
realizations = 2
n_particles = 20
{extra}
[grid]
phi = 0.05
B_T = [0.1, 0.2]
gradB_T_per_m = 1.78
{grid}
"""


def _rve_study(extra="", grid=""):
    return parse_study(_RVE.format(extra=extra, grid=grid), "p.toml")


def test_material_presets_fill_the_keys_not_given():
    s = _rve_study('particle_material = "carbonyl-iron"\nmatrix_material = "sylgard184-10to1"\n'
                   'fem = true\nvoxels = 8\n[rve]\ncore_sigma_Am2_kg = 200.0')
    assert s.rve == {"core_sigma_Am2_kg": 200.0, "mean_radius_m": 1e-6, "gsd": 1.5,
                     "shell_thickness_m": 0.0, "core_density_kg_m3": 7800.0}   # explicit wins
    assert s.magnetics == {"rho_kg_m3": 7800.0, "sigma_s_Am2_kg": 210.0}
    assert s.cell == {"particle_E_Pa": 211e9, "particle_nu": 0.29, "matrix_E_Pa": 2e6,
                      "matrix_nu": 0.49}
    # a grid axis is not overwritten; magnetite sets the regime law's core material
    s = _rve_study('particle_material = "magnetite"', "mean_radius_m = [20e-9, 40e-9]")
    assert "mean_radius_m" not in s.rve and s.law == {"material": "Fe3O4"}
    # the relax evaluator takes the matrix in [relax]
    s = parse_study(_RVE.format(extra='evaluator = "relax"\nmatrix_material = "ecoflex-00-30"',
                                grid="").replace("gradB_T_per_m = 1.78", ""), "r.toml")
    assert s.relax == {"matrix_E_Pa": 0.118e6, "matrix_nu": 0.49}


def test_seed_paper_preset_changes_nothing():
    a = _rve_study()
    b = _rve_study('particle_material = "seed-paper"\nmatrix_material = "seed-paper"')
    assert a.settings() == b.settings()
    assert [t.key("x") for t in a.tasks()] == [t.key("x") for t in b.tasks()]


def test_bounds_follow_a_micron_mean_radius_in_a_study():
    from homogenize.tables._evaluate import _rve_kwargs
    s = _rve_study(grid="mean_radius_m = 1e-6")         # failed before: bounds [10, 50] nm
    d = _rve_kwargs({**s.rve, "mean_radius_m": 1e-6})["distribution"]
    assert (d.r_min_m, d.r_max_m) == pytest.approx((0.4e-6, 2e-6), rel=1e-15)
    d = _rve_kwargs({})["distribution"]
    assert (d.r_min_m, d.r_max_m) == (10e-9, 50e-9)     # the seed's, bit for bit


@pytest.mark.parametrize("extra, words", [
    ('particle_material = "unobtainium"', ["particle_material", "carbonyl-iron"]),
    ('matrix_material = "jelly"', ["matrix_material", "sylgard184-10to1"]),
    ('matrix_material = "rtv615"', ["matrix_material", "fem = true"]),
    ('particle_material = 3', ["particle_material", "string"]),
])
def test_bad_material_presets_are_refused(extra, words):
    with pytest.raises(InputError) as e:
        _rve_study(extra)
    for w in words:
        assert w in str(e.value)
    with pytest.raises(InputError, match="synthetic"):
        parse_study(GOOD.replace("[study]", '[study]\nparticle_material = "magnetite"'))
