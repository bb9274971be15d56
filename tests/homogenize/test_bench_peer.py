"""The muSpectre peer of ``mapsim bench --only peer`` (homogenize/bench/bench_peer.py): the
record says plainly when muSpectre is missing, and the wrapper that drives it returns the
exact stiffness of a homogeneous cell (where it runs: the optional ``peers`` extra)."""
import sys

import numpy as np
import pytest

from homogenize.bench import bench_peer
from homogenize.bench.bench_cell import muspectre_stiffness


def test_missing_peer_is_a_skipped_record(monkeypatch):
    monkeypatch.setitem(sys.modules, "muSpectre", None)      # import fails
    recs = bench_peer.bench_records(quick=True)
    assert len(recs) == 1
    assert "muSpectre not installed" in recs[0]["skipped"]
    assert recs[0]["seconds"] is None and recs[0]["ratio"] is None


@pytest.mark.parametrize("gradient", ["fourier", "central"])
def test_muspectre_wrapper_homogeneous_cell(gradient):
    pytest.importorskip("muSpectre", reason="muSpectre is an optional peer (pip install .[peers])")
    E, nu, n = 2.0e6, 0.3, 5
    C, fev, setup = muspectre_stiffness(np.full((n, n, n), E), np.full((n, n, n), nu),
                                        gradient, 1e-10)
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    ref = np.zeros((6, 6))
    ref[:3, :3] = lam
    ref[range(3), range(3)] = lam + 2 * mu
    ref[range(3, 6), range(3, 6)] = mu                      # engineering shear
    assert np.abs(C - ref).max() <= 1e-9 * ref.max()
    assert setup >= 0.0
