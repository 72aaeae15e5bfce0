# Two entry points for a fresh machine: `make run` (the main job) and `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
DB ?= llcps.db

.PHONY: setup run test test-slow clean

$(BIN)/llcps: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(BIN)/llcps

setup: $(BIN)/llcps

run: setup
	$(BIN)/llcps --db $(DB) db init
	$(BIN)/llcps --db $(DB) db status

test: setup
	$(BIN)/python -m pytest

test-slow: setup
	$(BIN)/python -m pytest -m slow

clean:
	rm -rf $(VENV) *.egg-info
