"""Pictures of an RVE: particle surfaces as a trimesh mesh (PLY/GLB) and a PNG for reports.

Meshes are in metres (SI, like every file of the project). Each particle is an icosphere of
its outer radius; particles of the same cluster or chain share a colour, isolated particles
are grey. Particles that cross a face of the periodic box are drawn once, at their wrapped
centre (they stick out of the box on one side).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from micro.common.files import atomic_path
from micro.common.validate import InputError
from micro.rve import RVE

__all__ = ["rve_mesh", "rve_scene", "export_mesh", "save_picture"]

_GREY = np.array([170, 170, 170, 255], dtype=np.uint8)


def _colors(cluster_id: np.ndarray) -> np.ndarray:
    """RGBA (N, 4) uint8: grey for isolated particles, a stable colour per cluster id."""
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    out = np.tile(_GREY, (cluster_id.size, 1))
    grouped = cluster_id >= 0
    out[grouped] = (np.asarray(cmap(cluster_id[grouped] % 20)) * 255).round().astype(np.uint8)
    return out


def rve_mesh(rve: RVE, subdivisions: int | None = None):
    """One ``trimesh.Trimesh`` with an icosphere per particle (vertex colours by cluster).

    ``subdivisions`` of the icosphere defaults to 2 (320 triangles) up to 5000 particles and 1
    (80 triangles) above, to keep files viewable.
    """
    import trimesh

    if subdivisions is None:
        subdivisions = 2 if rve.n <= 5000 else 1
    unit = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v0 = np.asarray(unit.vertices)
    f0 = np.asarray(unit.faces)
    verts = (rve.centers_m[:, None, :] + rve.radii_m[:, None, None] * v0[None]).reshape(-1, 3)
    faces = (f0[None] + (np.arange(rve.n) * len(v0))[:, None, None]).reshape(-1, 3)
    colors = np.repeat(_colors(rve.cluster_id), len(v0), axis=0)
    return trimesh.Trimesh(vertices=verts, faces=faces, vertex_colors=colors, process=False)


def rve_scene(rve: RVE, subdivisions: int | None = None):
    """A ``trimesh.Scene``: the particle mesh (:func:`rve_mesh`) and the 12 box edges [m]."""
    import trimesh

    L = rve.box_m
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float) * L
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8)
             if np.count_nonzero(corners[a] != corners[b]) == 1]
    # Built directly (load_path would merge vertices closer than trimesh's 1e-8 tolerance,
    # i.e. the whole nanometre-scale box).
    box = trimesh.path.Path3D(entities=[trimesh.path.entities.Line(np.array(p)) for p in pairs],
                              vertices=corners, process=False)
    return trimesh.Scene({"particles": rve_mesh(rve, subdivisions), "box": box})


def export_mesh(rve: RVE, path) -> Path:
    """Write the particle surfaces to ``path`` atomically: .ply (particle mesh) or .glb (scene
    with particles and box edges), metres."""
    path = Path(path)
    kind = path.suffix.lower().lstrip(".")
    if kind not in ("ply", "glb"):
        raise InputError(f"mesh file {path} must end in .ply or .glb")
    if kind == "glb":
        data = rve_scene(rve).export(file_type="glb")
    else:
        data = rve_mesh(rve).export(file_type="ply")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def _slice_circles(rve: RVE, axis: int, level_m: float):
    """Cross-sections of the particles with the plane x[axis] = level (periodic).

    Returns (centres (k, 2) in the plane, radii (k,), cluster ids (k,)) including the periodic
    images needed to draw circles that cross the picture edges.
    """
    d = rve.centers_m[:, axis] - level_m
    d = rve.minimum_image(d)
    hit = np.abs(d) < rve.radii_m
    rc = np.sqrt(rve.radii_m[hit] ** 2 - d[hit] ** 2)
    other = [k for k in range(3) if k != axis]
    xy = rve.centers_m[hit][:, other]
    cid = rve.cluster_id[hit]
    L = rve.box_m
    parts_xy, parts_r, parts_c = [], [], []
    for sx in (-L, 0.0, L):
        for sy in (-L, 0.0, L):
            q = xy + np.array([sx, sy])
            keep = ((q[:, 0] + rc > 0) & (q[:, 0] - rc < L) & (q[:, 1] + rc > 0)
                    & (q[:, 1] - rc < L))
            parts_xy.append(q[keep])
            parts_r.append(rc[keep])
            parts_c.append(cid[keep])
    return np.concatenate(parts_xy), np.concatenate(parts_r), np.concatenate(parts_c)


def save_picture(rve: RVE, path, distribution=None) -> Path:
    """PNG of the RVE: a 3D view, a mid-plane slice (true cross-sections) and the radius
    histogram (with the requested distribution's density if given). Written atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PatchCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"picture file {path} must end in .png")
    nm = 1e9
    L = rve.box_m * nm
    fig = Figure(figsize=(13, 4.4))
    FigureCanvasAgg(fig)
    colors = _colors(rve.cluster_id) / 255.0

    ax = fig.add_subplot(1, 3, 1, projection="3d")
    # Marker area ~ radius^2, scaled for a box that spans about 150 points on screen.
    size = (rve.radii_m * nm / L * 150.0) ** 2 * np.pi
    c = rve.centers_m * nm
    ax.scatter(c[:, 0], c[:, 1], c[:, 2], s=size, c=colors, depthshade=True, linewidths=0)
    for lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        lim(0, L)
    ax.set_xlabel("x [nm]")
    ax.set_ylabel("y [nm]")
    ax.set_zlabel("z [nm]")
    ax.set_title(f"N = {rve.n}, phi = {rve.phi:.4g}, L = {L:.4g} nm", fontsize=9)

    ax = fig.add_subplot(1, 3, 2)
    # Slice across z, or for chains along the plane that contains their axis best.
    axis = 2
    if rve.params.get("arrangement") == "chains":
        axis = int(np.argmin(np.abs(np.asarray(rve.params.get("chain_direction", (0, 0, 1))))))
    xy, rc, cid = _slice_circles(rve, axis, 0.5 * rve.box_m)
    names = [n for k, n in enumerate("xyz") if k != axis]
    patches = [Circle(tuple(p * nm), r * nm) for p, r in zip(xy, rc)]
    ax.add_collection(PatchCollection(patches, facecolor=_colors(cid) / 255.0,
                                      edgecolor="k", linewidth=0.3))
    ax.add_patch(Rectangle((0, 0), L, L, fill=False, edgecolor="k", linewidth=1))
    ax.set_xlim(0, L)
    ax.set_ylim(0, L)
    ax.set_aspect("equal")
    ax.set_xlabel(f"{names[0]} [nm]")
    ax.set_ylabel(f"{names[1]} [nm]")
    ax.set_title(f"slice {'xyz'[axis]} = L/2 (periodic)", fontsize=9)

    ax = fig.add_subplot(1, 3, 3)
    r = rve.radii_m * nm
    bins = np.linspace(r.min(), r.max(), 31) if np.ptp(r) > 0 else 10
    ax.hist(r, bins=bins, density=True, color="0.6", label="drawn radii")
    if distribution is not None and np.ptp(r) > 0:
        rr = np.linspace(r.min(), r.max(), 400)
        pdf = np.gradient(distribution.cdf(rr / nm), rr)
        ax.plot(rr, pdf, "k-", label="requested")
    if (rve.core_radii_m != rve.radii_m).any():
        ax.hist(rve.core_radii_m * nm, bins=30, density=True, histtype="step", color="C3",
                label="core radii")
    ax.set_xlabel("radius [nm]")
    ax.set_ylabel("probability density [1/nm]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path
