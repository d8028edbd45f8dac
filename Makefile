# Everything installs into .venv from the package registries; `make demo` and
# `make test` set it up on first use (and again when pyproject.toml changes).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
export MUJOCO_GL ?= egl
# Small problems on 2 cores run faster single-threaded.
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
# Python caches each module's bytecode on its first import, unless PYTHONDONTWRITEBYTECODE
# is set (these machines set it): then every process compiles every module it imports
# again (scipy's, MuJoCo's, dm_control's, ours), and the test suite starts many
# processes. The targets here let Python cache it.
unexport PYTHONDONTWRITEBYTECODE

.PHONY: demo test test-slow docs install bench-env bench-standard clean

# --no-compile: Python compiles a module when it is first imported, instead of every
# installed file up front (torch's thousands): the install takes about 40 % less.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --no-compile --disable-pip-version-check -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	rm -rf runs/demo
	$(BIN)/legcal-bench bench --suite smoke --out runs/demo --data runs/demo/data

# Tests run in TEST_WORKERS processes (pytest-xdist; 2, the CI machine's cores);
# TEST_WORKERS=0 runs them in this one. Tests that start worker pools of their own
# size them to the cores left per test process (tests/conftest.py, pool_workers).
TEST_WORKERS ?= 2
test: $(STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS)

# The tests marked slow: the same checks over more robots than the test command's budget
# holds (tests/protocol/test_robots_as_they_come.py's other five hip orders).
test-slow: $(STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) -m slow

# The documentation site (MkDocs with Material) into site/, strict: a broken link or a
# missing page fails (tests/docs/test_site.py builds it the same way in `make test`).
docs: $(STAMP)
	$(BIN)/mkdocs build --strict --site-dir site

# Maintainers: regenerate committed results (they change only when named: --out).
bench-env: $(STAMP)
	$(BIN)/legcal-bench bench-env --out reports/bench_env

bench-standard: $(STAMP)
	$(BIN)/legcal-bench bench --suite standard --out leaderboard --data runs/bench/data

clean:
	rm -rf $(VENV) runs site
