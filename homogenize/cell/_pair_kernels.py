"""Pair sums of the magnetic stiffness of point dipoles (:func:`homogenize.cell.relax.
magnetic_stiffness_analytic`): numba kernel and its plain-numpy twin (the reference of the
kernel's test).

For every particle i and every lattice image of every particle j at distance 0 < r < r_c, with
``d = x_i - x_j + n L``, ``e = d / r``: the dipole tensor ``T = (3 e e - I) / (4 pi r^3)``, the
gradient of the field of a dipole m at d ``A(m) = 3 / (4 pi r^4) (e m + m e + (m.e) I
- 5 (m.e) e e)`` and the Hessian ``Hs`` of ``mu0 m_i . T(d) m_j``; summed into (N, N, 3, 3)
blocks ``T[i, j] += T``, ``Hx[i, i] += A(m_j)``, ``Hx[i, j] -= A(m_j)``, ``Fx[i, i] += Hs``,
``Fx[i, j] -= Hs``, ``Fm[i, i] += mu0 A(m_j)``, ``Fm[i, j] += mu0 A(m_i)``.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["pair_sums", "pair_sums_reference"]


@numba.njit(cache=True, parallel=True)
def _pair_sums_kernel(x, m, imgs, rc, mu0, T, Hx, Fx, Fm):
    N = x.shape[0]
    rc2 = rc * rc
    for i in numba.prange(N):          # row i only: no two threads write the same block
        for j in range(N):
            for n in range(imgs.shape[0]):
                d0 = x[i, 0] - x[j, 0] + imgs[n, 0]
                d1 = x[i, 1] - x[j, 1] + imgs[n, 1]
                d2 = x[i, 2] - x[j, 2] + imgs[n, 2]
                r2 = d0 * d0 + d1 * d1 + d2 * d2
                if r2 <= 0.0 or r2 >= rc2:
                    continue
                r = math.sqrt(r2)
                e = (d0 / r, d1 / r, d2 / r)
                ae = m[i, 0] * e[0] + m[i, 1] * e[1] + m[i, 2] * e[2]
                be = m[j, 0] * e[0] + m[j, 1] * e[1] + m[j, 2] * e[2]
                ab = m[i, 0] * m[j, 0] + m[i, 1] * m[j, 1] + m[i, 2] * m[j, 2]
                c3 = 1.0 / (4.0 * math.pi * r2 * r)
                c4 = 3.0 / (4.0 * math.pi * r2 * r2)
                c5 = mu0 / (4.0 * math.pi * r2 * r2 * r)
                for a in range(3):
                    for b in range(3):
                        dab = 1.0 if a == b else 0.0
                        ee = e[a] * e[b]
                        Tp = (3.0 * ee - dab) * c3
                        Aj = c4 * (e[a] * m[j, b] + m[j, a] * e[b] + be * dab - 5.0 * be * ee)
                        Ai = c4 * (e[a] * m[i, b] + m[i, a] * e[b] + ae * dab - 5.0 * ae * ee)
                        Hs = (3.0 * (m[i, a] * m[j, b] + m[j, a] * m[i, b] + ab * dab)
                              - 15.0 * ab * ee
                              - 15.0 * (be * (m[i, a] * e[b] + e[a] * m[i, b])
                                        + ae * (m[j, a] * e[b] + e[a] * m[j, b]) + ae * be * dab)
                              + 105.0 * ae * be * ee) * c5
                        T[i, j, a, b] += Tp
                        Hx[i, i, a, b] += Aj
                        Hx[i, j, a, b] -= Aj
                        Fx[i, i, a, b] += Hs
                        Fx[i, j, a, b] -= Hs
                        Fm[i, i, a, b] += mu0 * Aj
                        Fm[i, j, a, b] += mu0 * Ai


def pair_sums(x, m, imgs, rc: float, mu0: float):
    """(T, Hx, Fx, Fm), each (N, N, 3, 3), for centres ``x`` [m] (N, 3), moments ``m`` [A m^2]
    (N, 3), lattice vectors ``imgs`` [m] (n, 3) and cutoff ``rc`` [m] (numba, parallel over i;
    every block summed in the same order on any thread count)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    m = np.ascontiguousarray(m, dtype=np.float64)
    imgs = np.ascontiguousarray(imgs, dtype=np.float64)
    N = x.shape[0]
    out = [np.zeros((N, N, 3, 3)) for _ in range(4)]
    _pair_sums_kernel(x, m, imgs, float(rc), float(mu0), *out)
    return tuple(out)


def pair_sums_reference(x, m, imgs, rc: float, mu0: float):
    """The same sums with numpy, one particle i at a time (vectorised over j and images)."""
    x = np.asarray(x, dtype=float)
    m = np.asarray(m, dtype=float)
    N = x.shape[0]
    I3 = np.eye(3)
    T, Hx, Fx, Fm = (np.zeros((N, N, 3, 3)) for _ in range(4))

    def o(u, v):
        return u[:, :, None] * v[:, None, :]

    for i in range(N):
        d = (x[i] - x)[:, None, :] + imgs[None, :, :]           # x_i - x_j + n L
        r2 = np.einsum("jnk,jnk->jn", d, d)
        jj, nn = np.nonzero((r2 > 0) & (r2 < rc * rc))
        dv = d[jj, nn]
        r = np.sqrt(r2[jj, nn])
        e = dv / r[:, None]
        ee = o(e, e)
        T_p = (3.0 * ee - I3) / (4.0 * math.pi * r[:, None, None] ** 3)

        def grad_field(mv):
            me = np.einsum("pk,pk->p", mv, e)[:, None, None]
            return 3.0 / (4.0 * math.pi * r[:, None, None] ** 4) * (
                o(e, mv) + o(mv, e) + me * I3 - 5.0 * me * ee)

        mj = m[jj]
        mi = np.broadcast_to(m[i], mj.shape)
        Aj, Ai = grad_field(mj), grad_field(mi)
        ae = np.einsum("pk,pk->p", mi, e)[:, None, None]
        be = np.einsum("pk,pk->p", mj, e)[:, None, None]
        ab = np.einsum("pk,pk->p", mi, mj)[:, None, None]
        Hs = (3.0 * (o(mi, mj) + o(mj, mi) + ab * I3) - 15.0 * ab * ee
              - 15.0 * (be * (o(mi, e) + o(e, mi)) + ae * (o(mj, e) + o(e, mj)) + ae * be * I3)
              + 105.0 * ae * be * ee) * (mu0 / (4.0 * math.pi * r[:, None, None] ** 5))
        np.add.at(T[i], jj, T_p)
        Hx[i, i] += Aj.sum(axis=0)
        np.add.at(Hx[i], jj, -Aj)
        Fx[i, i] += Hs.sum(axis=0)
        np.add.at(Fx[i], jj, -Hs)
        Fm[i, i] += mu0 * Aj.sum(axis=0)
        np.add.at(Fm[i], jj, mu0 * Ai)
    return T, Hx, Fx, Fm
