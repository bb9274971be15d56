"""The solver layer: operators, preconditioners and Krylov drivers, and their frozen options.

The only place the project sets up a solver: the cell FEM (:mod:`homogenize.cell.problem`), the cut
voxels (:mod:`homogenize.cell.cut`), the conforming meshes and the macro FEM all take their
smoothed-aggregation hierarchies (:func:`smoothed_aggregation`, near-null space from
:func:`rigid_body_modes`), V-cycles and block CG from here. Settings are frozen objects passed in
(:class:`SolverOptions`, :class:`AMGOptions`), never module globals.

Modules: ``options`` (the settings), ``amg`` (smoothed aggregation, its block V-cycle, the BSR
operator), ``krylov`` (block CG, coupled block CG, deflation), and the private ``_matfree`` (the
matrix-free voxel operator and its geometric multigrid) and ``_patches`` (the particle patches
of its fine level), whose public names are in ``matfree``. Numba kernels: :mod:`homogenize.voxels._kernels`, and (not yet moved there) the
node-operator, transfer and patch kernels inside ``_matfree`` and ``_patches``.
"""
from homogenize.solvers.amg import (SA_SMOOTH, BlockVCycle, BSROp, greedy_colours, grid_colours,
                  grid_node_coordinates, rigid_body_modes, smoothed_aggregation)
from homogenize.solvers.krylov import Deflation, block_cg, coupled_block_cg
from homogenize.solvers.options import BLOCK_CG_MODES, MATFREE_COARSE_SOLVERS, AMGOptions, SolverOptions

__all__ = ["SolverOptions", "AMGOptions", "BLOCK_CG_MODES", "MATFREE_COARSE_SOLVERS",
           "smoothed_aggregation", "rigid_body_modes", "grid_node_coordinates", "SA_SMOOTH",
           "BSROp", "BlockVCycle", "grid_colours", "greedy_colours",
           "Deflation", "block_cg", "coupled_block_cg"]
