"""Batch runs on Dask: same table with 1 or 2 workers (threads and processes), resume after an
interruption without recomputation, dead workers retried, failures reported, table layout."""
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from homogenize.tables._evaluate import SyntheticEvaluator, synthetic_truth
from homogenize.tables._stats import summarize
from homogenize.tables._study import parse_study
from homogenize.tables.batch import (BatchError, parts_dir_for, read_table, run_batch)

STUDY = """
[study]
name = "batch-test"
seed = 2024
realizations = 3
n_particles = 100
evaluator = "synthetic"

[grid]
phi = [0.0175, 0.035]
B_T = [0.01, 0.1, 0.5]
gradB_T_per_m = 1.78
"""


@pytest.fixture(scope="module")
def study():
    return parse_study(STUDY, "batch-test.toml")


@pytest.fixture(scope="module")
def client1(inprocess_client):
    """In-process (threads) cluster with one worker, shared by the module (start-up is slow)."""
    with inprocess_client(1) as cl:
        yield cl


@pytest.fixture(scope="module")
def client2(inprocess_client):
    with inprocess_client(2) as cl:
        yield cl


@pytest.fixture(scope="module")
def reference(study, client1, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "table.h5"
    run_batch(study, out, client=client1, progress=False)
    return out


def _contents(path):
    """Every dataset and every attribute but the manifest (which holds times)."""
    out = {}
    with h5py.File(path, "r") as h:
        for k, v in h.attrs.items():
            if k != "manifest":
                out[f"@{k}"] = v
        for k in h:
            out[k] = h[k][()]
    return out


def _assert_same_table(a, b):
    ca, cb = _contents(a), _contents(b)
    assert sorted(ca) == sorted(cb)
    for k in ca:
        assert np.array_equal(np.asarray(ca[k]), np.asarray(cb[k])), k


def test_table_layout_units_and_statistics(study, reference):
    t = read_table(reference)
    assert t.axes == {"phi": (0.0175, 0.035), "B_T": (0.01, 0.1, 0.5), "gradB_T_per_m": (1.78,)}
    assert t.values["f_eff_N_m3"].shape == (6, 3, 3)
    assert t.units["f_eff_N_m3"] == "N/m^3" and t.units["M_eff_A_per_m"] == "A/m"
    assert "E_eff_Pa" not in t.values        # fem = false: not computed, not faked
    with h5py.File(reference, "r") as h:
        assert h["B_T"].attrs["units"] == "T"
        assert h["gradB_T_per_m"].attrs["units"] == "T/m"
        assert h["f_eff_N_m3_mean"].attrs["units"] == "N/m^3"
        # one dimension per grid axis (phi, B_T, gradB_T_per_m); flat point 4 = (1, 1, 0)
        assert h["virial_stress_Pa_sd"].shape == (2, 3, 1, 3, 3)
        assert h.attrs["study_toml"] == STUDY
        man = json.loads(h.attrs["manifest"])
        assert {"versions", "git_revision", "started_utc", "finished_utc"} <= set(man)
        assert man["started_utc"] <= man["finished_utc"]
        s = summarize(h["f_eff_N_m3"][1, 1, 0], 0.95)
        for key in ("mean", "sd", "ci_low", "ci_high"):
            assert np.array_equal(h[f"f_eff_N_m3_{key}"][1, 1, 0], s[key])
        assert np.array_equal(h["n"][()], np.full((2, 3, 1), 3))
        seeds = h["seed"][()]
    assert seeds[1, 1, 0, 1] == study.tasks()[4 * 3 + 1].seed_int()
    assert Path(str(reference).replace(".h5", ".manifest.json")).exists()
    # the stored values are those of the evaluator at that seed (reproducible one by one)
    t41 = study.tasks()[4 * 3 + 1]
    assert np.array_equal(t.values["f_eff_N_m3"][4, 1], SyntheticEvaluator()(t41)["f_eff_N_m3"])
    # and they follow the synthetic truth: 3 realizations within 6 sd of the mean
    mu, sd = synthetic_truth(t41.point, t41.settings)["f_eff_N_m3"]
    assert np.all(np.abs(t.values["f_eff_N_m3"][4] - mu) < 6 * sd)


def test_xarray_can_open_the_table(reference):
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    with xr.open_dataset(reference, engine="h5netcdf") as ds:
        assert ds["f_eff_N_m3_mean"].dims == ("phi", "B_T", "gradB_T_per_m", "i")
        assert "B_T" in ds.coords and "phi" in ds.coords
        assert ds["f_eff_N_m3_mean"].attrs["units"] == "N/m^3"
        sel = ds["f_eff_N_m3_mean"].sel(B_T=0.1, phi=0.035)
        assert sel.sizes == {"gradB_T_per_m": 1, "i": 3}


def test_two_workers_give_the_same_table_as_one(study, client2, reference, tmp_path):
    out = tmp_path / "t2.h5"
    run_batch(study, out, client=client2, progress=False)
    _assert_same_table(reference, out)


def test_processes_with_a_dying_worker_give_the_same_table(study, reference, tmp_path):
    """A real local cluster of 2 worker processes on loopback; the first attempt of one
    realization kills its worker process: the nanny restarts it, the scheduler reruns the
    task, and the table is bit-identical to the single-worker one."""
    die = tmp_path / "die"
    die.mkdir()
    calls = tmp_path / "calls"
    calls.mkdir()
    for t in study.tasks():               # arm the trap for one realization only
        if (t.grid_index, t.realization) != (2, 1):
            (die / f"g{t.grid_index}_r{t.realization}").touch()
    ev = SyntheticEvaluator(counter_dir=str(calls), die_once_dir=str(die))
    out = tmp_path / "tp.h5"
    run_batch(study, out, evaluator=ev, workers=2, processes=True, progress=False)
    _assert_same_table(reference, out)
    assert len(list(calls.glob("g2_r1_*"))) == 2        # died once, then retried


def test_interrupted_batch_resumes_without_recomputing(study, client1, reference, tmp_path):
    calls = tmp_path / "calls"
    calls.mkdir()
    ev = SyntheticEvaluator(counter_dir=str(calls))
    out = tmp_path / "ti.h5"
    with pytest.raises(KeyboardInterrupt):
        run_batch(study, out, evaluator=ev, client=client1, progress=False, _stop_after=7)
    assert not out.exists()                               # no half-written table
    parts = parts_dir_for(out)
    stored = {p.name.split("_")[0] + "_" + p.name.split("_")[1] for p in parts.glob("*.npz")}
    assert 7 <= len(stored) < 18
    assert not list(parts.glob(".*.tmp"))                # no half-written part
    before = {p.name for p in calls.iterdir()}
    run_batch(study, out, evaluator=ev, client=client1, progress=False)
    _assert_same_table(reference, out)
    new_calls = [p.name for p in calls.iterdir() if p.name not in before]
    recomputed = {"g" + n.split("_")[0][1:].lstrip("0").rjust(5, "0") + "_r"
                  + n.split("_")[1][1:].rjust(4, "0") for n in new_calls}
    assert not recomputed & stored                        # nothing finished is recomputed
    assert len(list(parts.glob("*.npz"))) == 18           # none lost, none duplicated
    # a third run finds everything done and evaluates nothing
    n_calls = len(list(calls.iterdir()))
    run_batch(study, out, evaluator=ev, client=None, progress=False)
    assert len(list(calls.iterdir())) == n_calls
    _assert_same_table(reference, out)


def test_failed_realizations_are_reported_and_the_rest_kept(study, client1, tmp_path):
    out = tmp_path / "tf.h5"
    ev = SyntheticEvaluator(fail_on=("g1_r2", "g4_r0"))
    with pytest.raises(BatchError, match="2 of 18 realizations failed") as exc:
        run_batch(study, out, evaluator=ev, client=client1, progress=False, retries=1)
    assert "grid point 1" in str(exc.value) and "synthetic failure of g1_r2" in str(exc.value)
    assert not out.exists()
    assert len(list(parts_dir_for(out).glob("*.npz"))) == 16
    # after the cause is fixed, the rerun computes the two missing ones only
    calls = tmp_path / "calls"
    calls.mkdir()
    run_batch(study, out, evaluator=SyntheticEvaluator(counter_dir=str(calls)), client=client1,
              progress=False, clean=True)
    assert sorted(p.name.split("_")[0] + p.name.split("_")[1] for p in calls.iterdir()) == \
        ["g1r2", "g4r0"]
    assert out.exists() and not parts_dir_for(out).exists()


def test_rewrite_keeps_a_table_equal_to_round_off_and_replaces_a_changed_one(study, tmp_path):
    """A rerun on another CPU changes the last digits of the results: the table already there is
    kept byte for byte (so a committed table is not rewritten); a change beyond
    TABLE_ROUNDOFF_RTOL (1e-8) writes the new table."""
    from homogenize.tables.batch import (TABLE_ROUNDOFF_RTOL, _part_path, _write_part, aggregate,
                                   write_table)
    evaluator = SyntheticEvaluator()
    parts = tmp_path / "parts"
    for t in study.tasks():
        k = t.key(evaluator.id)
        _write_part(_part_path(parts, t, k), t, k, evaluator(t))
    data = aggregate(study, parts, evaluator.id)
    man = {"config": "fixed"}
    out = tmp_path / "table.h5"
    write_table(out, study, data, man, evaluator.id)
    first = out.read_bytes()

    def scaled(factor):
        return {**data, "values": {q: v * factor for q, v in data["values"].items()},
                "summaries": {q: {k: v * factor for k, v in s.items()}
                              for q, s in data["summaries"].items()}}

    write_table(out, study, scaled(1.0 + 1e-13), man, evaluator.id)    # round-off: kept
    assert out.read_bytes() == first
    write_table(out, study, scaled(1.0 + 100 * TABLE_ROUNDOFF_RTOL), man, evaluator.id)
    assert out.read_bytes() != first                                   # a real change
    q = next(iter(data["values"]))
    with h5py.File(out) as h:
        np.testing.assert_allclose(h[q][()].ravel(), (data["values"][q] * (1 + 1e-6)).ravel(),
                                   rtol=1e-15)
