"""The periodic cube (micro/box.py) against plain loops over the periodic images."""
import dataclasses
import itertools

import numpy as np
import pytest

from micro import InputError, PeriodicBox, RVE, generate_rve
from micro.particles import pair_distances

L = 3.0
IMAGES = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=float)


def points(n=60, seed=0):
    """Random points spread over several boxes, with the awkward ones: exactly at L, at -L,
    a tiny negative coordinate (wraps to L in round-off) and negative coordinates."""
    x = np.random.default_rng(seed).uniform(-2 * L, 3 * L, (n, 3))
    x[0] = [L, 0.0, 0.5 * L]
    x[1] = [-L, -1e-30, 2 * L]
    x[2] = [-0.1, -0.2, -0.3]
    x[3] = x[0] + [0.05, -0.01, 0.02]         # a close pair across the faces
    return x


def brute_pairs(x, cutoff):
    """{(i, j): distance} over i < j, the distance the smallest over the 27 image shifts of
    the points first brought into [0, L) one coordinate at a time."""
    w = [[c % L for c in p] for p in x]
    out = {}
    for i in range(len(w)):
        for j in range(i + 1, len(w)):
            d = min(float(np.linalg.norm(np.subtract(w[j], w[i]) + L * s)) for s in IMAGES)
            if d <= cutoff:
                out[(i, j)] = d
    return out


def as_dict(i, j, d):
    return {(int(a), int(b)): float(c) for a, b, c in zip(i, j, d)}


@pytest.mark.parametrize("cutoff", [0.2, 0.9, 0.5 * L, 0.7 * L, 2 * L])
def test_pairs_within_matches_the_double_loop(cutoff):
    x = points()
    i, j, d = PeriodicBox(L).pairs_within(x, cutoff)
    got, want = as_dict(i, j, d), brute_pairs(x, cutoff)
    assert set(got) == set(want)
    assert np.allclose([got[k] for k in want], [want[k] for k in want], rtol=1e-12, atol=1e-12)
    assert np.all(i < j) and i.dtype == np.int64 and j.dtype == np.int64
    order = np.lexsort((j, i))
    assert np.array_equal(order, np.arange(i.size))          # sorted by i, then j
    if cutoff >= 0.05:
        assert (0, 3) in got and got[(0, 3)] == pytest.approx(np.sqrt(0.05 ** 2 + 0.01 ** 2
                                                                      + 0.02 ** 2))


def test_tree_and_direct_search_agree_across_half_the_box():
    x = points(120, seed=3)
    box = PeriodicBox(L)
    below = box.pairs_within(x, np.nextafter(0.5 * L, 0))     # KD-tree
    at = box.pairs_within(x, 0.5 * L)                          # every pair checked
    assert np.any(at[2] == 0.5 * L)                 # points 0 and 1: half an edge apart
    at = [a[at[2] < 0.5 * L] for a in at]
    for a, b in zip(below, at):
        assert np.array_equal(a, b)


def test_wrap_fractional_minimum_image():
    box = PeriodicBox(L)
    x = points()
    w = box.wrap(x)
    assert np.all((w >= 0) & (w < L))
    assert np.array_equal(w[0], [0.0, 0.0, 0.5 * L]) and np.array_equal(w[1], [0.0, 0.0, 0.0])
    assert np.allclose(w[2], [L - 0.1, L - 0.2, L - 0.3])
    assert np.array_equal(box.wrap(w), w)                     # idempotent
    u = box.fractional(x)
    assert np.all((u >= 0) & (u < 1)) and np.allclose(u, w / L, atol=1e-15)
    d = x[:, None, :] - x[None, :, :]
    m = box.minimum_image(d)
    assert np.all(np.abs(m) <= 0.5 * L * (1 + 1e-15))
    assert np.allclose(np.round((d - m) / L), (d - m) / L, atol=1e-9)   # whole edges only
    assert np.array_equal(box.minimum_image(-d), -m)


def test_nearest_matches_the_double_loop():
    x = points(40, seed=5)
    dist, idx = PeriodicBox(L).nearest(x, k=2)
    assert np.array_equal(idx[:, 0], np.arange(40)) and np.all(dist[:, 0] == 0)
    full = brute_pairs(x, np.inf)
    for p in range(40):
        others = {(q if a == p else a): v for (a, q), v in full.items() if p in (a, q)}
        q = min(others, key=others.get)
        assert idx[p, 1] == q and dist[p, 1] == pytest.approx(others[q], rel=1e-10)


def test_translation_invariance():
    x = points(80, seed=7)
    base = as_dict(*PeriodicBox(L).pairs_within(x, 0.8))
    for shift in ([0.3, -1.7, 5.2], [L, -2 * L, 0.0], [1e-9, 0.0, -1e-9]):
        moved = as_dict(*PeriodicBox(L).pairs_within(x + shift, 0.8))
        assert set(moved) == set(base)
        assert np.allclose([moved[k] for k in base], [base[k] for k in base], atol=1e-12)


@pytest.mark.parametrize("s", [1e-7, 0.25, 37.0])
def test_scale_invariance(s):
    x = points(80, seed=9)
    base = as_dict(*PeriodicBox(L).pairs_within(x, 1.1))
    scaled = as_dict(*PeriodicBox(s * L).pairs_within(s * x, s * 1.1))
    assert set(scaled) == set(base)
    assert np.allclose([scaled[k] / s for k in base], [base[k] for k in base], rtol=1e-12)
    assert np.allclose(PeriodicBox(s * L).wrap(s * x) / s, PeriodicBox(L).wrap(x), atol=1e-12)


def test_small_and_empty_inputs():
    box = PeriodicBox(L)
    for x in (np.zeros((0, 3)), np.ones((1, 3))):
        i, j, d = box.pairs_within(x, 1.0)
        assert i.size == j.size == d.size == 0 and i.dtype == np.int64
    i, j, d = box.pairs_within(points(), -1.0)
    assert i.size == 0
    with pytest.raises(InputError, match="shape"):
        box.pairs_within(np.ones((4, 2)), 1.0)


def test_immutable_and_checked():
    box = PeriodicBox(2)
    assert box.L == 2.0 and isinstance(box.L, float) and box == PeriodicBox(2.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        box.L = 3.0
    for bad in (0.0, -1.0, float("inf"), float("nan"), "x"):
        with pytest.raises(InputError, match="PeriodicBox"):
            PeriodicBox(bad)


def test_rve_uses_its_box():
    rve = generate_rve(0.1, 80, 2)
    assert rve.box == PeriodicBox(rve.box_m)
    i, j, d = pair_distances(rve, 0.3 * rve.box_m)
    want = brute_pairs(rve.centers_m / rve.box_m * L, 0.3 * L)
    assert set(as_dict(i, j, d)) == set(want)
    r = RVE.from_spheres(1.0, [[1.0, -1e-30, 0.5], [0.2, 0.3, 0.4]], [0.1, 0.1])
    assert np.array_equal(r.centers_m[0], [0.0, 0.0, 0.5])
