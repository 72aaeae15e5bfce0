# Two entry points for a fresh machine: `make run` (the main job) and `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
DB ?= llcps.db

.PHONY: setup run lint test test-fast test-slow clean

$(BIN)/llcps: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(BIN)/llcps

setup: $(BIN)/llcps

# The paper's sequence on the default store: pretrain the world model on 200 random
# interactions, then solve the three scenarios' novelties in order (each solve trains
# on everything before it), and end with the exploration table. A scenario the budget
# cannot solve exits 1; the sequence goes on and the table shows it.
run: setup
	$(BIN)/llcps --db $(DB) db init
	$(BIN)/llcps --db $(DB) pretrain --trials 200 --seed 1 --workers 2
	-$(BIN)/llcps --db $(DB) solve scenario1
	-$(BIN)/llcps --db $(DB) solve scenario2
	-$(BIN)/llcps --db $(DB) solve scenario3
	$(BIN)/llcps --db $(DB) inspect episodes

# The lint, then the whole suite, slow tests included (what CI runs), on both cores, listing its 25
# slowest tests and then its budget (tests/conftest.py): the wall time against 25 min, and the
# tests nearest their 600 s timeout, with a warning for any over a third of it. .ci/services.sh
# installs the system packages the tests need (as root); tests/services.sh runs the suite
# beside a throwaway PostgreSQL server (installed first when missing) and stops it after.
test: lint
	bash .ci/services.sh
	tests/services.sh $(BIN)/python -m pytest -n 2 --dist loadfile --durations=25

# Unused imports and variables, undefined names, syntax errors (pyproject.toml [tool.ruff]);
# then the import contract (pyproject.toml [tool.importlinter]): layers import downward only,
# and no two modules of a package import each other in a loop.
lint: setup
	$(BIN)/ruff check llcps tests migrations
	$(BIN)/lint-imports --no-cache

# The inner loop: everything but the slow tests (sweep slices, lifelong sequences in physics,
# end-to-end experiment runs), on both cores; the PostgreSQL cases are skipped.
test-fast: setup
	$(BIN)/python -m pytest -n 2 --dist loadfile -m "not slow"

test-slow: setup
	tests/services.sh $(BIN)/python -m pytest -n 2 --dist loadfile --durations=25 -m slow

clean:
	rm -rf $(VENV) *.egg-info
