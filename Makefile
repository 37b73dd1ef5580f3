# One-command set-up: the first target run on a fresh machine installs the system packages for
# offscreen rendering, creates .venv from requirements.lock and installs ipr into it.
# The first of Python 3.11, 3.12, 3.13 found (pyproject's requires-python); override with PYTHON=...
PYTHON ?= $(firstword $(foreach v,3.11 3.12 3.13,$(shell command -v python$(v) 2>/dev/null)) python3.11)
VENV   := .venv
PY     := $(VENV)/bin/python
IPR    := $(VENV)/bin/ipr-shapes
STAMP  := $(VENV)/.installed
RAY_STAMP := $(VENV)/.installed-ray
PYBULLET_STAMP := $(VENV)/.installed-pybullet
DEMO_OUT ?= out/demo

.PHONY: setup demo test test-slow mutants bench gallery lint format clean

setup: $(STAMP)

$(STAMP): requirements.lock pyproject.toml scripts/setup_system.sh
	bash scripts/setup_system.sh
	@command -v $(PYTHON) >/dev/null || { echo "ipr setup: $(PYTHON) not found; install Python 3.11, 3.12 or 3.13 or run 'make PYTHON=/path/to/python3'" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
# The distribution was called "ipr" before it became "ipr-shapes": drop the old record.
	$(PY) -m pip uninstall --quiet --yes ipr >/dev/null 2>&1 || true
	$(PY) -m pip install --quiet --no-deps -e .
	$(PY) -c 'import sys, ipr_shapes.gl; sys.exit(ipr_shapes.gl.main())'
	touch $(STAMP)

# Ray for `ipr-shapes batch --ray` (the "ray" extra), pinned apart so that `make test` does not need it.
$(RAY_STAMP): $(STAMP) requirements-ray.lock
	$(PY) -m pip install --quiet -r requirements-ray.lock
	touch $(RAY_STAMP)

$(PYBULLET_STAMP): $(STAMP) requirements-pybullet.lock
	$(PY) -m pip install --quiet -r requirements-pybullet.lock
	touch $(PYBULLET_STAMP)

demo: $(STAMP)
	$(PY) -m ipr_shapes.demo $(DEMO_OUT)

# The default tests (under 3 minutes on 2 cores); .ci/run also runs the slow ones (test-slow).
# Two pytest-xdist workers: CI has 2 cores, and each worker compiles the numba kernels it needs on
# a cold cache, so more workers than cores only repeat that work. TEST_WORKERS=0 runs in one process.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(PY) -m pytest -q -m "not slow" -n $(TEST_WORKERS) tests

# The slow tests include a Ray cluster on this machine: Ray is installed first.
test-slow: $(STAMP) $(RAY_STAMP) $(PYBULLET_STAMP)
	$(PY) -m pytest -q -m slow tests

bench: $(STAMP)
	$(PY) -m benchmarks.run
	$(PY) -m benchmarks.gallery

# Overlays of the perception on the real frames a person judges: docs/GALLERY.md, docs/gallery/.
gallery: $(STAMP)
	$(PY) -m benchmarks.gallery

# Mutation testing of the core (scripts/mutants.py): writes docs/MUTANTS.md.
mutants: $(STAMP)
	$(PY) scripts/mutants.py

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks scripts
	$(VENV)/bin/ruff format --check src tests benchmarks scripts

format: $(STAMP)
	$(VENV)/bin/ruff check --fix src tests benchmarks
	$(VENV)/bin/ruff format src tests benchmarks

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
