"""results/specimen/diguet.py (the Diguet et al. 2010 prediction) in its quick mode."""
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]


def test_diguet_prediction_quick(load_script, tmp_path):
    """results/specimen/diguet.py in its quick mode: every input with a source, the composite's
    magnetization from RVEs (initial susceptibility near Maxwell-Garnett's 3 phi / (1 - phi) for
    random soft spheres: the RVEs are random, not chained), both models on the cylinder and the
    spheroid, compared with the measured curve; nothing fitted."""
    mod = load_script(ROOT / "results" / "specimen" / "diguet.py")
    res = mod.run(tmp_path, quick=True)
    assert all(v["source"] for v in res["inputs"].values())
    phi = res["inputs"]["phi"]["value"]
    assert res["composite_law"]["chi_initial"] == pytest.approx(3 * phi / (1 - phi), rel=0.15)
    models = {(c["shape"], c["model"]) for c in res["cases"] if c["steps"]}
    # the relaxed model joins when the relax table at the data set's modulus exists
    names = ("continuum", "affine") + (("relaxed",) if res["relax"].get("available", True)
                                       else ())
    assert models == {(s, m) for s in ("cylinder", "spheroid") for m in names}
    cont = next(c for c in res["cases"] if c["shape"] == "spheroid" and c["model"] == "continuum")
    aff = next(c for c in res["cases"] if c["shape"] == "spheroid" and c["model"] == "affine")
    # the microstructural stress shortens the specimen against the shape's pull
    assert aff["steps"][-1]["strain_axis"] < cont["steps"][-1]["strain_axis"]
    assert json.loads((tmp_path / "diguet.json").read_text())["quick"] is True
    assert (tmp_path / "diguet.png").stat().st_size > 0 and (tmp_path / "diguet.md").exists()
