# Everything a new machine needs is installed by these targets themselves.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
NAME   ?= liu_vs_ols
FILE   ?=
VIEW   ?=
VIEWFLAG := $(if $(filter 1 yes true,$(VIEW)),--view,)
SEEDS  ?= 8
OVER   ?= both
ENGINE ?= ray
SET    ?=
SETFLAGS := $(foreach s,$(SET),--set $(s))

.PHONY: setup test test-fast scenario sweep bench lint format view screenshots clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,scenarios]"
	$(PY) -m twin.kinematics.warm_up  # compile the kinematics kernels into numba's cache
	touch $(STAMP)

# The tests on every core (pytest-xdist; WORKERS=0: in this process), a module whole on one
# worker (its fixtures built once), the modules with accuracy gates first (tests/conftest.py).
# BLAS on one thread per worker: the workers already fill the cores. -rs: a line per
# skipped test with its reason at the end; TESTFLAGS: more pytest options (.ci/run: a junit
# XML that .ci/check_skips.py reads).
WORKERS   ?= auto
TESTFLAGS ?=
PYTEST    := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
	$(PY) -m pytest -q -rs -n $(WORKERS) --dist loadfile --no-loadscope-reorder $(TESTFLAGS)

test: $(STAMP)
	$(PYTEST)

test-fast: $(STAMP)
	$(PYTEST) -m "not accuracy"

scenario: $(STAMP)
ifneq ($(strip $(FILE)),)
	$(PY) -m scenarios run $(FILE) $(VIEWFLAG)
else
	$(PY) -m scenarios run $(NAME) $(VIEWFLAG)
endif

# make sweep NAME=undeclared_effect SEEDS=16 [OVER=noise] [SET="tracker.sigma_mm=0.002,0.005"]
# [ENGINE=local]; on a cluster: RAY_ADDRESS=<head>:6379 make sweep ...
sweep: $(STAMP)
	$(PY) -m scenarios sweep $(if $(strip $(FILE)),$(FILE),$(NAME)) --seeds $(SEEDS) \
		--over $(OVER) --engine $(ENGINE) $(SETFLAGS)

bench: $(STAMP)
	$(PY) -m bench

lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

format: $(STAMP)
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .

# docs/img: the first-open face and a scrubbed face of every recording under results/, as the
# web viewer shows them (needs Chromium: apt-get install chromium; not part of `make test`).
# RRD=results/x/x.rrd for one; WAIT=seconds for the viewer to draw (software rendering).
RRD  ?=
WAIT ?= 60
screenshots: $(STAMP)
	$(PY) docs/screenshots.py $(RRD) --out docs/img --wait $(WAIT)

MODEL ?= models/hexapod_rrrprr.xml
view: $(STAMP)
	$(PY) -m mujoco.viewer --mjcf=$(MODEL)

clean:
	rm -rf $(VENV) results .pytest_cache .ruff_cache *.egg-info
