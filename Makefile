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

demo: install
	$(PYTHON) -m roshan simulate --map 35x36_Woods --fire-percentage 0.05 --envs 4 --drones 4 --policy greedy \
		--steps 3000 --every 50 --seed 0 \
		--frames $(DEMO_DIR)/frames --gif $(DEMO_DIR)/fire.gif --json $(DEMO_DIR)/summary.json
	@echo "demo: $(DEMO_DIR)/fire.gif, $(DEMO_DIR)/summary.json, $(DEMO_DIR)/frames/"

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
