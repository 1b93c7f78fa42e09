# clfx: the two commands of the README's quick start are `make demo` and `make test`.
# Each installs what is missing first (Debian's PoCL and OpenCL headers, a .venv with clfx,
# its test extras and pyvkfft built for OpenCL): see scripts/setup.sh.

VENV ?= .venv
PY := $(VENV)/bin/python
CLFX := $(VENV)/bin/clfx
DEMO_OUT ?= demo-out
PYTEST_ARGS ?=
# Test workers (pytest-xdist): each module whole on one worker, the modules tests/conftest.py
# names (SPLIT_ACROSS_WORKERS) one test at a time.  0 runs the suite in one process.
PYTEST_WORKERS ?= 2

.PHONY: setup demo test bench docs clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(CLFX) demo $(DEMO_OUT) --overwrite

test: setup
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadscope $(PYTEST_ARGS)

bench: setup
	$(CLFX) bench --size 1920x1080 --markdown bench.md --json > bench.jsonl

# The generated reference pages: docs/effects/*.md and the looks table in docs/looks.md.
docs: setup
	$(PY) -m clfx.docsgen

clean:
	rm -rf $(DEMO_OUT) build dist *.egg-info .pytest_cache
