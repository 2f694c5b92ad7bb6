# The two commands of the README. Both first bring the environment up to date (scripts/setup.sh is idempotent:
# on a fresh machine it installs FreeCAD when root, creates .venv and the pinned stack; afterwards it takes a second).
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
VENV := .venv
PY := $(VENV)/bin/python
V2C := $(VENV)/bin/v2c
# pytest-xdist workers: 2 fits the 2-core machine; override with `make test JOBS=auto` (or JOBS=0 for none)
JOBS ?= 2
DEMO_OUT ?= out/demo

.PHONY: all setup test demo lint clean

all: test

setup:
	bash scripts/setup.sh

test: setup
	$(PY) -m pytest -n $(JOBS) -q tests

# For now: generate one synthetic scan and describe it. Becomes `v2c to-step samples/<name>/` once that exists.
demo: setup
	rm -rf $(DEMO_OUT)
	$(V2C) synth $(DEMO_OUT) --n 1 --seed 0 --size 320x240 --noise sensor
	scan=$$(dirname "$$(find $(DEMO_OUT) -name camera.json | sort | sed -n 1p)"); \
	  test -n "$$scan" && test "$$scan" != . || { echo "no scan written under $(DEMO_OUT)" >&2; exit 1; }; \
	  $(V2C) info "$$scan"

lint: setup
	$(VENV)/bin/ruff check .

clean:
	rm -rf out .pytest_cache .ruff_cache
