"""The specimen in its field: Lamb's sphere (pole 5/57, mean 1/15), the microstructural stress,
the cylinder's mean strain against the virtual work of its demagnetizing energy, bad input."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from homogenize.experiments._physics import shape_stress_coefficient
from homogenize.macro import finite_strain as fs
from homogenize.macro import magnetostatics as ms
from homogenize.macro.specimen import Specimen, solve_specimen
from micro._validate import InputError

R = 1e-3
CHI = 1e-3            # weakly magnetizable: M uniform to O(chi) inside an ellipsoid and the
B = 1.0               # cylinder, so the closed forms for a fixed uniform M apply
G = 1e3               # mu0 M^2 / G ~ 1e-6: the linear (small-strain) limit


def _M_sphere():
    return CHI * (B / MU0) / (1.0 + CHI / 3.0)


@pytest.fixture(scope="module")
def sphere_continuum():
    return solve_specimen(Specimen("sphere", R, n_mesh=12, n_boundary=64), ms.linear(CHI),
                          fs.NeoHookeanSolid.incompressible(G), [B])


def test_sphere_pole_and_mean_strain_are_lambs(sphere_continuum):
    """Kelvin loads on a uniformly magnetized sphere: the traction (mu0/2)(M.n)^2 n and no body
    force; Lamb's solution: pole strain 5/57 mu0 M^2/G, mean axial strain 1/15 mu0 M^2/G.
    1 %: the mechanics mesh (n = 12) is within 0.2 % (finite_strain's own rate study), the field
    mesh's N within 2e-3 (magnetostatics), their product within 0.5 %."""
    st = sphere_continuum.steps[0]
    unit = MU0 * _M_sphere() ** 2 / G
    assert st.M_mean_A_per_m == pytest.approx(_M_sphere(), rel=1e-3)
    assert st.strain_axis == pytest.approx(5.0 / 57.0 * unit, rel=1e-2)   # u_z(pole) / R
    assert st.mean_strain_zz == pytest.approx(unit / 15.0, rel=1e-2)
    # the pole is not the mean: 75/57 times it
    assert st.strain_axis / st.mean_strain_zz == pytest.approx(75.0 / 57.0, rel=2e-2)
    assert st.lateral_strain < 0 and math.isnan(st.length_change_mean_m)


def test_affine_lorentz_stress_cancels_the_mean_but_not_the_length():
    """With the isotropic (Lorentz) microstructural stress kappa = 1/5 the mean strain of a
    sphere vanishes (shape and microstructure cancel in the mean), the change of length is
    (5/57 - 1/15) mu0 M^2 / G."""
    res = solve_specimen(Specimen("sphere", R, n_mesh=12, n_boundary=64), ms.linear(CHI),
                         fs.NeoHookeanSolid.incompressible(G), [B], model="affine", kappa=0.2)
    st = res.steps[0]
    unit = MU0 * _M_sphere() ** 2 / G
    # a uniform sigma_mag strains the free body uniformly (exact on any mesh): what is left is
    # the discretization error of the Kelvin part, 1 % of it as in the continuum test
    assert abs(st.mean_strain_zz) < 1e-2 * unit / 15.0
    assert st.strain_axis == pytest.approx((5.0 / 57.0 - 1.0 / 15.0) * unit,
                                           abs=1e-2 * 5.0 / 57.0 * unit)


def test_cylinder_mean_strain_converges_to_the_virtual_work_of_its_demagnetizing_energy():
    """An independent route: at fixed uniform M the mean axial stress of the magnetic loads on a
    cylinder is -(3/4) a dN/da mu0 M^2 (the derivative of its demagnetizing energy under an
    isochoric stretch, homogenize.experiments._physics.shape_stress_coefficient), so the mean
    strain of an incompressible body is that over 3 G. The Kelvin loads converge at first
    order in the field mesh (the traction near the rim): measured +2.9 % at 64 boundary
    segments, +1.5 % at 128, +0.6 % at 256 (n_mesh 10-20)."""
    k = shape_stress_coefficient(0.8)
    errs = []
    for nb in (64, 128):
        spec = Specimen("cylinder", R, length_m=1.6 * R, n_mesh=10, n_boundary=nb,
                        edge_radius_m=0.0)
        st = solve_specimen(spec, ms.linear(CHI), fs.NeoHookeanSolid.incompressible(G),
                            [B]).steps[0]
        M = st.M_mean_A_per_m
        errs.append(st.mean_strain_zz / (k * MU0 * M ** 2 / (3 * G)) - 1.0)
        # the ends are pulled out less than the mean on the axis: the end faces bulge at the
        # rim, where the traction concentrates (strain on the axis 0.92 of the mean)
        assert 0 < st.strain_axis < st.mean_strain_zz
        assert np.isfinite(st.strain_end_mean)
    assert abs(errs[1]) < 0.02
    assert abs(errs[0]) / abs(errs[1]) > 1.5          # converging (first order: 2)


def test_finite_strain_coupling_follows_the_deformed_shape():
    """At mu0 M^2/G ~ 0.3 the sphere elongates by a few per cent and the field is solved on the
    deformed body: its demagnetizing factor falls as that of a spheroid with the same axes
    (Osborn), within 15 % of the change (the deformed body is not exactly a spheroid), and the
    staggered iteration contracts."""
    from micro.demag import spheroid_demag_factors
    spec = Specimen("sphere", R, n_mesh=6, n_boundary=32)
    law = ms.froehlich_kennelly(2.0, 4e5)
    stiff = solve_specimen(spec, law, fs.NeoHookeanSolid.incompressible(2e7), [0.5]).steps[0]
    soft = solve_specimen(spec, law, fs.NeoHookeanSolid.incompressible(2e5), [0.5]).steps[0]
    assert soft.strain_axis > 0.02
    dN = soft.demag_factor - stiff.demag_factor                 # same mesh error cancels
    a, c = R * (1 + soft.lateral_strain), R * (1 + soft.strain_axis)
    dN_spheroid = spheroid_demag_factors(c, a)[2] - 1.0 / 3.0
    assert dN == pytest.approx(dN_spheroid, rel=0.15)
    h = soft.stagger_history
    assert soft.stagger_iterations <= 8 and all(b < a for a, b in zip(h, h[1:]))


@pytest.mark.parametrize("kwargs, match", [
    ({"B_applied_T": [0.2, 0.1]}, "increase strictly"),
    ({"B_applied_T": [-0.1, 0.1]}, "increase strictly"),
    ({"model": "magic"}, "model"),
    ({"model": "affine"}, "needs kappa"),
    ({"relaxation": 0.0}, "relaxation"),
])
def test_bad_input_is_refused_before_any_work(kwargs, match):
    args = {"B_applied_T": [0.1], **kwargs}
    B = args.pop("B_applied_T")
    with pytest.raises(InputError, match=match):
        solve_specimen(Specimen("sphere", R), ms.linear(0.5),
                       fs.NeoHookeanSolid.incompressible(1e5), B, **args)


def test_specimen_geometry_is_checked():
    with pytest.raises(InputError, match="needs length_m"):
        Specimen("cylinder", R)
    with pytest.raises(InputError, match="spheroid"):
        Specimen("sphere", R, length_m=3 * R)
    with pytest.raises(InputError, match="shape"):
        Specimen("cube", R, length_m=R)


def test_magnetic_pressure_against_closed_forms():
    """psi = mu0 int_0^H M dh: linear mu0 chi H^2 / 2; Froehlich-Kennelly
    mu0 [Ms H - Ms^2/chi0 ln(1 + chi0 H / Ms)]; tanh mu0 Ms^2/chi0 ln cosh(chi0 H / Ms). The
    24-point Gauss rule integrates these smooth M(h) to 4e-9 at H = 10 Ms (the FK knee at
    h = Ms / chi0 is the least smooth part), to ~1e-12 below Ms."""
    from homogenize.macro.specimen import magnetic_pressure_Pa
    H = np.array([0.0, 1e3, 1e5, 4e5, 4e6])
    np.testing.assert_allclose(magnetic_pressure_Pa(ms.linear(2.0), H), MU0 * H ** 2,
                               rtol=1e-12)
    c, Ms = 3.0, 4e5
    fk = MU0 * (Ms * H - Ms ** 2 / c * np.log1p(c * H / Ms))
    np.testing.assert_allclose(magnetic_pressure_Pa(ms.froehlich_kennelly(c, Ms), H), fk,
                               rtol=1e-8, atol=1e-12)
    th = MU0 * Ms ** 2 / c * np.log(np.cosh(c * H[:-1] / Ms))
    np.testing.assert_allclose(magnetic_pressure_Pa(ms.tanh(c, Ms), H[:-1]), th, rtol=1e-9,
                               atol=1e-12)


def test_table_law_interpolates_and_is_never_extrapolated():
    """A TableLaw goes through its nodes, is monotone (PCHIP), and a body whose internal field
    leaves its range is refused with the range named."""
    law = ms.TableLaw((1e4, 1e5, 3e5), (2e4, 1.5e5, 2e5), source="test table")
    np.testing.assert_allclose(law.M_A_per_m(np.array([1e4, 1e5, 3e5])), [2e4, 1.5e5, 2e5])
    h = np.linspace(0, 3e5, 301)
    assert np.all(np.diff(law.M_A_per_m(h)) >= 0) and np.all(law.dM_dH(h[:-1]) >= 0)
    with pytest.raises(InputError, match="not extrapolated"):
        solve_specimen(Specimen("sphere", R, n_mesh=4, n_boundary=24), law,
                       fs.NeoHookeanSolid.incompressible(1e6), [0.5])
    with pytest.raises(InputError, match="strictly"):
        ms.TableLaw((1e4, 1e4), (1.0, 2.0))


def test_rounded_rim_has_the_volume_of_its_profile():
    """The cylinder's rim rounded with radius rho: the mechanics mesh (the corner square mapped
    onto a quarter disk) and the field profile (an arc of 16 segments) describe the same body:
    their volumes agree within 0.5 % (both polygons, of different resolutions)."""
    spec = Specimen("cylinder", R, length_m=1.6 * R, n_mesh=12, edge_radius_m=0.2 * R)
    body = spec.mechanics_body()
    from homogenize.macro.specimen import _field_shape
    V_profile = _field_shape(spec).volume_m3
    assert body.volume_m3 == pytest.approx(V_profile, rel=5e-3)
    assert V_profile < math.pi * R ** 2 * 1.6 * R
    with pytest.raises(InputError, match="edge_radius_m"):
        Specimen("cylinder", R, length_m=1.6 * R, edge_radius_m=0.6 * R)
    with pytest.raises(InputError, match="edge_radius_m"):
        Specimen("sphere", R, edge_radius_m=0.1 * R)
