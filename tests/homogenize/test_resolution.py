"""The discretization error of the cell FEM's table quantities (homogenize.tables.resolution): the
two-grid estimate is exact for an exactly first-order error, the floor holds where the grids
agree, the tables carry it next to the statistical interval and the interpolation and the
macro consumers propagate it."""
import json
import math

import numpy as np
import pytest

from homogenize.tables import resolution as res
from homogenize.tables._evaluate import SYNTHETIC_DISC_REL, synthetic_truth
from homogenize.tables._study import parse_study
from homogenize.tables.batch import interpolate, modulus_from_table, read_table, run_batch
from micro.common.validate import InputError


@pytest.mark.parametrize("n, nc", [(6, 4), (8, 6), (12, 8), (16, 10), (24, 16), (32, 22),
                                   (48, 32), (5, 4), (17, 12)])
def test_coarse_grid_is_even_near_two_thirds_and_coarser(n, nc):
    assert res.coarse_voxels(n) == nc
    assert nc % 2 == 0 and 4 <= nc < n


def test_coarse_grid_needs_six_voxels():
    with pytest.raises(ValueError):
        res.coarse_voxels(4)


def test_two_grid_estimate_is_exact_for_a_first_order_error():
    """Q(n) = Q_inf + a / n + noise shared by both grids: the estimate is |a| / n, and the
    signed bias a / n (the noise cancels in the paired differences)."""
    rng = np.random.default_rng(3)
    q_inf, a, n, nc = 2.0e6, 4.0e6, 24, 16
    noise = 3e4 * rng.standard_normal(7)
    fine, coarse = q_inf + a / n + noise, q_inf + a / nc + noise
    e = res.discretization_error(fine, coarse, n, nc, 0.95, matrix_value=1.9e6)
    assert math.isclose(float(e["bias"]), a / n, rel_tol=1e-9)      # Q(n) - Q_inf
    assert math.isclose(float(e["two_grid"]), a / n, rel_tol=1e-9)
    assert float(e["err"]) == float(e["two_grid"])                  # above the floor here
    # the true error of the fine mean is a / n: the combined interval covers Q_inf
    lo, hi = res.combined_interval(fine.mean() - 1.0, fine.mean() + 1.0, e["err"])
    assert lo <= q_inf <= hi
    assert not fine.mean() - 1.0 <= q_inf           # the statistical interval alone does not


def test_bias_sign_follows_the_convergence_direction():
    """Rising with resolution (the under-resolved composite voxels) gives a negative bias: the
    fine value lies below the limit (Richardson: Q_inf = Q(n) + (Q(n) - Q(n_c)) / (r - 1))."""
    fine = np.array([1.90e6, 1.91e6, 1.92e6])
    coarse = fine - 0.05e6
    e = res.discretization_error(fine, coarse, 16, 10, 0.95, matrix_value=1.0e6)
    assert math.isclose(float(e["bias"]), -0.05e6 / 0.6, rel_tol=1e-9)


def test_uncertainty_of_the_paired_differences_is_included():
    rng = np.random.default_rng(5)
    fine = 2e6 + 1e4 * rng.standard_normal(4)
    coarse = fine - 1e3 * rng.standard_normal(4)            # differences with zero mean
    e = res.discretization_error(fine, coarse, 18, 12, 0.95)
    d = fine - coarse
    from scipy import stats
    want = (abs(d.mean()) + stats.t.ppf(0.975, 3) * d.std(ddof=1) / 2.0) / 0.5
    assert math.isclose(float(e["two_grid"]), want, rel_tol=1e-12)


def test_floor_when_the_grids_agree():
    """On the hump of the composite voxels the two grids can agree while the bias stays: the
    estimate never drops below 2.2 % of the filler's contribution."""
    fine = np.array([2.5e6, 2.5e6, 2.5e6])
    e = res.discretization_error(fine, fine.copy(), 24, 16, 0.95, matrix_value=2.0e6)
    assert float(e["two_grid"]) == 0.0
    assert math.isclose(float(e["err"]), res.FILLER_BIAS_REL * 0.5e6, rel_tol=1e-12)


def test_tensor_quantities_componentwise():
    fine = np.zeros((3, 3, 3))
    fine[:, 2, 2] = [100.0, 110.0, 120.0]
    coarse = fine.copy()
    coarse[:, 2, 2] -= 30.0
    e = res.discretization_error(fine, coarse, 12, 8, 0.95)
    assert e["err"].shape == (3, 3)
    assert math.isclose(e["err"][2, 2], 30.0 / 0.5, rel_tol=1e-9)
    assert e["err"][0, 0] == 0.0


def test_resolution_warning_threshold():
    box, r = 1e-5, 1e-6
    assert res.voxels_per_radius(r, box, 30) == pytest.approx(3.0)
    assert res.resolution_warning(r, box, 30) is None
    w = res.resolution_warning(r, box, 12, "phi = 0.05")
    assert w.startswith("warning: phi = 0.05: the mean particle radius is 1.2 voxels")
    assert "voxels >= 30" in w
    assert res.voxels_needed(r, box) == 30


STUDY = """
[study]
name = "disc"
seed = 31
realizations = 6
n_particles = 100
evaluator = "synthetic"
fem = true
voxels = 24
coarse_voxels = 16
[grid]
phi = [0.0175, 0.035]
B_T = [0.05, 0.3]
gradB_T_per_m = 1.78
"""


@pytest.fixture(scope="module")
def table(inprocess_client, tmp_path_factory):
    study = parse_study(STUDY, "disc.toml")
    out = tmp_path_factory.mktemp("disc") / "t.h5"
    with inprocess_client(1) as cl:
        run_batch(study, out, client=cl, progress=False)
    return study, out


def test_table_carries_the_discretization_error(table):
    """The synthetic FEM quantities carry exactly 0.3 truth / voxels: the table's estimate is
    that (the floor is smaller here), and the widened interval covers the truth."""
    study, out = table
    t = read_table(out)
    assert set(t.disc_err) == {"E_eff_Pa", "nu_eff", "stress_mag_Pa", "strain_mag"}
    attrs = json.loads(t.attrs["discretization"])
    assert attrs["voxels"] == 24 and attrs["coarse_voxels"] == 16 and attrs["order"] == 1.0
    for g, point in enumerate(study.points()):
        truth = synthetic_truth(point, study.settings())["E_eff_Pa"][0]
        want = SYNTHETIC_DISC_REL * float(truth) / 24
        assert math.isclose(float(t.disc_err["E_eff_Pa"][g]), want, rel_tol=1e-6)
    import xarray as xr
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        lo = ds["E_eff_Pa_total_low"].values.ravel()
        hi = ds["E_eff_Pa_total_high"].values.ravel()
        assert np.allclose(ds["E_eff_Pa_ci_low"].values.ravel() - lo,
                           ds["E_eff_Pa_disc_err"].values.ravel())
        assert ds["E_eff_Pa_disc_err"].attrs["units"] == "Pa"
    truths = [float(synthetic_truth(p, study.settings())["E_eff_Pa"][0])
              for p in study.points()]
    assert all(a <= x <= b for a, x, b in zip(lo, truths, hi))


def test_interpolation_and_modulus_carry_it(table):
    study, out = table
    t = read_table(out)
    e0 = interpolate(t, "E_eff_Pa", phi=0.0175, B_T=0.05)
    assert e0.has_disc and math.isclose(e0.disc_err, float(t.disc_err["E_eff_Pa"][0]))
    mid = interpolate(t, "E_eff_Pa", phi=0.0175, B_T=0.175)
    assert math.isclose(mid.disc_err, 0.5 * (t.disc_err["E_eff_Pa"][0]
                                             + t.disc_err["E_eff_Pa"][1]), rel_tol=1e-12)
    assert mid.total_low == mid.ci_low - mid.disc_err
    E = modulus_from_table(t, 0.035)
    assert math.isclose(E.disc_err, float(t.disc_err["E_eff_Pa"][2:].mean()), rel_tol=1e-12)
    assert E.total_rel_half_width > E.rel_half_width
    assert "discretization +-" in E.describe()
    f = interpolate(t, "f_eff_N_m3", phi=0.035, B_T=0.3)
    assert not f.has_disc and f.disc_err == 0.0 and "discretization" not in f.describe()


def test_study_defaults_and_bad_coarse_grids():
    rve = ('[study]\nseed = 1\nrealizations = 2\nn_particles = 8\nfem = true\nvoxels = 16\n'
           '[grid]\nphi = 0.05\nB_T = 0.1\ngradB_T_per_m = 1.0\n')
    assert parse_study(rve, "s.toml").coarse_voxels == 10
    assert parse_study(rve.replace("voxels = 16", "voxels = 16\ncoarse_voxels = 0"),
                       "s.toml").coarse_voxels == 0
    assert parse_study(rve.replace("fem = true", "fem = false"), "s.toml").coarse_voxels == 0
    for bad, words in (("coarse_voxels = 16", "[4, voxels - 1] = [4, 15]"),
                       ("coarse_voxels = 3", "[4, voxels - 1]")):
        with pytest.raises(InputError, match=r"coarse_voxels") as exc:
            parse_study(rve.replace("voxels = 16", f"voxels = 16\n{bad}"), "s.toml")
        assert words in str(exc.value)
    with pytest.raises(InputError, match="fem = false"):
        parse_study(rve.replace("fem = true", "fem = false\ncoarse_voxels = 8"), "s.toml")


def test_homogenize_warns_when_particles_are_under_resolved(tmp_path, capsys):
    """`mapsim homogenize` names the resolution of the mean radius and warns below 3 voxels
    per radius (and only there)."""
    from homogenize.cli import main
    from micro.particles import Monodisperse, generate_rve
    rve = generate_rve(0.05, 4, 7, distribution=Monodisperse(25e-9), gap_m=5e-9)
    rve.save(tmp_path / "rve.h5")
    vpr8 = res.voxels_per_radius(25e-9, rve.box_m, 8)
    n_ok = res.voxels_needed(25e-9, rve.box_m)
    assert vpr8 < res.MIN_VOXELS_PER_RADIUS <= res.voxels_per_radius(25e-9, rve.box_m, n_ok)
    for n, warned in ((8, True), (n_ok, False)):
        out = tmp_path / f"c{n}.json"
        assert main(["homogenize", str(tmp_path / "rve.h5"), "--voxels", str(n), "--json",
                     str(out), "--quiet"]) == 0
        err = capsys.readouterr().err
        assert ("warning:" in err and f"use voxels >= {n_ok}" in err) is warned
        assert json.loads(out.read_text())["voxels_per_radius"] == pytest.approx(
            res.voxels_per_radius(25e-9, rve.box_m, n))


def test_batch_warns_per_grid_population_below_three_voxels_per_radius():
    """The box of N particles of mean volume <V> at phi is (N <V> / phi)^(1/3): at 12 voxels
    the tutorial's 8 particles at phi 0.05 get 1.2 voxels per radius (a warning per phi that
    falls short), at 24 only phi 0.05 (2.5; phi 0.4: 4.9 voxels per radius)."""
    from homogenize.tables._evaluate import resolution_warnings
    text = ('[study]\nseed = 1\nrealizations = 2\nn_particles = 8\nfem = true\nvoxels = 12\n'
            'particle_material = "carbonyl-iron"\n'
            '[grid]\nphi = [0.05, 0.4]\nB_T = 0.1\ngradB_T_per_m = 1.0\n')
    ws = resolution_warnings(parse_study(text, "s.toml"))
    assert len(ws) == 2 and "phi = 0.05: the mean particle radius is 1.2 voxels" in ws[0]
    ws = resolution_warnings(parse_study(text.replace("voxels = 12", "voxels = 24"), "s.toml"))
    assert len(ws) == 1 and ws[0].startswith("warning: phi = 0.05: the mean particle radius "
                                             "is 2.5 voxels")
    relax = text.replace("n_particles = 8", 'n_particles = 8\nevaluator = "relax"').replace(
        "gradB_T_per_m = 1.0\n", "")
    assert len(resolution_warnings(parse_study(relax, "r.toml"))) == 2


def test_a_prefix_names_the_quantity_not_its_coarse_companion(table):
    _, out = table
    t = read_table(out)
    assert "E_eff_Pa_coarse" in t.values
    assert t.resolve_quantity("E_eff") == "E_eff_Pa"
    assert t.resolve_quantity("E_eff_Pa_coarse") == "E_eff_Pa_coarse"
