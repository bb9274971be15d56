"""Closed forms and the elastica of the cantilever under a uniform body force."""
import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid, quad

from homogenize.macro import closed_form as cf
from micro.common.validate import InputError

GEO = dict(length_m=0.02, width_m=5e-3, thickness_m=1e-3, E_Pa=2e6)


def test_eb_matches_double_integration_of_the_moment():
    # independent route: w'' = M / EI with M = q (L - x)^2 / 2, integrated numerically twice
    f, L, w, t, E = 4e4, GEO["length_m"], GEO["width_m"], GEO["thickness_m"], GEO["E_Pa"]
    q, EI = f * w * t, E * w * t**3 / 12
    x = np.linspace(0, L, 20001)
    kappa = q * (L - x) ** 2 / 2 / EI
    slope = cumulative_trapezoid(kappa, x, initial=0)
    defl = cumulative_trapezoid(slope, x, initial=0)
    # trapezoid error O(dx^2) ~ 1e-9 relative here
    assert cf.eb_tip_deflection_m(f, **GEO) == pytest.approx(defl[-1], rel=1e-7)


def test_plate_and_shear_corrections():
    d = cf.eb_tip_deflection_m(1e3, **GEO)
    assert cf.eb_tip_deflection_m(1e3, **GEO, nu=0.45, plate=True) == pytest.approx(
        d * (1 - 0.45**2), rel=1e-14)  # plate: stiffer by 1 / (1 - nu^2)
    # shear term relative to bending ~ (t/L)^2: halving t/L must divide it by 4
    rel = [cf.timoshenko_tip_deflection_m(1e3, L, 5e-3, 1e-3, 2e6, nu=0.3)
           / cf.eb_tip_deflection_m(1e3, L, 5e-3, 1e-3, 2e6) - 1 for L in (0.01, 0.02)]
    assert rel[0] / rel[1] == pytest.approx(4.0, rel=1e-12)
    assert cf.shear_coefficient_rectangle(0.0) == pytest.approx(10 / 12)


def test_vectorised_and_linear_in_force():
    f = np.array([3e4, 1e3, 5e4])
    out = cf.eb_tip_deflection_m(f, **GEO)
    assert out.shape == (3,)
    np.testing.assert_allclose(out, [cf.eb_tip_deflection_m(v, **GEO) for v in f], rtol=1e-15)
    v, h = cf.elastica_tip_deflection(f, **GEO)  # unsorted input, continuation sorts
    for fi, vi, hi in zip(f, v, h):
        vs, hs = cf.elastica_tip_deflection(fi, **GEO)
        assert vi == pytest.approx(vs, rel=1e-7) and hi == pytest.approx(hs, rel=1e-6)


def test_elastica_small_load_is_euler_bernoulli():
    f = 1.0  # alpha = q L^3 / EI ~ 1e-4: nonlinear correction ~ alpha^2 ~ 1e-8
    v, h = cf.elastica_tip_deflection(f, **GEO)
    assert v == pytest.approx(cf.eb_tip_deflection_m(f, **GEO), rel=1e-6)
    # shortening to second order: (1/2) int theta^2 ds with the linear slope theta(s)
    L, w, t, E = GEO["length_m"], GEO["width_m"], GEO["thickness_m"], GEO["E_Pa"]
    alpha = f * w * t * L**3 / (E * w * t**3 / 12)
    short = quad(lambda s: 0.5 * (alpha * (1 - (1 - s) ** 3) / 6) ** 2, 0, 1)[0] * L
    assert h == pytest.approx(short, rel=1e-3)


def test_elastica_bvp_agrees_with_shooting_over_the_whole_load_range():
    # two independent solvers of the same BVP (collocation with continuation vs shooting from
    # the free end in ln(angle from vertical)); both at tolerances ~1e-9 or better. alpha = 60
    # and beyond broke the former shooting's bracket; 3000 has delta / L = 0.99.
    a = np.array([0.5, 3.0, 12.0, 40.0, 60.0, 400.0, 3000.0])
    v, h = cf.elastica_tip_deflection(a, 1.0, 1.0, 1.0, 12.0)  # EI = 1, q = alpha
    for ai, vi, hi in zip(a, v, h):
        vs, hs = cf.elastica_shooting(ai)
        assert vi == pytest.approx(vs, rel=1e-7), ai
        assert hi == pytest.approx(hs, rel=1e-6), ai


def test_elastica_shooting_small_load_is_euler_bernoulli():
    # delta / L = alpha / 8 (1 - c alpha^2 + ...): the relative correction must vanish at the
    # rate alpha^2 (polyfit of log|1 - ratio| against log alpha), and be below 1e-6 at 1e-3
    a = np.array([0.02, 0.04, 0.08, 0.16])
    dev = np.array([1.0 - cf.elastica_shooting(x)[0] / (x / 8.0) for x in a])
    assert np.all(dev > 0)                                   # large rotation stiffens
    assert np.polyfit(np.log(a), np.log(dev), 1)[0] == pytest.approx(2.0, abs=0.02)
    assert cf.elastica_shooting(1e-3)[0] == pytest.approx(1e-3 / 8.0, rel=1e-6)
    assert cf.elastica_shooting(0.0) == (0.0, 0.0)


def test_elastica_shooting_heavy_load_asymptote():
    """alpha -> inf: the strip hangs vertically from a clamp boundary layer where
    phi'' = alpha sin(phi) (phi from the vertical); its first integral phi' = -2 sqrt(alpha)
    sin(phi / 2) gives int (1 - cos phi) ds = (2 - sqrt 2) / sqrt(alpha) and int sin phi ds =
    sqrt(2 / alpha). The variation of the lever arm (1 - s) across the layer adds O(1 / alpha),
    so the scaled errors must vanish as alpha^-1/2 (fitted rate, tolerance 0.05)."""
    a = np.array([1e3, 1e4, 1e5])
    res = np.array([cf.elastica_shooting(x) for x in a])
    dv = (1.0 - res[:, 0]) * np.sqrt(a) - (2.0 - np.sqrt(2.0))
    dh = (1.0 - res[:, 1]) * np.sqrt(a) - np.sqrt(2.0)
    assert np.polyfit(np.log(a), np.log(np.abs(dv)), 1)[0] == pytest.approx(-0.5, abs=0.05)
    assert np.polyfit(np.log(a), np.log(np.abs(dh)), 1)[0] == pytest.approx(-0.5, abs=0.05)
    assert abs(dv[-1]) < 2e-3 and abs(dh[-1]) < 5e-3


def test_elastica_limits():
    a = np.array([0.1, 1, 5, 20, 200.0])
    v, h = cf.elastica_tip_deflection(a, 1.0, 1.0, 1.0, 12.0)
    ratio = v / (a / 8)
    assert np.all(np.diff(ratio) < 0) and np.all(ratio < 1)  # stiffening with rotation
    assert np.all(v < 1) and np.all(h < 1)                   # inextensible
    # very large load: the strip hangs nearly straight down, tip at (~0, -L)
    assert v[-1] > 0.95 and h[-1] > 0.88


@pytest.mark.parametrize("kw,msg", [(dict(length_m=-1.0), "length_m"),
                                    (dict(nu=0.5), "nu"), (dict(E_Pa=0.0), "E_Pa")])
def test_bad_input(kw, msg):
    args = {**GEO, **kw}
    with pytest.raises(InputError, match=msg):
        cf.eb_tip_deflection_m(1.0, **args)
    with pytest.raises(InputError, match="f_N_m3"):
        cf.elastica_tip_deflection(-1.0, **GEO)
