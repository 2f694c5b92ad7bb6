# The two commands of the README. Both first bring the environment up to date (scripts/setup.sh is idempotent:
# on a fresh machine it installs FreeCAD when root, creates .venv and the pinned stack; afterwards it takes a second).
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
VENV := .venv
PY := $(VENV)/bin/python
V2C := $(VENV)/bin/v2c
# pytest-xdist workers: 2 fits the 2-core machine; override with `make test JOBS=auto` (or JOBS=0 for none)
JOBS ?= 2

.PHONY: all setup test demo lint clean

all: test

setup:
	bash scripts/setup.sh

# The layer contract and the code style first (seconds), then the tests
test: setup lint
	$(PY) -m pytest -n $(JOBS) -q tests

# The main job on a bundled sample: SCAN/reconstruction.step (+ .vbrep.json and the .png figure next to it).
DEMO_SCAN ?= samples/turned_unaligned
demo: setup
	$(V2C) to-step $(DEMO_SCAN)/ --force  # the bundled sample folder is v2c's own: replace whatever an older v2c wrote
	@echo "open $(DEMO_SCAN)/reconstruction.step in FreeCAD; the figure is $(DEMO_SCAN)/reconstruction.png"

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports

clean:
	rm -rf out .pytest_cache .ruff_cache samples/*/reconstruction.*
