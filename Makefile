# Two commands for a fresh machine: `make demo` and `make test` (lint, then the tests).
# Both create or refresh the local virtual environment first (idempotent: a stamp
# file tracks pyproject.toml, so nothing is reinstalled when nothing changed).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEMO_OUT ?= demo_out
PYTEST_ARGS ?=

.PHONY: demo test lint format env clean

env: $(STAMP)

$(STAMP): pyproject.toml .ci/constraints.txt .ci/system-deps.sh
	bash .ci/system-deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	# torch first, pinned: the CPU build on these machines; unpinned pulls CUDA.
	$(BIN)/pip install -q --disable-pip-version-check -c .ci/constraints.txt torch
	$(BIN)/pip install -q --disable-pip-version-check -c .ci/constraints.txt -e ".[all,dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/alcn demo --out $(DEMO_OUT)

# The linter, the formatter's check and the runtime's type hints (pyproject.toml [tool.ruff], [tool.mypy]).
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

# Apply the linter's safe fixes and the formatter.
format: $(STAMP)
	$(BIN)/ruff check --fix .
	$(BIN)/ruff format .

test: lint
	$(BIN)/python -m pytest $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) $(DEMO_OUT) .pytest_cache .ruff_cache .mypy_cache build *.egg-info
