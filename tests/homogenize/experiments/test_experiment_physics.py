"""The physics the extensions use: owned laws against references, adapters against the
project modules they wrap."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0

from homogenize.experiments import _physics as P


# --- demagnetizing factor of a cylinder -----------------------------------------------------

def test_demag_limits():
    # thin disk -> 1; the first correction is O(aspect ln(1/aspect)), ~4 % at aspect 1e-2
    assert P.cylinder_demag_factor(1e-4) == pytest.approx(1.0, abs=2e-3)
    # long rod: N -> 4 / (3 pi aspect), next term O(aspect^-2): at aspect 100 below 1 %
    assert P.cylinder_demag_factor(100.0) == pytest.approx(4 / (3 * math.pi * 100), rel=1e-2)
    a = np.geomspace(0.05, 20, 12)
    N = P.cylinder_demag_factor(a)
    assert np.all(np.diff(N) < 0) and np.all((N > 0) & (N < 1))


@pytest.mark.parametrize("aspect", [0.3, 0.8, 2.5])
def test_demag_against_magpylib_volume_average(aspect):
    """Independent method: the analytic field of a uniformly magnetized cylinder (magpylib),
    averaged over its volume on a 60 x 60 midpoint (r, z) grid. The grid error (log edge
    singularity of H) stays below 0.3 %; tolerance 0.5 %."""
    magpy = pytest.importorskip("magpylib")
    D, L = 1.0, aspect
    cyl = magpy.magnet.Cylinder(polarization=(0, 0, 1.0), dimension=(D, L))
    n = 60
    r = (np.arange(n) + 0.5) / n * D / 2
    z = ((np.arange(n) + 0.5) / n - 0.5) * L
    R, Z = np.meshgrid(r, z, indexing="ij")
    H = cyl.getH(np.c_[R.ravel(), np.zeros(R.size), Z.ravel()])[:, 2].reshape(R.shape)
    N_ref = -(H * R).sum() / R.sum() * mu_0            # M = J / mu0 = 1 / mu0
    assert P.cylinder_demag_factor(aspect) == pytest.approx(N_ref, rel=5e-3)


def test_demag_rejects_bad_aspect():
    from micro.common.validate import InputError
    with pytest.raises(InputError, match="aspect_ratio"):
        P.cylinder_demag_factor(0.0)


# --- hyperelastic laws ----------------------------------------------------------------------

@pytest.mark.parametrize("form,extra", [("neo-hookean", None), ("mooney-rivlin", 0.4),
                                        ("gent", 5.0)])
def test_hyperelastic_small_strain_slope_is_E(form, extra):
    E = 1.3e6
    e = 1e-7
    slope = (P.uniaxial_stress_Pa(form, e, E, extra) - P.uniaxial_stress_Pa(form, -e, E, extra)) / (2 * e)
    assert slope == pytest.approx(E, rel=1e-6)       # central difference: O(e^2) error


def test_hyperelastic_reference_values():
    lam = np.array([0.8, 1.5, 2.5])
    e = lam - 1
    G = 1e6 / 3
    nh = G * (lam - lam ** -2)
    np.testing.assert_allclose(P.uniaxial_stress_Pa("neo-hookean", e, 1e6), nh, rtol=1e-14)
    np.testing.assert_allclose(P.uniaxial_stress_Pa("mooney-rivlin", e, 1e6, 0.0), nh, rtol=1e-14)
    # pure C2 Mooney-Rivlin: P = G / lam (lam - lam^-2)
    np.testing.assert_allclose(P.uniaxial_stress_Pa("mooney-rivlin", e, 1e6, 1.0), nh / lam, rtol=1e-14)
    # Gent -> neo-Hookean as J_m -> inf (relative difference (I1 - 3) / J_m)
    np.testing.assert_allclose(P.uniaxial_stress_Pa("gent", e, 1e6, 1e9), nh, rtol=1e-8)
    # Gent stiffens: above neo-Hookean for finite J_m
    assert np.all(P.uniaxial_stress_Pa("gent", e[1:], 1e6, 5.0) > nh[1:])


# --- beams ----------------------------------------------------------------------------------

def test_eb_compliance_matches_closed_form():
    L, w, t, E = np.array([0.02, 0.03]), np.array([5e-3, 4e-3]), np.array([1e-3, 2e-3]), 2e6
    c = P.eb_compliance_m4_N(L, w, t, E)
    np.testing.assert_allclose(c, 1.5 * L ** 4 / (E * t ** 2), rtol=1e-13)


@pytest.mark.parametrize("alpha", [0.5, 3.0, 20.0, 45.0, 200.0, 3000.0, 3e4])
def test_elastica_table_against_shooting(alpha):
    """Independent solver: closed_form.elastica_shooting (shooting from the free end). The
    cubic interpolation in log(alpha) on 201 nodes up to 1e4 is accurate to ~1e-6, the
    heavy-load asymptote beyond to ~1e-6 (next term O(alpha^-3/2)); tolerance 1e-5."""
    import homogenize.macro.closed_form as cf
    v, _ = cf.elastica_shooting(alpha)
    assert P.elastica_ratio(alpha) * alpha / 8.0 == pytest.approx(v, rel=1e-5)


def test_elastica_ratio_limits():
    assert P.elastica_ratio(1e-6) == 1.0
    a = np.geomspace(0.01, 1e6, 80)
    r = P.elastica_ratio(a)
    assert np.all(np.diff(r) < 0) and r[0] == pytest.approx(1.0, abs=1e-5)
    # the tip deflection itself grows with the load and stays below the length (inextensible),
    # continuously across the end of the table
    d = r * a / 8.0
    assert np.all(np.diff(d) > 0) and np.all(d < 1.0)
    edge = P.elastica_ratio(np.array([1e4 * (1 - 1e-9), 1e4 * (1 + 1e-9)]))
    assert edge[1] == pytest.approx(edge[0], rel=1e-7)
    assert P.elastica_ratio(-3.0) == P.elastica_ratio(3.0)       # even in the load's sign


# --- magnetization laws through micro.magnetization ---------------------------------------

@pytest.mark.parametrize("law", P.LAWS)
def test_law_adapter_initial_slope_and_saturation(law):
    Ms, chi0 = 1.4e6, 2.0
    h = 1e-3 * Ms / chi0
    M = P.particle_magnetization_A_per_m(law, np.array([h, -h]), Ms, chi0)
    assert M[0] / h == pytest.approx(chi0, rel=2e-3)   # curvature: O(chi0 h / Ms) = 1e-3
    assert M[1] == -M[0]                                # odd in H
    big = P.particle_magnetization_A_per_m(law, np.array([1e4 * Ms]), Ms, chi0)[0]
    # saturation: Langevin 1 - 1/x, FK 1 - Ms/(chi0 H): both ~1e-4 short at 1e4 Ms
    assert big == pytest.approx(Ms, rel=2e-4)
    assert np.all(np.diff(P.particle_magnetization_A_per_m(law, np.geomspace(1, 1e8, 30), Ms, chi0)) >= 0)


# --- core-shell through micro.particles ------------------------------------------------------

def test_core_shell_ratio_against_hand_formula():
    r0, t = 25e-9, 3e-9
    r = np.array([10e-9, 25e-9, 50e-9])
    ratio = P.core_shell_moment_ratio(r, t, r0, 7870.0, 178.0)
    # hand: core sigma s_c from 178 (mass-averaged) at r0, then moment per volume at r
    vc0, vs0 = (r0 - t) ** 3, r0 ** 3 - (r0 - t) ** 3
    s_c = (178.0 * (7870 * vc0 + 5170 * vs0) - 92.0 * 5170 * vs0) / (7870 * vc0)
    mpv = lambda rr: (s_c * 7870 * (rr - t) ** 3 + 92.0 * 5170 * (rr ** 3 - (rr - t) ** 3)) / rr ** 3
    np.testing.assert_allclose(ratio, mpv(r) / mpv(r0), rtol=1e-12)
    assert ratio[1] == pytest.approx(1.0, rel=1e-14) and ratio[0] < 1 < ratio[2]
    # a particle thinner than the shell is all Fe3O4: 92 A m^2/kg x 5170 kg/m^3 per volume
    tiny = P.core_shell_moment_ratio(np.array([2e-9]), t, r0, 7870.0, 178.0)
    assert tiny[0] == pytest.approx(92.0 * 5170 / mpv(r0), rel=1e-12)


def test_composite_density():
    assert P.composite_density_kg_m3(0.0, 1210, 7870) == 1210
    assert P.composite_density_kg_m3(0.261, 1050, 7870) == pytest.approx(2830, rel=1e-3)


# --- filler stiffening through homogenize.cell.problem -------------------------------------------------

def test_mori_tanaka_cross_check_dilute_einstein_limit():
    """Rigid spheres in an incompressible matrix: E_eff / E_m = 1 + 2.5 phi + O(phi^2)
    (Einstein / Smallwood). Iron in PDMS is rigid to 1e-5; nu = 0.4999 leaves O(1e-4)."""
    phi = 1e-4
    slope = (P.mori_tanaka_stiffening_ratio(phi, 0.4999, 2e6) - 1.0) / phi
    assert slope == pytest.approx(2.5, rel=2e-3)
    r = P.mori_tanaka_stiffening_ratio(np.linspace(0, 0.4, 9), 0.45, 2e6)
    assert r[0] == pytest.approx(1.0, abs=1e-14) and np.all(np.diff(r) > 0)


def test_stiffening_adapter_is_the_fem_table():
    from homogenize.experiments import rve_tables as T
    phi = np.linspace(0.0, 0.3, 7)
    np.testing.assert_array_equal(P.stiffening_ratio(phi, 0.45, 2e6), T.filler_stiffness_ratio(phi))
