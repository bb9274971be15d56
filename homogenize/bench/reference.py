"""Plain-numpy (and generic scikit-fem) twins of the numba kernels: slow, obvious, independent.

Used by the kernel tests (each kernel against its twin on a small input) and by the benchmarks
(each kernel's speed as a ratio against its twin). Nothing in the library calls them.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementHex1, ElementVector, MeshHex
from skfem.helpers import ddot, sym_grad, trace

__all__ = ["relax_step_reference", "rsa_bodies_reference", "skfem_reference"]


def relax_step_reference(centers, radii, gap, push_scale, box):
    """All-pairs numpy twin of :func:`micro._kernels.placement_relax_step`: (disp, count)."""
    d = centers[:, None, :] - centers[None, :, :]
    d -= box * np.rint(d / box)
    dist = np.sqrt(np.sum(d * d, axis=2))
    lim = radii[:, None] + radii[None, :] + gap
    over = (dist < lim) & ~np.eye(len(radii), dtype=bool)
    f = np.where(over, 0.5 * (lim * push_scale - dist) / np.where(over, dist, 1.0), 0.0)
    return (f[:, :, None] * d).sum(axis=1), int(over.sum() // 2)


def rsa_bodies_reference(offsets, radii, body_start, candidates, gap, box, ncell, head, nxt,
                         centers, state, max_attempts):
    """Plain-numpy twin of :func:`micro._kernels.placement_rsa_bodies` (same signature and
    results; the cell list ``head``/``nxt``/``ncell`` is ignored: every placed particle is
    checked, which is what a cell list must reproduce)."""
    nbody = body_start.shape[0] - 1
    for m in range(candidates.shape[0]):
        b = state[0]
        if b >= nbody:
            return 0
        if state[1] >= max_attempts:
            return 2
        state[1] += 1
        state[2] += 1
        lo, hi = body_start[b], body_start[b + 1]
        placed = body_start[b]        # bodies are placed in order: members 0..placed-1 are in
        p = (candidates[m][None, :] + offsets[lo:hi]) % box
        if placed:
            d = centers[None, :placed, :] - p[:, None, :]
            d -= box * np.rint(d / box)
            s2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
            lim = radii[lo:hi, None] + radii[None, :placed] + gap
            if np.any(s2 < lim * lim):
                continue
        centers[lo:hi] = p
        state[0] = b + 1
        state[1] = 0
    if state[0] >= nbody:
        return 0
    return 2 if state[1] >= max_attempts else 1


def skfem_reference(lam, mu, h, sri):
    """Generic ``skfem.asm`` of the same operator: the independent reference for the voxel kernel.

    Returns ``(P, K, mesh)``: the stiffness ``K`` on the (n+1)^3 grid and the 0/1 matrix ``P``
    folding it onto the periodic nodes (``P.T @ K @ P`` is the periodic matrix). Slow on purpose:
    used only by tests and benchmarks.
    """
    n = lam.shape[0]
    x = np.linspace(0.0, n * h, n + 1)
    m = MeshHex.init_tensor(x, x, x)
    e = ElementVector(ElementHex1())
    b = Basis(m, e)
    bl = Basis(m, e, quadrature=(np.full((3, 1), 0.5), np.ones(1))) if sri else b
    idx = np.floor(m.p[:, m.t].mean(axis=1) / h).astype(int)
    le, me = lam[idx[2], idx[1], idx[0]], mu[idx[2], idx[1], idx[0]]

    @BilinearForm
    def fl(u, v, w):
        return w["c"] * trace(sym_grad(u)) * trace(sym_grad(v))

    @BilinearForm
    def fm(u, v, w):
        return 2.0 * w["c"] * ddot(sym_grad(u), sym_grad(v))

    K = fl.assemble(bl, c=np.repeat(le[:, None], bl.X.shape[-1], 1)) + \
        fm.assemble(b, c=np.repeat(me[:, None], b.X.shape[-1], 1))
    ijk = np.rint(m.p / h).astype(int) % n
    pn = ijk[0] + n * (ijk[1] + n * ijk[2])
    rows = b.nodal_dofs.T.ravel()
    P = sp.csr_matrix((np.ones(rows.size), (rows, (3 * pn[:, None] + np.arange(3)).ravel())),
                      shape=(b.N, 3 * n ** 3))
    return P, K, m
