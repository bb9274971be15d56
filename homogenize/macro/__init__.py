"""Macro solvers: cantilever and channel, closed forms, exporters for Elmer and Abaqus."""
__all__: list[str] = []
