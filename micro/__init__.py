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
