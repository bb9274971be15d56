"""Benchmarks of ``mapsim bench``: performance records, each a ratio against a reference run in
the same command (time and, where measured, peak memory).

Every provider module exposes ``bench_records(quick: bool) -> list[dict]``; a record has the
keys ``name, n, seconds, reference, reference_seconds, ratio, max_rel_error`` (plus any
extra keys it needs). ``ratio`` is reference_seconds / seconds (> 1: we are faster).
:mod:`.reference` holds the plain-numpy twins of the numba kernels, used by the benchmarks and
by the kernel tests.
"""
from __future__ import annotations

import sys
import time

from homogenize.bench import (bench_cell, bench_dipoles, bench_macro, bench_particles,
                              bench_peer, bench_relax, bench_specimen, bench_tables)

__all__ = ["PROVIDERS", "run"]

#: Providers by name, in the order they run.
PROVIDERS = {"particles": bench_particles, "dipoles": bench_dipoles, "cell": bench_cell,
             "macro": bench_macro, "tables": bench_tables, "relax": bench_relax,
             "specimen": bench_specimen, "peer": bench_peer}


def run(quick: bool = False, only: str | None = None) -> list[dict]:
    """Run the providers whose name contains ``only`` (all if None); return their records."""
    records = []
    for name, mod in PROVIDERS.items():
        if only and only not in name:
            continue
        t0 = time.perf_counter()
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        recs = mod.bench_records(quick)
        print(f"[bench] {name}: {len(recs)} records in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr, flush=True)
        records.extend(recs)
    return records
