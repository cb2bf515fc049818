# Set-up is part of every target: `make demo` and `make test` work on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
LRAUV  := $(VENV)/bin/lrauv
STAMP  := $(VENV)/.installed
OUT    ?= out/demo
# The TypeScript MCAP reader (@mcap/core) that tests/planner/shore/test_mcap_node.py reads the logs with; installed
# from tests/node/package-lock.json when node and npm are on PATH, else those tests skip.
NODE_DIR   := tests/node
NODE_STAMP := $(NODE_DIR)/node_modules/.installed
HAVE_NODE  := $(shell command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1 && echo yes)
# Where the demo vehicle starts (LON,LAT): open water 16 km west-south-west of the goal.
DEMO_START ?= -117.96,33.34
DEMO_SPEEDUP ?= 1000
# Wall-time limit of the demo's dive (s): a start far from the goal needs longer.
DEMO_TIMEOUT_S ?= 170
# Start states of the closed-loop comparison at the end of `make demo` (docs/evaluation.md uses 200).
EVAL_STARTS ?= 40

.PHONY: demo test typecheck node bench clean sysdeps bytecode

# System packages: a Python >= 3.11 with venv and pip (Debian: python3-venv).
sysdeps:
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 is required, found " + sys.version' \
	  || { echo "install Python 3.11 or newer"; exit 1; }
	@$(PYTHON) -c 'import venv, ensurepip' 2>/dev/null || { \
	  echo "installing python3-venv (Debian)"; \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y -qq python3-venv; \
	  else sudo apt-get update -qq && sudo apt-get install -y -qq python3-venv; fi; }

$(STAMP): pyproject.toml | sysdeps
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

# The package's bytecode, compiled here (only what changed since): where nothing writes it on import (a read-only
# install, as on a vehicle, or PYTHONDONTWRITEBYTECODE set) every process would compile the package from source again,
# 0.1 to 0.2 s of each `lrauv` command's start-up (docs/benchmarks.md).
bytecode: $(STAMP)
	@$(PY) -m compileall -q planner executive vehicle_sim

demo: $(STAMP) bytecode
	$(LRAUV) forecast synth $(OUT)/forecast.nc --issue 0
	$(LRAUV) forecast synth $(OUT)/truth.nc
	$(LRAUV) plan missions/demo.yaml --forecast $(OUT)/forecast.nc --out $(OUT)/demo.lrpt \
	  --export-values $(OUT)/values.nc --plot $(OUT)/pictures --start $(DEMO_START),0,0
	$(LRAUV) demo --mission missions/demo.yaml --table $(OUT)/demo.lrpt --truth $(OUT)/truth.nc \
	  --start $(DEMO_START) --speedup $(DEMO_SPEEDUP) --timeout-s $(DEMO_TIMEOUT_S) --out $(OUT)
	$(LRAUV) replay $(OUT)/demo.mcap --report $(OUT)/report \
	  --csv $(OUT)/dive.csv --geojson $(OUT)/dive.geojson --gpx $(OUT)/dive.gpx
	$(LRAUV) plan missions/demo-physical.yaml --forecast $(OUT)/forecast.nc --out $(OUT)/demo-physical.lrpt \
	  --start $(DEMO_START),0,0 --quiet
	$(LRAUV) evaluate missions/demo-physical.yaml --forecast $(OUT)/forecast.nc --truth $(OUT)/truth.nc \
	  --starts $(EVAL_STARTS) --out $(OUT)/evaluation

# The stamp lives in node_modules: deleting node_modules, or a newer package.json or lock, reinstalls.
# An install that fails (no registry) removes what it left, warns, and the Node tests skip.
$(NODE_STAMP): $(NODE_DIR)/package.json $(NODE_DIR)/package-lock.json
	@echo "npm ci --prefix $(NODE_DIR) --no-audit --no-fund"
	@if npm ci --prefix $(NODE_DIR) --no-audit --no-fund; then touch $@; else rm -rf $(NODE_DIR)/node_modules; \
	  echo "WARNING: npm ci failed: @mcap/core is not installed and tests/planner/shore/test_mcap_node.py will skip"; fi

ifeq ($(HAVE_NODE),yes)
node: $(NODE_STAMP)
else
node:
	@echo "node or npm not on PATH: not installing @mcap/core; tests/planner/shore/test_mcap_node.py will skip"
endif

# The type check is part of the tests: mypy and the stubs come with the test extra; settings in pyproject.toml.
typecheck: $(STAMP)
	$(PY) -m mypy

# Two pytest workers (pytest-xdist), handed tests as they free up. Before them, the planners' numba kernels compile
# into their on-disk cache beside the type check, a core each, so that no worker compiles them again.
TEST_WORKERS ?= 2

test: $(STAMP) node bytecode
	@$(PY) -m tests.support.warm_kernels & warm=$$!; \
	  echo "$(PY) -m mypy"; $(PY) -m mypy; typed=$$?; wait $$warm; warmed=$$?; \
	  test $$typed = 0 && test $$warmed = 0
	$(PY) -m pytest -n $(TEST_WORKERS) --dist worksteal

bench: $(STAMP) bytecode
	$(PY) bench/bench_plan.py
	$(PY) bench/bench_exec.py

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache
