"""Macro solvers fed by a batch table: the effective material with its intervals.

The table gives the body force and (with FEM results) the modulus as estimates with confidence
intervals (:mod:`homogenize.tables.batch`); the functions here carry those intervals through the
macro models.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from micro.common.validate import check_choice
from micro.common.validate import InputError
from micro.materials import FE, PDMS, SEED, ElasticMaterial, mixture_density_kg_m3
from scipy.constants import mu_0 as MU0

from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.closed_form import eb_tip_deflection_m, elastica_tip_deflection
from homogenize.macro.magnets import linear_magnetization, tabulated_magnetization
from homogenize.tables._stats import widen_in_quadrature
from homogenize.tables.batch import (Estimate, Table, body_force_from_table, interpolate,
                               modulus_from_table, read_table)

__all__ = ["TipDeflection", "tip_deflection_from_table", "EffectiveMaterial",
           "effective_material_from_table", "beam_with_interval",
           "magnetization_from_table", "magnetization_table_law", "soft_sphere_magnetization"]


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
                              E_Pa: float | None = None, nu: float = PDMS.nu, model="elastica",
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
        lo, hi = widen_in_quadrature(mid, lo, hi, E_est.total_rel_half_width)
    return TipDeflection(mid, lo, hi, float(eb[0]), model, f, E, E_est, f.confidence)


@dataclass(frozen=True)
class EffectiveMaterial:
    """The composite as a macro solver sees it: body force and modulus with their intervals.

    force : Estimate -- transverse magnetic body force [N/m^3] (mean and confidence interval)
    E_Pa : float -- Young's modulus used [Pa]; E_estimate : Estimate or None -- the table's
        E_eff with its interval (None when E was given or taken as the PDMS value)
    nu : float -- Poisson's ratio [-]; density_kg_m3 : float -- mass density [kg/m^3]
    E_source : str -- "given", "table" or "PDMS"
    """

    force: Estimate
    E_Pa: float
    nu: float
    density_kg_m3: float
    E_estimate: Estimate | None = None
    E_source: str = "given"

    @property
    def elastic(self) -> ElasticMaterial:
        return ElasticMaterial(self.E_Pa, self.nu, self.density_kg_m3)


def effective_material_from_table(table, phi: float, B_T: float, gradB_T_per_m: float, *,
                                  other_axes: dict | None = None, E_Pa: float | None = None,
                                  E_from_table: bool = True, nu: float | None = None,
                                  density_kg_m3: float | None = None,
                                  matrix=None) -> EffectiveMaterial:
    """Interpolate the effective material of a batch table at (phi, B, gradB).

    The body force comes with its interval. ``E_Pa`` given wins; else the table's ``E_eff`` if
    it holds FEM results and ``E_from_table``; else the matrix's. ``nu``: given, else the
    table's ``nu_eff``, else the matrix's. The density defaults to the mixture of the matrix and
    Fe at phi. ``matrix``: anything with ``E_Pa``, ``nu``, ``density_kg_m3`` (e.g. a
    :class:`micro.materials.MatrixPreset`; default the seed's PDMS).
    """
    m = PDMS if matrix is None else matrix
    if not isinstance(table, Table):
        table = read_table(table)
    others = dict(other_axes or {})
    force = body_force_from_table(table, phi, B_T, gradB_T_per_m, **others)
    mech = {k: v for k, v in others.items() if k not in ("B_T", "gradB_T_per_m")}
    E_est = modulus_from_table(table, phi, **mech) if (E_Pa is None and E_from_table) else None
    if E_Pa is not None:
        E, src = float(E_Pa), "given"
    elif E_est is not None:
        E, src = E_est.mean, "table"
    else:
        E, src = m.E_Pa, "PDMS" if matrix is None else "matrix"
    if nu is None:
        if "nu_eff" in table.values:
            coords = {"phi": phi, **mech}
            for a, v in (("B_T", B_T), ("gradB_T_per_m", gradB_T_per_m)):
                if a in table.axes and len(table.axes[a]) > 1:
                    coords[a] = v
            nu = interpolate(table, "nu_eff", **coords).mean
        else:
            nu = m.nu
    rho = density_kg_m3 if density_kg_m3 is not None else mixture_density_kg_m3(phi, m, FE)
    return EffectiveMaterial(force, E, float(nu), float(rho), E_est, src)


def beam_with_interval(strip: Strip, material: EffectiveMaterial, models, *, order: int = 2,
                       nz: int = 3, gravity_m_s2: float = 0.0, n_steps: int = 4) -> list[dict]:
    """Tip deflection [m] of each model at the mean force and at both ends of its interval.

    The deflection is monotone in the force, so the force interval maps to the deflection
    interval; the modulus interval (deflection ~ 1/E) is added in quadrature.
    """
    f = material.force
    if f.ci_low < 0:
        raise InputError(f"the force interval reaches below zero ({f.ci_low:g} N/m^3): too few "
                         f"realizations for a deflection interval")
    mat = material.elastic
    rows = []
    for model in models:
        tips = {}
        for k, q in (("mean", f.mean), ("ci_low", f.ci_low), ("ci_high", f.ci_high)):
            r = solve_cantilever(strip, mat, q, model=model, order=order, nz=nz,
                                 gravity_m_s2=gravity_m_s2, n_steps=n_steps)
            tips[k] = r.tip_m
        lo, hi = tips["ci_low"], tips["ci_high"]
        if material.E_estimate is not None and tips["mean"] > 0:
            lo, hi = widen_in_quadrature(tips["mean"], lo, hi,
                                         material.E_estimate.total_rel_half_width)
        rows.append({"model": model, "tip_m": tips["mean"], "ci_low_m": lo, "ci_high_m": hi})
    return rows


def _table_M_nodes(table, phi, bound, other_axes):
    """(B_T nodes, M_eff nodes [A/m]) of a batch table at ``phi`` (z component, the field's
    direction), from the ``bound`` ("mean", "low", "high") of each grid value's estimate."""
    check_choice("bound", bound, ("mean", "low", "high"))
    if not isinstance(table, Table):
        table = read_table(table)
    if "B_T" not in table.axes or len(table.axes["B_T"]) < 2:
        raise InputError("M_eff(H) from a table needs at least two B_T values in the table")
    B = np.array(sorted(float(b) for b in table.axes["B_T"]))
    others = {k: v for k, v in other_axes.items() if k != "B_T"}
    if "gradB_T_per_m" in table.axes and "gradB_T_per_m" not in others:
        others["gradB_T_per_m"] = table.axes["gradB_T_per_m"][0]
    attr = {"mean": "mean", "low": "ci_low", "high": "ci_high"}[bound]
    M = [getattr(interpolate(table, "M_eff_A_per_m", component="z", phi=phi, B_T=b, **others),
                 attr) for b in B]
    return B, np.maximum(np.asarray(M, float), 0.0)


def magnetization_from_table(table, phi: float, *, bound: str = "mean", **other_axes):
    """The composite's ``M_eff(H)`` [A/m] from a batch table at ``phi``, for the macro solvers.

    The table's RVEs have a metallic boundary, so its ``B_T`` axis is ``mu0 H`` of the field
    inside the specimen; ``M_eff`` (z component, along the field) is interpolated in the table
    and linearly between its ``B_T`` values, with ``M(0) = 0``. Fields beyond the table's largest
    ``B_T`` are refused (:class:`micro.InputError`), never extrapolated. ``bound``: "mean",
    "low" or "high" (ends of the confidence interval of each grid value).
    """
    B, M = _table_M_nodes(table, phi, bound, other_axes)
    return tabulated_magnetization(np.concatenate([[0.0], B / MU0]), np.concatenate([[0.0], M]))


def magnetization_table_law(table, phi: float, *, bound: str = "mean", **other_axes):
    """The same nodes as :func:`magnetization_from_table` as a
    :class:`homogenize.macro.magnetostatics.TableLaw` (monotone cubic through ``(0, 0)`` and the
    nodes, with the slope Newton needs) for the specimen solver; the node at ``B_T = 0`` is
    dropped (the law passes through the origin). ``M_eff`` of a few random RVEs can dip between
    neighbouring fields by its sampling noise; the law takes the running maximum (a magnetization
    curve does not decrease), so such a dip is flattened, not refused."""
    from homogenize.macro.magnetostatics import TableLaw
    B, M = _table_M_nodes(table, phi, bound, other_axes)
    keep = B > 0.0
    return TableLaw(B[keep] / MU0, np.maximum.accumulate(M[keep]),
                    source=f"M_eff of the batch table at phi = {phi:g} ({bound})")


def soft_sphere_magnetization(phi: float, Ms_A_m: float = SEED.Ms_A_m):
    """``M_eff(H) = min(3 phi H / (1 - phi), phi Ms)``: demagnetization-limited soft spheres at
    volume fraction ``phi`` (Clausius-Mossotti for an infinite intrinsic susceptibility),
    capped at saturated particles. An analytic estimate where no table is at hand."""
    return linear_magnetization(3.0 * phi / (1.0 - phi), phi * Ms_A_m)
