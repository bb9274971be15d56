"""mapsim.micro: the particle scale (particles, magnetization laws, periodic dipoles).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
# first: chooses a writable numba cache before numba is imported (micro/_numba_cache.py)
from . import _numba_cache  # noqa: F401
from ._validate import ConvergenceError, InputError
from .rve import RVE
from .particles import (CoreShell, Histogram, LogNormal, Monodisperse, default_distribution,
                        describe, generate_rve)

__all__ = ["InputError", "ConvergenceError"]
__all__ += ["RVE", "generate_rve", "describe", "LogNormal", "Histogram", "Monodisperse",
            "CoreShell", "default_distribution"]
from .magnetization import get_law
from .dipoles import (DipoleSum, MagneticState, applied_gradient,
                      dipole_field_direct, dipole_pair_interactions, solve)

__all__ += ["get_law", "solve", "MagneticState", "DipoleSum",
            "applied_gradient", "dipole_field_direct", "dipole_pair_interactions"]
