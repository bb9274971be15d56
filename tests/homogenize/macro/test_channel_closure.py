"""The field that shuts the channel (issue 35, item 2 for the channel): closed form for a clamped
plate ceiling, the flow solver as an independent check, and `mapsim channel --close`."""
import json
import math

import numpy as np
import pytest

from homogenize.cli import main
from homogenize.macro.channel import ChannelGeometry
from homogenize.macro.fem import Material
from homogenize.macro.flow import CeilingModel, closure, solve_channel_flow
from micro.common.validate import InputError

GEO = ChannelGeometry(5e-3, 50e-6, 0.5e-3, 10e-3)
MAT = Material(2e6, 0.45, 1030.0)


@pytest.mark.parametrize("dp, p_out", [(0.0, 0.0), (100.0, 0.0), (1000.0, 50.0)])
def test_clamped_plate_closes_at_its_closed_form(dp, p_out):
    """Plate strip: centre deflection q a^4 / (384 D) with q = f c - p reaches b:
    f = 384 D b / (c a^4) + p_in / c, at the centre line and the outlet."""
    c = CeilingModel.clamped_plate(GEO, MAT)
    D = MAT.E_Pa * GEO.c_m ** 3 / (12 * (1 - MAT.nu ** 2))
    r = closure(c, GEO.d_m, pressure_drop_Pa=dp, outlet_pressure_Pa=p_out)
    want = 384 * D * GEO.b_m / (GEO.c_m * GEO.a_m ** 4) + (p_out + dp) / GEO.c_m
    assert math.isclose(r.body_force_N_m3, want, rel_tol=1e-12)
    assert math.isclose(r.body_force_first_contact_N_m3,
                        384 * D * GEO.b_m / (GEO.c_m * GEO.a_m ** 4) + p_out / GEO.c_m,
                        rel_tol=1e-12)
    assert r.y_contact_m == pytest.approx(GEO.a_m / 2) and r.x_contact_m == GEO.d_m
    assert math.isclose(r.lift_off_Pa_per_N_m3, GEO.c_m, rel_tol=1e-12)


@pytest.mark.parametrize("source", ["plate", "fem"])
def test_flow_solver_stops_exactly_there(source):
    """Independent route: the coupled flow at a fixed pressure drop passes liquid 1 % below
    the closing force and none 1 % above it."""
    c = (CeilingModel.clamped_plate(GEO, MAT) if source == "plate"
         else CeilingModel.from_fem(GEO, MAT))
    dp = 200.0
    f = closure(c, GEO.d_m, pressure_drop_Pa=dp).body_force_N_m3
    below = solve_channel_flow(c, GEO.d_m, body_force_N_m3=0.99 * f, pressure_drop_Pa=dp)
    above = solve_channel_flow(c, GEO.d_m, body_force_N_m3=1.01 * f, pressure_drop_Pa=dp)
    assert below.flow_rate_m3_s > 0 and above.flow_rate_m3_s == 0.0
    # the 3D block's ceiling (rotating edges) is more compliant than the clamped plate
    if source == "fem":
        plate = closure(CeilingModel.clamped_plate(GEO, MAT), GEO.d_m, pressure_drop_Pa=dp)
        assert f < plate.body_force_N_m3


def test_closure_refuses_an_outlet_that_is_shut_already():
    c = CeilingModel.clamped_plate(GEO, MAT)
    with pytest.raises(InputError, match="outlet pressure"):
        closure(c, GEO.d_m, outlet_pressure_Pa=-1e9)


def test_cli_close(tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["channel", "--close", "--pressure-drop-Pa", "100", "--matrix-material",
                 "sylgard184-10to1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "the channel shuts against 100 Pa at body force" in text
    assert "touches the glass at the outlet (x = 0.01 m), y = 0.0025 m" in text
    d = json.loads(out.read_text())["closure"]
    assert d["inlet_pressure_Pa"] == 100.0 and d["x_contact_m"] == pytest.approx(0.01)
    assert d["body_force_N_m3"] > d["body_force_first_contact_N_m3"] > 0
    assert np.isclose(d["body_force_N_m3"] - d["body_force_first_contact_N_m3"],
                      100.0 / d["lift_off_Pa_per_N_m3"], rtol=1e-9)


@pytest.mark.parametrize("extra, words", [
    (["--flow-rate-m3-s", "1e-10"], "flow rate never shuts"),
    (["--target-gap-m", "1e-5", "--pressure-drop-Pa", "10"], "--close takes"),
])
def test_cli_close_bad_input(extra, words, tmp_path, capsys):
    assert main(["channel", "--close", *extra, "--json", str(tmp_path / "x.json")]) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()
