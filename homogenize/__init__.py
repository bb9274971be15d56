"""mapsim.homogenize: the RVE scale and above (cell FEM, batch tables, macro solvers,
applications).

Public API is what ``__all__`` lists; modules starting with ``_`` are private. The subpackages
follow the flow, each importing only from those before it: ``voxels`` (the grid), ``solvers``,
``cell`` (cell problems), ``tables`` (batch runs), then ``macro``, ``experiments``,
``studies``, ``bench`` and ``cli``, which are imported on their own.
"""
from homogenize.cell import (CellConfig, CellResult, CutResult, Material, conforming_tet_mesh,
                             homogenize_cell, homogenize_conforming, homogenize_cut,
                             homogenize_mesh, homogenize_rve)
from homogenize.voxels import VoxelMesh, voxelize
from homogenize.tables import Study, Table, load_study, read_table, run_batch

__all__: list[str] = [
    "CellConfig", "CellResult", "Material", "homogenize_cell", "homogenize_rve", "homogenize_mesh",
    "CutResult", "homogenize_cut",
    "conforming_tet_mesh", "homogenize_conforming",
    "VoxelMesh", "voxelize", "Table", "read_table", "run_batch", "Study", "load_study",
]
