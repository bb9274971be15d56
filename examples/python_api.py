"""The whole chain from Python: place -> magnetize -> homogenize -> (table) -> beam.

The same ten lines as the README's "Python API" section. Module-level names hold the results;
``python examples/python_api.py`` prints them. ``tests/test_examples.py`` runs this file.
"""
from homogenize.cell import CellConfig, homogenize_cell
from homogenize.macro.cantilever import Strip, solve_cantilever
from micro.dipoles import FieldConfig, magnetize
from micro.materials import ElasticMaterial
from micro.particles import ParticleConfig, place

rve = place(ParticleConfig(phi=0.035, n=100, seed=1))               # particles -> periodic RVE
state = magnetize(rve, FieldConfig(B_T=0.3, gradB_T_per_m=1.78))    # moments and forces
cell = homogenize_cell(rve, state, CellConfig(voxels=16))           # C_eff, f_eff, stress_mag
strip = Strip(length_m=0.019369, width_m=5e-3, thickness_m=1e-3)
beam = solve_cantilever(strip, ElasticMaterial(cell.E_eff_Pa, cell.nu_eff), cell.f_eff_N_m3[2],
                        model="elastica")

if __name__ == "__main__":
    print(f"M_eff = {state.M_eff_A_per_m[2]:.4g} A/m, f_eff = {cell.f_eff_N_m3[2]:.4g} N/m^3, "
          f"E_eff = {cell.E_eff_Pa:.4g} Pa (16^3 voxels), tip deflection {beam.tip_m * 1e3:.3f} mm")
