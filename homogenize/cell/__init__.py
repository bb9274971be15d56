"""Periodic cell problems of one RVE: effective stiffness, effective body force, magnetic stress.

The voxel cell FEM (:mod:`homogenize.cell.problem`), the cut voxels with Nitsche coupling
(:mod:`homogenize.cell.cut`), conforming tetrahedral meshes (``_conforming``), the cell's local
fields for plots and ParaView (``_output``), the closed-form effective media it is checked
against (``_effective_media``), and particles that move in the matrix
(:mod:`homogenize.cell.relax`, with the periodic Green's function ``_green``). Stands on the
voxel grid (:mod:`homogenize.voxels`) and the solver layer (:mod:`homogenize.solvers`).
"""
from homogenize.cell.problem import (CellConfig, CellResult, Material, anisotropy_index,
                                     homogenize_cell, homogenize_mesh, homogenize_rve,
                                     isotropic_projection, magnetic_tol, tensor_to_voigt,
                                     voigt_to_tensor)
from homogenize.cell.cut import CutResult, homogenize_cut
from homogenize.cell._conforming import conforming_tet_mesh, homogenize_conforming

__all__ = ["CellConfig", "CellResult", "Material", "homogenize_cell", "homogenize_rve",
           "homogenize_mesh", "magnetic_tol", "isotropic_projection", "anisotropy_index",
           "voigt_to_tensor", "tensor_to_voigt", "CutResult", "homogenize_cut",
           "conforming_tet_mesh", "homogenize_conforming"]
