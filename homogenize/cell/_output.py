"""Local fields of a cell solution: VTU / PVD for ParaView (meshio) and a PNG slice figure.

Symmetric tensors are written in VTK's component order XX, YY, ZZ, XY, YZ, XZ (not Voigt's
xx, yy, zz, yz, xz, xy), with component names, so ParaView labels them right.
"""
from __future__ import annotations

import numpy as np

from micro.common.files import atomic_path

from homogenize.voxels import _assembly as asm

__all__ = ["local_fields", "write_vtu", "write_pvd", "all_cases", "plot_slice",
           "VTK_TENSOR_ORDER", "VTK_COMPONENT_NAMES"]


def local_fields(result, case: str = "magnetic") -> dict:
    """Voxel fields of one load case: stress (n, n, n, 3, 3) [Pa], von Mises (n, n, n) [Pa],
    nodal displacement (n, n, n, 3) [m] (total: affine + fluctuation), phase fraction."""
    from homogenize.cell.problem import CASES, voigt_to_tensor
    if case not in result.fields:
        raise KeyError(f"no field for load case {case!r}; run with keep_fields=True")
    mesh = result.mesh
    n, h = mesh.n, mesh.h_m
    w = result.fields[case]
    E = np.zeros((3, 3)) if case == "magnetic" else \
        voigt_to_tensor(np.eye(6)[CASES.index(case)], engineering=True)
    eps = asm.element_mean_strain(w.ravel(), n, h) + E
    sig = asm.element_stress(result.fields["lambda_Pa"], result.fields["mu_Pa"], eps)
    if "cut_voxels" in result.fields:
        # composite voxels: the stress of the stiffness the solver used in each cut voxel
        vox, C = result.fields["cut_voxels"], result.fields["cut_voxel_C_Pa"]
        e = eps.reshape(-1, 3, 3)[vox]
        ev = np.stack([e[:, 0, 0], e[:, 1, 1], e[:, 2, 2], 2 * e[:, 1, 2], 2 * e[:, 0, 2],
                       2 * e[:, 0, 1]], axis=1)
        s = np.einsum("vij,vj->vi", C, ev)
        S = sig.reshape(-1, 3, 3)
        S[vox] = np.stack([np.stack([s[:, 0], s[:, 5], s[:, 4]], axis=1),
                           np.stack([s[:, 5], s[:, 1], s[:, 3]], axis=1),
                           np.stack([s[:, 4], s[:, 3], s[:, 2]], axis=1)], axis=1)
    dev = sig - np.trace(sig, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    vm = np.sqrt(1.5 * np.sum(dev * dev, axis=(-2, -1)))
    return {"stress_Pa": sig, "von_mises_Pa": vm, "displacement_m": w, "strain": eps,
            "fraction": mesh.fraction, "owner": mesh.owner, "mean_strain": E}


#: VTK's order of the six components of a symmetric tensor (what ParaView labels XX ... XZ)
VTK_TENSOR_ORDER = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
VTK_COMPONENT_NAMES = ("XX", "YY", "ZZ", "XY", "YZ", "XZ")
#: units of the arrays written to the VTU files (also stored in the file as field data ``units``)
VTU_UNITS = {"points": "m", "displacement_m": "m", "stress_Pa": "Pa", "von_mises_Pa": "Pa",
             "particle_fraction": "1", "particle_id": "1", "mean_strain": "1", "B_T": "T",
             "gradB_T_per_m": "T/m", "h_m": "m", "box_m": "m"}


def all_cases(result) -> tuple:
    """Load cases of ``result`` with stored fields: the unit strains, then ``magnetic``."""
    from homogenize.cell.problem import CASES
    return tuple(c for c in CASES + ("magnetic",) if c in result.fields)


def _text(s: str) -> np.ndarray:
    """A string as field data: its UTF-8 bytes (``bytes(a).decode()`` reads it back)."""
    return np.frombuffer(str(s).encode(), dtype=np.uint8).copy()


def _vec3(name, v, unit):
    from micro.common.validate import InputError
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.size == 1:
        a = np.array([0.0, 0.0, float(a[0])])
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be a finite scalar or 3-vector [{unit}], got {v!r}")
    return a


def write_vtu(path, result, case: str = "magnetic", *, B_T=None, gradB_T_per_m=None,
              law: str | None = None) -> None:
    """Hexahedral VTU of one load case of the cell (nodes on the closed (n+1)^3 grid, periodic
    values copied).

    Arrays: point data ``displacement_m`` (total: affine + fluctuation) [m]; cell data
    ``stress_Pa`` [Pa] as a 6-component symmetric tensor in VTK order XX, YY, ZZ, XY, YZ, XZ
    (with ``ComponentName`` attributes, so ParaView labels them right), ``von_mises_Pa`` [Pa],
    ``particle_fraction``, ``particle_id``. Field data: ``load_case`` and ``law`` (UTF-8 bytes,
    ``bytes(a).decode()``), ``load_case_index`` (0..5 = e11, e22, e33, g23, g13, g12; 6 =
    magnetic), ``mean_strain`` (3, 3) [1] applied, ``B_T`` (3,) [T] and ``gradB_T_per_m`` (3,)
    [T/m] of the magnetic state (only if given), ``voxels``, ``h_m``, ``box_m`` [m], and
    ``units`` (``name: unit; ...`` for every array).

    Parameters
    ----------
    path : path -- output ``.vtu``
    result : CellResult -- computed with ``keep_fields=True``
    case : str -- one of :func:`all_cases` ``(result)``
    B_T : float or array_like, shape (3,), optional -- applied flux density [T] (a scalar
        is along z)
    gradB_T_per_m : float or array_like, shape (3,), optional -- field gradient dB_z/dx_i [T/m]
    law : str, optional -- magnetization law of the particles
    """
    import meshio
    from homogenize.cell.problem import CASES

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
        "stress_Pa": [np.stack([sig[:, r, c] for r, c in VTK_TENSOR_ORDER], axis=1)],
    }
    field_data = {
        "load_case": _text(case),
        "load_case_index": np.array([(CASES + ("magnetic",)).index(case)], dtype=np.int64),
        "law": _text(law or "none"),
        "mean_strain": np.asarray(fl["mean_strain"], dtype=np.float64).reshape(1, 9),
        "voxels": np.array([n], dtype=np.int64),
        "h_m": np.array([h], dtype=np.float64),
        "box_m": np.array([n * h], dtype=np.float64),
        "units": _text("; ".join(f"{k}: {v}" for k, v in VTU_UNITS.items())),
    }
    if B_T is not None:
        field_data["B_T"] = _vec3("B_T", B_T, "T")
    if gradB_T_per_m is not None:
        field_data["gradB_T_per_m"] = _vec3("gradB_T_per_m", gradB_T_per_m, "T/m")
    m = meshio.Mesh(pts, [("hexahedron", hexes)], point_data={"displacement_m": u},
                    cell_data=cell_data)
    with atomic_path(path) as tmp:
        meshio.write(str(tmp), m, file_format="vtu")
        _finish_xml(tmp, {"stress_Pa": VTK_COMPONENT_NAMES, "displacement_m": ("X", "Y", "Z")},
                    field_data)


_VTK_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.int64): "Int64",
              np.dtype(np.uint8): "UInt8"}


def _finish_xml(path, names: dict, field_data: dict) -> None:
    """Add ``ComponentName<k>`` attributes to the named DataArrays of a VTU file written by
    meshio, and a ``FieldData`` block (ASCII) before its ``Piece`` (meshio writes none)."""
    import xml.etree.ElementTree as ET
    tree = ET.parse(path)
    for da in tree.iter("DataArray"):
        comp = names.get(da.get("Name"))
        if comp:
            for k, c in enumerate(comp):
                da.set(f"ComponentName{k}", c)
    grid = tree.getroot().find("UnstructuredGrid")
    fd = ET.Element("FieldData")
    for name, arr in field_data.items():
        arr = np.asarray(arr)
        arr2 = arr.reshape(arr.shape[0], -1) if arr.ndim > 1 else arr.reshape(-1, 1)
        da = ET.SubElement(fd, "DataArray", type=_VTK_TYPES[arr.dtype], Name=name,
                           NumberOfTuples=str(arr2.shape[0]),
                           NumberOfComponents=str(arr2.shape[1]), format="ascii")
        da.text = " ".join(repr(float(v)) if arr.dtype.kind == "f" else str(int(v))
                           for v in arr2.ravel())
    grid.insert(0, fd)
    tree.write(path, xml_declaration=True, encoding="utf-8")


def write_pvd(path, result, cases=None, *, B_T=None, gradB_T_per_m=None,
              law: str | None = None) -> list:
    """All load cases as a ParaView collection: ``<stem>.pvd`` plus one ``<stem>_<case>.vtu``
    per case, next to it (see :func:`write_vtu` for the arrays).

    The collection's ``timestep`` is the load-case index (0..5 = e11 ... g12, 6 = magnetic), so
    ParaView's time control steps through the cases; each entry also carries ``name=<case>``.
    ``cases`` defaults to :func:`all_cases` ``(result)``. Returns the paths written, the
    ``.pvd`` first.
    """
    import xml.etree.ElementTree as ET
    from pathlib import Path
    from micro.common.validate import InputError
    from homogenize.cell.problem import CASES

    path = Path(path)
    available = all_cases(result)
    cases = available if cases is None else tuple(cases)
    if not cases:
        raise InputError("no load-case fields in the cell result: compute it with "
                         "keep_fields=True")
    for c in cases:
        if c not in available:
            raise InputError(f"load case {c!r} has no stored field; available: "
                             f"{', '.join(available) or 'none'}")
    written = [path]
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    coll = ET.SubElement(root, "Collection")
    for c in cases:
        vtu = path.with_name(f"{path.stem}_{c}.vtu")
        write_vtu(vtu, result, c, B_T=B_T, gradB_T_per_m=gradB_T_per_m, law=law)
        written.append(vtu)
        ET.SubElement(coll, "DataSet", timestep=str((CASES + ("magnetic",)).index(c)),
                      group="", part="0", name=c, file=vtu.name)
    ET.indent(root)
    with atomic_path(path) as tmp:
        ET.ElementTree(root).write(tmp, xml_declaration=True, encoding="utf-8")
    return written


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
