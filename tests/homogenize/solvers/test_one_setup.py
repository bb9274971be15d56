"""The solver layer is the only place that sets up a smoothed-aggregation hierarchy or builds
rigid-body modes (issue 33, item 1): one ``smoothed_aggregation_solver(`` call site in the
package, in homogenize/solvers/amg.py."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np

import homogenize
from homogenize.solvers import grid_node_coordinates, rigid_body_modes

PACKAGE = Path(homogenize.__file__).resolve().parent


def _sources() -> list[Path]:
    """The package's Python files; inside a git checkout the tracked ones only (files another
    change is still writing are not the package yet), else every file."""
    try:
        out = subprocess.run(["git", "ls-files", "--", "*.py"], cwd=PACKAGE, check=True,
                             capture_output=True, text=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        out = []
    files = [PACKAGE / f for f in out] if out else list(PACKAGE.rglob("*.py"))
    return [f for f in files if f.is_file()]


def test_one_smoothed_aggregation_call_site():
    sites = [(f.relative_to(PACKAGE).as_posix(), m.start())
             for f in _sources()
             for m in re.finditer(r"smoothed_aggregation_solver\(", f.read_text())]
    assert [s[0] for s in sites] == ["solvers/amg.py"], sites


def test_rigid_body_modes_span_the_rigid_motions():
    """3D: six modes, the rotation about z is (-y, x, 0); per-DOF form equals the node form;
    2D: three modes; the wrap moves the coordinates' jump to the given node layer."""
    x = np.random.default_rng(0).normal(size=(5, 3))
    B = rigid_body_modes(x)
    assert B.shape == (15, 6)
    Bn = B.reshape(5, 3, 6)
    assert np.array_equal(Bn[:, :, 5], np.stack([-x[:, 1], x[:, 0], np.zeros(5)], axis=1))
    assert np.array_equal(Bn[:, :, :3], np.broadcast_to(np.eye(3), (5, 3, 3)))
    comp = np.tile(np.arange(3), 5)
    assert np.array_equal(rigid_body_modes(np.repeat(x, 3, axis=0), components=comp), B)
    x2 = x[:, :2]
    B2 = rigid_body_modes(x2).reshape(5, 2, 3)
    assert np.array_equal(B2[:, :, 2], np.stack([-x2[:, 1], x2[:, 0]], axis=1))
    n = 4
    g, w = grid_node_coordinates(n), grid_node_coordinates(n, (1, 0, 0))
    assert np.array_equal(w.reshape(n, n, n, 3)[:, :, 1:], g.reshape(n, n, n, 3)[:, :, :-1])
    assert np.ptp(g, axis=0).max() < 1.0            # centred, scaled by the cell
