"""The periodic voxel grid: an RVE cut into voxels (:mod:`homogenize.voxels.mesh`), the Q1
element maths and assembly (``_assembly``), every numba kernel of ``homogenize``
(``_kernels``) and the one memory model of the cell solves (``_budget``).

The lowest layer of ``homogenize``: the solver layer and the cell problems stand on it.
"""
from homogenize.voxels.mesh import METHODS, VoxelMesh, sphere_voxel_fractions, voxelize

__all__ = ["VoxelMesh", "voxelize", "sphere_voxel_fractions", "METHODS"]
