"""Issue 37: the default cell solver ``solver="auto"`` (which solver it picks and why, recorded in
the result) and warm starts of the cell solves (``initial_guess``, the Krylov drivers' ``x0``).
Small grids (<= 16^3): a few seconds in all."""
from dataclasses import replace

import numpy as np
import pytest

from micro import InputError, Monodisperse, generate_rve
from homogenize.cell.problem import (AUTO_MAX_PHI, AUTO_MAX_PHI_PATCHED, SOLVERS, CellConfig,
                                     _choose_solver, homogenize_mesh, homogenize_rve, use_patches)
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
    # many particles without patches: a patch on every particle; with patches (plain 0) or
    # at most AUTO_MAX_PLAIN_PARTICLES: the plain rule
    solver, why = _choose_solver("auto", 16, 7, reason=True, phi=0.05, plain_particles=150)
    assert solver == "matrix-free" and "150 particles > 100 without patches" in why
    assert _choose_solver("auto", 16, 7, phi=0.05, plain_particles=100) == "matrix-free"
    # before the mesh exists (the command line's memory check): resolved later, on the mesh
    assert _choose_solver("auto", 16, 7) == "auto"
    assert _choose_solver("auto", 15, 7) == "fast"
    for s in ("fast", "reference", "matrix-free"):
        assert _choose_solver(s, 16, 7, reason=True) == (s, "requested")
    with pytest.raises(InputError, match="solver must be one of"):
        _choose_solver("fastest", 16, 7)


def test_choose_solver_rule_beyond_the_plain_range_and_for_rigid_particles():
    """Beyond the plain matrix-free range (phi > AUTO_MAX_PHI or many particles without patches)
    and for rigid particles: matrix-free with a patch on every particle up to
    AUTO_MAX_PHI_PATCHED, "fast" above it, on odd grids and for rigid particles without one."""
    assert AUTO_MAX_PHI < 0.1 < AUTO_MAX_PHI_PATCHED < 0.2
    for kw in (dict(phi=0.1, rigid=True), dict(phi=0.03, rigid=True), dict(phi=0.1),
               dict(phi=0.05, plain_particles=150)):
        solver, why = _choose_solver("auto", 16, 7, reason=True, **kw)
        assert solver == "matrix-free" and "patch on every particle" in why, kw
    # dilute Fe particles: the plain rule (patches only where use_patches says)
    solver, why = _choose_solver("auto", 16, 7, reason=True, phi=0.03)
    assert solver == "matrix-free" and "patch on every particle" not in why
    for kw in (dict(phi=0.2, rigid=True), dict(phi=0.2)):
        solver, why = _choose_solver("auto", 16, 7, reason=True, **kw)
        assert solver == "fast" and "volume fraction" in why, kw
    assert _choose_solver("auto", 15, 7, phi=0.1, rigid=True) == "fast"
    assert _choose_solver("fast", 16, 7, phi=0.1, rigid=True) == "fast"
    solver, why = _choose_solver("auto", 16, 7, reason=True, phi=0.1, rigid=True,
                                 plain_particles=2)
    assert solver == "fast" and "without a particle patch" in why
    # patches on every particle, however few and large; none when switched off
    assert use_patches(3, [4.0] * 3, every_particle=True) and not use_patches(3, [4.0] * 3)
    from homogenize.solvers import SolverOptions
    assert not use_patches(3, [4.0] * 3, SolverOptions().replace(patch_shell_voxels=None),
                           every_particle=True)


@pytest.mark.parametrize("rigid", [True, False])
def test_auto_beyond_the_plain_range_patches_every_particle_and_agrees_with_fast(rigid):
    """phi 0.1 (above AUTO_MAX_PHI), rigid or Fe particles: "auto" runs the matrix-free solver
    with a patch on each of the 6 particles and gives the C_eff and magnetic stress of "fast"
    to the solver tolerance."""
    rve = generate_rve(0.1, 6, 5, distribution=Monodisperse(25e-9))
    mesh = voxelize(rve, 16)
    F = _forces(rve.n)
    auto = homogenize_mesh(mesh, forces_N=F, rigid=rigid)
    fast = homogenize_mesh(mesh, forces_N=F, rigid=rigid, solver="fast")
    assert auto.phi_voxel > AUTO_MAX_PHI
    assert auto.settings["solver"] == "matrix-free" and auto.settings["patched_particles"] == 6
    assert "patch on every particle" in auto.settings["solver_reason"]
    rel = 2e-5 if rigid else 1e-6
    assert np.abs(auto.C_eff_Pa - fast.C_eff_Pa).max() < rel * np.abs(fast.C_eff_Pa).max()
    sa, sf = np.asarray(auto.stress_mag_Pa), np.asarray(fast.stress_mag_Pa)
    assert np.abs(sa - sf).max() < rel * np.abs(sf).max()
    # the same solver asked for by name keeps the plain patch rule (none for 6 large particles)
    # unless the particles are rigid
    mf = homogenize_mesh(mesh, rigid=rigid, solver="matrix-free", cases=("e11",))
    assert mf.settings["patched_particles"] == (6 if rigid else 0)


def test_rigid_particles_too_large_for_a_patch_go_to_fast():
    """Rigid particles whose patches exceed MAX_NODES or the factors' memory share (radius
    ~5.5 voxels at 24^3): "fast", with the reason."""
    big = generate_rve(0.1, 2, 5, distribution=Monodisperse(25e-9))
    r = homogenize_mesh(voxelize(big, 24), forces_N=_forces(2), rigid=True, cases=("e11",))
    assert r.settings["solver"] == "fast" and "without a particle patch" in r.settings["solver_reason"]


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
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("1 against several threads: numba has only one thread here")
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = homogenize_mesh(moved, forces_N=F, rigid=True, initial_guess=a.solution)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = homogenize_mesh(moved, forces_N=F, rigid=True, initial_guess=a.solution)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(one.C_eff_Pa, many.C_eff_Pa)
    np.testing.assert_array_equal(one.stress_mag_Pa, many.stress_mag_Pa)
