"""Elmer / Abaqus exporters: snippets parse back to the same numbers."""
import numpy as np
import pytest

from homogenize.macro.exporters import (DIRECTIONS, ExportSpec, parse_abaqus, parse_elmer,
                                        to_abaqus, to_elmer)
from micro.common.validate import InputError


@pytest.mark.parametrize("direction", list(DIRECTIONS))
def test_round_trip(direction):
    spec = ExportSpec(43636.7839, 2.0e6 * 1.0123456789, 0.4499999, 1443.1, direction=direction)
    u = np.array(DIRECTIONS[direction], float)
    e = parse_elmer(to_elmer(spec))
    a = parse_abaqus(to_abaqus(spec))
    for p in (e, a):
        # repr() writes the shortest exact decimal: the round trip is bit-exact
        assert p["E_Pa"] == spec.E_Pa and p["nu"] == spec.nu
        assert p["density_kg_m3"] == spec.density_kg_m3
        np.testing.assert_array_equal(p["body_force_N_m3"], spec.body_force_N_m3 * u)
    assert a["gravity_m_s2"] == 0.0


def test_gravity():
    spec = ExportSpec(4e4, 2e6, 0.45, 1443.1, gravity_m_s2=9.81)
    e = parse_elmer(to_elmer(spec))
    assert e["body_force_N_m3"][2] == pytest.approx(-(4e4 + 1443.1 * 9.81), rel=1e-15)
    a = parse_abaqus(to_abaqus(spec))
    assert a["body_force_N_m3"][2] == -4e4 and a["gravity_m_s2"] == 9.81
    np.testing.assert_array_equal(a["gravity_direction"], [0, 0, -1])


def test_snippet_keywords():
    e = to_elmer(ExportSpec(1.0, 2e6, 0.45, 1210.0))
    for kw in ("Material 1", "Youngs Modulus", "Poisson Ratio", "Density", "Body Force 1",
               "Stress Bodyforce 3", "End"):
        assert kw in e
    a = to_abaqus(ExportSpec(1.0, 2e6, 0.45, 1210.0, elset="BEAM"))
    for kw in ("*MATERIAL, NAME=MAP_PDMS", "*ELASTIC", "*DENSITY", "*DLOAD", "BEAM, BZ, -1.0"):
        assert kw in a


@pytest.mark.parametrize("kw,msg", [(dict(nu=0.5), "nu"), (dict(E_Pa=-1.0), "E_Pa"),
                                    (dict(direction="z"), "direction"),
                                    (dict(name="1bad name"), "name")])
def test_bad_input(kw, msg):
    args = dict(body_force_N_m3=1.0, E_Pa=2e6, nu=0.45, density_kg_m3=1210.0) | kw
    with pytest.raises(InputError, match=msg):
        ExportSpec(**args)
    with pytest.raises(InputError, match="Youngs Modulus"):
        parse_elmer("Material 1\nEnd\n")


def test_deck_physics_helpers_against_closed_forms():
    """The NLGEOM rule's linear estimates and the magnet's body force against closed forms."""
    from scipy.constants import mu_0
    from homogenize.macro.cantilever import Strip
    from homogenize.macro.channel import ChannelGeometry
    from homogenize.macro.exporters import linear_deflection_estimate_m, magnet_body_force
    from homogenize.macro.magnets import PermanentMagnet, linear_magnetization
    L, w, t, E, nu = 19.369e-3, 5e-3, 1e-3, 2e6, 0.45
    spec = ExportSpec(4e4, E, nu, 1210.0, gravity_m_s2=9.81)
    q = 4e4 + 1210.0 * 9.81
    # cantilever, uniform load: q w t L^4 / (8 E w t^3 / 12)
    assert linear_deflection_estimate_m("cantilever", spec, Strip(L, w, t)) == \
        pytest.approx(1.5 * q * L**4 / (E * t**2), rel=1e-12)
    # channel ceiling: clamped plate strip, q c a^4 / (384 D), D = E c^3 / (12 (1 - nu^2))
    g = ChannelGeometry(a_m=5e-3, b_m=50e-6, c_m=0.5e-3, d_m=10e-3)
    D = E * g.c_m**3 / (12 * (1 - nu**2))
    assert linear_deflection_estimate_m("channel", spec, g) == \
        pytest.approx(q * g.c_m * g.a_m**4 / (384 * D), rel=1e-12)
    # on the axis of a cylinder magnet (radius R, faces at zc -+ H/2, along +z), linear law
    # M = chi H, no demagnetization: f_z = chi / mu0 B_z dB_z/dz with the closed-form axial field
    R, H, Br, zc, chi = 5e-3, 5e-3, 1.2, -0.010, 0.05
    f = magnet_body_force(PermanentMagnet("cylinder", (2 * R, H), Br, (0.0, 0.0, zc)),
                          linear_magnetization(chi), 0.0)
    z = np.array([0.0, 1e-3, 4e-3])
    d1, d2 = z - (zc + H / 2), z - (zc - H / 2)
    Bz = Br / 2 * (d2 / np.hypot(d2, R) - d1 / np.hypot(d1, R))
    dBz = Br / 2 * R**2 * (np.hypot(d2, R)**-3 - np.hypot(d1, R)**-3)
    got = f(np.column_stack([np.zeros(3), np.zeros(3), z]))
    np.testing.assert_allclose(got[:, 2], chi / mu_0 * Bz * dBz, rtol=1e-6)
    np.testing.assert_allclose(got[:, :2], 0.0, atol=1e-9 * np.abs(got[:, 2]).max())


def test_export_matrix_material_fills_the_material(tmp_path):
    """`export --matrix-material` fills --E-Pa, --nu, --density-kg-m3 that were not given
    (explicit options win), as in `beam` (issue 36)."""
    from homogenize.cli import main
    from micro.materials import matrix_preset
    m = matrix_preset("ecoflex-00-30")
    out = tmp_path / "a.inp"
    assert main(["export", "--to", "abaqus", "--body-force-N-m3", "4e4", "--matrix-material",
                 "ecoflex-00-30", "--out", str(out)]) == 0
    p = parse_abaqus(out.read_text())
    assert np.isclose(p["E_Pa"], m.E_Pa) and np.isclose(p["nu"], m.nu)
    assert np.isclose(p["density_kg_m3"], m.density_kg_m3)
    out2 = tmp_path / "b.inp"
    assert main(["export", "--to", "abaqus", "--body-force-N-m3", "4e4", "--matrix-material",
                 "ecoflex-00-30", "--E-Pa", "3e5", "--out", str(out2)]) == 0
    p2 = parse_abaqus(out2.read_text())
    assert np.isclose(p2["E_Pa"], 3e5) and np.isclose(p2["nu"], m.nu)
