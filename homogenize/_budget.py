"""What this machine can hold: refuse, before allocating, work whose memory estimate exceeds it.

Each caller estimates its own peak memory from a measured cost per unit (particle, voxel,
degree of freedom, realization) and calls :func:`check_memory`, which raises
:class:`micro.InputError` naming the option, the estimate and the machine's memory.
"""
from __future__ import annotations

import os

from micro._validate import InputError

__all__ = ["machine_memory_bytes", "check_memory", "MEMORY_SHARE", "cell_memory_bytes",
           "check_cell_memory"]

#: Assumed when the operating system does not tell the physical memory [bytes].
_DEFAULT_MEMORY_BYTES = 24 * 2 ** 30
#: Share of the physical memory one run may plan to use (the rest: OS, other processes).
MEMORY_SHARE = 0.8


def machine_memory_bytes() -> int:
    """Physical memory of this machine [bytes] (24 GiB if the OS does not tell)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return _DEFAULT_MEMORY_BYTES


def check_memory(what: str, estimate_bytes: float, hint: str = "") -> None:
    """Raise :class:`InputError` if ``estimate_bytes`` exceeds :data:`MEMORY_SHARE` of memory.

    ``what`` names the option and value (``"--voxels 200"``); the message gives the estimate,
    the machine's memory and ``hint`` (what to do instead).
    """
    have = machine_memory_bytes()
    if estimate_bytes > MEMORY_SHARE * have:
        raise InputError(f"{what} needs about {_size(estimate_bytes)} of memory (estimate), more "
                         f"than {MEMORY_SHARE:.0%} of this machine's {_size(have)}"
                         + (f"; {hint}" if hint else ""))


def _size(nbytes: float) -> str:
    gib = nbytes / 2 ** 30
    return f"{gib:.3g} GiB" if gib < 1e4 else f"{gib / 2 ** 10:.3g} TiB"


def cell_memory_bytes(voxels: int, solver: str = "fast", n_cases: int = 7) -> int:
    """Peak memory estimate of one periodic voxel cell solve (``voxels`` per edge, ``n_cases``
    load cases) for ``solver`` in {"fast", "reference", "matrix-free"} [bytes].

    Assembled solvers: 27 3x3 float64 blocks per node for the matrix, x 3.2 for the AMG
    hierarchy and the Gauss-Seidel copies, ~12 work vectors per load case
    (:func:`homogenize.mesh.estimate_memory_bytes`, measured within 30 % at 32^3-64^3).
    "matrix-free": no fine matrix; work vectors, diagonal blocks, element types and cut-voxel
    matrices, the assembled (n/2)^3 Galerkin matrix with its AMG hierarchy
    (:func:`homogenize.solvers._matfree.memory_estimate_bytes`).
    """
    n = int(voxels)
    if solver == "matrix-free":
        from homogenize.solvers._matfree import memory_estimate_bytes
        return memory_estimate_bytes(n, n_cases)
    from homogenize.mesh import estimate_memory_bytes
    return estimate_memory_bytes(n, "composite", n_cases)


def check_cell_memory(voxels: int, solver: str = "fast", n_cases: int = 7,
                      what: str | None = None) -> int:
    """Refuse (InputError) a cell solve whose estimate exceeds :data:`MEMORY_SHARE` of the
    machine, before allocating; returns the estimate [bytes]."""
    need = cell_memory_bytes(voxels, solver, n_cases)
    n = int(voxels)
    hint = ("use fewer voxels" if solver == "matrix-free"
            else "use fewer voxels or solver='matrix-free'")
    check_memory(what or f"voxels={n} ({3 * n ** 3:.3g} DOF, {n_cases} load cases, "
                 f"solver={solver!r})", need, hint)
    return need
