"""The magnetostriction experiment predicted as measured (a change of length), three models."""
from pathlib import Path

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from homogenize.experiments import load_experiment
from homogenize.experiments.specimen_account import (composite_law, loo_fitted_kappa,
                                                     relaxed_kappa, specimen_account)
from homogenize.experiments.rve_tables import Restructuring, affine_kappa
from micro.common.validate import InputError

ROOT = Path(__file__).resolve().parents[3]
DIGUET = ROOT / "examples" / "data" / "diguet2010_magnetostriction.toml"


def test_loo_fitted_kappa_matches_refitting_without_each_row():
    rng = np.random.default_rng(3)
    x = rng.uniform(0.1, 1.0, 9)
    pred = rng.normal(0, 0.01, 9)
    y = pred + 0.3 * x + rng.normal(0, 0.02, 9)
    k, se, rmse, loo = loo_fitted_kappa(pred, y, x)
    # the closed form against the least squares it stands for
    assert k == pytest.approx(np.linalg.lstsq(x[:, None], y - pred, rcond=None)[0][0], rel=1e-12)
    held = []
    for i in range(9):
        m = np.arange(9) != i
        ki = np.sum(x[m] * (y[m] - pred[m])) / np.sum(x[m] ** 2)
        held.append(y[i] - pred[i] - ki * x[i])
    # the hat-matrix identity is exact for linear least squares: round-off only
    assert loo == pytest.approx(np.sqrt(np.mean(np.square(held))), rel=1e-10)
    assert rmse < loo and se > 0
    with pytest.raises(InputError):
        loo_fitted_kappa([0.0], [1.0], [0.0])


def _restructuring(d_eps, M, E):
    K, R = d_eps.shape
    x = MU0 * M ** 2 / E
    z = np.zeros((K, R))
    return Restructuring(path="synthetic", phi=0.26, E_Pa=1e5, B_T=np.linspace(0, 1, K),
                         d_eps_rve=d_eps, d_x=z, eps_rve_relaxed=d_eps, eps_rve_affine=z,
                         x_relaxed=x, x_affine=x, provenance={}, M_relaxed_A_per_m=M,
                         E_parallel_Pa=E)


def test_relaxed_kappa_is_affine_without_restructuring_and_shifts_by_the_free_strain():
    phi, Ms = 0.26, 1.7e6
    M = np.array([[0.0, 0.0], [2e5, 2.2e5], [4e5, 4.2e5]])
    E = np.full_like(M, 3e5)
    base = affine_kappa(phi, Ms)
    same = relaxed_kappa(phi, Ms, _restructuring(np.zeros_like(M), M, E))
    Mq = np.linspace(0, 5e5, 7)
    assert np.array_equal(same(Mq), base(Mq))
    # a free strain d_eps at (M, E) is the coefficient change -d_eps E / (mu0 M^2): an
    # eigenstress kappa mu0 M^2 (mm - I/3) strains a free incompressible body by -kappa x
    d_eps = np.array([[0.0, 0.0], [0.01, 0.01], [0.02, 0.02]])
    k = relaxed_kappa(phi, Ms, _restructuring(d_eps, M, E))
    Mn = M.mean(axis=1)
    expect = -(d_eps[1:] / (MU0 * M[1:] ** 2 / E[1:])).mean(axis=1)
    assert k(Mn[1:]) - base(Mn[1:]) == pytest.approx(expect, rel=1e-12)
    assert k(np.array([0.0]))[0] == pytest.approx(base(np.array([0.0]))[0], abs=0)


def test_composite_law_is_the_dipole_rve_and_linear_at_small_field():
    exp = load_experiment(DIGUET)
    law, H, M = composite_law(0.261, exp.particles, B_max_T=1.0, seeds=(1,), n=30, n_nodes=6)
    assert M.shape == (1, 6) and np.all(np.diff(law.M_nodes_A_per_m) >= 0)
    chi = M[0, 0] / H[0]
    # random soft spheres at phi = 0.26: Maxwell-Garnett 3 phi / (1 - phi) = 1.06 is the
    # mean-field value; one RVE of 30 particles lies within ~20 % of it
    assert 0.8 < chi < 1.4
    # saturation bound: never above phi Ms of the particles
    assert law.M_nodes_A_per_m[-1] <= 0.261 * exp.particles.Ms_A_per_m * (1 + 1e-9)


@pytest.fixture(scope="module")
def account():
    exp = load_experiment(DIGUET)
    rng = np.random.default_rng(0)
    final = exp.y + rng.normal(0, 0.003, exp.n_rows)
    return exp, specimen_account(exp, final_cv_pred=final, mesh="coarse", seeds=(1,),
                                 n_particles=30)


def test_diguet_account_predicts_the_change_of_length_of_each_model(account):
    exp, acc = account
    assert acc["available"] and len(acc["groups"]) == 1
    g = acc["groups"][0]
    assert g["aspect_ratio_L_over_D"] == 0.8 and g["matrix_E_Pa"] == 140e3
    assert g["composite_E_Pa"] == pytest.approx(140e3 * g["filler_stiffness_ratio"])
    for m in ("continuum", "affine"):
        r = acc["models"][m]
        assert r["available"]
        at = np.flatnonzero(np.isclose(exp.columns["B_T"], r["at"]["B_T"]) & ~exp.down)
        assert at.size == 1 and r["measured"] == exp.y[at[0]]
        # the largest field the model reached on the rising branch
        reached = max(acc["groups"][0]["models"][m]["B_applied_T"])
        assert r["at"]["B_T"] == pytest.approx(reached)
        assert r["fraction_explained"] == pytest.approx(r["predicted_end_mean"] / r["measured"])
        lo, hi = r["predicted_end_mean_ci95_modulus_linearized"]
        assert lo <= r["predicted_end_mean"] <= hi
        f = r["fitted"]
        assert f["heldout_rmse"] >= f["rmse"] > 0
        assert r["heldout_gain_with_fitted_kappa"] > 0
    # the continuum body elongates (Kelvin tractions pull the end faces); the affine model's
    # microstructural stress contracts it: less elongation than the continuum at every field
    c, a = (acc["groups"][0]["models"][m] for m in ("continuum", "affine"))
    n = min(len(c["strain_end_mean"]), len(a["strain_end_mean"]))
    assert n >= 3
    assert np.all(np.asarray(c["strain_end_mean"][:n]) > 0)
    assert np.all(np.asarray(a["strain_end_mean"][:n]) < np.asarray(c["strain_end_mean"][:n]))
    # small field: strain ~ B^2 (linear law, small strain): the ratio of the first two steps
    B = np.asarray(c["B_applied_T"][:2])
    e = np.asarray(c["strain_end_mean"][:2])
    # susceptibility and geometry change a little between 0.14 and 0.28 T: within 25 %
    assert e[1] / e[0] == pytest.approx((B[1] / B[0]) ** 2, rel=0.25)


def test_specimen_account_refuses_other_kinds_and_meshes(account):
    exp, _ = account
    with pytest.raises(InputError, match="mesh"):
        specimen_account(exp, mesh="fine")
    tensile = load_experiment(ROOT / "examples" / "data" / "rtv615_tensile.toml")
    assert specimen_account(tensile)["available"] is False
