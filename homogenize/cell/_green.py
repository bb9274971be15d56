"""Periodic displaceability matrix of rigid spheres in an elastic matrix (Ewald-summed).

A force ``F`` on a rigid sphere of radius ``a`` bonded to an infinite isotropic matrix (shear
modulus ``G``, Poisson's ratio ``nu``) displaces it by ``U0 F``,

    U0 = (5 - 6 nu) / (24 pi G a (1 - nu)),

and the matrix around it by ``(1 + a^2/6 lap) K(r) F`` with the Kelvin tensor

    K(r) = [(3 - 4 nu) I + r^ r^] / (16 pi G (1 - nu) r).

(The ``a^2/6`` term is the harmonic ``grad grad 1/r`` that makes the displacement uniform on the
sphere; with it ``u(a) = U0 F`` exactly.) A force-free rigid sphere j in that field moves with its
Faxen average ``(1 + a_j^2/6 lap) u`` -- reciprocity (M_ij = M_ji^T) fixes the coefficient, and
``lap^2 K = 0`` ends the series. The pair displaceability to leading orders, the elastic
analogue of the Rotne-Prager tensor, is therefore

    M_ij = (1 + (a_i^2 + a_j^2)/6 lap) K(r_ij),     M_ii = U0 I,

exact to O(r^-3); the reflections that it leaves out start at O((a/r)^4) in the self terms
(Puljiz, Menzel et al., arXiv:1901.06303, give them to higher order; not included here).

Periodic cell: every force is balanced by a uniform counter-load (the k = 0 term is left out,
the convention of the cell FEM, :func:`homogenize.cell.problem.homogenize_mesh`). The lattice sum is
split Ewald-style in Fourier space, ``K^(k) = [I/k^2 - kappa k k / k^4] / G`` with
``kappa = 1 / (2 (1 - nu))``: the ``1/k^2`` part with ``exp(-x)``, the ``k k / k^4`` part with
``(1 + x) exp(-x)`` (Hasimoto's splitting), ``x = k^2 / (4 xi^2)``. Both real-space remainders
then decay like ``exp(-xi^2 r^2)`` (no conditionally convergent dipolar tail is left):

    I/k^2 (1 - e^-x)            <->  I erfc(xi r) / (4 pi r)
    k k/k^4 (1 - (1 + x) e^-x)  <->  -grad grad f,  f = [exp(-xi^2 r^2)/(xi sqrt(pi)) - r erfc(xi r)] / (8 pi)

and ``lap`` acts on them in closed form. The result does not depend on ``xi`` (tested).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import erfc

from micro.box import PeriodicBox

__all__ = ["rigid_sphere_displaceability", "periodic_displaceability", "free_displaceability"]

_SQRT_PI = math.sqrt(math.pi)


def rigid_sphere_displaceability(radius_m, shear_modulus_Pa, nu):
    """Displacement per force of one rigid sphere in an infinite matrix [m/N]:
    ``(5 - 6 nu) / (24 pi G a (1 - nu))``."""
    return (5.0 - 6.0 * nu) / (24.0 * math.pi * shear_modulus_Pa * np.asarray(radius_m) * (1.0 - nu))


def _radial_hessian(d1, d2, rhat, r):
    """grad grad q for a radial q(r) with q' = d1, q'' = d2: (..., 3, 3)."""
    rr = rhat[..., :, None] * rhat[..., None, :]
    eye = np.eye(3)
    return d2[..., None, None] * rr + (d1 / r)[..., None, None] * (eye - rr)


def free_displaceability(d_m, s_m2, shear_modulus_Pa, nu):
    """``(1 + s lap) K(d)`` for separations d (..., 3) [m] and s = (a_i^2 + a_j^2)/6 (...,) [m^2];
    returns (..., 3, 3) [m/N]. Infinite matrix, r > 0."""
    d = np.asarray(d_m, dtype=float)
    r = np.linalg.norm(d, axis=-1)
    rh = d / r[..., None]
    rr = rh[..., :, None] * rh[..., None, :]
    A = 1.0 / (16.0 * math.pi * shear_modulus_Pa * (1.0 - nu))
    eye = np.eye(3)
    out = A * ((3.0 - 4.0 * nu) * eye + rr) / r[..., None, None]
    out += (np.asarray(s_m2) * 2.0 * A / r ** 3)[..., None, None] * (eye - 3.0 * rr)
    return out


def _short(d, s, G, kappa, xi):
    """Real-space (short-range) part of (1 + s lap) K for separations d (..., 3), r > 0."""
    r = np.linalg.norm(d, axis=-1)
    rh = d / r[..., None]
    E = np.exp(-(xi * r) ** 2)
    ec = erfc(xi * r)
    eye = np.eye(3)
    # I erfc(xi r)/(4 pi r) and its Laplacian (r > 0): xi^3 exp(-xi^2 r^2) / pi^1.5
    a_part = (ec / (4.0 * math.pi * r))[..., None, None] * eye
    a_lap = (xi ** 3 * E / math.pi ** 1.5)[..., None, None] * eye
    # + kappa grad grad f, f' = -erfc/(8 pi), f'' = (2 xi/sqrt(pi)) E / (8 pi)
    f1 = -ec / (8.0 * math.pi)
    f2 = (2.0 * xi / _SQRT_PI) * E / (8.0 * math.pi)
    b_part = kappa * _radial_hessian(f1, f2, rh, r)
    # lap f = -[erfc/(4 pi r) - exp(-xi^2 r^2) xi / (4 pi^1.5)] =: q
    e1p = -ec / r ** 2 - (2.0 * xi / _SQRT_PI) * E / r
    e1pp = 2.0 * ec / r ** 3 + (2.0 * xi / _SQRT_PI) * E * (2.0 / r ** 2 + 2.0 * xi ** 2)
    c = xi / (4.0 * math.pi ** 1.5)
    q1 = -e1p / (4.0 * math.pi) + c * (-2.0 * xi ** 2 * r) * E
    q2 = -e1pp / (4.0 * math.pi) + c * (-2.0 * xi ** 2 + 4.0 * xi ** 4 * r ** 2) * E
    b_lap = kappa * _radial_hessian(q1, q2, rh, r)
    s = np.asarray(s)[..., None, None]
    return (a_part + b_part + s * (a_lap + b_lap)) / G


def periodic_displaceability(centers_m, radii_m, box_m, shear_modulus_Pa, nu, *,
                             accuracy=1e-8, xi_box=None):
    """Displaceability matrix of rigid spheres in a periodic elastic cell.

    Parameters
    ----------
    centers_m : ndarray, shape (N, 3) -- sphere centres [m]
    radii_m : ndarray, shape (N,) -- sphere radii [m]
    box_m : float -- periodic cube edge L [m]
    shear_modulus_Pa : float -- matrix shear modulus G [Pa] (> 0)
    nu : float -- matrix Poisson's ratio, (-1, 0.5]
    accuracy : float -- relative truncation of the real and reciprocal Ewald sums
    xi_box : float, optional -- Ewald splitting xi L (default: chosen from ``accuracy``)

    Returns
    -------
    ndarray, shape (3N, 3N) -- ``u = M F`` [m/N]: displacement of sphere i (rows 3i..3i+2) per
    force on sphere j, each force balanced by a uniform counter-load over the cell; symmetric.
    """
    c = np.asarray(centers_m, dtype=float)
    a = np.asarray(radii_m, dtype=float)
    N = a.size
    L = float(box_m)
    G = float(shear_modulus_Pa)
    kappa = 1.0 / (2.0 * (1.0 - nu))
    p = math.sqrt(-math.log(accuracy))          # exp(-p^2) = accuracy
    xi = (xi_box if xi_box is not None else p * 1.05) / L   # real space: one shell of images
    V = L ** 3
    # reciprocal lattice: exp(-k^2/(4 xi^2)) (1 + x) < accuracy for k > kmax
    kmax = 2.0 * xi * (p + 1.0)
    nmax = int(math.ceil(kmax * L / (2.0 * math.pi)))
    rng = np.arange(-nmax, nmax + 1)
    n = np.stack(np.meshgrid(rng, rng, rng, indexing="ij"), axis=-1).reshape(-1, 3)
    n = n[np.any(n != 0, axis=1)]
    k = 2.0 * math.pi * n / L
    k = k[np.linalg.norm(k, axis=1) <= kmax]
    # keep one of each +-k pair (the sum is real): half space, weight 2
    first = np.where(k[:, 0] != 0, k[:, 0], np.where(k[:, 1] != 0, k[:, 1], k[:, 2]))
    k = k[first > 0]
    k2 = np.einsum("ij,ij->i", k, k)
    x = k2 / (4.0 * xi ** 2)
    ex = np.exp(-x)
    kk = k[:, :, None] * k[:, None, :]
    T = (ex / k2)[:, None, None] * np.eye(3) - kappa * ((1.0 + x) * ex / k2 ** 2)[:, None, None] * kk
    T *= 2.0 / (V * G)
    phase = np.exp(1j * (c @ k.T))                  # (N, nk)
    M = np.zeros((N, 3, N, 3))
    s_row = a ** 2 / 6.0
    for i3 in range(3):
        for j3 in range(i3, 3):
            w = T[:, i3, j3]
            P0 = ((phase * w) @ phase.conj().T).real          # sum_k w e^{ik(r_i - r_j)}
            P2 = ((phase * (w * k2)) @ phase.conj().T).real
            blk = P0 - (s_row[:, None] + s_row[None, :]) * P2
            M[:, i3, :, j3] = blk
            M[:, j3, :, i3] = blk
    # real space: images within one shell (xi L >= p: exp(-(xi L)^2) < accuracy beyond)
    shifts = L * np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"),
                          axis=-1).reshape(-1, 3)
    iu, ju = np.triu_indices(N, 1)
    if iu.size:
        d = PeriodicBox(L).minimum_image(c[iu] - c[ju])
        s = (a[iu] ** 2 + a[ju] ** 2) / 6.0
        acc = np.zeros((iu.size, 3, 3))
        for sh in shifts:
            acc += _short(d + sh, s, G, kappa, xi)
        M[iu, :, ju, :] += acc
        M[ju, :, iu, :] += np.transpose(acc, (0, 2, 1))
    # self terms: U0 + images of itself - the smooth (long-range) part of its own free field at 0
    img = shifts[np.any(shifts != 0, axis=1)]
    s_self = a ** 2 / 3.0
    J0 = _SQRT_PI * xi                               # int_0^inf exp(-k^2/(4 xi^2)) dk
    sig2 = 1.0 / (2.0 * xi ** 2)                     # sigma^2 of the Gaussian split
    long0 = J0 * ((1.0 - kappa / 2.0) - (s_self / sig2) * (1.0 - 5.0 * kappa / 6.0)) \
        / (2.0 * math.pi ** 2 * G)
    U0 = rigid_sphere_displaceability(a, G, nu)
    for i in range(N):
        self_img = _short(img, np.full(len(img), s_self[i]), G, kappa, xi).sum(axis=0)
        M[i, :, i, :] += self_img + (U0[i] - long0[i]) * np.eye(3)
    # k = 0 value of the short part of I/k^2 (1 - e^-x) -> 1/(4 xi^2): not in the cell sum
    M -= (1.0 / (4.0 * xi ** 2 * V * G)) * np.eye(3)[None, :, None, :]
    return M.reshape(3 * N, 3 * N)
