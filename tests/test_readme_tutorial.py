"""The README's tutorial "your own composite" (issue 36, item 4): every command runs, and every
number the README shows as its output is what the command prints.

The commands and their quoted output are parsed from README.md (section "Tutorial", each
```sh block followed by the ```text block of what it prints), so the README and the code cannot
drift apart. A quoted line must match one line of the command's output (stdout and stderr, and
for ``--out FILE`` the text of FILE, e.g. the exported deck) with the same words and the same
numbers; " ... " in a quoted line stands for text left out. Tolerance: a number agrees when it
differs from the printed one by at most 2 units of the last digit (of the finer of the two) or
1e-5 relative, whichever is larger: the solvers stop at relative tolerances of 1e-6, and the
last digits move with a CPU's vector units; a README number rounded coarser than the print
fails. The batch is deterministic whatever the number of workers.

The commands run in ``tmp_path`` (with a copy of examples/your_composite.toml), each in its own
process as a user would run them: about 2 min on 2 free cores (the beam 1.5 min of it), ~3.5 min
on a heavily loaded one.
"""
from __future__ import annotations

import math
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
NUMBER = r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?"
ELLIPSIS = " ... "


def tutorial_steps(text: str) -> list[tuple[list[str], list[str]]]:
    """``[(argv, quoted output lines)]`` of the README's tutorial section, in order."""
    m = re.search(r"^## Tutorial.*?$(.*?)(?=^## )", text, re.S | re.M)
    assert m, "README.md has no '## Tutorial' section"
    steps = []
    for kind, body in re.findall(r"^```(sh|text)\n(.*?)^```", m.group(1), re.S | re.M):
        if kind == "sh":
            cmd = " ".join(line.rstrip("\\").strip() for line in body.splitlines()
                           if line.strip() and not line.lstrip().startswith("#"))
            argv = shlex.split(cmd)
            assert argv[0] == "mapsim", f"tutorial command does not start with mapsim: {cmd}"
            steps.append((argv[1:], []))
        else:
            assert steps, "a ```text block before any command"
            steps[-1][1].extend(line for line in body.splitlines() if line.strip())
    return steps


def _digits_tolerance(token: str) -> float:
    """Half-width of agreement of a printed number: 2 units of its last printed digit."""
    mant, _, exp = token.lower().partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 2.0 * 10.0 ** (int(exp or 0) - decimals)


def _pattern(quoted: str) -> tuple[re.Pattern, list[str]]:
    """A regex for one quoted line, whitespace-normalized: the words literally, the numbers
    captured, " ... " any text; and the quoted numbers in order."""
    numbers, pieces = [], []
    for piece in quoted.split(ELLIPSIS):
        tokens = []
        for tok in piece.split():
            parts = re.split(f"({NUMBER})", tok)
            tokens.append("".join(re.escape(t) if k % 2 == 0 else f"({NUMBER})"
                                  for k, t in enumerate(parts)))
            numbers.extend(parts[1::2])
        pieces.append(" ".join(tokens))
    return re.compile(" .*? ".join(pieces)), numbers


def _agrees(printed: str, quoted: str) -> bool:
    a, b = float(printed), float(quoted)
    return math.isclose(a, b, rel_tol=1e-5,
                        abs_tol=min(_digits_tolerance(printed), _digits_tolerance(quoted)))


def check_quoted(quoted: str, output: str) -> str | None:
    """None when ``quoted`` matches a line of ``output``, else the reason."""
    pat, numbers = _pattern(" ".join(quoted.split()))
    near = None
    for line in output.splitlines():
        m = pat.fullmatch(" ".join(line.split()))
        if not m:
            continue
        printed = list(m.groups())
        if all(_agrees(p, q) for p, q in zip(printed, numbers)):
            return None
        near = line
    return (f"README quotes\n  {quoted.strip()}\nbut the command printed "
            + (f"\n  {near.strip()}" if near else "no line with these words"))


def test_parser_on_examples():
    """The matcher itself: words must match, numbers within the printed digits."""
    out = "eb             0.00282271               0        0  \nflow: Q = 1.667e-10 m^3/s x"
    assert check_quoted("eb 0.00282271 0 0", out) is None
    assert check_quoted("eb 0.00282272 0 0", out) is None          # 1 unit of the last digit
    assert check_quoted("eb 0.00282291 0 0", out) is not None
    assert check_quoted("ec 0.00282271 0 0", out) is not None
    assert check_quoted("flow: Q = 1.667e-10 ... x", out) is None
    assert check_quoted("flow: Q = 1.7e-10 m^3/s x", out) is not None  # printed digits differ


def test_readme_tutorial(tmp_path):
    steps = tutorial_steps(README.read_text())
    assert len(steps) == 5, f"the tutorial has five commands, found {len(steps)}"
    assert all(quoted for _, quoted in steps), "every tutorial command shows what it prints"
    (tmp_path / "examples").mkdir()
    shutil.copy(ROOT / "examples" / "your_composite.toml", tmp_path / "examples")
    problems = []
    for argv, quoted in steps:
        proc = subprocess.run([sys.executable, "-m", "homogenize.cli", *argv], cwd=tmp_path,
                              capture_output=True, text=True, timeout=1200)
        assert proc.returncode == 0, (f"mapsim {' '.join(argv)} exited {proc.returncode}:\n"
                                      f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
        output = proc.stdout + "\n" + proc.stderr
        if "--out" in argv:
            out = tmp_path / argv[argv.index("--out") + 1]
            if out.suffix in (".inp", ".sif") and out.is_file():
                output += "\n" + out.read_text()
        for q in quoted:
            why = check_quoted(q, output)
            if why:
                problems.append(f"mapsim {argv[0]}: {why}")
    assert not problems, "\n".join(problems)
