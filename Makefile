# One-command set-up: every target that needs Python creates .venv first and
# installs the project (editable) with its test dependencies into it.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
export OPENBLAS_NUM_THREADS ?= 1
export MPLBACKEND ?= Agg
# pytest-xdist workers for `make test` (the CI machine has 2 cores); modules stay whole on one worker and are
# handed out in collection order, the costliest modules first (tests/conftest.py COSTLY_FIRST, decision 0030).
# `make test` runs the not-slow tests and the slow ones marked ci_slow: the realistic world's close-loop cases (four single effects,
# five of the ten control seeds, a logged channel; decisions 0074, 0080, 0095, 0100 and 0131), in three
# modules that the two workers share out; the other slow tests (the realistic pairs and run-level cases among
# them) run with `make test-slow`
TEST_WORKERS ?= 2

.PHONY: docs venv test test-slow test-all check-install fmus demo dist bench clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -e ".[test,docs]"
	touch $(STAMP)

fmus: $(STAMP)
	$(PY) build_fmu.py

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow or ci_slow" -n $(TEST_WORKERS) --dist loadscope --no-loadscope-reorder --durations=25

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

check-install:
	bash .ci/install_check.sh

test-all: $(STAMP)
	$(PY) -m pytest -q

demo: $(STAMP)
	$(PY) -m l1b2.cli demo --out demo_out

dist: $(STAMP)
	$(PY) -m l1b2.cli export --out dist

# the documentation site into site/ (warnings are errors, as in CI)
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf dist demo_out build site .pytest_cache
