"""Fault tolerance of the batch (issue 38, item 3): a write that fails for lack of space, a
worker killed mid-task, the run (with its local scheduler) killed and resumed.

Fast tests: 100 synthetic realizations on a threads cluster with ``OSError(ENOSPC)`` injected
at the part and the table writes; the messages of killed workers and of a lost scheduler.
Scenario tests: ``results/reliability/fault_tolerance.py`` (real kills of a worker, of the
run and of an external scheduler, a real size-limited
tmpfs where the machine allows a mount, else an injected ENOSPC; the real ``rve`` evaluator on
2 worker processes, the table compared with an uninterrupted 1-worker run): CI runs 24
realizations without FEM; MAPSIM_FULL=1 runs the script's 100 realizations with FEM.
"""
import errno
import os
from pathlib import Path

import h5py
import numpy as np
import pytest

import homogenize.tables.batch as tables
from homogenize.tables._evaluate import SyntheticEvaluator
from homogenize.tables._study import parse_study
from homogenize.cli import main
from homogenize.tables.batch import (BatchError, StorageError, parts_dir_for, run_batch)

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "results" / "reliability" / "fault_tolerance.py"
FULL = os.environ.get("MAPSIM_FULL") == "1"

STUDY = """
[study]
name = "faults-test"
seed = 38
realizations = 50
n_particles = 100
evaluator = "synthetic"

[grid]
phi = [0.0175, 0.035]
B_T = 0.1
gradB_T_per_m = 1.78
"""
N = 100


@pytest.fixture(scope="module")
def study():
    return parse_study(STUDY, "faults-test.toml")


@pytest.fixture(scope="module")
def client2(inprocess_client):
    with inprocess_client(2) as cl:
        yield cl


@pytest.fixture(scope="module")
def reference(study, client2, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "table.h5"
    run_batch(study, out, client=client2, progress=False)
    return out


def _same_table(a, b):
    with h5py.File(a, "r") as ha, h5py.File(b, "r") as hb:
        assert sorted(ha) == sorted(hb)
        for k in hb:
            assert np.array_equal(ha[k][()], hb[k][()]), k
        for k in hb.attrs:
            if k != "manifest":
                assert np.array_equal(np.asarray(ha.attrs[k]), np.asarray(hb.attrs[k])), k


def _temps(out):
    return [p.name for d in (out.parent, parts_dir_for(out)) if d.is_dir()
            for p in d.iterdir() if p.name.endswith(".tmp")]


def _no_room_after(n, monkeypatch):
    """np.savez in tables: n parts are written, then each write puts a few bytes on disk and
    fails with ENOSPC (a disk that fills up mid-write)."""
    real = tables.np.savez
    left = {"n": n}

    def savez(fh, **arrays):
        if left["n"] <= 0:
            fh.write(b"PK\x03\x04half a part")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        left["n"] -= 1
        return real(fh, **arrays)

    monkeypatch.setattr(tables.np, "savez", savez)


def _stored(out):
    return {p.name: p.stat().st_mtime_ns for p in parts_dir_for(out).glob("g*.npz")}


def test_disk_full_at_a_part_keeps_the_rest_and_the_rerun_finishes(study, client2, reference,
                                                                   tmp_path, monkeypatch):
    out = tmp_path / "t.h5"
    calls = tmp_path / "calls"
    calls.mkdir()
    ev = SyntheticEvaluator(counter_dir=str(calls))
    _no_room_after(40, monkeypatch)
    with pytest.raises(StorageError) as exc:
        run_batch(study, out, evaluator=ev, client=client2, progress=False)
    msg = str(exc.value)
    assert isinstance(exc.value, BatchError) and "\n" not in msg
    assert f"cannot write {parts_dir_for(out)}{os.sep}g0" in msg
    assert "No space left on device" in msg and "40 of 100 realizations are stored" in msg
    assert "make room" in msg and "computes only the 60 missing" in msg
    assert not out.exists() and not _temps(out)          # no half part, no table
    before = _stored(out)
    assert len(before) == 40
    for p in parts_dir_for(out).glob("g*.npz"):          # every stored part reads back whole
        assert tables._read_part(p, p.stem.split("_", 2)[2]) is not None
    monkeypatch.undo()                                   # room made
    old_calls = set(calls.iterdir())
    run_batch(study, out, evaluator=ev, client=client2, progress=False)
    _same_table(out, reference)
    after = _stored(out)
    assert len(after) == N and all(after[k] == v for k, v in before.items())
    # the resume evaluated none of the stored ones
    tags = {p.name.rsplit("_", 1)[0] for p in set(calls.iterdir()) - old_calls}
    stored = {f"g{int(n[1:6])}_r{int(n[8:12])}" for n in before}
    assert not tags & stored and len(tags) <= N - 40


def test_disk_full_at_the_table_keeps_every_part(study, client2, reference, tmp_path,
                                                 monkeypatch):
    out = tmp_path / "t.h5"
    calls = tmp_path / "calls"
    calls.mkdir()
    ev = SyntheticEvaluator(counter_dir=str(calls))
    real = tables._write_table_file

    def full(tmp, *a, **k):
        real(tmp, *a, **k)
        raise OSError(errno.ENOSPC, "Can't synchronously write data (file write failed...)")

    monkeypatch.setattr(tables, "_write_table_file", full)
    with pytest.raises(StorageError, match=f"cannot write {out}: No space left on device "
                                           f"\\(errno {errno.ENOSPC}\\); all 100 realizations"):
        run_batch(study, out, evaluator=ev, client=client2, progress=False)
    assert not out.exists() and not _temps(out) and len(_stored(out)) == N
    monkeypatch.undo()
    n_calls = len(list(calls.iterdir()))
    run_batch(study, out, evaluator=ev, client=client2, progress=False)
    assert len(list(calls.iterdir())) == n_calls         # nothing recomputed
    _same_table(out, reference)


def test_cli_disk_full_is_one_line_naming_the_file_exit_1(tmp_path, monkeypatch, capsys):
    from dask.distributed import LocalCluster
    study = tmp_path / "s.toml"
    study.write_text(STUDY.replace("realizations = 50", "realizations = 5"))
    out = tmp_path / "t.h5"
    _no_room_after(3, monkeypatch)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address="127.0.0.1:0") as c:
        rc = main(["batch", str(study), "--out", str(out), "--scheduler", c.scheduler_address,
                   "--no-progress"])
    err = [ln for ln in capsys.readouterr().err.splitlines()
           if ln.strip() and not ln[:4].isdigit()]           # not Dask's timestamped log
    assert rc == 1, err
    assert len(err) == 1 and err[0].startswith(f"mapsim batch: cannot write {parts_dir_for(out)}")
    assert "No space left on device" in err[0] and "3 of 10 realizations are stored" in err[0]


def test_killed_worker_and_lost_scheduler_are_told_in_words(tmp_path):
    from distributed.client import FutureCancelledError
    from distributed.scheduler import KilledWorker

    class W:
        address = "tcp://127.0.0.1:1"

    f = tables._failure_of(KilledWorker("mapsim-x", W(), tables.ALLOWED_WORKER_DEATHS))
    assert f.kind == "KilledWorker" and "died 4 times" in f.message and not f.input_error
    tasks = parse_study(STUDY, "s.toml").tasks()[:30]
    lost = [(t, tables._failure_of(FutureCancelledError(f"mapsim-{i}",
                                                        "scheduler-connection-lost")))
            for i, t in enumerate(tasks)]
    with pytest.raises(BatchError) as exc:
        tables._raise_failures(lost, N, tmp_path / "t.parts")
    msg = str(exc.value)
    assert "\n" not in msg and "lost the connection to the Dask scheduler" in msg
    assert "30 of 100 realizations not done" in msg and "run the same command again" in msg


def test_local_cluster_reschedules_a_killed_task_a_bounded_number_of_times():
    """The retry policy for dead workers is mapsim's, not the user's Dask configuration."""
    import dask
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
            tables.dask_client(None, 1, False) as cl:
        assert cl.cluster.scheduler.allowed_failures == tables.ALLOWED_WORKER_DEATHS


# --------------------------------------------------------------------------- scenarios
@pytest.fixture(scope="module")
def measured(load_script, tmp_path_factory, request):
    """The script's scenarios, once per size (CI: 24 realizations, no FEM)."""
    cache = {}

    def get(full):
        if full not in cache:
            ft = load_script(SCRIPT)
            cfg = dict(ft.FULL) if full else dict(realizations=12, fem=False)
            res = ft.measure(tmp_path_factory.mktemp("ft"), **cfg, log=lambda m: None)
            cache[full] = (ft, res)
        return cache[full]
    return get


@pytest.mark.parametrize("full", [pytest.param(True, marks=pytest.mark.slow), False])
@pytest.mark.parametrize("scenario", ["worker_killed", "run_killed", "scheduler_restarted",
                                      "disk_full"])
def test_fault_scenario_loses_nothing_and_gives_the_reference_table(measured, full, scenario):
    if full and not FULL:
        pytest.skip("full version (100 realizations with FEM): MAPSIM_FULL=1")
    ft, res = measured(full)
    r = res[scenario]
    assert r["table"]["equal"] == "bitwise", r["table"]
    assert ft.verdicts(res)[scenario], r
    if scenario == "worker_killed":
        assert r["kills"] and r["outcome"] == "finished"     # no rerun needed
    elif scenario in ("run_killed", "scheduler_restarted"):
        assert r["resume"]["recomputed"] == res["study"]["realizations"] - r["parts_after_kill"]
    elif r.get("tmpfs"):
        assert r["parts_full"]["exit"] == 1 and r["table_full"]["exit"] == 1
