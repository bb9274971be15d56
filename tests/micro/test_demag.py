"""Specimen demagnetizing factors: sum rule, symmetric shapes, limits, and magpylib's field."""
import math

import magpylib
import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from micro.common.validate import InputError
from micro.demag import (cylinder_demag_factors, ellipsoid_demag_factors, prism_demag_factors,
                         spheroid_demag_factors)

SEED_STRIP_M = (19.369e-3, 5e-3, 1e-3)


@pytest.mark.parametrize("dims", [(1, 1, 1), (2, 1, 0.5), SEED_STRIP_M, (1, 1, 1e-3),
                                  (1e-3, 1e-3, 1), (7, 0.3, 2)])
def test_prism_factors_sum_to_one(dims):
    # trace rule of the magnetometric tensor; the algebraic terms cancel from ~aspect^2, so
    # ~2 log10(aspect) digits are lost (docstring): 1e-16 * aspect^2 * 100 as the tolerance
    aspect = max(dims) / min(dims)
    assert sum(prism_demag_factors(*dims)) == pytest.approx(1.0, abs=1e-14 * max(aspect, 10) ** 2)


def test_cube_is_one_third_and_scale_free():
    for s in (1e-6, 1.0, 3e2):
        assert prism_demag_factors(s, s, s) == pytest.approx((1 / 3,) * 3, abs=1e-14)
    # homogeneous of degree 0 and covariant under permutation of the axes
    n1 = prism_demag_factors(*SEED_STRIP_M)
    n2 = prism_demag_factors(*(10 * d for d in SEED_STRIP_M))
    assert n1 == pytest.approx(n2, rel=1e-13)
    n3 = prism_demag_factors(SEED_STRIP_M[2], SEED_STRIP_M[0], SEED_STRIP_M[1])
    assert (n3[1], n3[2], n3[0]) == pytest.approx(n1, rel=1e-12)


def test_prism_limits():
    # thin plate: N through the thickness -> 1 - O(t/a); long rod: N along it -> 0 as O(a/L)
    nz_plate = [prism_demag_factors(1, 1, t)[2] for t in (1e-1, 1e-2, 1e-3)]
    assert np.all(np.diff(nz_plate) > 0) and 1 - nz_plate[-1] < 5e-3
    nz_rod = [prism_demag_factors(1, 1, L)[2] for L in (1e1, 1e2, 1e3)]
    assert np.all(np.diff(nz_rod) < 0) and nz_rod[-1] < 1e-3


def test_seed_strip_through_thickness():
    # the value quoted in issue 12 for the 19 x 5 x 1 mm strip
    assert prism_demag_factors(*SEED_STRIP_M)[2] == pytest.approx(0.771, abs=1e-3)


def test_sphere_and_spheroids():
    assert spheroid_demag_factors(1.0, 1.0) == pytest.approx((1 / 3,) * 3, abs=1e-15)
    for m in (0.05, 0.5, 0.95, 0.995, 1.005, 1.5, 3.0, 50.0):
        n = spheroid_demag_factors(m, 1.0)
        assert sum(n) == pytest.approx(1.0, abs=1e-14)
        # Osborn's closed forms against Carlson's R_D, an independent evaluation (1e-12: the
        # closed forms lose ~log10(1 / |m - 1|) digits near the sphere)
        assert n == pytest.approx(ellipsoid_demag_factors(1.0, 1.0, m), rel=1e-12)
    # continuity where the implementation switches formula (|m - 1| = 1e-2)
    lo, hi = spheroid_demag_factors(1.01 - 1e-9, 1.0), spheroid_demag_factors(1.01 + 1e-9, 1.0)
    assert lo[2] == pytest.approx(hi[2], abs=1e-8)
    # limits: needle -> 0 along, disc -> 1 through
    assert spheroid_demag_factors(1e4, 1.0)[2] < 1e-6
    assert spheroid_demag_factors(1e-4, 1.0)[2] > 1 - 2e-4


def test_cylinder_tabulated_and_limits():
    # Chen, Brug & Goldfarb (1991) tabulate the magnetometric axial factor 0.3116 at L = 2R
    assert cylinder_demag_factors(1.0, 2.0)[2] == pytest.approx(0.3116, abs=1e-4)
    nx, ny, nz = cylinder_demag_factors(0.3, 1.7)
    assert nx == ny and nx + ny + nz == pytest.approx(1.0, abs=1e-15)
    # long rod: N_z -> (2R/L) 4/(3 pi) (the disc self-energy term); thin disc: N_z -> 1
    R, L = 1.0, 1e4
    assert cylinder_demag_factors(R, L)[2] == pytest.approx(8 * R / (3 * math.pi * L), rel=1e-3)
    assert cylinder_demag_factors(1.0, 1e-3)[2] > 0.996


def _box_average_H(magnet, lo, hi, n):
    """Volume average of magpylib's H over a box [lo, hi] by an n^3 Gauss-Legendre product rule."""
    x, w = np.polynomial.legendre.leggauss(n)
    axes = [0.5 * (h + l) + 0.5 * (h - l) * x for l, h in zip(lo, hi)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    W = (w[:, None, None] * w[None, :, None] * w[None, None, :]).ravel() / 8.0
    H = magnet.getH(np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]))
    return W @ H


def test_prism_against_magpylib_volume_average():
    dims = np.array(SEED_STRIP_M)
    M = 1e5
    N = prism_demag_factors(*dims)
    for axis in range(3):
        pol = np.zeros(3)
        pol[axis] = MU0 * M
        cube = magpylib.magnet.Cuboid(dimension=dims, polarization=pol)
        Hbar = _box_average_H(cube, -dims / 2, dims / 2, 24)
        # the field of a prism has only integrable log singularities at its edges: a 24^3
        # Gauss rule averages it to ~1e-4 of M (seen: halving n changes the mean by < 3e-4 M)
        assert -Hbar[axis] / M == pytest.approx(N[axis], abs=1e-3)


def test_cylinder_against_magpylib_volume_average():
    R, L, M = 2e-3, 3e-3, 1e5
    N = cylinder_demag_factors(R, L)
    # axial: average over the cylinder in polar coordinates (Gauss in r with weight r, in z,
    # uniform in angle; the field is axisymmetric so one angle suffices)
    cyl = magpylib.magnet.Cylinder(dimension=(2 * R, L), polarization=(0, 0, MU0 * M))
    xr, wr = np.polynomial.legendre.leggauss(40)
    r = 0.5 * R * (xr + 1)
    z = 0.5 * L * xr
    Rg, Zg = np.meshgrid(r, z, indexing="ij")
    W = (wr * r)[:, None] * wr[None, :]
    H = cyl.getH(np.column_stack([Rg.ravel(), 0 * Rg.ravel(), Zg.ravel()]))
    hz = (W.ravel() @ H[:, 2]) / W.sum()
    assert -hz / M == pytest.approx(N[2], abs=1e-3)
    # transverse: magnetization along x; average over angle too (8 angles x 40 x 40)
    cyl = magpylib.magnet.Cylinder(dimension=(2 * R, L), polarization=(MU0 * M, 0, 0))
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    pts = np.column_stack([(Rg[..., None] * np.cos(ang)).ravel(),
                           (Rg[..., None] * np.sin(ang)).ravel(),
                           np.repeat(Zg.ravel(), ang.size)])
    hx = (np.repeat(W.ravel(), ang.size) @ cyl.getH(pts)[:, 0]) / (W.sum() * ang.size)
    assert -hx / M == pytest.approx(N[0], abs=1e-3)


def test_bad_input():
    with pytest.raises(InputError, match="b_m"):
        prism_demag_factors(1.0, -1.0, 1.0)
    with pytest.raises(InputError, match="radius_m"):
        cylinder_demag_factors(0.0, 1.0)
    with pytest.raises(InputError, match="polar_m"):
        spheroid_demag_factors(float("nan"), 1.0)
