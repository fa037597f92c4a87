# Two commands do everything: `make run` and `make test` (both set up first).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run test lint clean

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

test: setup lint
	@$(BIN)/python -m pytest

# The packages mypy checks; it sees the repository's folders under their installed names through links.
MYPY_PACKAGES := nbrdf.neural nbrdf.cli
LINT_ROOT := $(VENV)/lint

lint: setup
	@$(BIN)/ruff check --quiet .
	@mkdir -p $(LINT_ROOT)/nbrdf
	@for d in cli neural training viewer; do ln -sfn ../../../$$d $(LINT_ROOT)/nbrdf/$$d; done
	@cd $(LINT_ROOT) && ../bin/mypy --config-file ../../pyproject.toml $(addprefix -p ,$(MYPY_PACKAGES))

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
