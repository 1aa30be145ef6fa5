# repro: two commands on a fresh machine with Python 3.11 -- `make figures`, `make test`.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
LOCK := requirements.lock

.PHONY: help figures results report test test-slow bench lint lock clean sweeps videos

help:  ## list the targets
	@grep -E '^[a-z-]+:.*##' $(MAKEFILE_LIST) | sed -E 's/:.*## /\t/' | expand -t 12

define CHECK_PYTHON
	@$(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), \
	  f"repro needs Python 3.11 (pybullet 3.2.7 wheels stop there); found {sys.version.split()[0]}"'
endef

# The exact versions of requirements.lock (-c: every package the ranges of pyproject.toml
# pull in is held to its locked version; tests/test_lock.py checks that nothing else is).
$(STAMP): pyproject.toml $(LOCK)
	$(CHECK_PYTHON)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c $(LOCK) -e '.[dev]'
	@touch $(STAMP)

figures: $(STAMP)  ## run missing/stale experiments, then every figure, claims.csv and REPORT.md
	$(BIN)/repro results
	$(BIN)/repro figures
	$(BIN)/repro report

results: $(STAMP)  ## run every experiment whose trace is missing or stale
	$(BIN)/repro results

report: $(STAMP)  ## regenerate REPORT.md from results/ and figures/
	$(BIN)/repro report

test: $(STAMP)  ## the test suite (slow runs excluded)
	$(BIN)/pytest -q

test-slow: $(STAMP)  ## only the long runs marked slow
	$(BIN)/pytest -q -m slow

# The committed sweeps (issue 19): each reruns only the variants not yet judged.
# experiment:variants[:camera] (camera exact unless render: the rendered subsamples)
SWEEPS := pomares2011.exp3:100 pomares2011.exp3_no_tactile:100 \
          pomares2011.exp1:50 pomares2011.exp1:10:render \
          pomares2011.exp2:30 pomares2011.exp2:10:render \
          chan2011.experiment:50 chan2011.experiment:15:render chan2011.simulation:200 \
          chan2011.simulation:10:render \
          thomas2024.case1:360 thomas2024.case2:1100 thomas2024.case3:100 \
          thomas2024.case1:16:render thomas2024.case2:106:render thomas2024.case3:10:render
# (case 1 and case 2 refuse 16 % and 91 % of their starts: 360 and 1100 variants judge >= 300
# and >= 100; their rendered subsamples, and chan2011.experiment's, are the first variants
# with >= 10 judged)

sweeps: $(STAMP)  ## the variant sweeps over the declared ranges -> results/sweeps/ (Dask, all cores)
	@for s in $(SWEEPS); do IFS=: read -r exp n cam <<< "$$s"; \
	  $(BIN)/repro sweep "$$exp" --n "$$n" --seed 0 --camera "$${cam:-exact}" || exit 1; done
	$(BIN)/repro figures
	$(BIN)/repro report

videos: $(STAMP)  ## an MP4 of every canonical run, replayed from its files -> figures/<paper>/videos/
	$(BIN)/repro video --all
	$(BIN)/repro report

bench: $(STAMP)  ## controller-step, QP, NMPC and sensor timings -> results/bench.csv
	$(BIN)/python -m repro.bench

lint: $(STAMP)  ## ruff and mypy
	$(BIN)/ruff check repro experiments tests
	$(BIN)/mypy repro experiments

lock:  ## re-resolve pyproject.toml's ranges in a scratch venv and rewrite requirements.lock
	$(CHECK_PYTHON)
	rm -rf .lock-venv
	$(PYTHON) -m venv .lock-venv
	.lock-venv/bin/pip install --quiet --upgrade pip
	.lock-venv/bin/pip install --quiet '.[dev]'
	{ echo "# Exact versions for make figures / make test (pip constraints). Written by"; \
	  echo "# 'make lock' from pyproject.toml's ranges; after a refresh, remake the committed"; \
	  echo "# runs (tests/test_lock.py checks their manifests against this file)."; \
	  .lock-venv/bin/pip freeze --exclude repro; } > $(LOCK)
	rm -rf .lock-venv build *.egg-info

clean:  ## remove the virtual environment and caches (results and figures are kept)
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
