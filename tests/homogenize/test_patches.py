"""Particle patches in the matrix-free V-cycle (homogenize.solvers._patches).

Patch nodes against a brute-force distance test (periodic wrap, pinned node left out); the
colouring never puts two coupled patches in one colour (brute force over the stencil
neighbourhoods); one patch solve equals the dense solve of the assembled principal submatrix;
the parallel sweep equals the serial one to round-off; many columns at once equal one column at a
time; the patched V-cycle is symmetric positive definite and cuts the CG iterations; C_eff and
the magnetic stress equal to the assembled solver's.
"""
from __future__ import annotations

import types

import numba
import numpy as np
import pytest

from homogenize.solvers import _matfree as mf
from homogenize.solvers import _patches as pt
from homogenize.cell import problem as C
from homogenize.solvers import AMGOptions, SolverOptions

from .test_matfree import _assembled, _fields, _geometry, _pin, check_spd_and_convergent


def _setup(n=12, n_part=6, seed=4, shell=0.5, pin=0):
    mesh, lam, mu, comp = _fields(n, geom=_geometry(n_part=n_part, seed=seed))
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(field, pin)
    h = mesh.h_m
    P = pt.ParticlePatches(op, mesh.centers_m / h, mesh.radii_m / h, shell)
    return mesh, lam, mu, comp, op, P


def test_patch_nodes_brute_force():
    n = 10
    c = np.array([[0.3, 5.2, 9.6], [4.5, 4.5, 4.5]])       # the first wraps over two faces
    r = np.array([1.7, 0.2])                              # the second holds no node alone
    pin = 9 + n * (5 + n * 0)                             # inside the first patch
    ptr, nodes = pt.patch_nodes(c, r, n, 0.5, pin)
    I, J, K = np.meshgrid(*[np.arange(n)] * 3, indexing="ij")
    pos = np.stack([I, J, K], -1).reshape(-1, 3).astype(float)
    idx = (I + n * (J + n * K)).reshape(-1)
    for q in range(2):
        d = pos - c[q]
        d -= n * np.round(d / n)                          # periodic minimum image
        want = np.sort(idx[np.linalg.norm(d, axis=1) <= r[q] + 0.5])
        want = want[want != pin]
        assert np.array_equal(nodes[ptr[q]:ptr[q + 1]], want)
    assert ptr[1] - ptr[0] > 20 and ptr[2] - ptr[1] == 0
    assert pin not in nodes
    assert pt.patch_factor_bytes(ptr) == np.dtype(pt.FACTOR_DTYPE).itemsize * sum(
        3 * m * (3 * m + 1) // 2 for m in np.diff(ptr))


def test_colours_never_couple_two_patches():
    n = 16
    rng = np.random.default_rng(3)
    c = rng.random((40, 3)) * n
    r = rng.uniform(0.5, 2.0, 40)
    shell = 0.5
    ptr, nodes = pt.patch_nodes(c, r, n, shell)
    colour = pt.patch_colours(c, r + shell, n)
    assert colour.max() >= 1                             # the test has couplings to separate
    # the stencil neighbourhood of every patch (its nodes grown by one in every direction)
    near = []
    for q in range(40):
        p = nodes[ptr[q]:ptr[q + 1]]
        i, j, k = p % n, (p // n) % n, p // (n * n)
        grown = {int(((i + dx) % n)[t] + n * (((j + dy) % n)[t] + n * ((k + dz) % n)[t]))
                 for t in range(p.size) for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                 for dz in (-1, 0, 1)}
        near.append(grown)
    coupled = 0
    for a in range(40):
        for b in range(a + 1, 40):
            if near[a] & set(nodes[ptr[b]:ptr[b + 1]].tolist()):
                coupled += 1
                assert colour[a] != colour[b]
    assert coupled > 0


@pytest.mark.parametrize("dtype,rtol", [(np.float64, 1e-9), (np.float32, 1e-4)])
def test_patch_solve_equals_dense_solve_of_assembled_submatrix(monkeypatch, dtype, rtol):
    """Exact with float64 factors; float32 storage (the default: half the memory) rounds the
    factor, so the patch solve is the exact solve of a nearby SPD matrix."""
    monkeypatch.setattr(pt, "FACTOR_DTYPE", dtype)
    mesh, lam, mu, comp, op, P = _setup(n=12)
    assert P.L.dtype == dtype
    K = _pin(_assembled(mesh, lam, mu, comp), op.pin, op.pin_scale).toarray()
    rng = np.random.default_rng(1)
    B = rng.normal(size=(3 * 12 ** 3, 3))
    B[3 * op.pin:3 * op.pin + 3] = 0.0
    for q in range(len(P.ptr) - 1):
        nodes = P.nodes[P.ptr[q]:P.ptr[q + 1]]
        if nodes.size == 0:
            continue
        dof = (3 * nodes[:, None] + np.arange(3)).reshape(-1)
        X0 = rng.normal(size=B.shape)
        X = X0.copy()
        single = types.SimpleNamespace(**vars(P))
        single.colours = [np.array([q], dtype=np.int64)]
        single._grouped = {}
        single._groups = types.MethodType(pt.ParticlePatches._groups, single)
        pt.ParticlePatches._sweep(single, X, B, [0])
        want = X0.copy()
        want[dof] += np.linalg.solve(K[np.ix_(dof, dof)], (B - K @ X0)[dof])
        assert np.abs(X - want).max() <= rtol * np.abs(want[dof]).max()
        other = np.setdiff1d(np.arange(B.shape[0]), dof)
        assert np.array_equal(X[other], X0[other])        # nothing outside the patch moves


def test_parallel_sweep_equals_serial_and_columns_equal_one_at_a_time():
    mesh, lam, mu, comp, op, P = _setup(n=16, n_part=10, seed=6)
    assert len(P.colours) >= 2
    rng = np.random.default_rng(2)
    B = rng.normal(size=(3 * 16 ** 3, 7))
    X0 = rng.normal(size=B.shape)
    out = {}
    for name, kern in (("parallel", pt.solve_colour), ("serial", pt.solve_colour_serial)):
        P._solve = kern
        X = X0.copy()
        P.forward(X, B)
        P.backward(X, B)
        out[name] = X
    # two compilations of fastmath kernels (reassociated sums: vector width and order are the
    # compiler's choice for each), so equal to round-off like the column paths below, not
    # bitwise on every CPU (measured: bitwise here); a race inside a colour would be O(update)
    assert np.abs(out["parallel"] - out["serial"]).max() <= 1e-10 * np.abs(out["serial"]).max()
    for c in (0, 4, 6):                       # the 8-wide, 4-wide and single-column paths
        X = np.ascontiguousarray(X0[:, [c]])
        P.forward(X, np.ascontiguousarray(B[:, [c]]))
        P.backward(X, np.ascontiguousarray(B[:, [c]]))
        assert np.abs(X[:, 0] - out["serial"][:, c]).max() <= 1e-10 * np.abs(X).max()
    X = np.ascontiguousarray(X0[:, :3])
    P.forward(X, np.ascontiguousarray(B[:, :3]))
    P.backward(X, np.ascontiguousarray(B[:, :3]))
    assert np.abs(X - out["serial"][:, :3]).max() <= 1e-10 * np.abs(X).max()


def test_thread_groups_cover_each_colour_once_balanced_and_bitwise_thread_independent():
    """The sweep's groups (one per thread, :meth:`ParticlePatches._groups`): every patch of a
    colour in exactly one group of it, the largest group's work at most the mean plus the
    largest patch's (the greedy largest-first bound), and the sweep bitwise the same for 1 and
    2 threads and any number of groups (the patches of a colour are independent)."""
    mesh, lam, mu, comp, op, P = _setup(n=16, n_part=10, seed=6)
    m = np.diff(P.ptr)
    work = (3 * m) * (3 * m + 1) + 243 * m
    for threads in (1, 2, 3, 5):
        groups = P._groups(threads)
        assert len(groups) == len(P.colours)
        for col, (which, bounds) in zip(P.colours, groups):
            assert bounds.shape == (threads + 1,) and bounds[0] == 0
            assert np.array_equal(np.sort(which), np.sort(col))
            loads = [work[which[bounds[g]:bounds[g + 1]]].sum() for g in range(threads)]
            assert max(loads) <= work[col].sum() / threads + work[col].max()
    rng = np.random.default_rng(3)
    B = rng.normal(size=(3 * 16 ** 3, 7))
    X0 = rng.normal(size=B.shape)
    P._solve = pt.solve_colour
    ref = None
    for groups in (1, 2, 3):
        P._groups = lambda t, g=groups: pt.ParticlePatches._groups(P, g)
        X = X0.copy()
        P.forward(X, B)
        P.backward(X, B)
        if ref is None:
            ref = X
        assert np.array_equal(X, ref)
    del P._groups
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("bitwise 1 against 2 threads: numba has only one thread here")
    out = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            X = X0.copy()
            P.forward(X, B)
            P.backward(X, B)
            out.append(X)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(out[0], out[1]) and np.array_equal(out[0], ref)


def test_patched_vcycle_symmetric_positive_definite_and_convergent():
    n = 16
    mesh, lam, mu, comp, op, P = _setup(n=n, n_part=8, seed=5, shell=1.0)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    kw = dict(pin=0, pin_scale=op.pin_scale, h=mesh.h_m, amg_options=AMGOptions(), fine_op=op,
              assembled_max=4, interface_sweeps=1)
    M = mf.GeometricVCycle(field, patches=P, **kw)
    M0 = mf.GeometricVCycle(field, **kw)
    B = np.random.default_rng(4).normal(size=(3 * n ** 3, 2))
    assert not np.allclose(M @ B, M0 @ B)               # the patches do act
    e_p, e_start = check_spd_and_convergent(M, op, n, 1e-10)
    e_0, _ = check_spd_and_convergent(M0, op, n, 1e-8)
    # one cycle reduces the energy of the error, and more than the cycle without the patches
    assert e_p < 0.5 * e_start and e_p < e_0


def test_c_eff_with_patches_equals_assembled_solver():
    geom = _geometry(n_part=8, seed=7, r=(0.08, 0.13))
    forces = np.random.default_rng(8).normal(size=(8, 3)) * 1e-15
    a = C.homogenize_rve(geom, 12, solver="fast", forces_N=forces, tol=1e-8)
    b = C.homogenize_rve(geom, 12, solver="matrix-free", forces_N=forces, tol=1e-8,
                         options=SolverOptions(patch_shell_voxels=0.5))
    assert b.settings["patch_shell_voxels"] == 0.5
    assert np.abs(a.C_eff_Pa - b.C_eff_Pa).max() <= 1e-8 * np.abs(a.C_eff_Pa).max()
    assert np.abs(a.stress_mag_Pa - b.stress_mag_Pa).max() <= 1e-6 * np.abs(a.stress_mag_Pa).max()


def test_patches_cut_iterations_on_small_particles():
    """100 particles of 1.25 voxels mean radius at 32^3 with random particle forces
    (results/cell/particle_patch_experiments.json): at the same user tolerance (the patched CG runs
    to SolverOptions.patch_tol_factor x tol) the patches need fewer iterations in every column, the
    magnetic one most, and their C_eff and magnetic stress are no further from a tight reference
    than the default's (within 2x: the two stopping points differ by chance)."""
    from homogenize.bench.bench_cell import bench_rve
    rve = bench_rve(64)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    ref = C.homogenize_rve(rve, 32, solver="matrix-free", forces_N=forces, tol=1e-11,
                           tol_magnetic=1e-10, options=SolverOptions(patch_shell_voxels=None))
    out = {}
    for shell in (None, 0.5):
        out[shell] = C.homogenize_rve(rve, 32, solver="matrix-free", forces_N=forces, tol=1e-6,
                                      options=SolverOptions(patch_shell_voxels=shell))
    assert out[None].settings["patched_particles"] == 0
    assert out[0.5].settings["patched_particles"] == rve.n
    assert out[0.5].settings["tol_cg"] == pytest.approx(1e-6 * SolverOptions().patch_tol_factor)
    it0, it1 = out[None].iterations, out[0.5].iterations
    strains = [c for c in it0 if c != "magnetic"]
    assert max(it1[c] for c in strains) < max(it0[c] for c in strains)
    assert it1["magnetic"] < 0.8 * it0["magnetic"]

    def err(r):
        return (np.abs(r.C_eff_Pa - ref.C_eff_Pa).max() / np.abs(ref.C_eff_Pa).max(),
                np.abs(r.stress_mag_Pa - ref.stress_mag_Pa).max()
                / np.abs(ref.stress_mag_Pa).max())
    e0, e1 = err(out[None]), err(out[0.5])
    assert e1[0] <= max(2 * e0[0], 1e-9) and e1[1] <= max(2 * e0[1], 1e-9), (e0, e1)


def test_patch_rule():
    """Patches for many particles or small ones (homogenize.cell.problem.use_patches), none for the
    64^3 bench RVE's 100 particles of ~2.5 voxels (where they cost more than they save), none
    without particles or with patch_shell_voxels = None."""
    assert not C.use_patches(100, np.full(100, 2.5))
    m = SolverOptions().patch_min_particles
    assert m == 200 and C.use_patches(m, np.full(m, 2.5))
    assert C.use_patches(100, np.full(100, 1.25))
    assert not C.use_patches(0, np.zeros(0))
    assert not C.use_patches(1000, np.full(1000, 1.0), SolverOptions(patch_shell_voxels=None))


def test_factorization_uses_one_blas_thread_and_restores_the_pool(monkeypatch):
    """The patches are factorized inside numba's parallel loop with ONE BLAS thread (OpenBLAS
    threads started in each numba thread oversubscribe the cores); the caller's BLAS thread
    counts are restored afterwards, and the factors equal the ones the serial kernel gives
    without any limit."""
    from threadpoolctl import threadpool_info

    seen = []
    real = pt.threadpool_limits

    def spy(*args, **kw):
        seen.append((args, kw))
        return real(*args, **kw)

    before = [(d["filepath"], d["num_threads"]) for d in threadpool_info()]
    monkeypatch.setattr(pt, "threadpool_limits", spy)
    mesh, lam, mu, comp, op, P = _setup(n=12, n_part=6)
    assert seen and seen[0][1].get("limits") == 1
    assert seen[0][1].get("user_api") == "blas"
    after = {d["filepath"]: d["num_threads"] for d in threadpool_info()}
    for path, threads in before:
        assert after[path] == threads
    L = np.empty_like(P.L)
    pt.factorize_serial(op.n, P.ptr, P.nodes, op.stype, op.S, op.pin, P.fptr, L)
    assert np.array_equal(L, P.L)
