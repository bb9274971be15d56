"""Blood plasma through the seed paper's tunable channel, with the field pulling the ceiling.

Channel a = 5 mm wide, b = 50 um high, ceiling c = 0.5 mm, length d = 10 mm, PDMS (E = 2 MPa,
nu = 0.45). The ceiling's response to pressure and body force comes from the 3D channel FEM;
the flow is coupled to the deformation along the channel (lubrication approximation).

* at 10 uL/min: pressure drop and gaps with no field and at the seed force 40 kN/m^3;
* the body force, and the field gradient of the seed formula (saturated particles,
  ``f = c d rho sigma_s dB/dz``), that bring the smallest gap down to 15 um (cells of 10-20 um
  held back);
* flow rate against pressure drop without field, deformable against rigid.

Run it to print the numbers and write results/channel_flow/ (JSON with manifest, plot);
import it to use the numbers.
"""
from homogenize.experiments.seed_model import seed_body_force_N_m3
from homogenize.macro.channel import ChannelGeometry
from homogenize.macro.fem import Material
from homogenize.macro.flow import (BLOOD_PLASMA, CeilingModel, field_for_target_gap,
                                   solve_channel_flow)
from micro.materials import PDMS, SEED

GEOMETRY = ChannelGeometry(a_m=5e-3, b_m=50e-6, c_m=0.5e-3, d_m=10e-3)
MATERIAL = Material(E_Pa=PDMS.E_Pa, nu=PDMS.nu, density_kg_m3=PDMS.density_kg_m3)
CEILING = CeilingModel.from_fem(GEOMETRY, MATERIAL)
FLOW_RATE_M3_S = 10e-9 / 60.0                 # 10 uL/min
BODY_FORCE_N_M3 = SEED.abaqus_force_N_m3      # 40 kN/m^3
TARGET_GAP_M = 15e-6
PHI = SEED.c * SEED.d                          # particle volume fraction of the seed


def seed_force_of_gradient(gradB_T_per_m: float) -> float:
    """Seed body force [N/m^3] at a field gradient [T/m] (saturated, non-interacting)."""
    return float(seed_body_force_N_m3(PHI, gradB_T_per_m, SEED.particle_density_kg_m3,
                                      SEED.sigma_s_Am2_kg))


NO_FIELD = solve_channel_flow(CEILING, GEOMETRY.d_m, flow_rate_m3_s=FLOW_RATE_M3_S,
                              liquid=BLOOD_PLASMA)
AT_SEED_FORCE = solve_channel_flow(CEILING, GEOMETRY.d_m, body_force_N_m3=BODY_FORCE_N_M3,
                                   flow_rate_m3_s=FLOW_RATE_M3_S, liquid=BLOOD_PLASMA)
TARGET = field_for_target_gap(CEILING, GEOMETRY.d_m, TARGET_GAP_M,
                              flow_rate_m3_s=FLOW_RATE_M3_S, liquid=BLOOD_PLASMA,
                              body_force_of_field=seed_force_of_gradient,
                              field_range=(0.0, 200.0), field_unit="T/m")
#: pressure drop [Pa] -> (flow rate of the deformable channel, of the rigid one) [m^3/s]
PRESSURE_SWEEP = {dp: (r.flow_rate_m3_s, r.rigid_flow_rate_m3_s) for dp, r in (
    (dp, solve_channel_flow(CEILING, GEOMETRY.d_m, pressure_drop_Pa=dp))
    for dp in (30.0, 100.0, 300.0, 1000.0))}


if __name__ == "__main__":
    from pathlib import Path

    from micro.common.files import manifest, write_json

    out = Path(__file__).resolve().parents[1] / "results" / "channel_flow"
    ul_min = 6e10
    print(f"ceiling: {CEILING.source}; centre uplift {CEILING.up_per_pressure_m_Pa.max():.3g} "
          f"m/Pa, centre deflection {CEILING.down_per_force_m4_N.max():.3g} m per N/m^3")
    for name, r in (("no field", NO_FIELD), ("40 kN/m^3", AT_SEED_FORCE)):
        print(f"{name:>10}: Q = {r.flow_rate_m3_s * ul_min:.3g} uL/min, dp = "
              f"{r.pressure_drop_Pa:.4g} Pa (rigid duct {FLOW_RATE_M3_S / r.rigid_flow_rate_m3_s * r.pressure_drop_Pa:.4g} Pa), "
              f"smallest gap {r.min_gap_overall_m * 1e6:.3f} um at x = {r.x_min_gap_m * 1e3:.2f} mm")
    t = TARGET
    print(f"target gap {t.target_gap_m * 1e6:.1f} um: body force {t.body_force_N_m3:.4g} N/m^3, "
          f"seed gradient {t.field:.3g} T/m, reached at x = {t.x_target_m * 1e3:.2f} mm; "
          f"dp = {t.flow.pressure_drop_Pa:.4g} Pa at 10 uL/min")
    for dp, (q, qr) in PRESSURE_SWEEP.items():
        print(f"dp = {dp:6.0f} Pa: Q = {q * ul_min:8.3g} uL/min (rigid {qr * ul_min:8.3g})")
    from homogenize.macro.flow import plot_channel_flow
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "channel_flow.json", {
        "geometry": vars(GEOMETRY), "material": vars(MATERIAL),
        "liquid": vars(BLOOD_PLASMA), "flow_rate_m3_s": FLOW_RATE_M3_S,
        "no_field": NO_FIELD.to_dict(), "at_40kN_m3": AT_SEED_FORCE.to_dict(),
        "target": TARGET.to_dict(),
        "pressure_sweep": [{"pressure_drop_Pa": dp, "flow_rate_m3_s": q,
                            "rigid_flow_rate_m3_s": qr} for dp, (q, qr) in
                           PRESSURE_SWEEP.items()],
        "manifest": manifest({"example": "examples/channel_flow.py"}, None)})
    plot_channel_flow(TARGET.flow, target_gap_m=TARGET_GAP_M).savefig(
        out / "channel_flow.png", dpi=120)
    print(f"wrote {out}/channel_flow.json and channel_flow.png")
