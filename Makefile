# ROSHAN-Taichi: the two set-up commands of the README are `make demo` and `make test`.
# Both install everything first (system Vulkan driver for GGUI, CPU torch, the package with dev extras).
PYTHON ?= python3
PIP := $(PYTHON) -m pip
DEMO_DIR ?= out/demo

.PHONY: install system-deps demo test lint bench-fire bench-fidelity clean

install: system-deps
	$(PIP) install -q --upgrade pip
	# The CPU build of torch: an unpinned `torch` would pull several GB of CUDA wheels.
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[dev]"

# GGUI renders offscreen through Vulkan; on a machine without a GPU driver Mesa's lavapipe provides it.
# Without it (not root, not Debian) frames still render through the raster fallback, with a warning.
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

# The full hierarchy on the bundled 35x36 map at the thesis's 35 % ignition: the shipped planner (drones flown by
# the shipped FlyAgent, explorers sweeping the map) against the greedy heuristic on the same 8 episodes.
demo: install
	$(PYTHON) -m roshan eval models/planner --baseline greedy --episodes 8 --envs 8 --seed 0 --out $(DEMO_DIR) \
		--json $(DEMO_DIR)/planner_vs_greedy.json --gif $(DEMO_DIR)/planner.gif
	@echo "demo: $(DEMO_DIR)/planner.gif, $(DEMO_DIR)/planner_vs_greedy.json, plots in $(DEMO_DIR) and $(DEMO_DIR)/greedy"

test: install
	$(PYTHON) -m pytest -q

lint:
	ruff check .

bench-fire:
	$(PYTHON) -m roshan bench fire --json benchmarks/results/fire_cpu.json

bench-fidelity:
	$(PYTHON) -m roshan bench fidelity --seeds 20 --json benchmarks/results/fidelity.json

clean:
	rm -rf out .pytest_cache .ruff_cache
