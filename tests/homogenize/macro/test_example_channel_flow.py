"""examples/channel_flow.py runs and its numbers are consistent."""
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def ex(load_script):
    path = Path(__file__).resolve().parents[3] / "examples" / "channel_flow.py"
    return load_script(path)


def test_example_numbers(ex):
    b = ex.GEOMETRY.b_m
    centre_down = ex.CEILING.down_per_force_m4_N.max()
    # no field: the outlet (p = 0) keeps the undeformed height, the rest bulges open
    assert ex.NO_FIELD.flow_rate_m3_s == pytest.approx(ex.FLOW_RATE_M3_S, rel=1e-12)
    assert ex.NO_FIELD.min_gap_overall_m == pytest.approx(b, rel=1e-12)
    # seed force: the outlet gap is the linear FEM deflection, independent of the flow
    assert ex.AT_SEED_FORCE.min_gap_overall_m == pytest.approx(
        b - ex.BODY_FORCE_N_M3 * centre_down, rel=1e-9)
    assert ex.AT_SEED_FORCE.pressure_drop_Pa > ex.NO_FIELD.pressure_drop_Pa
    # target: f = (b - target) / centre compliance, the seed gradient linear in f
    t = ex.TARGET
    assert t.body_force_N_m3 == pytest.approx((b - ex.TARGET_GAP_M) / centre_down, rel=1e-9)
    assert ex.seed_force_of_gradient(t.field) == pytest.approx(t.body_force_N_m3, rel=1e-9)
    assert t.field == pytest.approx(t.body_force_N_m3 / ex.seed_force_of_gradient(1.0),
                                    rel=1e-9)
    assert t.flow.min_gap_overall_m == pytest.approx(ex.TARGET_GAP_M, rel=1e-9)
    assert t.x_target_m == pytest.approx(ex.GEOMETRY.d_m)
    # bulging: more flow than the rigid duct, increasingly so with the pressure drop
    gain = [q / qr for q, qr in ex.PRESSURE_SWEEP.values()]
    assert all(g > 1 for g in gain) and gain == sorted(gain)
