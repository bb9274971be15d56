"""Macro solvers fed by a batch table: the effective material with its intervals.

The table gives the body force and (with FEM results) the modulus as estimates with confidence
intervals (:mod:`homogenize.tables`); the functions here carry those intervals through the
macro models.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from micro._validate import check_choice
from micro.materials import PDMS

from homogenize.macro.closed_form import eb_tip_deflection_m, elastica_tip_deflection
from homogenize.tables import Estimate, Table, body_force_from_table, modulus_from_table, read_table

__all__ = ["TipDeflection", "tip_deflection_from_table"]


@dataclass(frozen=True)
class TipDeflection:
    """Cantilever tip deflection from a table, with the interval propagated from it."""

    deflection_m: float           # with the chosen model
    ci_low_m: float
    ci_high_m: float
    deflection_eb_m: float        # small-deflection Euler-Bernoulli value at the mean force
    model: str
    force: Estimate               # body force used [N/m^3]
    E_Pa: float
    E_estimate: Estimate | None   # from the table (FEM), or None (E given / PDMS)
    confidence: float

    @property
    def large_deflection(self) -> bool:
        """True if the elastica differs from Euler-Bernoulli by more than 1 %."""
        return abs(self.deflection_m - self.deflection_eb_m) > 0.01 * abs(self.deflection_eb_m)


def tip_deflection_from_table(table, phi: float, B_T: float, gradB_T_per_m: float,
                              length_m: float, width_m: float, thickness_m: float, *,
                              E_Pa: float | None = None, nu: float = 0.45, model="elastica",
                              confidence: float | None = None, **other_axes) -> TipDeflection:
    """Tip deflection [m] of a clamped strip under the body force interpolated from a table.

    The force interval of :func:`body_force_from_table` maps through the deflection, which is
    monotone in the force, to the deflection interval. The modulus is ``E_Pa`` if given, else
    ``E_eff`` of the table if it holds FEM results (its relative interval is added in
    quadrature), else the PDMS value 2 MPa. ``model``: ``"elastica"`` (large rotation, dead
    load; equals Euler-Bernoulli for small deflections) or ``"eb"``.
    """
    check_choice("model", model, ("elastica", "eb"))
    if not isinstance(table, Table):
        table = read_table(table)
    f = body_force_from_table(table, phi, B_T, gradB_T_per_m, confidence=confidence,
                              **other_axes)
    E_est = None
    if E_Pa is None:
        E_est = modulus_from_table(table, phi, confidence=confidence,
                                   **{k: v for k, v in other_axes.items()
                                      if k not in ("B_T", "gradB_T_per_m")})
        E = PDMS.E_Pa if E_est is None else E_est.mean
    else:
        E = float(E_Pa)
    forces = np.clip(np.array([f.mean, f.ci_low, f.ci_high]), 0.0, None)
    eb = np.asarray(eb_tip_deflection_m(forces, length_m, width_m, thickness_m, E), float)
    if model == "elastica":
        d, _h = elastica_tip_deflection(forces, length_m, width_m, thickness_m, E)
        d = np.asarray(d, float)
    else:
        d = eb
    mid, lo, hi = float(d[0]), float(d[1]), float(d[2])
    if E_est is not None and mid > 0:
        rel_E = (E_est.ci_high - E_est.ci_low) / (2 * E_est.mean)
        lo = mid * (1 - math.hypot(1 - lo / mid, rel_E))
        hi = mid * (1 + math.hypot(hi / mid - 1, rel_E))
    return TipDeflection(mid, lo, hi, float(eb[0]), model, f, E, E_est, f.confidence)
