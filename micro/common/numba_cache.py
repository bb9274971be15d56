"""A writable numba cache, chosen before numba is imported (imported first by ``micro``).

Our kernels are compiled with ``cache=True``. Numba writes the cache beside the source
(``__pycache__``) or, if that is read-only (an installed package), in the user's cache
directory (``$XDG_CACHE_HOME`` or ``~/.cache``); when neither can be written (a service user
without a home, a read-only image) it raises at the first kernel call. Only then is
``NUMBA_CACHE_DIR`` set to a private directory under the system temporary directory; an
explicit ``NUMBA_CACHE_DIR`` is always respected. Nothing else in the environment changes.
"""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

__all__ = ["choose_cache_dir"]

_PACKAGES = (Path(__file__).resolve().parents[1], Path(__file__).resolve().parents[2] / "homogenize")


def _writable(d: Path) -> bool:
    """``d`` exists as a writable directory, or can be created under a writable ancestor."""
    d = Path(d)
    while not d.exists():
        if d.parent == d:
            return False
        d = d.parent
    return d.is_dir() and os.access(d, os.W_OK | os.X_OK)


def _user_cache() -> Path | None:
    base = os.environ.get("XDG_CACHE_HOME")
    if not base:
        try:
            base = str(Path.home() / ".cache")
        except (RuntimeError, KeyError):
            return None
    return Path(base) / "numba"


def _private_dir(tmp: Path) -> Path:
    """``tmp/mapsim-numba-<uid>``, ours alone (0700); a fresh one if that name is taken."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    d = Path(tmp) / f"mapsim-numba-{uid}"
    try:
        d.mkdir(mode=0o700, exist_ok=True)
        st = d.lstat()
        if stat.S_ISDIR(st.st_mode) and st.st_uid == uid and os.access(d, os.W_OK | os.X_OK):
            return d
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix="mapsim-numba-", dir=tmp))


def choose_cache_dir(package_dirs=_PACKAGES, user_cache=None, tmp=None, environ=None):
    """The directory to set as ``NUMBA_CACHE_DIR``, or None when numba's default works.

    Parameters are for tests: the source packages, the user-wide cache directory, the
    temporary directory and the environment (default: the real ones).
    """
    environ = os.environ if environ is None else environ
    if environ.get("NUMBA_CACHE_DIR"):
        return None
    if all(_writable(Path(p) / "__pycache__") for p in package_dirs):
        return None
    user = _user_cache() if user_cache is None else Path(user_cache)
    if user is not None and _writable(user):
        return None
    return _private_dir(Path(tmp) if tmp is not None else Path(tempfile.gettempdir()))


def _apply() -> None:
    try:
        d = choose_cache_dir()
    except OSError:
        return                      # no writable place at all: numba's own error will say so
    if d is not None:
        os.environ["NUMBA_CACHE_DIR"] = str(d)


_apply()
