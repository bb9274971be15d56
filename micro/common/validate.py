"""Input validation shared by every layer: one clear message per bad input.

Every public function that takes user-facing parameters checks them here and raises
:class:`InputError`, whose message names the parameter, its value, its unit and the allowed
range. The CLI turns an ``InputError`` into one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import math
import os
import stat
from dataclasses import dataclass

import numpy as np

__all__ = ["InputError", "ConvergenceError", "Range", "check_regular_file", "EXIT_INPUT", "EXIT_CONVERGENCE", "check_finite", "check_positive", "check_range", "check_choice", "check_slender", "check_header"]


#: Exit code of the CLI for unusable input (:class:`InputError`).
EXIT_INPUT = 2
#: Exit code of the CLI for a numerical solve that did not converge (:class:`ConvergenceError`).
EXIT_CONVERGENCE = 3


class InputError(ValueError):
    """Unusable input: the message names what is wrong and what is allowed."""


class ConvergenceError(RuntimeError):
    """A numerical solve did not converge. Not an input error: the CLI exits with 3.

    ``residual_history`` holds the relative residuals of the iteration, first to last.
    """

    def __init__(self, message, residual_history=()):
        super().__init__(message)
        self.residual_history = list(residual_history)


def _fmt(unit: str) -> str:
    return f" {unit}" if unit else ""


def check_finite(name: str, value, unit: str = ""):
    """Return ``value`` (scalar or array) if every entry is a finite real number."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number{_fmt(unit)}, got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must be finite{_fmt(unit)}, got {value!r}")
    return value


def check_positive(name: str, value, unit: str = "", allow_zero: bool = False) -> float:
    """Return ``float(value)`` if it is finite and > 0 (>= 0 with ``allow_zero``)."""
    check_finite(name, value, unit)
    v = float(value)
    if v < 0 or (v == 0 and not allow_zero):
        rng = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name} must be {rng}{_fmt(unit)}, got {v:g}")
    return v


def check_range(name: str, value, lo: float, hi: float, unit: str = "",
                lo_open: bool = False, hi_open: bool = False) -> float:
    """Return ``float(value)`` if it lies in the interval [lo, hi] (ends open as asked)."""
    check_finite(name, value, unit)
    v = float(value)
    bad_lo = v <= lo if lo_open else v < lo
    bad_hi = v >= hi if hi_open else v > hi
    if bad_lo or bad_hi or math.isnan(v):
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        raise InputError(f"{name} must be in {left}{lo:g}, {hi:g}{right}{_fmt(unit)}, got {v:g}")
    return v


@dataclass(frozen=True)
class Range:
    """The allowed values of one configuration parameter, defined once where the parameter is
    defined (e.g. ``micro.dipoles.FIELD_RANGES``, ``homogenize.cell.problem.CELL_RANGES``) and
    used by every entry point: the config class, the keyword function, the study file rules
    and the CLI option (:meth:`arg`), so that all of them accept and refuse the same values.

    ``lo``, ``hi``: the ends (``lo_open``/``hi_open``: excluded); ``unit``: appended to the
    messages (a unit or a parenthesised meaning, e.g. ``"(relative residual)"``); ``integer``:
    an integer in [lo, hi] (ints and numpy integers, never bool; the ends are closed).
    """

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def __post_init__(self):
        if self.integer and (self.lo_open or self.hi_open):
            raise ValueError("an integer Range has closed ends")

    def _ends(self) -> str:
        if self.integer:
            return f"[{int(self.lo)}, {int(self.hi)}]"
        left, right = ("(" if self.lo_open else "["), (")" if self.hi_open else "]")
        return f"{left}{self.lo:g}, {self.hi:g}{right}"

    def describe(self) -> str:
        """The allowed values in words: ``"in [1e-14, 0.01] (relative residual)"``,
        ``"an integer in [4, 256]"``."""
        head = "an integer in " if self.integer else "in "
        return f"{head}{self._ends()}{_fmt(self.unit)}"

    def contains(self, v) -> bool:
        """Whether the number ``v`` (already of the right type) lies in the range."""
        if v != v:
            return False
        return not ((v <= self.lo if self.lo_open else v < self.lo)
                    or (v >= self.hi if self.hi_open else v > self.hi))

    def check(self, name: str, value):
        """Return ``value`` as a float (an int for an integer range) if it is allowed; else
        raise :class:`InputError` naming ``name``, the value and the range (the messages of
        :func:`check_range`)."""
        if self.integer:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
                    or not self.contains(value):
                raise InputError(f"{name} must be {self.describe()}, got {value!r}")
            return int(value)
        if isinstance(value, (bool, np.bool_, str, bytes)):
            raise InputError(f"{name} must be a number {self.describe()}, got {value!r}")
        return check_range(name, value, self.lo, self.hi, self.unit, self.lo_open, self.hi_open)

    def arg(self, option: str):
        """argparse ``type=``: the option's text as a number in the range, else a usage error
        (exit 2) with the message of :meth:`check` (``"--tol must be in [1e-14, 0.01]
        (relative residual), got 0.5"``); the same messages as ``homogenize.cli._common``'s
        ``float_in`` / ``int_in``, which are built on it. ``conv.range`` is this object."""
        def conv(text):
            try:
                v = int(text) if self.integer else float(text)
            except ValueError:
                what = "an integer" if self.integer else "a number"
                raise argparse.ArgumentTypeError(
                    f"{option} must be {what} in {self._ends()}{_fmt(self.unit)}, "
                    f"got {text!r}") from None
            if not self.contains(v):
                got = v if self.integer else text
                raise argparse.ArgumentTypeError(f"{option} must be {self.describe()}, got {got}")
            return v
        conv.range = self
        return conv


def check_choice(name: str, value, choices) -> str:
    """Return ``value`` if it is one of ``choices``."""
    if value not in choices:
        raise InputError(f"{name} must be one of {', '.join(map(str, choices))}; got {value!r}")
    return value


def check_regular_file(path, label: str, max_bytes: int, missing: str = "does not exist",
                       unreadable: str = "cannot be examined") -> None:
    """Refuse a file to read that is missing, not a regular file (a device such as /dev/zero
    would be read forever, a FIFO would block) or larger than ``max_bytes``, before it is
    opened. ``label`` starts every message (e.g. ``"--data x.csv"``)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{label} {missing}") from None
    except OSError as exc:
        raise InputError(f"{label}: {unreadable} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{label} must be a regular file (this is a device, pipe or "
                         f"directory)")
    if st.st_size > max_bytes:
        raise InputError(f"{label} is {st.st_size / 2 ** 20:.1f} MiB, more than the "
                         f"{max_bytes / 2 ** 20:g} MiB allowed")


def check_slender(what: str, long_name: str, long_value: float, thin_name: str,
                  thin_value: float, min_ratio: float, unit: str = "m",
                  assumption: str = "") -> None:
    """Refuse a geometry that contradicts the slender-body assumption of a model: ``long_value``
    must be at least ``min_ratio`` times ``thin_value``. The message names both dimensions
    (a unit slip such as a thickness in metres for one in millimetres is the usual cause)."""
    lv, tv = float(long_value), float(thin_value)
    if not (math.isfinite(lv) and math.isfinite(tv)) or lv < min_ratio * tv:
        why = f" ({assumption})" if assumption else ""
        raise InputError(f"{what}: {thin_name} = {tv:g} {unit} is not small against "
                         f"{long_name} = {lv:g} {unit}; the model needs {long_name} >= "
                         f"{min_ratio:g} x {thin_name}{why}; a value in the wrong unit?")


def check_header(where: str, header, required=(), one_of=()) -> list:
    """Check a CSV header (a list of column names): no name twice, every ``required`` name
    present, and exactly one of the alternatives ``one_of`` (when given; two would leave it
    unsaid which one is meant). Returns the stripped names. ``where`` starts every message
    (e.g. ``"sizes.csv, row 1"``)."""
    names = [str(h).strip() for h in header]
    seen = set()
    for h in names:
        if h in seen:
            raise InputError(f"{where}, column '{h}': duplicate column name; which one is meant "
                             f"is ambiguous: keep one")
        seen.add(h)
    for r in required:
        if r not in seen:
            raise InputError(f"{where}: required column '{r}' missing (header has: "
                             f"{', '.join(names)})")
    if one_of:
        given = [c for c in one_of if c in seen]
        if not given:
            raise InputError(f"{where}: the header needs one of the columns "
                             f"{' or '.join(repr(c) for c in one_of)} (header has: "
                             f"{', '.join(names)})")
        if len(given) > 1:
            raise InputError(f"{where}: columns {' and '.join(repr(c) for c in given)} are both "
                             f"given, which one to use is ambiguous; keep only one of them")
    return names
