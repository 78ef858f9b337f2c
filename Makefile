# pige_sym — make targets.  `make help` lists them.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
MACHINE ?= wC'A'bXYZ(C1)t
# Test processes (pytest-xdist): one per core; each test file runs whole in one of them (its module fixtures once).
TEST_JOBS ?= auto
# LinuxCNC tests: one process per file of tests/linuxcnc, all at once (a simulation's servo thread is paced by the
# wall clock: it mostly waits, about 6 % of a core each); a new file gets its own (docs/testing.md).
LCNC_JOBS ?= $(words $(wildcard tests/linuxcnc/test_*.py))
# Kernels live in generated/ (the shipped machines are tracked there; the list is in pige_sym/constants.py).

.PHONY: help venv gen gen-all check-generated test test-slow test-linuxcnc lint demo bench clean

help:  ## list targets
	@grep -E '^[a-zA-Z_-]+:.*## ' Makefile | sed -E 's/:.*## /\t/' | expand -t 18

$(STAMP): pyproject.toml setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(if $(TEST_ENV),$(PY) tests/bytecode_prefix.py $(VENV)/pycache $(VENV)/lib)
	$(TEST_ENV) $(PY) -m compileall -q -j 0 pige_sym generated tests > /dev/null
	$(TEST_ENV) $(PY) -m pytest -q --collect-only -p no:cacheprovider > /dev/null || echo "venv: the tests were not collected (make test will say why)"
	touch $(STAMP)

venv: $(STAMP)  ## create .venv and install pige_sym with dev tools

gen: $(STAMP)  ## generate kernels for MACHINE="..." into generated/
	$(PY) -m pige_sym gen "$(MACHINE)"

gen-all: $(STAMP)  ## regenerate every shipped machine's kernels in generated/
	$(PY) -m pige_sym gen --shipped --all-shipped

check-generated: $(STAMP)  ## regenerate shipped kernels in memory and fail on any code difference
	$(PY) -m pige_sym gen --check --all-shipped

# Whole files to each process, in the order tests/conftest.py gives them (the heaviest first), not xdist's (most tests
# first).  Under PYTHONDONTWRITEBYTECODE (set on some build machines) the suite's bytecode (its own, the pige commands'
# and the libraries') goes to .venv/pycache and is kept from one run to the next: never beside the sources, and not
# compiled again by every process (collection: 13.6 -> 7.0 s CPU).  A PYTHONPYCACHEPREFIX of your own wins.
# `make venv` links the bytecode pip compiled for the venv's packages into it (tests/bytecode_prefix.py): the first
# run on a fresh clone no longer compiles NumPy, SciPy, matplotlib and SymPy again; it compiles pige_sym, its kernels
# and the tests' helper modules as pip does an installed package's (where make test reads bytecode), not make test's
# two processes and the pige commands they start, each the same modules at once. It collects the tests once too: pytest
# keeps the test modules' assertion-rewritten bytecode, which both processes of the first make test made again (6.5 s
# of CPU each).
TEST_OPTS := -n $(TEST_JOBS) --dist loadfile --no-loadscope-reorder
TEST_ENV  := $(if $(and $(PYTHONDONTWRITEBYTECODE),$(if $(PYTHONPYCACHEPREFIX),,x)),env -u PYTHONDONTWRITEBYTECODE PYTHONPYCACHEPREFIX=$(CURDIR)/$(VENV)/pycache)

test: $(STAMP)  ## run the default test suite (slow studies excluded), one process per core
	$(TEST_ENV) $(PY) -m pytest -q $(TEST_OPTS)

# PIGE_TEST_SLOW=1: the costliest property tests draw all their examples (tests/property_budget.py; a third in make test).
test-slow: $(STAMP)  ## run the slow studies too (not the LinuxCNC runs: make test-linuxcnc)
	PIGE_TEST_SLOW=1 $(TEST_ENV) $(PY) -m pytest -q -m 'not linuxcnc' $(TEST_OPTS)

test-linuxcnc: $(STAMP)  ## the loop on real LinuxCNC 2.9 simulations, side by side (tests/linuxcnc; skips without linuxcnc-uspace)
	$(PY) -m pytest -q -rsP -m linuxcnc -n $(LCNC_JOBS) --dist loadfile --durations=40 tests/linuxcnc

lint: $(STAMP)  ## ruff + mypy on pige_sym/
	$(VENV)/bin/ruff check pige_sym tests benchmarks
	$(VENV)/bin/mypy pige_sym

demo: $(STAMP)  ## the whole story on the default AC machine
	$(PY) -m pige_sym demo --force

bench: $(STAMP)  ## install the peers (JAX, CasADi: the bench extra), run benchmarks/, write benchmarks/RESULTS.md
	$(PY) -m pip install --quiet -e '.[bench]' || echo "bench extra not installed: the peer rows will say skipped"
	$(PY) benchmarks/run.py

clean:  ## remove the virtual environment and caches
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
