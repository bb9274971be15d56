"""mapsim.homogenize: the RVE scale and above (FEM homogenization, tables, macro solvers).

Public API is what ``__all__`` lists; modules starting with ``_`` are private.
"""
# FEM homogenization (owner: FEM helper)
from .cell import CellResult, Material, homogenize_mesh, homogenize_rve
from .mesh import VoxelMesh, voxelize

__all__: list[str] = [
    # FEM homogenization
    "CellResult", "Material", "homogenize_rve", "homogenize_mesh", "VoxelMesh", "voxelize",
]
