"""The bad-input contract (issue 13): every case of tests/bad_input_cases.py, plus the resume
and atomic-write guarantees of batch runs and the numba cache fallback.

Each table case runs ``mapsim`` in a fresh copy of the fixtures and must be *clean*: the
expected exit code; a refusal is one line ``mapsim CMD: error: ...`` with the expected words;
no file left behind; no input changed (see :func:`bad_input_cases.run_case`).
"""
import json
import os
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

# the packages first: with tests/ on sys.path and the editable install's finder behind it,
# tests/homogenize (a directory without __init__.py) would become a namespace package
import homogenize.cli  # noqa: E402,F401
import micro  # noqa: E402,F401

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bad_input_cases as B  # noqa: E402

from homogenize.tables._evaluate import SyntheticEvaluator  # noqa: E402
from homogenize.tables._study import parse_study  # noqa: E402
from homogenize.tables.batch import parts_dir_for, read_table, run_batch  # noqa: E402
from micro.common.numba_cache import choose_cache_dir  # noqa: E402
from micro.common.validate import InputError  # noqa: E402


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    d = B.build_fixtures(tmp_path_factory.mktemp("bad_input") / "fixtures")
    for name, text in B.STUDIES.items():
        (d / name).write_text(text)
    return d


@pytest.mark.parametrize("case", B.CASES, ids=[c.id for c in B.CASES])
def test_case(case, fixtures, tmp_path):
    o = B.run_case(case, tmp_path / "run", fixtures)
    assert o.verdict == "clean", f"{o.verdict}: {o.detail}\n{o.stderr[-2000:]}"


# --------------------------------------------------------------------------- batch resume
@pytest.fixture(scope="module")
def client1():
    """In-process (threads) cluster with one worker, shared by the module."""
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as c, Client(c) as cl:
        yield cl


@pytest.fixture(scope="module")
def study():
    return parse_study(B.STUDY, "fixture.toml")


def _values(path):
    t = read_table(path)
    return {q: v.copy() for q, v in t.values.items()}, t.n.copy()


def test_damaged_parts_are_quarantined_and_recomputed(study, client1, tmp_path, capsys):
    ref = tmp_path / "ref.h5"
    run_batch(study, ref, client=client1, progress=False)
    out = tmp_path / "t.h5"
    parts = parts_dir_for(out)
    parts.mkdir()
    for p in parts_dir_for(ref).iterdir():
        (parts / p.name).write_bytes(p.read_bytes())
    names = sorted(p.name for p in parts.glob("*.npz"))
    (parts / names[0]).write_bytes(b"")                                   # zero length
    data = (parts / names[1]).read_bytes()
    (parts / names[1]).write_bytes(data[: len(data) // 2])               # truncated
    run_batch(study, out, client=client1, progress=False)
    q = sorted(p.name for p in (parts / "quarantine").iterdir())
    assert q == sorted(names[:2])                                         # moved aside, kept
    assert "moved to" in capsys.readouterr().err
    (va, na), (vb, nb) = _values(ref), _values(out)
    assert np.array_equal(na, nb)
    for k in va:
        assert np.array_equal(va[k], vb[k]), k                           # same seeds, same table


def test_stale_temps_cleaned_and_sidecar_rewritten(study, client1, tmp_path):
    out = tmp_path / "t.h5"
    run_batch(study, out, client=client1, progress=False)
    parts = parts_dir_for(out)
    # a run killed mid-write leaves hidden temporaries of the table, its side-car and a part
    stale = [tmp_path / ".t.h5.abc123.tmp", tmp_path / ".t.manifest.json.x1y2.tmp",
             parts / ".g00000_r0000_0123456789abcdef.npz.zz9.tmp"]
    for f in stale:
        f.write_bytes(b"\0" * 100)
    foreign = tmp_path / ".other.h5.abc.tmp"           # not ours: left alone
    foreign.write_bytes(b"x")
    side = tmp_path / "t.manifest.json"
    side.write_text(json.dumps({"seed": 1}))            # disagrees with the table's manifest
    run_batch(study, out, client=client1, progress=False)
    assert not any(f.exists() for f in stale) and foreign.exists()
    with h5py.File(out, "r") as h:
        inner = json.loads(h.attrs["manifest"])
    assert json.loads(side.read_text()) == inner
    assert not (tmp_path / ".t.h5.lock").exists()


def test_other_study_table_refused_unless_clean(study, client1, tmp_path):
    out = tmp_path / "t.h5"
    run_batch(study, out, client=client1, progress=False)
    other = parse_study(B.STUDY.replace("seed = 7", "seed = 8"), "other.toml")
    before = out.read_bytes()
    with pytest.raises(InputError, match="another study"):
        run_batch(other, out, client=client1, progress=False)
    assert out.read_bytes() == before
    run_batch(other, out, client=client1, progress=False, clean=True)
    assert read_table(out).attrs["study_toml"] == other.text


def test_deterministic_errors_not_retried(study, client1, tmp_path):
    calls = tmp_path / "calls"
    calls.mkdir()
    ev = SyntheticEvaluator(counter_dir=str(calls), fail_on=("g1_r2",))
    with pytest.raises(Exception, match="1 of 6 realizations failed") as exc:
        run_batch(study, tmp_path / "t.h5", evaluator=ev, client=client1, progress=False,
                  retries=3)
    assert "Traceback" not in str(exc.value)
    tags = [p.name.rsplit("_", 1)[0] for p in calls.iterdir()]
    assert tags.count("g1_r2") == 1                     # evaluated once, not 1 + 3 retries


def test_batch_lock_refuses_a_second_writer(study, tmp_path):
    import fcntl
    out = tmp_path / "t.h5"
    lock = out.with_name(".t.h5.lock")
    with open(lock, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(InputError, match="another mapsim batch"):
            run_batch(study, out, progress=False)
    assert not out.exists()


# --------------------------------------------------------------------------- numba cache
def test_numba_cache_fallback_only_when_needed(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    user = tmp_path / "home" / ".cache" / "numba"
    user.parent.mkdir(parents=True)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {}
    # the source tree is writable: numba's default works
    assert choose_cache_dir([src], user, tmp, env) is None
    # an explicit NUMBA_CACHE_DIR is always respected
    assert choose_cache_dir([tmp_path / "nope" / "x"], user, tmp, {"NUMBA_CACHE_DIR": "/c"}) \
        is None
    # neither the source tree nor the user cache can be written (simulated by a file where a
    # directory is needed): a private directory under tmp
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    d = choose_cache_dir([blocker / "pkg"], blocker / "numba", tmp, env)
    assert d is not None and Path(d).parent == tmp and Path(d).is_dir()
    assert (os.stat(d).st_mode & 0o777) == 0o700
    # the source tree is read-only but the user cache works: numba falls back itself
    assert choose_cache_dir([blocker / "pkg"], user, tmp, env) is None


# --------------------------------------------------------------------------- atomic writes
def test_stale_temporaries_of_a_name_are_removed_by_its_next_write(tmp_path):
    import time
    from micro.common.files import STALE_TEMP_SECONDS, atomic_write_text
    old = tmp_path / ".a.json.abcd1234.tmp"          # a writer killed an hour ago
    live = tmp_path / ".a.json.efgh5678.tmp"         # a writer busy right now
    other = tmp_path / ".b.json.abcd1234.tmp"        # another file's: not ours to judge
    for f in (old, live, other):
        f.write_bytes(b"\0" * 10)
    t = time.time() - 2 * STALE_TEMP_SECONDS
    os.utime(old, (t, t))
    os.utime(other, (t, t))
    atomic_write_text(tmp_path / "a.json", "{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, other.name,
                                                                 "a.json"])


def test_rve_sidecar_manifest_follows_the_file(tmp_path, capsys):
    from homogenize.cli import main
    from micro.rve import check_sidecar_manifest
    out = tmp_path / "r.h5"
    assert main(["rve", "--n", "20", "--phi", "0.05", "--seed", "2", "--out", str(out)]) == 0
    side = tmp_path / "r.manifest.json"
    good = json.loads(side.read_text())
    # a kill between the two writes of a later run: the side-car is of another seed
    side.write_text(json.dumps({**good, "seed": 1}))
    note = check_sidecar_manifest(out)
    assert "rewritten" in note and json.loads(side.read_text()) == good
    assert check_sidecar_manifest(out) is None
    # a file without a stored manifest: a disagreeing side-car is flagged, not rewritten
    side.write_text(json.dumps({"seed": 1}))
    with h5py.File(out, "r+") as f:
        del f.attrs["manifest_json"]
    assert "does not describe" in check_sidecar_manifest(out)
    assert main(["rve", "--load", str(out)]) == 0
    assert "does not describe" in capsys.readouterr().err


def test_untrusted_parts_are_quarantined_and_recomputed(study, client1, tmp_path, capsys):
    """Issue 38: a part whose values are NaN (or of the wrong seed) is never trusted on resume,
    and a FIFO among the parts is moved aside without being opened (it would block forever);
    the table equals the uninterrupted one."""
    ref = tmp_path / "ref.h5"
    run_batch(study, ref, client=client1, progress=False)
    out = tmp_path / "t.h5"
    parts = parts_dir_for(out)
    parts.mkdir()
    for p in parts_dir_for(ref).iterdir():
        (parts / p.name).write_bytes(p.read_bytes())
    names = sorted(p.name for p in parts.glob("*.npz"))
    with np.load(parts / names[0]) as z:
        arrays = {k: z[k] for k in z.files}
    nan = {k: (np.full_like(v, np.nan) if k.startswith("q_") else v) for k, v in arrays.items()}
    with open(parts / names[0], "wb") as fh:
        np.savez(fh, **nan)                                              # NaN values
    with np.load(parts / names[1]) as z:
        arrays = {k: z[k] for k in z.files}
    with open(parts / names[1], "wb") as fh:
        np.savez(fh, **{**arrays, "seed": np.int64(int(arrays["seed"]) + 1)})  # wrong seed
    (parts / names[2]).unlink()
    os.mkfifo(parts / names[2])                                          # a FIFO
    run_batch(study, out, client=client1, progress=False)
    assert sorted(p.name for p in (parts / "quarantine").iterdir()) == sorted(names[:3])
    err = capsys.readouterr().err
    assert "not finite" in err and "seed" in err and "not a regular file" in err
    (va, na), (vb, nb) = _values(ref), _values(out)
    assert np.array_equal(na, nb)
    for k in va:
        assert np.array_equal(va[k], vb[k]), k


def test_part_with_other_quantities_is_quarantined(study, client1, tmp_path, capsys):
    """Issue 38: a readable part that lacks a quantity the other parts hold (edited, or from
    another version) would make every resume fail in the aggregation; it is quarantined and
    recomputed instead."""
    ref = tmp_path / "ref.h5"
    run_batch(study, ref, client=client1, progress=False)
    out = tmp_path / "t.h5"
    parts = parts_dir_for(out)
    parts.mkdir()
    for p in parts_dir_for(ref).iterdir():
        (parts / p.name).write_bytes(p.read_bytes())
    name = sorted(p.name for p in parts.glob("*.npz"))[3]
    with np.load(parts / name) as z:
        arrays = {k: z[k] for k in z.files if k != "q_phi_eff"}
    with open(parts / name, "wb") as fh:
        np.savez(fh, **arrays)
    run_batch(study, out, client=client1, progress=False)
    assert [p.name for p in (parts / "quarantine").iterdir()] == [name]
    assert "the other parts" in capsys.readouterr().err
    (va, na), (vb, nb) = _values(ref), _values(out)
    for k in va:
        assert np.array_equal(va[k], vb[k]), k
