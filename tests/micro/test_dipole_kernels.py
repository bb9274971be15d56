"""Each dipole kernel of micro/_kernels.py against a plain-numpy reference on a small input."""
import math

import numpy as np
import pytest
from scipy.interpolate import BSpline
from scipy.special import erfc

from micro import _kernels as K

RNG = np.random.default_rng(42)


def _np_dipole_field(src, mom, obs):
    d = obs[:, None, :] - src[None, :, :]
    r2 = np.einsum("ijk,ijk->ij", d, d)
    ok = r2 > 0
    r2s = np.where(ok, r2, 1.0)
    mr = np.einsum("ijk,jk->ij", d, mom)
    h = (3 * mr[..., None] * d / r2s[..., None] - mom[None]) / r2s[..., None] ** 1.5
    return np.where(ok[..., None], h, 0.0).sum(axis=1)


def test_direct_field_serial_and_parallel():
    src = RNG.normal(size=(37, 3))
    mom = RNG.normal(size=(37, 3))
    obs = np.concatenate([RNG.normal(size=(300, 3)), src[:5]])   # some observers on sources
    ref = _np_dipole_field(src, mom, obs)
    for fn in (K.dipole_field_direct, K.dipole_field_direct_par):
        out = np.empty((3, obs.shape[0]))
        fn(np.ascontiguousarray(src.T), np.ascontiguousarray(mom.T), np.ascontiguousarray(obs.T),
           out)
        # same operations in another order: a few ulps of the largest term
        np.testing.assert_allclose(out.T, ref, rtol=1e-11, atol=1e-11 * np.abs(ref).max())


def test_direct_field_bitwise_independent_of_threads():
    """Each observer sums its sources in the same order whatever the blocks and threads: the
    serial, 1-thread and all-thread results are identical, not just close (600 observers: three
    blocks, the last one partial)."""
    import numba
    src = np.ascontiguousarray(RNG.normal(size=(3, 211)))
    mom = np.ascontiguousarray(RNG.normal(size=(3, 211)))
    obs = np.ascontiguousarray(RNG.normal(size=(3, 600)))
    outs = []
    before = numba.get_num_threads()
    try:
        for fn, nt in ((K.dipole_field_direct, 1), (K.dipole_field_direct_par, 1),
                       (K.dipole_field_direct_par, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(nt)
            out = np.empty((3, 600))
            fn(src, mom, obs, out)
            outs.append(out)
    finally:
        numba.set_num_threads(before)
    for o in outs[1:]:
        np.testing.assert_array_equal(o, outs[0])


def test_b123_against_closed_forms():
    a = 3.7
    for r in (0.01, 0.2, 0.9):
        b1, b2, b3 = K.ewald_b123(r, a)
        e = 2 * a / math.sqrt(math.pi) * math.exp(-a * a * r * r)
        assert math.isclose(b1, (erfc(a * r) + r * e) / r ** 3, rel_tol=1e-13)
        assert math.isclose(b2, (3 * erfc(a * r) + r * e * (3 + 2 * a * a * r * r)) / r ** 5,
                            rel_tol=1e-13)
        # B3 = -B2'(r) / r, checked by a central difference (step 1e-6 r: error ~1e-9)
        h = 1e-6 * r
        d = (K.ewald_b123(r + h, a)[1] - K.ewald_b123(r - h, a)[1]) / (2 * h)
        assert math.isclose(b3, -d / r, rel_tol=1e-7)


def _np_real(pos, mom, alpha, rc, nimg=1):
    n = len(pos)
    h = np.zeros((n, 3))
    f = np.zeros((n, 3))
    v = np.zeros((3, 3))
    for i in range(n):
        for j in range(n):
            for s in np.ndindex(2 * nimg + 1, 2 * nimg + 1, 2 * nimg + 1):
                d = pos[i] - pos[j] - (np.array(s) - nimg)
                r = np.linalg.norm(d)
                if r == 0 or r >= rc:
                    continue
                b1, b2, b3 = K.ewald_b123(r, alpha)
                h[i] += b2 * (mom[j] @ d) * d - b1 * mom[j]
                mi, mj = mom[i], mom[j]
                p = (b2 * (mi @ mj) - b3 * (mi @ d) * (mj @ d)) * d + b2 * ((mj @ d) * mi + (mi @ d) * mj)
                f[i] += p
                v += 0.5 * np.outer(d, p)
    return h, f, v


def test_ewald_real_against_numpy_any_cutoff():
    pos = RNG.random((9, 3))
    mom = RNG.normal(size=(9, 3))
    from micro._ewald import _CellList
    for alpha, rc in ((6.0, 0.3), (3.0, 0.8)):     # rc > L/2: several images of a pair
        cl = _CellList(pos, rc)
        h = np.empty((9, 3))
        f = np.empty((9, 3))
        v = np.empty((9, 9))
        K.ewald_real(pos, mom, np.arange(9), cl.order, cl.cell_start, cl.ncell, cl.noff, alpha,
                     rc, True, h, f, v)
        hr, fr, vr = _np_real(pos, mom, alpha, rc)
        np.testing.assert_allclose(h, hr, rtol=1e-12, atol=1e-12 * np.abs(hr).max())
        np.testing.assert_allclose(f, fr, rtol=1e-12, atol=1e-12 * np.abs(fr).max())
        np.testing.assert_allclose(v.sum(0).reshape(3, 3), vr, rtol=1e-11, atol=1e-12 * np.abs(vr).max())
        tg = np.array([7, 2])                  # a subset of targets gives the same rows
        hs = np.empty((2, 3))
        K.ewald_real(pos, mom, tg, cl.order, cl.cell_start, cl.ncell, cl.noff, alpha, rc, False,
                     hs, f, v)
        np.testing.assert_array_equal(hs, h[tg])


def test_structure_factor_and_gather():
    pos = RNG.random((11, 3))
    mom = RNG.normal(size=(11, 3))
    kv = 2 * np.pi * RNG.integers(-3, 4, size=(5, 3)).astype(float)
    t = np.empty((5, 6))
    K.ewald_structure_factor(pos, mom, kv, t)
    ref = np.exp(-1j * kv @ pos.T) @ mom
    np.testing.assert_allclose(t[:, :3] + 1j * t[:, 3:], ref, atol=1e-12)
    coef = RNG.normal(size=(5, 2))
    h = np.empty((11, 3))
    f = np.empty((11, 3))
    K.ewald_recip_gather(pos, mom, kv, coef, h, f)
    z = (coef[:, 0] + 1j * coef[:, 1])[None, :] * np.exp(1j * pos @ kv.T)      # (N, K)
    np.testing.assert_allclose(h, z.real @ kv, atol=1e-11)
    np.testing.assert_allclose(f, (z.imag * (mom @ kv.T)) @ kv, atol=1e-11)


def test_bspline_weights_against_scipy():
    for p in (4, 6, 8):
        w = np.empty(p)
        card = BSpline.basis_element(np.arange(p + 1), extrapolate=False)   # M_p on [0, p]
        for frac in (0.0, 0.25, 0.999):
            K.pme_bspline(frac, p, w)
            np.testing.assert_allclose(w, np.nan_to_num(card(frac + np.arange(p))), atol=1e-14)
            assert abs(w.sum() - 1) < 1e-14


def _slabs(gpos, kk, nslab):
    bounds = np.arange(nslab + 1) * kk // nslab
    slab = np.searchsorted(bounds, np.floor(gpos[:, 0]), side="right") - 1
    order = np.argsort(slab, kind="stable").astype(np.int64)
    return order, np.searchsorted(slab[order], np.arange(nslab + 1)).astype(np.int64)


def _scratch(s, p):
    return np.empty((s, 3, p)), np.empty((s, 3, p), dtype=np.int64), np.empty((s, 9))


@pytest.mark.parametrize("nc", [2, 3, 9])
def test_spread_gather_adjoint_and_numpy(nc):
    """Every component count: 3 (the field) has its own unrolled loops, 9 is the gradient's."""
    p, kk = 4, 8
    gpos = RNG.random((6, 3)) * kk
    gpos[0, 0] = kk - 1e-9                   # a particle whose stencil wraps around the box
    val = RNG.normal(size=(6, nc))
    order, start = _slabs(gpos, kk, 1)
    grid = np.zeros((kk, kk, kk, nc))
    K.pme_spread(gpos, val, p, order, start, *_scratch(1, p), grid)
    ref = np.zeros_like(grid)
    card = BSpline.basis_element(np.arange(p + 1), extrapolate=False)
    for i, u in enumerate(gpos):
        for g in np.ndindex(kk, kk, kk):
            w = 1.0
            for a in range(3):
                x = (u[a] - g[a]) % kk          # M_p(u - g) on the periodic grid
                w *= np.nan_to_num(card(x)) if x < p else 0.0
            ref[g[0], g[1], g[2], :] += w * val[i]
    np.testing.assert_allclose(grid, ref, atol=1e-13)
    G = RNG.normal(size=(kk, kk, kk, nc))
    out = np.full((6, nc), np.nan)              # gather overwrites, never accumulates
    K.pme_gather(gpos, G, p, *_scratch(4, p)[:2], out)
    # gather is the transpose of spread: <spread(v), G> = <v, gather(G)>
    assert math.isclose(np.sum(grid * G), np.sum(val * out), rel_tol=1e-12)
    out1 = np.empty((6, nc))
    K.pme_gather(gpos, G, p, *_scratch(1, p)[:2], out1)       # chunking changes nothing
    np.testing.assert_array_equal(out, out1)


def test_parallel_spread_slabs_equal_serial():
    # 4 slabs of 6 planes (>= p = 6) run as two race-free colours; the result must be the
    # serial one to rounding (contributions to a grid point arrive in another order), and
    # bitwise the same on a second call (fixed order whatever the threads)
    p, kk, n = 6, 24, 500
    gpos = RNG.random((n, 3)) * kk
    val = RNG.normal(size=(n, 3))
    o1, s1 = _slabs(gpos, kk, 1)
    o4, s4 = _slabs(gpos, kk, 4)
    assert np.all(np.diff(s4) > 0)
    g1 = np.zeros((kk, kk, kk, 3))
    K.pme_spread(gpos, val, p, o1, s1, *_scratch(1, p), g1)
    g4 = np.zeros((kk, kk, kk, 3))
    K.pme_spread(gpos, val, p, o4, s4, *_scratch(2, p), g4)
    g4b = np.zeros((kk, kk, kk, 3))
    K.pme_spread(gpos, val, p, o4, s4, *_scratch(2, p), g4b)
    np.testing.assert_allclose(g4, g1, rtol=0, atol=1e-13 * np.abs(g1).max())
    np.testing.assert_array_equal(g4, g4b)


def _kspace_case(kk=6):
    sh = (kk, kk, kk // 2 + 1, 3)
    qh = RNG.normal(size=sh) + 1j * RNG.normal(size=sh)
    kv = RNG.normal(size=kk)
    kvz = RNG.normal(size=kk // 2 + 1)
    g = RNG.random((kk, kk, kk // 2 + 1))
    g[0, 0, 0] = 0.0                             # k = 0 is excluded (tin-foil)
    return qh, kv, kvz, g


def test_pme_influence_against_numpy():
    qh, kv, kvz, g = _kspace_case()
    out = np.empty_like(qh)
    K.pme_influence(qh, kv, kvz, g, 2.0, out)
    kx, ky, kz = kv[:, None, None], kv[None, :, None], kvz[None, None, :]
    s = kx * qh[..., 0] + ky * qh[..., 1] + kz * qh[..., 2]
    for a, k in enumerate((kx, ky, kz)):
        np.testing.assert_allclose(out[..., a], -2.0 * g * s * k, atol=1e-12)


def test_pme_influence_grad_against_numpy():
    qh, kv, kvz, g = _kspace_case()
    kk = qh.shape[0]
    wz = RNG.random(kk // 2 + 1)
    out = np.empty(qh.shape[:3] + (9,), dtype=complex)
    acc = np.full((kk, 10), np.nan)
    K.pme_influence_grad(qh, kv, kvz, g, wz, 2.0, 0.3, out, acc)
    ks = np.broadcast_arrays(kv[:, None, None], kv[None, :, None], kvz[None, None, :])
    s = sum(ks[a] * qh[..., a] for a in range(3))
    t = -2.0 * g * s
    # all nine i k_b k_a t, then check the six stored ones and the symmetry that allows it
    full = np.stack([np.stack([1j * ks[b] * ks[a] * t for b in range(3)]) for a in range(3)])
    np.testing.assert_allclose(full, np.swapaxes(full, 0, 1), atol=0)
    for a in range(3):
        np.testing.assert_allclose(out[..., a], ks[a] * t, atol=1e-12)
    for c, (a, b) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
        np.testing.assert_allclose(out[..., 3 + c], full[a, b], atol=1e-12)
    k2 = ks[0] ** 2 + ks[1] ** 2 + ks[2] ** 2
    k2[0, 0, 0] = 1.0
    wg = wz * g
    ss = np.abs(s) ** 2
    u = 0.5 * np.sum(wg * ss)
    w = wg * (1 / k2 + 0.3) * ss
    p = np.array([[np.sum(w * ks[a] * ks[b]) - np.sum(wg * np.real(np.conj(s) * ks[a] * qh[..., b]))
                   for b in range(3)] for a in range(3)])
    tot = acc.sum(axis=0)
    assert math.isclose(tot[0], u, rel_tol=1e-12)
    np.testing.assert_allclose(tot[1:].reshape(3, 3), p, rtol=1e-12, atol=1e-12 * np.abs(p).max())


def test_pme_solve_bitwise_on_one_and_all_threads():
    """The whole PME dipole solve (numba kernels and the FFT, whose workers follow numba's
    thread count) gives the same moments and forces to the last bit on 1 thread and on all."""
    import numba
    from micro import generate_rve
    from micro.dipoles import solve
    rve = generate_rve(0.035, 3500, 4)
    before = numba.get_num_threads()
    out = []
    try:
        for nt in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(nt)
            st = solve(rve, 0.1, 1.78, summation="pme")
            out.append((st.moments_Am2.copy(), st.total_force_N.copy()))
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])
