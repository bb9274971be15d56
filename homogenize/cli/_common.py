"""Shared pieces of the CLI: help formatter, option types with ranges, output-path safety."""
from __future__ import annotations

import argparse
import fnmatch
import os
import re
import stat
import sys
from pathlib import Path

import numpy as np

from micro.common.files import atomic_write_text
from micro.common.validate import InputError, Range, check_finite, check_regular_file

from homogenize.voxels._budget import check_memory, machine_memory_bytes
from micro.common.files import json_ready  # noqa: F401  (re-exported for the commands)

__all__ = ["Formatter", "Parser", "NEGATIVE_NUMBER", "one_line_errors", "int_in", "float_in", "json_ready",
           "scheduler_address", "check_outputs", "check_output_dir", "check_input_file",
           "machine_memory_bytes", "check_memory", "parse_at", "parse_values", "write_snippet",
           "config_of",
           "add_material_options", "fill_from_preset"]


class Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """argparse's defaults in the help, except where the help text states its own default."""

    def _get_help_string(self, action):
        if "(default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


#: a number with a minus sign in any notation Python's float() reads: -1, -1.5, -.5, -1e-6,
#: -2.5E+3, -1_000, -inf, -nan (argparse's own pattern knows only -1 and -1.5); also a list of
#: numbers that starts with one, separated by ':' or ',' (a range START:STOP:COUNT, e.g.
#: --gap-sweep-m -0.01:0.005:3, reaches its own check instead of being read as an option)
_NUMBER = r"(?:(?:\d[\d_]*\.?[\d_]*|\.\d[\d_]*)(?:[eE][-+]?\d[\d_]*)?|inf|infinity|nan)"
NEGATIVE_NUMBER = re.compile(rf"^-{_NUMBER}(?:[:,][-+]?{_NUMBER})*$", re.IGNORECASE)


class Parser(argparse.ArgumentParser):
    """The argument parser of every ``mapsim`` command (subcommands inherit the class).

    A word that is a negative number in any notation (:data:`NEGATIVE_NUMBER`: ``-15.5e-3``,
    ``-1e-6``, ``-inf``) is a value, never an option, so it reaches the option's range check
    (``--mean-radius -1e-6`` -> the range message) and fills ``nargs=3`` vectors
    (``--magnet-position 20e-3 2.5e-3 -15.5e-3``). No option of mapsim looks like a number,
    which is argparse's own condition for this reading.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER


def one_line_errors(sub) -> None:
    """Make every parser registered so far in the subparsers action ``sub`` report a usage
    error as ONE line ``mapsim CMD: error: ...`` (exit 2), without argparse's usage block.
    Idempotent; each command module calls it at the end of its ``register``."""
    for parser in sub.choices.values():
        parser.error = _OneLineError(parser)


class _OneLineError:
    def __init__(self, parser):
        self.prog = parser.prog

    def __call__(self, message: str):
        # "argument --nz: --nz must be ..." -> "--nz must be ..."
        m = re.match(r"argument ([^:]+): (.*)$", message, re.S)
        if m and m.group(2).startswith(m.group(1).split("/")[0]):
            message = m.group(2)
        sys.stderr.write(f"{self.prog}: error: {' '.join(message.split())}\n")
        raise SystemExit(2)


def int_in(name: str, lo: int, hi: int):
    """argparse type: an integer in [lo, hi]; anything else is a usage error (exit 2)."""
    return Range(lo, hi, integer=True).arg(name)


def float_in(name: str, lo: float, hi: float, unit: str = "", lo_open: bool = False,
             hi_open: bool = False):
    """argparse type: a finite float in the interval (ends open as asked). A parameter with a
    range defined by its owner (``FIELD_RANGES``, ``CELL_RANGES``) uses ``RANGES[key].arg(opt)``
    instead, the same checks and messages."""
    return Range(lo, hi, unit, lo_open, hi_open).arg(name)


def scheduler_address(text):
    """argparse type: a Dask scheduler address ``PROTOCOL://HOST:PORT`` (tcp, tls, ucx, ws,
    wss, inproc); anything else is a usage error before any connection is tried."""
    m = re.fullmatch(r"(tcp|tls|ucx|ws|wss|inproc)://([^\s/:]+|\[[0-9a-fA-F:]+\])(:(\d{1,5}))?/?",
                     text.strip())
    if m is None or (m.group(4) is not None and not 0 < int(m.group(4)) < 65536):
        raise argparse.ArgumentTypeError(
            f"--scheduler must be an address PROTOCOL://HOST:PORT (protocol tcp, tls, ucx, ws, "
            f"wss or inproc; port 1-65535), e.g. tcp://127.0.0.1:8786; got {text!r}")
    return text.strip()


def _name_max(directory: Path) -> int:
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _check_name(opt: str, p: Path) -> None:
    """Refuse a path with a component too long for its file system (and the temp-file prefix
    and suffix of an atomic write) before anything is created."""
    limit = _name_max(Path("."))
    for part in p.parts:
        if len(part.encode()) > limit - 16:
            raise InputError(f"{opt}: file name is too long ({len(part.encode())} bytes; at most "
                             f"{limit - 16} per name)")


def _exists(p: Path) -> bool:
    try:
        os.lstat(p)
        return True
    except OSError:
        return False


def check_outputs(outputs, inputs=()) -> None:
    """Refuse unsafe output paths before any work starts.

    ``outputs``: (option, path) pairs (path None is skipped; ``-`` is stdout); ``inputs``: paths
    the command reads. An output is refused if it is one of the inputs (same file, by inode),
    if it exists and is not a regular file (a device such as /dev/null, a directory, a pipe),
    if its file name is too long, or if its directory cannot be created or written.
    """
    ins = [Path(p) for p in inputs if p is not None and _exists(Path(p))]
    seen = {}
    for opt, path in outputs:
        if path is None or str(path) == "-":
            continue
        p = Path(path)
        _check_name(opt, p)
        key = os.path.realpath(p)
        if key in seen:
            raise InputError(f"{opt} {p}: the same file is also given to {seen[key]}; one "
                             f"output would replace the other: give another name")
        seen[key] = opt
        # a table's parts directory beside it is written (and removed by --clean) by the run
        for comp in (p.with_name(p.stem + ".parts"),):
            for q in ins:
                same = _inside(q, comp) is not None if _exists(comp) else False
                if same:
                    raise InputError(f"{q} is an input of this command, but {opt} {p} writes "
                                     f"{comp} beside it; refusing to overwrite it: give "
                                     f"another output name")
        if _exists(p):
            for q in ins:
                try:
                    same = os.path.samefile(p, q)
                except OSError:
                    same = False
                if same:
                    raise InputError(f"{opt} {p} is an input of this command ({q}); refusing "
                                     f"to overwrite it: give another output name")
            try:
                mode = os.stat(p).st_mode
            except OSError as exc:
                raise InputError(f"{opt} {p}: cannot be examined ({exc.strerror})") from None
            if not stat.S_ISREG(mode):
                kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
                raise InputError(f"{opt} {p} exists and is {kind}; give a regular file name")
        parent = p.parent if str(p.parent) else Path(".")
        anc = parent
        while not _exists(anc):
            anc = anc.parent
        if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
            raise InputError(f"{opt} {p}: directory {anc} is not writable")


def check_input_file(opt: str, path, max_bytes: int = 64 * 2 ** 20) -> None:
    """Refuse an input that is not a regular file of at most ``max_bytes`` (a device such as
    /dev/zero would be read forever, a FIFO would block) before it is opened."""
    if path is None:
        return
    check_regular_file(path, f"{opt} {Path(path)}", max_bytes)


def _inside(path: Path, directory: Path) -> Path | None:
    """``path`` relative to ``directory`` if it lies inside it (after resolving links)."""
    try:
        return Path(os.path.realpath(path)).relative_to(os.path.realpath(directory))
    except ValueError:
        return None


def check_output_dir(opt: str, path, inputs=(), writes=None, other_outputs=()) -> None:
    """Refuse an output directory that exists as a non-directory or cannot be written, or that
    would overwrite an input of the same run.

    ``inputs``: paths the command reads; ``writes``: the names (glob patterns, relative to the
    directory; a directory name covers everything under it) the command writes there. An
    input that is one of them is refused; with ``writes`` None (not declared) every input
    inside the directory is refused.
    """
    if path is None:
        return
    p = Path(path)
    _check_name(opt, p)
    if _exists(p) and not p.is_dir():
        raise InputError(f"{opt} {p} exists and is not a directory")
    for q in inputs:
        if q is None or str(q) == "-" or not _exists(Path(q)):
            continue
        rel = _inside(Path(q), p)
        if rel is None:
            continue
        hit = writes is None or any(
            fnmatch.fnmatchcase(str(rel), pat) or fnmatch.fnmatchcase(rel.parts[0], pat)
            for pat in writes)
        if hit:
            raise InputError(f"{q} is an input of this command and lies in the output "
                             f"directory {opt} {p}, where this run writes {rel}; refusing to "
                             f"overwrite it: give another {opt} or move the input")
    # another output of the same run that is this directory, or a file the run writes in it
    for o_opt, o in other_outputs:
        if o is None or str(o) == "-":
            continue
        rel = _inside(Path(o), p)
        if rel is None:
            continue
        if str(rel) == "." or writes is not None and any(
                fnmatch.fnmatchcase(str(rel), pat) or fnmatch.fnmatchcase(rel.parts[0], pat)
                for pat in writes):
            what = o_opt if " " in o_opt else f"{o_opt} {o}"
            raise InputError(f"{what} is written where the output directory {opt} {p} is "
                             f"(or writes {rel}); one output would replace the other: give "
                             f"another name")
    anc = p
    while not _exists(anc):
        anc = anc.parent
    if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"{opt} {p}: directory {anc} is not writable")


def parse_values(text: str, opt: str, unit: str, *, max_count: int = 1000,
                 min_count: int = 1) -> np.ndarray:
    """A list of values in the one syntax of every mapsim option that takes several: one value,
    comma-separated values, or ``START:STOP:COUNT`` (``COUNT`` evenly spaced values from START
    to STOP, both included). Only the syntax and the count are checked here; each option checks
    its range and order itself."""
    text = str(text).strip()
    try:
        if ":" in text:
            a, b, n = text.split(":")
            a, b, n = float(a), float(b), int(n)
        else:
            vals = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise InputError(f"{opt} must be one value, comma-separated values or START:STOP:COUNT "
                         f"[{unit}], got {text!r}") from None
    if ":" in text:
        if not min_count <= n <= max_count:
            raise InputError(f"{opt}: COUNT must be in [{min_count}, {max_count}], got {n}")
        vals = np.linspace(a, b, n)
    if not min_count <= vals.size <= max_count:
        raise InputError(f"{opt}: {min_count} to {max_count} values, got {vals.size}")
    return vals


#: the applied flux density's range [T] on every command that takes one field
B_LIMIT_T = 50.0


def add_field_options(g, *, help_B: str = "") -> None:
    """The one syntax of an applied field on every mapsim command: ``--B`` its magnitude
    mu0 |H| [T] and ``--B-direction BX BY BZ`` its direction (any length; default 0 0 1, along
    z). A vector is never written into ``--B``: ``'Bx,By,Bz'`` reads as a list, and the commands
    that sweep the field (``relax --B``, ``specimen --B``) take lists in the one syntax of
    :func:`parse_values`."""
    g.add_argument("--B", dest="B_T", type=_field_magnitude, default=None,
                   help=help_B or "applied flux density mu0 |H| [T], along --B-direction")
    g.add_argument("--B-direction", dest="B_direction", nargs=3, metavar=("BX", "BY", "BZ"),
                   type=float_in("--B-direction", -1e6, 1e6), default=None,
                   help="direction of the applied field (any length) [-] (default: 0 0 1)")


def _field_magnitude(text):
    """argparse type of ``--B`` (one field): a number in [-50, 50] T; a comma list is refused
    with the syntax of a direction."""
    if "," in str(text) or ":" in str(text):
        raise argparse.ArgumentTypeError(
            f"--B takes one value [T] here, got {text!r}; give a direction with "
            f"--B-direction BX BY BZ (the field is --B times the unit direction)")
    return float_in("--B", -B_LIMIT_T, B_LIMIT_T, "T")(text)


def field_vector(B_T: float, direction) -> np.ndarray | float:
    """The applied flux density of ``--B`` and ``--B-direction``: ``B_T`` along the unit
    direction (a 3-vector [T]), or the scalar ``B_T`` (along z) without a direction."""
    if direction is None:
        return float(B_T)
    d = np.asarray(direction, dtype=float)
    check_finite("--B-direction", d)
    if np.linalg.norm(d) == 0:
        raise InputError("--B-direction must not be the zero vector")
    return float(B_T) * d / np.linalg.norm(d)


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


#: attributes of the parsed options that describe the command, not the run
_DISPATCH = ("func", "inputs", "outputs", "output_dirs", "output_dir_writes")


def config_of(args) -> dict:
    """The parsed options as a JSON-able configuration (for manifests).

    ``inputs`` and ``outputs`` are the files this run really read and wrote, by option
    (``{"table": "t.h5"}``; ``{}`` when no input file was given), not the names of the options
    that could hold one.
    """
    def js(v):
        return str(v) if isinstance(v, Path) else v
    out = {k: js(v) for k, v in vars(args).items() if k not in _DISPATCH}
    for key in ("inputs", "outputs"):
        given = {d: js(getattr(args, d, None)) for d in getattr(args, key, ())}
        out[key] = {d: v for d, v in given.items() if v is not None}
    return out


# --------------------------------------------------------------------------- material presets
def add_material_options(p, *, particle: bool = True, matrix: bool = True,
                         what: str = "") -> None:
    """``--particle-material`` / ``--matrix-material``: named presets of
    :mod:`micro.materials` whose numbers fill every option of the command left unset (explicit
    options win). ``what``: which options they fill, for the help."""
    from micro.materials import DEFAULT_PRESET, MATRIX_PRESETS, PARTICLE_PRESETS
    g = p.add_argument_group(
        "materials (named presets with sources, micro.materials; explicit options win)", what)
    if particle:
        g.add_argument("--particle-material", choices=tuple(PARTICLE_PRESETS),
                       default=DEFAULT_PRESET,
                       help="filler powder: density, specific moment, size distribution, "
                            "shell, elastic constants (default: seed-paper, the seed's "
                            "7870 kg/m^3, 178 A m^2/kg, 25 nm)")
    if matrix:
        g.add_argument("--matrix-material", choices=tuple(MATRIX_PRESETS),
                       default=DEFAULT_PRESET,
                       help="elastomer: E, nu, density (default: seed-paper, the seed's PDMS "
                            "2 MPa, 0.45, 1210 kg/m^3)")


def fill_from_preset(args, values: dict) -> None:
    """Every option (by ``dest``) of ``values`` that was not given (None) takes the preset's
    value, so that the manifest records the numbers the run used."""
    for dest, v in values.items():
        if getattr(args, dest, None) is None:
            setattr(args, dest, v)


def check_option_needs(args, parser, needs: dict) -> None:
    """Refuse an option given without the option(s) that give it a meaning: it would be
    silently ignored (``mapsim beam --E-from-table`` without ``--table``). ``needs`` maps an
    option's dest to the dests of which at least one must be given (not None/False/default);
    an option counts as given when its value differs from the parser's default."""
    def given(dest):
        if "=" in dest:                   # "dest=value": that option has that value
            d, value = dest.split("=", 1)
            return str(getattr(args, d, None)) == value
        v, default = getattr(args, dest, None), parser.get_default(dest)
        if isinstance(v, (list, tuple)) and isinstance(default, (list, tuple)):
            v, default = tuple(v), tuple(default)
        return v is not None and v is not False and v != default

    def name(dest):
        if "=" in dest:
            d, value = dest.split("=", 1)
            return f"{_opt_name(parser, d)} {value}"
        return _opt_name(parser, dest)
    for dest, others in needs.items():
        others = (others,) if isinstance(others, str) else tuple(others)
        if not given(dest):
            continue
        for o in (o for o in others if o.startswith("!")):      # "!dest": not together
            if given(o[1:]):
                raise InputError(f"{name(dest)} and {name(o[1:])} are both given; which one "
                                 f"is meant is ambiguous: give only one of them")
        others = [o for o in others if not o.startswith("!")]
        if others and not any(given(o) for o in others):
            want = " or ".join(name(o) for o in others)
            raise InputError(f"{name(dest)} has no effect without {want}; give {want} too, "
                             f"or leave it out")


def _opt_name(parser, dest: str) -> str:
    for a in parser._actions:
        if a.dest == dest and a.option_strings:
            return max(a.option_strings, key=len)
    return "--" + dest.replace("_", "-")


def add_magnet_options(g) -> None:
    """The field source of `beam`, `export` and `channel` (magpylib; homogenize.macro.magnets)."""
    g.add_argument("--magnet", choices=("cuboid", "cylinder", "coil"), default=None,
                   help="field source (default: none, the uniform --body-force-N-m3)")
    g.add_argument("--magnet-size", type=float_in("--magnet-size", 0.0, 10.0, "m", lo_open=True), nargs="+", default=None,
                   metavar="M",
                   help="cuboid: A B C edges; cylinder: DIAMETER HEIGHT; coil: RADIUS LENGTH [m]")
    g.add_argument("--magnet-position", type=float_in("--magnet-position", -10.0, 10.0, "m"),
                   nargs=3, default=None,
                   metavar=("X", "Y", "Z"), help="centre of the source in the strip frame [m]")
    g.add_argument("--magnet-direction", type=float_in("--magnet-direction", -1e6, 1e6), nargs=3,
                   default=(0.0, 0.0, 1.0),
                   metavar=("X", "Y", "Z"), help="magnetization direction of a permanent magnet")
    g.add_argument("--magnet-axis", type=float_in("--magnet-axis", -1e6, 1e6), nargs=3,
                   default=(0.0, 0.0, 1.0),
                   metavar=("X", "Y", "Z"), help="axis of a cylinder or coil (cuboid: its C edge)")
    g.add_argument("--remanence-T", dest="remanence_T", type=float_in("--remanence-T", 0.0, 3.0,
                                                                       "T", lo_open=True),
                   default=None,
                   help="remanent polarization B_r of a permanent magnet [T] (NdFeB ~1.2-1.4)")
    g.add_argument("--current-A", dest="current_A", type=float_in("--current-A", -1e5, 1e5, "A"),
                   default=None,
                   help="coil current [A] (the seed's electromagnet: 1.5 A)")
    g.add_argument("--turns", type=int_in("--turns", 1, 100000), default=None,
                   help="coil turns")
    g.add_argument("--demag-factor", dest="demag_factor",
                   type=float_in("--demag-factor", 0.0, 1.0), default=None,
                   help="specimen demagnetizing factor for the field direction (default: "
                        "Aharoni's prism factor of the strip through its thickness, 0.771 for "
                        "19.4 x 5 x 1 mm)")
