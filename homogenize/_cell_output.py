"""Local fields of a cell solution: VTU for ParaView (meshio) and a PNG slice figure."""
from __future__ import annotations

import numpy as np

from micro._io import atomic_path

from . import _assembly as asm

__all__ = ["local_fields", "write_vtu", "plot_slice"]


def local_fields(result, case: str = "magnetic") -> dict:
    """Voxel fields of one load case: stress (n, n, n, 3, 3) [Pa], von Mises (n, n, n) [Pa],
    nodal displacement (n, n, n, 3) [m] (total: affine + fluctuation), phase fraction."""
    from .cell import CASES, voigt_to_tensor
    if case not in result.fields:
        raise KeyError(f"no field for load case {case!r}; run with keep_fields=True")
    mesh = result.mesh
    n, h = mesh.n, mesh.h_m
    w = result.fields[case]
    E = np.zeros((3, 3)) if case == "magnetic" else \
        voigt_to_tensor(np.eye(6)[CASES.index(case)], engineering=True)
    eps = asm.element_mean_strain(w.ravel(), n, h) + E
    sig = asm.element_stress(result.fields["lambda_Pa"], result.fields["mu_Pa"], eps)
    dev = sig - np.trace(sig, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    vm = np.sqrt(1.5 * np.sum(dev * dev, axis=(-2, -1)))
    return {"stress_Pa": sig, "von_mises_Pa": vm, "displacement_m": w, "strain": eps,
            "fraction": mesh.fraction, "owner": mesh.owner, "mean_strain": E}


def write_vtu(path, result, case: str = "magnetic") -> None:
    """Hexahedral VTU of the cell (nodes on the closed (n+1)^3 grid, periodic values copied)."""
    import meshio

    fl = local_fields(result, case)
    mesh = result.mesh
    n, h = mesh.n, mesh.h_m
    g = np.arange(n + 1)
    K, J, I = np.meshgrid(g, g, g, indexing="ij")
    pts = np.stack([I.ravel(), J.ravel(), K.ravel()], axis=1) * h
    per = (I % n).ravel() + n * ((J % n).ravel() + n * (K % n).ravel())
    u = fl["displacement_m"].reshape(-1, 3)[per] + pts @ fl["mean_strain"].T
    k, j, i = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    nid = lambda a, b, c: (i + a) + (n + 1) * ((j + b) + (n + 1) * (k + c))  # noqa: E731
    hexes = np.stack([nid(0, 0, 0), nid(1, 0, 0), nid(1, 1, 0), nid(0, 1, 0),
                      nid(0, 0, 1), nid(1, 0, 1), nid(1, 1, 1), nid(0, 1, 1)], axis=1)
    sig = fl["stress_Pa"].reshape(-1, 3, 3)
    cell_data = {
        "particle_fraction": [fl["fraction"].ravel()],
        "particle_id": [fl["owner"].ravel().astype(np.int64)],
        "von_mises_Pa": [fl["von_mises_Pa"].ravel()],
        "stress_Pa": [np.stack([sig[:, r, c] for r, c in asm.VOIGT], axis=1)],
    }
    m = meshio.Mesh(pts, [("hexahedron", hexes)], point_data={"displacement_m": u},
                    cell_data=cell_data)
    with atomic_path(path) as tmp:
        meshio.write(str(tmp), m, file_format="vtu")


def plot_slice(path, result, case: str = "magnetic", axis: int = 2, index: int | None = None) -> None:
    """PNG: particle phase, von Mises stress and displacement magnitude on one voxel slice."""
    import matplotlib
    from matplotlib.figure import Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fl = local_fields(result, case)
    n = result.mesh.n
    index = n // 2 if index is None else int(index)
    take = lambda a: np.take(a, index, axis=2 - axis)  # noqa: E731  (arrays are [k, j, i])
    umag = np.linalg.norm(fl["displacement_m"], axis=-1)
    L_um = result.mesh.box_m * 1e6
    fig = Figure(figsize=(12, 3.8))
    FigureCanvasAgg(fig)
    panels = ((take(fl["fraction"]), "particle fraction [1]", "gray_r"),
              (take(fl["von_mises_Pa"]), "von Mises stress [Pa]", "viridis"),
              (take(umag), "|u - E x| [m]", "magma"))
    names = "xyz"
    for ax_i, (img, title, cmap) in enumerate(panels):
        ax = fig.add_subplot(1, 3, ax_i + 1)
        im = ax.imshow(img, origin="lower", extent=(0, L_um, 0, L_um), cmap=matplotlib.colormaps[cmap])
        ax.set_title(title, fontsize=9)
        other = [c for c in range(3) if c != axis]
        ax.set_xlabel(f"{names[other[0]]} [um]")
        ax.set_ylabel(f"{names[other[1]]} [um]")
        fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(f"load case {case}, slice {names[axis]} = {(index + 0.5) / n * L_um:.3g} um", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
