"""Shared fixtures of the test suite."""
import contextlib
import importlib.util
import os
from pathlib import Path

import pytest


def pytest_configure(config):
    """Under pytest-xdist, each worker's share of the cores: ``make test`` runs two workers on
    two cores, and with numba's and BLAS's default of a thread per core in each, four threads
    compete for two cores (numba's parallel kernels then wait on descheduled threads: the
    heaviest tests took 1.2x as long). The tests that compare one thread with several set
    ``numba.config.NUMBA_NUM_THREADS`` (all the cores) themselves."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    if workers < 2:
        return
    import numba
    from threadpoolctl import threadpool_limits
    share = max(1, (os.cpu_count() or 1) // workers)
    numba.set_num_threads(min(share, numba.config.NUMBA_NUM_THREADS))
    config._mapsim_blas_limit = threadpool_limits(limits=share, user_api="blas")


#: the modules that took longest (``make test --durations``, 2 cores, cold numba cache: the
#: README tutorial ~200 s, the fault scenarios ~140 s, the dilute sphere ~100 s, the real-data
#: account ~70 s, the specimen account ~55 s, the cut cells ~50 s), longest first.
LONG_MODULES = ("tests/test_readme_tutorial.py",
                "tests/homogenize/test_batch_faults.py",
                "tests/homogenize/test_dilute_rate.py",
                "tests/homogenize/experiments/test_example_diagnose_real_data.py",
                "tests/homogenize/experiments/test_specimen_account.py",
                "tests/homogenize/test_cut.py")
ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items):
    """The longest modules first, each kept whole, the rest in collection order. ``make test``
    hands whole modules to the workers (``--dist loadscope``: a module's fixtures are built
    once, not once per worker), in this order (``--no-loadscope-reorder``): a long module
    handed out last would leave the other worker idle to the end."""
    rank = {ROOT / m: i for i, m in enumerate(LONG_MODULES)}
    items.sort(key=lambda item: rank.get(Path(item.path).resolve(), len(rank)))   # stable


def _load_script(path: Path):
    """Import the script at ``path`` (an example or a results/ study, not a package module) as a
    fresh module named after its file."""
    path = Path(path)
    spec = importlib.util.spec_from_file_location(f"script_{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def load_script():
    """``load_script(path)``: a script outside the packages, imported as a module."""
    return _load_script


@contextlib.contextmanager
def _inprocess_client(n_workers: int):
    """A Dask client on an in-process (threads) cluster of ``n_workers`` single-thread workers,
    without a dashboard: what the batch tests run on."""
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as c, Client(c) as cl:
        yield cl


@pytest.fixture(scope="session")
def inprocess_client():
    """``with inprocess_client(n) as client:`` a Dask client on an in-process cluster of ``n``
    single-thread workers (the batch tests' cluster)."""
    return _inprocess_client


#: the synthetic study the macro tests read M_eff (and with fem, E_eff) from: phi 0.02 and 0.05,
#: B_T up to 2 T, 4 realizations
SYNTHETIC_STUDY = """
[study]
name = "syn"
seed = 7
realizations = 4
n_particles = 20
evaluator = "synthetic"
{fem}[grid]
phi = [0.02, 0.05]
B_T = [0.05, 0.2, 0.5, 1.0, 2.0]
gradB_T_per_m = 1.78
"""


def _synthetic_table(path: Path, study_text: str | None = None, *, fem: bool = False) -> Path:
    """A finished table of the synthetic evaluator (known means and deviations), made
    in-process: every part written directly, then aggregated by run_batch (no Dask).
    ``study_text`` None: :data:`SYNTHETIC_STUDY` (``fem``: with ``fem = true`` on 8^3, which
    adds E_eff and its discretization error)."""
    if study_text is None:
        study_text = SYNTHETIC_STUDY.format(fem="fem = true\nvoxels = 8\n" if fem else "")
    from homogenize.tables._evaluate import get_evaluator
    from homogenize.tables._study import parse_study
    from homogenize.tables.batch import _part_path, _write_part, parts_dir_for, run_batch
    study = parse_study(study_text, str(path.with_suffix(".toml")))
    ev = get_evaluator("synthetic")
    parts = parts_dir_for(path)
    for task in study.tasks():
        k = task.key(ev.id)
        _write_part(_part_path(parts, task, k), task, k, ev(task))
    run_batch(study, path, progress=False)
    return path


@pytest.fixture(scope="session")
def synthetic_table():
    """``synthetic_table(path[, study_text][, fem=True])``: a finished synthetic-evaluator table
    at ``path`` (default study: :data:`SYNTHETIC_STUDY`)."""
    return _synthetic_table
