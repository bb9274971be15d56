"""What this machine can hold: the one memory model of the project.

Refuse, before allocating, work whose memory estimate exceeds :data:`MEMORY_SHARE` of the
machine. Each caller estimates its peak memory from a measured cost per unit (particle, voxel,
degree of freedom, realization) and calls :func:`check_memory`, which raises
:class:`micro.InputError` naming the option, the estimate and the machine's memory. The cell
problems' estimates live here, one per solver (:func:`assembled_cell_bytes`,
:func:`matrix_free_cell_bytes`, :func:`cut_cell_bytes`), with the one threshold of
:func:`check_memory`; nothing else in the project reads the machine's memory.
"""
from __future__ import annotations

import os

from micro.common.validate import InputError

__all__ = ["machine_memory_bytes", "check_memory", "MEMORY_SHARE", "cell_memory_bytes",
           "check_cell_memory", "check_cheapest_cell_memory", "cheapest_cell_bytes", "assembled_cell_bytes",
           "matrix_free_cell_bytes", "cut_cell_bytes", "PATCH_BYTES_PER_NODE"]

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


#: memory of the particle patches' factors per grid node at their limit [bytes]
#: (:mod:`homogenize.solvers._patches`: dense Cholesky factors of the patches' nodes)
PATCH_BYTES_PER_NODE = 640


def assembled_cell_bytes(voxels: int, n_cases: int = 7) -> int:
    """Peak memory of one voxel cell solve with an assembled matrix and its AMG [bytes]: 27 3x3
    blocks of float64 per node for the matrix, x 3.2 for the AMG hierarchy and the Gauss-Seidel
    copies, ~12 work vectors per load case (measured within 30 % at 32^3-64^3,
    results/bench/cell.json)."""
    N = int(voxels) ** 3
    matrix = 27 * 9 * 8 * N
    vectors = 12 * int(n_cases) * 3 * 8 * N
    return int(3.2 * matrix + vectors + 200 * N)


def matrix_free_cell_bytes(voxels: int, n_cases: int = 7, cut_fraction: float = 0.1) -> int:
    """Peak memory of one matrix-free cell solve [bytes] (:mod:`homogenize.solvers._matfree`).

    Per fine node: 7 vectors of 3 n_cases float64 (the load block, whose pinned rows the solve
    zeroes in place; coupled block CG: X -- the active columns, the converged ones kept one by
    one beside them --, R, P, Q -- kept through the preconditioner --, and the V-cycle's result,
    the preconditioned residual; one spare for the copies made when columns leave the block;
    the V-cycle restricts its fine residual slab by slab, without a block of it; the energy
    products afterwards reuse that space), the diagonal blocks and their inverses (2 x 72 B;
    the blocks are freed once inverted), node and element types and indices (16 B); the cut
    voxels' own 24x24 matrices (4.6 kB each,
    ``cut_fraction`` of the voxels on the fine level and half as many on the coarse one; the
    operator's own stencil rows, ~2 nodes of 1.9 kB per cut voxel, replace them once the
    hierarchy is built); the assembled (n/2)^3 Galerkin matrix with its pyamg hierarchy
    (3 x 27 blocks of 72 B per coarse node; the restriction reads the prolongation's blocks
    transposed, no copy of them); the particle patches' factors at their limit
    (:data:`PATCH_BYTES_PER_NODE` per node); plus the Python/numba base (0.6 GB).
    Measured peak RSS (results/bench/threads.py's command, 7 load cases, 2 threads, cut voxels
    ~5 %): 0.85 GB at 64^3 (model 1.49), 5.19 GB at 128^3 (2.47 kB per voxel; model 7.72): the
    model is an upper bound, as the refusal before allocating needs. What is alive at the peak
    (the V-cycle inside the block CG; tracemalloc at 96^3, the same RVE density, bytes per
    voxel): the six load blocks F, X, R, P, A P and the V-cycle's result 1008, the pyamg
    hierarchy of the (n/2)^3 grid 274, the patches' factors 251, the fine stencil rows 212, the
    deflation space 112, the diagonal inverses 82, the coarse grid's stencil rows 59 and vectors
    44, mesh and phase fields 89, scratch, colours and node lists 43.
    """
    N = int(voxels) ** 3
    vec = 7 * 3 * int(n_cases) * 8 * N
    per_node = (2 * 72 + 16) * N
    cut = 1.5 * cut_fraction * N * 24 * 24 * 8
    coarse = 3 * 27 * 72 * (N // 8)
    patches = PATCH_BYTES_PER_NODE * N
    return int(vec + per_node + cut + coarse + patches + 0.6e9)


def cut_cell_bytes(voxels: int) -> int:
    """Peak memory of one Nitsche cut-voxel cell solve [bytes] (:mod:`homogenize.cell.cut`): the
    assembled two-field matrix, its smoothed-aggregation hierarchy (sparse LU at the bottom)
    and the work vectors, ~13.5 kB per grid node, plus the Python base. Measured peak RSS (one
    dilute sphere, one load case): 1.75 GB at 48^3 (model 1.79), 3.63 GB at 64^3 (model 3.84)."""
    return int(0.3e9 + 13.5e3 * int(voxels) ** 3)


def cell_memory_bytes(voxels: int, solver: str = "fast", n_cases: int = 7) -> int:
    """Peak memory estimate of one periodic voxel cell solve (``voxels`` per edge, ``n_cases``
    load cases) for ``solver`` in {"fast", "reference", "matrix-free"} [bytes]:
    :func:`assembled_cell_bytes` or :func:`matrix_free_cell_bytes`."""
    n = int(voxels)
    if solver == "matrix-free":
        return matrix_free_cell_bytes(n, n_cases)
    return assembled_cell_bytes(n, n_cases)


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


def cheapest_cell_bytes(voxels: int, n_cases: int = 7) -> int:
    """The estimate of the cheapest cell solver that can run ``voxels`` per edge [bytes]
    (matrix-free for even voxel counts >= 8, else assembled)."""
    n = int(voxels)
    need = assembled_cell_bytes(n, n_cases)
    if n % 2 == 0 and n >= 8:
        need = min(need, matrix_free_cell_bytes(n, n_cases))
    return need


def check_cheapest_cell_memory(voxels: int, n_cases: int = 7, what: str | None = None) -> int:
    """Refuse (InputError) a voxel grid that no cell solver can hold (:func:`cheapest_cell_bytes`);
    the solver actually chosen is checked again by the cell solve. Returns the estimate [bytes]."""
    n = int(voxels)
    need = cheapest_cell_bytes(n, n_cases)
    check_memory(what or f"voxels={n} ({3 * n ** 3:.3g} DOF, {n_cases} load cases)", need,
                 "use fewer voxels")
    return need
