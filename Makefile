# Quick start: `make run` (set up .venv, run the main job) and `make test` (run the test suite).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test venv bench clean peers

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

# per-run facts (git revision, times, machine) go to an ignored log, so that `make run` on the
# same code reproduces the committed results byte for byte
RUNLOG := MAPSIM_RUN_LOG=results/run_log.jsonl

run: $(STAMP)
	$(RUNLOG) $(BIN)/mapsim paper --out results/paper --json results/paper/paper.json
	$(RUNLOG) $(BIN)/mapsim chain --out results/chain

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/mapsim bench --json results/bench/bench.json

# Third-party solvers the tests use when present (Debian): CalculiX runs the exported decks.
peers:
	apt-get update && apt-get install -y calculix-ccx

clean:
	rm -rf $(VENV) build *.egg-info
