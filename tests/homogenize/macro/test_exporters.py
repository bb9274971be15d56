"""Elmer / Abaqus exporters: snippets parse back to the same numbers."""
import numpy as np
import pytest

from homogenize.macro.exporters import (DIRECTIONS, ExportSpec, parse_abaqus, parse_elmer,
                                        to_abaqus, to_elmer)
from micro._validate import InputError


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
