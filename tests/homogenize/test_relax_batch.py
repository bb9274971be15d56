"""The relax evaluator (particles that move) in batch runs: a reduced study of 2 realizations
through 3 field steps with few particles. Intervals present, zero field gives zero strain and
zero displacement, the same table for 1 and 2 workers, one RVE per realization shared by its
field steps, xarray opens the table; bad study files are refused before any work."""
import os

import h5py
import numpy as np
import pytest

from homogenize.tables import _evaluate
from homogenize.tables._study import parse_study
from homogenize.cell.relax import relax
from homogenize.tables.batch import read_table, run_batch
from micro.common.validate import InputError
from micro.materials import ElasticMaterial
from micro.particles import Monodisperse, generate_rve

FULL = bool(os.environ.get("MAPSIM_FULL"))
# CI: 4 particles, 8^3 voxels (~20-40 s for the two runs); full: 10 particles, 14^3 voxels
N, VOX = (10, 14) if FULL else (4, 8)

STUDY = f"""
[study]
name = "relax-batch-test"
seed = 7
realizations = 2
n_particles = {N}
evaluator = "relax"
fem = true
voxels = {VOX}

[grid]
phi = 0.15
B_T = [0.0, 0.3, 0.6]
matrix_E_Pa = 0.5e6
distribution = "monodisperse"
mean_radius_m = 2e-6

[relax]
matrix_nu = 0.49
"""


@pytest.fixture(scope="module")
def study():
    return parse_study(STUDY, "relax-batch-test.toml")


def _client(n):
    from dask.distributed import Client, LocalCluster
    c = LocalCluster(n_workers=n, threads_per_worker=1, processes=False,
                     dashboard_address="127.0.0.1:0")
    return c, Client(c)


@pytest.fixture(scope="module")
def tables(study, tmp_path_factory):
    out = {}
    for n in (1, 2):
        _evaluate._RELAX_CACHE.clear()       # each run computes its sweeps itself
        cluster, client = _client(n)
        with cluster, client:
            path = tmp_path_factory.mktemp(f"w{n}") / "table.h5"
            run_batch(study, path, client=client, progress=False)
            out[n] = path
    return out


def test_intervals_and_quantities_against_B(tables):
    t = read_table(tables[1])
    assert t.axes["B_T"] == (0.0, 0.3, 0.6)
    for q in ("strain_parallel", "strain_perpendicular", "M_eff_A_per_m", "E_eff_parallel_Pa",
              "E_eff_perpendicular_Pa", "min_gap_m", "displacement_rms_m", "strain_mag"):
        assert q in t.values, q
    with h5py.File(tables[1], "r") as h:
        for q in ("strain_parallel", "E_eff_parallel_Pa", "displacement_rms_m"):
            lo, mean, hi = (h[f"{q}_{s}"][()].ravel() for s in ("ci_low", "mean", "ci_high"))
            assert np.all(lo <= mean) and np.all(mean <= hi)
            assert h[q].attrs["units"] == _evaluate.QUANTITIES[q][0]
    eps = t.component_values("strain_parallel")          # (P, R), P in B order
    u = t.component_values("displacement_rms_m")
    M = t.component_values("M_eff_A_per_m", "z")
    # zero field: no moment, no force, no displacement, no strain
    assert np.all(M[0] == 0) and np.all(u[0] == 0) and np.all(eps[0] == 0)
    # in a field: the particles move, the RVE strains, the magnetization grows with B
    assert np.all(u[1:] > 0) and np.all(eps[1:] != 0)
    assert np.all(M[2] > M[1])
    # stiffness: rigid spheres stiffen the matrix (E_eff > E_matrix) at every field
    assert np.all(t.component_values("E_eff_parallel_Pa") > 0.5e6)
    # the discretization error of every cell-FEM quantity (two grids: VOX and its coarse grid),
    # never below 2.2 % of the filler's part: E_matrix from the grid axis matrix_E_Pa
    from homogenize.tables.resolution import FILLER_BIAS_REL
    assert set(t.disc_err) == set(_evaluate.RELAX_FEM_QUANTITIES)
    E = t.component_values("E_eff_parallel_Pa").mean(axis=1)
    assert np.all(t.disc_err["E_eff_parallel_Pa"] >= FILLER_BIAS_REL * np.abs(E - 0.5e6)
                  * (1 - 1e-12))
    assert np.all(t.disc_err["strain_parallel"][0] == 0)       # no field, no strain


def test_one_rve_per_realization_through_its_field_steps(study, tables):
    """The steps of a realization share the RVE; the stored seed reproduces it, and the
    stored values are those of relax() run alone on that RVE."""
    t = read_table(tables[1])
    with h5py.File(tables[1], "r") as h:
        seeds = h["seed"][()].reshape(3, 2)
    assert np.all(seeds == seeds[0]) and seeds[0, 0] != seeds[0, 1]
    rve = generate_rve(0.15, N, int(seeds[0, 1]), distribution=Monodisperse(2e-6))
    res = relax(rve, [0.0, 0.3, 0.6], matrix=ElasticMaterial(0.5e6, 0.49), voxels=None)
    u = t.component_values("displacement_rms_m")[:, 1]
    assert np.allclose(u, [s["displacement_rms_m"] for s in res.steps], rtol=1e-9, atol=0)


def test_two_workers_give_the_same_table(tables):
    a, b = read_table(tables[1]), read_table(tables[2])
    assert set(a.values) == set(b.values)
    for q in a.values:
        assert np.array_equal(a.values[q], b.values[q]), q


def test_xarray_opens_the_relax_table(tables):
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    with xr.open_dataset(tables[1], engine="h5netcdf") as ds:
        da = ds["strain_parallel_mean"]
        assert da.dims == ("phi", "distribution", "mean_radius_m", "matrix_E_Pa", "B_T")
        assert float(da.sel(B_T=0.0).squeeze()) == 0.0
        assert ds["E_eff_parallel_Pa_ci_high"].attrs["units"] == "Pa"


@pytest.mark.parametrize("change, words", [
    (("B_T = [0.0, 0.3, 0.6]", "B_T = [0.0, 0.6, 0.3]"), ("B_T", "strictly increasing")),
    (("B_T = [0.0, 0.3, 0.6]", "B_T = [0.3, 0.3]"), ("B_T", "repeated")),
    (("matrix_E_Pa = 0.5e6", "matrix_E_Pa = 0.0"), ("matrix_E_Pa", "[100, 1e+13] Pa")),
    (("matrix_E_Pa = 0.5e6", "matrix_E_Pa = -2e6"), ("matrix_E_Pa", "[100, 1e+13] Pa")),
    (("matrix_nu = 0.49", "matrix_nu = 0.7"), ("[relax] matrix_nu", "0.5")),
    (("matrix_nu = 0.49", "elastic_model = \"fem\"\nfem_x = 1"), ("[relax] unknown key 'fem_x'",)),
    (("matrix_nu = 0.49", "boundary = \"open\""), ("[relax] boundary", "free, strain")),
    (("matrix_nu = 0.49", "near_field = 1"), ("[relax] near_field", "true or false")),
    (("fem = true", "fem = false\n[magnetics]\ntol = 1e-6"), ("[magnetics]", "[relax]")),
    (("matrix_E_Pa = 0.5e6", "matrix_E_Pa = 0.5e6\ngradB_T_per_m = 1.0"),
     ("unknown key 'gradB_T_per_m'",)),
])
def test_bad_study_files_name_file_key_and_range(change, words):
    text = STUDY.replace(*change)
    assert text != STUDY
    with pytest.raises(InputError) as e:
        parse_study(text, "bad-relax.toml")
    msg = str(e.value)
    assert "bad-relax.toml" in msg
    for w in words:
        assert w in msg, (w, msg)


def test_relax_table_only_with_the_relax_evaluator():
    text = STUDY.replace('evaluator = "relax"', 'evaluator = "rve"')
    with pytest.raises(InputError, match=r"\[relax\] is given but \[study\] evaluator = 'rve'"):
        parse_study(text, "x.toml")


def test_near_field_key_reaches_relax():
    s = parse_study(STUDY.replace("matrix_nu = 0.49", "matrix_nu = 0.49\nnear_field = true"),
                    "nf.toml")
    assert s.tasks()[0].settings["relax"]["near_field"] is True


def test_packaged_example_study_parses():
    from pathlib import Path
    import homogenize
    p = Path(homogenize.__file__).parent / "studies" / "relax_example.toml"
    from homogenize.tables._study import load_study
    s = load_study(p)
    assert s.evaluator == "relax" and s.fem
    # one RVE per realization and matrix modulus, shared by the field steps
    tasks = s.tasks()
    groups = {(t.point["matrix_E_Pa"], t.realization): t.seed_int() for t in tasks
              if t.point["B_T"] == 0.0}
    for t in tasks:
        assert t.seed_int() == groups[(t.point["matrix_E_Pa"], t.realization)]
