# Set-up and entry points. `make demo` and `make test` work on a fresh machine: they
# create or refresh .venv (Python 3.12, everything from PyPI) first. `make demo` installs
# the runtime set (requirements.txt: what the node and `analyze` need); `make test` adds
# the test, lint and benchmark stack (requirements-dev.txt) on top of it.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
RUNTIME := $(VENV)/.runtime
STAMP := $(VENV)/.installed
PIP := $(PY) -m pip install -q --disable-pip-version-check

.PHONY: venv runtime demo test lint bench clean

runtime: $(RUNTIME)
venv: $(STAMP)

$(RUNTIME): requirements.txt setup.py setup.cfg
	@py="$${PYTHON:-$$(tools/find_python312.sh)}" || exit 1; \
	if [ ! -x $(PY) ] || ! $(PY) -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2>/dev/null; then \
		rm -rf $(VENV); echo "creating $(VENV) with $$py"; "$$py" -m venv $(VENV) || exit 1; \
	fi
	$(PIP) --upgrade pip
	$(PIP) -r requirements.txt
	$(PIP) --no-deps -e .
	@# Byte-compiled as an installed package is (no .pyc is written where
	@# PYTHONDONTWRITEBYTECODE is set, and every start would compile each module).
	$(PY) -m compileall -q imu_allan >/dev/null
	@touch $(RUNTIME)

$(STAMP): $(RUNTIME) requirements-dev.txt
	$(PIP) -r requirements-dev.txt
	@touch $(STAMP)

demo: runtime
	$(PY) -m imu_allan demo

# Two xdist workers, one a core (tests sharing an expensive fixture on one: conftest's
# groups); then the tests of real ROS 2 nodes talking over DDS alone (their timers and
# discovery are timed: a linter beside them made a node drop messages). Wall times:
# docs/benchmarks.md.
test: venv
	$(PY) -m pytest -q -n 2 --dist loadgroup -m 'not ros_graph' test; a=$$?; \
	$(PY) -m pytest -q -m ros_graph test; b=$$?; exit $$((a || b))

lint: venv
	$(PY) -m pytest -q test/test_flake8.py test/test_pep257.py test/test_mypy.py

# Benchmarks print ratios against baselines measured in the same run (not timed tests).
bench: venv
	$(PY) bench/bench_guards.py
	$(PY) bench/bench_accumulator.py
	$(PY) bench/bench_batch.py
	$(PY) bench/bench_fit.py
	$(PY) bench/bench_bag_read.py
	$(PY) bench/bench_analyze.py
	$(PY) bench/bench_node.py
	$(PY) bench/bench_fleet.py
	$(PY) bench/validate_fit.py --seeds 50 --workers 2
	$(PY) bench/reproduce_paper.py
	$(PY) bench/search_power.py --seeds 4
	$(PY) bench/validate_adis.py
	$(PY) bench/unusual_campaign.py --seed 1 --rounds 4 --node 2 --quiet

clean:
	rm -rf $(VENV) build install log .pytest_cache
