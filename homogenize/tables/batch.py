"""Batch runs of random RVEs on Dask, and the effective-parameter tables they produce.

A study (:mod:`homogenize.tables._study`) is a grid of conditions times a number of random
realizations. :func:`run_batch` evaluates every realization on a Dask cluster (a local one,
or an existing one via its scheduler address) and stores each result the moment it arrives, as
one small file ``<table>.parts/g<grid>_r<realization>_<hash>.npz`` written atomically by the
client process only. The hash covers everything that determines the result (evaluator
version, for real RVEs including a hash of the physics source code; grid point, settings,
seed), so running the same command again resumes: stored
realizations are loaded, not recomputed, and a changed study never reuses stale results.
The table is then aggregated from the stored parts in grid order, so it is identical whatever
the number of workers, the order of completion, or how often the batch was interrupted.

Table layout (HDF5 / netCDF-4, format version 2, CF-1.10 attributes)
--------------------------------------------------------------------
The grid of a study is always the full Cartesian product of its axes, so each grid axis is a
dimension of its own and the table is a regular xarray grid::

    import xarray as xr
    ds = xr.open_dataset("results/chain/table.h5", engine="h5netcdf")
    ds["f_eff_N_m3_mean"].sel(phi=0.035, B_T=0.1, i="z")           # one grid point
    ds["f_eff_N_m3_mean"].sel(phi=0.035, i="z").interp(B_T=0.3)    # linear in B

Dimensions: one per grid axis, in the study's canonical order (e.g. ``phi``, ``arrangement``,
``B_T``, ``gradB_T_per_m``; axes with one value are dimensions of length 1), then
``realization``, ``i`` and ``j`` (Cartesian components of vectors and tensors).

* coordinate variables: each grid axis (float64, or strings such as ``arrangement``), the
  ``realization`` index, and ``i``, ``j`` = ``"x", "y", "z"`` (strings, so ``.sel(i="z")``);
  every one with ``units`` (``"1"`` for dimensionless and string coordinates) and
  ``long_name``;
* for each quantity Q (``f_eff_N_m3``, ``phi_eff``, ``d_eff``, ``M_eff_A_per_m``,
  ``virial_stress_Pa``, ``volume_m3``, ``phi_rve``; with ``fem = true`` also ``E_eff_Pa``,
  ``nu_eff``, ``stress_mag_Pa``, ``strain_mag``; with ``evaluator = "relax"``:
  ``M_eff_A_per_m``, ``virial_stress_Pa``, ``min_gap_m``, ``displacement_rms_m``,
  ``n_contacts``, ``chain_fraction``, and with ``fem = true`` ``strain_mag``,
  ``strain_parallel``, ``strain_perpendicular``, ``stress_mag_Pa``, ``E_eff_parallel_Pa``,
  ``E_eff_perpendicular_Pa``, ``strain_affine_parallel``, ``M_eff_affine_A_per_m``): ``Q_mean``, ``Q_sd`` (sample sd, ddof 1),
  ``Q_ci_low``, ``Q_ci_high`` (Student-t interval of the mean at the study's confidence), shape
  (*grid, [i, [j]]), and the per-realization values ``Q`` (*grid, realization, [i, [j]]); each
  with ``units`` and ``long_name``;
* ``n`` (*grid): realizations per point; ``seed`` (*grid, realization): the integer seed of
  each realization (``generate_rve(..., seed=...)`` reproduces it alone);
* root attributes: ``Conventions = "CF-1.10"``, ``title``, ``source``,
  ``format = "mapsim-table"``, ``format_version = 2``, ``confidence``, ``grid_axes`` (JSON:
  axis -> values), ``grid_shape``, ``study_toml`` (the study file text), ``evaluator``,
  ``manifest`` (JSON: versions, git revision, start and end times); the same manifest is
  written to ``<table>.manifest.json``.

The flat grid-point index of :func:`read_table` (and of the seeds, ``study.tasks()``) is the C
order over the grid dimensions. A flat view, or a sparse (non-product) subset of points, is an
xarray MultiIndex::

    flat = ds.stack(point=list(json.loads(ds.attrs["grid_axes"])))  # point = MultiIndex
    some = flat.sel(point=[(0.035, 0.1, 1.78), (0.0175, 0.5, 1.78)])  # tuples in axis order

Version 1 files (a flat ``point`` dimension with the axes as ``point`` coordinates) are still
read by :func:`read_table`.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import collections
import contextlib
import datetime as _dt
import errno
import fcntl
import json
import math
import os
import signal
import threading
import sys
import tomllib
import zipfile
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from micro.common.files import (atomic_path, hdf5_agree, is_regular_file, manifest as _manifest,
                       open_regular, write_json)
from micro.common.validate import InputError

from homogenize.tables._evaluate import COARSE, FEM_QUANTITIES, QUANTITIES, RELAX_FEM_QUANTITIES, get_evaluator
from homogenize.tables.resolution import FILLER_BIAS_REL, ORDER, combined_interval, discretization_error
from micro.materials import PDMS
from homogenize.tables._stats import summarize, t_half_width
from homogenize.tables._study import Study, Task, _unit_of, load_study
from micro.common.progress import progress_bar
import shutil
import h5py
from micro.common.files import open_hdf5
import itertools

__all__ = ["run_batch", "aggregate", "read_table", "Table", "Estimate", "BatchError",
           "StorageError", "parts_dir_for", "interpolate", "body_force_from_table",
           "modulus_from_table",
           "load_study", "dask_client"]

FORMAT = "mapsim-table"
FORMAT_VERSION = 2
_COMPONENTS = ("x", "y", "z")


class BatchError(RuntimeError):
    """Some realizations failed for good (after retries); the others are stored."""


class StorageError(BatchError):
    """A result or the table could not be written (disk full, quota, I/O error). Every part
    stored before is kept, nothing half-written is left or trusted (atomic writes), and the
    same command run again computes only what is missing (exit 1, like :class:`BatchError`)."""


#: errno values for which the remedy is to make room
_NO_ROOM = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


def _storage_error(path: Path, exc: OSError, n_stored: int, n_tasks: int,
                   parts: Path) -> StorageError:
    """One line: the file that could not be written, why, what is kept, what to do."""
    why = os.strerror(exc.errno) if exc.errno else (str(exc).splitlines() or [""])[0]
    missing = n_tasks - n_stored
    kept = (f"all {n_tasks} realizations are stored in {parts}" if not missing else
            f"{n_stored} of {n_tasks} realizations are stored in {parts}")
    todo = ("computes nothing and writes the table" if not missing else
            f"computes only the {missing} missing")
    room = ("make room (or give --out on another file system) and "
            if exc.errno in _NO_ROOM else "")
    return StorageError(f"cannot write {path}: {why} (errno {exc.errno}); {kept}, nothing "
                        f"half-written is kept; {room}run the same command again: it {todo}")


def parts_dir_for(out) -> Path:
    """Where the per-realization results of the table ``out`` are kept."""
    out = Path(out)
    return out.with_name(out.stem + ".parts")


def _utcnow() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- parts
def _part_path(parts: Path, task: Task, key: str) -> Path:
    return parts / f"g{task.grid_index:05d}_r{task.realization:04d}_{key}.npz"


def _write_part(path: Path, task: Task, key: str, result: dict) -> None:
    arrays = {f"q_{k}": np.asarray(v, dtype=np.float64) for k, v in result.items()}
    arrays["seed"] = np.int64(task.seed_int())
    arrays["key"] = np.array(key)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


#: what a damaged part file raises on reading (truncated zip, zero length, bad array header)
_DAMAGED = (OSError, ValueError, TypeError, KeyError, EOFError, zipfile.BadZipFile)


def check_part(out: dict, key: str, stored_key, seed: int | None = None) -> dict:
    """Validate a part read back as strictly as a fresh result of an evaluator: the key it
    was stored under, the seed of its task, known quantities only, each of its shape and
    finite. Raises ``ValueError`` naming the first problem."""
    if str(stored_key) != key:
        raise ValueError(f"stored key {str(stored_key)!r} is not {key!r}")
    if seed is not None and out.get("__seed__") != seed:
        raise ValueError(f"stored seed {out.get('__seed__')} is not the task's seed {seed}")
    qs = [q for q in out if q != "__seed__"]
    if not qs:
        raise ValueError("no quantities stored")
    for q in qs:
        if q not in QUANTITIES:
            raise ValueError(f"unknown quantity {q!r}")
        a = out[q]
        if a.shape != QUANTITIES[q][1] or not np.issubdtype(a.dtype, np.floating):
            raise ValueError(f"{q} has shape {a.shape} and type {a.dtype}, expected float "
                             f"{QUANTITIES[q][1]}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{q} is not finite ({a.ravel()[:3]}...)")
    return out


def _read_part(path: Path, key: str, seed: int | None = None) -> dict | None:
    """The stored result, or None if there is none usable (then it is recomputed).

    A part that exists but cannot be read (zero length or truncated by a crash, not a regular
    file, a key that does not match its name) or whose values fail :func:`check_part` (NaN, a
    wrong shape or seed) is quarantined: renamed to ``quarantine/<name>`` in the parts
    directory, never deleted, and a note goes to stderr. A FIFO or device is never opened
    in blocking mode (:func:`micro.common.files.open_regular`).
    """
    try:
        # our own handle: np.load leaks the one it opens when the file is empty
        with open_regular(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            out = {k[2:]: z[k].copy() for k in z.files if k.startswith("q_")}
            out["__seed__"] = int(z["seed"])
            return check_part(out, key, z["key"], seed)
    except FileNotFoundError:
        return None
    except _DAMAGED as exc:
        _quarantine(path, f"{type(exc).__name__}: {exc}")
        return None


def _quarantine(path: Path, why: str) -> None:
    """Move an unusable part aside (``quarantine/`` beside it) so that it is recomputed."""
    qdir = path.parent / "quarantine"
    try:
        qdir.mkdir(exist_ok=True)
        dest = qdir / path.name
        k = 1
        while dest.exists():
            dest = qdir / f"{path.name}.{k}"
            k += 1
        os.replace(path, dest)
    except OSError as exc:
        raise InputError(f"{path}: unreadable part ({why}) that cannot be moved aside "
                         f"({exc.strerror}); remove it by hand") from None
    print(f"mapsim: unusable part {path.name} ({why.splitlines()[0][:120]}) moved to {dest}; "
          f"it is recomputed", file=sys.stderr)


def _clean_stale_temps(directory: Path, names) -> int:
    """Remove hidden temporary files ``.NAME.*.tmp`` of our own atomic writes (left by a
    process killed mid-write) for the given file names, or for every ``.npz`` part when
    ``names`` is None. Only called while this process holds the batch lock."""
    n = 0
    if not directory.is_dir():
        return 0
    for f in directory.iterdir():
        name = f.name
        if not (name.startswith(".") and name.endswith(".tmp")) or not f.is_file():
            continue
        base = name[1:].rsplit(".", 2)[0]     # .NAME.XXXXXXXX.tmp -> NAME
        ours = (base.endswith(".npz") and base.startswith("g")) if names is None \
            else base in names
        if ours:
            with contextlib.suppress(FileNotFoundError):
                f.unlink()
                n += 1
    return n


@contextlib.contextmanager
def _batch_lock(out: Path):
    """Exclusive lock on a table being written: a second batch on the same ``--out`` is refused
    (so temporary files found while holding it are stale: their writer is gone)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    lock = out.with_name(f".{out.name}.lock")
    fh = open(lock, "a+")
    try:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{out}: another mapsim batch is writing this table now; wait for "
                             f"it or give another --out") from None
        yield
    finally:
        fh.close()
        with contextlib.suppress(OSError):
            lock.unlink()


def _check_existing_table(out: Path, study: Study, clean: bool) -> None:
    """Refuse to replace an existing file that is not this study's table (unless ``clean``),
    and any of the table's companions (the side-car manifest, the parts directory) that
    exists as something else than a regular file or a directory (never opened: a FIFO would
    block)."""
    side = out.with_name(out.stem + ".manifest.json")
    for p, want_dir in ((out, False), (side, False), (parts_dir_for(out), True)):
        if not os.path.lexists(p):
            continue
        ok = os.path.isdir(p) if want_dir else is_regular_file(p)
        if not ok:
            what = "a directory" if want_dir else "a regular file"
            raise InputError(f"{p} exists and is not {what} (a FIFO, device, link to nothing "
                             f"or the wrong kind); the table {out} needs it as {what}: move it "
                             f"away")
    if not out.exists():
        return
    try:
        with h5py.File(out, "r") as h:
            fmt = h.attrs.get("format")
            name = h.attrs.get("study_name")
            toml = h.attrs.get("study_toml")
    except OSError:
        fmt = name = toml = None
    if isinstance(fmt, bytes):
        fmt = fmt.decode()
    if fmt != FORMAT:
        if clean:
            return
        raise InputError(f"--out {out} exists and is not a mapsim table; refusing to replace "
                         f"it (give another --out, or --clean to replace it)")
    seed = None
    with contextlib.suppress(tomllib.TOMLDecodeError, TypeError, AttributeError, UnicodeError):
        text = toml.decode() if isinstance(toml, bytes) else toml
        seed = tomllib.loads(text).get("study", {}).get("seed")
    if isinstance(name, bytes):
        name = name.decode()
    if (name, seed) != (study.name, study.seed) and not clean:
        raise InputError(f"--out {out} holds the table of another study (name {name!r}, seed "
                         f"{seed}; this study: {study.name!r}, seed {study.seed}); give another "
                         f"--out, or --clean to replace it")


def reconcile_manifest(table) -> str | None:
    """Make the side-car ``<table>.manifest.json`` agree with the manifest stored inside the
    table (which is authoritative: both are written by one run, the table first, so a kill
    between the two writes leaves a stale side-car). Returns a note when it was rewritten (or
    could not be), None when it agreed."""
    table = Path(table)
    side = table.with_name(table.stem + ".manifest.json")
    try:
        with h5py.File(table, "r") as h:
            inner = h.attrs.get("manifest")
    except OSError:
        return None
    if inner is None:
        return None
    inner = inner.decode() if isinstance(inner, bytes) else inner
    try:
        want = json.loads(inner)
    except ValueError:
        return None
    try:
        with open_regular(side, "r", encoding="utf-8") as fh:
            have = json.loads(fh.read())
    except (OSError, ValueError):
        have = None
    if have == want:
        return None
    try:
        write_json(side, want)
    except OSError as exc:
        return f"{side} disagrees with the manifest inside {table} (authoritative) and cannot " \
               f"be rewritten ({exc.strerror})"
    return f"{side} disagreed with the manifest inside {table} (authoritative): rewritten"


@dataclass(frozen=True)
class _Failure:
    """A realization whose evaluation raised a deterministic error (returned, not raised, so
    that Dask does not retry it: the same seed would fail the same way)."""

    kind: str
    message: str
    input_error: bool


#: errors that may pass on another try (memory pressure, a file system hiccup): raised on the
#: worker so that Dask retries them; every other error is deterministic and returned
_TRANSIENT = (MemoryError, OSError)


def _run_task(task: Task, evaluator):
    """What a worker runs (module level, so it pickles by reference): the result dict, or a
    :class:`_Failure` for a deterministic error."""
    try:
        return evaluator(task)
    except _TRANSIENT:
        raise
    except Exception as exc:                 # deterministic: report once, do not retry
        text = str(exc).strip().splitlines()
        return _Failure(type(exc).__name__, text[0] if text else "",
                        isinstance(exc, InputError))


def _run_group(tasks, evaluator):
    """Several realizations in one worker call, in order (the field steps of one relax
    continuation: the evaluator computes the sweep once and each step picks its point)."""
    return [_run_task(t, evaluator) for t in tasks]


def _task_groups(todo, evaluator):
    """Tasks submitted together: one per realization, or for an evaluator with ``sweeps``
    (relax) all grid points of one seed group and realization, so that one worker computes
    each continuation once."""
    if not getattr(evaluator, "sweeps", False):
        return [[tk] for tk in todo]
    groups: dict = {}
    for t, k in todo:
        groups.setdefault((t.seed_group, t.realization), []).append((t, k))
    return list(groups.values())


#: a task whose worker process dies (SIGKILL, out of memory, a crash in compiled code) is
#: rescheduled on another worker by the local scheduler up to this many times, then reported as
#: failed (Dask's ``allowed-failures``; set here, not from the user's Dask configuration). An
#: external scheduler (``--scheduler``) applies its own setting.
ALLOWED_WORKER_DEATHS = 3


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int | None, processes: bool):
    """The Dask client a batch runs on: connected to ``scheduler`` (an address; refused with one
    message when it cannot connect), or a local cluster of ``workers`` workers (``processes``:
    worker processes with nannies, else threads), closed on leaving the ``with`` block."""
    from dask.distributed import Client, LocalCluster
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler "
                             f"({exc})") from None
        with client:
            if not client.scheduler_info().get("workers"):     # say why nothing moves
                print(f"mapsim: no Dask worker is connected to {scheduler} (yet); waiting for "
                      f"one (start workers with: dask worker {scheduler})", file=sys.stderr)
            yield client
        return
    n = workers or min(2, os.cpu_count() or 1)
    kwargs = dict(n_workers=n, threads_per_worker=1, processes=processes,
                  dashboard_address="127.0.0.1:0",
                  scheduler_kwargs={"allowed_failures": ALLOWED_WORKER_DEATHS})
    if processes:
        # loopback only; one numba/BLAS thread per worker process (no oversubscription)
        # workers log errors only: their warnings on cancelled tasks after Ctrl-C are noise
        # (failures reach the user through this process)
        kwargs.update(host="127.0.0.1", env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                                             "DASK_LOGGING__DISTRIBUTED": "error"})
    # Ctrl-C reaches the whole process group: worker processes started while SIGINT is
    # ignored keep ignoring it (Python installs its KeyboardInterrupt handler only over the
    # default disposition), so only this process reacts -- one line, no worker tracebacks
    ignore = processes and threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if ignore else None
    try:
        cluster = LocalCluster(**kwargs)
    finally:
        if ignore:
            signal.signal(signal.SIGINT, previous)
    with cluster, Client(cluster) as client:
        yield client


def run_batch(study, out, *, evaluator=None, workers: int | None = None,
              scheduler: str | None = None, processes: bool = True, client=None,
              retries: int = 2, progress: bool = True, clean: bool = False,
              _stop_after: int | None = None) -> Path:
    """Evaluate every realization of ``study`` on Dask and write the table ``out``.

    Parameters
    ----------
    study : Study or path
        The study (or its TOML file).
    out : path
        Table file (HDF5). Results of single realizations go to :func:`parts_dir_for` ``(out)``
        as they arrive; a second call resumes from them.
    evaluator : callable, optional
        Overrides the study's evaluator (tests: a :class:`SyntheticEvaluator` with counters).
    workers : int, optional
        Local cluster size (default: 2, or the number of cores if fewer).
    scheduler : str, optional
        Address ``tcp://HOST:PORT`` of an existing Dask scheduler (then ``workers`` is unused).
    processes : bool
        Local cluster of processes (default) or of threads in this process.
    client : dask.distributed.Client, optional
        Use this client (and its cluster) instead of creating one.
    retries : int
        How often a realization whose task raised is resubmitted (a worker that dies is
        replaced by its nanny and its tasks rescheduled by the scheduler, up to
        :data:`ALLOWED_WORKER_DEATHS` times per task).
    clean : bool
        Remove the parts directory once the table is written.

    Returns
    -------
    Path of the table. Raises :class:`BatchError` if realizations failed for good (the table is
    then not written; the finished realizations are kept for the next run), and its subclass
    :class:`StorageError` when a part or the table cannot be written (disk full: the message
    names the file; every part stored before is kept, none is half-written).
    """
    if not isinstance(study, Study):
        study = load_study(study)
    out = Path(out)
    _check_existing_table(out, study, clean)
    evaluator = evaluator or get_evaluator(study.evaluator, fem=study.fem, **study.synthetic)
    with _batch_lock(out):
        return _run_batch_locked(study, out, evaluator, workers=workers, scheduler=scheduler,
                                 processes=processes, client=client, retries=retries,
                                 progress=progress, clean=clean, _stop_after=_stop_after)


def _run_batch_locked(study, out, evaluator, *, workers, scheduler, processes, client, retries,
                      progress, clean, _stop_after) -> Path:
    started = _utcnow()
    parts = parts_dir_for(out)          # created with the first stored result
    _clean_stale_temps(parts, None)
    _clean_stale_temps(out.parent, {out.name, out.stem + ".manifest.json"})
    if out.exists():
        note = reconcile_manifest(out)
        if note:
            print(f"mapsim: {note}", file=sys.stderr)
    tasks = study.tasks()
    keys = [t.key(evaluator.id) for t in tasks]
    todo = _parts_to_compute(parts, tasks, keys)
    n_done = len(tasks) - len(todo)
    failures = []
    if todo:
        ctx = contextlib.nullcontext(client) if client is not None else \
            dask_client(scheduler, workers, processes)
        with ctx as cl, progress_bar(total=len(tasks), initial=n_done, desc=f"batch {study.name}",
                                     unit="RVE", file=sys.stderr, disable=not progress,
                                     dynamic_ncols=True) as bar:
            from dask.distributed import as_completed
            by_key = {}
            futures = []
            for group in _task_groups(todo, evaluator):
                if len(group) == 1:
                    (t, k), = group
                    fut = cl.submit(_run_task, t, evaluator, key=f"mapsim-{k}",
                                    retries=retries, pure=False)
                else:
                    fut = cl.submit(_run_group, [t for t, _ in group], evaluator,
                                    key=f"mapsim-{group[0][1]}-{len(group)}",
                                    retries=retries, pure=False)
                by_key[fut.key] = group
                futures.append(fut)
            stored = 0
            for fut in as_completed(futures):
                group = by_key[fut.key]
                # a result held by a worker that died after finishing is "lost": the scheduler
                # recomputes it because this client still holds the future, so wait for it;
                # only an error (after retries) or a cancellation is a failure
                result = exc = None
                if fut.status == "error":
                    exc = fut.exception()
                else:
                    try:
                        result = fut.result()
                    except Exception as e:          # cancelled, or failed on recomputation
                        exc = e
                results = result if len(group) > 1 and exc is None else [result] * len(group)
                for (t, k), res in zip(group, results):
                    if isinstance(res, _Failure):
                        failures.append((t, res))
                    elif exc is not None:
                        failures.append((t, _failure_of(exc)))
                    else:
                        path = _part_path(parts, t, k)
                        try:           # atomic: on failure no part, and no temporary, is left
                            _write_part(path, t, k, res)
                        except OSError as e:       # disk full: stop, say where, keep the rest
                            with contextlib.suppress(Exception):
                                cl.cancel(futures)         # a shared cluster: free it
                            raise _storage_error(path, e, n_done + stored, len(tasks),
                                                 parts) from None
                        stored += 1
                        bar.update(1)
                fut.release()
                if _stop_after is not None and stored >= _stop_after:
                    raise KeyboardInterrupt        # tests: an interruption after some results
    if failures:
        _raise_failures(failures, len(tasks), parts)
    data = aggregate(study, parts, evaluator.id)
    man = _manifest(study.config(), study.seed, started_utc=started, finished_utc=_utcnow(),
                    evaluator=evaluator.id, table=str(out))
    side = out.with_name(out.stem + ".manifest.json")
    target = out
    try:                      # atomic writes: on failure the previous file (or none) stays
        write_table(out, study, data, man, evaluator.id)
        target = side
        write_json(side, man)
    except OSError as e:
        raise _storage_error(target, e, len(tasks), len(tasks), parts) from None
    if clean:
        shutil.rmtree(parts, ignore_errors=True)
    return out


#: the kind of failure of a task whose scheduler went away (it is not the task's fault)
_LOST = "SchedulerLost"
#: a Dask future's cancellation (its FutureCancelledError derives from the first)
_CANCELLED = (concurrent.futures.CancelledError, asyncio.CancelledError)


def _failure_of(exc: BaseException) -> _Failure:
    """What the user is told about a task that raised on the cluster (after Dask's retries)."""
    name = type(exc).__name__
    if name == "KilledWorker":    # Dask's allowed-failures: the task killed several workers
        n = getattr(exc, "allowed_failures", 0) + 1
        return _Failure(name, f"the worker process computing it died {n} times (killed for "
                              f"memory, or a crash in compiled code); see the workers' logs",
                        False)
    # not asked for by mapsim: a task is cancelled when the client's connection to the
    # scheduler is lost (reason "scheduler-connection-lost", or none when the reconnection
    # gave up) or when the scheduler itself went away
    if isinstance(exc, _CANCELLED) or name == "CommClosedError":
        return _Failure(_LOST, "the connection to the Dask scheduler was lost", False)
    return _Failure(name, (str(exc).strip().splitlines() or [""])[0], False)


def _parts_to_compute(parts: Path, tasks, keys) -> list:
    """The (task, key) pairs without a usable stored part, in task order. A part that cannot
    be read or fails :func:`check_part` is quarantined by :func:`_read_part`; a readable part
    that holds other quantities than most stored parts (an edited or foreign part: the table
    could never be aggregated) is quarantined here, and all of them are recomputed."""
    held = {}
    todo = []
    for i, (t, k) in enumerate(zip(tasks, keys)):
        res = _read_part(_part_path(parts, t, k), k, t.seed_int())
        if res is None:
            todo.append(i)
        else:
            held[i] = frozenset(q for q in res if q != "__seed__")
    if held:
        common = collections.Counter(held.values()).most_common(1)[0][0]
        for i, qs in held.items():
            if qs != common:
                _quarantine(_part_path(parts, tasks[i], keys[i]),
                            f"ValueError: its quantities differ from the other parts "
                            f"({', '.join(sorted(qs ^ common))})")
                todo.append(i)
    return [(tasks[i], keys[i]) for i in sorted(todo)]


def _raise_failures(failures, n_tasks: int, parts: Path):
    """One line when every failure is an input error (exit 2); else :class:`BatchError`
    listing the first ten (exit 1)."""
    t, f0 = failures[0]
    if all(f.kind == _LOST for _, f in failures):     # the scheduler went away: one line
        raise BatchError(f"lost the connection to the Dask scheduler (it stopped, restarted or "
                         f"cancelled the tasks) "
                         f"with {len(failures)} of {n_tasks} realizations not done; the others "
                         f"are stored in {parts}; run the same command again (with the "
                         f"scheduler and its workers up): it computes only the missing ones")
    if all(f.input_error for _, f in failures):      # the study asks for the impossible
        raise InputError(f"{len(failures)} of {n_tasks} realizations refused their input, first "
                         f"at grid point {t.grid_index} ({_fmt_point(t.point)}): {f0.message}")
    lines = [f"  grid point {t.grid_index} ({_fmt_point(t.point)}) realization "
             f"{t.realization}: {f.kind}: {f.message}" for t, f in failures[:10]]
    more = f"\n  ... and {len(failures) - 10} more" if len(failures) > 10 else ""
    raise BatchError(f"{len(failures)} of {n_tasks} realizations failed; the other "
                     f"results are kept in {parts} and a rerun computes only the "
                     f"missing ones:\n" + "\n".join(lines) + more)


def _fmt_point(point: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in point.items())


# --------------------------------------------------------------------------- aggregation
def aggregate(study: Study, parts: Path, evaluator_id: str) -> dict:
    """Per-realization arrays and statistics, read from the stored parts in grid order."""
    tasks = study.tasks()
    R = study.realizations
    P = study.n_points
    values: dict[str, np.ndarray] = {}
    seeds = np.zeros((P, R), dtype=np.int64)
    names = None
    for t in tasks:
        k = t.key(evaluator_id)
        res = _read_part(_part_path(parts, t, k), k, t.seed_int())
        if res is None:
            raise BatchError(f"realization {t.realization} of grid point {t.grid_index} is "
                             f"missing from {parts}")
        seeds[t.grid_index, t.realization] = res.pop("__seed__")
        if names is None:
            names = [q for q in QUANTITIES if q in res]
            for q in names:
                values[q] = np.empty((P, R) + QUANTITIES[q][1])
        if set(res) != set(names):
            raise BatchError(f"inconsistent quantities in {parts}: {sorted(res)} vs {names}")
        for q in names:
            values[q][t.grid_index, t.realization] = res[q]
    summaries = {q: summarize(np.moveaxis(values[q], 1, 0), study.confidence) for q in names}
    return {"values": values, "summaries": summaries, "seeds": seeds,
            "n": np.full(P, R, dtype=np.int64), "disc": _discretization(study, values)}


def _matrix_value(study: Study, key: str | None, ndim: int):
    """The value of a cell-FEM quantity without filler, per grid point (P, 1, ...) for a
    quantity of ``ndim`` component dimensions: the matrix's E or nu, else 0. The rve
    evaluator's matrix is ``[cell]``'s; the relax evaluator's a ``matrix_E_Pa`` grid axis or
    ``[relax]``'s."""
    if key is None:
        return 0.0
    default = {"matrix_E_Pa": PDMS.E_Pa, "matrix_nu": PDMS.nu}[key]
    table = study.relax if study.evaluator == "relax" else study.cell
    vals = [float(p.get(key, table.get(key, default))) for p in study.points()]
    return np.asarray(vals).reshape((-1,) + (1,) * ndim)


def _discretization(study: Study, values: dict) -> dict:
    """Per cell-FEM quantity with coarse-grid values: the discretization error of its mean
    (:func:`homogenize.tables.resolution.discretization_error`), arrays (P, ...)."""
    out = {}
    for q, key in {**FEM_QUANTITIES, **RELAX_FEM_QUANTITIES}.items():
        if q in values and q + COARSE in values:
            out[q] = discretization_error(np.moveaxis(values[q], 1, 0),
                                          np.moveaxis(values[q + COARSE], 1, 0),
                                          study.voxels, study.coarse_voxels, study.confidence,
                                          matrix_value=_matrix_value(study, key,
                                                                     values[q].ndim - 2))
    return out


def discretization_attrs(study: Study) -> dict:
    """How the table's discretization errors were estimated (root attribute
    ``discretization``, JSON)."""
    return {"voxels": study.voxels, "coarse_voxels": study.coarse_voxels, "order": ORDER,
            "floor_rel_of_filler_contribution": FILLER_BIAS_REL,
            "estimate": "max((|mean(Q_n - Q_nc)| + t sd/sqrt(R)) / ((n/nc)^order - 1), "
                        "floor_rel |Q - Q_matrix|)",
            "combination": "linear: [ci_low - disc_err, ci_high + disc_err] (a bias shared "
                           "by the realizations)",
            "source": "homogenize.tables.resolution; results/cell/README.md (dilute sphere "
                      "convergence of the composite voxels)"}


def _str_array(values):
    return np.array(values, dtype=h5py.string_dtype())


#: CF conventions version the table attributes follow
CONVENTIONS = "CF-1.10"
_COMPONENT_NAME = "Cartesian component of vectors and tensors (x, y, z)"


def write_table(out, study: Study, data: dict, man: dict, evaluator_id: str) -> None:
    """Write the aggregated table atomically (layout: module docstring).

    Arrays in ``data`` are indexed by the flat grid point (C order over the grid axes); they
    are stored reshaped to one dimension per grid axis. A table already at ``out`` that holds
    the same content to :data:`TABLE_ROUNDOFF_RTOL` is kept byte for byte.
    """
    out = Path(out)
    with atomic_path(out) as tmp:
        _write_table_file(tmp, study, data, man, evaluator_id)
        if out.is_file() and hdf5_agree(out, tmp, TABLE_ROUNDOFF_RTOL):
            # the table there already holds these numbers (to round-off): keep its bytes, so
            # that a rerun on another CPU does not rewrite a committed table
            shutil.copyfile(out, tmp)


#: relative agreement (to each dataset's largest magnitude) under which a rerun keeps the table
#: that is already there: round-off of another CPU's vector units moves the last digits of the
#: per-realization results (about 1e-15, grown by the iterative solves to 1e-12 at most); the
#: tables' statistical intervals are 1e-2 to 1e-4 wide, so 1e-8 hides nothing a user can see
TABLE_ROUNDOFF_RTOL = 1e-8


def _write_table_file(tmp, study: Study, data: dict, man: dict, evaluator_id: str) -> None:
    """Build the table in memory (HDF5's core driver, no backing store), then write its bytes
    to ``tmp`` with one plain write: HDF5 never writes to the disk itself, so a full disk is one
    ``OSError(ENOSPC)`` here and never a failure inside the HDF5 library (which, out of space,
    floods stderr with ignored errors from its handles or crashes the process). The bytes are
    those that HDF5 would write to a file."""
    grid_shape = tuple(study.grid_shape)
    axis_names = study.axis_names
    dimsizes = [(a, len(v)) for a, v in study.axes]
    dimsizes += [("realization", study.realizations), ("i", 3), ("j", 3)]

    def grid(arr):
        arr = np.asarray(arr)
        return arr.reshape(grid_shape + arr.shape[1:])

    with h5py.File(str(tmp), "w", driver="core", backing_store=False) as h:
        h.attrs["Conventions"] = CONVENTIONS
        h.attrs["title"] = f"mapsim effective-parameter table of study {study.name}"
        h.attrs["source"] = f"mapsim batch run, evaluator {evaluator_id}"
        h.attrs["format"] = FORMAT
        h.attrs["format_version"] = FORMAT_VERSION
        h.attrs["confidence"] = study.confidence
        h.attrs["grid_axes"] = json.dumps({a: list(v) for a, v in study.axes})
        h.attrs["grid_shape"] = np.array(grid_shape, dtype=np.int64)
        h.attrs["study_name"] = study.name
        h.attrs["study_toml"] = study.text
        h.attrs["evaluator"] = evaluator_id
        h.attrs["manifest"] = json.dumps(man, default=str)
        dims = {}
        for name, size in dimsizes:
            if name in axis_names:
                vals = dict(study.axes)[name]
                if isinstance(vals[0], str):
                    d = h.create_dataset(name, data=_str_array(vals))
                    d.attrs["units"] = "1"
                else:
                    d = h.create_dataset(name, data=np.array(vals, dtype=np.float64))
                    d.attrs["units"] = _unit_of(name)
                d.attrs["long_name"] = f"grid axis {name}"
            elif name == "realization":
                d = h.create_dataset(name, data=np.arange(size, dtype=np.int64))
                d.attrs["units"] = "1"
                d.attrs["long_name"] = "realization index (random RVE) at each grid point"
            else:
                d = h.create_dataset(name, data=_str_array(_COMPONENTS))
                d.attrs["units"] = "1"
                d.attrs["long_name"] = _COMPONENT_NAME
            d.make_scale(name)
            dims[name] = d

        def put(name, arr, dimnames, units, desc):
            ds = h.create_dataset(name, data=arr)
            for ax, dn in enumerate(dimnames):
                ds.dims[ax].attach_scale(dims[dn])
            ds.attrs["units"] = units
            ds.attrs["long_name"] = desc
            return ds

        gdims = tuple(axis_names)
        put("n", grid(data["n"]), gdims, "1", "realizations per grid point")
        put("seed", grid(data["seeds"]), gdims + ("realization",), "1",
            "integer seed of each realization")
        lvl = f"{100 * study.confidence:g} %"
        disc = data.get("disc") or {}
        if disc:
            h.attrs["discretization"] = json.dumps(discretization_attrs(study))
        for q, vals in data["values"].items():
            unit, shape, desc = QUANTITIES[q]
            comp = ("i", "j")[:len(shape)]
            put(q, grid(vals), gdims + ("realization",) + comp, unit,
                desc + " (per realization)")
            s = data["summaries"][q]
            put(f"{q}_mean", grid(s["mean"]), gdims + comp, unit, desc + " (mean)")
            put(f"{q}_sd", grid(s["sd"]), gdims + comp, unit, desc + " (sample sd)")
            put(f"{q}_ci_low", grid(s["ci_low"]), gdims + comp, unit,
                desc + f" (lower end of the {lvl} Student-t interval of the mean)")
            put(f"{q}_ci_high", grid(s["ci_high"]), gdims + comp, unit,
                desc + f" (upper end of the {lvl} Student-t interval of the mean)")
            if q in disc:
                lo, hi = combined_interval(s["ci_low"], s["ci_high"], disc[q]["err"])
                put(f"{q}_disc_err", grid(disc[q]["err"]), gdims + comp, unit,
                    desc + f" (discretization error of the mean at {study.voxels} voxels, "
                    f"two-grid estimate with {study.coarse_voxels} voxels: attribute "
                    f"discretization)")
                put(f"{q}_total_low", grid(lo), gdims + comp, unit,
                    desc + f" (lower end of the {lvl} interval widened by the discretization "
                    f"error)")
                put(f"{q}_total_high", grid(hi), gdims + comp, unit,
                    desc + f" (upper end of the {lvl} interval widened by the discretization "
                    f"error)")
        h.flush()
        image = h.id.get_file_image()
    with open(tmp, "wb") as fh:
        fh.write(image)


# --------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class Table:
    """An effective-parameter table in memory (see :func:`read_table`)."""

    path: str
    axes: dict            # axis -> tuple of grid values (canonical order)
    points: tuple         # tuple of dicts, grid order
    confidence: float
    n: np.ndarray         # (P,)
    values: dict          # quantity -> (P, R, ...) per-realization values
    units: dict           # quantity -> unit
    attrs: dict
    #: quantity -> (P, ...) discretization error of the mean (cell FEM quantities of tables
    #: with ``[study] coarse_voxels``; :mod:`homogenize.tables.resolution`)
    disc_err: dict = dataclasses.field(default_factory=dict)

    @property
    def quantities(self) -> tuple:
        return tuple(self.values)

    def resolve_quantity(self, name: str) -> str:
        """Full quantity name from a prefix such as ``f_eff`` or ``E_eff``."""
        if name in self.values:
            return name
        hits = [q for q in self.values if q.startswith(name + "_") or q == name]
        if len(hits) > 1:       # a prefix means the quantity, not its coarse-grid companion
            hits = [q for q in hits if not q.endswith(COARSE)]
        if len(hits) == 1:
            return hits[0]
        raise InputError(f"{self.path}: no quantity {name!r} in the table; available: "
                         f"{', '.join(self.values)}")

    def component_values(self, quantity: str, component: str | None = None) -> np.ndarray:
        """(P, R) per-realization values of one scalar component of ``quantity``.

        ``component``: ``x``/``y``/``z`` (vectors, default z), ``xx``..``zz`` (tensors,
        default zz), ``norm`` (Euclidean norm of a vector); ignored for scalars.
        """
        q = self.resolve_quantity(quantity)
        return _component(self.values[q], 2, component, q)

    def component_disc_err(self, quantity: str, component: str | None = None):
        """(P,) discretization error of one scalar component of ``quantity``'s mean (None when
        the table has no estimate for it); components as in :meth:`component_values`."""
        q = self.resolve_quantity(quantity)
        if q not in self.disc_err:
            return None
        return _component(self.disc_err[q], 1, component, q)

    def select(self, spec) -> int:
        """Index of the grid point given as an integer or ``axis=value,axis=value``."""
        if isinstance(spec, (int, np.integer)):
            i = int(spec)
        elif isinstance(spec, str) and spec.strip().lstrip("-").isdigit():
            i = int(spec)
        else:
            want = {}
            for item in str(spec).split(","):
                if "=" not in item:
                    raise InputError(f"point {spec!r}: expected an index or axis=value pairs "
                                     f"separated by commas (axes: {', '.join(self.axes)})")
                a, v = (s.strip() for s in item.split("=", 1))
                if a not in self.axes:
                    raise InputError(f"point {spec!r}: unknown axis {a!r}; axes: "
                                     f"{', '.join(self.axes)}")
                want[a] = v
            hits = [i for i, p in enumerate(self.points)
                    if all(_same(p[a], v) for a, v in want.items())]
            if len(hits) != 1:
                what = "no" if not hits else f"{len(hits)}"
                raise InputError(f"point {spec!r} matches {what} grid points; give a value for "
                                 f"each axis with several values: "
                                 + "; ".join(f"{a} in {list(v)}" for a, v in self.axes.items()
                                             if len(v) > 1))
            return hits[0]
        if not 0 <= i < len(self.points):
            raise InputError(f"point index {i} out of range [0, {len(self.points) - 1}]")
        return i


def _component(v: np.ndarray, lead: int, component: str | None, q: str) -> np.ndarray:
    """One scalar component of an array whose first ``lead`` axes are not components:
    ``x``/``y``/``z`` (vectors, default z), ``xx``..``zz`` (tensors, default zz), ``norm`` (the
    Euclidean norm of a vector); scalars are returned as they are."""
    shape = v.shape[lead:]
    if not shape:
        return v
    if component in (None, ""):
        component = "z" * len(shape)
    if component == "norm" and len(shape) == 1:
        return np.linalg.norm(v, axis=-1)
    if len(component) != len(shape) or any(c not in _COMPONENTS for c in component):
        allowed = "x, y, z, norm" if len(shape) == 1 else "xx, xy, ..., zz"
        raise InputError(f"component {component!r} of {q}: allowed {allowed}")
    idx = tuple(_COMPONENTS.index(c) for c in component)
    return v[(slice(None),) * lead + idx]


def _same(grid_value, text: str) -> bool:
    if isinstance(grid_value, str):
        return grid_value == text
    try:
        v = float(text)
    except ValueError:
        return False
    return math.isclose(v, grid_value, rel_tol=1e-9, abs_tol=0.0)


def _decode_axis(raw) -> list:
    return [x.decode() if isinstance(x, bytes) else
            (str(x) if isinstance(x, str) else float(x)) for x in raw]


def read_table(path) -> Table:
    """Load a table written by :func:`run_batch` (format version 1 or 2).

    The returned :class:`Table` is flat over the grid points (C order over the axes), whatever
    the file layout: version 2 files store one dimension per grid axis, version 1 files a flat
    ``point`` dimension. What is read back is validated as strictly as a study typed by a user
    (:func:`check_table`): a damaged or edited table raises :class:`InputError`.
    """
    path = Path(path)
    try:
        return check_table(_read_table(path))
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}: damaged table, cannot be read ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0][:160] if str(exc) else ''})") from None


def check_table(t: Table) -> Table:
    """Refuse a table whose values or attributes no run of :func:`run_batch` can have written:
    a confidence level outside (0, 1), realization counts below 2, per-realization values
    that are not finite or of the wrong shape, grid axes without values."""
    where = t.path
    if not (0.0 < t.confidence < 1.0):
        raise InputError(f"{where}: attribute confidence = {t.confidence:g} is not in (0, 1) "
                         f"(the table was edited or damaged)")
    P = len(t.points)
    if P == 0 or any(len(v) == 0 for v in t.axes.values()):
        raise InputError(f"{where}: a grid axis has no values (the table is damaged)")
    n = np.asarray(t.n)
    if n.shape != (P,) or not np.issubdtype(n.dtype, np.integer) or np.any(n < 2):
        raise InputError(f"{where}: dataset n must hold an integer >= 2 per grid point "
                         f"({P}), got {n.ravel()[:5].tolist()}")
    if not t.values:
        raise InputError(f"{where}: the table holds no quantities")
    for q, v in t.values.items():
        want = QUANTITIES[q][1]
        if v.ndim != 2 + len(want) or v.shape[0] != P or v.shape[2:] != want \
                or v.shape[1] < int(n.max()):
            raise InputError(f"{where}: dataset {q} has shape {v.shape}, expected ({P}, R"
                             f"{''.join(f', {d}' for d in want)}) with R >= {int(n.max())}")
        if not np.all(np.isfinite(v)):
            i = np.argwhere(~np.isfinite(v))[0]
            raise InputError(f"{where}: dataset {q} holds a non-finite value at grid point "
                             f"{int(i[0])} realization {int(i[1])} (the table is damaged)")
    for q, e in t.disc_err.items():
        if q not in t.values or e.shape != (P,) + QUANTITIES[q][1] \
                or not np.all(np.isfinite(e)) or np.any(e < 0):
            raise InputError(f"{where}: dataset {q}_disc_err must hold a finite value >= 0 of "
                             f"shape ({P}{''.join(f', {d}' for d in QUANTITIES[q][1])}) for a "
                             f"quantity of the table (the table is damaged)")
    return t


def _read_table(path: Path) -> Table:
    with open_hdf5(path, "table") as h:
        if h.attrs.get("format") != FORMAT:
            raise InputError(f"{path} is not a mapsim table (format attribute "
                             f"{h.attrs.get('format')!r})")
        version = int(h.attrs.get("format_version", 1))
        if version not in (1, 2):
            raise InputError(f"{path}: table format version {version} is newer than this "
                             f"mapsim understands (1 or 2)")
        axes = {a: tuple(v) for a, v in json.loads(h.attrs["grid_axes"]).items()}
        if version == 1:
            P = h["point"].shape[0]
            cols = {a: _decode_axis(h[a][()]) for a in axes}
            points = tuple({a: cols[a][i] for a in axes} for i in range(P))
        else:
            cols = {a: _decode_axis(h[a][()]) for a in axes}
            points = tuple(dict(zip(axes, combo))
                           for combo in itertools.product(*(cols[a] for a in axes)))
            P = len(points)
        nd = 1 if version == 1 else len(axes)

        def flat(arr):
            return arr.reshape((P,) + arr.shape[nd:])

        values, units, disc = {}, {}, {}
        for q in QUANTITIES:
            if q in h:
                values[q] = flat(h[q][()])
                units[q] = h[q].attrs["units"]
                if isinstance(units[q], bytes):
                    units[q] = units[q].decode()
                if f"{q}_disc_err" in h:
                    disc[q] = flat(h[f"{q}_disc_err"][()])
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h.attrs.items()}
        return Table(path=str(path), axes=axes, points=points,
                     confidence=float(h.attrs["confidence"]), n=flat(h["n"][()]),
                     values=values, units=units, attrs=attrs, disc_err=disc)


# --------------------------------------------------------------------------- interpolation
@dataclass(frozen=True)
class Estimate:
    """An interpolated table value with its confidence interval and, for the cell FEM's
    quantities, the discretization error of the grid (:mod:`homogenize.tables.resolution`; 0 when
    the table has no estimate)."""

    mean: float
    ci_low: float
    ci_high: float
    se: float             # standard error of the mean
    dof: float            # Welch-Satterthwaite degrees of freedom
    confidence: float
    unit: str
    disc_err: float = 0.0     # discretization error of the mean (same unit)
    has_disc: bool = False    # whether the table estimated it

    @property
    def rel_half_width(self) -> float:
        """Half the statistical interval's width relative to the mean (0 for a zero mean)."""
        return (self.ci_high - self.ci_low) / (2 * abs(self.mean)) if self.mean else 0.0

    @property
    def total_low(self) -> float:
        """Lower end of the interval widened by the discretization error (linear sum)."""
        return self.ci_low - self.disc_err

    @property
    def total_high(self) -> float:
        return self.ci_high + self.disc_err

    @property
    def total_rel_half_width(self) -> float:
        """Half the widened interval's width relative to the mean (0 for a zero mean)."""
        return ((self.total_high - self.total_low) / (2 * abs(self.mean)) if self.mean
                else 0.0)

    def scaled(self, factor: float) -> "Estimate":
        lo, hi = sorted((self.ci_low * factor, self.ci_high * factor))
        return Estimate(self.mean * factor, lo, hi, self.se * abs(factor), self.dof,
                        self.confidence, self.unit, self.disc_err * abs(factor), self.has_disc)

    def describe(self, fmt: str = ".6g") -> str:
        """``[lo, hi]`` and, where estimated, ``, discretization +- e, combined [lo, hi]``."""
        text = f"[{self.ci_low:{fmt}}, {self.ci_high:{fmt}}]"
        if self.has_disc:
            text += (f", discretization +- {self.disc_err:.2g}, combined "
                     f"[{self.total_low:{fmt}}, {self.total_high:{fmt}}]")
        return text


def _axis_weights(table: Table, axis: str, value) -> list[tuple[int, float]]:
    """(index into the axis values, weight) pairs of 1-D linear interpolation."""
    grid = table.axes[axis]
    if isinstance(grid[0], str):
        if value not in grid:
            raise InputError(f"{axis} = {value!r} is not in the table; available: {list(grid)}")
        return [(grid.index(value), 1.0)]
    v = float(value)
    order = np.argsort(grid)
    g = np.asarray(grid, dtype=float)[order]
    if len(g) == 1:
        if not math.isclose(v, g[0], rel_tol=1e-9):
            raise InputError(f"{axis} = {v:g} {_unit_of(axis)}: the table has only "
                             f"{axis} = {g[0]:g}")
        return [(int(order[0]), 1.0)]
    if v < g[0] * (1 - 1e-12) or v > g[-1] * (1 + 1e-12):
        raise InputError(f"{axis} = {v:g} {_unit_of(axis)} lies outside the table's range "
                         f"[{g[0]:g}, {g[-1]:g}] (no extrapolation)")
    k = int(np.clip(np.searchsorted(g, v, side="right") - 1, 0, len(g) - 2))
    w = (v - g[k]) / (g[k + 1] - g[k])
    w = min(max(w, 0.0), 1.0)
    return [(int(order[k]), 1.0 - w), (int(order[k + 1]), w)]


def interpolate(table, quantity: str, *, component: str | None = None,
                confidence: float | None = None, **coords) -> Estimate:
    """Multilinear interpolation of a table quantity, with the propagated interval.

    The grid points are independent samples, so the interpolated mean
    ``sum_k w_k mean_k`` has the variance ``sum_k w_k^2 sd_k^2 / n_k``; the interval uses
    Student's t with Welch-Satterthwaite degrees of freedom (at a grid point it is the table's
    own interval). The discretization errors of the grid points (a bias, correlated between
    neighbouring points) are interpolated with the same weights: ``sum_k w_k e_k``.
    Interpolation error between grid points is not included: make the grid dense where the
    quantity curves. Axes with a single value may be omitted.
    """
    if not isinstance(table, Table):
        table = read_table(table)
    conf = table.confidence if confidence is None else confidence
    for a in coords:
        if a not in table.axes:
            raise InputError(f"{a} is not a grid axis of {table.path}; axes: "
                             f"{', '.join(table.axes)}")
    per_axis = []
    for a, grid in table.axes.items():
        if a not in coords:
            if len(grid) > 1:
                raise InputError(f"give {a} (the table {table.path} has {a} in {list(grid)})")
            per_axis.append([(0, 1.0)])
        else:
            per_axis.append(_axis_weights(table, a, coords[a]))
    shape = tuple(len(v) for v in table.axes.values())
    vals = table.component_values(quantity, component)
    errs = table.component_disc_err(quantity, component)
    q = table.resolve_quantity(quantity)
    mean = 0.0
    disc = 0.0
    var_terms = []
    for combo in itertools.product(*per_axis):
        w = math.prod(c[1] for c in combo)
        if w == 0.0:
            continue
        p = int(np.ravel_multi_index(tuple(c[0] for c in combo), shape))
        x = vals[p]
        n = x.size
        mean += w * float(x.mean())
        if errs is not None:
            disc += abs(w) * float(errs[p])
        var_terms.append((w * w * float(x.var(ddof=1)) / n, n))
    se2 = sum(v for v, _ in var_terms)
    if se2 > 0:
        dof = se2 ** 2 / sum(v * v / (n - 1) for v, n in var_terms)
    else:
        dof = float(min(n for _, n in var_terms) - 1)
    half = t_half_width(math.sqrt(se2), dof, conf)
    return Estimate(mean, mean - half, mean + half, math.sqrt(se2), float(dof), conf,
                    table.units[q], disc, errs is not None)


def body_force_from_table(table, phi: float, B_T: float, gradB_T_per_m: float, *,
                          component: str = "z", confidence: float | None = None,
                          **other_axes) -> Estimate:
    """Effective body force [N/m^3] at (phi, B, dB/dz), interpolated with its interval.

    If the table holds one gradient only, the force is scaled linearly to the asked gradient:
    ``F_i = (m_i . grad) B`` is linear in the gradient at fixed moments, and the moments are set
    by the local field, which a gradient of a few T/m changes by ~1e-6 T across an RVE.
    """
    if not isinstance(table, Table):
        table = read_table(table)
    coords = {"phi": phi, "B_T": B_T, **other_axes}
    grads = table.axes.get("gradB_T_per_m")
    if grads is not None and len(grads) == 1:
        g0 = float(grads[0])
        if g0 == 0:
            raise InputError(f"{table.path} was computed at gradB_T_per_m = 0: no body force "
                             f"to scale")
        est = interpolate(table, "f_eff_N_m3", component=component, confidence=confidence,
                          **coords)
        return est.scaled(float(gradB_T_per_m) / g0)
    coords["gradB_T_per_m"] = gradB_T_per_m
    return interpolate(table, "f_eff_N_m3", component=component, confidence=confidence,
                       **coords)


def modulus_from_table(table, phi: float, *, confidence: float | None = None,
                       **other_axes) -> Estimate | None:
    """Effective Young's modulus [Pa] at phi (None if the table has no FEM results).

    The modulus does not depend on the field in this model, so field axes not given are
    averaged over (equal weights, which keeps the interval honest: all realizations count).
    """
    if not isinstance(table, Table):
        table = read_table(table)
    if "E_eff_Pa" not in table.values:
        return None
    coords = {"phi": phi, **other_axes}
    ests = []
    field_axes = [a for a in ("B_T", "gradB_T_per_m") if a in table.axes and a not in coords]
    for combo in itertools.product(*(table.axes[a] for a in field_axes)):
        ests.append(interpolate(table, "E_eff_Pa", confidence=confidence, **coords,
                                **dict(zip(field_axes, combo))))
    m = len(ests)
    mean = sum(e.mean for e in ests) / m
    se2 = sum(e.se ** 2 for e in ests) / m ** 2
    dof = se2 ** 2 / sum((e.se ** 2 / m ** 2) ** 2 / e.dof for e in ests) if se2 > 0 else ests[0].dof
    conf = ests[0].confidence
    half = t_half_width(math.sqrt(se2), dof, conf)
    disc = sum(e.disc_err for e in ests) / m      # a bias: averaged, not reduced by 1/sqrt(m)
    return Estimate(mean, mean - half, mean + half, math.sqrt(se2), float(dof), conf, "Pa",
                    disc, ests[0].has_disc)
