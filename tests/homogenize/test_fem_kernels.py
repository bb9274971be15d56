"""numba kernels of homogenize against plain numpy/scipy references, and the fast cell solver
against the reference path (BLAS assembly, pyamg's own V-cycle, scipy products)."""
import numpy as np
import pytest
import scipy.sparse as sp

from homogenize.voxels import _assembly as A
from homogenize.voxels import _kernels as K
from homogenize.solvers import BSROp, greedy_colours, grid_colours


def _random_bsr(rows, cols, R, C, seed):
    rng = np.random.default_rng(seed)
    M = sp.random(rows * R, cols * C, density=0.3, random_state=rng, format="csr")
    return M.tobsr(blocksize=(R, C))


def test_bsr_products_and_residual_equal_scipy_for_many_columns():
    rng = np.random.default_rng(1)
    for R, C in ((3, 3), (3, 6), (6, 3)):
        M = _random_bsr(7, 5, R, C, seed=R + C)
        for k in (1, 4):
            x = rng.normal(size=(M.shape[1], k))
            b = rng.normal(size=(M.shape[0], k))
            for mm, res in ((K.bsr_matmat, K.bsr_residual),
                            (K.bsr_matmat_serial, K.bsr_residual_serial)):
                y = np.empty((M.shape[0], k))
                mm(M.indptr, M.indices, M.data, x.reshape(-1, C, k), y.reshape(-1, R, k))
                # same products summed in another order: round-off only
                assert np.allclose(y, M @ x, rtol=1e-13, atol=1e-13 * np.abs(M @ x).max())
                out = np.empty((M.shape[0], k))
                res(M.indptr, M.indices, M.data, x.reshape(-1, C, k), b.reshape(-1, R, k),
                    out.reshape(-1, R, k))
                assert np.allclose(out, b - M @ x, rtol=1e-13, atol=1e-13 * np.abs(b - M @ x).max())
        op = BSROp(M)           # the wrapper: 1-D and 2-D inputs
        x = rng.normal(size=M.shape[1])
        assert np.allclose(op @ x, M @ x, rtol=1e-13, atol=1e-13 * np.abs(M @ x).max())
        assert np.allclose(op.residual(x, M @ x), 0.0, atol=1e-13 * np.abs(M @ x).max())


def test_transposed_bsr_product_equals_the_explicit_transpose_bit_for_bit():
    """The AMG restriction reads P's blocks transposed instead of a transposed copy: the same
    sums in the same order as the product with the explicit transpose."""
    from homogenize.solvers.amg import TransposedBSROp
    rng = np.random.default_rng(3)
    for R, C in ((3, 6), (3, 3), (6, 3)):
        M = _random_bsr(9, 6, R, C, seed=R * C)
        M.sort_indices()
        T = M.T.tobsr(blocksize=(C, R))
        T.sort_indices()
        tr = TransposedBSROp(BSROp(M))
        for k in (1, 3, 7):
            x = rng.normal(size=(M.shape[0], k))
            ref = BSROp(T) @ x
            assert np.array_equal(tr @ x, ref)
            y = np.empty_like(ref)
            K.bsr_transposed_matmat_serial(tr.indptr, tr.indices, tr.perm, tr.data,
                                           x.reshape(-1, R, k), y.reshape(-1, C, k))
            assert np.array_equal(y, ref)
            y[:] = 0.0
            K.bsr_transposed_matmat(tr.indptr, tr.indices, tr.perm, tr.data,
                                    x.reshape(-1, R, k), y.reshape(-1, C, k))
            assert np.array_equal(y, ref)
        x = rng.normal(size=M.shape[0])
        assert np.array_equal(tr @ x, BSROp(T) @ x)


def test_greedy_colouring_is_proper():
    M = _random_bsr(40, 40, 6, 6, seed=2)
    M = (M + M.T).tobsr(blocksize=(6, 6))
    M.sort_indices()
    colours = greedy_colours(BSROp(M))
    colour = np.empty(40, dtype=int)
    for c, rows in enumerate(colours):
        colour[rows] = c
    assert sorted(np.concatenate(colours)) == list(range(40))
    rows = np.repeat(np.arange(40), np.diff(M.indptr))
    off = rows != M.indices
    assert np.all(colour[rows[off]] != colour[M.indices[off]])       # coupled rows differ


def test_typed_stencil_kernel_equals_blas_assembly():
    rng = np.random.default_rng(0)
    for n in (3, 4, 5):                       # n = 3: every neighbour wraps; odd and even n
        ph = rng.random((n, n, n)) < 0.3
        lam, mu = np.where(ph, 1.2e11, 6.2e6), np.where(ph, 8.2e10, 6.9e5)
        Kn = A.assemble_bsr(lam, mu, 1e-8, method="numba")
        Kb = A.assemble_bsr(lam, mu, 1e-8, method="blas")
        idx, dat = np.empty_like(Kn.indices), np.empty_like(Kn.data)
        etype, Ktab = A.voxel_types(lam, mu, 1e-8)
        assert len(Ktab) == 2
        K.typed_stencil_blocks(n, np.arange(n ** 3), etype, Ktab, A._stencil_tables(),
                               A._AXIS_ORDER, idx, dat)
        # parallel variant == serial one used at this size, bitwise on any CPU: one source, no
        # fastmath (LLVM keeps the IEEE order), each block summed by one thread
        assert np.array_equal(dat, Kn.data)
        assert np.array_equal(Kn.indices, Kb.indices) and np.array_equal(Kn.indptr, Kb.indptr)
        # same element blocks, summed in a different order: relative round-off
        assert np.abs(Kn.data - Kb.data).max() <= 1e-14 * np.abs(Kb.data).max()


def _sequential_block_sweep(D, b, x, order, R):
    """Plain numpy block Gauss-Seidel: the R x R diagonal blocks of the dense D solved one after
    another in ``order``, all columns of b at once; returns the updated copy of x."""
    xr = x.copy()
    for p in order:
        s = slice(R * p, R * p + R)
        r = b[s] - D[s] @ xr + D[s, s] @ xr[s]
        xr[s] = np.linalg.solve(D[s, s], r)
    return xr


def test_colour_sweep_equals_sequential_block_gauss_seidel():
    """A multicolour sweep IS a sequential block Gauss-Seidel sweep in colour order, because the
    nodes of one colour share no voxel (checked here for odd and even n)."""
    rng = np.random.default_rng(3)
    for n in (4, 5):
        ph = rng.random((n, n, n)) < 0.3
        M = A.assemble_bsr(np.where(ph, 50.0, 1.0), np.where(ph, 30.0, 1.0), 1.0)
        M = (M + 1e-3 * sp.identity(M.shape[0])).tobsr(blocksize=(3, 3))   # SPD (periodic K is singular)
        M.sort_indices()
        colours = grid_colours(n)
        assert sum(c.size for c in colours) == n ** 3
        Md = M.tocsr()
        for c in colours:                       # no coupling inside a colour
            sub = Md[np.repeat(3 * c, 3) + np.tile(np.arange(3), c.size)][:, np.repeat(3 * c, 3)
                                                                           + np.tile(np.arange(3), c.size)]
            assert abs(sub - sp.block_diag([Md[3 * p:3 * p + 3, 3 * p:3 * p + 3] for p in c])).max() == 0
        k = 3
        b = rng.normal(size=(M.shape[0], k))
        x = rng.normal(size=(M.shape[0], k))
        rows = np.repeat(np.arange(n ** 3), np.diff(M.indptr))
        dinv = np.ascontiguousarray(np.linalg.inv(M.data[M.indices == rows]))
        xk, xs = x.copy(), x.copy()
        tmp = np.empty((n ** 3, 3, k))
        for c in colours:
            K.bsr_gauss_seidel_colour(M.indptr, M.indices, M.data, dinv, c, xk.reshape(-1, 3, k),
                                      b.reshape(-1, 3, k), tmp)
            K.bsr_gauss_seidel_colour_serial(M.indptr, M.indices, M.data, dinv, c,
                                             xs.reshape(-1, 3, k), b.reshape(-1, 3, k), tmp)
        assert np.array_equal(xk, xs)       # thread-count independent, bit for bit
        # plain numpy sequential block sweep in the same node order, column by column
        xr = _sequential_block_sweep(Md.toarray(), b, x, np.concatenate(colours), 3)
        assert np.allclose(xk, xr, rtol=1e-12, atol=1e-12 * np.abs(xr).max())


@pytest.mark.parametrize("k", [1, 3])
def test_colour_sweep_with_6x6_blocks_equals_sequential_block_gauss_seidel(k):
    """The smoothed-aggregation levels have 6x6 blocks (rigid modes per aggregate): the kernel's
    general block path (one column, several columns) against a plain sequential block sweep in
    colour order."""
    rng = np.random.default_rng(4)
    nrow, R = 9, 6
    M = sp.random(nrow * R, nrow * R, density=0.15, random_state=rng, format="csr")
    M = (M @ M.T + nrow * R * sp.identity(nrow * R)).tobsr(blocksize=(R, R))   # SPD
    M.sort_indices()
    colours = greedy_colours(M)
    rows = np.repeat(np.arange(nrow), np.diff(M.indptr))
    dinv = np.ascontiguousarray(np.linalg.inv(M.data[M.indices == rows]))
    b = rng.normal(size=(M.shape[0], k))
    x = rng.normal(size=(M.shape[0], k))
    xk = x.copy()
    tmp = np.empty((nrow, R, k))
    for c in colours:
        K.bsr_gauss_seidel_colour_serial(M.indptr, M.indices, M.data, dinv, c,
                                         xk.reshape(-1, R, k), b.reshape(-1, R, k), tmp)
    xr = _sequential_block_sweep(M.toarray(), b, x, np.concatenate(colours), R)
    assert np.allclose(xk, xr, rtol=1e-12, atol=1e-12 * np.abs(xr).max())
    assert not np.allclose(xk, x)           # the sweep did something


def test_coupled_block_cg_kernels_equal_numpy_and_do_not_depend_on_threads():
    import numba
    rng = np.random.default_rng(5)
    n, kp, ka, chunk = 1000, 5, 3, 64
    P, Q = rng.normal(size=(n, kp)), rng.normal(size=(n, kp))
    X, R, Z = rng.normal(size=(n, ka)), rng.normal(size=(n, ka)), rng.normal(size=(n, ka))
    alpha, beta = rng.normal(size=(kp, ka)), rng.normal(size=(kp, ka))
    nch = (n + chunk - 1) // chunk
    parts = np.empty((nch, kp, ka))
    K.gram_parts(P, R, chunk, parts)
    assert np.allclose(parts.sum(axis=0), P.T @ R, rtol=1e-13, atol=1e-12)
    assert np.allclose(parts[1], P[chunk:2 * chunk].T @ R[chunk:2 * chunk], rtol=1e-13, atol=1e-12)
    sq = np.empty((nch, ka))
    K.colsq_parts(R, chunk, sq)
    assert np.allclose(sq.sum(axis=0), (R ** 2).sum(axis=0), rtol=1e-13)
    X1, R1 = X.copy(), R.copy()
    K.block_step(X1, R1, P, Q, alpha)
    assert np.allclose(X1, X + P @ alpha, rtol=1e-13, atol=1e-12)
    assert np.allclose(R1, R - Q @ alpha, rtol=1e-13, atol=1e-12)
    out = np.empty((n, ka))
    K.block_directions(P, Z, beta, chunk, out)
    assert np.allclose(out, Z + P @ beta, rtol=1e-13, atol=1e-12)
    # in place (square coefficient block): every row of P is read before it is written
    P2, Z2, b2 = P[:, :ka].copy(), Z.copy(), beta[:ka].copy()
    ref = Z2 + P2 @ b2
    K.block_directions(P2, Z2, b2, chunk, P2)
    assert np.allclose(P2, ref, rtol=1e-13, atol=1e-12)
    # the partial sums are per fixed chunk: bitwise the same on 1 and on all threads
    threads = numba.get_num_threads()
    outs = []
    try:
        for t in sorted({1, numba.config.NUMBA_NUM_THREADS}):
            numba.set_num_threads(t)
            outs.append(np.empty_like(parts))
            K.gram_parts(P, R, chunk, outs[-1])
    finally:
        numba.set_num_threads(threads)
    assert all(np.array_equal(o, parts) for o in outs)


def test_zero_rows_and_deflation_csr_kernels_equal_numpy_scipy_and_do_not_depend_on_threads():
    """The V-cycle's parallel zeroing and the deflation's row-parallel CSR products: the same
    numbers as numpy/scipy (bit for bit: each row summed over its entries in order, as scipy
    does), and the same on 1 and on all threads."""
    import numba
    from homogenize.solvers import Deflation
    from homogenize.solvers.amg import zeros_block
    rng = np.random.default_rng(8)
    X = rng.normal(size=(K.PARALLEL_MIN_ROWS + 7, 3))
    K.zero_rows(X)
    assert not X.any()
    Z0 = zeros_block(rng.normal(size=(K.PARALLEL_MIN_ROWS, 2)))
    assert Z0.shape == (K.PARALLEL_MIN_ROWS, 2) and not Z0.any()
    n, m, k = 3000, 40, 5
    A = sp.random(m, 900, density=0.05, random_state=3, format="csr")
    A.sort_indices()
    rows = np.sort(rng.choice(n, size=900, replace=False)).astype(np.int64)
    Y = rng.normal(size=(n, k))
    out = np.empty((m, k))
    C = rng.normal(size=(m, k))
    results = []
    threads = numba.get_num_threads()
    try:
        for t in sorted({1, numba.config.NUMBA_NUM_THREADS}):
            numba.set_num_threads(t)
            K.csr_gather_matmat(A.indptr, A.indices, A.data, rows, Y, out)
            assert np.array_equal(out, A @ Y[rows])
            X = Y.copy()
            K.csr_scatter_matmat(A.T.tocsr().indptr, A.T.tocsr().indices, A.T.tocsr().data, C,
                                 rows, X, -1.0)
            want = Y.copy()
            want[rows] -= A.T.tocsr() @ C
            assert np.array_equal(X, want)
            results.append((out.copy(), X))
    finally:
        numba.set_num_threads(threads)
    assert all(np.array_equal(a, results[0][0]) and np.array_equal(b, results[0][1])
               for a, b in results)
    # the Deflation's kernel path (C-contiguous blocks) against its scipy path (a strided view)
    Zs = sp.random(n, 6, density=0.2, random_state=4, format="csr")
    KZ = sp.random(n, 6, density=0.3, random_state=5, format="csr")
    E = (Zs.T @ KZ).toarray() + 10 * np.eye(6)
    defl = Deflation(Zs, KZ, lambda y: np.linalg.solve(E, y))
    R = rng.normal(size=(n, 2 * k))
    blk, view = np.ascontiguousarray(R[:, ::2]), R[:, ::2].copy(order="F")
    assert not defl._block(view) and defl._block(blk)
    a, b = blk.copy(), blk.copy()
    defl.correct(a, b)
    c, d = view.copy(order="F"), view.copy(order="F")
    defl.correct(c, d)
    assert np.array_equal(a, c) and np.array_equal(b, d)
    defl.project(a)
    defl.project(c)
    assert np.array_equal(a, c)
    assert np.array_equal(defl.start(blk), defl.start(view))
