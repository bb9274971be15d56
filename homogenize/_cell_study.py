"""Effective Young's modulus against particle volume fraction: voxel FEM vs closed forms.

One sphere in the periodic cube (simple cubic array) at volume fractions up to 30 %, compared
with Eshelby's dilute estimate, Mori-Tanaka (= lower Hashin-Shtrikman bound for stiff spheres),
Guth-Gold and the upper HS bound. Shows where the estimates part.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ._effective_media import (bulk_shear, eshelby_dilute, guth_gold, hashin_shtrikman_bounds,
                               mori_tanaka, young_poisson)

__all__ = ["phi_study", "plot_phi_study"]


def phi_study(phis=(0.01, 0.05, 0.1, 0.2, 0.3), voxels: int = 24, *, matrix_E_Pa=2e6,
              matrix_nu=0.45, particle_E_Pa=211e9, particle_nu=0.29, progress=False) -> dict:
    """E_eff [Pa] of a simple cubic array of spheres by FEM and by the closed forms, per phi."""
    from .cell import homogenize_rve
    Km, Gm = bulk_shear(matrix_E_Pa, matrix_nu)
    Kp, Gp = bulk_shear(particle_E_Pa, particle_nu)
    rows = []
    it = phis
    if progress:
        from tqdm import tqdm
        it = tqdm(phis, desc="phi study", unit="phi", leave=False)
    for phi in it:
        a = (3.0 * phi / (4.0 * np.pi)) ** (1.0 / 3.0)
        rve = SimpleNamespace(box_m=1e-6, centers_m=np.full((1, 3), 0.5e-6), radii_m=np.array([a * 1e-6]))
        r = homogenize_rve(rve, voxels, matrix_E_Pa=matrix_E_Pa, matrix_nu=matrix_nu,
                           particle_E_Pa=particle_E_Pa, particle_nu=particle_nu)
        pv = r.phi_voxel
        hs = hashin_shtrikman_bounds(pv, Km, Gm, Kp, Gp)
        rows.append({
            "phi": phi, "phi_voxel": pv, "E_fem_Pa": r.E_eff_Pa, "anisotropy_index": r.anisotropy_index,
            "E_dilute_Pa": young_poisson(*eshelby_dilute(pv, Km, Gm, Kp, Gp))[0],
            "E_mori_tanaka_Pa": young_poisson(*mori_tanaka(pv, Km, Gm, Kp, Gp))[0],
            "E_guth_gold_Pa": float(guth_gold(pv, matrix_E_Pa)),
            "E_hs_upper_Pa": float(hs["E_upper_Pa"]), "iterations": r.iterations,
        })
    return {"voxels": voxels, "matrix_E_Pa": matrix_E_Pa, "matrix_nu": matrix_nu,
            "particle_E_Pa": particle_E_Pa, "particle_nu": particle_nu, "rows": rows}


def plot_phi_study(path, study: dict) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from micro._io import atomic_path
    rows = study["rows"]
    pv = np.array([r["phi_voxel"] for r in rows])
    Em = study["matrix_E_Pa"]
    fig = Figure(figsize=(6, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for key, lab, st in (("E_fem_Pa", f"voxel FEM ({study['voxels']}^3, SC array)", "ko-"),
                         ("E_dilute_Pa", "Eshelby dilute", "b--"),
                         ("E_mori_tanaka_Pa", "Mori-Tanaka = HS lower", "g-"),
                         ("E_guth_gold_Pa", "Guth-Gold", "r-.")):
        ax.plot(pv, np.array([r[key] for r in rows]) / Em, st, label=lab)
    ax.set_xlabel("particle volume fraction phi [1]")
    ax.set_ylabel("E_eff / E_matrix [1]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
