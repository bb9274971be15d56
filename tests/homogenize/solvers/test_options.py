"""The solver options: today's defaults, one validation per field, frozen, derived copies."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from homogenize.cell import problem as C
from homogenize.solvers import AMGOptions, SolverOptions, smoothed_aggregation
from micro.common.validate import InputError


def test_defaults_are_the_measured_settings():
    """The values the cell solver used as module globals before the options object (its
    results in results/cell/ were made with them)."""
    o = SolverOptions()
    assert (o.matfree_assembled_max, o.matfree_coarse, o.matfree_sweeps) == (64, "amg", 1)
    assert (o.matfree_interface_sweeps, o.matfree_interface_halo) == (1, 1)
    assert o.block_cg == "strains"
    assert (o.patch_shell_voxels, o.patch_min_particles, o.patch_small_radius_voxels) \
        == (0.5, 200, 2.0)
    assert o.patch_tol_factor == 1e-2
    assert o.krylov is None and o.preconditioner is None
    a = o.amg
    assert a == AMGOptions()
    assert (a.symmetry, a.strength_theta, a.improve_candidates, a.coarse_solver, a.max_coarse,
            a.keep) == ("hermitian", 0.05, False, "splu", None, False)


def test_frozen_and_replace():
    o = SolverOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.block_cg = "coupled"
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.amg.max_coarse = 10
    p = o.replace(block_cg="independent", patch_shell_voxels=None)
    assert (p.block_cg, p.patch_shell_voxels) == ("independent", None)
    assert o.block_cg == "strains" and o.patch_shell_voxels == 0.5    # the original is intact
    assert p.replace(block_cg="strains", patch_shell_voxels=0.5) == o
    assert o.amg.replace(max_coarse=40).max_coarse == 40
    with pytest.raises(InputError, match="block_cg"):
        o.replace(block_cg="magic")                   # a derived copy is validated again


@pytest.mark.parametrize("field,value", [
    ("matfree_assembled_max", 0), ("matfree_assembled_max", 4.5), ("matfree_assembled_max", True),
    ("matfree_coarse", "svd"), ("matfree_sweeps", 0), ("matfree_interface_sweeps", -1),
    ("matfree_interface_halo", -1), ("block_cg", "strain"), ("patch_shell_voxels", -0.5),
    ("patch_shell_voxels", float("nan")), ("patch_shell_voxels", "0.5"),
    ("patch_min_particles", 0), ("patch_small_radius_voxels", -1.0), ("patch_tol_factor", 0.0),
    ("patch_tol_factor", 2.0), ("krylov", "coupled"), ("preconditioner", 3), ("amg", {}),
])
def test_solver_options_refuse_bad_values(field, value):
    with pytest.raises(InputError, match=field) as e:
        SolverOptions(**{field: value})
    assert isinstance(e.value, ValueError)           # InputError is a ValueError


@pytest.mark.parametrize("field,value", [
    ("symmetry", "nonsymmetric"), ("strength_theta", -0.1), ("strength_theta", 1.0),
    ("improve_candidates", None), ("coarse_solver", "gauss"), ("max_coarse", 0),
    ("max_coarse", 10.0), ("keep", 1),
])
def test_amg_options_refuse_bad_values(field, value):
    with pytest.raises(InputError, match=field):
        AMGOptions(**{field: value})


def test_good_values_pass():
    SolverOptions(matfree_coarse="lu", matfree_interface_sweeps=0, block_cg="coupled",
                  patch_shell_voxels=None, patch_tol_factor=1.0, krylov=lambda *a, **k: None,
                  amg=AMGOptions(symmetry="symmetric", strength_theta=None,
                                 improve_candidates=True, coarse_solver=None, max_coarse=500))


def test_setup_needs_a_coarse_size_and_the_cell_solver_options():
    import scipy.sparse as sp
    with pytest.raises(InputError, match="max_coarse"):
        smoothed_aggregation(sp.identity(6, format="csr"), np.ones((6, 1)), AMGOptions())
    with pytest.raises(InputError, match="SolverOptions"):
        C.use_patches(300, np.ones(300), options={"patch_shell_voxels": None})


def test_no_module_globals_left_in_the_cell_solver():
    """The settings live in the options object only: nothing left to patch from outside."""
    assert not [k for k in vars(C) if k.startswith("MATFREE_") or k == "AMG_OPTIONS"]
