# Two commands do everything: `make run` and `make test` (both set up first).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup run test test-slow test-ci-slow lint clean fuzz soak goldens mutation

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

# Test files run side by side in TEST_WORKERS processes (pytest-xdist; a file's tests stay in one process, so its
# module fixtures are made once): 2 halves the suite's wall time on a 2-core machine (record 104); 0 runs serially.
TEST_WORKERS ?= 2
XDIST := $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile)

# The default suite (no wall-clock assertions; tests marked slow left out): what CI runs
# (.ci/run), within its 20 minutes. The slow set takes about 25 minutes more: `make test-slow`.
test: setup lint
	@$(BIN)/python -m pytest -m "not slow" $(XDIST) --durations=20

# The slow tests alone (multi-seed statistics, long Monte Carlo runs, installs).
test-slow: setup
	@$(BIN)/python -m pytest -m slow

# The slow tests CI runs after `make test` (.ci/run): those also marked ci_slow, chosen by measured duration to
# fit CI's 20 minutes (the list and the ones left to `make test-slow`: docs/decisions/076-ci-slow-subset.md).
test-ci-slow: setup
	@$(BIN)/python -m pytest -m "slow and ci_slow"

# Rewrites every stored render or array the tests compare against (golden images, the
# session render: tests/viewer/goldens.py; the look-development reference lobes and sphere
# renders the shipped networks are held to: tests/training/shipped_lobes.py, shipped_renders.py);
# nothing else writes them.
goldens: setup
	@$(BIN)/python tests/viewer/goldens.py
	@$(BIN)/python tests/training/shipped_lobes.py
	@$(BIN)/python tests/training/shipped_renders.py

# The packages mypy checks; it sees the repository's folders under their installed names through links.
MYPY_PACKAGES := nbrdf.neural nbrdf.cli
LINT_ROOT := $(VENV)/lint

lint: setup
	@$(BIN)/ruff check --quiet .
	@mkdir -p $(LINT_ROOT)/nbrdf
	@for d in cli neural training imaging viewer; do ln -sfn ../../../$$d $(LINT_ROOT)/nbrdf/$$d; done
	@cd $(LINT_ROOT) && ../bin/mypy --config-file ../../pyproject.toml $(addprefix -p ,$(MYPY_PACKAGES))

# Every input format fuzzed (tools/fuzz.py): 10,000 byte-level mutations per format, then the
# structure-aware hypothesis tests at 1,000 examples each; FUZZ_SEED picks the mutations.
FUZZ_SEED ?= 1
FUZZ_COUNT ?= 10000
fuzz: setup
	@nice $(BIN)/python tools/fuzz.py --count $(FUZZ_COUNT) --seed $(FUZZ_SEED)
	@NBRDF_FUZZ_EXAMPLES=1000 NBRDF_FUZZ_MUTATIONS=1000 nice $(BIN)/python -m pytest tests/fuzz -q

# The window under Xvfb for 1,000 random edits: memory and live GL objects per 100 edits, as the states come
# and in one state every 25 edits (tools/soak.py).
soak: setup
	@xvfb-run -a -s "-screen 0 640x480x24" nice $(BIN)/python tools/soak.py --edits 1000 --seed 1 --in-state --out soak.json

# Mutation testing of the pure-Python core (material schema, stack translator, coat, microfacet, closed-form
# BxDFs, tone mappers) with mutmut against their fast unit tests ([tool.mutmut] in pyproject.toml); prints the
# kill rate per module. The staging tree build/mutation is kept, so a rerun tests only changed functions;
# MUTATION_ARGS=--fresh starts over.
MUTATION_ARGS ?=
mutation: setup
	@nice $(BIN)/python tools/mutation.py $(MUTATION_ARGS)

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
