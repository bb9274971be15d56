"""Measured data, the seed model, causes and their extensions, and ``diagnose``."""
__all__: list[str] = []
