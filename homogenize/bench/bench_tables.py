"""Benchmark of ``mapsim batch``: realizations per minute with 1 and 2 Dask workers.

A fixed small study of real RVEs (particles -> self-consistent dipoles) runs on a local cluster
of 1 worker process (the reference) and of 2; the ratio is the parallel speed-up (ideal 2 on
two free cores). Each cluster is started and warmed up (imports, numba caches) before the
clock starts, so the figure is the steady-state throughput; the two set-ups alternate and
each keeps its fastest run (the machine is shared). ``max_rel_error`` is the largest
relative difference between the two tables: 0, since the table must not depend on the number
of workers.

The second record is the batch OVERHEAD at production size (2000 particles per RVE, FEM on): the
same realizations are first computed one after another by the evaluator alone inside a worker
process (its environment: one numba, OpenMP and BLAS thread), then as a ``mapsim batch`` on 1
and on 2 workers. The
overhead is ``t_batch / (sum of single-RVE times / workers) - 1`` (target < 10 %). With 2 workers
that figure also holds the hardware's own loss when two computations share the two cores (memory
bandwidth, caches, clock), so the record splits it: the same realizations computed on both
workers at once without the batch machinery (``hardware_slowdown_two_at_once``), and the batch
against that (``overhead_vs_concurrent_fraction``: scheduling, serialization, table writing).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from homogenize.tables._evaluate import RVEEvaluator
import contextlib
import os
from homogenize.tables._study import parse_study
from homogenize.tables.batch import read_table, run_batch

_STUDY = """
[study]
name = "bench"
seed = 1
realizations = {R}
n_particles = {N}
evaluator = "rve"
[grid]
phi = 0.035
B_T = [0.05, 0.5]
gradB_T_per_m = 1.78
"""


_STUDY_FEM = """
[study]
name = "bench-overhead"
seed = 7
realizations = {R}
n_particles = {N}
evaluator = "rve"
fem = true
voxels = {V}
[grid]
phi = 0.035
B_T = 0.1
gradB_T_per_m = 1.78
"""


def _warm(task):
    RVEEvaluator()(task)
    return True


def _cluster(workers):
    from dask.distributed import LocalCluster
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address="127.0.0.1:0",
                        env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})


def bench_records(quick: bool) -> list[dict]:

    from dask.distributed import Client

    load_before = os.getloadavg()[0]
    R, N = (4, 60) if quick else (12, 150)
    repeats = 1 if quick else 2
    study = parse_study(_STUDY.format(R=R, N=N), "bench-study.toml")
    n = len(study.tasks())
    times = {1: [], 2: []}
    with tempfile.TemporaryDirectory() as d, contextlib.ExitStack() as stack:
        clients = {}
        for w in (1, 2):
            clients[w] = stack.enter_context(Client(stack.enter_context(_cluster(w))))
            # imports and numba caches on every worker before the clock starts
            clients[w].run(_warm, study.replace(seed=study.seed + 1).tasks()[0])
        # alternate the two set-ups and keep each one's fastest run: the machine is shared,
        # and the minimum is the run least disturbed by other load
        for rep in range(repeats):
            for w in (1, 2):
                t0 = time.perf_counter()
                run_batch(study, Path(d) / f"w{w}_{rep}.h5", client=clients[w], progress=False)
                times[w].append(time.perf_counter() - t0)
        a, b = read_table(Path(d) / "w1_0.h5"), read_table(Path(d) / "w2_0.h5")
        err = 0.0
        for q, v in a.values.items():
            scale = np.maximum(np.abs(v), 1e-300)
            err = max(err, float(np.max(np.abs(b.values[q] - v) / scale)))
    t1, t2 = min(times[1]), min(times[2])
    return [{
        "name": f"tables: batch of {n} RVEs ({N} particles), 2 workers vs 1",
        "n": n, "seconds": t2, "reference": "same batch, 1 worker", "reference_seconds": t1,
        "ratio": t1 / t2, "max_rel_error": err,
        "realizations_per_minute_1_worker": 60.0 * n / t1,
        "realizations_per_minute_2_workers": 60.0 * n / t2,
        "runs_seconds": {"1_worker": times[1], "2_workers": times[2]},
        # the speed-up needs two free cores: the 1-minute load average tells whether it had them
        "load_average_1min": [load_before, os.getloadavg()[0]],
        "cpu_count": os.cpu_count(),
    }] + overhead_records(quick)


def _concurrent(client, tasks) -> tuple[float, list[float]]:
    """Every worker computes its share of ``tasks`` (round robin) one after another, all workers
    at once: (wall seconds until all are done, seconds per realization in task order)."""
    workers = sorted(client.scheduler_info()["workers"])
    shares = [tasks[i::len(workers)] for i in range(len(workers))]
    t0 = time.perf_counter()
    futs = [client.submit(_time_tasks, sh, workers=[a], pure=False)
            for a, sh in zip(workers, shares) if sh]
    got = client.gather(futs)
    wall = time.perf_counter() - t0
    per = [0.0] * len(tasks)
    for i, times in enumerate(got):
        for j, sec in enumerate(times):
            per[i + j * len(workers)] = sec
    return wall, per


def _time_tasks(tasks) -> list[float]:
    """Each realization computed alone, one after another, inside a worker process (same
    environment as the batch: one numba, OpenMP and BLAS thread); seconds per realization."""
    ev = RVEEvaluator(fem=True)
    out = []
    for task in tasks:
        t0 = time.perf_counter()
        ev(task)
        out.append(time.perf_counter() - t0)
    return out


def overhead_records(quick: bool) -> list[dict]:
    """Batch overhead of ``mapsim batch`` at production RVE size, 1 and 2 workers."""
    from dask.distributed import Client

    R, N, V = (2, 300, 12) if quick else (4, 2000, 24)
    study = parse_study(_STUDY_FEM.format(R=R, N=N, V=V), "bench-overhead.toml")
    load_before = os.getloadavg()[0]
    singles, total = [], 0.0
    recs = []
    with tempfile.TemporaryDirectory() as d:
        for w in (1, 2):
            with _cluster(w) as cluster, Client(cluster) as client:
                client.run(_warm, study.replace(seed=study.seed + 1).tasks()[0])
                if w == 1:   # the single-RVE compute times, in the worker (same environment)
                    singles = client.submit(_time_tasks, study.tasks(), pure=False).result()
                    total = float(sum(singles))
                else:        # the same computations on both workers at once, no batch machinery
                    conc_wall, conc = _concurrent(client, study.tasks())
                t0 = time.perf_counter()
                run_batch(study, Path(d) / f"w{w}.h5", client=client, progress=False)
                t = time.perf_counter() - t0
            ideal = total / min(w, len(singles))
            extra = {}
            if w > 1:
                # two single-threaded computations on two cores each run slower than one alone
                # (shared memory bandwidth and cache, clock): that is the hardware, not the
                # batch. The batch's own overhead is measured against the same work run at once
                # on the same two workers without the batch (no scheduling of single tasks, no
                # table writing).
                extra = {"concurrent_compute_seconds": conc_wall,
                         "concurrent_single_rve_seconds": conc,
                         "hardware_slowdown_two_at_once": float(sum(conc)) / total - 1.0,
                         "overhead_vs_concurrent_fraction": t / conc_wall - 1.0}
            recs.append({
                "name": f"tables: batch overhead, {len(singles)} RVEs of {N} particles + FEM "
                        f"{V}^3, {w} worker{'s' if w > 1 else ''}",
                "n": len(singles), "seconds": t,
                "reference": f"sum of the single-RVE compute times / {w} (same realizations, "
                             "evaluator alone in a worker process, one after another)",
                "reference_seconds": ideal, "ratio": ideal / t,
                "overhead_fraction": t / ideal - 1.0, "target_overhead_fraction": 0.10,
                "max_rel_error": None, "single_rve_seconds": singles,
                "load_average_1min": [load_before, os.getloadavg()[0]],
                "cpu_count": os.cpu_count(),
                "note": "2 workers need 2 free cores; on a loaded machine the 2-worker figure "
                        "measures the load, not the batch" if w > 1 else None, **extra,
            })
    return recs
