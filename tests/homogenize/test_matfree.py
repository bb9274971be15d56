"""The matrix-free cell solver (homogenize.solvers._matfree, solver="matrix-free").

Operator equal to the assembled one to round-off (matrix, particle and composite voxels, periodic
wrap, pinned node); Gauss-Seidel sweep equal to the assembled sweep; the trilinear transfer
kernels equal the global prolongation matrix; the element-wise Galerkin coarse operator equals
P^T K P; symmetry and positive definiteness of the operator and of the V-cycle (also with the
local sweeps over the interface nodes, whose node set is checked by brute force, and which cut
the iterations); C_eff and the magnetic stress equal to the assembled solver's to the solver
tolerance; bad input.
The bigger version (24^3 RVE) runs with MAPSIM_FULL=1.
"""
from __future__ import annotations

import os
import types

import numpy as np
import pytest

from homogenize.voxels import _assembly as asm
from homogenize.voxels import _budget
from homogenize.solvers import _matfree as mf
from homogenize.cell import problem as C
from homogenize.solvers import AMGOptions, SolverOptions, grid_colours
from homogenize.solvers.amg import _Level
from homogenize.voxels.mesh import voxelize
from micro.common.validate import InputError

FULL = bool(os.environ.get("MAPSIM_FULL"))


def _geometry(n_part=6, box=1e-6, seed=4, r=(0.09, 0.16)):
    """Spheres at random places, some cut by the periodic boundary (the wrap is exercised)."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n_part, 3)) * box
    centres[0] = (0.02 * box, 0.5 * box, 0.98 * box)     # straddles two faces
    radii = rng.uniform(*r, size=n_part) * box
    return types.SimpleNamespace(box_m=box, centers_m=centres, radii_m=radii)


def _fields(n, method="composite", geom=None):
    mesh = voxelize(geom or _geometry(), n, method=method)
    if method in ("composite", "laminate"):
        lam, mu, comp = C._composite_fields(mesh, C.elastic(C.PDMS), C.elastic(C.FE))
    else:
        lam, mu = C._material_fields(mesh, C.elastic(C.PDMS), C.elastic(C.FE))
        comp = None
    return mesh, lam, mu, comp


def _assembled(mesh, lam, mu, comp):
    K = asm.assemble_bsr(lam, mu, mesh.h_m)
    if comp is not None:
        comp.add_to(K)
    return K


def _pin(K, pin, scale):
    K = K.copy()
    ptr, ind = K.indptr, K.indices
    K.data[ind == pin] = 0.0
    K.data[ptr[pin]:ptr[pin + 1]] = 0.0
    row = np.arange(ptr[pin], ptr[pin + 1])
    K.data[row[ind[row] == pin][0]] = scale * np.eye(3)
    return K


@pytest.mark.parametrize("method", ["composite", "centre", "laminate"])
def test_operator_equals_assembled(method):
    n = 10
    mesh, lam, mu, comp = _fields(n, method)
    # all three voxel kinds are present: matrix, particle, and (composite) cut voxels
    assert (mu == mu.max()).any() and (mu == mu.min()).any()
    if comp is not None:
        assert comp.vox.size > 0
    K = _assembled(mesh, lam, mu, comp)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(field)
    # shared stencil rows and own rows (assembled by slot), own rows also at the grid faces
    # where the wrapped neighbours' sorted BSR order differs from the slot order
    own = op.stype >= max(field.n_shared, 1)
    assert own.any() and (~own).any()
    ijk = np.stack(np.unravel_index(np.flatnonzero(own), (n, n, n)), axis=1)
    assert ((ijk == 0) | (ijk == n - 1)).any()
    U = np.random.default_rng(0).normal(size=(3 * n ** 3, 4))
    ref = K @ U
    got = op @ U
    assert np.abs(got - ref).max() <= 1e-13 * np.abs(ref).max()
    assert np.allclose(op @ U[:, 1], ref[:, 1], rtol=0, atol=1e-13 * np.abs(ref).max())
    # the assembled matrix of the element types, the diagonal blocks
    Kt = mf.typed_bsr(field)
    assert abs(Kt - K).max() <= 1e-14 * abs(K).max()
    diag = K.diagonal().reshape(-1, 3)
    assert np.allclose(np.einsum("pii->pi", op.diag), diag, rtol=1e-14, atol=0)


def test_pinned_operator_and_gauss_seidel_equal_assembled():
    n = 8
    mesh, lam, mu, comp = _fields(n)
    K = _assembled(mesh, lam, mu, comp)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    pin = 2 + n * (4 + n * 6)
    op = mf.MatFreeOperator(field, pin)
    scale = float(np.mean(K.diagonal()))
    assert op.pin_scale == pytest.approx(scale, rel=1e-14)
    Kp = _pin(K, pin, scale)
    U = np.random.default_rng(1).normal(size=(3 * n ** 3, 3))
    ref = Kp @ U
    assert np.abs(op @ U - ref).max() <= 1e-13 * np.abs(ref).max()
    R = np.random.default_rng(2).normal(size=U.shape)
    assert np.abs(op.residual(U, R) - (R - ref)).max() <= 1e-13 * np.abs(ref).max()
    assert np.abs(mf.typed_bsr(field, pin=pin) - Kp).max() <= 1e-14 * abs(K).max()
    # one forward sweep of 8-colour block Gauss-Seidel, matrix-free vs the assembled kernel
    X1, X2 = np.zeros_like(U), np.zeros_like(U)
    cols = grid_colours(n)
    op.gauss_seidel(X1, R, cols)
    _Level(Kp, cols).smooth(X2, R, range(len(cols)))
    assert np.abs(X1 - X2).max() <= 1e-12 * np.abs(X2).max()


@pytest.mark.parametrize("n", [8, 10])
def test_gauss_seidel_from_zero_skips_only_zeros(n):
    """The V-cycle's pre-smoothing starts from X = 0: its first sweep skips the neighbours of a
    not-yet-visited colour (and the node itself). Same result to the last bit as the full
    sweep, with the pinned node, a second sweep and the interface classes after it; colours of
    a subset of the nodes in parity order (the interface sweep alone) are skipped the same way."""
    mesh, lam, mu, comp = _fields(n)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(field, 2 + n * (4 + n * 6))
    cols = grid_colours(n)
    mask = op.interface_nodes(0)
    iface = [c[mask[c]] for c in cols]
    B = np.random.default_rng(3).normal(size=(3 * n ** 3, 4))
    for order in (cols, cols + iface, cols * 2 + iface, iface):
        X1, X2 = np.zeros_like(B), np.zeros_like(B)
        op.gauss_seidel(X1, B, order)
        op.gauss_seidel_from_zero(X2, B, order)
        # bitwise on any CPU: the skipped products are exact zeros (x + 0.0 == x) and the kernels
        # have no fastmath, so the remaining operations keep their order
        assert np.array_equal(X1, X2)
    # a sweep that does not start from zero is NOT what the skipped blocks compute: the test
    # above would see a wrong skip rule
    X1, X2 = np.ones_like(B), np.ones_like(B)
    op.gauss_seidel(X1, B, cols)
    op.gauss_seidel_from_zero(X2, B, cols)
    assert not np.array_equal(X1, X2)
    # classes that are not the parity colours in order: the plain sweep runs
    X1, X2 = np.zeros_like(B), np.zeros_like(B)
    op.gauss_seidel(X1, B, cols[::-1])
    op.gauss_seidel_from_zero(X2, B, cols[::-1])
    assert np.array_equal(X1, X2)


def test_gauss_seidel_from_zero_odd_grid_falls_back():
    """On an odd grid (27 colours, the assembled grid under an odd fine grid) the parity rule
    does not hold: the plain sweep runs."""
    n = 9
    mesh, lam, mu, comp = _fields(n)
    op = mf.MatFreeOperator(mf.element_field(lam, mu, mesh.h_m, comp), 0)
    cols = grid_colours(n)
    B = np.random.default_rng(4).normal(size=(3 * n ** 3, 2))
    X1, X2 = np.zeros_like(B), np.zeros_like(B)
    op.gauss_seidel(X1, B, cols)
    op.gauss_seidel_from_zero(X2, B, cols)
    assert np.array_equal(X1, X2)


def test_operator_symmetric_positive_definite():
    n = 8
    mesh, lam, mu, comp = _fields(n)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    rng = np.random.default_rng(3)
    U = rng.normal(size=(3 * n ** 3, 5))
    op = mf.MatFreeOperator(field)
    G = U.T @ (op @ U)
    assert np.abs(G - G.T).max() <= 1e-13 * np.abs(G).max()
    # unpinned: the rigid translations are its null space, everything else has positive energy
    T = np.zeros((3 * n ** 3, 3))
    for c in range(3):
        T[c::3, c] = 1.0
    assert np.abs(op @ T).max() <= 1e-10 * np.abs(op @ U).max()
    Uc = U - T @ np.linalg.lstsq(T, U, rcond=None)[0]
    assert np.all(np.einsum("ij,ij->j", Uc, op @ Uc) > 0)
    # pinned: positive definite (smallest eigenvalue of a small dense matrix > 0)
    mesh6, lam6, mu6, comp6 = _fields(6)
    Kd = mf.typed_bsr(mf.element_field(lam6, mu6, mesh6.h_m, comp6), pin=0).toarray()
    assert np.abs(Kd - Kd.T).max() <= 1e-14 * np.abs(Kd).max()
    assert np.linalg.eigvalsh(Kd)[0] > 0


def test_transfer_kernels_equal_prolongation_matrix():
    nc = 5
    P = mf.prolongation_matrix(nc)
    rng = np.random.default_rng(4)
    Xc = rng.normal(size=(3 * nc ** 3, 2))
    X = rng.normal(size=(3 * (2 * nc) ** 3, 2))
    out = X.copy()
    mf.prolong_add(nc, Xc.reshape(-1, 3, 2), out.reshape(-1, 3, 2))
    assert np.allclose(out, X + P @ Xc, rtol=0, atol=1e-14)
    R = np.empty_like(Xc)
    mf.restrict(nc, X.reshape(-1, 3, 2), R.reshape(-1, 3, 2))
    assert np.allclose(R, P.T @ X, rtol=0, atol=1e-13)
    # interpolation reproduces constants and linear fields (away from the periodic seam)
    assert np.allclose(P @ np.ones(3 * nc ** 3), 1.0)
    # each child prolongation is a partition of unity
    Pc = mf.child_prolongations()
    assert np.allclose(Pc.sum(axis=2), 1.0)


def test_restricted_residual_and_freed_diagonal_are_the_same_numbers():
    """The V-cycle restricts the residual slab by slab (no fine residual block): bit for bit the
    restriction of the whole residual, for every slab height; the diagonal blocks are dropped
    once their inverses exist."""
    rng = np.random.default_rng(5)
    for n in (8, 10, 16):
        ph = rng.random((n, n, n)) < 0.15
        op = mf.MatFreeOperator(mf.element_field(np.where(ph, 1e11, 1e6),
                                                 np.where(ph, 8e10, 6e5), 1e-8), pin=0)
        nc = n // 2
        for k in (1, 7):
            X, B = rng.normal(size=(2, 3 * n ** 3, k))
            ref = np.empty((3 * nc ** 3, k))
            mf.restrict(nc, op.residual(X, B).reshape(-1, 3, k), ref.reshape(-1, 3, k))
            for planes in (None, 1, 2, 3, nc):
                out = np.empty_like(ref)
                op.restricted_residual(X, B, out, planes)
                assert np.array_equal(out, ref)
        D = op.diag.copy()
        assert np.allclose(np.einsum("pij,pjk->pik", op.dinv, D), np.eye(3), atol=1e-10)
        assert op.diag is None
        Y = rng.normal(size=(3 * n ** 3, 2))
        assert np.array_equal(op @ Y, op @ Y.copy())        # the products no longer need it


def test_stiffness_times_sparse_does_not_depend_on_the_chunks():
    rng = np.random.default_rng(6)
    n = 8
    ph = rng.random((n, n, n)) < 0.2
    field = mf.element_field(np.where(ph, 1e11, 1e6), np.where(ph, 8e10, 6e5), 1e-8)
    import scipy.sparse as sp
    Z = sp.random(3 * n ** 3, 12, density=0.05, random_state=7, format="csr")
    Z = sp.csr_matrix(Z.multiply(np.arange(3 * n ** 3)[:, None] >= 3))   # zero at the pin
    ref = mf.stiffness_times_sparse(field, Z, pin=0, chunk=10 ** 9)
    for chunk in (1, 7, 100):
        out = mf.stiffness_times_sparse(field, Z, pin=0, chunk=chunk)
        assert np.array_equal(out.indptr, ref.indptr) and np.array_equal(out.indices, ref.indices)
        assert np.array_equal(out.data, ref.data)
    K = sp.diags((np.arange(3 * n ** 3) >= 3).astype(float)) @ mf.typed_bsr(field).tocsr()
    assert np.allclose(ref.toarray(), (K @ Z).toarray(), rtol=1e-12, atol=1e-12 * abs(K).max())


@pytest.mark.parametrize("method", ["composite", "centre"])
def test_galerkin_coarse_operator_elementwise(method):
    n = 12
    mesh, lam, mu, comp = _fields(n, method)
    K = _assembled(mesh, lam, mu, comp).tocsr()
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    fc = mf.coarsen(field)
    P = mf.prolongation_matrix(n // 2)
    G = (P.T @ K @ P).tocsr()
    Gc = mf.typed_bsr(fc).tocsr()
    assert abs(G - Gc).max() <= 1e-13 * abs(G).max()
    # shared coarse types: the coarse voxels whose children are all matrix share one matrix
    assert fc.n_shared == field.n_shared and fc.Ktab.shape[0] < fc.n ** 3
    # twice: the 3^3 grid of the 12^3 one
    fcc = mf.coarsen(fc)
    P2 = mf.prolongation_matrix(n // 4)
    G2 = (P2.T @ G @ P2).tocsr()
    assert abs(G2 - mf.typed_bsr(fcc).tocsr()).max() <= 1e-13 * abs(G2).max()


def test_amg_level_smoothed_matrix_free_equals_assembled():
    """The assembled grid under the geometric levels keeps its smoothed-aggregation transfer
    but smooths and takes residuals with the matrix-free operator (``_Level.use_operator``):
    the same V-cycle as with the assembled blocks, to round-off."""
    from homogenize.solvers import (BlockVCycle, grid_node_coordinates, rigid_body_modes,
                                    smoothed_aggregation)
    n = 12
    mesh, lam, mu, comp = _fields(n)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(field, 0)
    A = mf.typed_bsr(field, pin=0, pin_scale=op.pin_scale)
    ml = smoothed_aggregation(A, rigid_body_modes(grid_node_coordinates(n)),
                              AMGOptions(max_coarse=50))
    assert len(ml.levels) >= 2
    assembled = BlockVCycle(ml, fine_colours=grid_colours(n))
    free = BlockVCycle(ml, fine_colours=grid_colours(n))
    free.levels[0].use_operator(op)
    assert free.levels[0].dinv is None                   # the assembled blocks are dropped
    B = np.random.default_rng(8).normal(size=(3 * n ** 3, 3))
    ref = assembled @ B
    assert np.abs(free @ B - ref).max() <= 1e-12 * np.abs(ref).max()


def test_interface_nodes():
    """The interface nodes of the local sweeps: the nodes with their own stencil row (not all 8
    voxels of one shared type), grown by `halo` nodes = every node within Chebyshev distance
    `halo` of one (periodic), checked by brute force."""
    n = 12
    mesh, lam, mu, comp = _fields(n)
    e = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(e)
    # own rows: a node whose 8 voxels differ in type or hold a cut voxel (its own type)
    et = e.etype.reshape(n, n, n)
    own = np.zeros((n, n, n), dtype=bool)
    for kk in range(n):
        for j in range(n):
            for i in range(n):
                t = {int(et[(kk - az) % n, (j - ay) % n, (i - ax) % n])
                     for ax, ay, az in asm.CORNERS}
                own[kk, j, i] = len(t) > 1 or max(t) >= e.n_shared
    assert np.array_equal(op.interface_nodes(0), own.reshape(-1))
    assert 0.0 < own.mean() < 1.0
    for halo in (1, 2):
        ref = np.zeros_like(own)
        for dz in range(-halo, halo + 1):
            for dy in range(-halo, halo + 1):
                for dx in range(-halo, halo + 1):
                    ref |= np.roll(own, (dz, dy, dx), axis=(0, 1, 2))
        assert np.array_equal(op.interface_nodes(halo), ref.reshape(-1))


@pytest.mark.parametrize("coarse,interface_sweeps", [("amg", 0), ("lu", 0), ("amg", 1),
                                                     ("amg", 2)])
def test_vcycle_symmetric_positive_definite(coarse, interface_sweeps):
    """Also with the assembled grid solved exactly (coarse="lu", the diagnostic of
    results/cell/multigrid_robustness.py) and with local sweeps over the interface nodes
    (forward after the full sweeps, backward before them: the cycle stays symmetric)."""
    n = 16
    mesh, lam, mu, comp = _fields(n)
    field = mf.element_field(lam, mu, mesh.h_m, comp)
    op = mf.MatFreeOperator(field, 0)
    M = mf.GeometricVCycle(field, pin=0, pin_scale=op.pin_scale, h=mesh.h_m,
                           amg_options=AMGOptions(), fine_op=op, assembled_max=4,
                           coarse=coarse, interface_sweeps=interface_sweeps)
    assert len(M.levels) == 2 and M.coarse_n == 4       # two matrix-free levels, then AMG / LU
    for L in M.levels:
        assert (len(L.interface_colours) > 0) == (interface_sweeps > 0)
        assert 0.0 <= L.interface_share < 1.0
    assert (M.ml is None) == (coarse == "lu")
    e_cycle, e_start = check_spd_and_convergent(M, op, n, 1e-8)
    assert e_cycle < 0.5 * e_start


def check_spd_and_convergent(M, op, n, sym_tol, seed=5):
    """The preconditioner M of the pinned operator op on n^3 nodes is symmetric (|G - G^T| <=
    sym_tol |G| for G = B^T M B on random loads, the pinned node unloaded) and positive definite;
    returns the energy of the error of K x = b after one application of M and before it."""
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(3 * n ** 3, 4))
    B[0:3] = 0.0                                         # the pinned node carries no load
    G = B.T @ (M @ B)
    assert np.abs(G - G.T).max() <= sym_tol * np.abs(G).max()
    assert np.all(np.linalg.eigvalsh(0.5 * (G + G.T)) > 0)
    X = rng.normal(size=(3 * n ** 3, 1))
    X[0:3] = 0.0
    b = op @ X

    def energy(v):
        return float(v[:, 0] @ (op @ v)[:, 0])
    return energy(X - M @ b), energy(X)


def _c_eff(n, solver, forces, geom):
    return C.homogenize_rve(geom, n, solver=solver, forces_N=forces, tol=1e-8)


@pytest.mark.parametrize("n", [12] + ([24] if FULL else []))
def test_c_eff_equals_assembled_solver(n):
    geom = _geometry(n_part=8, seed=7, r=(0.08, 0.13))
    forces = np.random.default_rng(8).normal(size=(8, 3)) * 1e-15
    a = _c_eff(n, "fast", forces, geom)
    b = _c_eff(n, "matrix-free", forces, geom)
    assert b.settings["solver"] == "matrix-free" and b.settings["geometric_levels"] == 1
    assert b.settings["interface_sweeps"] == SolverOptions().matfree_interface_sweeps == 1
    assert a.settings["interface_sweeps"] == 0
    assert max(v for k, v in b.residuals.items() if k != "magnetic") <= 1e-8
    assert b.residuals["magnetic"] <= C.magnetic_tol(1e-8) == 1e-4
    # variational C_eff: error ~ tol^2 relative; both solvers agree far below the tolerance
    assert np.abs(a.C_eff_Pa - b.C_eff_Pa).max() <= 1e-8 * np.abs(a.C_eff_Pa).max()
    assert np.abs(a.stress_mag_Pa - b.stress_mag_Pa).max() <= 1e-6 * np.abs(a.stress_mag_Pa).max()
    # symmetric positive definite effective stiffness, stiffer than the matrix
    Cb = b.C_eff_Pa
    assert np.abs(Cb - Cb.T).max() <= 1e-12 * np.abs(Cb).max()
    assert np.linalg.eigvalsh(Cb)[0] > 0
    assert b.E_eff_Pa > C.PDMS.E_Pa


def test_interface_sweeps_cut_iterations():
    """The local sweeps over the interface nodes (the default, matfree_interface_sweeps = 1)
    against none on the 32^3 bench RVE: fewer CG iterations in every load case that needs more
    than a handful, the same C_eff to the solver tolerance (results/cell/multigrid_robustness.json
    holds the bigger RVEs)."""
    from homogenize.bench.bench_cell import bench_rve
    opts = SolverOptions(patch_shell_voxels=None)       # the sweeps alone
    rve = bench_rve(32)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    out = {}
    for sweeps in (0, 1):
        out[sweeps] = C.homogenize_rve(rve, 32, forces_N=forces, solver="matrix-free",
                                       options=opts.replace(matfree_interface_sweeps=sweeps))
    it0, it1 = out[0].iterations, out[1].iterations
    assert max(it1.values()) < max(it0.values())
    assert sum(it1.values()) < 0.9 * sum(it0.values())
    a, b = out[0].C_eff_Pa, out[1].C_eff_Pa
    assert np.abs(a - b).max() <= 1e-6 * np.abs(a).max()



def test_coupled_block_cg_cuts_iterations():
    """The load cases' CGs coupled (homogenize.solvers.SolverOptions.block_cg) against lock-step
    independent CGs on the RVE of 100 particles of 1.25 voxels at 32^3 (results/cell/README.md,
    "Coupled block CG"): the default "strains" couples the six strains (fewer iterations each)
    and leaves the magnetic column's recursion alone (its single-column iterations); "coupled"
    puts the magnetic column in the block too (fewer for it as well on this RVE). The same C_eff
    and magnetic stress to the solver tolerance in every mode."""
    from homogenize.bench.bench_cell import bench_rve
    assert SolverOptions().block_cg == "strains"
    # the block CG alone: particle patches (the default since session 14) cut the iterations of
    # every mode to where the modes' differences are within one or two iterations
    opts = SolverOptions(patch_shell_voxels=None)
    rve = bench_rve(64)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    out = {}
    for mode in ("independent", "strains", "coupled"):
        out[mode] = C.homogenize_rve(rve, 32, forces_N=forces, solver="matrix-free",
                                     options=opts.replace(block_cg=mode))
        assert out[mode].settings["block_cg"] == mode
    it0 = out["independent"].iterations
    strains = [c for c in it0 if c != "magnetic"]
    for mode in ("strains", "coupled"):
        it = out[mode].iterations
        assert all(it[c] < it0[c] for c in strains), (mode, it0, it)
        assert max(it[c] for c in strains) < 0.8 * max(it0[c] for c in strains)
    assert abs(out["strains"].iterations["magnetic"] - it0["magnetic"]) <= 1
    assert out["coupled"].iterations["magnetic"] < it0["magnetic"]
    a, s0 = out["independent"].C_eff_Pa, out["independent"].stress_mag_Pa
    for mode in ("strains", "coupled"):
        assert np.abs(out[mode].C_eff_Pa - a).max() <= 1e-6 * np.abs(a).max()
        assert np.abs(out[mode].stress_mag_Pa - s0).max() <= 1e-5 * np.abs(s0).max()


def test_solve_restores_the_load_block(monkeypatch):
    """The solvers zero the pinned node's rows of the load block in place for the solve (no copy
    of the block) and put them back: the caller's F (used afterwards for f_a . w_b) is intact."""
    seen = []
    orig = C._CellSolver.solve

    def spy(self, F, **kw):
        rows = slice(3 * self.pin, 3 * self.pin + 3)
        F[rows] = np.arange(1.0, 1.0 + 3 * F.shape[1]).reshape(3, -1)   # ignored by the solve
        before = F.copy()
        out = orig(self, F, **kw)
        seen.append(np.array_equal(F, before))
        return out
    monkeypatch.setattr(C._CellSolver, "solve", spy)
    forces = np.random.default_rng(1).normal(size=(6, 3)) * 1e-15
    for solver in ("matrix-free", "fast"):
        C.homogenize_rve(_geometry(), 8, forces_N=forces, solver=solver)
    assert seen == [True, True]

def test_bad_input():
    geom = _geometry()
    with pytest.raises(InputError, match="even number of voxels"):
        C.homogenize_rve(geom, 9, solver="matrix-free")
    with pytest.raises(InputError, match="solver must be one of"):
        C.homogenize_rve(geom, 8, solver="matfree")
    with pytest.raises(InputError, match="solver must be one of"):
        C.CellConfig(voxels=8, solver="matfree")
    assert C.CellConfig(voxels=8, solver="matrix-free").solver == "matrix-free"


def test_memory_estimate(monkeypatch):
    # no assembled fine matrix: the matrix-free model is well below the assembled one, and
    # grows with the grid and the number of load cases
    mfree = _budget.cell_memory_bytes(128, "matrix-free", 7)
    fast = _budget.cell_memory_bytes(128, "fast", 7)
    assert mfree < 0.6 * fast
    assert _budget.cell_memory_bytes(64, "matrix-free", 7) < mfree
    assert _budget.cell_memory_bytes(128, "matrix-free", 1) < mfree
    # a grid beyond the machine is refused before any allocation, with the estimate named
    monkeypatch.setattr(_budget, "machine_memory_bytes", lambda: 4 * 2 ** 30)
    with pytest.raises(InputError, match=r"voxels=128 .* needs about .* GiB"):
        C._choose_solver("matrix-free", 128, 7)
    # "fast" falls back to the matrix-free solver where only that one fits
    monkeypatch.setattr(_budget, "machine_memory_bytes", lambda: 12 * 2 ** 30)
    assert C._choose_solver("fast", 128, 7) == "matrix-free"
    assert C._choose_solver("fast", 32, 7) == "fast"
    with pytest.raises(InputError, match="needs about"):
        C._choose_solver("fast", 127, 7)       # odd: no matrix-free fallback


def test_cli_solver_choice(tmp_path, monkeypatch):
    import json

    from homogenize.cli import main
    from micro.particles import Monodisperse, generate_rve
    rve = generate_rve(0.05, 4, 7, distribution=Monodisperse(25e-9), gap_m=5e-9)
    path = tmp_path / "rve.h5"
    rve.save(path)
    out = tmp_path / "cell.json"
    assert main(["homogenize", str(path), "--voxels", "8", "--solver", "matrix-free",
                 "--json", str(out), "--quiet"]) == 0
    d = json.loads(out.read_text())
    assert d["settings"]["solver"] == "matrix-free" and d["E_eff_Pa"] > 2e6
    # odd grid, and a grid beyond the machine: exit 2 before any work, no output file
    bad = tmp_path / "bad.json"
    assert main(["homogenize", str(path), "--voxels", "9", "--solver", "matrix-free",
                 "--json", str(bad), "--quiet"]) == 2
    monkeypatch.setattr(_budget, "machine_memory_bytes", lambda: 2 ** 30)
    assert main(["homogenize", str(path), "--voxels", "128", "--solver", "matrix-free",
                 "--json", str(bad), "--quiet"]) == 2
    assert not bad.exists()
