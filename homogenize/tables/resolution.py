"""The discretization error of the cell FEM's composite voxels, next to the statistical one.

A table quantity from the cell FEM (``E_eff_Pa``, ``nu_eff``, ``stress_mag_Pa``,
``strain_mag``; with the relax evaluator the strains, stresses and moduli of the relaxed RVE) is
the mean over random RVEs, each solved on ``n`` voxels per edge. Its
statistical interval says how far the mean of the RVEs is from the mean of infinitely many RVEs
ON THAT GRID; the grid's own error is a bias shared by all realizations, which no number of
realizations removes. This module estimates it from two resolutions of the SAME RVEs and adds
it to the interval.

The estimate (what the study measured, results/cell/README.md, "One dilute sphere: convergence
rate")
-----------------------------------------------------------------------------------------------
Composite voxels are first order asymptotically (mean error of a dilute Fe sphere's shear
coefficient ~ 0.69/D - 5.5/D^2 for D >= 10 voxels per diameter) and NOT monotone: the error is
-5.3 % at 4.3 voxels per diameter, -1.2 % at 5.9, +1.2 % at 8.0, then a plateau of +2.2 % near
16 (the hump) that decays only slowly (+1.6 % at 34). So:

1. **Two grids, first order.** Every realization is also solved on ``n_c`` =
   :func:`coarse_voxels` (n) (about 2/3 n, even). With ``D_i = Q_i(n) - Q_i(n_c)`` and
   ``r = n / n_c``, a first-order error ``Q(n) = Q_inf + a / n`` gives the bias of the fine grid
   ``b = Q(n) - Q_inf = -mean(D) / (r - 1)`` (Richardson with p = :data:`ORDER`). Its statistical uncertainty is
   included: ``e_two_grid = (|mean D| + t sd(D) / sqrt(R)) / (r - 1)`` (t at the study's
   confidence, R - 1 degrees of freedom). For a quantity that converges at second order
   (the position-dependent part) this overestimates by r + 1.
2. **A floor from the accuracy study.** Between ~8 and ~34 voxels per diameter the two-grid
   difference can vanish on the hump while the bias stays at +1.6 to +2.2 % of the filler's
   contribution. The estimate is therefore never below :data:`FILLER_BIAS_REL` = 2.2 % of the
   filler's contribution ``|Q - Q_matrix|`` (``Q_matrix``: the matrix's E and nu; 0 for the
   magnetic stress and strain, which the filler alone makes).

``e = max(e_two_grid, FILLER_BIAS_REL |Q - Q_matrix|)``, componentwise.

**Combination.** The discretization error is a bias common to all realizations, not a random
error, so it is added to the statistical half-width linearly (a worst-case sum):
``[ci_low - e, ci_high + e]`` (:func:`combined_interval`). The tables store it as
``Q_disc_err`` and the combined ends as ``Q_total_low``, ``Q_total_high``.

**Resolution needed.** At fewer than :data:`MIN_VOXELS_PER_RADIUS` = 3 voxels per mean radius
(6 per diameter) the dilute sphere's error was -5.3 % at 2.15 voxels per radius with a 9 %
spread over positions, and grows quickly below; above it, within +-2.2 %. Batches and
``mapsim cell`` warn below it (:func:`resolution_warning`).
"""
from __future__ import annotations

import math

import numpy as np

from homogenize.tables._stats import t_half_width

__all__ = ["ORDER", "FILLER_BIAS_REL", "MIN_VOXELS_PER_RADIUS", "coarse_voxels",
           "discretization_error", "combined_interval", "voxels_per_radius",
           "resolution_warning", "voxels_needed"]

#: asymptotic order of the composite voxels' error (results/cell/README.md, dilute_rate: the
#: two-term fit a/D + b/D^2 on D >= 10 voxels per diameter)
ORDER = 1.0
#: largest measured bias of the composite voxels relative to the filler's contribution (a
#: dilute Fe sphere's shear coefficient, +2.2 % at 16 voxels per diameter, results/cell)
FILLER_BIAS_REL = 0.022
#: voxels per mean particle radius below which the composite voxels' error exceeds ~2 %
#: (dilute sphere: -1.2 % at 2.95, -5.3 % at 2.15 voxels per radius, results/cell)
MIN_VOXELS_PER_RADIUS = 3.0


def coarse_voxels(voxels: int) -> int:
    """The second, coarser grid of the two-grid estimate: the even count nearest 2/3 of
    ``voxels`` (even, so that the matrix-free solver can run it), at least 4 and below
    ``voxels``."""
    n = int(voxels)
    c = 2 * int(round(n / 3.0))
    c = max(4, min(c, n - 2 if n % 2 == 0 else n - 1))
    if c >= n:
        raise ValueError(f"no coarser grid below {n} voxels (at least 6 are needed)")
    return c


def discretization_error(fine, coarse, voxels: int, voxels_coarse: int, confidence: float, *,
                         matrix_value=0.0, order: float = ORDER) -> dict:
    """The discretization error of the fine grid's mean (module docstring).

    ``fine``, ``coarse``: per-realization values, shape (R, ...), of the same RVEs at
    ``voxels`` and ``voxels_coarse``. ``matrix_value``: the quantity's value without filler
    (broadcast). Returns ``bias`` (signed two-grid estimate of Q(n) - Q_inf), ``two_grid``,
    ``floor`` and ``err`` (the estimate used: their maximum), arrays of shape (...).
    """
    f = np.asarray(fine, dtype=float)
    c = np.asarray(coarse, dtype=float)
    if f.shape != c.shape or f.shape[0] < 2:
        raise ValueError(f"fine and coarse values need the same shape (R >= 2, ...); got "
                         f"{f.shape} and {c.shape}")
    if not voxels > voxels_coarse > 0:
        raise ValueError(f"need voxels > voxels_coarse > 0, got {voxels}, {voxels_coarse}")
    R = f.shape[0]
    d = f - c
    scale = (voxels / voxels_coarse) ** order - 1.0
    mean_d = d.mean(axis=0)
    half = t_half_width(d.std(axis=0, ddof=1) / math.sqrt(R), R - 1, confidence)
    two_grid = (np.abs(mean_d) + half) / scale
    floor = FILLER_BIAS_REL * np.abs(f.mean(axis=0) - np.asarray(matrix_value, dtype=float))
    # Richardson: Q_inf = Q(n) + (Q(n) - Q(n_c)) / (r^p - 1), so Q(n) - Q_inf = -mean(D) / ...
    return {"bias": -mean_d / scale, "two_grid": two_grid, "floor": floor,
            "err": np.maximum(two_grid, floor)}


def combined_interval(ci_low, ci_high, err):
    """The statistical interval widened by the discretization error on both sides (linear
    sum: the discretization error is a bias shared by the realizations)."""
    e = np.abs(np.asarray(err, dtype=float))
    return np.asarray(ci_low, dtype=float) - e, np.asarray(ci_high, dtype=float) + e


def voxels_per_radius(mean_radius_m: float, box_m: float, voxels: int) -> float:
    """The mean particle radius in voxel edges: ``r / (L / n)``."""
    return float(mean_radius_m) * int(voxels) / float(box_m)


def voxels_needed(mean_radius_m: float, box_m: float) -> int:
    """Voxels per edge that give :data:`MIN_VOXELS_PER_RADIUS` for this radius and box (even)."""
    n = math.ceil(MIN_VOXELS_PER_RADIUS * float(box_m) / float(mean_radius_m) * (1 - 1e-12))
    return n + (n % 2)


def resolution_warning(mean_radius_m: float, box_m: float, voxels: int,
                       where: str = "") -> str | None:
    """One line naming an under-resolved cell (None when resolved well enough)."""
    vpr = voxels_per_radius(mean_radius_m, box_m, voxels)
    if vpr >= MIN_VOXELS_PER_RADIUS * (1 - 1e-12):     # round-off of r n / L
        return None
    return (f"warning: {where + ': ' if where else ''}the mean particle radius is "
            f"{vpr:.2g} voxels at {voxels} voxels per edge; the composite voxels' error exceeds "
            f"~2 % below {MIN_VOXELS_PER_RADIUS:g} voxels per radius (results/cell/README.md: "
            f"-5.3 % at 2.15): use voxels >= {voxels_needed(mean_radius_m, box_m)} for "
            f"numbers to rely on")
