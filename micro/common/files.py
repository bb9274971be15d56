"""Atomic file output and run manifests, used by every command that writes results."""
from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import math
import os
import platform
import re
import stat
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path
from micro.common.validate import InputError
import h5py
import numpy as np

__all__ = ["atomic_path", "clean_stale_temps", "open_regular", "is_regular_file", "NotRegularFile",
           "protect_inputs", "protected_inputs", "atomic_write_text", "write_json", "manifest", "git_revision",
           "open_hdf5", "RESULT_DIGITS", "round_floats", "data_digest", "save_png", "hdf5_agree"]

_PACKAGES = ("mapsim", "numpy", "scipy", "numba", "scikit-fem", "h5py", "trimesh", "pyamg",
             "dask", "distributed", "matplotlib", "meshio")


def _read_umask() -> int:
    """The process umask, read without changing it where the OS tells it (Linux /proc).

    Elsewhere it is read once here, at import, by setting and restoring it: never again while
    threads (Dask workers, numba) may be creating files.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


#: a temporary file of ours untouched for this long belongs to a writer that died (kill -9,
#: power loss): the next atomic write of the same name removes it [s]
STALE_TEMP_SECONDS = 3600.0


def clean_stale_temps(path, max_age_s: float = STALE_TEMP_SECONDS) -> int:
    """Remove hidden temporaries ``.NAME.XXXXXXXX.tmp`` of :func:`atomic_path` for ``path``
    that were last modified more than ``max_age_s`` ago; return how many."""
    path = Path(path)
    pat = re.compile(r"\." + re.escape(path.name) + r"\.[A-Za-z0-9_]{8}\.tmp")
    n = 0
    now = time.time()
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return 0
    for e in entries:
        if not pat.fullmatch(e.name):
            continue
        with contextlib.suppress(OSError):
            if e.is_file(follow_symlinks=False) and now - e.stat().st_mtime > max_age_s:
                os.unlink(e.path)
                n += 1
    return n


class NotRegularFile(OSError):
    """A path to read that is not a regular file (a FIFO, device, directory or socket)."""


def is_regular_file(path) -> bool:
    """Whether ``path`` is (or links to) a regular file; never opens it."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def open_regular(path, mode: str = "rb", **kwargs):
    """Open ``path`` for reading only if it is a regular file, without ever blocking.

    A FIFO would block ``open`` until a writer appears and a device such as /dev/zero is read
    forever: the file is opened non-blocking, checked with ``fstat`` on the open descriptor (no
    race with a rename), and only then handed out in blocking mode. Anything else raises
    :class:`NotRegularFile` (an ``OSError``); a missing file ``FileNotFoundError``.
    """
    if any(c in mode for c in "wax+"):
        raise ValueError("open_regular opens for reading only")
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = "a directory" if stat.S_ISDIR(st.st_mode) else "a device, pipe or socket"
            raise NotRegularFile(f"not a regular file (it is {kind}): {path}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, mode, **kwargs)
    except BaseException:
        os.close(fd)
        raise


# Inputs of the running command (device, inode): no atomic write may replace one of them,
# whatever path names it (the last line of defence behind the CLI's checks of its options).
_PROTECTED: dict = {}


def protect_inputs(paths) -> None:
    """Declare the files the running command reads: :func:`atomic_path` then refuses to replace
    any of them (an output that is also an input of the same run) with :class:`InputError`.
    Missing paths are skipped. ``protect_inputs(())`` does nothing; see
    :func:`protected_inputs` to clear."""
    for p in paths:
        if p is None:
            continue
        try:
            st = os.stat(p)
        except (OSError, ValueError):
            continue
        if stat.S_ISREG(st.st_mode):
            _PROTECTED[(st.st_dev, st.st_ino)] = str(p)


@contextlib.contextmanager
def protected_inputs(paths):
    """Context manager: :func:`protect_inputs` for the block, then forget them again."""
    saved = dict(_PROTECTED)
    protect_inputs(paths)
    try:
        yield
    finally:
        _PROTECTED.clear()
        _PROTECTED.update(saved)


def _refuse_protected(path: Path) -> None:
    if not _PROTECTED:
        return
    try:
        st = os.stat(path)
    except OSError:
        return
    src = _PROTECTED.get((st.st_dev, st.st_ino))
    if src is not None:
        raise InputError(f"{path} is an input of this command ({src}); refusing to overwrite "
                         f"it: give another output name or directory")


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; move it onto ``path`` only if the block succeeds.

    A reader never sees a half-written file: either the old file (or none) or the new one.
    Temporaries of earlier writers of the same name that died mid-write (older than
    :data:`STALE_TEMP_SECONDS`) are removed first.
    """
    path = Path(path)
    _refuse_protected(path)
    if os.path.isdir(path):               # os.replace would fail after the work is done
        raise InputError(f"{path} exists and is a directory; refusing to replace it with a "
                         f"file: move it away or give another output name")
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temps(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp creates 0600; results are meant to be shared like any other file
        os.chmod(tmp, 0o666 & ~_UMASK)
        with open(tmp, "rb") as fh:          # on disk before it takes the name
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def open_hdf5(path, what: str):
    """Open an existing HDF5 file for reading; ``what`` names it in the one-line error.

    A missing file or one that is not HDF5 raises :class:`micro.InputError`, never a traceback.
    """

    path = Path(path)
    if not path.exists():
        raise InputError(f"{what} {path} does not exist")
    if not path.is_file():
        raise InputError(f"{what} {path} must be a regular file (this is a directory, device "
                         f"or pipe)")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{what} {path} is not a readable HDF5 file ({exc})") from None


def _default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json(path, obj, *, digits: int | None = None) -> None:
    """Write ``obj`` as indented JSON, atomically (numpy arrays become lists).

    ``digits``: round every float to that many significant digits first
    (:func:`round_floats`; committed results use :data:`RESULT_DIGITS`).
    """
    if digits is not None:
        obj = round_floats(obj, digits)
    atomic_write_text(path, json.dumps(obj, indent=2, default=_default, allow_nan=False) + "\n")


#: Significant digits of the floats in committed result files. Their numbers come from solvers
#: stopped at relative tolerances of 1e-6 or looser, and from interval estimates of a few
#: random RVEs: more digits carry no information, and the last of 16 digits changes with the
#: CPU's vector units (round-off in BLAS, numpy and numba kernels). A value 1e-12 (relative)
#: away from a rounding boundary of 6 digits is the only case where another CPU can still
#: change a written digit: about one number in a million.
RESULT_DIGITS = 6


def _round(x: float, digits: int) -> float:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else x


def round_floats(obj, digits: int = RESULT_DIGITS):
    """A copy of ``obj`` (dicts, lists, tuples, numpy arrays and scalars, recursively) with every
    float rounded to ``digits`` significant digits; integers, strings, None unchanged.

    numpy arrays become lists (as in the JSON files), tuples stay tuples.
    """
    if isinstance(obj, (bool, np.bool_)) or obj is None:
        return obj.item() if isinstance(obj, np.bool_) else obj
    if isinstance(obj, (float, np.floating)):
        return _round(float(obj), digits)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return round_floats(obj.tolist(), digits)
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(round_floats(v, digits) for v in obj)
    return obj


def data_digest(obj, *sources) -> str:
    """SHA-256 of ``obj`` rounded to :data:`RESULT_DIGITS` (canonical JSON) and of the text of
    the source files ``sources`` (e.g. the module that draws a figure): the same digest means
    the same rounded numbers drawn by the same code."""
    h = hashlib.sha256(json.dumps(round_floats(obj), sort_keys=True, default=_default,
                                  allow_nan=True).encode())
    for src in sources:
        h.update(Path(src).read_bytes())
    return h.hexdigest()


#: PNG text key that holds :func:`data_digest` of what a figure shows
PNG_DIGEST_KEY = "mapsim-data-digest"


def _png_digest(path: Path) -> str | None:
    """The :data:`PNG_DIGEST_KEY` text chunk of the PNG at ``path`` (None if absent)."""
    try:
        from PIL import Image            # matplotlib's own dependency
        with Image.open(path) as im:
            return im.text.get(PNG_DIGEST_KEY)
    except (OSError, ValueError, AttributeError):
        return None


def save_png(fig, path, digest: str, *, dpi: int = 120) -> bool:
    """Save the matplotlib figure ``fig`` as the PNG ``path`` (atomically), unless the PNG there
    already shows the same data: its :data:`PNG_DIGEST_KEY` equals ``digest``. Returns whether
    it was written.

    So a committed figure is redrawn only when its rounded numbers or its drawing code change,
    not when the last digit of a float moves on another CPU or a newer matplotlib draws an
    antialiased pixel differently.
    """
    path = Path(path)
    if path.is_file() and _png_digest(path) == digest:
        return False
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata={PNG_DIGEST_KEY: digest})
    return True


def git_revision() -> str:
    """The git revision of the source tree (with ``-dirty``), or ``"unknown"``."""
    here = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "-uno"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if not rev:
        return "unknown"
    return rev + ("-dirty" if dirty else "")


#: Environment variable naming a run log (JSON lines). When it is set, the per-run facts of
#: every manifest (git revision, times, machine, command line) go to that log instead of the
#: manifest, so that re-running a committed study on the same code reproduces its files byte
#: for byte (``make run`` sets it to the ignored ``results/run_log.jsonl``).
RUN_LOG_ENV = "MAPSIM_RUN_LOG"


def _relative_paths(obj):
    """Absolute paths inside the working directory written relative to it (recursively), so
    that a manifest does not depend on where the checkout lives."""
    cwd = os.getcwd().rstrip(os.sep) + os.sep
    if isinstance(obj, str) and obj.startswith(cwd):
        return obj[len(cwd):]
    if isinstance(obj, Path):
        return _relative_paths(str(obj))
    if isinstance(obj, dict):
        return {k: _relative_paths(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_relative_paths(v) for v in obj)
    return obj


def manifest(config: dict | None = None, seed=None, **extra) -> dict:
    """A run manifest: configuration, seed, package versions, git revision, time, machine.

    Extra keywords are added; those ending in ``_utc`` are per-run facts like the time. With
    the environment variable :data:`RUN_LOG_ENV` set, the per-run facts are appended to that
    log and the manifest keeps only what determines the numbers (config, seed, versions).
    """
    versions = {}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    config = _relative_paths(config or {})
    out = {"config": config, "seed": seed, "versions": versions}
    run = {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "git_revision": git_revision(),
        "written_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "argv": sys.argv,
    }
    for k, v in extra.items():
        (run if k.endswith("_utc") else out)[k] = v
    log = os.environ.get(RUN_LOG_ENV)
    if log:
        out["run"] = f"per-run facts (git revision, times, machine) in the run log {Path(log).name}"
        Path(log).parent.mkdir(parents=True, exist_ok=True)
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(json.dumps({"config": config, "seed": seed, **run},
                                default=_default) + "\n")
    else:
        out.update(run)
    return out


#: attributes that HDF5 dimension scales keep as object references (file addresses): they follow
#: from the datasets and their order, and are not compared by :func:`hdf5_agree`
_SCALE_ATTRS = frozenset({"DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME"})


def _attrs_equal(a, b) -> bool:
    ka = {k for k in a.attrs if k not in _SCALE_ATTRS}
    kb = {k for k in b.attrs if k not in _SCALE_ATTRS}
    if ka != kb:
        return False
    for k in ka:
        va, vb = a.attrs[k], b.attrs[k]
        if isinstance(va, np.ndarray) or isinstance(vb, np.ndarray):
            if not np.array_equal(np.asarray(va), np.asarray(vb)):
                return False
        elif va != vb:
            return False
    return True


def hdf5_agree(path_a, path_b, rtol: float) -> bool:
    """Whether two HDF5 files hold the same content: the same groups, datasets and attributes,
    non-float data equal, and every float dataset ``b`` within ``rtol`` of ``a`` relative to the
    dataset's largest magnitude (NaN where the other has NaN). A file that cannot be read does
    not agree.
    """
    try:
        with h5py.File(path_a, "r") as fa, h5py.File(path_b, "r") as fb:
            if not _attrs_equal(fa, fb):
                return False
            names_a, names_b = [], []
            fa.visit(names_a.append)
            fb.visit(names_b.append)
            if sorted(names_a) != sorted(names_b):
                return False
            for name in names_a:
                oa, ob = fa[name], fb[name]
                if isinstance(oa, h5py.Group) != isinstance(ob, h5py.Group) or \
                        not _attrs_equal(oa, ob):
                    return False
                if isinstance(oa, h5py.Group):
                    continue
                va, vb = oa[()], ob[()]
                if oa.dtype != ob.dtype or np.shape(va) != np.shape(vb):
                    return False
                if np.issubdtype(oa.dtype, np.floating):
                    va, vb = np.asarray(va), np.asarray(vb)
                    finite = np.isfinite(va)
                    scale = float(np.max(np.abs(va[finite]))) if finite.any() else 0.0
                    if not np.allclose(vb, va, rtol=rtol, atol=rtol * scale, equal_nan=True):
                        return False
                elif not np.array_equal(np.asarray(va), np.asarray(vb)):
                    return False
    except (OSError, KeyError, ValueError, TypeError):
        return False
    return True


def json_ready(obj):
    """NaN and infinities -> None, recursively (JSON has no NaN): a quantity that is undefined
    (an end-face mean of a sphere, a gap beyond a traced branch) is written as null."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
