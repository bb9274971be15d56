"""mapsim.micro: the particle scale (particles, magnetization laws, periodic dipoles).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
from ._validate import InputError

__all__ = ["InputError"]
