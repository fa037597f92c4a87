# Two commands do everything: `make run` and `make test` (both set up first).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run test clean

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt tools/setup_system.sh
	@bash tools/setup_system.sh
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	@$(BIN)/python -m pip install -q --upgrade pip >/dev/null
	@$(BIN)/python -m pip install -q -c constraints.txt "torch==2.13.0"
	@$(BIN)/python -m pip install -q -c constraints.txt -e ".[test,mitsuba]"
	@touch $(STAMP)

run: setup
	@$(BIN)/nbrdf-view

test: setup
	@$(BIN)/python -m pytest

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
