"""Moved: the AMG, V-cycles and block CG live in :mod:`homogenize.solvers` (amg, krylov). This
name stays only so that code written against it still imports; use
:func:`homogenize.solvers.smoothed_aggregation` to set up a hierarchy."""
from .solvers.amg import SA_SMOOTH, BlockVCycle, BSROp, greedy_colours, grid_colours  # noqa: F401
from .solvers.krylov import Deflation, block_cg, coupled_block_cg  # noqa: F401
