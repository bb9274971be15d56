"""The periodic cube: the one owner of the project's periodic geometry.

:class:`PeriodicBox` answers every question that involves periodic images of points in a cube
of edge ``L`` (after freud's ``Box``, cubic only): wrapping into ``[0, L)``, fractional
coordinates, the minimum image of a separation, the pairs closer than a cutoff and the nearest
neighbours. The unit is the caller's: metres for an RVE, voxels for a grid.

The numba kernels (``micro/_kernels.py``) cannot call a Python object and keep their inline
``d -= box * np.rint(d / box)``: the same minimum image, repeated inside compiled loops.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from micro.common.validate import InputError

__all__ = ["PeriodicBox"]

#: the KD-tree's periodic box is ``L (1 + TREE_MARGIN)``: a point at ``L`` minus round-off is
#: inside it whatever arithmetic brought it there
TREE_MARGIN = 1e-12
#: pairs per block of the brute-force search (bounds its temporaries to ~100 MB)
_BLOCK = 1 << 22


@dataclass(frozen=True)
class PeriodicBox:
    """A periodic cube of edge ``L`` (> 0, finite), in the caller's unit.

    Immutable; two boxes of the same edge are equal. Arrays of points or separations have
    shape (..., 3); nothing is changed in place.
    """

    L: float

    def __post_init__(self):
        try:
            L = float(self.L)
        except (TypeError, ValueError):
            raise InputError(f"PeriodicBox edge L must be a number, got {self.L!r}") from None
        if not (math.isfinite(L) and L > 0):
            raise InputError(f"PeriodicBox edge L must be > 0 and finite, got {L:g}")
        object.__setattr__(self, "L", L)

    # -------------------------------------------------------------------- coordinates
    def wrap(self, x) -> np.ndarray:
        """Points (..., 3) moved by whole edges into ``[0, L)``: ``x mod L``, with a result of
        exactly ``L`` (round-off of a tiny negative coordinate) set to 0, the same point."""
        w = np.mod(np.asarray(x, dtype=float), self.L)
        return np.where(w >= self.L, 0.0, w)

    def fractional(self, x) -> np.ndarray:
        """Fractional coordinates (..., 3) in ``[0, 1)`` of points ``x``: ``(x / L) mod 1``
        (a result of exactly 1 set to 0)."""
        u = np.mod(np.asarray(x, dtype=float) / self.L, 1.0)
        return np.where(u >= 1.0, 0.0, u)

    def minimum_image(self, d) -> np.ndarray:
        """Separations (..., 3) mapped to their shortest periodic image,
        ``d - L round(d / L)``: each component in ``[-L/2, L/2]``."""
        d = np.asarray(d, dtype=float)
        return d - self.L * np.round(d / self.L)

    # -------------------------------------------------------------------- neighbours
    def _tree(self, wrapped):
        from scipy.spatial import cKDTree
        return cKDTree(wrapped, boxsize=self.L * (1 + TREE_MARGIN))

    def pairs_within(self, points, cutoff: float):
        """Every pair of ``points`` (N, 3) whose minimum-image distance is at most ``cutoff``.

        Returns ``(i, j, dist)``: int64 indices with ``i < j``, sorted by ``i`` then ``j``
        (whatever the search), and the distances ``|minimum_image(x_j - x_i)|`` of the wrapped
        points. A periodic KD-tree finds the pairs; from ``cutoff >= L/2`` on, where nearly
        every pair is within reach, all pairs are checked directly.
        """
        w = self.wrap(points)
        if w.ndim != 2 or w.shape[1] != 3:
            raise InputError(f"points must have shape (N, 3), got {w.shape}")
        n = w.shape[0]
        cutoff = float(cutoff)
        if n < 2 or not cutoff >= 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        if cutoff < 0.5 * self.L:
            ij = self._tree(w).query_pairs(cutoff, output_type="ndarray").astype(np.int64)
            ij = ij[np.lexsort((ij[:, 1], ij[:, 0]))]
            i, j = ij[:, 0], ij[:, 1]
            return i, j, np.linalg.norm(self.minimum_image(w[j] - w[i]), axis=-1)
        iu, ju = np.triu_indices(n, 1)
        parts = []
        for s in range(0, iu.size, _BLOCK):
            i, j = iu[s:s + _BLOCK], ju[s:s + _BLOCK]
            dist = np.linalg.norm(self.minimum_image(w[j] - w[i]), axis=-1)
            keep = dist <= cutoff
            parts.append((i[keep], j[keep], dist[keep]))
        return tuple(np.concatenate(p) for p in zip(*parts))

    def nearest(self, points, k: int = 1):
        """The ``k`` nearest of ``points`` (N, 3) to each of them, itself included (first, at
        distance 0): ``(dist, index)`` as ``scipy.spatial.cKDTree.query`` returns them, shape
        (N,) for ``k = 1`` and (N, k) otherwise; minimum-image distances."""
        w = self.wrap(points)
        return self._tree(w).query(w, k=k)
