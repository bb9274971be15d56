"""The matrix-free voxel operator and its geometric multigrid: the public names.

What the solver studies in ``results/cell`` (and any user's experiment) may build their own
preconditioners from, handed to the cell solver through
:attr:`homogenize.solvers.SolverOptions.preconditioner`: the element field of a voxel grid
(:class:`ElementField`, :func:`element_field`, :func:`coarsen`), the operator
(:class:`MatFreeOperator`: products, residuals, block Gauss-Seidel sweeps), its assembled forms
(:func:`typed_bsr`, :func:`typed_rows_bsr`, :func:`stiffness_times_sparse`), the trilinear grid
transfers (:func:`restrict`, :func:`prolong_add`, :func:`prolongation_matrix`,
:func:`child_prolongations`), the parity colours (:func:`grid_colours`), the V-cycle
(:class:`GeometricVCycle`) and the particle patches of its fine level (:class:`ParticlePatches`);
``CORNERS``: the (x, y, z) offsets of a voxel's corner a = x + 2 y + 4 z, the local node order.

The implementation (numba kernels) is in the private ``_matfree`` and ``_patches``; this module
only names what may be used from outside them.
"""
from homogenize.solvers._matfree import (ElementField, GeometricVCycle, MatFreeOperator, child_prolongations,
                       coarsen, element_field, grid_colours,
                       node_stencils, prolong_add, prolongation_matrix, restrict,
                       stiffness_times_sparse, typed_bsr, typed_rows_bsr)
from homogenize.voxels._assembly import CORNERS
from homogenize.solvers._patches import ParticlePatches, patch_colours, patch_nodes, select_patches

__all__ = ["ElementField", "element_field", "coarsen", "MatFreeOperator", "GeometricVCycle",
           "typed_bsr", "typed_rows_bsr", "stiffness_times_sparse", "node_stencils",
           "restrict", "prolong_add", "prolongation_matrix", "child_prolongations",
           "grid_colours", "ParticlePatches", "patch_nodes",
           "patch_colours", "select_patches", "CORNERS"]
