"""mapsim.micro: the particle scale (particles, magnetization laws, periodic dipoles).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
from ._validate import InputError
from .rve import RVE
from .particles import (CoreShell, Histogram, LogNormal, Monodisperse, default_distribution,
                        describe, generate_rve)

__all__ = ["InputError"]
__all__ += ["RVE", "generate_rve", "describe", "LogNormal", "Histogram", "Monodisperse",
            "CoreShell", "default_distribution"]
from .magnetization import get_law
from .dipoles import (ConvergenceError, DipoleSum, MagneticState, applied_gradient,
                      dipole_field_direct, dipole_pair_interactions, solve)

__all__ += ["get_law", "solve", "MagneticState", "ConvergenceError", "DipoleSum",
            "applied_gradient", "dipole_field_direct", "dipole_pair_interactions"]
