# ROSHAN-Taichi: the two set-up commands of the README are `make demo` and `make test`.
# Both install everything first (system Vulkan driver for GGUI, torch, the package with dev extras), once: a stamp in
# the environment names what was installed, and only a change (pyproject.toml, the torch choice, another checkout)
# installs again.
#
# Which Python: PYTHON=... when given; else the active virtualenv (VIRTUAL_ENV set, or a `python3` on PATH that runs
# inside one, as in CI and fresh-check); else the project's own .venv, made here: Debian's Python refuses
# `pip install` outside a virtualenv (PEP 668, "externally-managed-environment").
ifeq ($(origin PYTHON),undefined)
  ifneq ($(VIRTUAL_ENV),)
    PYTHON := $(VIRTUAL_ENV)/bin/python
  else ifeq ($(shell python3 -c 'import sys; print(sys.prefix != sys.base_prefix)' 2>/dev/null),True)
    PYTHON := python3
  else
    VENV := $(CURDIR)/.venv
    PYTHON := $(VENV)/bin/python
  endif
endif
PIP := $(PYTHON) -m pip
# torch: scripts/install_torch.sh takes the CPU build on a machine without an NVIDIA GPU (from the configured index
# when it serves one, else from PyTorch's CPU index) and what the configured index offers with one (on PyPI for
# Linux, the CUDA build: several GB with its nvidia-* wheels); TORCH_INDEX=URL takes torch from that index. It says
# in one line which; `make print-torch` shows the choice without installing.
TORCH ?= torch==2.13.0
TORCH_INDEX ?=
NVIDIA_SMI ?= nvidia-smi
TORCH_BUILD := $(if $(TORCH_INDEX),index,$(if $(shell command -v $(NVIDIA_SMI) 2>/dev/null),cuda,cpu))
DEMO_DIR ?= out/demo

INSTALL_KEY := $(shell (cat pyproject.toml; echo "$(CURDIR) $(TORCH) $(TORCH_INDEX) $(TORCH_BUILD)") | sha256sum | cut -c1-12)
# The stamp lives in the virtualenv it describes (a new venv has none); a Python outside any venv keeps it in build/.
ifdef VENV
  STAMP_DIR := $(VENV)
else
  STAMP_DIR := $(or $(shell $(PYTHON) -c 'import sys; print(sys.prefix if sys.prefix != sys.base_prefix else "build")'                  2>/dev/null),build)
endif
STAMP := $(STAMP_DIR)/.roshan-installed-$(INSTALL_KEY)

.PHONY: install system-deps demo test test-fast lint bench-fire bench-fidelity clean print-python print-torch

install: $(STAMP)

$(STAMP):
	@$(MAKE) --no-print-directory system-deps
	@if [ -n "$(VENV)" ] && [ ! -x "$(PYTHON)" ]; then echo "python3 -m venv .venv"; python3 -m venv "$(VENV)"; fi
	$(PIP) install -q --upgrade pip
	@PYTHON="$(PYTHON)" TORCH="$(TORCH)" TORCH_INDEX="$(TORCH_INDEX)" NVIDIA_SMI="$(NVIDIA_SMI)" sh scripts/install_torch.sh
	$(PIP) install -q -e ".[dev]"
	@mkdir -p $(STAMP_DIR) && rm -f $(STAMP_DIR)/.roshan-installed-* && touch $@

# GGUI renders offscreen through Vulkan; on a machine without a GPU driver Mesa's lavapipe provides it.
# Without it (not root, not Debian) frames still render through the raster fallback, with a warning.
# python3-venv: Debian's python3 makes no virtualenv without it (ensurepip).
system-deps:
	@if dpkg -s mesa-vulkan-drivers >/dev/null 2>&1; then \
		echo "mesa-vulkan-drivers: installed"; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
		(apt-get install -y -qq mesa-vulkan-drivers >/dev/null 2>&1 || \
		 (apt-get update -qq && apt-get install -y -qq mesa-vulkan-drivers)) \
		|| echo "WARNING: could not install mesa-vulkan-drivers; GGUI falls back to the raster renderer"; \
	else \
		echo "WARNING: install Vulkan (Debian: apt-get install -y mesa-vulkan-drivers) for GGUI frames"; \
	fi
	@if [ -n "$(VENV)" ] && [ ! -x "$(PYTHON)" ] && ! python3 -c 'import ensurepip' >/dev/null 2>&1; then \
		if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
			apt-get install -y -qq python3-venv >/dev/null 2>&1 || \
			(apt-get update -qq && apt-get install -y -qq python3-venv); \
		else \
			echo "ERROR: python3 cannot make a virtualenv; install it (Debian: apt-get install -y python3-venv)"; \
			exit 1; \
		fi; \
	fi

# The full hierarchy on the bundled 35x36 map in the thesis setting: the shipped planner (drones flown by the shipped
# collision FlyAgent, explorers sweeping the map) against the greedy heuristic on the same 8 episodes, each starting
# with up to 35 % of the 1,260 cells burning (the thesis-era generator). The heuristic is the fixed one
# (planner.greedy_home: fixed; the planner's thesis config keeps the original's defect, a fire on the groundstation
# cell never put out), and the table's column says so. --replace: out/demo is the demo's own folder, and a second
# `make demo` shows a fresh run there.
demo: install
	$(PYTHON) -m roshan eval models/planner --baseline greedy --episodes 8 --envs 8 --seed 0 --out $(DEMO_DIR) \
		--set planner.greedy_home=fixed --json $(DEMO_DIR)/planner_vs_greedy.json --gif $(DEMO_DIR)/planner.gif --replace
	@echo "demo: $(DEMO_DIR)/planner.gif, $(DEMO_DIR)/planner_vs_greedy.json, plots in $(DEMO_DIR) and $(DEMO_DIR)/greedy"
	@echo "demo: 8 episodes are a quick look, where the two are often close. The figures to quote, on 100 held-out"
	@echo "      episodes: models/planner 100 % success, median TTE 862.5 against the fixed greedy's 925.5; with"
	@echo "      batteries, where the planner schedules returns, models/planner_endurance 78 % against the"
	@echo "      resource-aware greedy's 71 % (README, 'What to try next'; BENCHMARKS.md)."

# Two pytest-xdist workers, a test file to each: with the suite compiling fast (tests/conftest.py), compiling no
# longer keeps both cores busy, and a cold suite on the 2-core machine took 850 s with two workers against 1,724 s in
# one process (BENCHMARKS.md, "Test suite"). Each worker resets Taichi after each file, as one process does.
test: install
	$(PYTHON) -m pytest -q -n 2 --dist loadfile --durations=15

# The edit loop: everything but the tests marked slow (each took 5 s or more in a full run on the 2-core machine:
# training, subprocesses, long physics); CI runs them all.
test-fast: install
	$(PYTHON) -m pytest -q -n 2 --dist loadfile -m "not slow"

lint: install
	$(PYTHON) -m ruff check .

bench-fire:
	$(PYTHON) -m roshan bench fire --json benchmarks/results/fire_cpu.json

bench-fidelity:
	$(PYTHON) -m roshan bench fidelity --seeds 20 --json benchmarks/results/fidelity.json

clean:
	rm -rf out .pytest_cache .ruff_cache

# Which interpreter and install stamp this make would use (tests/test_makefile.py).
print-python:
	@echo "$(PYTHON) $(STAMP)"

# Which torch build `make install` would take: cpu (no NVIDIA GPU), cuda (nvidia-smi found) or index (TORCH_INDEX).
print-torch:
	@echo "torch: $(TORCH_BUILD) build of $(TORCH)$(if $(TORCH_INDEX), from $(TORCH_INDEX))"
