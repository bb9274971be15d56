"""The channel ceiling under a real magnet with the field on the deformed ceiling (issue 35,
items 1 and 2 for the channel): homogenize.macro.channel_magnet."""
import math

import magpylib
import numpy as np
import pytest
from numpy.polynomial import polynomial as P
from scipy.constants import mu_0 as MU0

from homogenize.macro.channel import ChannelGeometry
from homogenize.macro.channel_magnet import (ChannelMagnet, channel_demag_factor,
                                             channel_magnet_sweep, check_gap_sweep,
                                             place_channel_magnet)
from homogenize.macro.effective import soft_sphere_magnetization
from homogenize.macro.fem import Material
from homogenize.macro.flow import CeilingModel, closure
from homogenize.macro.magnets import PermanentMagnet
from micro.common.validate import InputError

GEO = ChannelGeometry(5e-3, 50e-6, 0.5e-3, 10e-3)
MAT = Material(2e6, 0.45, 1210.0)
CYL = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3)
PHI = 0.0175
CHI = 3 * PHI / (1 - PHI)


@pytest.fixture(scope="module")
def plate():
    return CeilingModel.clamped_plate(GEO, MAT)


def _lopsided():
    """An asymmetric CeilingModel (any shape: the uniform limit does not depend on it)."""
    y = np.linspace(0.0, GEO.a_m, 41)
    s = np.sin(np.pi * y / GEO.a_m) ** 2 * (1 + 0.5 * y / GEO.a_m)
    return CeilingModel(GEO.a_m, GEO.b_m, y, 3e-11 * s, 8e-8 * s ** 1.3, "test")


# ------------------------------------------------------------------ the uniform limit
D_PLATE = MAT.E_Pa * GEO.c_m ** 3 / (12 * (1 - MAT.nu ** 2))


@pytest.mark.parametrize("coupled", [False, True])
@pytest.mark.parametrize("dp", [0.0, 150.0])
def test_uniform_force_reproduces_closure(dp, coupled):
    """A force uniform in space, f(g) = F0 exp(-g / lam): the ceiling deflects exactly as
    f d(y) (independent or coupled sections), and it shuts where closure() puts the uniform
    force: f(g_close) = f_close."""
    ce = _lopsided()
    F0, lam = 3e6, 2e-3

    def force(pts, g):
        return np.full(len(pts), F0 * math.exp(-g / lam)), np.zeros(len(pts))

    r = channel_magnet_sweep(GEO, ce, None, gap_sweep_m=np.linspace(6e-3, 0.0, 7),
                             pressure_drop_Pa=dp, body_force=force, n_x=5, gap_scale_m=lam,
                             plate_rigidity_N_m=D_PLATE if coupled else None)
    first = closure(ce, GEO.d_m).body_force_N_m3
    hold = closure(ce, GEO.d_m, pressure_drop_Pa=dp).body_force_N_m3
    assert r.event == "contact" and r.hold_event == "contact"
    assert math.isclose(r.closure_gap_m, lam * math.log(F0 / first), rel_tol=1e-8)
    assert math.isclose(r.hold_gap_m, lam * math.log(F0 / hold), rel_tol=1e-8)
    c = closure(ce, GEO.d_m)
    assert r.y_event_m == pytest.approx(c.y_contact_m)
    # every open sweep state is the uniform-force answer: q = f d_max
    m = ChannelMagnet(GEO, ce, None, body_force=force, n_x=5)
    for g, q, s in zip(r.sweep_gap_m, r.sweep_max_deflection_m, r.sweep_state):
        if s == "open":
            assert math.isclose(q, F0 * math.exp(-g / lam) * m.d_max, rel_tol=1e-9)


# ------------------------------------------------------------------ the one-mode projection
def _plate_centre_exact(load_coef, D, a):
    """Clamped-clamped strip D w'''' = q(y) (q a polynomial): the exact centre deflection."""
    W = P.polyint(load_coef, 4) / D
    A = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [1, a, a * a, a ** 3], [0, 1, 2 * a, 3 * a * a]])
    rhs = -np.array([P.polyval(0, W), P.polyval(0, P.polyder(W)), P.polyval(a, W),
                     P.polyval(a, P.polyder(W))])
    return P.polyval(a / 2, P.polyadd(W, np.linalg.solve(A, rhs)))


@pytest.mark.parametrize("shape, rel", [("uniform", 1e-12), ("ramp", 1e-12),
                                        ("parabola", 3e-3)])
def test_one_mode_against_the_exact_plate_strip(plate, shape, rel):
    """A force varying across the width (as under a magnet, +-30 %) on the clamped plate
    strip: the one-mode projection's centre deflection against the exact solution (exact for
    uniform and antisymmetric parts, 0.23 % low for the parabola)."""
    a, c = GEO.a_m, GEO.c_m
    D = MAT.E_Pa * c ** 3 / (12 * (1 - MAT.nu ** 2))
    f0 = 1e6
    s = {"uniform": [1.0], "ramp": [0.7, 0.6 / a],
         "parabola": P.polyadd([1.3], P.polymul([-0.3], P.polypow([-1, 2 / a], 2)))}[shape]
    coef = f0 * c * np.asarray(s)               # load per area [N/m^2]
    m = ChannelMagnet(GEO, plate, None, n_x=1,
                      body_force=lambda p, g: (P.polyval(p[:, 1], coef) / c, 0 * p[:, 1]))
    q = m.dead_load_deflection_m(1.0)[0]
    exact = _plate_centre_exact(coef, D, a)
    assert q == pytest.approx(exact, rel=rel)
    if shape == "parabola":
        assert q / exact - 1 == pytest.approx(-2.3e-3, abs=2e-4)


def test_one_mode_projection_of_the_pressure_against_the_fem():
    """The 3D FEM (solve_channel through CeilingModel.from_fem) under a different load
    distribution, the liquid pressure on the underside: the one-mode projection with the
    body-force mode, uplift p d_max / c, is within 0.3 % of the FEM's own centre uplift."""
    fem = CeilingModel.from_fem(GEO, MAT)
    m = ChannelMagnet(GEO, fem, None, n_x=1,
                      body_force=lambda p, g: (np.zeros(len(p)), np.zeros(len(p))))
    p = 1.0
    q_one_mode = p * float(np.sum(m.w_y * m.phi_q)) / m.k      # generalized force p int phi
    assert q_one_mode == pytest.approx(fem.up_per_pressure_m_Pa.max(), rel=3e-3)


@pytest.mark.parametrize("half_width_m, rel", [(3e-3, 0.03), (2e-3, 0.03)])
def test_coupled_sections_against_the_fem_along_the_channel(monkeypatch, half_width_m, rel):
    """solve_channel itself, its body force made to vary along the channel like a magnet's,
    f0 exp(-((x - d/2) / w)^2) (its load form replaced through monkeypatch; mesh, supports and
    probes are solve_channel's): the mid-length centre deflection of the coupled sections is
    within 3 % of the 3D FEM's (1.7 % / 1.9 % low), the independent sections' 27 % / 54 % high."""
    import homogenize.macro.channel as channel_module
    from skfem import LinearForm, asm
    from skfem.models.elasticity import linear_elasticity
    from homogenize.macro.channel import solve_channel
    from homogenize.macro.fem import FEMSolution, _solve_free, vector_basis

    d = GEO.d_m

    def fx(x):
        return np.exp(-((x - d / 2) / half_width_m) ** 2)

    def solve_loaded(mesh, material, f_down, pressure_Pa, fixed, order, solver, ceiling, wall):
        basis = vector_basis(mesh, order)
        lam, mu = material.lame_Pa
        K = asm(linear_elasticity(lam, mu), basis)

        @LinearForm
        def body(v, w):
            return -f_down * fx(w.x[0]) * v[2]
        u, name, it, res = _solve_free(K, asm(body, basis), fixed(basis), solver, 1e-10, basis)
        return FEMSolution(u, basis, name, it, res)

    fem_ceiling = CeilingModel.from_fem(GEO, MAT)           # nc 3, aspect 2
    monkeypatch.setattr(channel_module, "_solve_loaded", solve_loaded)
    want = solve_channel(GEO, MAT, 1e6, nc=3, aspect=2.0).max_deflection_m
    monkeypatch.undo()
    got = {}
    for coupled in (True, False):
        m = ChannelMagnet(GEO, fem_ceiling, None, n_x=21, n_y=8, n_z=1,
                          plate_rigidity_N_m=D_PLATE if coupled else None,
                          body_force=lambda p, g: (1e6 * fx(p[:, 0]), 0 * p[:, 0]))
        got[coupled] = m.dead_load_deflection_m(1.0)[10]    # x = d/2
    assert got[True] == pytest.approx(want, rel=rel)
    assert got[False] > 1.2 * want


# ------------------------------------------------------------------ snap-down, 1 dof
def _piston(geo, d0):
    y = np.linspace(0.0, geo.a_m, 5)
    return CeilingModel(geo.a_m, geo.b_m, y, np.full(5, d0), np.zeros(5), "piston")


@pytest.mark.parametrize("n", [1, 2, 3])
def test_one_dof_snap_down(n):
    """A rigid (piston) ceiling, one point through the thickness: q = d0 A / (G - q)^n with G
    the distance of the mid-plane from the magnet face. The fold is at q* = G / (n + 1),
    G* = ((n + 1)^(n+1) d0 A / n^n)^(1/(n+1)); the ceiling snaps before it touches (q* < b)."""
    geo = ChannelGeometry(5e-3, 0.4e-3, 0.1e-3, 10e-3)
    d0, G_want = 2e-11, 0.75 * 0.4e-3 * (n + 1)          # the fold at q* = 0.75 b
    A = G_want ** (n + 1) * n ** n / ((n + 1) ** (n + 1) * d0)

    def force(pts, g):
        s = pts[:, 2] + g
        return A / s ** n, -n * A / s ** (n + 1)

    r = channel_magnet_sweep(geo, _piston(geo, d0), None,
                             gap_sweep_m=np.linspace(3e-3, 0.0, 13),
                             body_force=force, n_x=2, n_y=4, n_z=1, gap_scale_m=1e-3)
    g_star = G_want - geo.b_m - geo.c_m / 2
    assert r.event == "pull-in"
    assert r.closure_gap_m == pytest.approx(g_star, rel=1e-6)
    assert r.event_deflection_m == pytest.approx(G_want / (n + 1), rel=1e-4)
    assert r.event_deflection_m < geo.b_m
    assert np.all(r.sweep_state[r.sweep_gap_m > g_star] == "open")
    assert np.all(r.sweep_state[r.sweep_gap_m < g_star] == "closed")


def test_coupled_snap_equals_the_single_section_for_a_force_uniform_along_x():
    """A force that does not vary along the channel (A / (z + g)^2, varying across it through
    the deflection): the coupled sections stay uniform along x and fold exactly where one
    section alone does (the pull-in of a bent ceiling, not a piston)."""
    geo = ChannelGeometry(5e-3, 0.4e-3, 0.1e-3, 10e-3)
    mat = Material(2e6, 0.45, 1210.0)
    ce = CeilingModel.clamped_plate(geo, mat)
    D = mat.E_Pa * geo.c_m ** 3 / (12 * (1 - mat.nu ** 2))
    A = 0.08                    # the fold near g = 0.3 mm, q* ~ G / 3 < b

    def force(pts, g):
        s = pts[:, 2] + g
        return A / s ** 2, -2 * A / s ** 3

    kw = dict(gap_sweep_m=[3e-3, 0.0], body_force=force, n_y=8, n_z=2, gap_scale_m=1e-3)
    one = channel_magnet_sweep(geo, ce, None, n_x=1, **kw)
    coupled = channel_magnet_sweep(geo, ce, None, n_x=5, plate_rigidity_N_m=D, **kw)
    assert one.event == coupled.event == "pull-in"
    assert coupled.closure_gap_m == pytest.approx(one.closure_gap_m, rel=1e-7)
    assert coupled.event_deflection_m == pytest.approx(one.event_deflection_m, rel=1e-4)
    assert coupled.event_deflection_m < coupled.contact_deflection_m
    assert len(coupled.x_event_m) == 5                  # every section together


def test_one_dof_contact_before_snap():
    """Weaker force law (n = 1, far): the piston reaches the glass, q = b, on the stable
    branch: b (G - b) = d0 A."""
    geo = ChannelGeometry(5e-3, 0.1e-3, 0.5e-3, 10e-3)
    d0, A = 2e-11, 2e4

    def force(pts, g):
        s = pts[:, 2] + g
        return A / s, -A / s ** 2

    r = channel_magnet_sweep(geo, _piston(geo, d0), None,
                             gap_sweep_m=np.linspace(3e-3, 0.0, 7),
                             body_force=force, n_x=2, n_y=4, n_z=1, gap_scale_m=1e-3)
    G = geo.b_m + d0 * A / geo.b_m
    assert r.event == "contact"
    assert r.closure_gap_m == pytest.approx(G - geo.b_m - geo.c_m / 2, rel=1e-8)


# ------------------------------------------------------------------ the real magnet
@pytest.fixture(scope="module")
def sweep(plate):
    mag = place_channel_magnet(CYL, GEO, 6e-3)
    return channel_magnet_sweep(GEO, plate, mag, soft_sphere_magnetization(PHI),
                                np.linspace(6e-3, 1e-3, 6), n_x=5, n_y=8)


def test_far_gaps_reproduce_the_dead_load(plate):
    """The follower correction vanishes far from the magnet, like the deflection over the
    distance: < 2e-4 at 10 mm, < 1e-5 at 20 mm."""
    m = ChannelMagnet(GEO, plate, place_channel_magnet(CYL, GEO, 0.0),
                      soft_sphere_magnetization(PHI), n_x=5, n_y=8)
    corr = []
    for g in (5e-3, 10e-3, 20e-3):
        dead = m.dead_load_deflection_m(g)
        q = m.solve_at(g, dead)
        corr.append(float(np.max(np.abs(q / dead - 1))))
    assert corr[0] > corr[1] > corr[2]
    assert corr[1] < 2e-4 and corr[2] < 1e-5
    assert corr[0] > 1e-3                          # near the magnet the correction is real


def _magpylib_generalized_force(q, g, ceiling, n_x=5, n_y=8, n_z=3):
    """Per section, c sum_k w_k phi_k <f_down> with the field of a magpylib Cylinder built here,
    |B| differenced along z at the deflected Gauss points, M = chi H / (1 + N chi) (the linear
    soft-sphere law below saturation); and the same at the undeformed points."""
    N = channel_demag_factor(GEO)
    src = magpylib.magnet.Cylinder(dimension=(10e-3, 10e-3), polarization=(0, 0, 1.3),
                                   position=(GEO.d_m / 2, GEO.a_m / 2, -g - 5e-3))
    a, b, c = GEO.a_m, GEO.b_m, GEO.c_m
    gy, wy = np.polynomial.legendre.leggauss(n_y)
    gz, wz = np.polynomial.legendre.leggauss(n_z)
    y, wyy = a / 2 * (1 + gy), a / 2 * wy
    d_col = ceiling.down_per_force_m4_N
    phi = np.interp(y, ceiling.y_m, d_col) / d_col.max()
    k = c * np.sum(wyy * phi) / d_col.max()
    h = 1e-7
    F, F_dead = np.zeros(n_x), np.zeros(n_x)
    for i, x in enumerate(np.linspace(0.0, GEO.d_m, n_x)):
        for yk, wk, pk in zip(y, wyy, phi):
            for zk, wzk in zip(c / 2 * (1 + gz), wz / 2):
                for shift, acc in ((q[i] * pk, F), (0.0, F_dead)):
                    z = b + zk - shift
                    pts = np.array([[x, yk, z + h], [x, yk, z - h], [x, yk, z]])
                    B = np.linalg.norm(magpylib.getB(src, pts), axis=1)
                    M = CHI * (B[2] / MU0) / (1 + N * CHI)
                    assert M < PHI * 1.4e6             # below saturation: linear law
                    acc[i] += c * wk * pk * wzk * (-M * (B[0] - B[1]) / (2 * h))
    return k, F, F_dead


def test_deformed_sampling_against_magpylib(sweep, plate):
    """Independent check of an equilibrium of the sweep (independent sections): k q = F with F
    from magpylib at the DEFORMED points, and not the dead load's."""
    n = 1                                          # gap 5 mm, open
    g = sweep.sweep_gap_m[n]
    assert sweep.sweep_state[n] == "open"
    q = sweep.sweep_deflection_m[n]
    k, F, F_dead = _magpylib_generalized_force(q, g, plate)
    assert np.allclose(k * q, F, rtol=1e-6, atol=0)
    assert np.all(np.abs(F / F_dead - 1) > 50e-6)      # the deformed position matters


def test_coupled_equilibrium_against_magpylib(plate):
    """The coupled sections at 3 mm: K q = W F with F from magpylib at the deflected points."""
    m = ChannelMagnet(GEO, plate, place_channel_magnet(CYL, GEO, 0.0),
                      soft_sphere_magnetization(PHI), n_x=5, n_y=8, n_z=3,
                      plate_rigidity_N_m=D_PLATE)
    g = 3e-3
    q = m.solve_at(g, m.dead_load_deflection_m(g))
    k, F, F_dead = _magpylib_generalized_force(q, g, plate)
    assert k == pytest.approx(m.k, rel=1e-12)
    assert np.allclose(m.K @ q, m.W * F, rtol=1e-6, atol=0)
    assert not np.allclose(m.K @ q, m.W * F_dead, rtol=1e-3, atol=0)
    assert q[2] == pytest.approx(np.max(q))            # the centre deflects most at 3 mm


def test_realistic_sweep_closes_by_contact(sweep):
    """The centred cylinder: contact (no snap: b << the field's length scale) on the centre
    column, at mirror-image sections (the same event gap on both sides of the axis)."""
    r = sweep
    assert r.event == "contact"
    assert 1e-3 < r.closure_gap_m < 6e-3
    xs = np.array(r.x_event_m)
    assert np.allclose(np.sort(GEO.d_m - xs), xs, atol=1e-12)
    assert r.y_event_m == pytest.approx(GEO.a_m / 2)
    assert np.nanmax(r.section_event_gap_m) == r.closure_gap_m
    assert r.path_x_m in xs
    assert r.event_deflection_m == pytest.approx(GEO.b_m, rel=1e-8)
    # the follower load pulls harder than the dead load: contact at a larger gap
    assert r.event_dead_load_deflection_m < r.event_deflection_m
    open_ = r.sweep_state == "open"
    assert np.all(np.diff(r.sweep_max_deflection_m[open_]) > 0)
    assert np.all(r.sweep_max_deflection_m[open_] > r.sweep_dead_load_max_deflection_m[open_])
    assert np.all(r.sweep_state[r.sweep_gap_m <= r.closure_gap_m] == "closed")
    assert np.allclose(r.sweep_min_gap_m[open_], GEO.b_m - r.sweep_max_deflection_m[open_])
    d = r.to_dict()
    assert d["event"] == "contact" and isinstance(d["sweep_state"], list)


def test_self_weight_adds_as_a_uniform_force():
    """rho g on top of the uniform force: closure where f(g) + rho g = f_close."""
    ce = _lopsided()
    F0, lam, w = 3e6, 2e-3, 2e5

    def force(pts, g):
        return np.full(len(pts), F0 * math.exp(-g / lam)), np.zeros(len(pts))

    r = channel_magnet_sweep(GEO, ce, None, gap_sweep_m=[6e-3, 0.0], body_force=force, n_x=1,
                             gap_scale_m=lam, self_weight_N_m3=w)
    f_close = closure(ce, GEO.d_m).body_force_N_m3
    assert math.isclose(r.closure_gap_m, lam * math.log(F0 / (f_close - w)), rel_tol=1e-8)


def test_cuboid_and_an_opening_sweep(plate):
    """A cuboid magnet off the middle of the channel (axis at x = 7, y = 2 mm); the sweep run
    opening gives the same states and deflections as closing (no hysteresis without a snap)."""
    cub = PermanentMagnet("cuboid", (10e-3, 10e-3, 5e-3), 1.3)
    mag = place_channel_magnet(cub, GEO, 0.0, x_axis_m=7e-3, y_axis_m=2e-3)
    kw = dict(n_x=5, n_y=6, n_z=2)
    M = soft_sphere_magnetization(PHI)
    down = channel_magnet_sweep(GEO, plate, mag, M, [4e-3, 2e-3, 0.5e-3], **kw)
    up = channel_magnet_sweep(GEO, plate, mag, M, [0.5e-3, 2e-3, 4e-3], **kw)
    assert down.event == up.event == "contact"
    assert down.closure_gap_m == pytest.approx(up.closure_gap_m, rel=1e-9)
    assert list(down.sweep_state) == list(up.sweep_state)[::-1] == ["open", "open", "closed"]
    assert np.allclose(down.sweep_max_deflection_m[:2], up.sweep_max_deflection_m[::-1][:2],
                       rtol=1e-9)
    # a flat magnet's face pulls hardest under its rim (x = 2 mm), little over its middle
    assert down.x_event_m == (2.5e-3,)
    assert np.isnan(down.section_event_gap_m[2])         # x = 5 mm: open down to 0.5 mm


def test_newton_failure_is_a_convergence_error_with_history(plate):
    from micro.common.validate import ConvergenceError
    m = ChannelMagnet(GEO, plate, place_channel_magnet(CYL, GEO, 0.0),
                      soft_sphere_magnetization(PHI), n_x=2, n_y=4, n_z=1)
    with pytest.raises(ConvergenceError) as exc:
        m.solve_at(3e-3, 0.0, max_it=1)
    assert len(exc.value.residual_history) == 1 and exc.value.residual_history[0] > 0


# ------------------------------------------------------------------ refused input
@pytest.mark.parametrize("sweep_, words", [
    ([3e-3, -1e-3], "gap_sweep_m: a gap below zero"),
    ([3e-3, 1e-3, 2e-3], "gap_sweep_m must be strictly monotonic"),
])
def test_bad_sweeps_refused(sweep_, words):
    with pytest.raises(InputError, match=words):
        check_gap_sweep(sweep_)
    with pytest.raises(InputError, match="gap_sweep_m"):
        channel_magnet_sweep(GEO, CeilingModel.clamped_plate(GEO, MAT),
                             place_channel_magnet(CYL, GEO, 1e-3),
                             soft_sphere_magnetization(PHI), sweep_)


def test_magnet_overlapping_the_channel_refused():
    with pytest.raises(InputError, match="gap_m = -0.0001 m < 0 puts the magnet into the glass"):
        place_channel_magnet(CYL, GEO, -1e-4)
    tilted = PermanentMagnet("cuboid", (5e-3, 5e-3, 5e-3), 1.3, axis=(1.0, 0.0, 0.0))
    with pytest.raises(InputError, match="axis must be along z"):
        place_channel_magnet(tilted, GEO, 1e-3)


# ------------------------------------------------------------------------------- the CLI
@pytest.fixture
def cli():
    """``mapsim`` (the channel command with --magnet)."""
    from homogenize.cli import main
    return main


MAGNET = ["--magnet", "cylinder", "--magnet-size", "10e-3", "10e-3", "--remanence-T", "1.3",
          "--sections", "5"]


def test_cli_gap_sweep_and_close(cli, tmp_path, capsys):
    import json
    out = tmp_path / "m.json"
    assert cli(["channel", *MAGNET, "--gap-sweep-m", "0.006:0.001:6", "--pressure-drop-Pa",
                "100", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "closure gap" in text and "<- closure (contact)" in text
    assert "holds shut below the gap" in text
    d = json.loads(out.read_text())
    r = d["channel_magnet"]
    assert r["event"] == "contact" and 1e-3 < r["closure_gap_m"] < 6e-3
    assert r["hold_gap_m"] < r["closure_gap_m"]          # holding 100 Pa needs it closer
    assert d["demag_factor"] == pytest.approx(channel_demag_factor(GEO))
    assert r["sweep_state"][0] == "open" and r["sweep_state"][-1] == "closed"
    assert r["sweep_max_deflection_m"][-1] is None
    assert "manifest" in d


@pytest.mark.parametrize("extra, words", [
    (["--gap-sweep-m", "0.003:-0.001:5"], "--gap-sweep-m: START and STOP must be >= 0"),
    (["--close", "--target-gap-m", "1e-5", "--pressure-drop-Pa", "10"],
     "--target-gap-m is not used with --magnet"),
    ([], "needs --close"),
])
def test_cli_bad_input(cli, extra, words, tmp_path, capsys):
    out = tmp_path / "x.json"
    assert cli(["channel", *MAGNET, *extra, "--json", str(out)]) == 2
    assert words in capsys.readouterr().err
    assert not out.exists()


def test_cli_close_alone(cli, capsys):
    """--close without a sweep: from the magnet's size down to contact."""
    assert cli(["channel", *MAGNET, "--close", "--b-m", "30e-6"]) == 0
    text = capsys.readouterr().out
    assert "closure gap" in text and "<- closure (contact)" in text


def test_cli_magnet_options_need_the_magnet(cli, capsys):
    assert cli(["channel", "--gap-sweep-m", "0.003:0:4"]) == 2
    assert "--gap-sweep-m has no effect without --magnet" in capsys.readouterr().err


def test_cli_table_interval(cli, tmp_path, capsys, synthetic_table):
    """With --table: the closure and hold gaps carry the table's M_eff interval (the weaker
    magnetization closes closer to the magnet), the mean inside it."""
    import json
    table = synthetic_table(tmp_path / "t.h5")
    out = tmp_path / "m.json"
    assert cli(["channel", *MAGNET, "--table", str(table), "--phi", "0.05",
                "--gap-sweep-m", "0.008:0.0005:4", "--pressure-drop-Pa", "100",
                "--json", str(out)]) == 0, capsys.readouterr().err
    assert "(table's M_eff interval)" in capsys.readouterr().out
    d = json.loads(out.read_text())
    lo, hi = d["interval"]["closure_gap_m"]
    assert lo < d["channel_magnet"]["closure_gap_m"] < hi
    lo, hi = d["interval"]["hold_gap_m"]
    assert lo < d["channel_magnet"]["hold_gap_m"] < hi
    assert set(d["interval_ends"]) == {"low", "high"}
