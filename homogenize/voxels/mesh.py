"""RVE -> finite-element mesh: a periodic voxel (hexahedral) grid with a phase per voxel.

A :class:`VoxelMesh` is an immutable description of the periodic cube ``[0, L)^3`` cut into
``n^3`` cubic voxels of edge ``h = L / n``. Each voxel carries the volume fraction of particle
material in it (``method="centre"``: 1 if the voxel centre lies in a particle, else 0;
``method="fraction"``: the fraction of ``s^3`` sub-sample points inside, which gives mixed voxels
at the interfaces; ``method="composite"``: the exact volume of the sphere inside the voxel, see
:func:`sphere_voxel_fractions`, plus the outward sphere normal at every interface voxel, from
which :mod:`homogenize.cell.problem` builds a laminate stiffness) and the index of the particle that
owns it (``-1`` for matrix).

Each particle also has a list of voxels with weights over which a force on it is spread. A
particle too small to contain a voxel centre (or sub-sample point) keeps the voxel that contains
its centre, so every particle force reaches the mesh and the mean force density is exact.

Arrays are indexed ``[k, j, i]`` (z, y, x), matching :mod:`homogenize.voxels._assembly`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from micro.box import PeriodicBox
from micro.common.validate import InputError, check_choice, check_positive

from homogenize.voxels._budget import check_cheapest_cell_memory

__all__ = ["VoxelMesh", "voxelize", "sphere_voxel_fractions", "METHODS"]

METHODS = ("centre", "fraction", "composite", "laminate")


@dataclass(frozen=True, eq=False)
class VoxelMesh:
    """Periodic voxel mesh of an RVE.

    Attributes
    ----------
    n : int -- voxels per edge
    box_m : float -- cube edge L [m]
    fraction : ndarray, shape (n, n, n) -- particle volume fraction per voxel [1]
    owner : ndarray of int64, shape (n, n, n) -- particle owning the voxel, -1 for matrix
    centers_m : ndarray, shape (N, 3) -- particle centres [m]
    radii_m : ndarray, shape (N,) -- particle radii [m]
    force_ptr, force_voxels, force_weights : CSR lists -- voxels (flat index) and weights [1]
        over which the force on particle ``i`` is spread (``force_ptr[i]:force_ptr[i+1]``)
    resolved : ndarray of bool, shape (N,) -- particle contains at least one voxel centre
    method : str -- ``"centre"``, ``"fraction"`` or ``"composite"``
    normal : ndarray, shape (n, n, n, 3), or None -- ``method="composite"``: unit outward normal
        of the owning sphere at each voxel (centre of the sphere to centre of the voxel) [1]
    """

    n: int
    box_m: float
    fraction: np.ndarray
    owner: np.ndarray
    centers_m: np.ndarray
    radii_m: np.ndarray
    force_ptr: np.ndarray
    force_voxels: np.ndarray
    force_weights: np.ndarray
    resolved: np.ndarray
    method: str
    normal: np.ndarray | None = None

    @property
    def h_m(self) -> float:
        """Voxel edge [m]."""
        return self.box_m / self.n

    @property
    def n_particles(self) -> int:
        return int(self.radii_m.shape[0])

    @property
    def n_nodes(self) -> int:
        return self.n ** 3

    @property
    def n_dof(self) -> int:
        return 3 * self.n ** 3

    @property
    def phi_voxel(self) -> float:
        """Particle volume fraction represented by the mesh [1]."""
        return float(self.fraction.mean())

    def voxel_centres_m(self) -> np.ndarray:
        """Voxel centres, shape (n, n, n, 3) [m] (component order x, y, z)."""
        c = (np.arange(self.n) + 0.5) * self.h_m
        k, j, i = np.meshgrid(c, c, c, indexing="ij")
        return np.stack([i, j, k], axis=-1)


def _as_geometry(rve):
    """(box, centres, radii) from an RVE or anything with the same attribute names."""
    try:
        box = float(rve.box_m)
        centres = np.asarray(rve.centers_m, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(rve.radii_m, dtype=np.float64).ravel()
    except AttributeError as exc:
        raise InputError(f"rve must provide box_m, centers_m and radii_m ({exc})") from None
    check_positive("rve.box_m", box, "m")
    if centres.shape[0] != radii.shape[0]:
        raise InputError(f"rve has {centres.shape[0]} centres but {radii.shape[0]} radii")
    if radii.size and (not np.all(np.isfinite(radii)) or np.any(radii <= 0)):
        raise InputError("rve.radii_m must be finite and > 0 m")
    if not np.all(np.isfinite(centres)):
        raise InputError("rve.centers_m must be finite")
    return box, PeriodicBox(box).wrap(centres), radii


# Gauss-Legendre rule on [0, 1] for the one numerical direction of the sphere-voxel volume, used
# on every piece between kinks after the smoothstep map x = 3u^2 - 2u^3 (which removes the
# square-root behaviour at the ends of a piece)
_GL_U, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_U, _GL_W = 0.5 * (_GL_U + 1.0), 0.5 * _GL_W
_SMOOTH_X = 3.0 * _GL_U ** 2 - 2.0 * _GL_U ** 3
_SMOOTH_W = _GL_W * 6.0 * _GL_U * (1.0 - _GL_U)


def _circle_min_integral(c, R, y0, y1):
    """``int_{y0}^{y1} min(c, s(y)) dy`` with ``s(y) = sqrt(R^2 - y^2)`` on ``|y| < R``, else 0.

    Closed form (arrays broadcast; ``c >= 0``, ``R >= 0``): the integrand is ``c`` where
    ``|y| <= w = sqrt(R^2 - c^2)`` and the circle ``s(y)`` elsewhere on ``|y| < R``.
    """
    def S(y):            # antiderivative of sqrt(R^2 - y^2), y clipped to [-R, R]
        y = np.clip(y, -R, R)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(R > 0, y / np.where(R > 0, R, 1.0), 0.0)
        return 0.5 * (y * np.sqrt(np.maximum(R * R - y * y, 0.0))
                      + R * R * np.arcsin(np.clip(t, -1.0, 1.0)))

    w = np.sqrt(np.maximum(R * R - c * c, 0.0))
    a, b = np.clip(y0, -w, w), np.clip(y1, -w, w)      # the flat part [y0, y1] n [-w, w]
    flat = c * (b - a)
    circ = (S(y1) - S(y0)) - (S(b) - S(a))             # the rest of [y0, y1] n [-R, R]
    return flat + circ


def sphere_voxel_fractions(lower, centre, radius):
    """Volume fraction of a sphere inside unit voxels, exact up to a 16-point rule in one axis.

    Parameters
    ----------
    lower : ndarray, shape (m, 3) -- lower corners of the voxels (x, y, z) in voxel units [1]
    centre : ndarray, shape (3,) -- sphere centre, voxel units [1]
    radius : float -- sphere radius, voxel units [1]

    Returns
    -------
    ndarray, shape (m,) -- fraction of each voxel inside the sphere [1]

    The chord of the sphere along z at (x, y) meets the voxel in ``clip(t1, -s, s) - clip(t0,
    -s, s)`` (``t = z - z_c`` at the voxel faces, ``s`` the half chord); its integral over y is
    closed-form (:func:`_circle_min_integral`); the remaining integral over x is split where the
    circle of the x-section passes a face or edge of the voxel, and each piece gets 8 Gauss points
    after a smoothstep map (error < 1e-6 of a voxel, tests/homogenize/test_cell_composite.py).
    """
    lower = np.asarray(lower, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64)
    r = float(radius)
    # voxels entirely inside or outside (centre distance vs half the diagonal) need no quadrature
    dist = np.sqrt(np.sum((lower + 0.5 - c) ** 2, axis=1))
    out = (dist + 0.5 * np.sqrt(3.0) <= r).astype(np.float64)
    cut = np.flatnonzero(np.abs(dist - r) < 0.5 * np.sqrt(3.0))
    if cut.size:
        out[cut] = _cut_fractions(lower[cut], c, r)
    return out


def _cut_fractions(lower, c, r):
    y0 = (lower[:, 1] - c[1])[:, None]
    t0 = (lower[:, 2] - c[2])[:, None]
    y1, t1 = y0 + 1.0, t0 + 1.0
    # the y-integral is smooth in x except where the circle of radius R(x) passes a face or an
    # edge of the voxel's (y, z) rectangle: R^2 = d^2 for these d^2; split x there
    d2 = np.concatenate([y0 ** 2, y1 ** 2, t0 ** 2, t1 ** 2, y0 ** 2 + t0 ** 2, y0 ** 2 + t1 ** 2,
                         y1 ** 2 + t0 ** 2, y1 ** 2 + t1 ** 2], axis=1)
    half = np.sqrt(np.maximum(r * r - d2, 0.0))
    xa = np.clip(lower[:, 0], c[0] - r, c[0] + r)[:, None]
    xb = np.clip(lower[:, 0] + 1.0, c[0] - r, c[0] + r)[:, None]
    brk = np.sort(np.clip(np.concatenate([xa, xb, c[0] - half, c[0] + half], axis=1), xa, xb),
                  axis=1)
    lo, width = brk[:, :-1], np.diff(brk, axis=1)                         # (m, pieces)
    x = lo[:, :, None] + width[:, :, None] * _SMOOTH_X[None, None, :]      # (m, pieces, q)
    wts = width[:, :, None] * _SMOOTH_W[None, None, :]
    R = np.sqrt(np.maximum(r * r - (x - c[0]) ** 2, 0.0))            # circle radius in (y, z)
    y0, y1 = y0[:, :, None], y1[:, :, None]
    t0, t1 = t0[:, :, None], t1[:, :, None]
    # clip(t, -s, s) = sign(t) min(|t|, s), integrated over y
    area = (np.sign(t1) * _circle_min_integral(np.abs(t1), R, y0, y1)
            - np.sign(t0) * _circle_min_integral(np.abs(t0), R, y0, y1))
    return np.clip((area * wts).sum(axis=(1, 2)), 0.0, 1.0)


def voxelize(rve, voxels: int, *, method: str = "composite", subsamples: int = 4) -> VoxelMesh:
    """Voxel mesh of an RVE.

    Parameters
    ----------
    rve : RVE -- or any object with ``box_m`` [m], ``centers_m`` (N, 3) [m], ``radii_m`` (N,) [m]
    voxels : int -- voxels per cube edge, >= 4
    method : {"centre", "fraction", "composite", "laminate"} -- phase by voxel-centre-in-sphere;
        or volume fraction per voxel from ``subsamples^3`` points (stiffness by majority phase,
        forces by fraction); or the exact volume fraction and the sphere normal per voxel
        (composite voxels, forces by fraction: Reuss stiffness for "composite", the Kabel
        laminate along the normal for "laminate"; see :class:`homogenize.cell.problem._Composite`)
    subsamples : int -- sub-sample points per voxel edge for ``method="fraction"``

    Raises
    ------
    InputError -- voxels < 4, or the voxels are so coarse that no particle contains a voxel centre.
    """
    check_choice("method", method, METHODS)
    if isinstance(voxels, bool) or int(voxels) != voxels or voxels < 4:
        raise InputError(f"voxels must be an integer >= 4 (voxels per cube edge), got {voxels!r}")
    n = int(voxels)
    check_cheapest_cell_memory(n)      # the one memory model (homogenize.voxels._budget)
    s = int(subsamples)
    if s < 1 or s != subsamples:
        raise InputError(f"subsamples must be an integer >= 1, got {subsamples!r}")
    box, centres, radii = _as_geometry(rve)
    h = box / n
    N = radii.shape[0]
    fraction = np.zeros((n, n, n))
    best = np.zeros((n, n, n))
    owner = -np.ones((n, n, n), dtype=np.int64)
    ptr = np.zeros(N + 1, dtype=np.int64)
    vox_lists, w_lists = [], []
    resolved = np.zeros(N, dtype=bool)
    composite = method in ("composite", "laminate")
    normal = np.zeros((n, n, n, 3)) if composite else None
    # sub-sample offsets inside a voxel, in units of h (centre method: the centre only)
    q = (np.arange(s) + 0.5) / s if method == "fraction" else np.array([0.5])
    sub = np.stack(np.meshgrid(q, q, q, indexing="ij"), axis=-1).reshape(-1, 3)[:, ::-1]
    for p in range(N):
        c, r = centres[p], radii[p]
        lo = np.floor((c - r) / h).astype(np.int64)
        hi = np.floor((c + r) / h).astype(np.int64)
        if np.any(hi - lo + 1 > n):   # particle larger than the box: clip to one period
            hi = np.minimum(hi, lo + n - 1)
        rng = [np.arange(lo[d], hi[d] + 1) for d in range(3)]
        I, J, K = np.meshgrid(rng[0], rng[1], rng[2], indexing="ij")
        base = np.stack([I.ravel(), J.ravel(), K.ravel()], axis=1).astype(np.float64)
        pts = (base[:, None, :] + sub[None, :, :]) * h          # unwrapped sample points
        inside = np.sum((pts - c) ** 2, axis=-1) <= r * r
        centre_in = np.sum(((base + 0.5) * h - c) ** 2, axis=-1) <= r * r
        resolved[p] = bool(np.any(centre_in))
        if composite:
            frac = sphere_voxel_fractions(base, c / h, r / h)
        else:
            frac = inside.mean(axis=1)
        keep = frac > 0
        idx = np.mod(base[keep].astype(np.int64), n)
        flat = idx[:, 0] + n * (idx[:, 1] + n * idx[:, 2])
        f = frac[keep]
        if flat.size == 0:   # unresolved: the voxel containing the centre carries its force
            ic = np.mod(np.floor(c / h).astype(np.int64), n)
            flat = np.array([ic[0] + n * (ic[1] + n * ic[2])])
            w = np.ones(1)
        else:
            w = f
            fv = fraction.reshape(-1)
            np.add.at(fv, flat, f)
            bv, ov = best.reshape(-1), owner.reshape(-1)
            better = f > bv[flat]
            bv[flat[better]] = f[better]
            ov[flat[better]] = p
            if composite:
                d = (base[keep][better] + 0.5) * h - c
                nrm = np.linalg.norm(d, axis=1)
                d[nrm == 0.0] = (0.0, 0.0, 1.0)    # voxel centre at the sphere centre: any normal
                nrm[nrm == 0.0] = 1.0
                normal.reshape(-1, 3)[flat[better]] = d / nrm[:, None]
        vox_lists.append(flat)
        w_lists.append(w)
        ptr[p + 1] = ptr[p] + flat.size
    if N and not resolved.any():
        need = math.ceil(math.sqrt(3.0) / 2.0 * box / radii.max())
        raise InputError(
            f"voxels={n} (voxel edge {h:.3g} m) resolves none of the {N} particles (largest radius "
            f"{radii.max():.3g} m): no voxel centre lies inside any particle; use voxels >= {need}")
    np.minimum(fraction, 1.0, out=fraction)   # overlapping shells must not exceed full voxels
    for arr in (fraction, owner, centres, radii, ptr, resolved) + ((normal,) if composite else ()):
        arr.setflags(write=False)
    fvox = np.concatenate(vox_lists) if vox_lists else np.zeros(0, np.int64)
    fw = np.concatenate(w_lists) if w_lists else np.zeros(0)
    fvox.setflags(write=False)
    fw.setflags(write=False)
    return VoxelMesh(n=n, box_m=box, fraction=fraction, owner=owner, centers_m=centres,
                     radii_m=radii, force_ptr=ptr, force_voxels=fvox, force_weights=fw,
                     resolved=resolved, method=method, normal=normal)
