"""The ``mapsim`` command: argparse and printing only.

Each module of this package adds the parsers of one group of commands (``register(sub,
formatter)``, with ``set_defaults(func=...)``); ``func(args)`` builds the library's frozen
configurations from the options, calls the library and prints. No physics lives here.

Exit codes (documented in the README):

* 0 -- done;
* 1 -- some batch realizations failed, or a result could not be stored (disk full: the message
  names the file); the others are kept and the same command run again computes the rest;
* 2 -- unusable input (:class:`micro.InputError`: one line naming the parameter, file, row or
  column and the allowed range), also argparse's own usage errors;
* 3 -- a numerical solve did not converge (:class:`micro.ConvergenceError`, with the last
  residuals in the message);
* 130 -- interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from micro.common.files import protected_inputs
from micro.common.validate import EXIT_CONVERGENCE, EXIT_INPUT, ConvergenceError, InputError

from homogenize.cli import (cmd_bench, cmd_cell, cmd_experiments, cmd_macro, cmd_relax,
                            cmd_rve, cmd_specimen, cmd_tables)
from homogenize.cli._common import (Formatter, Parser, check_option_needs, check_output_dir,
                                    check_outputs)

__all__ = ["main", "build_parser"]

# Command groups, in the order their commands appear in --help.
_GROUPS = (cmd_macro, cmd_specimen, cmd_rve, cmd_cell, cmd_relax, cmd_tables, cmd_experiments,
           cmd_bench)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="mapsim", formatter_class=Formatter,
        description="Particle-resolved micromechanics of magnetic active polymers. "
                    "All quantities in SI units (m, Pa, T, A/m, N/m^3). Exit codes: 0 done, "
                    "1 some batch realizations failed or could not be stored (rerun to "
                    "resume), 2 bad input, 3 a solve did not converge, 130 interrupted.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for group in _GROUPS:
        group.register(sub, Formatter)
    return parser


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _check_option_needs(parser, args) -> None:
    """Options that mean nothing without another one are refused (``option_needs`` of each
    command), never silently ignored."""
    needs = getattr(args, "option_needs", None)
    if not needs:
        return
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    check_option_needs(args, sub.choices[args.command], needs)


def _check_paths(args) -> None:
    """Outputs that are inputs, devices, directories or unwritable are refused before any work
    (each command declares its ``outputs``, ``output_dirs`` and ``inputs`` by option name)."""
    inputs = [getattr(args, d, None) for d in getattr(args, "inputs", ())]
    outputs = [(_flag(d), getattr(args, d, None)) for d in getattr(args, "outputs", ())]
    # an output written with a side-car manifest <stem>.manifest.json: the side-car is an
    # output of the run too (it may be neither an input nor another output)
    for d in getattr(args, "sidecar_outputs", ()):
        path = getattr(args, d, None)
        if path is not None and str(path) != "-":
            p = Path(path)
            outputs.append((f"{_flag(d)} {p} (its side-car manifest)",
                            p.with_name(p.stem + ".manifest.json")))
    check_outputs(outputs, inputs)
    writes = getattr(args, "output_dir_writes", {})
    for d in getattr(args, "output_dirs", ()):
        check_output_dir(_flag(d), getattr(args, d, None), inputs, writes.get(d),
                         other_outputs=outputs)


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:          # usage errors (2) and --help (0): return, do not exit
        return int(exc.code or 0)
    try:
        _check_option_needs(parser, args)
        _check_paths(args)
        # no write of this run may replace one of its inputs (atomic_path refuses)
        with protected_inputs(getattr(args, d, None) for d in getattr(args, "inputs", ())):
            return int(args.func(args) or 0)
    except InputError as exc:
        print(f"mapsim {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except ConvergenceError as exc:
        print(f"mapsim {args.command}: did not converge: {exc}", file=sys.stderr)
        return EXIT_CONVERGENCE
    except KeyboardInterrupt:
        print(f"mapsim {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:             # `mapsim ... | head`: the reader left; say nothing
        try:
            sys.stdout = open(os.devnull, "w")     # no second error while Python flushes
        except OSError:
            pass
        return 0


