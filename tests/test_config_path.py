"""One configuration path (issue 33 item 2): a parameter's range is defined once, next to its
config class (micro.dipoles.FIELD_RANGES, homogenize.cell.problem.CELL_RANGES), and every
entry point -- the CLI option, the study file rules, the config class and the keyword
function -- checks that same object, so they accept and refuse the same values.

The dipole solve's tol, the cell's tol and the cell's voxels are followed through all four
entry points at their boundaries; the identity tests keep the duplicated literals from coming
back.
"""
import argparse
import math
from types import SimpleNamespace

import numpy as np
import pytest

from micro.common.validate import InputError, Range
from micro.dipoles import FIELD_RANGES, FieldConfig, solve
from homogenize.cell.problem import CELL_RANGES, CellConfig, homogenize_mesh, homogenize_rve
from homogenize.cli import build_parser
from homogenize.tables import _study
from homogenize.tables._study import parse_study

TOL_GOOD = (1e-14, 1e-8, 1e-2)
TOL_BAD = (0.0, -1e-8, 9.9e-15, 1.00001e-2, 0.5, 2.0, math.nan, math.inf)
VOXELS_GOOD = (4, 16, 256)
VOXELS_BAD = (-4, 0, 3, 257, 1000)

_STUDY = """
[study]
seed = 1
realizations = 2
n_particles = 10
evaluator = "rve"
{study}

[grid]
B_T = 0.1
phi = 0.0175
gradB_T_per_m = 1.78
{tables}
"""


def _action(command: str, option: str) -> argparse.Action:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next(a for a in sub.choices[command]._actions if option in a.option_strings)


def _cli_accepts(command: str, option: str, value) -> bool:
    try:
        _action(command, option).type(str(value))
    except argparse.ArgumentTypeError:
        return False
    return True


def _toml(v) -> str:
    return {math.inf: "inf"}.get(v, "nan" if v != v else repr(v))


def _study_accepts(where: str, study: str = "", tables: str = "") -> bool:
    """Whether the study parses; a refusal must name ``where`` (e.g. ``[cell] tol``)."""
    try:
        parse_study(_STUDY.format(study=study, tables=tables), "t.toml")
    except InputError as exc:
        assert f"t.toml: {where} must be" in str(exc), str(exc)
        return False
    return True


def _accepts(f, name: str) -> bool:
    """Whether ``f()`` gets past the check of ``name``: each call below passes one value that
    is refused after it, so an accepted value ends in that later message, never a solve."""
    try:
        f()
    except InputError as exc:
        return not str(exc).startswith(name + " ")
    return True


def _rve():
    return SimpleNamespace(box_m=1e-6, centers_m=np.array([[0.5e-6] * 3]),
                           radii_m=np.array([0.1e-6]), m_sat_Am2=np.array([1e-16]))


# ------------------------------------------------------------------------- the dipole tol
@pytest.mark.parametrize("v", TOL_GOOD + TOL_BAD)
def test_dipole_tol_one_range_at_every_entry(v):
    want = FIELD_RANGES["tol"].contains(v)
    assert want == (v in TOL_GOOD)
    assert _cli_accepts("rve", "--tol", v) == want
    assert _study_accepts("[magnetics] tol", tables=f"[magnetics]\ntol = {_toml(v)}\n") == want
    assert _accepts(lambda: FieldConfig(tol=v), "tol") == want
    # damping 5 is refused after tol: an accepted tol ends there
    assert _accepts(lambda: solve(_rve(), 0.1, 0.0, "saturated", tol=v, damping=5.0),
                    "tol") == want


# ------------------------------------------------------------------------- the cell tol
@pytest.mark.parametrize("v", TOL_GOOD + TOL_BAD)
def test_cell_tol_one_range_at_every_entry(v):
    want = CELL_RANGES["tol"].contains(v)
    assert want == (v in TOL_GOOD)
    assert _cli_accepts("homogenize", "--tol", v) == want
    assert _study_accepts("[cell] tol", "fem = true", f"[cell]\ntol = {_toml(v)}\n") == want
    assert _accepts(lambda: CellConfig(tol=v), "tol") == want
    # matrix_E_Pa 1e20 / maxiter 0 are refused after tol
    assert _accepts(lambda: homogenize_rve(_rve(), 8, tol=v, matrix_E_Pa=1e20), "tol") == want
    assert _accepts(lambda: homogenize_mesh(None, tol=v, maxiter=0), "tol") == want


# ------------------------------------------------------------------------- the cell voxels
@pytest.mark.parametrize("v", VOXELS_GOOD + VOXELS_BAD)
def test_voxels_one_range_at_every_entry(v):
    want = CELL_RANGES["voxels"].contains(v)
    assert want == (v in VOXELS_GOOD)
    assert _cli_accepts("homogenize", "--voxels", v) == want
    assert _cli_accepts("cell-phi-study", "--voxels", v) == want
    assert _study_accepts("[study] voxels", f"voxels = {v}") == want
    assert _accepts(lambda: CellConfig(voxels=v), "voxels") == want
    assert _accepts(lambda: homogenize_rve(_rve(), v, matrix_E_Pa=1e20), "voxels") == want


@pytest.mark.parametrize("bad", (16.0, True, "16"))
def test_voxels_must_be_an_integer_everywhere(bad):
    assert not _accepts(lambda: CellConfig(voxels=bad), "voxels")
    assert not _accepts(lambda: homogenize_rve(_rve(), bad), "voxels")
    assert not _study_accepts("[study] voxels",
                              f"voxels = {bad!r}".replace("True", "true").replace("'", '"'))


# ------------------------------------------------------------------------- one object each
def test_the_study_rules_are_the_owners_range_objects():
    assert _study._RULES["tol"] is FIELD_RANGES["tol"]
    for key, r in FIELD_RANGES.items():
        assert _study._RULES[key] is r, key
    assert _study._CELL_RULES["tol"] is CELL_RANGES["tol"]
    assert _study._RULES["cell_tol"] is CELL_RANGES["tol"]
    assert _study._RULES["maxiter"] is CELL_RANGES["maxiter"]
    assert _study._RULES["tol_magnetic"] is CELL_RANGES["tol_magnetic"]
    for key in ("matrix_E_Pa", "particle_E_Pa"):
        assert _study._RULES[key] is CELL_RANGES["E_Pa"]
    for key in ("matrix_nu", "particle_nu"):
        assert _study._RULES[key] is CELL_RANGES["nu"]


def test_the_cli_options_are_the_owners_range_objects():
    for command, option, r in (("rve", "--tol", FIELD_RANGES["tol"]),
                               ("rve", "--accuracy", FIELD_RANGES["accuracy"]),
                               ("rve", "--demag-factor", FIELD_RANGES["demag_factor"]),
                               ("rve", "--c-powder", FIELD_RANGES["c_powder"]),
                               ("homogenize", "--tol", CELL_RANGES["tol"]),
                               ("homogenize", "--voxels", CELL_RANGES["voxels"]),
                               ("homogenize", "--matrix-E", CELL_RANGES["E_Pa"]),
                               ("homogenize", "--particle-nu", CELL_RANGES["nu"]),
                               ("cell-phi-study", "--voxels", CELL_RANGES["voxels"])):
        assert _action(command, option).type.range is r, (command, option)


def test_poissons_ratio_is_the_materials_range_everywhere():
    from micro.materials import POISSON_RANGE, ElasticMaterial
    assert CELL_RANGES["nu"] is POISSON_RANGE
    for command, option in (("homogenize", "--matrix-nu"), ("homogenize", "--particle-nu"),
                            ("relax", "--matrix-nu"), ("beam", "--nu"), ("specimen", "--nu")):
        assert _action(command, option).type.range is POISSON_RANGE, (command, option)
    for v in (-1.0, 0.5, math.nan):
        with pytest.raises(InputError, match=r"nu \(Poisson's ratio\) must be"):
            ElasticMaterial(2e6, v)
    assert ElasticMaterial(2e6, 0.4999).nu == 0.4999


def test_range_messages_keep_the_project_format():
    r = Range(1e-14, 1e-2, "(relative residual)")
    with pytest.raises(InputError, match=r"^tol must be in \[1e-14, 0.01\] \(relative residual\), "
                                         r"got 0.5$"):
        r.check("tol", 0.5)
    with pytest.raises(argparse.ArgumentTypeError,
                       match=r"^--tol must be a number in \[1e-14, 0.01\] \(relative residual\), "
                             r"got 'abc'$"):
        r.arg("--tol")("abc")
    v = Range(4, 256, integer=True)
    assert v.describe() == "an integer in [4, 256]"
    with pytest.raises(argparse.ArgumentTypeError, match=r"^--voxels must be an integer in "
                                                         r"\[4, 256\], got 2$"):
        v.arg("--voxels")("2")
    assert Range(0.0, 1.0, lo_open=True).describe() == "in (0, 1]"
    assert r.check("tol", 1e-8) == 1e-8 and v.check("voxels", np.int64(8)) == 8
