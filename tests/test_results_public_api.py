"""The studies in results/ are users of the public API (issue 33, item 5): no private project
imports, no private attributes of library objects, no mock patching of the library; and the
public names exposed for them do what the private ones they stand for did."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ("homogenize", "micro", "mapsim")
SCRIPTS = sorted((ROOT / "results").rglob("*.py"))
#: script -> the private uses still tolerated there (without line numbers), and why. Keep short:
#: an entry no longer needed fails the test, so that it is removed.
PENDING: dict = {}   # script -> (tolerated private uses, why): none today


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def violations(source: str) -> list[str]:
    """What in ``source`` (a results script) reaches past the public API: private modules or
    names imported from the project's packages, private attributes of anything the script does
    not define itself, ``unittest.mock`` / ``mock`` / monkeypatching."""
    tree = ast.parse(source)
    own = set()                       # names the script defines: its own privates are fine
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            own.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            own.add(node.attr)
    out = []
    for node in ast.walk(tree):
        where = f"line {getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] in ("mock", "unittest") and "mock" in parts:
                    out.append(f"{where}: import {a.name}")
                elif parts[0] in PROJECT and any(_private(p) for p in parts):
                    out.append(f"{where}: import {a.name}")
        elif isinstance(node, ast.ImportFrom) and node.module:
            parts = node.module.split(".")
            names = [a.name for a in node.names]
            if parts[0] in ("mock", "unittest") and ("mock" in parts or "mock" in names):
                out.append(f"{where}: from {node.module} import mock")
            elif parts[0] in PROJECT and (any(_private(p) for p in parts)
                                          or any(_private(n) for n in names)):
                out.append(f"{where}: from {node.module} import {', '.join(names)}")
        elif isinstance(node, ast.Attribute) and _private(node.attr) and node.attr not in own:
            out.append(f"{where}: private attribute .{node.attr}")
        elif isinstance(node, ast.Name) and node.id in ("monkeypatch", "mock"):
            out.append(f"{where}: {node.id}")
    return out


def test_the_checker_catches_private_use():
    bad = ("from homogenize.bench.bench_cell import _rve\n"
           "import homogenize.voxels._assembly as asm\n"
           "from homogenize import _kernels as kn\n"
           "from micro._ewald import ewald_sum\n"
           "from unittest import mock\n"
           "import homogenize.cell.problem as cell\n"
           "s = cell._CellSolver\n"
           "with mock.patch('homogenize.cell.problem.X', 1):\n    pass\n")
    assert len(violations(bad)) == 7
    good = ("import resumable\nfrom homogenize.bench.bench_cell import bench_rve\n"
            "class P:\n    def _build(self):\n        self._x = 1\n"
            "    def run(self):\n        self._build()\n        return self._x\n"
            "print(P.__doc__, __file__)\n")
    assert violations(good) == []


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_results_script_uses_the_public_api_only(path):
    assert SCRIPTS, "no scripts under results/"
    rel = path.relative_to(ROOT).as_posix()
    found = violations(path.read_text(encoding="utf-8"))
    tolerated = PENDING.get(rel, (set(), ""))[0]
    bad = [v for v in found if v.split(": ", 1)[1] not in tolerated]
    assert not bad, f"{rel} reaches past the public API: {bad}"
    stale = tolerated - {v.split(": ", 1)[1] for v in found}
    assert not stale, f"{rel}: PENDING entries no longer needed, remove them: {sorted(stale)}"


# ------------------------------------------------------------------------------------------------
# the public names exposed for the studies
# ------------------------------------------------------------------------------------------------

def test_public_names_are_listed_in_all():
    import homogenize
    import micro
    from homogenize.cell import problem as cell
    from homogenize.cell import cut
    from homogenize.cell import relax
    from homogenize.bench import bench_cell
    from homogenize.solvers import krylov, matfree
    for mod, names in ((micro, ["atomic_write_text", "write_json", "round_floats", "data_digest",
                                "save_png", "RESULT_DIGITS", "ConvergenceError"]),
                       (homogenize, ["homogenize_conforming", "conforming_tet_mesh"]),
                       (bench_cell, ["bench_rve"]),
                       (cell, ["cell_solver", "isotropic_voigt", "laminate_voigt"]),
                       (cut, ["cut_cell_problem", "side_integrals",
                              "isotropic_element_matrices"]),
                       (relax, ["pair_contact_forces", "rigid_sphere_displaceability"]),
                       (krylov, ["cg_start", "own", "gram", "colnorms", "group_pinv",
                                 "record_step", "block_step", "block_directions"]),
                       (matfree, ["GeometricVCycle", "MatFreeOperator", "restrict",
                                  "prolong_add", "CORNERS", "typed_bsr", "ElementField"])):
        for name in names:
            assert name in mod.__all__ and hasattr(mod, name), (mod.__name__, name)
    for name in matfree.__all__:
        assert hasattr(matfree, name), name


def test_bench_rve_is_the_bench_family():
    from homogenize.bench.bench_cell import bench_rve
    a, b = bench_rve(32), bench_rve(32)
    assert a.n == max(8, int(round(0.035 * (32 / 2.5) ** 3 / (4.0 / 3.0 * np.pi) / 1.4)))
    np.testing.assert_array_equal(a.centers_m, b.centers_m)
    assert abs(a.phi - 0.035) < 0.01


def test_krylov_steps_by_public_names():
    from homogenize.solvers import krylov
    rng = np.random.default_rng(0)
    A, B = rng.normal(size=(2, 3000, 4))
    A, B = np.ascontiguousarray(A), np.ascontiguousarray(B)
    np.testing.assert_allclose(krylov.gram(A, B), A.T @ B, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(krylov.colnorms(A), np.linalg.norm(A, axis=0), rtol=1e-12)
    X, R = np.zeros((3000, 4)), B.copy()
    alpha = rng.normal(size=(4, 4))
    krylov.block_step(X, R, A, A, alpha)
    np.testing.assert_allclose(X, A @ alpha, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(R, B - A @ alpha, rtol=1e-12, atol=1e-12)


def test_cell_solver_matches_homogenize_mesh_and_its_cycle():
    """The public ``cycle(0, B)`` of the solver's V-cycle is its ``M @ B``, the operator's
    ``node_residual`` over all nodes its ``residual``; ``cell_solver`` solves."""
    from homogenize.bench.bench_cell import bench_rve
    from homogenize.cell.problem import cell_solver
    from homogenize.voxels.mesh import voxelize
    from homogenize.solvers import SolverOptions
    n = 16
    mesh = voxelize(bench_rve(n), n, method="composite")
    opts = SolverOptions(patch_shell_voxels=None)
    s = cell_solver(mesh, solver="matrix-free", options=opts)
    rng = np.random.default_rng(1)
    B = np.ascontiguousarray(rng.normal(size=(3 * n ** 3, 2)))
    X = np.ascontiguousarray(rng.normal(size=(3 * n ** 3, 2)))
    np.testing.assert_array_equal(s.M.cycle(0, B), s.M @ B)
    op = s.matvec
    r = np.empty((n ** 3, 3, 2))
    op.node_residual(np.arange(n ** 3, dtype=np.int64), X, B, r)
    np.testing.assert_allclose(r.reshape(-1, 2), op.residual(X, B), rtol=1e-12, atol=1e-9)
    F = B.reshape(-1, 3, 2) - B.reshape(-1, 3, 2).mean(axis=0)      # balanced loads
    W, hist = s.solve(np.ascontiguousarray(F.reshape(-1, 2)))
    assert W.shape == B.shape and all(0 < len(h) < 2000 and h[-1] <= 1e-6 for h in hist)


def test_pair_contact_forces_is_the_relaxation_penalty():
    from homogenize.cell import relax
    from micro.materials import PDMS, elastic
    a = np.array([1e-6, 1e-6])
    x = np.array([[5e-6, 5e-6, 5e-6], [7.05e-6, 5e-6, 5e-6]])     # gap 0.05 um < 0.1 um
    got = relax.pair_contact_forces(x, a, 20e-6, 0.1e-6, elastic(PDMS))
    assert len(got) == 1
    i, j, d, f = got[0]
    assert {int(i), int(j)} == {0, 1}
    assert np.dot(f, d) != 0.0 and np.allclose(np.cross(f, d), 0.0)
    assert relax.pair_contact_forces(x, a, 20e-6, 0.01e-6, elastic(PDMS)) == []
