"""One dilute Fe sphere with composite voxels (results/cell/dilute_rate.py; results/cell/README.md): the part of the
error that depends on the sphere's position against the grid shrinks fast, the systematic part
does not -- at 16 voxels per diameter the offset-averaged coefficient is still above a curved P2
value that bounds the exact one from above."""
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "results" / "cell" / "dilute_rate.py"


def test_dilute_sphere_position_error_shrinks_but_the_composite_bias_stays(tmp_path, load_script):
    """(G/G_m - 1)/phi of the cubic array at phi 0.01, C44/C55/C66 at the study's first random
    sphere-centre offsets (same seed). Measured with 8 offsets (dilute_rate.json): spread over
    offsets 0.36 % at 8 voxels per diameter and 0.03 % at 16 (order ~3); offset mean +2.2 % above
    the extrapolated P2 limit at 16 and +1.6 % at 34 (first order, large constant).

    1. spread (std over offsets and the three shear entries) falls >= 4x from 8 to 16 voxels per
       diameter (>= second order);
    2. the curved P2 mesh hs 0.15 / 32 per 2 pi (a conforming displacement FEM: its diagonal
       C entries bound the exact ones from above; 2.3775, limit 2.341) lies below the
       composite-voxel mean at 16 voxels per diameter by more than 0.3 % (measured 0.6 %)."""
    pytest.importorskip("gmsh")
    dr = load_script(SCRIPT)
    offsets = np.random.default_rng(dr.SEED).random((4, 3))
    rows = [dr.voxel_run(30, o) for o in offsets] + [dr.voxel_run(60, o) for o in offsets[:2]]
    c8 = np.array([r["c44_c55_c66"] for r in rows if r["voxels"] == 30])     # D = 8.0
    c16 = np.array([r["c44_c55_c66"] for r in rows if r["voxels"] == 60])    # D = 16.0
    s8, s16 = c8.std(ddof=1) / c8.mean(), c16.std(ddof=1) / c16.mean()
    assert 1e-3 < s8 < 1e-2                      # the position dependence is real at D = 8
    assert s16 < s8 / 4.0
    bound = dr.p2_run(0.15, 32)
    assert bound["n_dof"] > 3e4 and abs(bound["phi_mesh_rel_error"]) < 1e-4
    assert 2.35 < bound["coefficient"] < 2.40
    assert c16.mean() > 1.003 * bound["coefficient"]
    # the script's analysis and figure on these rows (one P2 mesh: the reference is that mesh)
    doc = {"p2": [bound], "voxel_rows": rows}
    dr.analyse(doc)
    assert doc["reference"]["c_inf"] == bound["coefficient"]
    assert [t["voxels"] for t in doc["table"]] == [30, 60]
    assert doc["table"][1]["mean_error"] == pytest.approx(c16.mean() / bound["coefficient"] - 1)
    dr.plot(tmp_path / "rate.png", doc)
    assert (tmp_path / "rate.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
