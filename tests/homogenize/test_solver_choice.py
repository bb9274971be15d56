"""Issue 37: the default cell solver ``solver="auto"`` (which solver it picks and why, recorded in
the result) and warm starts of the cell solves (``initial_guess``, the Krylov drivers' ``x0``).
Small grids (<= 16^3): a few seconds in all."""
from dataclasses import replace

import numpy as np
import pytest

from micro import InputError, Monodisperse, generate_rve
from homogenize.cell.problem import (AUTO_MAX_PHI, SOLVERS, CellConfig, _choose_solver,
                             homogenize_mesh, homogenize_rve)
from homogenize.voxels.mesh import voxelize
from homogenize.solvers import block_cg, coupled_block_cg


@pytest.fixture(scope="module")
def rve():
    return generate_rve(0.05, 8, 3, distribution=Monodisperse(25e-9))


def _forces(n):
    return np.random.default_rng(0).normal(size=(n, 3)) * 1e-15


def test_auto_is_the_default_and_picks_matrix_free_on_even_grids(rve):
    assert SOLVERS[0] == "auto" and CellConfig().solver == "auto"
    r = homogenize_rve(rve, 16)
    assert r.settings["solver"] == "matrix-free"
    assert r.settings["solver_requested"] == "auto"
    assert r.settings["solver_reason"].startswith("auto: matrix-free")
    fast = homogenize_rve(rve, 16, solver="fast")
    assert fast.settings["solver"] == "fast" and fast.settings["solver_reason"] == "requested"
    # the same stiffness to the solver tolerance (C_eff is variational: error ~ tol^2)
    assert np.abs(r.C_eff_Pa - fast.C_eff_Pa).max() < 1e-7 * np.abs(fast.C_eff_Pa).max()


def test_auto_falls_back_to_fast_with_a_stated_reason(rve):
    odd = homogenize_rve(rve, 15)
    assert odd.settings["solver"] == "fast" and "odd" in odd.settings["solver_reason"]
    dense = generate_rve(0.3, 12, 1, distribution=Monodisperse(25e-9))
    r = homogenize_mesh(voxelize(dense, 12), cases=("e11",))
    assert r.phi_voxel > AUTO_MAX_PHI
    assert r.settings["solver"] == "fast"
    assert "volume fraction" in r.settings["solver_reason"]


def test_choose_solver_rule():
    assert _choose_solver("auto", 16, 7, phi=0.05) == "matrix-free"
    assert _choose_solver("auto", 16, 7, phi=0.3) == "fast"
    assert _choose_solver("auto", 17, 7, phi=0.05) == "fast"
    assert _choose_solver("auto", 6, 7, phi=0.05) == "fast"
    # many particles without patches: fast; with patches (plain_particles 0): matrix-free
    solver, why = _choose_solver("auto", 16, 7, reason=True, phi=0.05, plain_particles=150)
    assert solver == "fast" and "without particle patches" in why
    assert _choose_solver("auto", 16, 7, phi=0.05, plain_particles=100) == "matrix-free"
    # before the mesh exists (the command line's memory check): resolved later, on the mesh
    assert _choose_solver("auto", 16, 7) == "auto"
    assert _choose_solver("auto", 15, 7) == "fast"
    for s in ("fast", "reference", "matrix-free"):
        assert _choose_solver(s, 16, 7, reason=True) == (s, "requested")
    with pytest.raises(InputError, match="solver must be one of"):
        _choose_solver("fastest", 16, 7)


@pytest.mark.parametrize("solver", ["fast", "matrix-free", "reference"])
def test_warm_start_same_results_fewer_iterations(rve, solver):
    """From the solutions of the same mesh every strain column has converged at the start; on a
    mesh of slightly moved particles with other forces the results agree with a cold start to
    the tolerance."""
    mesh = voxelize(rve, 16)
    F = _forces(rve.n)
    kw = dict(rigid=True, solver=solver)
    a = homogenize_mesh(mesh, forces_N=F, keep_solution=True, **kw)
    assert a.solution.shape == (mesh.n_dof, 7) and a.settings["warm_start"] is False
    assert homogenize_mesh(mesh, forces_N=F, **kw).solution is None
    b = homogenize_mesh(mesh, forces_N=F, initial_guess=a.solution, **kw)
    assert b.settings["warm_start"] is True
    assert all(v == 0 for k, v in b.iterations.items())
    assert np.abs(a.C_eff_Pa - b.C_eff_Pa).max() < 1e-8 * np.abs(a.C_eff_Pa).max()
    shift = np.random.default_rng(1).normal(size=rve.centers_m.shape) * 0.03 * rve.box_m / 16
    moved = voxelize(replace(rve, centers_m=rve.centers_m + shift), 16)
    cold = homogenize_mesh(moved, forces_N=2.0 * F, **kw)
    warm = homogenize_mesh(moved, forces_N=2.0 * F, initial_guess=a.solution, **kw)
    strains = [k for k in cold.iterations if k != "magnetic"]
    assert sum(warm.iterations[k] for k in strains) < sum(cold.iterations[k] for k in strains)
    assert max(warm.residuals[k] for k in strains) <= 1e-6
    # rigid particles (contrast 1e6): both stop at residual 1e-6, C_eff within ~1e-5
    assert np.abs(cold.C_eff_Pa - warm.C_eff_Pa).max() < 3e-5 * np.abs(cold.C_eff_Pa).max()
    assert (np.abs(cold.stress_mag_Pa - warm.stress_mag_Pa).max()
            < 1e-5 * np.abs(cold.stress_mag_Pa).max())


def test_warm_start_shape_checked(rve):
    mesh = voxelize(rve, 12)
    with pytest.raises(InputError, match="initial guess"):
        homogenize_mesh(mesh, initial_guess=np.zeros((10, 6)))


@pytest.mark.parametrize("driver", [block_cg, coupled_block_cg])
def test_krylov_initial_guess(driver):
    rng = np.random.default_rng(5)
    n, k = 50, 3
    Q = rng.normal(size=(n, n))
    A = Q @ Q.T + n * np.eye(n)
    F = rng.normal(size=(n, k))
    exact = np.linalg.solve(A, F)
    kw = dict(tol=1e-10, maxiter=200)
    X, hist = driver(lambda Y: A @ Y, lambda Y: Y.copy(), F, x0=exact, **kw)
    assert all(len(h) == 1 for h in hist)             # converged at the start
    np.testing.assert_array_equal(X, exact)
    x0 = exact + 1e-3 * rng.normal(size=exact.shape)
    X, hist = driver(lambda Y: A @ Y, lambda Y: Y.copy(), F, x0=x0, **kw)
    _, cold = driver(lambda Y: A @ Y, lambda Y: Y.copy(), F, **kw)
    assert np.allclose(X, exact, rtol=0, atol=1e-8 * np.abs(exact).max())
    assert max(map(len, hist)) < max(map(len, cold))
    for c in range(k):                                # relative to ||f||, not to the start
        res0 = np.linalg.norm(F[:, c] - A @ x0[:, c]) / np.linalg.norm(F[:, c])
        assert hist[c][0] == pytest.approx(res0, rel=1e-8)
    with pytest.raises(ValueError, match="x0 must have the shape"):
        driver(lambda Y: A @ Y, lambda Y: Y.copy(), F, x0=x0[:, :2], **kw)


def test_cli_default_solver_is_auto(tmp_path):
    import json

    from homogenize.cli import main
    rve = generate_rve(0.05, 4, 7, distribution=Monodisperse(25e-9), gap_m=5e-9)
    path = tmp_path / "rve.h5"
    rve.save(path)
    out = tmp_path / "cell.json"
    assert main(["homogenize", str(path), "--voxels", "8", "--json", str(out), "--quiet"]) == 0
    s = json.loads(out.read_text())["settings"]
    assert s["solver"] == "matrix-free" and s["solver_requested"] == "auto"


def test_warm_start_independent_of_the_thread_count(rve):
    """The warm start's reductions and combinations are the chunked numba kernels: the same
    numbers on one thread and on all."""
    import numba
    mesh = voxelize(rve, 12)
    F = _forces(rve.n)
    a = homogenize_mesh(mesh, forces_N=F, rigid=True, keep_solution=True)
    shift = np.random.default_rng(2).normal(size=rve.centers_m.shape) * 0.03 * rve.box_m / 12
    moved = voxelize(replace(rve, centers_m=rve.centers_m + shift), 12)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = homogenize_mesh(moved, forces_N=F, rigid=True, initial_guess=a.solution)
    finally:
        numba.set_num_threads(threads)
    many = homogenize_mesh(moved, forces_N=F, rigid=True, initial_guess=a.solution)
    np.testing.assert_array_equal(one.C_eff_Pa, many.C_eff_Pa)
    np.testing.assert_array_equal(one.stress_mag_Pa, many.stress_mag_Pa)
