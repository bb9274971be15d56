"""Effective-parameter tables as xarray grids: selection and interpolation by coordinate,
units and CF attributes on every variable, the MultiIndex recipe, and read_table unchanged."""
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from homogenize.tables._study import parse_study
from homogenize.tables.batch import interpolate, read_table, run_batch

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

STUDY = """
[study]
name = "xarray-test"
seed = 7
realizations = 3
n_particles = 100
evaluator = "synthetic"

[grid]
phi = [0.0175, 0.035]
arrangement = ["dispersed", "chains"]
B_T = [0.01, 0.1, 0.5]
gradB_T_per_m = 1.78
"""
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    out = tmp_path_factory.mktemp("xr") / "table.h5"
    run_batch(parse_study(STUDY, "xarray-test.toml"), out, workers=1, processes=False,
              progress=False)
    return out


def test_sel_by_coordinates_gives_the_grid_point(table):
    t = read_table(table)
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        assert ds["f_eff_N_m3_mean"].dims == ("phi", "arrangement", "B_T", "gradB_T_per_m", "i")
        v = ds["f_eff_N_m3_mean"].sel(phi=0.035, B_T=0.1, arrangement="chains", i="z")
        per = ds["f_eff_N_m3"].sel(phi=0.035, B_T=0.1, arrangement="chains", i="z")
        assert v.shape == (1,) and per.shape == (1, 3)
        p = t.select("phi=0.035,B_T=0.1,arrangement=chains")
        # the same numbers as the project's own reader (stored, not recomputed: exact)
        assert float(v.squeeze()) == t.values["f_eff_N_m3"][p, :, 2].mean()
        assert np.array_equal(per.values[0], t.values["f_eff_N_m3"][p, :, 2])
        assert int(ds["n"].sel(phi=0.035, B_T=0.1, arrangement="chains").squeeze()) == 3


def test_interp_along_B_is_linear_and_matches_interpolate(table):
    t = read_table(table)
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        m = ds["f_eff_N_m3_mean"].sel(phi=0.0175, arrangement="dispersed", i="z").squeeze()
        got = float(m.interp(B_T=0.3))
        lo, hi = float(m.sel(B_T=0.1)), float(m.sel(B_T=0.5))
        # linear between the grid values 0.1 and 0.5 T (weights 1/2, 1/2); round-off only
        assert got == pytest.approx(0.5 * (lo + hi), rel=1e-12)
        est = interpolate(t, "f_eff_N_m3", component="z", phi=0.0175, B_T=0.3,
                          arrangement="dispersed")
        assert got == pytest.approx(est.mean, rel=1e-12)
        # a whole dataset interpolates too (string coordinates kept)
        ds3 = ds.interp(B_T=[0.05, 0.3])
        assert ds3["f_eff_N_m3_mean"].sizes["B_T"] == 2
        assert list(ds3["arrangement"].values) == ["dispersed", "chains"]


def test_units_and_cf_attributes_everywhere(table):
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        assert ds.attrs["Conventions"].startswith("CF-")
        assert ds.attrs["format"] == "mapsim-table" and int(ds.attrs["format_version"]) == 2
        for name in list(ds.data_vars) + list(ds.coords):
            assert "units" in ds[name].attrs, name
            assert ds[name].attrs.get("long_name"), name
        assert ds["B_T"].attrs["units"] == "T"
        assert ds["gradB_T_per_m"].attrs["units"] == "T/m"
        assert ds["arrangement"].attrs["units"] == "1"        # string coordinate
        assert ds["i"].attrs["units"] == "1" and list(ds["i"].values) == ["x", "y", "z"]
        assert ds["virial_stress_Pa_sd"].attrs["units"] == "Pa"
        assert ds["virial_stress_Pa_sd"].dims[-2:] == ("i", "j")


def test_multiindex_recipe_flattens_in_read_table_order(table):
    t = read_table(table)
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        axes = list(json.loads(ds.attrs["grid_axes"]))
        flat = ds.stack(point=axes)        # the documented recipe for a flat / sparse view
        keys = [tuple(p[a] for a in axes) for p in t.points]
        assert list(flat.indexes["point"]) == keys     # C order over the axes, as read_table
        v = flat["f_eff_N_m3_mean"].sel(i="x").transpose("point").values
        assert np.array_equal(v, t.values["f_eff_N_m3"][:, :, 0].mean(axis=1))
        some = flat["n"].sel(point=[keys[5], keys[1]])
        assert some.sizes["point"] == 2


def test_read_table_is_flat_and_in_grid_order(table):
    t = read_table(table)
    study = parse_study(STUDY, "xarray-test.toml")
    assert t.points == tuple(study.points())
    assert t.values["f_eff_N_m3"].shape == (study.n_points, 3, 3)
    assert t.values["virial_stress_Pa"].shape == (study.n_points, 3, 3, 3)
    assert np.array_equal(t.n, np.full(study.n_points, 3))
    axes = dict(study.axes)
    assert [dict(zip(axes, c)) for c in itertools.product(*axes.values())] == list(t.points)


def test_version_1_tables_are_still_read():
    # tests/data/table_format1.h5: the chain's table as written before format 2 (commit
    # 80fa043), kept as a fixture so that this test always runs
    old = REPO / "tests" / "data" / "table_format1.h5"
    t = read_table(old)
    assert int(t.attrs.get("format_version", 1)) == 1
    P = len(t.points)
    assert P == int(np.prod([len(v) for v in t.axes.values()]))
    assert all(v.shape[0] == P for v in t.values.values())
