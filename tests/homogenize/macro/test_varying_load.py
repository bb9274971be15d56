"""Body force varying along the strip: elastica, Euler-Bernoulli, Timoshenko and 3D FEM."""
import numpy as np
import pytest

from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material
from micro.common.validate import InputError

GEO = dict(length_m=0.02, width_m=5e-3, thickness_m=1e-3, E_Pa=2e6)
L, W, T, E = GEO["length_m"], GEO["width_m"], GEO["thickness_m"], GEO["E_Pa"]
EI = E * W * T**3 / 12
MAT = Material(2e6, 0.45, 1210.0)


def _ramp(f_tip):
    """Linearly varying load, zero at the clamp and ``f_tip`` at the free end [N/m^3]."""
    return lambda x: f_tip * np.asarray(x) / L


def test_constant_callable_and_profile_reproduce_the_uniform_result():
    f = 4e4     # alpha = 4.8: a large deflection (delta / L ~ 0.23), well past linear
    v0, h0 = cf.elastica_tip_deflection(f, **GEO)
    for load in (lambda x: np.full(np.shape(x), f), cf.BodyForceProfile([0.0, L], [f, f])):
        v, h = cf.elastica_tip_deflection(load, **GEO)
        # same ODE (the shear shape is 1 - s to round-off), same continuation: round-off
        assert v == pytest.approx(v0, rel=1e-12) and h == pytest.approx(h0, rel=1e-12)
        assert cf.eb_tip_deflection_m(load, **GEO) == pytest.approx(
            cf.eb_tip_deflection_m(f, **GEO), rel=1e-13)
        assert cf.timoshenko_tip_deflection_m(load, **GEO) == pytest.approx(
            cf.timoshenko_tip_deflection_m(f, **GEO), rel=1e-13)


@pytest.mark.parametrize("model", ["fem", "neo-hookean"])
def test_fem_constant_callable_reproduces_the_uniform_result(model):
    strip = Strip(0.2, 0.01, 0.01)
    kw = dict(model=model, divisions=(10, 1, 2), gravity_m_s2=9.81)
    a = solve_cantilever(strip, MAT, 100.0, **kw)
    b = solve_cantilever(strip, MAT, lambda x: np.full(np.shape(x), 100.0), **kw)
    # the load vector differs only by the quadrature rule of an integrand both rules integrate
    # exactly (P2 shape function times a constant): round-off, amplified by the stiffness
    # matrix's conditioning (~1e4 here) -> 1e-11
    assert b.tip_m == pytest.approx(a.tip_m, rel=1e-11)
    assert b.f_N_m3 == pytest.approx(a.f_N_m3, rel=1e-13)


def test_linearly_varying_load_euler_bernoulli_closed_form():
    # Roark / superposition: a load rising linearly from 0 at the clamp to q0 at the tip gives
    # delta = 11 q0 L^4 / (120 EI); falling from q0 to 0 gives q0 L^4 / (30 EI)
    f0 = 1e3
    q0 = f0 * W * T
    assert cf.eb_tip_deflection_m(_ramp(f0), **GEO) == pytest.approx(
        11 * q0 * L**4 / (120 * EI), rel=1e-13)
    falling = cf.BodyForceProfile(np.linspace(0, L, 5), np.linspace(f0, 0, 5))
    assert cf.eb_tip_deflection_m(falling, **GEO) == pytest.approx(q0 * L**4 / (30 * EI),
                                                                  rel=1e-13)


def test_elastica_small_load_limit_of_linearly_varying_load():
    f0 = 1.0   # alpha ~ 1e-4: the nonlinear correction is O(alpha^2) ~ 1e-8 relative
    v, h = cf.elastica_tip_deflection(_ramp(f0), **GEO)
    assert v == pytest.approx(11 * f0 * W * T * L**4 / (120 * EI), rel=1e-6)
    assert abs(h) < 1e-3 * v     # shortening is O(alpha^2 L), at the BVP tolerance here
    # linear in the load in this limit
    v2, _ = cf.elastica_tip_deflection(_ramp(2 * f0), **GEO)
    assert v2 / v == pytest.approx(2.0, rel=1e-6)


def test_elastica_varying_load_large_deflection_is_consistent():
    # the same total load placed nearer the tip bends more; both stay below the EB value
    uniform = cf.elastica_tip_deflection(4e4, **GEO)[0]
    ramp = cf.elastica_tip_deflection(_ramp(8e4), **GEO)[0]   # same resultant, 2/3 L lever
    assert ramp > uniform
    assert ramp < cf.eb_tip_deflection_m(_ramp(8e4), **GEO)


def test_fem_linearly_varying_load_converges_to_timoshenko():
    # slender square section (L/t = 20), beam-theory clamp: the 3D solution tends to Timoshenko
    # with the varying load (EB + int q x dx / kappa G A); the error falls at the rate of P2
    # with the clamp-corner singularity (~2-3, as for the uniform load in test_cantilever_fem)
    strip, f0 = Strip(1.0, 0.05, 0.05), 1e3
    ramp = lambda x: f0 * np.asarray(x) / strip.length_m   # noqa: E731
    geo = (strip.length_m, strip.width_m, strip.thickness_m, MAT.E_Pa, MAT.nu)
    timo = cf.timoshenko_tip_deflection_m(ramp, *geo)
    eb = cf.eb_tip_deflection_m(ramp, *geo[:4])
    ei = MAT.E_Pa * strip.width_m * strip.thickness_m**3 / 12
    q0 = f0 * strip.width_m * strip.thickness_m
    assert eb == pytest.approx(11 * q0 * strip.length_m**4 / (120 * ei), rel=1e-12)
    ks = np.array([1, 2, 4])
    tips = np.array([solve_cantilever(strip, MAT, ramp, clamp="beam",
                                      divisions=(7 * k, max(1, k // 2), k)).tip_m for k in ks])
    err = np.abs(tips / timo - 1)
    assert np.all(np.diff(err) < 0)
    assert err[-1] < 2e-3        # measured 7e-4 at (28, 2, 4)
    rate = np.polyfit(np.log(1.0 / ks), np.log(err), 1)[0]
    assert 1.5 < rate < 4.0, rate
    # EB is 0.3 % below Timoshenko here (shear ~ (t/L)^2): within 1 % of it on the finest mesh
    assert tips[-1] == pytest.approx(eb, rel=1e-2)


def test_profile_must_cover_the_strip_and_callable_shape():
    short = cf.BodyForceProfile([0.0, 0.5 * L], [1.0, 1.0])
    with pytest.raises(InputError, match="cover"):
        cf.elastica_tip_deflection(short, **GEO)
    with pytest.raises(InputError, match="increasing"):
        cf.BodyForceProfile([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(InputError, match="shaped like x"):
        cf.eb_tip_deflection_m(lambda x: 1.0, **GEO)
    with pytest.raises(InputError, match="finite"):
        solve_cantilever(Strip(L, W, T), MAT, lambda x: np.full(np.shape(x), np.nan), model="eb")
