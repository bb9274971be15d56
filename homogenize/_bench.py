"""``mapsim bench``: performance records, each a ratio against a reference run in the same command.

Every provider module exposes ``bench_records(quick: bool) -> list[dict]``; a record has the
keys ``name, n, seconds, reference, reference_seconds, ratio, max_rel_error`` (plus any
extra keys it needs). ``ratio`` is reference_seconds / seconds (> 1: we are faster).
"""
from __future__ import annotations

import importlib
import sys
import time

from micro._io import manifest, write_json

_PROVIDERS = (
    "micro._bench_particles",
    "micro._bench_dipoles",
    "homogenize._bench_cell",
    "homogenize.macro._bench",
    "homogenize._bench_tables",
)


def run(quick: bool = False, only: str | None = None) -> list[dict]:
    records = []
    for name in _PROVIDERS:
        if only and only not in name:
            continue
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue
            raise
        t0 = time.perf_counter()
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        recs = mod.bench_records(quick)
        print(f"[bench] {name}: {len(recs)} records in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr, flush=True)
        records.extend(recs)
    return records


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _cmd(args) -> int:
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
    p.add_argument("--only", default=None, help="run only providers whose module name contains this")
    p.add_argument("--json", default=None, help="write the records to this JSON file")
    p.set_defaults(func=_cmd)
