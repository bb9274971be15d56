"""Files of a specimen run (:func:`homogenize.macro.specimen.solve_specimen`): the deformed
mechanics mesh as VTU (ParaView, meshio) and the figure of the strains against the field.

The VTU holds the half meridian section ``r >= 0`` (the computed quarter ``z >= 0`` mirrored
about the mid-plane) in the plane ``y = 0`` of Cartesian coordinates (x = r, z along the
field), as quadratic triangles (VTK ``triangle6``, the P2 nodes of the mechanics solve) at
their DEFORMED positions; ParaView's "Rotational Extrusion" about z gives the body of
revolution. Point data: ``displacement_m`` (u_r, 0, u_z) [m] (reference position = point -
displacement) and ``mean_stress_Pa`` [Pa], the material's Cauchy mean stress (the u-p
pressure field, positive in tension, without the magnetic stress; linear in each element, its
P1 values interpolated to the edge nodes).

A 3D specimen (``geometry="3d"``, :func:`specimen_vtu_arrays_3d`): the whole body, the computed
octant ``x, y, z >= 0`` mirrored about its three symmetry planes (nodes on a plane shared), as
quadratic tetrahedra (VTK ``tetra10``: vertices 0-3, then the midside nodes of the edges (0, 1),
(1, 2), (0, 2), (0, 3), (1, 3), (2, 3), matched here to the P2 nodes by position, every
tetrahedron with a positive volume) at their DEFORMED positions; point data ``displacement_m``
(u_x, u_y, u_z) [m] and ``mean_stress_Pa`` as above. A body mechanics mesh without symmetry
planes (the supported specimen) is written as it is.
"""
from __future__ import annotations

import numpy as np

from homogenize.cell._output import _finish_xml, _text
from micro.common.files import atomic_path

__all__ = ["write_specimen_vtu", "specimen_vtu_arrays", "specimen_vtu_arrays_3d",
           "plot_specimen_strains", "SPECIMEN_VTU_UNITS"]

#: units of the arrays of the VTU (also stored in the file as field data ``units``)
SPECIMEN_VTU_UNITS = {"points": "m (deformed)", "displacement_m": "m", "mean_stress_Pa": "Pa",
                      "B_applied_T": "T", "M_mean_A_per_m": "A/m"}

#: skfem's P2 triangle: vertices 0, 1, 2, then the midpoints of edges (0, 1), (1, 2), (0, 2)
#: -- the order of VTK's triangle6, whose third edge (2, 0) is the same edge
_EDGES = ((0, 1), (1, 2), (0, 2))


def specimen_vtu_arrays(solution, mirror: bool | None = None) -> dict:
    """The half section of an :class:`~homogenize.macro.finite_strain.AxisymmetricSolution`
    (its quarter mirrored about ``z = 0`` if ``mirror``, default: with mid-plane symmetry; a
    specimen on a plate is a whole section solved with its plate as the plane ``z = 0``:
    ``mirror=False``): ``points`` (N, 3) deformed [m], ``triangle6`` (ne, 6) node indices,
    ``displacement_m`` (N, 3) [m], ``mean_stress_Pa`` (N,) [Pa]."""
    basis = solution.basis
    P = np.asarray(solution.doflocs_m)                  # (2, N) reference (r, z)
    U = np.asarray(solution.u_m)                        # (2, N)
    dofs = np.asarray(basis.element_dofs)               # (6, ne)
    nv = solution.body.mesh.p.shape[1]
    # the pressure (P1) at the P2 nodes: vertices as solved, edge nodes the mean of the ends
    p = np.empty(P.shape[1])
    p[:nv] = solution.p_Pa
    for k, (a, b) in enumerate(_EDGES):
        p[dofs[3 + k]] = 0.5 * (p[dofs[a]] + p[dofs[b]])
    tri = dofs.T.copy()
    if solution.body.mid_plane if mirror is None else mirror:
        # mirror about z = 0: nodes on the mid-plane are shared
        on = P[1] == 0.0
        n = P.shape[1]
        new = np.flatnonzero(~on)
        index = np.arange(n)
        index[new] = n + np.arange(new.size)
        P = np.hstack([P, P[:, new] * np.array([[1.0], [-1.0]])])
        U = np.hstack([U, U[:, new] * np.array([[1.0], [-1.0]])])
        p = np.concatenate([p, p[new]])
        tri = np.vstack([tri, index[tri]])
    # every triangle counter-clockwise in the (x, z) plane (the solver's mesh mixes both):
    # a clockwise one swaps vertices 1 <-> 2 and so edges (0, 1) <-> (0, 2)
    x = P[:, tri[:, :3]]
    area2 = ((x[0, :, 1] - x[0, :, 0]) * (x[1, :, 2] - x[1, :, 0])
             - (x[1, :, 1] - x[1, :, 0]) * (x[0, :, 2] - x[0, :, 0]))
    tri[area2 < 0] = tri[area2 < 0][:, [0, 2, 1, 5, 4, 3]]
    pts = np.stack([P[0] + U[0], np.zeros(P.shape[1]), P[1] + U[1]], axis=1)
    disp = np.stack([U[0], np.zeros(P.shape[1]), U[1]], axis=1)
    return {"points": pts, "triangle6": tri.astype(np.int64), "displacement_m": disp,
            "mean_stress_Pa": p}


#: VTK's tetra10: the midside node k (4..9) sits on the edge _TET10_EDGES[k - 4]
_TET10_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
#: the same tetrahedron with vertices 1 and 2 swapped (opposite orientation), in VTK's order
_TET10_FLIP = [0, 2, 1, 3, 6, 5, 4, 7, 9, 8]


def _tet10_connectivity(P, dofs) -> np.ndarray:
    """(ne, 10) node indices in VTK's tetra10 order from the P2 element dofs ``dofs`` (10, ne)
    at positions ``P`` (3, N): the midside node of each VTK edge found by position (whatever
    the element's local edge numbering)."""
    dofs = np.asarray(dofs)
    v = dofs[:4].T                                          # (ne, 4)
    e = dofs[4:].T                                          # (ne, 6)
    Pe = P[:, e]                                            # (3, ne, 6)
    out = np.empty((dofs.shape[1], 10), dtype=np.int64)
    out[:, :4] = v
    for k, (a, b) in enumerate(_TET10_EDGES):
        mid = 0.5 * (P[:, v[:, a]] + P[:, v[:, b]])         # (3, ne)
        d = np.sum((Pe - mid[:, :, None]) ** 2, axis=0)     # (ne, 6)
        out[:, 4 + k] = e[np.arange(e.shape[0]), np.argmin(d, axis=1)]
    return out


def _tet_volumes(P, tet):
    """Signed volumes [m^3] of the straight tetrahedra of the vertices ``tet[:, :4]``."""
    x = P[:, tet[:, :4]]                                     # (3, ne, 4)
    return np.einsum("ie,ie->e", x[:, :, 1] - x[:, :, 0],
                     np.cross(x[:, :, 2] - x[:, :, 0], x[:, :, 3] - x[:, :, 0], axis=0)) / 6.0


def specimen_vtu_arrays_3d(solution) -> dict:
    """The whole body of a :class:`~homogenize.macro.finite_strain.Solution3D`: its mesh
    mirrored about the symmetry planes of ``solution.body.symmetry`` (``x_i = 0``; the
    displacement's ``i`` component changes sign in the image). ``points`` (N, 3) deformed [m],
    ``tetra10`` (ne, 10) node indices (VTK order, positive volume), ``displacement_m`` (N, 3)
    [m], ``mean_stress_Pa`` (N,) [Pa]."""
    basis = solution.basis
    P = np.asarray(solution.doflocs_m, float)               # (3, N) reference
    U = np.asarray(solution.u_m, float)                     # (3, N)
    dofs = np.asarray(basis.element_dofs)                   # (10, ne)
    nv = solution.body.mesh.p.shape[1]
    tet = _tet10_connectivity(P, dofs)
    p = np.empty(P.shape[1])
    p[:nv] = solution.p_Pa
    for k, (a, b) in enumerate(_TET10_EDGES):
        p[tet[:, 4 + k]] = 0.5 * (p[tet[:, a]] + p[tet[:, b]])
    size = float(np.abs(P).max())
    for axis, sym in enumerate(solution.body.symmetry):
        if not sym:
            continue
        on = np.abs(P[axis]) <= 1e-12 * size
        n = P.shape[1]
        new = np.flatnonzero(~on)
        index = np.arange(n)
        index[new] = n + np.arange(new.size)
        flip = np.ones((3, 1))
        flip[axis] = -1.0
        P = np.hstack([P, P[:, new] * flip])
        U = np.hstack([U, U[:, new] * flip])
        p = np.concatenate([p, p[new]])
        tet = np.vstack([tet, index[tet]])
    # a mirror image turns a tetrahedron inside out (and the solver's mesh may mix both)
    neg = _tet_volumes(P, tet) < 0
    tet[neg] = tet[neg][:, _TET10_FLIP]
    return {"points": (P + U).T.copy(), "tetra10": tet, "displacement_m": U.T.copy(),
            "mean_stress_Pa": p}


def write_specimen_vtu(path, result) -> None:
    """Write the last field step of a :class:`~homogenize.macro.specimen.SpecimenResult` as a
    VTU (module docstring for the arrays). Field data: ``B_applied_T``, ``M_mean_A_per_m``,
    ``model``, ``law``, ``shape``, ``configuration`` (text as UTF-8 bytes,
    ``bytes(a).decode()``) and ``units``."""
    import meshio

    if result.solution is None:
        raise ValueError("the result holds no mechanics solution (no field step was solved)")
    three_d = getattr(result.specimen, "geometry", "axisymmetric") == "3d"
    if three_d:
        a = specimen_vtu_arrays_3d(result.solution)
        cells = [("tetra10", a["tetra10"])]
        sym = result.solution.body.symmetry
        config = ("deformed; the whole body (the computed part x, y, z >= 0 mirrored about the "
                  "symmetry planes)" if all(sym) else "deformed; the whole body") \
            + ", field along z"
    elif result.setup:
        a = specimen_vtu_arrays(result.solution, mirror=False)
        cells = [("triangle6", a["triangle6"])]
        config = ("deformed; half meridian section r >= 0 in the plane y = 0, the bottom face "
                  f"at z = 0 (support: {result.setup.get('support')}), the magnet below; "
                  "rotate about z for the body")
    else:
        a = specimen_vtu_arrays(result.solution)
        cells = [("triangle6", a["triangle6"])]
        config = ("deformed; half meridian section r >= 0 in the plane y = 0, field along z; "
                  "rotate about z for the body")
    last = result.steps[-1]
    field_data = {
        "B_applied_T": np.array([last.B_applied_T], dtype=np.float64),
        "M_mean_A_per_m": np.array([last.M_mean_A_per_m], dtype=np.float64),
        "model": _text(result.model), "law": _text(result.law),
        "shape": _text(result.specimen.shape),
        "configuration": _text(config),
        "units": _text("; ".join(f"{k}: {v}" for k, v in SPECIMEN_VTU_UNITS.items())),
    }
    for key in ("gap_m", "reaction_N"):
        if hasattr(last, key):
            field_data[key] = np.array([getattr(last, key)], dtype=np.float64)
    m = meshio.Mesh(a["points"], cells,
                    point_data={"displacement_m": a["displacement_m"],
                                "mean_stress_Pa": a["mean_stress_Pa"]})
    with atomic_path(path) as tmp:
        meshio.write(str(tmp), m, file_format="vtu")
        _finish_xml(tmp, {"displacement_m": ("X", "Y", "Z")}, field_data)


def plot_specimen_strains(result_dict: dict):
    """Figure of the strains [%] against the applied field mu0 H0 [T] from
    :meth:`SpecimenResult.to_dict` (returns a matplotlib Figure; the caller saves it)."""
    from matplotlib.figure import Figure      # lazy: only for plotting
    steps = result_dict["steps"]
    B = np.array([s["B_applied_T"] for s in steps])

    def col(key):
        return 100.0 * np.array([np.nan if s[key] is None else s[key] for s in steps], float)

    spec = result_dict["specimen"]
    fig = Figure(figsize=(7.0, 4.4), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(B, col("strain_axis"), "o-", label="end to end on the axis")
    end = col("strain_end_mean")
    if np.any(np.isfinite(end)):
        ax.plot(B, end, "s--", label="between the end-face means")
    ax.plot(B, col("mean_strain_zz"), "^-", label="volume mean (axial)")
    ax.plot(B, col("lateral_strain"), "v-", label="lateral (diameter at mid-height)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel(r"applied field $\mu_0 H_0$ [T]")
    ax.set_ylabel("strain [%]")
    shape = spec["shape"]
    geo = (f"R = {1e3 * spec['radius_m']:.3g} mm" if shape == "sphere" else
           f"L/D = {spec['aspect_ratio_L_over_D']:.3g}, D = {2e3 * spec['radius_m']:.3g} mm")
    if shape == "cylinder" and spec.get("edge_radius_m") is not None:
        geo += f", rim radius {1e3 * spec['edge_radius_m']:.3g} mm"
    G = result_dict["shear_modulus_Pa"]
    ax.set_title(f"{shape} ({geo}), model: {result_dict['model']}\n{result_dict['law']}, "
                 f"G = {G:.3g} Pa", fontsize=9)
    ax.legend(fontsize=8)
    return fig
