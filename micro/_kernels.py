"""Every numba kernel of ``micro``, and nothing else.

Rules (STYLE.md): contiguous float64 arrays in, caller-allocated output, no defaults, short;
``cache=True``; no ``fastmath`` in physics kernels. Each kernel has a test against a plain-numpy
reference on a small input. Python wrappers (in particles.py, dipoles.py) check shapes and
units and allocate.
"""
from __future__ import annotations

import numba as nb
import numpy as np

# ---------------------------------------------------------------------------------------------
# Placement (cell lists, overlap tests) -- owned by particles.py
# ---------------------------------------------------------------------------------------------

# ---------------------------------------------------------------------------------------------
# Dipoles (direct sums, Ewald real space, forces) -- owned by dipoles.py
# ---------------------------------------------------------------------------------------------
