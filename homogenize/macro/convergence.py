"""Mesh-converged tip deflection of the cantilever, with a Richardson discretization-error
estimate from two nested meshes.

:func:`converged_tip` solves the linear 3D FEM problem of
:func:`homogenize.macro.cantilever.solve_cantilever` on a coarse mesh and on the same mesh
refined ``refine`` times in every direction (explicit ``divisions``; the half-width model),
and returns the fine-mesh tip deflection, the Richardson estimate of its discretization error

    e = (u_fine - u_coarse) / (refine**p - 1),

the extrapolated value ``u_fine + e``, and both meshes. ``p`` is the convergence rate of the
tip deflection under uniform refinement. It is not the smooth-solution rate of P2 elements
(3 for a point value): the fully clamped root has an edge singularity of the 3D elastic
field that sets the rate. Measured on the seed strip (19.369 x 5 x 1 mm, E = 2 MPa,
nu = 0.45, 40 kN/m^3, P2, half width, divisions (13, 2, 1) x 2^k, k = 0..2: tips 3.7349,
3.9310, 3.9792 mm): p = 2.03, :data:`MEASURED_RATE` = 2 (tests/homogenize/macro/
test_convergence.py measures it again). CalculiX C3D20R on (20, 4, 2) x 2^k (full width:
3.9385, 3.9859, 3.9954 mm; p = 2.3) extrapolates to 3.9977 mm, the P2 pair below to 3.9970 mm.

Default meshes (:func:`default_divisions`): coarse ``beam_divisions(half strip, nz=2,
aspect=1.25)``, fine twice as many divisions. For the seed strip that is (31, 4, 2) and
(62, 8, 4): fine tip 3.9841 mm, 0.33 % below the converged 3.997 mm, Richardson estimate
+0.0129 mm (57 k dofs on the fine mesh). ``solve_cantilever``'s own default mesh
(``nz=2, aspect=3``: (13, 2, 2)) gives 3.8161 mm, 4.5 % low.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from homogenize.macro.cantilever import Strip, beam_divisions, solve_cantilever
from homogenize.macro.fem import Material
from micro.common.validate import InputError, check_positive

__all__ = ["ConvergedTip", "converged_tip", "default_divisions", "observed_rate", "MEASURED_RATE",
           "DEFAULT_NZ", "DEFAULT_ASPECT"]

#: observed rate p of the P2 tip deflection under uniform refinement (seed strip, see above)
MEASURED_RATE = 2.0
#: layers through the thickness and element aspect of the default coarse mesh
DEFAULT_NZ = 2
DEFAULT_ASPECT = 1.25


@dataclass(frozen=True)
class ConvergedTip:
    """Tip deflection [m] on the fine mesh, its Richardson error estimate [m] (signed: add it
    to ``tip_m`` to extrapolate), the extrapolated value [m], the rate used, and the meshes
    ``((divisions, tip_m, n_dof), ...)`` coarse first."""
    tip_m: float
    error_estimate_m: float
    extrapolated_m: float
    rate: float
    refine: int
    meshes: tuple

    @property
    def rel_error_estimate(self) -> float:
        return abs(self.error_estimate_m) / abs(self.extrapolated_m) if self.extrapolated_m \
            else 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["rel_error_estimate"] = self.rel_error_estimate
        return d


def default_divisions(strip: Strip, *, half: bool = True, nz: int = DEFAULT_NZ,
                      aspect: float = DEFAULT_ASPECT) -> tuple[int, int, int]:
    """Coarse mesh of :func:`converged_tip`: :func:`beam_divisions` of the modelled strip (half
    the width with ``half``) with ``nz`` layers and element aspect ``aspect``."""
    modelled = Strip(strip.length_m, strip.width_m / 2, strip.thickness_m) if half else strip
    return beam_divisions(modelled, nz, aspect)


def converged_tip(strip: Strip, material: Material, f_N_m3: float, *, divisions=None,
                  refine: int = 2, rate: float = MEASURED_RATE, order: int = 2,
                  gravity_m_s2: float = 0.0, half: bool = True, clamp: str = "full",
                  solver: str = "auto") -> ConvergedTip:
    """Tip deflection of the clamped strip on two nested meshes, with a Richardson estimate.

    Parameters
    ----------
    strip : Strip -- geometry [m]
    material : Material -- E [Pa], nu, density [kg/m^3]
    f_N_m3 : float -- body force along -z [N/m^3], >= 0
    divisions : (nx, ny, nz) or None -- the coarse mesh (hexahedra, 6 tetrahedra each; ``ny``
        across the modelled width); None: :func:`default_divisions`
    refine : int >= 2 -- the fine mesh has ``refine`` times the divisions in every direction
    rate : float > 0 -- convergence rate p of the tip deflection (:data:`MEASURED_RATE`)
    order, gravity_m_s2, half, clamp, solver : as in :func:`solve_cantilever` (model "fem")

    Returns
    -------
    ConvergedTip: ``tip_m`` is the fine-mesh value (what ``solve_cantilever`` gives on that
    mesh), ``error_estimate_m = (u_fine - u_coarse) / (refine**rate - 1)``.
    """
    refine = int(check_positive("refine", refine, ""))
    if refine < 2:
        raise InputError(f"refine must be an integer >= 2 (fine mesh = refine x coarse), got "
                         f"{refine}")
    rate = check_positive("rate", rate, "")
    coarse = default_divisions(strip, half=half) if divisions is None else \
        tuple(int(d) for d in divisions)
    if len(coarse) != 3 or min(coarse) < 1:
        raise InputError(f"divisions must be three positive integers (nx, ny, nz), got "
                         f"{divisions!r}")
    fine = tuple(refine * d for d in coarse)
    runs = []
    for div in (coarse, fine):
        r = solve_cantilever(strip, material, f_N_m3, model="fem", order=order, divisions=div,
                             gravity_m_s2=gravity_m_s2, half=half, clamp=clamp, solver=solver)
        runs.append((div, r.tip_m, r.n_dof))
    uc, uf = runs[0][1], runs[1][1]
    err = (uf - uc) / (refine ** rate - 1.0)
    return ConvergedTip(float(uf), float(err), float(uf + err), float(rate), refine,
                        tuple(runs))


def observed_rate(tips, refine: int = 2) -> float:
    """Rate p from three tips on meshes refined by ``refine`` each time:
    ``log((u1 - u0) / (u2 - u1)) / log(refine)``."""
    u0, u1, u2 = (float(t) for t in tips)
    return float(np.log((u1 - u0) / (u2 - u1)) / np.log(refine))
