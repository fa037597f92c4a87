# Two commands do everything: `make run` and `make test` (both set up first).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run test test-slow clean goldens

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt tools/setup_system.sh
	@bash tools/setup_system.sh
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	@$(BIN)/python -m pip install -q --upgrade pip >/dev/null
	@$(BIN)/python -m pip install -q -c constraints.txt "torch==2.13.0"
	@$(BIN)/python -m pip install -q -c constraints.txt -e ".[test]"
	@touch $(STAMP)

run: setup
	@$(BIN)/nbrdf-view

# The default suite (no wall-clock assertions; tests marked slow left out); CI runs
# `make test test-slow`, so every test runs there.
test: setup
	@$(BIN)/python -m pytest -m "not slow"

# The slow tests alone (multi-seed statistics, long Monte Carlo runs, installs).
test-slow: setup
	@$(BIN)/python -m pytest -m slow

# Rewrites every stored render or array the tests compare against (golden images, the
# session render: tests/viewer/goldens.py; the look-development reference lobes the
# shipped networks are held to: tests/training/shipped_lobes.py); nothing else writes them.
goldens: setup
	@$(BIN)/python tests/viewer/goldens.py
	@$(BIN)/python tests/training/shipped_lobes.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
