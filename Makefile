# dume: `make demo` and `make test` are the whole set-up on a fresh machine.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: install demo test test-quick bench lint clean

install: $(STAMP)

$(STAMP): pyproject.toml setup.py services/navigation/astar.c
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(VENV)/bin/rerun analytics disable >/dev/null 2>&1 || true
	touch $(STAMP)

demo: install
	$(VENV)/bin/dume demo

# The unit tests on both cores (pytest-xdist); the system tests one at a time: their
# stacks use 1.4 cores each, and some run against wall clocks.
test: install
	$(PY) -m pytest -q -n 2 --dist worksteal --durations=10 tests/unit
	$(PY) -m pytest -q --durations=15 tests/integration

test-quick: install
	$(PY) -m pytest -q -m "not slow"

bench: install
	$(VENV)/bin/dume bench all

lint: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy

clean:
	rm -rf $(VENV) var .pytest_cache .mypy_cache .ruff_cache
