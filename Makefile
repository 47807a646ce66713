# omnical: `make run` runs the demo, `make test` runs ruff (check and format), mypy, the import
# contracts (import-linter) and pytest.
# Both create .venv and install the project into it on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint format typecheck contracts unit bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "omnical needs Python 3.11 or newer")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

run: $(STAMP)
	$(BIN)/omnical demo --overwrite

test: lint typecheck contracts unit

lint: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench

format: $(STAMP)
	$(BIN)/ruff format src tests bench
	$(BIN)/ruff check --fix src tests bench

contracts: $(STAMP)
	$(BIN)/lint-imports

typecheck: $(STAMP)
	$(BIN)/mypy

# The parallel suite on every core, whole files per worker, the heaviest files first
# (tests/conftest.py); then the scaled-clock `alone` tests one after another in one process,
# with nothing beside them (two queues side by side on xdist workers stalled the x3 square).
unit: $(STAMP)
	$(BIN)/pytest -n auto --dist loadfile --no-loadscope-reorder -m "not alone"
	$(BIN)/pytest -p no:xdist -m alone

bench: $(STAMP)
	$(BIN)/python bench/bench_twin.py
	$(BIN)/python bench/bench_multilateration.py
	$(BIN)/python bench/bench_bag.py
	$(BIN)/python bench/bench_startup.py

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache .mypy_cache .ruff_cache
