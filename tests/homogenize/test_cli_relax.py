"""`mapsim relax`: the CLI over homogenize.cell.relax (physics tested in test_relax.py)."""
import json

import numpy as np

from homogenize.cli import main
from micro.particles import Monodisperse, generate_rve


def test_relax_writes_steps_and_a_loadable_rve(tmp_path, capsys):
    rve = generate_rve(0.05, 8, 3, distribution=Monodisperse(25e-9))
    src = tmp_path / "r.h5"
    rve.save(src)
    out, relaxed = tmp_path / "rel.json", tmp_path / "rel.h5"
    assert main(["relax", str(src), "--B", "0:0.6:3", "--voxels", "8", "--json", str(out),
                 "--out", str(relaxed), "--quiet"]) == 0
    d = json.loads(out.read_text())
    steps = d["steps"]
    assert [s["B_T"] for s in steps] == [0.0, 0.3, 0.6]
    # zero field: nothing moves; the field moves the particles
    assert steps[0]["displacement_rms_m"] == 0.0 and steps[-1]["displacement_rms_m"] > 0.0
    for k in ("strain_mag", "M_eff_A_per_m", "E_eff_parallel_Pa", "E_eff_perpendicular_Pa",
              "min_gap_m", "iterations", "substeps", "substep_B_T", "failed_attempts"):
        assert k in steps[-1]
    assert np.shape(steps[-1]["strain_mag"]) == (3, 3)
    # the relaxed RVE opens with the other commands
    assert main(["rve", "--load", str(relaxed)]) == 0
    capsys.readouterr()
    # bad input: decreasing steps, a mean strain without the strain boundary or with the wrong
    # number of components, the output is the input
    assert main(["relax", str(src), "--B", "1,0.5", "--json", str(tmp_path / "x.json")]) == 2
    assert main(["relax", str(src), "--mean-strain", "0,0,0,0,0,0",
                 "--json", str(tmp_path / "y.json")]) == 2
    assert main(["relax", str(src), "--boundary", "strain", "--mean-strain", "0,0,0,0,0",
                 "--json", str(tmp_path / "z.json")]) == 2
    assert main(["relax", str(src), "--json", str(src)]) == 2
    assert main(["relax", str(src), "--max-substep-halvings", "-1",
                 "--json", str(tmp_path / "w.json")]) == 2
    for f in ("x.json", "y.json", "z.json", "w.json"):
        assert not (tmp_path / f).exists()


def test_relax_near_field_and_prescribed_strain(tmp_path, capsys):
    rve = generate_rve(0.05, 6, 5, distribution=Monodisperse(25e-9))
    src = tmp_path / "r.h5"
    rve.save(src)
    out = tmp_path / "nf.json"
    assert main(["relax", str(src), "--B", "0,0.3", "--voxels", "8", "--near-field", "on",
                 "--boundary", "strain", "--mean-strain", "1e-3,0,0,0,0,0", "--json", str(out),
                 "--quiet"]) == 0
    d = json.loads(out.read_text())
    assert d["settings"]["near_field"] is True and d["settings"]["boundary"] == "strain"
    for s in d["steps"]:
        assert np.allclose(s["mean_strain"], np.diag([1e-3, 0, 0]), rtol=0, atol=0)
        assert np.shape(s["mean_stress_Pa"]) == (3, 3)
    # zero field: the mean stress is the elastic one, C_eff : E, tension along x
    assert d["steps"][0]["mean_stress_Pa"][0][0] > 0
    assert "stress_zz" in capsys.readouterr().out


def test_relax_matrix_material(tmp_path):
    """--matrix-material fills --matrix-E / --matrix-nu not given (issue 36)."""
    rve = generate_rve(0.05, 6, 5, distribution=Monodisperse(25e-9))
    src = tmp_path / "r.h5"
    rve.save(src)
    for extra, want in (([], (2e6, 0.45)), (["--matrix-material", "ecoflex-00-30"],
                                            (0.118e6, 0.49)),
                        (["--matrix-material", "rtv615", "--matrix-nu", "0.4"], (1.96e6, 0.4))):
        out = tmp_path / "o.json"
        assert main(["relax", str(src), "--B", "0,0.2", "--voxels", "8", "--json", str(out),
                     "--quiet", *extra]) == 0
        cfg = json.loads(out.read_text())["manifest"]["config"]
        assert (cfg["matrix_E"], cfg["matrix_nu"]) == want
