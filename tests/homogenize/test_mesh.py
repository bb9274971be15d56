"""Voxelization of the periodic RVE."""
from types import SimpleNamespace

import numpy as np
import pytest

from homogenize.voxels.mesh import voxelize
from micro.common.validate import InputError


def _rve(centres, radii, L=1.0):
    return SimpleNamespace(box_m=L, centers_m=np.atleast_2d(centres) * L,
                           radii_m=np.atleast_1d(radii) * L)


def test_sphere_volume_converges_and_fraction_is_more_accurate():
    r = 0.3
    exact = 4.0 / 3.0 * np.pi * r ** 3
    errs = {}
    for method in ("centre", "fraction"):
        errs[method] = [abs(voxelize(_rve([0.5, 0.5, 0.5], r), n, method=method).phi_voxel - exact)
                        / exact for n in (8, 16, 32)]
    # voxel volume -> sphere volume (staircase error O(h) at worst)
    assert errs["centre"][-1] < 0.02 and errs["fraction"][-1] < 0.005
    assert errs["fraction"][-1] < errs["centre"][-1]


def test_periodic_wrap_is_a_translation():
    # a sphere across the corner of the cell is the centred sphere shifted by whole voxels
    n = 10
    a = voxelize(_rve([0.55, 0.55, 0.55], 0.27), n)
    b = voxelize(_rve([0.05, 0.05, 0.05], 0.27), n)
    # composite voxels: exact fractions from closed forms, equal up to round-off (1e-14 of a
    # voxel measured; the staircase was bit-identical)
    np.testing.assert_allclose(np.roll(a.fraction, shift=(-5, -5, -5), axis=(0, 1, 2)),
                               b.fraction, rtol=0, atol=1e-12)
    assert a.fraction.sum() == pytest.approx(b.fraction.sum(), rel=1e-12)


def test_force_lists_cover_every_particle():
    m = voxelize(_rve([[0.25, 0.25, 0.25], [0.71, 0.73, 0.69]], [0.2, 0.01]), 8)
    assert m.resolved.tolist() == [True, False]
    cnt = np.diff(m.force_ptr)
    assert cnt[0] == int((m.owner == 0).sum()) and cnt[1] == 1     # unresolved: its centre voxel
    ic = np.floor(np.array([0.71, 0.73, 0.69]) * 8).astype(int)
    assert m.force_voxels[m.force_ptr[1]] == ic[0] + 8 * (ic[1] + 8 * ic[2])


def test_bad_input():
    with pytest.raises(InputError, match="resolves none"):
        voxelize(_rve([0.5, 0.5, 0.5], 0.02), 8)
    with pytest.raises(InputError, match="voxels must be an integer >= 4"):
        voxelize(_rve([0.5, 0.5, 0.5], 0.3), 3)
    with pytest.raises(InputError, match="method"):
        voxelize(_rve([0.5, 0.5, 0.5], 0.3), 8, method="smooth")
