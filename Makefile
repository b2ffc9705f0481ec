# vical: every target creates/reuses the local virtual environment first.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.vical-installed
export MUJOCO_GL ?= egl

.PHONY: venv test test-all browser lint train tables demo bench clean

venv: $(STAMP)

# torch first (the CPU wheel on this machine's disk); then the project with a torch range 2.13.0 satisfies.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

lint: venv
	$(VENV)/bin/ruff check .

# pytest-xdist workers: the tiers were timed with 2 on 2 cores. Tests that start a local Ray instance run
# in one group (--dist loadgroup), one at a time.
WORKERS ?= 2
PYTEST := $(VENV)/bin/pytest -n $(WORKERS) --dist loadgroup

# The unit tier: every test but the `integration` marker (pyproject.toml's addopts), ~5 min on 2 cores.
test: lint
	$(PYTEST) --durations=15

# Both tiers: the unit tests and the integration ones (subprocesses, Ray, training runs, the tutorials,
# the 40-trial statistics, vical-guide's page in a browser). CI runs this.
test-all: lint browser
	$(PYTEST) -m "" --durations=30

# The page's browser test (tests/test_guide_page.py) drives Debian's headless Chromium: installed here as root, or
# with sudo in CI (CI set); elsewhere that test skips, saying how to install it (in CI it fails instead).
BROWSER := /usr/bin/chromium /usr/bin/chromedriver
browser:
	@if ! ls $(BROWSER) >/dev/null 2>&1; then \
		if [ "$$(id -u)" -eq 0 ]; then SUDO=; elif [ -n "$$CI" ]; then SUDO=sudo; else \
			echo "make: Chromium is not installed and this is not root: the page's browser test will skip"; exit 0; fi; \
		$$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq chromium chromium-driver; \
	fi

train: venv
	$(VENV)/bin/vical-train +experiment=train_paper_policy

# The paper's Tables I-III with the shipped learned policy (RUN=<vical-train run> evaluates another one).
RUN ?=
tables: venv
	for t in table1_intrinsic table2_extrinsic table3_joint; do \
		$(VENV)/bin/vical-evaluate +experiment=$$t $(if $(RUN),policy.run_dir=$(RUN)) out=evaluations/$$t overwrite=true || exit 1; \
	done

demo: venv
	$(VENV)/bin/vical-sim-demo

bench: venv
	$(PY) -m pip install -q -e '.[dev,bench]'
	for b in experiments/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache outputs runs
