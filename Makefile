# Every target installs what it needs into .venv first (scripts/setup.sh).
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test test-fast lint bench clean

setup:
	scripts/setup.sh dev,ray

demo:
	scripts/setup.sh
	$(VENV)/bin/avrisk demo

test:
	scripts/setup.sh dev,ray
	$(PY) -m pytest -n 2

test-fast:
	scripts/setup.sh dev,ray
	$(PY) -m pytest -n 2 -m "not slow"

lint:
	scripts/setup.sh dev
	$(VENV)/bin/ruff check avrisk tests benchmarks
	$(VENV)/bin/ruff format --check avrisk tests benchmarks

bench:
	scripts/setup.sh dev,bench
	$(PY) benchmarks/estimators.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
