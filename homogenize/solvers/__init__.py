"""The solver layer: operators, preconditioners and Krylov drivers, and their frozen options.

The only place the project sets up a solver: the cell FEM (:mod:`homogenize.cell`), the cut
voxels (:mod:`homogenize.cut`), the conforming meshes and the macro FEM all take their
smoothed-aggregation hierarchies (:func:`smoothed_aggregation`, near-null space from
:func:`rigid_body_modes`), V-cycles and block CG from here. Settings are frozen objects passed in
(:class:`SolverOptions`, :class:`AMGOptions`), never module globals.
"""
from .amg import (SA_SMOOTH, BlockVCycle, BSROp, greedy_colours, grid_colours,
                  grid_node_coordinates, rigid_body_modes, smoothed_aggregation)
from .krylov import Deflation, block_cg, coupled_block_cg
from .options import BLOCK_CG_MODES, MATFREE_COARSE_SOLVERS, AMGOptions, SolverOptions

__all__ = ["SolverOptions", "AMGOptions", "BLOCK_CG_MODES", "MATFREE_COARSE_SOLVERS",
           "smoothed_aggregation", "rigid_body_modes", "grid_node_coordinates", "SA_SMOOTH",
           "BSROp", "BlockVCycle", "grid_colours", "greedy_colours",
           "Deflation", "block_cg", "coupled_block_cg"]
