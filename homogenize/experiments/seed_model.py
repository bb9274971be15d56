"""The seed model (spec section 3): what "the simulation" predicts before any extension.

Every particle carries its saturated moment ``m = sigma_s rho_p V`` along the applied field; no
particle interacts with another; the matrix is linear elastic with its own E (particles neither
stiffen it nor weigh anything); small strains and small deflections; no self-weight; one
response for rising and falling branches; the applied field is the field inside the specimen.

Per kind (``Ms_p = rho_p sigma_s`` is the particle material's saturation magnetization):

* magnetization: ``M = scale phi Ms_p sign(H)``;
* deflection: body force ``f = scale phi Ms_p dB/dz`` (the seed paper's ``N F_g / V`` with the
  packing factor folded into ``scale``), tip deflection of Euler-Bernoulli,
  ``delta = 3 f L^4 / (2 E t^2)``;
* magnetostriction: non-interacting dipoles in a uniform field feel no force, so the seed
  model predicts no strain at all (``scale`` cannot be identified; it is reported as 1);
* tensile: Hooke, ``stress = E strain`` with E fitted.

The single fitted parameter is ``scale`` (magnetic kinds) or ``E_Pa`` (tensile).
"""
from __future__ import annotations

import numpy as np
from micro.materials import SEED

from homogenize.experiments.io import Experiment

__all__ = ["seed_body_force_N_m3", "seed_predict", "seed_parameter"]


def seed_parameter(kind: str) -> str:
    """Name of the seed model's one fitted parameter for ``kind``."""
    return "E_Pa" if kind == "tensile" else "scale"


def seed_body_force_N_m3(phi, gradB_T_per_m, density_kg_m3=SEED.particle_density_kg_m3,
                         sigma_s_Am2_kg=SEED.sigma_s_Am2_kg,
                         scale=1.0):
    """Seed body force ``scale phi rho_p sigma_s dB/dz`` [N/m^3].

    With the seed paper's numbers (phi = c d = 0.035 * 0.5, 1.78 T/m) this is 43.6 kN/m^3; the
    paper quotes 43.79 kN/m^3.
    """
    return scale * np.asarray(phi) * density_kg_m3 * sigma_s_Am2_kg * np.asarray(gradB_T_per_m)


def seed_predict(exp: Experiment, param: float) -> np.ndarray:
    """Seed-model prediction of the measured column of ``exp`` with its fitted parameter.

    Parameters
    ----------
    exp : Experiment
    param : float -- ``scale`` [-] for magnetic kinds, ``E_Pa`` [Pa] for tensile

    Returns
    -------
    ndarray, shape (n_rows,) -- in the unit of the measured column
    """
    c = exp.columns
    if exp.kind == "tensile":
        return param * c["strain"]
    Ms = exp.particles.Ms_A_per_m
    if exp.kind == "magnetization":
        return param * c["phi"] * Ms * np.sign(c["H_A_per_m"])
    if exp.kind == "magnetostriction":
        return np.zeros(exp.n_rows)
    f = seed_body_force_N_m3(c["phi"], c["gradB_T_per_m"], exp.particles.density_kg_m3,
                             exp.particles.sigma_s_Am2_kg, param)
    # Euler-Bernoulli, written out here as the reference the composed model is tested against
    return 1.5 * f * c["length_m"] ** 4 / (exp.matrix.E_Pa * c["thickness_m"] ** 2)

