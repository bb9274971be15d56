"""``mapsim specimen`` end to end on coarse meshes: the JSON keys, the PNG, the VTU read back
with meshio (deformed half section of the body), refusals (exit 2, nothing written) and a
field-mechanics iteration that does not converge (exit 3, residual history, no file).

The physics (Lamb's sphere, the cylinder's virtual work) is tested in
tests/homogenize/macro/test_specimen.py; here only what the command adds."""
import json
import math

import numpy as np
import pytest

from homogenize.cli import main

R, L = 1e-3, 1.6e-3
# coarse meshes (seconds): --n-mesh 4 --n-boundary 24; the Froehlich-Kennelly composite with
# G = 1e5 Pa strains the cylinder by ~0.6 % at 0.8 T (converges in 2-3 staggered iterations)
CYL = ["specimen", "--shape", "cylinder", "--radius-m", str(R), "--length-m", str(L),
       "--law", "froehlich-kennelly", "--chi0", "2", "--Ms-A-per-m", "1e5",
       "--shear-modulus-Pa", "1e5", "--n-mesh", "4", "--n-boundary", "24"]


@pytest.fixture(scope="module")
def cylinder_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("specimen")
    rc = main(CYL + ["--B", "0:0.8:3", "--json", str(d / "s.json"), "--png", str(d / "s.png"),
                     "--vtu", str(d / "s.vtu"), "--quiet"])
    return rc, d


def test_cylinder_json(cylinder_run):
    rc, d = cylinder_run
    assert rc == 0
    out = json.loads((d / "s.json").read_text())
    assert {"specimen", "model", "shear_modulus_Pa", "bulk_modulus_Pa", "law", "steps", "solid",
            "seconds", "manifest"} <= set(out)
    assert out["model"] == "continuum" and out["specimen"]["shape"] == "cylinder"
    assert out["specimen"]["aspect_ratio_L_over_D"] == pytest.approx(0.8)
    assert out["specimen"]["edge_radius_m"] == pytest.approx(0.1 * R)     # the default rim
    # --nu default 0.499: K = 2 G (1 + nu) / (3 (1 - 2 nu)) = 499.67 G
    assert out["bulk_modulus_Pa"] / out["shear_modulus_Pa"] == pytest.approx(499.666, rel=1e-4)
    steps = out["steps"]
    assert [s["B_applied_T"] for s in steps] == pytest.approx([0.0, 0.4, 0.8])
    keys = {"B_applied_T", "M_mean_A_per_m", "H_mean_A_per_m", "demag_factor",
            "length_change_axis_m", "length_change_mean_m", "strain_axis", "strain_end_mean",
            "diameter_change_m", "lateral_strain", "mean_strain_zz", "stagger_iterations",
            "newton_iterations", "stagger_history"}
    assert all(keys <= set(s) for s in steps)
    assert steps[0]["demag_factor"] is None               # undefined at B = 0 (NaN -> null)
    last = steps[-1]
    # the body lengthens along the field and narrows across it, by less than 10 %
    assert 0 < last["strain_axis"] < 0.1 and -0.1 < last["lateral_strain"] < 0
    # a sharp-edged cylinder's volume-mean axial strain is its end-face mean (divergence
    # theorem); with a rounded rim the end-face mean covers the flat part only (-2 % here)
    assert last["mean_strain_zz"] == pytest.approx(last["strain_end_mean"], rel=0.05)
    assert last["strain_axis"] == pytest.approx(last["length_change_axis_m"] / L)


def test_cylinder_png(cylinder_run):
    _, d = cylinder_run
    assert (d / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cylinder_vtu_opens_with_meshio(cylinder_run):
    import meshio
    _, d = cylinder_run
    m = meshio.read(d / "s.vtu")
    assert [c.type for c in m.cells] == ["triangle6"]
    u = m.point_data["displacement_m"]
    assert u.shape == (len(m.points), 3) and "mean_stress_Pa" in m.point_data
    X = m.points - u                                          # the reference half section
    assert np.allclose(X[:, 1], 0.0) and X[:, 0].min() >= 0.0
    assert X[:, 0].max() == pytest.approx(R) and X[:, 2].max() == pytest.approx(L / 2)
    assert X[:, 2].min() == pytest.approx(-L / 2)            # mirrored about the mid-plane
    out = json.loads((d / "s.json").read_text())
    # the top end's axial displacement on the axis is half the change of length
    top = np.argmin(np.hypot(X[:, 0], X[:, 2] - L / 2))
    assert u[top, 2] == pytest.approx(0.5 * out["steps"][-1]["length_change_axis_m"], rel=1e-9)
    # every triangle counter-clockwise in the (x, z) plane
    t = m.cells[0].data
    a = ((X[t[:, 1], 0] - X[t[:, 0], 0]) * (X[t[:, 2], 2] - X[t[:, 0], 2])
         - (X[t[:, 1], 2] - X[t[:, 0], 2]) * (X[t[:, 2], 0] - X[t[:, 0], 0]))
    assert np.all(a > 0)


def test_sphere_relaxed_model(tmp_path, capsys):
    """A sphere (no --length-m), linear law, --model relaxed with the given --kappa: the end-
    face mean is null in the JSON (a sphere has poles), the kappa's source is recorded."""
    rc = main(["specimen", "--shape", "sphere", "--radius-m", str(R), "--law", "linear",
               "--chi", "0.5", "--matrix-E-Pa", "3e5", "--nu", "0.45", "--B", "0.3",
               "--model", "relaxed", "--kappa", "0.2", "--n-mesh", "4", "--n-boundary", "24",
               "--json", str(tmp_path / "s.json")])
    assert rc == 0
    out = json.loads((tmp_path / "s.json").read_text())
    assert out["model"] == "relaxed" and out["kappa"]["value"] == 0.2
    assert out["shear_modulus_Pa"] == pytest.approx(3e5 / (2 * 1.45))
    st = out["steps"][0]
    assert st["strain_end_mean"] is None and math.isfinite(st["strain_axis"])
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 3 and printed[-1].startswith("sphere L/D = 1")   # header, step, end


@pytest.mark.parametrize("extra, words", [
    (["--B", "0.5,0.2"], ("--B", "increase strictly")),
    (["--B", "-0.1"], ("--B", ">= 0")),
    (["--model", "magic"], ("--model",)),
    (["--law", "linear", "--chi0", "2"], ("--law linear", "--chi")),
    (["--shape", "sphere"], ("--length-m", "sphere")),
    (["--nu", "0.5"], ("--nu", "(-1, 0.5)")),
    (["--radius-m", "0"], ("--radius-m",)),
    (["--model", "relaxed"], ("--kappa", "relax tables")),
    (["--model", "affine", "--phi", "0.1"], ("--particle-Ms-A-per-m",)),
])
def test_bad_input_exit_2_nothing_written(extra, words, tmp_path, capsys):
    j = tmp_path / "s.json"
    argv = list(CYL)
    for opt, val in zip(extra[::2], extra[1::2]):
        if opt in argv:
            argv[argv.index(opt) + 1] = val
        else:
            argv += [opt, val]
    if "--law" in extra and "linear" in extra:
        i = argv.index("--Ms-A-per-m")
        del argv[i:i + 2]
    assert main(argv + ["--json", str(j)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_no_convergence_exit_3_with_history_and_no_file(tmp_path, capsys):
    """Two staggered iterations to a tolerance of 1e-12 (the first change of the length is
    ~1e-3): exit 3, the residual history and the message on stderr, no JSON."""
    j = tmp_path / "s.json"
    rc = main(CYL + ["--B", "0.4", "--max-stagger", "2", "--tol", "1e-12", "--json", str(j),
                     "--quiet"])
    assert rc == 3
    err = capsys.readouterr().err
    assert "residual history (relative): " in err and "did not converge" in err
    assert "B = 0.4 T" in err and "residual history (relative): -" not in err
    assert not j.exists() and list(tmp_path.iterdir()) == []


def test_box_in_3d_from_the_command_line(tmp_path, capsys):
    """--geometry 3d: the eighth of a box and of the space around it; the JSON says so and the
    box elongates along the field in the linear regime as B^2 (strain ~ mu0 M^2 / G, M ~ B)."""
    j = tmp_path / "b.json"
    rc = main(["specimen", "--geometry", "3d", "--shape", "box", "--radius-m", "5e-3",
               "--length-m", "8e-3", "--law", "linear", "--chi", "0.5", "--shear-modulus-Pa",
               "1e6", "--B", "0.05,0.1", "--n-mesh", "3", "--json", str(j), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    res = json.loads(j.read_text())
    assert res["specimen"]["geometry"] == "3d"
    e = [s["strain_axis"] for s in res["steps"]]
    assert e[0] > 0
    # small strains (1e-4 .. 1e-3): quadratic in B within a few per cent (geometry change)
    assert e[1] / e[0] == pytest.approx(4.0, rel=0.03)


def _tet10_jacobians(P, t):
    """det(dx/dxi) (ne, 5) of quadratic tetrahedra (VTK tetra10 order) at the points of a
    degree-3 rule on the reference tetrahedron, and the rule's weights (5,): their product summed
    is the volume of the curved (isoparametric) tetrahedra, exact (det is cubic in xi)."""
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTet
    xi, w = get_quadrature(RefTet, 3)
    lam = np.vstack([1.0 - xi.sum(axis=0), xi])                         # (4, q)
    dlam = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])   # (4, 3)
    # dN/dxi (10, q, 3): vertices l (2 l - 1), edges 4 la lb
    dN = [(4.0 * lam[a] - 1.0)[:, None] * dlam[a] for a in range(4)]
    for a, b in ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)):
        dN.append(4.0 * (lam[a][:, None] * dlam[b] + lam[b][:, None] * dlam[a]))
    dN = np.stack(dN)
    Jm = np.einsum("eai,aqj->eqij", P[t], dN)                           # (ne, q, 3, 3)
    return np.linalg.det(Jm), w


def test_3d_vtu_is_the_whole_deformed_body(tmp_path, capsys):
    """--geometry 3d --vtu: the octant mirrored to the whole cylinder as VTK tetra10. Read back
    with meshio: the reference points (points - displacement) are the P2 nodes of the octant
    and their mirror images, the midside nodes sit on the midpoints of the reference edges in
    VTK's edge order, every curved tetrahedron has a positive Jacobian (node order), and the
    deformed volume (the isoparametric tetrahedra, exact quadrature) is the mesh's volume plus
    the JSON's volume change int (J - 1) dV to round-off."""
    import meshio
    from scipy.spatial import cKDTree
    from skfem import Basis, ElementTetP2

    from homogenize.macro.specimen import Specimen
    j, v = tmp_path / "c.json", tmp_path / "c.vtu"
    Rc, Lc = 5e-3, 8e-3
    # nu = 0.3: a volume change of ~1e-3, well above the round-off of the volume sums
    rc = main(["specimen", "--geometry", "3d", "--shape", "cylinder", "--radius-m", str(Rc),
               "--length-m", str(Lc), "--law", "linear", "--chi", "0.5", "--shear-modulus-Pa",
               "2e4", "--nu", "0.3", "--B", "0.1,0.2", "--n-mesh", "3", "--json", str(j),
               "--vtu", str(v), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    out = json.loads(j.read_text())
    m = meshio.read(v)
    assert [c.type for c in m.cells] == ["tetra10"]
    t = m.cells[0].data
    u = m.point_data["displacement_m"]
    assert u.shape == (len(m.points), 3) and m.point_data["mean_stress_Pa"].shape == (len(u),)
    X = m.points - u
    # the reference octant's P2 nodes and their mirror images, each once
    body = Specimen("cylinder", Rc, Lc, n_mesh=3, geometry="3d").mechanics_body()
    oct_ = np.asarray(Basis(body.mesh, ElementTetP2()).doflocs).T
    d, _ = cKDTree(oct_).query(np.abs(X))
    assert d.max() < 1e-12 * Rc
    n_images = 2 ** np.sum(np.abs(oct_) > 1e-12 * Rc, axis=1)
    assert len(X) == n_images.sum() == len(np.unique(np.round(X / Rc, 9), axis=0))
    assert np.allclose([X[:, 0].min(), X[:, 0].max(), X[:, 2].min(), X[:, 2].max()],
                       [-Rc, Rc, -Lc / 2, Lc / 2], rtol=0, atol=1e-12 * Rc)
    # the displacement is the mirror image's: odd in each coordinate it is along
    top, bottom = np.argmin(np.sum((X - [0, 0, Lc / 2]) ** 2, axis=1)), \
        np.argmin(np.sum((X - [0, 0, -Lc / 2]) ** 2, axis=1))
    assert u[top, 2] - u[bottom, 2] == pytest.approx(out["steps"][-1]["length_change_axis_m"],
                                                     rel=1e-9)
    # node order: midside nodes on the reference edges' midpoints in VTK's order
    for k, (a, b) in enumerate(((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))):
        assert np.allclose(X[t[:, 4 + k]], 0.5 * (X[t[:, a]] + X[t[:, b]]), rtol=0,
                           atol=1e-12 * Rc)
    det0, w = _tet10_jacobians(X, t)
    det1, _ = _tet10_jacobians(m.points, t)
    assert det0.min() > 0 and det1.min() > 0
    V0, V1 = det0 @ w, det1 @ w
    assert V0.sum() == pytest.approx(out["specimen"]["mesh_volume_m3"], rel=1e-12)
    dV = out["steps"][-1]["volume_change_m3"]
    # 0.3: compressible; the volume strain is of the order of the axial one
    assert abs(dV) > 1e-2 * abs(out["steps"][-1]["mean_strain_zz"]) * V0.sum()
    assert V1.sum() - V0.sum() == pytest.approx(dV, rel=1e-6)
    fd = m.field_data
    assert "mirrored" in bytes(fd["configuration"]).decode()
    assert fd["B_applied_T"][0] == pytest.approx(0.2)


MAG = ["specimen", "--shape", "cylinder", "--radius-m", "2e-3", "--length-m", "2e-3", "--law",
       "linear", "--chi", "0.5", "--shear-modulus-Pa", "1e6", "--n-mesh", "4", "--n-boundary",
       "24", "--magnet", "cylinder", "--magnet-size", "10e-3", "5e-3", "--remanence-T", "1.2"]


def test_specimen_on_a_magnet_from_the_command_line(tmp_path, capsys):
    """--magnet cylinder --gap-m: per gap the applied field at the centre, the plate's
    reaction and the net magnetic force in the JSON (the physics in
    tests/homogenize/macro/test_specimen_magnet.py); the VTU is the whole section resting on
    the plate z = 0 (not mirrored)."""
    import meshio
    j, v = tmp_path / "m.json", tmp_path / "m.vtu"
    rc = main(MAG + ["--gap-m", "4e-3,3e-3", "--json", str(j), "--vtu", str(v), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    out = json.loads(j.read_text())
    assert out["setup"]["support"] == "plate"
    assert out["setup"]["magnet"] == pytest.approx(
        {"shape": "cylinder", "diameter_m": 10e-3, "height_m": 5e-3, "remanence_T": 1.2,
         "magnetization": "+z (along the axis)",
         "position": "coaxial below the plate, top face at z = -gap_m"})
    steps = out["steps"]
    assert [s["gap_m"] for s in steps] == pytest.approx([4e-3, 3e-3])
    for s in steps:
        assert s["reaction_N"] > 0 and s["maxwell_force_N"] < 0
        assert s["reaction_N"] == pytest.approx(-s["maxwell_force_N"], rel=0.02)
    assert steps[1]["reaction_N"] > steps[0]["reaction_N"]
    printed = capsys.readouterr().out
    assert "reaction [N]" in printed and "on a plate above a magnet" in printed
    m = meshio.read(v)
    X = m.points - m.point_data["displacement_m"]
    assert X[:, 2].min() == pytest.approx(0.0, abs=1e-15) and X[:, 2].max() == pytest.approx(2e-3)
    assert np.abs(m.point_data["displacement_m"][np.abs(X[:, 2]) < 1e-15, 2]).max() < 1e-15
    assert m.field_data["gap_m"][0] == pytest.approx(3e-3)


@pytest.mark.parametrize("extra, words", [
    (["--gap-m", "0"], ("--gap-m", "> 0 m")),
    (["--gap-m=-1e-3"], ("--gap-m", "into the specimen")),
    (["--gap-m", "2e-3,3e-3"], ("--gap-m", "decrease strictly")),
    (["--gap-m", "3e-3", "--B", "0.2"], ("--B", "--magnet")),
    (["--gap-m", "3e-3", "--geometry", "3d"], ("--magnet", "axisymmetric")),
    ([], ("--magnet cylinder", "--gap-m")),
])
def test_magnet_bad_input_exit_2_nothing_written(extra, words, tmp_path, capsys):
    j = tmp_path / "m.json"
    assert main(MAG + extra + ["--json", str(j)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_magnet_options_without_magnet_are_refused(tmp_path, capsys):
    assert main(CYL + ["--gap-m", "3e-3", "--json", str(tmp_path / "s.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--gap-m" in err[0] and "--magnet" in err[0]
    assert list(tmp_path.iterdir()) == []
