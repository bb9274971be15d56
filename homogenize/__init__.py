"""mapsim.homogenize: the RVE scale and above (cell FEM, batch tables, macro solvers,
applications).

Public API is what ``__all__`` lists; modules starting with ``_`` are private. The subpackages
``macro``, ``experiments``, ``studies``, ``bench`` and ``cli`` are imported on their own.
"""
from .cell import CellConfig, CellResult, Material, homogenize, homogenize_mesh, homogenize_rve
from .cut import CutResult, homogenize_cut
from ._conforming import conforming_tet_mesh, homogenize_conforming
from .mesh import VoxelMesh, voxelize
from .tables import Table, read_table, run_batch
from ._study import Study, load_study

__all__: list[str] = [
    "CellConfig", "CellResult", "Material", "homogenize", "homogenize_rve", "homogenize_mesh",
    "CutResult", "homogenize_cut",
    "conforming_tet_mesh", "homogenize_conforming",
    "VoxelMesh", "voxelize", "Table", "read_table", "run_batch", "Study", "load_study",
]
