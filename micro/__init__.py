"""mapsim.micro: the particle scale (particles, magnetization laws, periodic dipoles).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
# first: chooses a writable numba cache before numba is imported (micro/common/numba_cache.py)
from micro.common import numba_cache as _numba_cache  # noqa: F401
from micro.common.validate import ConvergenceError, InputError
# result files (the commands' and the studies' in results/): atomic writes, floats rounded to
# RESULT_DIGITS, figures re-drawn only when their data digest changes
from micro.common.files import (RESULT_DIGITS, atomic_write_text, data_digest, round_floats, save_png,
                  write_json)
from micro.box import PeriodicBox
from micro.rve import RVE
from micro.particles import (CoreShell, Histogram, LogNormal, Monodisperse, default_distribution,
                        describe, generate_rve)

__all__ = ["InputError", "ConvergenceError"]
__all__ += ["atomic_write_text", "write_json", "round_floats", "data_digest", "save_png",
            "RESULT_DIGITS"]
__all__ += ["PeriodicBox", "RVE", "generate_rve", "describe", "LogNormal", "Histogram", "Monodisperse",
            "CoreShell", "default_distribution"]
from micro.particles import ParticleConfig, place
from micro.materials import FE, FE3O4, PDMS, SEED, Constituent, ElasticMaterial
from micro.magnetization import DEFAULT_LAW, LAW_NAMES, get_law, particle_regime
from micro.demag import (cylinder_demag_factors, ellipsoid_demag_factors, prism_demag_factors,
                    spheroid_demag_factors)
from micro.dipoles import (DipoleSum, FieldConfig, MagneticState, applied_gradient,
                      dipole_field_direct, dipole_pair_interactions, magnetize, solve)

__all__ += ["ParticleConfig", "place", "FE", "FE3O4", "PDMS", "SEED", "Constituent",
            "ElasticMaterial", "DEFAULT_LAW", "LAW_NAMES", "get_law", "particle_regime",
            "prism_demag_factors", "cylinder_demag_factors", "spheroid_demag_factors",
            "ellipsoid_demag_factors", "FieldConfig", "magnetize", "solve", "MagneticState",
            "DipoleSum", "applied_gradient", "dipole_field_direct", "dipole_pair_interactions"]
