"""Follower field, pull-in and contact of the magnet-driven cantilever (homogenize.macro.pullin)."""
import numpy as np
import pytest

from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip
from homogenize.macro.magnets import PermanentMagnet, body_force_along_strip, \
    linear_magnetization
from homogenize.macro.pullin import MagnetElastica, one_mode_pullin, place_magnet, \
    pullin_sweep, trace_branch
from micro.common.validate import InputError
from micro.demag import prism_demag_factors
from micro.materials import FE, ElasticMaterial

STRIP = Strip(20e-3, 5e-3, 1e-3)
L = STRIP.length_m
# 3 vol% iron: chi ~ 3 phi = 0.1 (dilute spheres of a soft ferromagnet), saturating at phi Ms_Fe
M_OF_H = linear_magnetization(0.1, 0.03 * FE.Ms_A_m)
NZ = prism_demag_factors(20e-3, 5e-3, 1e-3)[2]
MAGNET = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3)
# a stiffer strip (20 MPa) keeps the pull-in deflection small (~L/10), where one mode and
# small rotations are a fair model; the seed's 2 MPa strip snaps at a larger gap
STIFF = ElasticMaterial(20e6, 0.45, 1210.0)
SOFT = ElasticMaterial(2e6, 0.45, 1210.0)


def _newton(system, u, p, max_it=60, damp=0.1):
    for _ in range(max_it):
        R, J, _ = system(u, p)
        du = np.linalg.solve(J, -R)
        u = u + min(1.0, damp / max(np.abs(du[:-1] if du.size > 1 else du).max(), 1e-300)) * du
        if np.abs(du).max() < 1e-13:
            return u
    raise AssertionError("Newton did not converge")


# ------------------------------------------------------------------ the 1-DOF spring

@pytest.mark.parametrize("n", [2, 4])
def test_spring_pull_in_at_a_third_or_fifth_of_the_gap(n):
    k, c = 3.0, 0.7

    def system(u, g):
        x = u[0]
        d = g - x
        return (np.array([k * x - c / d**n]), np.array([[k - n * c / d ** (n + 1)]]),
                np.array([n * c / d ** (n + 1)]))
    # analytic fold: k = n c / (g - x)^(n+1) and k x = c / (g - x)^n give x = g / (n + 1),
    # x* = (c / (k n^n))^(1 / (n+1))
    xs = (c / (k * n**n)) ** (1.0 / (n + 1))
    gs = (n + 1) * xs
    tr = trace_branch(system, [0.0], 5 * gs, direction=-1.0, p_max=10 * gs, u_scale=gs,
                      p_scale=gs, r_scale=k * gs)
    assert len(tr.limit_points) == 1
    lp = tr.limit_points[0]
    # the fold is located by Brent's method on the tangent to 1e-13 in arc length, the points
    # corrected to 1e-10: the gap (stationary at the fold) to round-off, x to ~1e-10
    assert lp.p == pytest.approx(gs, rel=1e-10)
    assert lp.u[0] == pytest.approx(gs / (n + 1), rel=1e-8)
    # stable (k - n c / d^(n+1) > 0) before the fold, unstable after it
    assert tr.stable[:lp.index].all() and not tr.stable[lp.index + 1:].any()
    assert np.all(np.diff(tr.p[:lp.index + 1]) < 0) and np.all(np.diff(tr.p[lp.index:]) > 0)
    # the fold itself ends the stable part, whichever side of 0 its eigenvalue's round-off
    # falls: stability tests shifted by +-1e-9 k (far beyond the located fold's eigenvalue,
    # far inside the steps') classify every point alike, the fold as stable
    assert tr.stable[lp.index]
    for margin in (1e-9 * k, -1e-9 * k):
        tr_m = trace_branch(system, [0.0], 5 * gs, direction=-1.0, p_max=10 * gs, u_scale=gs,
                            p_scale=gs, r_scale=k * gs,
                            stability=lambda u, p, J, m=margin: bool(J[0, 0] > m))
        assert [x.index for x in tr_m.limit_points] == [lp.index]
        assert np.array_equal(tr_m.stable, tr.stable)


# ------------------------------------------------------------------ far gaps: the dead load

def _dead_and_follower(g):
    mag = place_magnet(MAGNET, STRIP, g)
    prof = body_force_along_strip(mag, STRIP, M_OF_H, 201, demag_factor=NZ, n_cross=3)
    v_ref, _ = cf.elastica_tip_deflection(prof.profile(), L, STRIP.width_m, STRIP.thickness_m,
                                          SOFT.E_Pa)
    out = {}
    for follower in (False, True):
        m = MagnetElastica(STRIP, SOFT, mag, M_OF_H, n_segments=32, n_cross=3,
                           demag_factor=NZ, follower=follower)
        u = _newton(m.system_free, np.zeros(m.N), g)
        out[follower] = m.tip_deflection_m(u)
    return v_ref, out


def test_far_gap_reproduces_the_dead_load_elastica():
    v_ref, out = _dead_and_follower(40e-3)
    # the dead-load discrete elastica against the closed-form one with the same profile: the
    # axial component f_x adds a moment ~ f_x delta (relative ~ delta / L ~ 1e-4) and the
    # discretization error is O(h^2) ~ (1/32)^2 / 12 ~ 1e-4 (measured 3e-4): 1e-3
    assert out[False] == pytest.approx(v_ref, rel=1e-3)
    # at 40 mm the tip moves 1.6 um: the follower correction, ~ delta |d ln f / dz| ~ 1.6 um *
    # 4 / 40 mm ~ 2e-4, vanishes within the same 1e-3, and has the sign of an attraction
    assert out[True] == pytest.approx(v_ref, rel=1e-3)
    assert out[True] > out[False]
    # closer, the correction grows: at 15 mm it is at least 10 times the one at 40 mm
    v15, out15 = _dead_and_follower(15e-3)
    corr40 = out[True] / out[False] - 1.0
    corr15 = out15[True] / out15[False] - 1.0
    assert corr15 > 10 * corr40 > 0


# ------------------------------------------------------------------ pull-in: ROM and convergence

def _fold(n_segments):
    mag = place_magnet(MAGNET, STRIP, 12e-3)
    m = MagnetElastica(STRIP, STIFF, mag, M_OF_H, n_segments=n_segments, n_cross=2,
                       demag_factor=NZ)
    tr = trace_branch(m.system_free, m.linear_guess(12e-3), 12e-3, direction=-1.0,
                      p_min=1e-3, r_scale=m.EI / L, u_scale=np.sqrt(m.N), p_scale=L,
                      ds=0.02, ds_max=0.05, stop_at_fold=True)
    assert tr.event is not None and tr.event.name == "fold"
    return tr.event.p, m.tip_deflection_m(tr.event.u)


def test_pull_in_gap_against_one_mode_galerkin_and_converging():
    folds = {n: _fold(n) for n in (8, 16, 32)}
    g = np.array([folds[n][0] for n in (8, 16, 32)])
    # monotone convergence, second order (trapezoid kinematics and load, linear theta): the
    # ratio of successive differences ~4
    d1, d2 = g[1] - g[0], g[2] - g[1]
    assert np.sign(d1) == np.sign(d2) and abs(d2) < abs(d1)
    assert 2.5 < d1 / d2 < 6.0
    g_ext = g[2] + d2 / 3.0                 # Richardson
    rom = one_mode_pullin(STRIP, STIFF, MAGNET.__class__(
        "cylinder", (10e-3, 10e-3), 1.3, position_m=(L, STRIP.width_m / 2, 0.0)), M_OF_H,
        n_cross=2, demag_factor=NZ)
    # one mode: the uniform-load shape is stiffer than the true shape under a tip-heavy load
    # (3.2 vs 3 EI/L^3, at most 7 %), and the pull-in gap scales as k^(-1/(n+1)) with n ~ 3-4:
    # <= ~1.5 %; small rotations vs the elastica: (delta/L)^2 ~ 1 %. A few percent: 3 %
    assert rom.pull_in_gap_m == pytest.approx(g_ext, rel=3e-2)
    assert rom.pull_in_tip_deflection_m == pytest.approx(folds[32][1], rel=0.15)


# ------------------------------------------------------------------ contact

@pytest.mark.parametrize("n_segments", [16, 32])
def test_contact_tip_on_the_face_and_force_balance(n_segments):
    g = 5e-3                                # below the pull-in gap (6.7 mm) of this strip
    m = MagnetElastica(STRIP, STIFF, place_magnet(MAGNET, STRIP, g), M_OF_H,
                       n_segments=n_segments, n_cross=2, demag_factor=NZ)
    s = m.s[1:]
    theta = -(3 * g / (2 * L**3)) * (2 * L * s - s**2)      # a tip load's shape, tip at g
    u = _newton(m.system_contact, np.concatenate([theta, [0.01]]), g)
    th, lam = u[:-1], u[-1]
    # Lagrange multiplier: the tip gap is zero to round-off (no penalty)
    assert abs(m.tip_gap_m(th, g)) < 1e-12 * L
    assert lam > 0 and m.other_clearance_m(th, g) > 0
    assert m.stable_contact(u, g, m.system_contact(u, g)[1])
    # the contact force balances the magnetic pull minus the elastic reaction: moments about
    # the clamp, EI theta'(0) = M_magnetic + x_contact * lam, with theta'(0) from the shape by
    # a one-sided second-order difference and the magnetic moment summed at the cross-section
    # points; both O(h^2): 2e-3 at 16 segments, 5e-4 at 32 (measured 6e-4 and 2e-4)
    full = np.concatenate([[0.0], th])
    dth0 = (-3 * full[0] + 4 * full[1] - full[2]) / (2 * m.h)
    lam_balance = (m.EI * dth0 - m.magnetic_moment_about_clamp_Nm(th, g)) / m.tip_corner(th)[0]
    assert lam == pytest.approx(lam_balance, rel=2e-3 if n_segments == 16 else 5e-4)
    # and the magnetic pull exceeds the contact force (the clamp carries the rest)
    assert -m.magnetic_force_N(th, g)[1] > lam


# ------------------------------------------------------------------ bad input

def test_bad_input():
    mag = place_magnet(MAGNET, STRIP, 10e-3)
    with pytest.raises(InputError, match="below zero"):
        pullin_sweep(STRIP, SOFT, mag, M_OF_H, [5e-3, 2e-3, -1e-3])
    with pytest.raises(InputError, match="monotonic"):
        pullin_sweep(STRIP, SOFT, mag, M_OF_H, [5e-3, 2e-3, 3e-3])
    inside = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3, position_m=(L, 2.5e-3, -2e-3))
    with pytest.raises(InputError, match="overlaps the strip"):
        pullin_sweep(STRIP, SOFT, inside, M_OF_H)
    with pytest.raises(InputError, match="gap_m"):
        place_magnet(MAGNET, STRIP, -1e-3)
    tilted = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3, axis=(1.0, 0.0, 0.0))
    with pytest.raises(InputError, match="axis"):
        pullin_sweep(STRIP, SOFT, tilted, M_OF_H, [5e-3])
    far = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3, position_m=(5e-3, 2.5e-3, -0.02))
    with pytest.raises(InputError, match="tip"):
        MagnetElastica(STRIP, SOFT, far, M_OF_H)


# ------------------------------------------------------------------ the whole sweep

def test_pullin_sweep_round_trip_hysteresis():
    mag = place_magnet(MAGNET, STRIP, 12e-3)
    gaps = np.linspace(12e-3, 3e-3, 10)
    r = pullin_sweep(STRIP, STIFF, mag, M_OF_H, gaps, n_segments=16, n_cross=2,
                     demag_factor=NZ)
    # the same fold as the free-branch trace alone (same discretization, Brent-located)
    g16, d16 = _fold(16)
    assert r.snap and r.pull_in_gap_m == pytest.approx(g16, rel=1e-9)
    assert r.pull_in_tip_deflection_m == pytest.approx(d16, rel=1e-6)
    # hysteresis: the contact is released at a larger gap than the pull-in
    assert r.release_gap_m > r.pull_in_gap_m and r.release_by == "contact force zero"
    # on contact the tip gap is zero (Lagrange multiplier, Newton tolerance 1e-9 relative to
    # the residual scale: 1e-9 L), the contact force positive; free states keep a positive gap
    c = r.sweep_branch == "contact"
    assert c.any() and (~c).any()
    np.testing.assert_allclose(r.sweep_tip_gap_m[c], 0.0, atol=1e-9 * L)
    assert np.all(r.sweep_contact_force_N[c] > 0) and np.all(r.sweep_tip_gap_m[~c] > 0)
    # approach: free above the pull-in gap, contact below; retreat: contact up to the release
    n = len(gaps)
    fwd, back = r.sweep_gap_m[:n], r.sweep_gap_m[n - 1:]
    assert np.all((r.sweep_branch[:n] == "contact") == (fwd < r.pull_in_gap_m))
    assert np.all((r.sweep_branch[n - 1:] == "contact") == (back < r.release_gap_m))
    # the contact force at 5 mm equals the direct contact solve of the contact test (same
    # model, Newton to round-off)
    k5 = int(np.argmin(np.abs(r.sweep_gap_m - 5e-3)))
    m = MagnetElastica(STRIP, STIFF, place_magnet(MAGNET, STRIP, 5e-3), M_OF_H, n_segments=16,
                       n_cross=2, demag_factor=NZ)
    s = m.s[1:]
    u = _newton(m.system_contact, np.concatenate(
        [-(3 * 5e-3 / (2 * L**3)) * (2 * L * s - s**2), [0.01]]), 5e-3)
    assert r.sweep_contact_force_N[k5] == pytest.approx(u[-1], rel=1e-7)
    # the path: stable free states before the fold, unstable after it
    free = r.branch == "free"
    assert r.stable[0] and not r.stable[free][-1]


def test_realistic_case_pull_in_against_one_mode():
    """Issue 35's strip (2 MPa) and NdFeB cylinder: the fold of the free branch."""
    mag = place_magnet(MAGNET, STRIP, 30e-3)
    m = MagnetElastica(STRIP, SOFT, mag, M_OF_H, n_segments=16, n_cross=3, demag_factor=NZ)
    tr = trace_branch(m.system_free, m.linear_guess(30e-3), 30e-3, direction=-1.0,
                      p_min=1e-3, r_scale=m.EI / L, u_scale=4.0, p_scale=L, ds=0.02,
                      ds_max=0.05, stop_at_fold=True)
    rom = one_mode_pullin(STRIP, SOFT, mag, M_OF_H, n_cross=3, demag_factor=NZ)
    # 16 segments lie 0.13 % above the extrapolated 11.316 mm (module docstring); one mode vs
    # the elastica: a few percent (see the 20 MPa test), measured +1 %: 3 %
    assert tr.event.p == pytest.approx(11.316e-3, rel=3e-3)
    assert rom.pull_in_gap_m == pytest.approx(tr.event.p, rel=3e-2)
    # the strip snaps with ~3 mm of tip deflection, far below the 11 mm gap
    assert 2.5e-3 < m.tip_deflection_m(tr.event.u) < 3.5e-3


def test_jacobian_against_finite_differences_of_the_residual():
    g = 8e-3
    m = MagnetElastica(STRIP, STIFF, place_magnet(MAGNET, STRIP, g), M_OF_H, n_segments=8,
                       n_cross=2, demag_factor=NZ)
    s = m.s[1:]
    u = -(3 * 3e-3 / (2 * L**3)) * (2 * L * s - s**2)          # a bent state, tip 3 mm down
    R, J, Rp = m.system_free(u, g)
    h = 1e-6
    Jfd = np.column_stack([(m.system_free(u + h * e, g)[0] - m.system_free(u - h * e, g)[0])
                           / (2 * h) for e in np.eye(m.N)])
    Rpfd = (m.system_free(u, g + 1e-7)[0] - m.system_free(u, g - 1e-7)[0]) / 2e-7
    # the analytic chain rule uses d f / d r by central differences (FD_HESSIAN_REL: ~1e-4 at
    # worst); these differences of R add ~(h/d)^2 and ~1e-10 / h noise: 1e-3 of the largest
    # entry
    assert np.abs(J - Jfd).max() < 1e-3 * np.abs(J).max()
    assert np.abs(Rp - Rpfd).max() < 1e-3 * np.abs(Rp).max()
    # a Hessian: symmetric
    np.testing.assert_allclose(J, J.T, atol=1e-12 * np.abs(J).max())
