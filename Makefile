# asmonc_vision — the two commands for a fresh machine:
#   make demo   install everything into .venv, then replay the bundled bag through the node graph
#   make test   install everything into .venv, then run the whole test suite
# For development: make test-fast (the core tests: no ROS, no processes, none slow),
# make lint (ruff and mypy).
# Nothing outside this directory is installed. Needs python3 (3.11 or 3.12), cmake, gcc.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.asmonc-installed
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: all venv demo test test-fast lint bags bench-soak clean-venv

all: demo

venv: $(STAMP)

$(STAMP): requirements.lock setup.py package.xml msg/CMakeLists.txt msg/package.xml msg/pyproject.toml $(wildcard msg/msg/*.msg)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --disable-pip-version-check -r requirements.lock
	# The interface package (ament_cmake + rosidl), built against the ROS wheels in .venv.
	AMENT_PREFIX_PATH=$(CURDIR)/$(VENV) CMAKE_PREFIX_PATH=$(CURDIR)/$(VENV) \
	  ASMONC_PYTHON=$(CURDIR)/$(PY) \
	  $(PIP) install --quiet --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps ./msg
	$(PIP) install --quiet --disable-pip-version-check --no-build-isolation --no-deps -e .
	# setup.cfg puts the console scripts where `ros2 run` looks (lib/asmonc_vision);
	# link them onto the venv's PATH too, under the same names.
	for f in $(VENV)/lib/asmonc_vision/*; do ln -sf "$$(realpath $$f)" $(VENV)/bin/; done
	# Compile the numba kernels into their disk cache once (2-3 minutes), so that no
	# node's first start and no test pays for it.
	$(PY) -m asmonc_vision.eval.warm_jit
	touch $(STAMP)

demo: venv
	$(VENV)/bin/asmonc run

# The tests that start no ROS node and no process on TEST_WORKERS workers (pytest-xdist);
# then those that do, one at a time, on an otherwise idle machine (their timing is the
# graph's: a FAULT within 0.5 s, a replay paced by the detector).
TEST_WORKERS ?= 2
test: venv
	$(PY) -m pytest -q -n $(TEST_WORKERS) -m "not ros and not e2e" test; core=$$?; \
	  $(PY) -m pytest -q -m "ros or e2e" test && exit $$core

# The tests marked neither ros, e2e nor slow (markers: setup.cfg, test/conftest.py).
test-fast: venv
	$(PY) -m pytest -q -m "not ros and not e2e and not slow" test

# ruff (ruff.toml) over the package, the tests and the launch files; mypy (setup.cfg) over
# core/.
LINT_PATHS := asmonc_vision test launch
MYPY_FILES = $(sort $(shell find asmonc_vision/core -name '*.py'))
lint: venv
	$(PY) -m ruff check --no-cache $(LINT_PATHS); ruff=$$?; \
	  $(PY) -m mypy $(MYPY_FILES) && exit $$ruff

# Loop a walking bag through the whole graph for 10 minutes: per-process memory and fd growth.
bench-soak: venv
	$(VENV)/bin/asmonc soak bags/walk_obstacles --minutes 10 --rate 1

# Regenerate the committed bags (bags/README.md): about a minute.
BUNDLED_BAGS := static_obstacles:5.5 clear_static:3 walk_obstacles:7.5 clear_walk:4 walk_stop_turn:7.5 slope:3
bags: venv
	for spec in $(BUNDLED_BAGS); do \
	  name=$${spec%%:*}; dur=$${spec##*:}; \
	  $(PY) -m asmonc_vision.sim $$name bags/$$name --seed 0 --duration $$dur --force || exit 1; \
	done

clean-venv:
	rm -rf $(VENV)
