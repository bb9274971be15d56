"""The one progress indicator of every command: a tqdm bar on a terminal, plain lines elsewhere.

A bar redraws itself with carriage returns many times a second: on a terminal that is what one
wants, in a log file (stderr redirected, a batch job, CI) it is thousands of lines of noise.
:func:`progress_bar` takes tqdm's arguments and returns a tqdm bar when its stream is a terminal;
otherwise the same object writes one plain line each time another tenth of the work is done
(``batch seed-conditions: 30 % (54/180 realization) 12 s``) and one at the end; without a
known total, a line at 1, 2, 5, 10, 20, 50, ... items. Every caller (``micro.particles``,
``homogenize.tables.batch``, ``homogenize.cell.problem``, the studies, ``mapsim diagnose``) goes through it.
"""
from __future__ import annotations

import io
import math
import sys

from tqdm import tqdm

__all__ = ["progress_bar", "Progress", "is_terminal"]


def is_terminal(stream) -> bool:
    """Whether ``stream`` is an interactive terminal (False for files, pipes, captured
    streams and anything without a working ``isatty``)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _fmt_time(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else (
        f"{s // 60}:{s % 60:02d}" if s >= 60 else f"{s} s")


class Progress(tqdm):
    """tqdm on a terminal; plain progress lines on any other stream (see the module doc)."""

    def __init__(self, iterable=None, *args, file=None, **kwargs):
        stream = sys.stderr if file is None else file
        self._stream = stream
        self._lines = not is_terminal(stream) and not kwargs.get("disable", False)
        self._last_step = -1            # last tenth (or log step) written
        self._last_n = None
        if self._lines:
            # tqdm's own drawing goes nowhere; display() writes the plain lines
            file = io.StringIO()
            kwargs["mininterval"] = 0.0
        super().__init__(iterable, *args, file=file if self._lines else stream, **kwargs)

    def _step(self, n: float, total) -> int:
        if total:
            return min(10, int(math.floor(10.0 * n / total + 1e-9)))
        if n <= 0:
            return -1
        k = int(math.floor(math.log10(n)))                  # 1, 2, 5, 10, 20, 50, ...
        lead = n / 10 ** k
        return 3 * k + (2 if lead >= 5 else 1 if lead >= 2 else 0)

    def _line(self) -> str:
        d = self.format_dict
        n, total, unit = d["n"], d["total"], d.get("unit") or "it"
        head = f"{d.get('prefix') or 'progress'}: "
        if total:
            head += f"{100.0 * n / total:.0f} % ({n:g}/{total:g} {unit})"
        else:
            head += f"{n:g} {unit}"
        head += f" {_fmt_time(d.get('elapsed') or 0.0)}"
        if d.get("postfix"):
            head += f", {d['postfix']}"
        return head

    def display(self, msg=None, pos=None):
        if not self._lines:
            return super().display(msg, pos)
        step = self._step(self.n, self.total)
        final = msg is None and pos == 0 and getattr(self, "_closing", False)
        if (step > self._last_step and step >= 0) or (final and self._last_n != self.n):
            self._last_step, self._last_n = max(step, self._last_step), self.n
            try:
                self._stream.write(self._line() + "\n")
                self._stream.flush()
            except (OSError, ValueError):
                pass
        return True

    def close(self):
        if self._lines and not self.disable and not getattr(self, "_closing", False):
            self._closing = True
            self.display(pos=0)                              # the last state, once
        return super().close()


def progress_bar(iterable=None, **kwargs) -> Progress:
    """A progress indicator with tqdm's arguments (``total``, ``desc``, ``unit``, ``initial``,
    ``leave``, ``disable``, ``file`` -- default stderr): a bar on a terminal, else lines."""
    return Progress(iterable, **kwargs)
