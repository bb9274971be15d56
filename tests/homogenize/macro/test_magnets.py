"""Real magnet fields (magpylib) and the body force they exert along the strip."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0
from scipy.integrate import simpson
from scipy.spatial.transform import Rotation

from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material
from homogenize.macro.magnets import (Coil, PermanentMagnet, body_force_along_strip,
                                      linear_magnetization, sample_field,
                                      tabulated_magnetization)
from micro.common.validate import InputError
from micro.demag import prism_demag_factors

STRIP = Strip(19.369e-3, 5e-3, 1e-3)


def _axis_points(z):
    return np.column_stack([np.zeros_like(z), np.zeros_like(z), z])


def test_cylinder_magnet_on_axis_closed_form_and_gradient():
    Br, D, Lm = 1.2, 10e-3, 6e-3
    R = D / 2
    mag = PermanentMagnet("cylinder", (D, Lm), Br)
    zp = np.array([3.5e-3, 5e-3, 1e-2, 3e-2])      # above the top face z = Lm / 2
    B, g = sample_field(mag, _axis_points(zp))
    z = zp - Lm / 2                                 # distance from the top face

    def closed(z):
        return Br / 2 * ((z + Lm) / np.hypot(z + Lm, R) - z / np.hypot(z, R))
    # magpylib's general cylinder field against the on-axis closed form: both analytic
    np.testing.assert_allclose(B[:, 2], closed(z), rtol=1e-10)
    np.testing.assert_allclose(B[:, :2], 0.0, atol=1e-12 * Br)
    dB = Br / 2 * (R**2 / np.hypot(z + Lm, R) ** 3 - R**2 / np.hypot(z, R) ** 3)
    # central differences with h = 1e-4 * 6 mm: error ~ (h/d)^2 / 6 < 1e-8 plus round-off
    # ~1e-14 d / h < 1e-9 (sample_field's docstring): 1e-6 is a safe margin
    np.testing.assert_allclose(g[:, 2], dB, rtol=1e-6)
    np.testing.assert_allclose(g[:, :2], 0.0, atol=1e-6 * np.abs(dB).max())


def test_solenoid_on_axis_closed_form_and_gradient():
    R, ell, n_turns, current = 10e-3, 20e-3, 200, 1.5
    coil = Coil(R, ell, n_turns, current)
    z = np.array([0.0, 5e-3, 9e-3, 11e-3, 15e-3, 4e-2])
    B, g = sample_field(coil, _axis_points(z))

    def sheet(z):
        return MU0 * n_turns * current / (2 * ell) * (
            (z + ell / 2) / np.hypot(z + ell / 2, R) - (z - ell / 2) / np.hypot(z - ell / 2, R))

    def dsheet(z):
        return MU0 * n_turns * current / (2 * ell) * (
            R**2 / np.hypot(z + ell / 2, R) ** 3 - R**2 / np.hypot(z - ell / 2, R) ** 3)
    # the loops sit at the midpoints of equal slices: the midpoint rule of the current sheet,
    # relative error ~ (pitch / R)^2 / 24 = 4e-6 here; 1e-4 leaves margin for the gradient
    np.testing.assert_allclose(B[:, 2], sheet(z), rtol=1e-4)
    np.testing.assert_allclose(g[:, 2], dsheet(z), rtol=1e-4, atol=1e-4 * np.abs(dsheet(z)).max())
    # single loop: mu0 I / (2R) at its centre (to round-off of magpylib's closed form)
    loop = Coil(R, 0.0, 1, current)
    assert sample_field(loop, np.zeros((1, 3)))[0][0, 2] == pytest.approx(
        MU0 * current / (2 * R), rel=1e-12)


def test_rotating_the_source_rotates_the_field():
    # the magnet turned from z onto x (90 deg about y) sees the turned points and gives the
    # turned field: B_b(R p) = R B_a(p), grad|B|_b(R p) = R grad|B|_a(p)
    a = PermanentMagnet("cylinder", (8e-3, 4e-3), 1.0, position_m=(1e-3, 0, 0))
    b = PermanentMagnet("cylinder", (8e-3, 4e-3), 1.0, position_m=(0, 0, -1e-3),
                        direction=(1, 0, 0), axis=(1, 0, 0))
    rot = Rotation.from_rotvec([0, np.pi / 2, 0])
    p = np.random.default_rng(3).normal(scale=2e-2, size=(6, 3)) + np.array([0, 0, 3e-2])
    Ba, ga = sample_field(a, p)
    Bb, gb = sample_field(b, rot.apply(p))
    np.testing.assert_allclose(Bb, rot.apply(Ba), rtol=1e-9, atol=1e-12 * np.abs(Ba).max())
    # finite differences along rotated axes: equal to the FD accuracy (1e-6)
    np.testing.assert_allclose(gb, rot.apply(ga), rtol=1e-6, atol=1e-6 * np.abs(ga).max())


def _magnet_below_tip(z=-8e-3):
    return PermanentMagnet("cylinder", (10e-3, 5e-3), 1.2,
                           position_m=(STRIP.length_m, STRIP.width_m / 2, z))


def test_integrated_body_force_equals_the_sum_over_the_strip():
    mag = _magnet_below_tip()
    law = linear_magnetization(0.1, 2e5)
    res = body_force_along_strip(mag, STRIP, law, 201, n_cross=4)
    # independent sum: midpoint rule on a 3D grid of cells, straight from sample_field
    nx, ny, nz = 400, 20, 4
    L, w, t = STRIP.length_m, STRIP.width_m, STRIP.thickness_m
    cx = (np.arange(nx) + 0.5) * L / nx
    cy = (np.arange(ny) + 0.5) * w / ny
    cz = (np.arange(nz) + 0.5) * t / nz
    pts = np.stack(np.meshgrid(cx, cy, cz, indexing="ij"), axis=-1).reshape(-1, 3)
    B, g = sample_field(mag, pts)
    M = law(np.linalg.norm(B, axis=1) / MU0)
    total = (M[:, None] * g).sum(axis=0) * (L * w * t / pts.shape[0])
    # Simpson along x on 201 stations and 4x4 Gauss points across against the midpoint rule on
    # 400 x 20 x 4 cells: the midpoint rule's O(h^2) error (~1e-4 relative with the field
    # varying on the 3 mm scale of the magnet distance) dominates
    np.testing.assert_allclose(res.total_force_N, total, rtol=1e-3,
                               atol=1e-3 * np.abs(total).max())
    assert res.total_force_N[2] < 0    # pulled towards the magnet below


def test_body_force_is_the_gradient_of_the_co_energy():
    # with M along H, f = grad W(|H|), W = mu0 int_0^H M: the net force is minus the derivative
    # of the strip's co-energy with respect to the magnet's position, computed from |B| only
    chi, Ms = 0.1, 1.5e4           # saturates over part of the strip
    law = linear_magnetization(chi, Ms)

    def W(H):
        Hs = Ms / chi
        return MU0 * np.where(H < Hs, 0.5 * chi * H**2, 0.5 * chi * Hs**2 + Ms * (H - Hs))

    z0, dz = -8e-3, 1e-6
    res = body_force_along_strip(_magnet_below_tip(z0), STRIP, law, 101)

    def coenergy(z):
        r = body_force_along_strip(_magnet_below_tip(z), STRIP, law, 101)
        w = np.einsum("c,nc->n", r.weights, W(r.H_applied_A_m))
        return STRIP.width_m * STRIP.thickness_m * simpson(w, x=r.x_m)
    dU = (coenergy(z0 + dz) - coenergy(z0 - dz)) / (2 * dz)
    # same quadrature points in both: only the central-difference errors remain (dz / d ~ 1e-4
    # squared, and round-off ~1e-16 U / dz): 1e-5
    assert res.total_force_N[2] == pytest.approx(-dU, rel=1e-5)


def test_demagnetization_in_the_linear_regime_and_saturation():
    N = prism_demag_factors(STRIP.length_m, STRIP.width_m, STRIP.thickness_m)[2]
    chi = 0.11
    mag = _magnet_below_tip()
    f0 = body_force_along_strip(mag, STRIP, linear_magnetization(chi), 41).f_N_m3
    fN = body_force_along_strip(mag, STRIP, linear_magnetization(chi), 41,
                                demag_factor=N).f_N_m3
    # linear: M = chi H_a / (1 + N chi) exactly; the root finder solves to round-off
    np.testing.assert_allclose(fN, f0 / (1 + N * chi), rtol=1e-12, atol=1e-12 * np.abs(f0).max())
    # saturating law: H_in + N M(H_in) = H_a holds to round-off at every point
    law = linear_magnetization(chi, 5e3)
    r = body_force_along_strip(mag, STRIP, law, 41, demag_factor=N)
    np.testing.assert_allclose(r.H_internal_A_m + N * law(r.H_internal_A_m), r.H_applied_A_m,
                               rtol=1e-13)
    assert np.any(r.M_A_m == 5e3) and np.any(r.M_A_m < 5e3)   # both regimes on the strip


@pytest.mark.parametrize("N", [0.01, 1 / 3, 0.7721, 1.0])
def test_internal_field_roots_of_a_table_law_exact_in_few_evaluations(N):
    """h + N M(h) = Ha for a piecewise-linear M (a table): against the root found segment by
    segment in closed form, to a few ulps of Ha, in at most 26 evaluations of M (bisection
    took 52; about 10 on fields between the nodes, up to 23 with Ha on the kinks too)."""
    from homogenize.macro.magnets import _internal_field
    rng = np.random.default_rng(11)
    H = np.concatenate([[0.0], np.sort(rng.uniform(1.0, 2e6, 12))])
    Mt = 1.2e5 * np.tanh(H / 3e5)
    calls = []

    def law(h):
        calls.append(h.size)
        return np.interp(h, H, Mt)
    G = H + N * Mt                         # g + Ha at the nodes, increasing
    Ha = np.concatenate([rng.uniform(0.0, G[-1], 3000), G[:-1], [0.0, 1e-300]])
    h = _internal_field(law, Ha, N)
    k = np.clip(np.searchsorted(G, Ha, side="right") - 1, 0, len(H) - 2)
    exact = H[k] + (Ha - G[k]) * (H[k + 1] - H[k]) / (G[k + 1] - G[k])
    assert np.max(np.abs(h - exact) / np.maximum(Ha, 1e-300)) < 8 * np.finfo(float).eps
    assert np.all((h >= 0) & (h <= Ha))
    assert len(calls) <= 26, len(calls)          # half of bisection's


def test_varying_force_bends_the_strip_like_its_mean_in_a_uniform_field_limit():
    # a magnet far away: the force is nearly uniform along the strip, and the solvers given the
    # profile agree with the uniform solve at its mean within the profile's variation
    mag = PermanentMagnet("cylinder", (40e-3, 40e-3), 1.3, position_m=(STRIP.length_m / 2,
                                                                        STRIP.width_m / 2, -0.3))
    r = body_force_along_strip(mag, STRIP, linear_magnetization(0.1), 21)
    q = r.transverse_N_m3
    spread = (q.max() - q.min()) / q.mean()
    assert 0 < spread < 0.05
    mat = Material()
    a = solve_cantilever(STRIP, mat, r.profile(), model="elastica").tip_m
    b = solve_cantilever(STRIP, mat, float(q.mean()), model="elastica").tip_m
    assert a == pytest.approx(b, rel=spread)


def test_overlap_and_bad_input_are_refused():
    inside = PermanentMagnet("cuboid", (4e-3, 4e-3, 4e-3), 1.0, position_m=(5e-3, 2.5e-3, 0.0))
    with pytest.raises(InputError, match="overlaps the strip"):
        body_force_along_strip(inside, STRIP, linear_magnetization(0.1))
    # the winding of a coil cutting through the strip is refused; a strip inside the bore is not
    cutting = Coil(2e-3, 10e-3, 50, 1.0, position_m=(10e-3, 2.5e-3, 0.5e-3), axis=(1, 0, 0))
    with pytest.raises(InputError, match="winding"):
        body_force_along_strip(cutting, STRIP, linear_magnetization(0.1))
    bore = Coil(20e-3, 40e-3, 50, 1.0, position_m=(10e-3, 2.5e-3, 0.5e-3), axis=(1, 0, 0))
    body_force_along_strip(bore, STRIP, linear_magnetization(0.1), 5)
    with pytest.raises(InputError, match="remanence_T"):
        PermanentMagnet("cuboid", (1e-3, 1e-3, 1e-3), -1.0)
    with pytest.raises(InputError, match="dimensions_m"):
        PermanentMagnet("cylinder", (1e-3, 1e-3, 1e-3), 1.0)
    with pytest.raises(InputError, match="shape"):
        PermanentMagnet("sphere", (1e-3,), 1.0)
    with pytest.raises(InputError, match="turns"):
        Coil(1e-2, 1e-2, 2.5, 1.0)
    with pytest.raises(InputError, match="demag_factor"):
        body_force_along_strip(_magnet_below_tip(), STRIP, linear_magnetization(0.1),
                               demag_factor=1.5)
    table = tabulated_magnetization([0.0, 1e3], [0.0, 1e2])
    with pytest.raises(InputError, match="outside the table"):
        body_force_along_strip(_magnet_below_tip(), STRIP, table)
    assert math.isclose(float(table(np.array(500.0))), 50.0)
