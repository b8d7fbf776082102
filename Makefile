# charctl — `make help` lists the targets. Two commands on a fresh machine: `make demo`, `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
CHARCTL := $(VENV)/bin/charctl
# On this (CPU-only) machine torch 2.13.0 is a local CPU wheel. A GPU user installs the CUDA
# build first (see README) and runs `make install TORCH=skip`.
TORCH ?= torch==2.13.0
STAMP := $(VENV)/.charctl-installed
# `make test` runs the suite in one pytest-xdist worker per core (`-n auto`), a test file per worker at a time
# (`--dist loadfile`: a file's module fixtures, e.g. its trained smoke run, are built once); the wall times are
# in the README's table ("Two commands"). PYTEST_PARALLEL= runs it in one process.
PYTEST_PARALLEL ?= -n auto --dist loadfile
export MUJOCO_GL ?= osmesa
export PYOPENGL_PLATFORM ?= osmesa
# The reproduction targets' multirun (-m) lines: LAUNCHER=basic runs their jobs one after another (the
# default), LAUNCHER=ray side by side on Ray: a local instance, or the cluster at RAY_ADDRESS (README
# "Running on a cluster"). Used as $(LAUNCH) in mk/*.mk.
LAUNCHER ?= basic
RAY_ADDRESS ?=
ifeq ($(filter $(LAUNCHER),basic ray),)
$(error LAUNCHER must be basic or ray, not '$(LAUNCHER)')
endif
LAUNCH := $(if $(filter ray,$(LAUNCHER)),--launcher ray$(if $(RAY_ADDRESS), --address $(RAY_ADDRESS)))

# pip compiles what it installs to bytecode one file at a time, the packages' test folders included; `--no-compile`,
# then this on every core without those folders, took a fresh `make test`'s set-up from 174 s to 143 s here (2 cores;
# README "Two commands"). Its result is ignored: some packages ship a file for a newer Python (torch's
# py312_intrinsics.py), which pip skips too.
define COMPILE_VENV
import compileall, re, sys
compileall.compile_dir(sys.argv[1] + "/lib", quiet=2, workers=0, rx=re.compile(r"site-packages/.*/tests?/"))
endef
export COMPILE_VENV

.DEFAULT_GOAL := help
.PHONY: help install render-deps test test-fast test-slow lint demo bench clean-outputs

help: ## show this help
	@grep -hE '^[a-zA-Z0-9_-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "}; {printf "  \033[36m%-24s\033[0m %s\n", $$1, $$2}'

install: $(STAMP) ## create .venv and install charctl (idempotent: re-runs only when pyproject.toml changes)

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory render-deps
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	@if [ "$(TORCH)" != "skip" ]; then $(PIP) install -q --no-compile "$(TORCH)"; fi
	$(PIP) install -q --no-compile -e '.[test]'
	@echo "compiling the installed packages to bytecode (every core; the packages' own test folders skipped)"
	@$(PY) -c "$$COMPILE_VENV" $(VENV)
	touch $(STAMP)

render-deps: ## install the OSMesa library MuJoCo's offscreen renderer needs (Debian; best effort)
	@if ldconfig -p 2>/dev/null | grep -q libOSMesa; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  (apt-get install -y -qq libosmesa6 >/dev/null 2>&1 || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libosmesa6 >/dev/null 2>&1)) \
	  || echo "note: could not install libosmesa6; video export will say how to enable rendering"; \
	else echo "note: install libosmesa6 (or use MUJOCO_GL=egl) to render videos"; fi

test: install ## install, lint (ruff), then run the whole test suite (< 10 min on 2 cores)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) -m pytest -q -m "not slow" $(PYTEST_PARALLEL)

test-slow: install ## the slow learning checks (minutes each)
	$(PY) -m pytest -q -m slow

lint: install ## ruff: lint rules and formatting (config in pyproject.toml)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

demo: install ## install, then the main job at a small default scale: clips, BVH/mp4 export, a short cgail training + evaluation
	$(CHARCTL) data list
	$(CHARCTL) export bvh walk -o outputs/demo/walk.bvh
	$(CHARCTL) export video walk -o outputs/demo/walk.mp4
	$(MAKE) --no-print-directory demo-cgail
	@echo "demo artefacts in outputs/demo/"

bench: install ## throughput benchmarks (scripts/bench_*.py)
	$(PY) scripts/bench_sim.py

clean-outputs: ## delete everything under outputs/ except its README
	find outputs -mindepth 1 -not -name README.md -delete

# Per-experiment reproduction targets live in mk/<experiment>.mk.
-include mk/*.mk
