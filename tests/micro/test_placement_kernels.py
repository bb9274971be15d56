"""Placement kernels of micro/_kernels.py against plain-numpy references."""
import numpy as np
import pytest

from micro import _kernels as K
from homogenize.bench.reference import relax_step_reference, rsa_bodies_reference
from micro.particles import _place_bodies


def _cell_list(centers, box, ncell):
    head = np.full(ncell ** 3, -1, dtype=np.int64)
    nxt = np.full(len(centers), -1, dtype=np.int64)
    for i, p in enumerate(centers):
        c = K.placement_cell_of(p, box, ncell)
        nxt[i] = head[c]
        head[c] = i
    return head, nxt


def test_cell_of_matches_numpy_floor():
    rng = np.random.default_rng(0)
    box, ncell = 3.7e-7, 6
    pts = rng.random((500, 3)) * box
    # Faces and the far face (a wrapped coordinate can round to exactly L) included.
    pts[:6] = [[0, 0, 0], [box, box, box], [box * (1 - 1e-16), 0, 0], [box / 6, 0, 0],
               [0, 2 * box / 6, 0], [0, 0, 5 * box / 6]]
    ref = np.floor(pts / box * ncell).astype(int) % ncell
    ref_flat = (ref[:, 0] * ncell + ref[:, 1]) * ncell + ref[:, 2]
    got = np.array([K.placement_cell_of(p, box, ncell) for p in pts])
    np.testing.assert_array_equal(got, ref_flat)


@pytest.mark.parametrize("ncell", [1, 2, 3, 5])
def test_overlaps_matches_brute_force(ncell):
    # Random polydisperse spheres (overlapping freely) and random probes; the cell-list answer
    # must equal the all-pairs minimum-image answer, including probes near faces and corners.
    rng = np.random.default_rng(ncell)
    box = 1.0
    rmax = box / ncell / 2.2 if ncell > 1 else 0.08
    centers = rng.random((60, 3)) * box
    radii = rng.uniform(0.2, 1.0, 60) * rmax
    gap = 0.1 * rmax
    head, nxt = _cell_list(centers, box, ncell)
    probes = rng.random((400, 3)) * box
    probes[:8] = np.array([[x, y, z] for x in (0, 1 - 1e-12) for y in (0, 1 - 1e-12)
                           for z in (0, 1 - 1e-12)])
    pr = rng.uniform(0.2, 1.0, 400) * rmax
    n_true = 0
    for p, r in zip(probes, pr):
        d = centers - p
        d -= box * np.rint(d / box)
        ref = bool(np.any(np.sum(d * d, 1) < (r + radii + gap) ** 2))
        n_true += ref
        assert K.placement_overlaps(p, r, gap, centers, radii, head, nxt, box, ncell) == ref
    assert 0 < n_true < len(probes)        # both outcomes exercised


def _bodies_case(rng, n_single, n_pairs, r0):
    """Bodies: pairs of touching spheres (largest first) followed by single spheres."""
    r_pairs = np.repeat(rng.uniform(1.0, 1.5, n_pairs) * r0, 2)
    off_pairs = np.zeros((2 * n_pairs, 3))
    u = rng.normal(size=(n_pairs, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    off_pairs[0::2] = -u * r_pairs[0::2, None] * 1.0000001
    off_pairs[1::2] = u * r_pairs[1::2, None] * 1.0000001
    r_single = np.sort(rng.uniform(0.3, 1.0, n_single) * r0)[::-1]
    radii = np.concatenate([r_pairs, r_single])
    offsets = np.concatenate([off_pairs, np.zeros((n_single, 3))])
    start = np.concatenate([np.arange(0, 2 * n_pairs + 1, 2),
                            2 * n_pairs + 1 + np.arange(n_single)]).astype(np.int64)
    return np.ascontiguousarray(offsets), np.ascontiguousarray(radii), start


@pytest.mark.parametrize("gap_rel", [0.0, 0.3])
def test_rsa_kernel_equals_numpy_reference(gap_rel):
    rng = np.random.default_rng(7)
    off, radii, start = _bodies_case(rng, 400, 30, 0.02)
    box = 1.0
    runs = []
    for kernel in (K.placement_rsa_bodies, rsa_bodies_reference):
        centers, state, status = _place_bodies(off, radii, start, box, gap_rel * 0.02,
                                               np.random.default_rng(3), 10_000, kernel)
        runs.append((centers, state, status))
    (c1, s1, st1), (c2, s2, st2) = runs
    assert st1 == st2 == 0
    np.testing.assert_array_equal(s1, s2)
    # Same candidates, same arithmetic, same decisions: bitwise identical centres.
    np.testing.assert_array_equal(c1, c2)
    # The pair bodies kept their shape (rigid translation, then wrapping).
    d = c1[1:60:2] - c1[0:60:2]
    d -= box * np.rint(d / box)
    np.testing.assert_allclose(d, off[1:60:2] - off[0:60:2], rtol=0, atol=1e-15)


def test_rsa_kernel_reports_jam_like_reference():
    # Monodisperse spheres pushed towards the RSA limit with few attempts: both stop at the
    # same body with status 2.
    n = 300
    radii = np.full(n, 0.06)
    off = np.zeros((n, 3))
    start = np.arange(n + 1, dtype=np.int64)
    out = []
    for kernel in (K.placement_rsa_bodies, rsa_bodies_reference):
        out.append(_place_bodies(off, radii, start, 1.0, 0.0, np.random.default_rng(1), 200,
                                 kernel))
    assert out[0][2] == out[1][2] == 2
    np.testing.assert_array_equal(out[0][1], out[1][1])
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert 0 < out[0][1][0] < n


def test_build_cells_matches_python_insertion():
    rng = np.random.default_rng(4)
    centers = rng.random((200, 3)) * 2.0
    head_ref, nxt_ref = _cell_list(centers, 2.0, 4)
    head = np.zeros(64, dtype=np.int64)          # stale content must be overwritten
    nxt = np.zeros(200, dtype=np.int64)
    K.placement_build_cells(centers, 2.0, 4, head, nxt)
    np.testing.assert_array_equal(head, head_ref)
    np.testing.assert_array_equal(nxt, nxt_ref)


@pytest.mark.parametrize("ncell", [1, 2, 4])
def test_relax_step_matches_numpy(ncell):
    rng = np.random.default_rng(ncell + 10)
    box, n = 1.0, 120
    rmax = box / ncell / 2.3 if ncell > 1 else 0.1
    centers = rng.random((n, 3)) * box
    radii = rng.uniform(0.4, 1.0, n) * rmax
    gap = 0.05 * rmax
    head = np.empty(ncell ** 3, dtype=np.int64)
    nxt = np.empty(n, dtype=np.int64)
    K.placement_build_cells(centers, box, ncell, head, nxt)
    disp = np.empty((n, 3))
    count = K.placement_relax_step(centers, radii, gap, 1.01, box, ncell, head, nxt, disp)
    ref, ref_count = relax_step_reference(centers, radii, gap, 1.01, box)
    assert count == ref_count > 0
    # Same terms summed in a different order: agreement to rounding.
    np.testing.assert_allclose(disp, ref, rtol=1e-12, atol=1e-15 * rmax)
    # Momentum conservation: pair pushes are equal and opposite.
    np.testing.assert_allclose(disp.sum(axis=0), 0.0, atol=1e-12 * rmax)
    # A single overlapping pair ends exactly at push_scale x contact after one step.
    c2 = np.array([[0.5, 0.5, 0.5], [0.5 + 0.1, 0.5, 0.5]])
    r2 = np.array([0.06, 0.07])
    h2 = np.empty(1, dtype=np.int64)
    n2 = np.empty(2, dtype=np.int64)
    K.placement_build_cells(c2, box, 1, h2, n2)
    d2 = np.empty((2, 3))
    assert K.placement_relax_step(c2, r2, 0.0, 1.01, box, 1, h2, n2, d2) == 1
    moved = c2 + d2
    assert np.linalg.norm(moved[1] - moved[0]) == pytest.approx(0.13 * 1.01, rel=1e-14)
