"""The seed paper reproduction: Eqs. (1)-(3), the JSON contract, written files (quick run)."""
import json

import numpy as np
import pytest

from homogenize.cli import main
from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip
from homogenize.studies import paper
from homogenize.studies.paper import seed_body_force
from micro.materials import SEED

KEYS = ["body_force_seed_N_m3", "beam", "force_for_4mm_N_m3", "tip_linear_m", "tip_nonlinear_m",
        "gravity", "channel"]


def test_seed_body_force_and_radius_independence():
    F = 0.035 * 0.5 * 7870 * 178 * 1.78
    assert F == pytest.approx(43636.8, abs=0.1)   # the "about 43.6 kN/m^3"
    vals = [seed_body_force(0.035, 0.5, r, 178, 7870, 1.78)["F_b_N_m3"]
            for r in (10e-9, 25e-9, 50e-9, 1e-6)]
    np.testing.assert_allclose(vals, F, rtol=1e-12)   # N ~ r^-3 and F_g ~ r^3 cancel
    # the paper's 43.79 kN/m^3 needs 1.786 T/m
    assert 43.79e3 / (F / 1.78) == pytest.approx(1.7862, abs=1e-4)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    rc = main(["paper", "--quick", "--quiet", "--out", str(out), "--json",
               str(out / "copy.json")])
    assert rc == 0
    return out, json.loads((out / "paper.json").read_text())


def test_paper_files_and_keys(quick):
    out, res = quick
    for name in ("summary.md", "paper.json", "copy.json", "manifest.json", "beam_convergence.png",
                 "beam_nonlinear.png", "channel.png", "element_sensitivity.png"):
        assert (out / name).stat().st_size > 0
    assert json.loads((out / "copy.json").read_text()) == res
    for k in KEYS:
        assert k in res
    for k in ("width_m", "thickness_m", "inferred_length_m"):
        assert res["beam"][k] > 0
    for k in ("P1_coarse", "P2_coarse", "converged", "coarse_mesh", "converged_mesh"):
        assert k in res["force_for_4mm_N_m3"]
    text = (out / "summary.md").read_text()
    assert "Abaqus" in text and "element-type sensitivity" in text
    assert "cannot single out" in text


def test_paper_numbers_are_physical(quick):
    _, res = quick
    b, f = res["beam"], res["force_for_4mm_N_m3"]
    # length: the converged 3D strip is stiffer than EB, so it is a little longer than the EB one
    assert 1.0 < b["inferred_length_m"] / b["eb_length_m"] < 1.05
    assert res["tip_linear_m"] == pytest.approx(4e-3, rel=1e-6)
    # linear tets lock: more force for the same deflection; quadratic ones nearly converged
    assert f["P1_coarse"] > 1.2 * f["P2_coarse"]
    assert f["P2_coarse"] == pytest.approx(f["converged"], rel=0.05)
    # shear locking alone at nu = 0; volumetric locking adds to it as nu -> 1/2
    lock = {r["nu"]: r["P1_over_P2_force"] for r in f["locking_vs_nu"]["rows"]}
    assert 1 < lock[0.0] < lock[0.45] < lock[0.49]
    # large deformation reduces the tip like the elastica does (quick mesh: 1 %)
    nl = res["nonlinear"]
    assert res["tip_nonlinear_m"] < res["tip_linear_m"]
    assert nl["nonlinear_over_linear"] == pytest.approx(nl["elastica_over_eb"], rel=0.01)
    g = res["gravity"]
    assert g["rho_eff_kg_m3"] == pytest.approx(0.965 * 1210 + 0.035 * 7870)
    # paper.json holds 6 significant digits: a ratio of two rounded values within 1e-6
    assert g["sag_linear_m"] == pytest.approx(4e-3 * g["self_weight_N_m3"] / 40e3, rel=2e-6)
    # EB check of the converged compliance at the inferred length: within the plate/beam band
    eb = cf.eb_tip_deflection_m(40e3, b["inferred_length_m"], b["width_m"], b["thickness_m"], 2e6)
    assert eb * (1 - 0.45**2) < 4e-3 < eb
    rows = res["channel"]["table"]
    assert len(rows) >= 4 and all(r["max_deflection_m"] > 0 for r in rows)


def test_seed_constants_come_from_micro_materials(quick):
    _, res = quick
    assert paper.SEED is SEED and paper.SeedParameters is type(SEED)
    assert res["parameters"]["E_Pa"] == SEED.E_Pa and res["parameters"]["nu"] == SEED.nu
    assert res["gravity"]["phi"] == SEED.c


def test_element_sensitivity_quick(quick):
    _, res = quick
    es = res["element_sensitivity"]
    rows = [r for r in es["rows"] if r["status"] == "ok"]
    assert es["converged_force_N_m3"]["0.45"] == pytest.approx(40e3, rel=1e-12)
    # with E fixed nu enters only through 3D effects (anticlastic curvature, the clamp): the
    # converged force moves by a few per cent (quick mesh: 38.6 kN/m^3)
    assert es["converged_force_N_m3"]["0.3"] == pytest.approx(40e3, rel=0.06)
    by = {(r["family"], r["layers"], r["nu"], r["element"]): r["ratio_to_converged"]
          for r in rows}
    for (fam, k, nu, name), q in by.items():
        if name in ("hex20", "hex20-r", "hex27", "tet10") and k >= 2:
            assert q == pytest.approx(1.0, abs=0.05)      # quadratic: near converged
        if name == "hex8":
            if (fam, k, nu, "hex20") in by:
                assert q > by[(fam, k, nu, "hex20")]      # trilinear stiffer than quadratic
            if nu == 0.45:
                # full integration locks more than SRI at nu = 0.45
                assert q > by[(fam, k, nu, "hex8-sri")]
        if name == "tet4":
            assert q > 1.5                                # linear tets lock strongly
        if name == "C3D8":
            assert q == pytest.approx(by[(fam, k, nu, "hex8")], rel=1e-4)
    for d in es["pairs_matching_paper"]:
        assert abs(d["ratio"] - 1.25) <= es["pair_tolerance"]
    # the main study never depends on CalculiX being installed: no CalculiX rows at all
    assert es["ccx"].startswith("not part of this study")
    assert not [r for r in rows if r["code"] == "CalculiX"]


def test_element_study_without_ccx_marks_the_columns():
    cfg = {"nu": (0.45,), "layers": (1,), "families": ("beam",),
           "cubic_quadratic_max_layers": 0, "p1_fine_layers": ()}
    es = paper._element_study(SEED, Strip(19.4e-3, 5e-3, 1e-3), 2.0, (1, 2), cfg, None,
                              "no-such-ccx-executable", None)
    assert es["ccx"] == "not run: ccx not installed"
    ccx_rows = [r for r in es["rows"] if r["code"] == "CalculiX"]
    assert ccx_rows and all(r["status"] == "not run: ccx not installed"
                            and r["force_N_m3"] is None for r in ccx_rows)
    assert all(r["status"] == "ok" for r in es["rows"] if r["code"] == "scikit-fem")


def test_calculix_peer_refuses_before_any_work_without_ccx(tmp_path, capsys):
    out = tmp_path / "peers"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PATH", str(tmp_path))          # no ccx on this PATH
        rc = main(["paper-calculix", "--quick", "--quiet", "--out", str(out)])
    assert rc == 2
    assert "CalculiX 'ccx' is not installed" in capsys.readouterr().err
    assert not out.exists()                       # nothing created before the refusal


def test_rerun_keeps_the_figures_of_unchanged_numbers(quick, tmp_path):
    """A figure carries the digest of the rounded numbers it shows and is not redrawn when they
    are unchanged (another CPU's last-digit round-off rewrites nothing); different numbers
    redraw it."""
    from micro.common.files import _png_digest, save_png
    from matplotlib.figure import Figure
    out, res = quick
    png = out / "channel.png"
    before = png.read_bytes()
    assert _png_digest(png)
    fig = Figure()
    fig.add_subplot().plot([0, 1], [0, 2])
    assert save_png(fig, png, _png_digest(png)) is False and png.read_bytes() == before
    assert save_png(fig, tmp_path / "new.png", "abc") is True
    assert _png_digest(tmp_path / "new.png") == "abc"
    assert save_png(fig, tmp_path / "new.png", "abd") is True
