"""The ``mapsim`` command.

Each command lives in the module of the layer it belongs to and exposes
``register(subparsers)``, which adds its parser(s) with ``set_defaults(func=...)``; ``func(args)``
returns the exit code. Any :class:`micro.InputError` raised by a command becomes one line on
stderr and exit code 2; argparse's own usage errors also exit 2.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from micro._validate import InputError

# Modules that provide commands, in the order their commands appear in --help.
_COMMAND_MODULES = (
    "homogenize.macro._cli",        # paper, export, beam, channel
    "homogenize._cli_rve",          # rve
    "homogenize._cli_cell",         # homogenize
    "homogenize._cli_tables",       # batch, rve-size, compare
    "homogenize.experiments._cli",  # diagnose, diagnose-study
    "homogenize._bench",            # bench
)


class _Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    pass


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mapsim", formatter_class=_Formatter,
        description="Particle-resolved micromechanics of magnetic active polymers. "
                    "All quantities in SI units (m, Pa, T, A/m, N/m^3).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _COMMAND_MODULES:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:   # a layer not built yet; never hide other errors
            if exc.name == name:
                continue
            raise
        mod.register(sub, _Formatter)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"mapsim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mapsim {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
