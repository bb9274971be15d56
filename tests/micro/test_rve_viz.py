"""Meshes and pictures of an RVE (micro/_viz.py)."""
import numpy as np
import pytest
import trimesh

from micro import InputError, generate_rve
from micro._viz import export_mesh, rve_mesh, save_picture


@pytest.fixture(scope="module")
def rve():
    return generate_rve(0.05, 60, 2, arrangement="chains", chain_length=3)


def test_mesh_spheres_match_particles(rve):
    mesh = rve_mesh(rve, subdivisions=3)
    per = len(mesh.vertices) // rve.n
    v = mesh.vertices.reshape(rve.n, per, 3)
    # Every vertex of sphere i lies on its surface.
    dist = np.linalg.norm(v - rve.centers_m[:, None, :], axis=2)
    np.testing.assert_allclose(dist, np.broadcast_to(rve.radii_m[:, None], dist.shape),
                               rtol=1e-12)
    # An icosphere of 3 subdivisions (1280 faces) encloses 99.3 % of the sphere volume
    # (inscribed polyhedron); total within 1 % of the particle volume.
    assert mesh.volume == pytest.approx(rve.particle_volumes_m3.sum(), rel=0.01)
    assert mesh.volume < rve.particle_volumes_m3.sum()


def test_export_reloads(tmp_path, rve):
    p = export_mesh(rve, tmp_path / "r.ply")
    back = trimesh.load(p, force="mesh")
    assert np.allclose(back.bounds, rve_mesh(rve).bounds, rtol=1e-6)
    scene = trimesh.load(export_mesh(rve, tmp_path / "r.glb"))
    geoms = list(scene.geometry.values())
    mesh = [g for g in geoms if isinstance(g, trimesh.Trimesh)][0]
    box = [g for g in geoms if isinstance(g, trimesh.path.Path3D)][0]
    assert np.allclose(mesh.bounds, rve_mesh(rve).bounds, rtol=1e-6)
    # The 12 edges of the periodic cube.
    np.testing.assert_allclose(box.bounds, [[0, 0, 0], [rve.box_m] * 3], atol=1e-6 * rve.box_m)
    # The file stores 12 segments (GL "LINES", vertex pairs), each one box edge long.
    seg = np.asarray(box.vertices).reshape(12, 2, 3)
    np.testing.assert_allclose(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1), rve.box_m,
                               rtol=1e-6)


def test_picture_and_bad_names(tmp_path, rve):
    p = save_picture(rve, tmp_path / "r.png")
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(InputError, match="png"):
        save_picture(rve, tmp_path / "r.jpg")
    with pytest.raises(InputError, match="ply or .glb"):
        export_mesh(rve, tmp_path / "r.obj")
