"""Shared pieces of the CLI: help formatter, option types with ranges, output-path safety."""
from __future__ import annotations

import argparse
import os
import stat
import sys
from pathlib import Path

from micro._io import atomic_write_text
from micro._validate import InputError

__all__ = ["Formatter", "int_in", "float_in", "check_outputs", "parse_at", "write_snippet",
           "config_of"]


class Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    pass


def int_in(name: str, lo: int, hi: int):
    """argparse type: an integer in [lo, hi]; anything else is a usage error (exit 2)."""
    def conv(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} must be an integer in [{lo}, {hi}], got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}], got {v}")
        return v
    return conv


def float_in(name: str, lo: float, hi: float, unit: str = "", lo_open: bool = False,
             hi_open: bool = False):
    """argparse type: a finite float in the interval (ends open as asked)."""
    u = f" {unit}" if unit else ""
    left, right = ("(" if lo_open else "["), (")" if hi_open else "]")

    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} must be a number in {left}{lo:g}, {hi:g}{right}{u}, got {text!r}") from None
        bad = (v != v or (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi))
        if bad:
            raise argparse.ArgumentTypeError(
                f"{name} must be in {left}{lo:g}, {hi:g}{right}{u}, got {text}")
        return v
    return conv


def _name_max(directory: Path) -> int:
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def check_outputs(outputs, inputs=()) -> None:
    """Refuse unsafe output paths before any work starts.

    ``outputs``: (option, path) pairs (path None is skipped; ``-`` is stdout); ``inputs``: paths
    the command reads. An output is refused if it is one of the inputs (same file, by inode),
    if it exists and is not a regular file (a device such as /dev/null, a directory, a pipe),
    if its file name is too long, or if its directory cannot be created or written.
    """
    ins = [Path(p) for p in inputs if p is not None and Path(p).exists()]
    seen = {}
    for opt, path in outputs:
        if path is None or str(path) == "-":
            continue
        p = Path(path)
        if str(p) in seen:
            raise InputError(f"{opt} {p}: the same file is also given to {seen[str(p)]}")
        seen[str(p)] = opt
        for q in ins:
            if p.exists() and os.path.samefile(p, q):
                raise InputError(f"{opt} {p} is an input of this command ({q}); refusing to "
                                 f"overwrite it: give another output name")
        if p.exists() or p.is_symlink():
            try:
                mode = os.stat(p).st_mode
            except OSError as exc:
                raise InputError(f"{opt} {p}: cannot be examined ({exc.strerror})") from None
            if not stat.S_ISREG(mode):
                kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
                raise InputError(f"{opt} {p} exists and is {kind}; give a regular file name")
        parent = p.parent if str(p.parent) else Path(".")
        if len(p.name.encode()) > _name_max(parent if parent.exists() else Path(".")) - 16:
            raise InputError(f"{opt}: file name is too long ({len(p.name.encode())} bytes; "
                             f"at most {_name_max(Path('.')) - 16}) ")
        anc = parent
        while not anc.exists():
            anc = anc.parent
        if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
            raise InputError(f"{opt} {p}: directory {anc} is not writable")


def check_output_dir(opt: str, path) -> None:
    """Refuse an output directory that exists as a non-directory or cannot be written."""
    if path is None:
        return
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{opt} {p} exists and is not a directory")
    anc = p
    while not anc.exists():
        anc = anc.parent
    if not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"{opt} {p}: directory {anc} is not writable")


def parse_at(text: str | None) -> dict:
    """``"axis=value,axis=value"`` -> dict (numbers where they parse)."""
    out: dict = {}
    if not text:
        return out
    for item in str(text).split(","):
        if "=" not in item:
            raise InputError(f"--at {text!r}: expected axis=value pairs separated by commas")
        a, v = (x.strip() for x in item.split("=", 1))
        try:
            out[a] = float(v)
        except ValueError:
            out[a] = v
    return out


def write_snippet(text: str, out: str, what: str) -> int:
    """Write ``text`` to ``out`` (``-`` = stdout) atomically; return exit code 0."""
    if out == "-":
        sys.stdout.write(text)
        return 0
    path = Path(out)
    atomic_write_text(path, text)
    print(f"wrote {what} to {path}")
    return 0


def config_of(args) -> dict:
    """The parsed options as a JSON-able configuration (for manifests)."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
            if k != "func"}
