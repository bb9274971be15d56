"""Periodic dipolar sums: plain Ewald (reference) and smooth particle-mesh Ewald (fast).

Everything here works in *box units* (cube of edge 1, centres in [0, 1)); :mod:`micro.dipoles`
converts to SI: fields scale as m / L^3, forces as mu0 m^2 / L^4, stresses as mu0 m^2 / L^6.

Ewald splitting with parameter ``alpha`` (inverse length, box units): the field of dipole j at
x_i is the screened real-space sum ``(1/4pi) sum_n [B2 (m_j.r) r - B1 m_j]`` over images within
``rc`` plus the reciprocal sum ``-sum_{k != 0} f(k) k (k.t(k)) e^{ik.x_i}`` with
``f = exp(-k^2/4 alpha^2) / k^2`` and ``t(k) = sum_j m_j exp(-ik.x_j)``, minus the self-field
of particle i's own Gaussian, ``-(alpha^3 / (3 pi^{3/2})) m_i``. The k = 0 term is omitted:
metallic ("tin-foil") boundary, the mean field in the sample equals the applied field. A
specimen with demagnetizing factor N adds ``-N M`` (``M = sum m / V``); a sphere (N = 1/3)
reproduces the sum over growing spherical shells of images in vacuum.

Accuracy: with ``s = sqrt(-ln(accuracy)) + 0.25`` the real-space cutoff is ``rc = s / alpha``
and the Ewald k cutoff ``|k| <= 2 alpha s``; both neglected tails are ~ exp(-s^2) relative to
the typical field, which the tests check against converged references.
"""
from __future__ import annotations

import math

import numba
import numpy as np
import scipy.fft

from micro import _kernels as K

_INV4PI = 1.0 / (4.0 * math.pi)


def split_s(accuracy: float) -> float:
    """Dimensionless cutoff product ``s = alpha rc = |k_max| / (2 alpha)`` for an accuracy."""
    return math.sqrt(-math.log(accuracy)) + 0.25


class _CellList:
    """Particles sorted into ``ncell^3`` cells for a real-space cutoff ``rc`` (box units)."""

    def __init__(self, pos: np.ndarray, rc: float):
        n = pos.shape[0]
        # about 2 cells per cutoff (fewer wasted pair checks than 1), at most ~n cells
        ncell = max(1, min(int(2.0 / rc), int(round(max(n, 1) ** (1 / 3))) + 1, 256))
        idx = np.minimum((pos * ncell).astype(np.int64), ncell - 1)
        cell = (idx[:, 0] * ncell + idx[:, 1]) * ncell + idx[:, 2]
        self.order = np.argsort(cell, kind="stable").astype(np.int64)
        counts = np.bincount(cell, minlength=ncell ** 3)
        self.cell_start = np.zeros(ncell ** 3 + 1, dtype=np.int64)
        np.cumsum(counts, out=self.cell_start[1:])
        self.ncell = ncell
        self.noff = int(math.ceil(rc * ncell - 1e-12))


class PeriodicSum:
    """Plan for the periodic dipolar field of N point dipoles at fixed positions (box units).

    Parameters
    ----------
    pos : ndarray, shape (N, 3) -- centres in box units, in [0, 1)
    accuracy : float -- requested relative accuracy of the field
    method : {"ewald", "pme"}
    alpha : float, optional -- splitting parameter [1/box]; automatic if None
    pme_order : int -- B-spline order of PME (even); automatic if None
    neighbours : float -- PME: mean number of real-space neighbours setting alpha (default 80)
    grid : int -- PME grid points per edge; automatic if None
    """

    def __init__(self, pos, accuracy=1e-6, method="pme", alpha=None, pme_order=None,
                 neighbours=None, grid=None):
        pos = np.ascontiguousarray(pos, dtype=np.float64)
        n = pos.shape[0]
        self.n = n
        self.method = method
        self.accuracy = float(accuracy)
        s = split_s(accuracy)
        self.s = s
        if alpha is None:
            if method == "ewald":
                # balance real-space pairs (4pi/3 rc^3 N per particle) against k-vectors
                # (2pi/3 (alpha s / pi)^3 per particle): alpha ~ (N)^(1/6), O(N^1.5) total.
                alpha = math.sqrt(math.pi) * (2.0 * max(n, 1)) ** (1.0 / 6.0)
            else:
                nb_target = 80.0 if neighbours is None else float(neighbours)
                rc = (nb_target / (4.0 / 3.0 * math.pi * max(n, 1))) ** (1.0 / 3.0)
                alpha = s / min(rc, 0.5)
        self.alpha = float(alpha)
        self.rc = s / self.alpha
        # work on particles sorted by cell: neighbours are then close in memory
        self.perm = _CellList(pos, self.rc).order
        self.inv = np.empty_like(self.perm)
        self.inv[self.perm] = np.arange(n)
        self.pos = np.ascontiguousarray(pos[self.perm])
        self.cells = _CellList(self.pos, self.rc)
        self.targets = np.arange(n, dtype=np.int64)
        if method == "ewald":
            self._setup_ewald()
        elif method == "pme":
            self.order = pme_order_for(accuracy) if pme_order is None else int(pme_order)
            self._setup_pme(grid)
        else:
            raise ValueError(method)
        self.evaluations = 0

    # ------------------------------------------------------------------ plain Ewald
    def _setup_ewald(self):
        kmax = 2.0 * self.alpha * self.s
        nmax = int(math.ceil(kmax / (2 * math.pi)))
        r = np.arange(-nmax, nmax + 1)
        nx, ny, nz = np.meshgrid(r, r, r, indexing="ij")
        nvec = np.stack([nx.ravel(), ny.ravel(), nz.ravel()], axis=1)
        half = (nvec[:, 2] > 0) | ((nvec[:, 2] == 0) & (nvec[:, 1] > 0)) | \
               ((nvec[:, 2] == 0) & (nvec[:, 1] == 0) & (nvec[:, 0] > 0))
        kv = 2 * math.pi * nvec[half].astype(np.float64)
        k2 = np.einsum("ij,ij->i", kv, kv)
        keep = k2 <= kmax ** 2
        self.kvec = np.ascontiguousarray(kv[keep])
        self.k2 = k2[keep]
        self.fk = np.exp(-self.k2 / (4 * self.alpha ** 2)) / self.k2

    def _ewald_recip(self, mom, want_force):
        t = np.empty((self.kvec.shape[0], 6))
        K.ewald_structure_factor(self.pos, mom, self.kvec, t)
        tc = t[:, :3] + 1j * t[:, 3:]
        s = np.einsum("kd,kd->k", self.kvec, tc)
        coef = -2.0 * self.fk * s           # factor 2: the k and -k halves
        c2 = np.ascontiguousarray(np.stack([coef.real, coef.imag], axis=1))
        h = np.empty_like(mom)
        f = np.empty_like(mom)
        K.ewald_recip_gather(self.pos, mom, self.kvec, c2, h, f)
        if not want_force:
            return h, None, None, None
        # energy and the strain derivative (P = dU/d eps / V) over the full k-space (x2)
        ss = np.abs(s) ** 2
        u = float(np.sum(self.fk * ss))              # = 2 * (1/2) sum_half f|s|^2 / mu0
        w = 2.0 * self.fk * (1.0 / self.k2 + 1.0 / (4 * self.alpha ** 2)) * ss
        p = np.einsum("k,ka,kb->ab", w, self.kvec, self.kvec)
        p -= 2.0 * np.real(np.einsum("k,k,ka,kb->ab", self.fk, np.conj(s), self.kvec, tc))
        p = -np.eye(3) * u + p
        return h, -f, u, p

    # ------------------------------------------------------------------ smooth PME
    def _setup_pme(self, grid):
        p = self.order
        if grid is None:
            kk = int(math.ceil(self.alpha * pme_grid_ratio(self.accuracy, p)))
            kk = max(kk, 2 * p)
            grid = scipy.fft.next_fast_len(kk + (kk % 2), real=True)
            while grid % 2:
                grid = scipy.fft.next_fast_len(grid + 1, real=True)
        self.grid = int(grid)
        kk = self.grid
        n1 = np.fft.fftfreq(kk, 1.0 / kk)
        n3 = np.fft.rfftfreq(kk, 1.0 / kk)
        # |b(m)|^2 of the Euler exponential spline, per axis
        w = np.empty(p)
        K.pme_bspline(0.0, p, w)                      # w[q] = M_p(q), q = 0..p-1
        q = np.arange(p)

        def bmod(nn):
            den = np.abs(np.exp(2j * np.pi * np.outer(nn, q) / kk) @ w) ** 2
            return np.where(den > 1e-30, 1.0 / np.maximum(den, 1e-300), 0.0)

        b1 = bmod(n1)
        b3 = bmod(n3)
        kx = 2 * np.pi * n1[:, None, None]
        ky = 2 * np.pi * n1[None, :, None]
        kz = 2 * np.pi * n3[None, None, :]
        k2 = kx ** 2 + ky ** 2 + kz ** 2
        k2[0, 0, 0] = 1.0
        g = np.exp(-k2 / (4 * self.alpha ** 2)) / k2 * b1[:, None, None] * b1[None, :, None] \
            * b3[None, None, :]
        g[0, 0, 0] = 0.0
        # Nyquist planes: no unique sign of k there, drop them (their weight is ~exp(-s^2)).
        if kk % 2 == 0:
            g[kk // 2, :, :] = 0.0
            g[:, kk // 2, :] = 0.0
            g[:, :, -1] = 0.0
        self.g = g
        self.kv1 = np.ascontiguousarray(2 * np.pi * n1)
        self.kv3 = np.ascontiguousarray(2 * np.pi * n3)
        # weights of the half-space (rfft) sum over full k-space
        wz = np.full(n3.shape, 2.0)
        wz[0] = 1.0
        if kk % 2 == 0:
            wz[-1] = 1.0
        self.wz = wz
        self.gpos = np.ascontiguousarray(self.pos * kk)
        # x-slabs of >= p grid planes for the race-free parallel spread (1 or an even number)
        nslab = kk // p
        nslab = 1 if nslab < 2 else nslab - nslab % 2
        bounds = np.arange(nslab + 1) * kk // nslab
        slab = np.searchsorted(bounds, np.floor(self.gpos[:, 0]), side="right") - 1
        self.slab_order = np.argsort(slab, kind="stable").astype(np.int64)
        self.slab_start = np.searchsorted(slab[self.slab_order], np.arange(nslab + 1)) \
            .astype(np.int64)
        nscr = max((nslab + 1) // 2, 64)       # spread: slab pairs; gather: 64 fixed chunks
        self._work = np.empty((nscr, 3, p))
        self._iwork = np.empty((nscr, 3, p), dtype=np.int64)
        self._row = np.empty((nscr, 9))
        self._qgrid = None          # the spread grid, kept between evaluations (see below)

    def _pme_spread_fft(self, mom):
        kk = self.grid
        # One real grid kept and zeroed in place on all threads: a new grid each evaluation
        # would be fresh memory, which the kernel maps and zeroes at first touch (slow on this
        # project's VMs; see _pme_back_gather). The transform's output is scipy's (no `out`).
        if self._qgrid is None:
            self._qgrid = np.empty((kk, kk, kk, 3))
        q = self._qgrid
        K.zero_planes(q)
        K.pme_spread(self.gpos, mom, self.order, self.slab_order, self.slab_start, self._work,
                     self._iwork, self._row, q)
        # the FFT's threads follow numba's (NUMBA_NUM_THREADS / numba.set_num_threads), so that a
        # one-thread run is one thread throughout; pocketfft splits the transform by lines, so
        # the result is bitwise the same on any count (tested)
        return scipy.fft.rfftn(q, axes=(0, 1, 2), workers=numba.get_num_threads())

    def _pme_back_gather(self, hg):
        kk = self.grid
        nt = numba.get_num_threads()
        # irfftn in its two stages, so that no full-size scratch grid is made: scipy's irfftn
        # copies its input to a new complex grid (it ignores overwrite_x), allocated outside
        # numpy and so faulted in 4 KiB at a time on every call: 82k faults at K = 240, which
        # made an inverse transform 1.4-1.9 s instead of 0.9 s on one thread. Here the x-y
        # transforms run in place in hg, then the last axis goes complex-to-real into numpy's
        # output (large numpy arrays get transparent huge pages). At N = 1e5 the dipole solve's
        # page faults fell from 1.19 M to 0.14 M and its peak RSS from 3.36 to 2.70 GB.
        hg = scipy.fft.ifftn(hg, axes=(0, 1), workers=nt, overwrite_x=True)
        grid = scipy.fft.irfft(hg, n=kk, axis=2, workers=nt)
        out = np.empty((self.n, grid.shape[3]))
        K.pme_gather(self.gpos, np.ascontiguousarray(grid), self.order, self._work[:64],
                     self._iwork[:64], out)
        return out

    def _pme_recip(self, mom, want_force):
        """Reciprocal part by smooth PME: one forward transform of the gridded moments (3
        real grids, component last), one k-space pass, one inverse transform of 3 field grids
        (or, with forces, 3 field + 6 gradient grids: grad H is symmetric) and one gather."""
        kk = self.grid
        qh = self._pme_spread_fft(mom)
        if not want_force:
            # in place: a new grid would be page-faulted in at first touch (see above)
            K.pme_influence(qh, self.kv1, self.kv3, self.g, float(kk) ** 3, qh)
            return self._pme_back_gather(qh), None, None, None
        hg = np.empty(qh.shape[:3] + (9,), dtype=np.complex128)
        acc = np.empty((kk, 10))
        K.pme_influence_grad(qh, self.kv1, self.kv3, self.g, self.wz, float(kk) ** 3,
                             1.0 / (4 * self.alpha ** 2), hg, acc)
        del qh
        out = self._pme_back_gather(hg)
        h = np.ascontiguousarray(out[:, :3])
        gr = out[:, 3:]                                  # xx, yy, zz, xy, xz, yz
        grad = gr[:, [0, 3, 4, 3, 1, 5, 4, 5, 2]].reshape(self.n, 3, 3)
        f = np.einsum("ia,iab->ib", mom, grad)          # F_b = m_a dH_a/dx_b (curl-free H)
        tot = acc.sum(axis=0)
        u = float(tot[0])
        p = tot[1:].reshape(3, 3) - np.eye(3) * u
        return h, f, u, p

    # ------------------------------------------------------------------ public (box units)
    def field(self, mom):
        """Periodic dipolar field at every particle from all others and all images (box units,
        tin-foil boundary): shape (N, 3)."""
        mom = np.ascontiguousarray(np.asarray(mom, dtype=np.float64)[self.perm])
        self.evaluations += 1
        h, _f, _v = self._real(mom, False)
        hr = self._ewald_recip(mom, False)[0] if self.method == "ewald" else \
            self._pme_recip(mom, False)[0]
        return (h * _INV4PI + hr + self._self_coef() * mom)[self.inv]

    def _self_coef(self):
        # minus the field of the particle's own Gaussian at its centre: + alpha^3/(3 pi^1.5) m
        return self.alpha ** 3 / (3.0 * math.pi ** 1.5)

    def _real(self, mom, want_force):
        n = self.n
        h = np.empty((n, 3))
        f = np.empty((n, 3)) if want_force else np.empty((1, 3))
        v = np.empty((n, 9)) if want_force else np.empty((1, 9))
        c = self.cells
        K.ewald_real(self.pos, mom, self.targets, c.order, c.cell_start, c.ncell, c.noff,
                     self.alpha, self.rc, want_force, h, f, v)
        return h, f, v

    def interactions(self, mom):
        """Field, force (without mu0), energy / mu0 and strain derivative P = dU/deps / (V mu0).

        Returns ``h (N,3), f (N,3), u, P (3,3)`` in box units; the force on i is
        ``mu0 (m_i . grad) H`` from all other dipoles, ``u = -(1/2) sum m_i . h_i``.
        """
        mom = np.ascontiguousarray(np.asarray(mom, dtype=np.float64)[self.perm])
        self.evaluations += 1
        h, f, v = self._real(mom, True)
        if self.method == "ewald":
            hr, fr, ur, pr = self._ewald_recip(mom, True)
        else:
            hr, fr, ur, pr = self._pme_recip(mom, True)
        h = h * _INV4PI + hr + self._self_coef() * mom
        f = f * _INV4PI + fr
        p_real = -(v.sum(axis=0).reshape(3, 3).T) * _INV4PI   # dU/deps_ab = -sum F_a r_b
        u = -0.5 * float(np.einsum("ij,ij->", mom, h))
        return h[self.inv], f[self.inv], u, p_real + pr


def pme_order_for(accuracy: float) -> int:
    """B-spline order used by PME for a requested accuracy (6, or 8 below 1e-5)."""
    return 6 if accuracy >= 1e-5 else 8


def pme_grid_ratio(accuracy: float, order: int) -> float:
    """Grid points per unit alpha (K / alpha, box units) that keep the PME aliasing error of
    the field under ``accuracy``.

    Fit to measured PME-vs-plain-Ewald relative field errors on random dipoles (N = 1000,
    alpha = 15 and 25, K = 24..96): the error falls like (alpha / K)^(p + 1.5) from 6.5e-6
    (p = 6) and 8.9e-7 (p = 8) at K / alpha = 2.56. Clustered RVEs with randomly oriented
    moments at small K showed 5x larger errors, so the constants below keep a margin of 20.
    tests/micro/test_pme.py checks the resulting accuracy on clustered RVEs.
    """
    e = min(max(accuracy, 1e-13), 1e-2)
    if order >= 8:
        return 2.56 * (1.8e-5 / e) ** (1.0 / 9.5)
    return 2.56 * (1.3e-4 / e) ** (1.0 / 7.4) if order >= 6 else 2.56 * (5e-4 / e) ** (1.0 / 4.5)
