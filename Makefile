# Quick start: `make run` (set up .venv, run the main job) and `make test` (run the test suite).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# the tested set of every package (pip constraints); `make lock` refreshes it
LOCK   := .ci/constraints.txt
# newest versions that pyproject.toml allows, without the lock (for `make lock`, `make test-latest`)
LATEST := .venv-latest
# pytest workers (pytest-xdist): both cores, numba and BLAS on one thread in each worker
# (tests/conftest.py). Fresh clone, new venv, cold numba cache, 2 cores (AMD EPYC, session 25):
# two workers 16.5 min (17.6-19.4 min in session 26, 17.4 min with whole modules per worker in
# session 27); with two threads in each worker it had taken 25 min.
# PYTEST_WORKERS=0: one process.
PYTEST_WORKERS ?= 2
# each test module whole on one worker, its fixtures built once (the default split had built
# the heaviest module fixtures on both workers), the longest modules first (tests/conftest.py:
# LONG_MODULES); the 15 slowest tests listed at the end
PYTEST_FLAGS := -q -n $(PYTEST_WORKERS) --dist loadscope --no-loadscope-reorder --durations=15

.PHONY: run test venv bench clean peers lock latest test-latest

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -c $(LOCK) --upgrade pip
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

# per-run facts (git revision, times, machine) go to an ignored log, so that `make run` on the
# same code reproduces the committed results byte for byte
RUNLOG := MAPSIM_RUN_LOG=results/run_log.jsonl

run: $(STAMP)
	$(RUNLOG) $(BIN)/mapsim paper --out results/paper --json results/paper/paper.json
	$(RUNLOG) $(BIN)/mapsim chain --out results/chain

test: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_FLAGS)

bench: $(STAMP)
	$(BIN)/mapsim bench --json results/bench/bench.json

# Third-party solvers the tests use when present (Debian): CalculiX runs the exported decks and
# its own elements are compared with mapsim's in results/peers/calculix.md (not part of `make run`).
peers: $(STAMP)
	apt-get update && apt-get install -y calculix-ccx
	$(RUNLOG) $(BIN)/mapsim paper-calculix --out results/peers

# The newest versions pyproject.toml allows, in their own environment (the lock is not used).
$(LATEST)/.installed: pyproject.toml
	rm -rf $(LATEST)
	$(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python -m pip install --quiet --upgrade pip
	$(LATEST)/bin/python -m pip install --quiet -e ".[test]"
	touch $@

latest: $(LATEST)/.installed

# The suite against the newest allowed versions (what a user without the lock gets today).
test-latest: $(LATEST)/.installed
	$(LATEST)/bin/python -m pytest $(PYTEST_FLAGS)

# Refresh the lock from the newest allowed versions; run `make test-latest` first.
lock: $(LATEST)/.installed
	{ sed -n '1,2p' $(LOCK); \
	  echo "# Resolved on $$(date -u +%Y-%m-%d) with Python $$($(LATEST)/bin/python -c 'import platform; print(platform.python_version())') on $$(uname -m) Linux."; \
	  echo "pip==$$($(LATEST)/bin/python -m pip --version | cut -d' ' -f2)"; \
	  $(LATEST)/bin/python -m pip freeze --exclude-editable | grep -v '^-e '; } > $(LOCK).new
	mv $(LOCK).new $(LOCK)

clean:
	rm -rf $(VENV) $(LATEST) build *.egg-info
