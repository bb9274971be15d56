"""mapsim.homogenize: the RVE scale and above (FEM homogenization, tables, macro solvers).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
__all__: list[str] = []
