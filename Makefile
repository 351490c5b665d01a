# Two entry points: `make reproduce` and `make test`. Both create .venv on first use.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# The tests run with Python's bytecode cache whatever the environment says: where
# PYTHONDONTWRITEBYTECODE is set (some shells and CI images set it), every pytest worker rewrites
# and compiles every test module again at collection, and every command a test starts compiles
# the project's modules again (lab notebook, 2026-11-29). The caches are __pycache__ folders,
# ignored by git, as in any Python project.
PYTEST := PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest

.PHONY: reproduce test check format install bench docs report clean strip-notebooks

$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

install: $(STAMP)

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# notebooks are committed without outputs (tests/test_notebook.py checks it): strip them after
# running them in Jupyter
strip-notebooks: $(STAMP)
	$(BIN)/python examples/strip_notebook.py examples/*.ipynb

reproduce: $(STAMP)
	$(BIN)/trunkslam reproduce --out results

# The documentation site with --strict (a broken link, or a number that does not resolve
# against docs/results/, fails), into build/site; then the whole suite on every core
# (pytest-xdist; --dist loadscope keeps each module's tests, and so its module fixtures, on one
# worker), property tests derandomized (tests/conftest.py). The site's tests
# (tests/test_docs_offline.py) read the site just built instead of building it again (about a
# minute of one core). --durations=25: the slowest tests, so CI's log shows where the time goes.
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
	TRUNKSLAM_BUILT_SITE=build/site $(PYTEST) -q -n auto --dist loadscope --hypothesis-profile=ci --durations=25

# The fast tier, for every change: lint, format, and the tests not marked slow (each under
# about 1 s; pyproject.toml's `slow` marker), and the 25 slowest of them.
check: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(PYTEST) -q -n auto --dist loadscope --hypothesis-profile=ci --durations=25 -m "not slow"

# each benchmark prints its table and writes it to bench_results/ for the performance page; one
# BLAS/OpenMP thread, as the figures say (a multi-threaded BLAS on a busy machine is slower)
BENCH := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 $(BIN)/trunkslam bench
bench: $(STAMP)
	mkdir -p bench_results
	$(BENCH) extract --out bench_results/bench_extract.md
	$(BENCH) association --out bench_results/bench_association.md
	$(BENCH) slam --out bench_results/bench_slam.md
	$(BENCH) raycast --out bench_results/bench_raycast.md
	$(BENCH) smoother --out bench_results/bench_smoother.md
	$(BENCH) startup --out bench_results/bench_startup.md
	$(BENCH) cold --out bench_results/bench_cold.md

# the documentation site, into build/site; --strict: a broken link or an unresolved number fails
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

# after `make reproduce` (and `make bench`): the docs' snapshot and the README's glance table
report: $(STAMP)
	$(BIN)/trunkslam report results $(wildcard bench_results)

clean:
	rm -rf $(VENV) results bench_results build .pytest_cache
