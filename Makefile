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

.PHONY: demo test install bench-env clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --disable-pip-version-check -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/legcal-bench collect --robot a3 --mode weld --offsets paper --out runs/demo

test: $(STAMP)
	$(BIN)/python -m pytest

bench-env: $(STAMP)
	$(BIN)/legcal-bench bench-env --out reports/bench_env

clean:
	rm -rf $(VENV) runs
