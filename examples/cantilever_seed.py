"""The seed paper's cantilever in a few lines: body force from Eqs. (1)-(3), tip deflections.

A 20 mm x 5 mm x 1 mm PDMS strip (E = 2 MPa, nu = 0.45) clamped at one end carries the seed
body force c d rho sigma_s dB/dx (about 43.6 kN/m^3). Euler-Bernoulli, Timoshenko, the elastica
(large deflection) and 3D finite elements (quadratic tetrahedra, linear and neo-Hookean) give its
tip deflection. Run it to print the table and save a plot; import it to use the numbers.
"""
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material
from homogenize.studies.paper import SeedParameters, seed_body_force

SEED = SeedParameters()
BODY_FORCE_N_M3 = seed_body_force(SEED.c, SEED.d, SEED.radius_m, SEED.sigma_s_Am2_kg,
                                  SEED.particle_density_kg_m3, SEED.gradB_T_per_m)["F_b_N_m3"]
STRIP = Strip(length_m=20e-3, width_m=5e-3, thickness_m=1e-3)
MATERIAL = Material(E_Pa=SEED.E_Pa, nu=SEED.nu, density_kg_m3=SEED.pdms_density_kg_m3)
#: half strip, two element layers through the thickness: P2 within ~4 % of the converged tip
FEM = {"divisions": (14, 2, 2), "order": 2}

RESULTS = {model: solve_cantilever(STRIP, MATERIAL, BODY_FORCE_N_M3, model=model,
                                   **(FEM if model in ("fem", "neo-hookean") else {}))
           for model in ("eb", "timoshenko", "elastica", "fem", "neo-hookean")}
TIP_M = {model: r.tip_m for model, r in RESULTS.items()}


if __name__ == "__main__":
    from matplotlib.figure import Figure

    print(f"seed body force: {BODY_FORCE_N_M3 / 1e3:.3f} kN/m^3")
    for model, r in RESULTS.items():
        print(f"{model:<12} tip {r.tip_m * 1e3:7.3f} mm   towards clamp "
              f"{r.tip_horizontal_m * 1e3:6.3f} mm")
    fig = Figure(figsize=(5, 3.5))
    ax = fig.subplots()
    ax.bar(list(TIP_M), [v * 1e3 for v in TIP_M.values()])
    ax.set_ylabel("tip deflection [mm]")
    ax.set_title("20 x 5 x 1 mm PDMS strip, seed body force")
    fig.tight_layout()
    fig.savefig("cantilever_seed.png", dpi=120)
    print("wrote cantilever_seed.png")
