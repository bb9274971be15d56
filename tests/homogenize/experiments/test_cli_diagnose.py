"""``mapsim diagnose`` and ``mapsim diagnose-study``: exit codes, the spec's JSON, the report."""
import json
from pathlib import Path

import pytest

from homogenize.cli import main
from homogenize.experiments.synthetic import generate, write_case

DATA = Path(__file__).resolve().parents[3] / "examples" / "data"
SPEC_KEYS = {"kind", "n_rows", "baseline", "causes", "steps", "candidates", "final", "gain"}


def test_diagnose_writes_spec_json_and_report(tmp_path, capsys):
    toml = write_case(generate(("gravity",), "deflection", seed=3), tmp_path / "exp" / "g.toml")
    out = tmp_path / "res.json"
    rc = main(["diagnose", str(toml), "--json", str(out), "--report", str(tmp_path / "rep"), "--quiet"])
    assert rc == 0
    res = json.loads(out.read_text())
    assert set(res) == SPEC_KEYS
    assert res["causes"] == ["gravity"] and res["kind"] == "deflection"
    assert set(res["steps"][0]) == {"cause", "cv_rmse", "params", "evidence"}
    assert all(set(c) == {"cause", "cv_rmse"} for c in res["candidates"])
    assert res["gain"] == pytest.approx(res["baseline"]["cv_rmse"] / res["final"]["cv_rmse"])
    assert (tmp_path / "res.manifest.json").exists()
    rep = tmp_path / "rep"
    for f in ("report.md", "data.png", "residuals.png", "diagnosis.json", "manifest.json"):
        assert (rep / f).stat().st_size > 0
    md = (rep / "report.md").read_text()
    assert "gravity" in md and "self-weight" in md
    assert "causes: gravity" in capsys.readouterr().out


def test_diagnose_bad_file_exits_2_with_one_line(tmp_path, capsys):
    (tmp_path / "d.csv").write_text("specimen,phi,strain,stress_Pa\nA,0,0.1,1\nA,0,0.2,x\n")
    (tmp_path / "e.toml").write_text('kind = "tensile"\ndata = "d.csv"\n')
    rc = main(["diagnose", str(tmp_path / "e.toml"), "--json", str(tmp_path / "o.json")])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "d.csv" in err and "row 3" in err and "'stress_Pa'" in err
    assert not (tmp_path / "o.json").exists()          # nothing half-written


def test_diagnose_single_point_runs(tmp_path):
    out = tmp_path / "s.json"
    assert main(["diagnose", str(DATA / "seed_paper_cantilever.toml"), "--json", str(out), "--quiet"]) == 0
    res = json.loads(out.read_text())
    assert res["n_rows"] == 1 and res["causes"] == [] and res["gain"] == 1.0
    # a priori seed model (scale 1) against the 4 mm: |4.36 - 4.00| mm
    assert res["baseline"]["cv_rmse"] == pytest.approx(3.56e-4, rel=1e-2)


def test_diagnose_study_small(tmp_path):
    rc = main(["diagnose-study", "--n", "3", "--out", str(tmp_path / "st"), "--quiet"])
    assert rc == 0
    st = json.loads((tmp_path / "st" / "study.json").read_text())
    assert st["summary"]["n_cases"] == 3
    assert len(st["summary"]["confusion"]) == len(st["summary"]["confusion_labels"])
    for f in ("confusion.csv", "confusion.png", "manifest.json"):
        assert (tmp_path / "st" / f).exists()
    assert main(["diagnose-study", "--n", "0", "--out", str(tmp_path / "x")]) == 2


def test_diagnose_tables_refuses_bad_resolution(capsys):
    # re-making the tables takes minutes (not run here); bad input is refused before any work
    assert main(["diagnose-tables", "--only", "stiffness", "--voxels", "4"]) == 2
    assert "--voxels" in capsys.readouterr().err
