"""Channel block (seed paper Section 3.2, Fig. 4): linearity, trends, limits, convergence."""
import pytest

from homogenize.macro.channel import ChannelGeometry, solve_channel
from homogenize.macro.closed_form import plate_clamped_strip_deflection_m
from homogenize.macro.fem import Material
from micro.common.validate import InputError

MAT = Material(2e6, 0.45, 1210.0)
F = 4e4


def _run(a, c, b=50e-6, d=10e-3, f=F, **kw):
    return solve_channel(ChannelGeometry(a, b, c, d), MAT, f, **kw)


def test_linear_in_body_force_and_self_weight():
    r1 = _run(2e-3, 0.5e-3, f=2e4, nc=1)
    r2 = _run(2e-3, 0.5e-3, f=4e4, nc=1)
    assert r2.max_deflection_m == pytest.approx(2 * r1.max_deflection_m, rel=1e-9)
    assert r2.area_reduction == pytest.approx(2 * r1.area_reduction, rel=1e-9)
    g = solve_channel(ChannelGeometry(2e-3, 50e-6, 0.5e-3, 10e-3), MAT, 0.0, nc=1,
                      gravity_m_s2=9.81)
    assert g.max_deflection_m == pytest.approx(r1.max_deflection_m * 1210 * 9.81 / 2e4,
                                               rel=1e-9)


def test_fig4_trends_wide_channel_thin_ceiling():
    base = _run(5e-3, 0.5e-3).max_deflection_m
    assert _run(10e-3, 0.5e-3).max_deflection_m > 5 * base      # ~a^4 for wide channels
    assert _run(5e-3, 1e-3).max_deflection_m < 0.6 * base       # ~1/c^2
    assert _run(1e-3, 0.5e-3).max_deflection_m < 0.02 * base    # narrow: negligible


def test_wide_channel_tends_to_clamped_plate_strip():
    # a/c = 20: elastic walls make the ceiling softer than a clamped strip, by ~10 %
    r = _run(10e-3, 0.5e-3)
    ratio = r.max_deflection_m / plate_clamped_strip_deflection_m(F, 10e-3, 0.5e-3, 2e6, 0.45)
    assert 1.0 < ratio < 1.25
    # clamped-strip profile (1 - (2y/a)^2)^2 has mean 8/15 of its maximum: area loss
    # ~ (8/15) delta / b (walls barely move sideways)
    assert r.area_reduction == pytest.approx(8 / 15 * r.max_deflection_m / 50e-6, rel=0.1)


def test_b_and_d_hardly_matter_for_a_much_larger_than_b():
    ref = _run(5e-3, 0.5e-3).max_deflection_m
    assert _run(5e-3, 0.5e-3, b=25e-6).max_deflection_m == pytest.approx(ref, rel=0.1)
    assert _run(5e-3, 0.5e-3, b=100e-6).max_deflection_m == pytest.approx(ref, rel=0.1)
    assert _run(5e-3, 0.5e-3, d=5e-3).max_deflection_m == pytest.approx(ref, rel=0.05)
    assert _run(5e-3, 0.5e-3, d=20e-3).max_deflection_m == pytest.approx(ref, rel=0.05)


def test_mesh_converged_to_two_percent():
    coarse = _run(5e-3, 0.5e-3, nc=2).max_deflection_m
    fine = _run(5e-3, 0.5e-3, nc=3).max_deflection_m
    assert coarse == pytest.approx(fine, rel=0.02)


def test_closure_flag_and_bad_input():
    assert _run(10e-3, 0.25e-3, nc=1).closes
    with pytest.raises(InputError, match="a_m"):
        ChannelGeometry(-1e-3, 50e-6, 0.5e-3, 1e-2)
