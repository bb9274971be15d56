"""Element types of the sensitivity study (homogenize.macro.elements): convergence with a
measured rate, beam theory for a slender strip, volumetric locking, identities between the
formulations, and CalculiX's own elements against ours (when ccx is installed)."""
import shutil

import numpy as np
import pytest

from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.elements import CCX_ELEMENTS, ELEMENTS, ccx_tip, solve_strip
from homogenize.macro.fem import Material
from micro.common.validate import InputError

E = 2.0e6
F = 1.0e3            # body force [N/m^3]; linear problems, the value only scales the tip
LINEAR = ("hex8", "hex8-sri", "hex8-r", "tet4")
QUADRATIC = ("hex20", "hex20-r", "hex27", "tet10")
needs_ccx = pytest.mark.skipif(shutil.which("ccx") is None,
                               reason="CalculiX (ccx) not installed")


def _rate(tips, ref):
    """polyfit rate of |tip - ref| against h on meshes refined by 2 each time."""
    err = np.abs(np.asarray(tips) - ref)
    h = 0.5 ** np.arange(len(tips))
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


def _richardson(tips):
    """Limit and observed order of three tips on meshes refined by 2 each time."""
    u0, u1, u2 = tips
    p = np.log((u1 - u0) / (u2 - u1)) / np.log(2.0)
    return u2 + (u2 - u1) / (2.0 ** p - 1.0), p


@pytest.fixture(scope="module")
def ladders():
    """Tips of a short clamped strip (6 x 2 x 1 mm, half width modelled, nu = 0.3) on nested
    grids (3k, k, k): k = 2, 4, 8 for the linear elements, k = 1, 2, 4 for the quadratic ones."""
    strip, mat = Strip(6e-3, 2e-3, 1e-3), Material(E, 0.3, 0.0)
    out = {}
    for name in ELEMENTS:
        ks = (2, 4, 8) if name in LINEAR else (1, 2, 4)
        out[name] = [solve_strip(strip, mat, F, name, (3 * k, k, k)).tip_m for k in ks]
    return out


def test_every_element_converges_to_the_same_tip_with_a_measured_rate(ladders):
    limits = {n: _richardson(ladders[n])[0] for n in QUADRATIC}
    ref = float(np.mean(list(limits.values())))
    # the quadratic elements' Richardson limits agree to 0.1 % (measured spread 0.08 %): the
    # extrapolation error of a clamp-singularity-limited rate ~2 on k = 1, 2, 4
    for n, lim in limits.items():
        assert lim == pytest.approx(ref, rel=1e-3), n
    for n in ELEMENTS:
        tips = ladders[n]
        err = np.abs(np.array(tips) - ref)
        # monotone convergence towards the common limit, the last refinement at least
        # halving the error (tet4's first one: measured factor 1.97)
        assert err[1] < err[0] and err[2] < 0.5 * err[1], n
        rate = _rate(tips, ref)
        if n == "tet4":
            # linear tetrahedra lock (constant strain per element): pre-asymptotic on these
            # meshes (local rates 1.0 then 1.5, rising towards 2), so only rising and >= 1.2
            r01 = np.log2(err[0] / err[1])
            r12 = np.log2(err[1] / err[2])
            assert r12 > r01 and rate > 1.2
        else:
            # second-order convergence of the displacement, limited to ~2 by the edge
            # singularity of the clamp (measured 1.7-2.4); 1.5 leaves room for the linear
            # hexahedra's pre-asymptotic locking
            assert rate > 1.5, (n, rate)
    # the extrapolated limits of the hexahedra agree with the common one within 1.5 %
    # (linear ones: their observed order is pre-asymptotic, 1.4-2.4, on k = 2, 4, 8)
    for n in ("hex8", "hex8-sri", "hex8-r"):
        assert _richardson(ladders[n])[0] == pytest.approx(ref, rel=1.5e-2), n


def test_hexahedra_reproduce_timoshenko_for_a_slender_strip():
    # L/t = 20, square section, nu = 0: no anticlastic or Poisson effect at the clamp, so the
    # 3D strip differs from Timoshenko only by the clamp's warping restraint (measured 0.03 %
    # with quadratic hexahedra); EB and Timoshenko differ by 0.2 % here
    strip, mat = Strip(20e-3, 1e-3, 1e-3), Material(E, 0.0, 0.0)
    timo = cf.timoshenko_tip_deflection_m(F, strip.length_m, strip.width_m, strip.thickness_m,
                                          E, 0.0)
    eb = cf.eb_tip_deflection_m(F, strip.length_m, strip.width_m, strip.thickness_m, E)
    assert timo / eb - 1 == pytest.approx(0.002, rel=0.01)
    for name in ("hex20", "hex20-r", "hex27"):
        coarse, fine = (solve_strip(strip, mat, F, name, d).tip_m for d in ((10, 1, 1),
                                                                          (20, 1, 2)))
        # within the discretisation error (the level difference, 1e-3 of the tip) plus the
        # 0.1 % model allowance
        assert abs(fine - timo) <= abs(fine - coarse) + 1e-3 * timo, name
        assert fine == pytest.approx(timo, rel=2e-3), name
    for name in ("hex8", "hex8-sri", "hex8-r"):
        tips = [solve_strip(strip, mat, F, name, d).tip_m for d in ((20, 1, 2), (40, 2, 4),
                                                                   (80, 4, 8))]
        lim, p = _richardson(tips)
        # the Richardson estimate of the finest mesh's error bounds its distance to
        # Timoshenko (factor 1.5 for the pre-asymptotic order, 1.5-2.3, + 0.3 % model)
        est = abs(tips[2] - tips[1]) / (2.0 ** p - 1.0)
        assert abs(tips[2] - timo) <= 1.5 * est + 3e-3 * timo, name
        assert lim == pytest.approx(timo, rel=2e-2), name


def test_full_integration_locks_as_nu_tends_to_one_half_sri_does_not():
    strip, div = Strip(10e-3, 2e-3, 1e-3), (10, 1, 2)
    full_over_sri, sri_over_quad = {}, {}
    for nu in (0.3, 0.49, 0.499):
        mat = Material(E, nu, 0.0)
        full, sri, quad = (solve_strip(strip, mat, F, n, div).tip_m
                           for n in ("hex8", "hex8-sri", "hex20"))
        full_over_sri[nu], sri_over_quad[nu] = full / sri, sri / quad
    # fully integrated trilinear hexes get stiffer (smaller tip) relative to SRI as nu -> 1/2:
    # measured 0.90, 0.55, 0.28 (eight volumetric constraints per element against one)
    assert full_over_sri[0.3] > full_over_sri[0.49] > full_over_sri[0.499]
    assert full_over_sri[0.499] < 0.5 * full_over_sri[0.3]
    # SRI keeps only the (nu-independent) shear locking: within 10 % of itself across nu
    # (measured 0.78-0.83 of the quadratic hexahedra on this coarse grid)
    vals = np.array(list(sri_over_quad.values()))
    assert vals.max() / vals.min() < 1.1


def test_formulation_identities():
    strip, mat, div = Strip(8e-3, 2e-3, 1e-3), Material(E, 0.45, 0.0), (8, 1, 2)
    # the hourglass-stabilised 1-point hex with the full stabilisation fraction is SRI
    a = solve_strip(strip, mat, F, "hex8-r", div, hourglass=1.0).tip_m
    b = solve_strip(strip, mat, F, "hex8-sri", div).tip_m
    # equal stiffness matrices assembled by two element routines: equal to the direct solve's
    # round-off, eps cond(K) ~ 3e-11 (cond 2.6e5; measured 1.6e-12)
    assert a == pytest.approx(b, rel=1e-9)
    # softer hourglass control, softer strip
    c = solve_strip(strip, mat, F, "hex8-r", div, hourglass=0.01).tip_m
    d = solve_strip(strip, mat, F, "hex8-r", div, hourglass=0.1).tip_m
    assert c > d > b
    # tetrahedra: the same P1/P2 spaces and mesh as solve_cantilever
    for name, order in (("tet4", 1), ("tet10", 2)):
        t = solve_strip(strip, mat, F, name, div).tip_m
        ref = solve_cantilever(strip, mat, F, order=order, divisions=div).tip_m
        # own elements against scikit-fem's assembly: round-off of the direct solves, eps cond(K)
        # ~ 3e-10 for tet10 (cond 2.5e6; measured 4.5e-12)
        assert t == pytest.approx(ref, rel=1e-8)
    # linear: the tip scales with the force; half model = full model by symmetry
    for name in ("hex8", "hex20-r"):
        t1 = solve_strip(strip, mat, F, name, div).tip_m
        t2 = solve_strip(strip, mat, 3 * F, name, div).tip_m
        assert t2 == pytest.approx(3 * t1, rel=1e-10)
        full = solve_strip(strip, mat, F, name, (8, 2, 2), half=False).tip_m
        assert full == pytest.approx(t1, rel=1e-8)


def test_bad_input():
    strip, mat = Strip(8e-3, 2e-3, 1e-3), Material(E, 0.45, 0.0)
    with pytest.raises(InputError):
        solve_strip(strip, mat, F, "hex9", (4, 1, 1))
    with pytest.raises(InputError):
        solve_strip(strip, mat, F, "hex8-r", (4, 1, 1), hourglass=0.0)
    with pytest.raises(InputError):
        solve_strip(strip, mat, F, "hex8", (4, 0, 1))


@needs_ccx
def test_calculix_elements_match_ours_on_the_same_grid(tmp_path):
    strip, mat = Strip(8e-3, 2e-3, 1e-3), Material(E, 0.45, 0.0)
    div = (8, 1, 3)          # odd layer count: the linear elements' tip is interpolated
    same = {"C3D8": "hex8", "C3D20": "hex20", "C3D20R": "hex20-r"}
    for cname, name in same.items():
        c = ccx_tip(strip, mat, F, cname, div, tmp_path).tip_m
        ours = solve_strip(strip, mat, F, name, div).tip_m
        # the same element, the same grid (full width against the half model): ccx prints
        # 5 significant digits
        assert c == pytest.approx(ours, rel=2e-5), cname
    for cname in set(CCX_ELEMENTS) - set(same):
        assert ccx_tip(strip, mat, F, cname, div, tmp_path).tip_m > 0, cname
