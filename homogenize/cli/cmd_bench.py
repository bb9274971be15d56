"""``mapsim bench``: performance records, each a ratio against a reference run in the same
command (see :mod:`homogenize.bench`)."""
from __future__ import annotations

from micro.common.files import manifest, write_json

from homogenize.bench import PROVIDERS, run
from homogenize.cli._common import check_outputs, one_line_errors


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _cmd(args) -> int:
    check_outputs([("--json", args.json)])
    records = run(quick=args.quick, only=args.only)
    if args.json:   # written first: the figures must survive any trouble in printing them
        write_json(args.json, {"records": records, "manifest": manifest({"quick": args.quick})})
    for r in records:
        print(f"{r['name']:<48s} n={r.get('n')!s:<10} {_fmt(r.get('seconds'), '9.4f')} s "
              f"vs {r.get('reference')}: ratio {_fmt(r.get('ratio'), '.3g')}"
              + (f" ({r['note']})" if r.get("note") else ""))
    return 0


def register(sub, formatter):
    p = sub.add_parser("bench", formatter_class=formatter,
                       help="performance benchmarks as ratios against reference runs",
                       description=__doc__)
    p.add_argument("--quick", action="store_true", help="smaller sizes (for CI and smoke runs)")
    p.add_argument("--only", default=None, choices=tuple(PROVIDERS),
                   help="run only this provider (default: all)")
    p.add_argument("--json", default=None, help="write the records to this JSON file")
    p.set_defaults(func=_cmd, outputs=("json",))
    one_line_errors(sub)
