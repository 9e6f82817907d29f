"""One env of 35x36_Woods, fire only, 1 thread, statistics read every K = 100 updates, the way `roshan simulate`
records them (``roshan.tools.simulate.record``), after a warm-up that compiles every kernel: updates per second.
Two versions of the code (their virtualenvs' python executables) alternate round by round in one session:

    python benchmarks/scripts/one_env_stats.py /path/old-venv/bin/python /path/new-venv/bin/python --rounds 5
"""

import argparse
import json
import subprocess
import sys

CHILD = """
import inspect, json, sys, time
from roshan.config import FireConfig, IgnitionConfig, WindConfig
from roshan.kernels.fire import FireSim
from roshan.maps import load_map
from roshan.runtime import init_taichi
from roshan.tools.simulate import record
init_taichi("cpu", 1)
takes_counters = len(inspect.signature(record).parameters) > 1  # this version's step returns the counters
land = load_map("35x36_Woods")
for pct in (0.015, 0.35):
    sim = FireSim(land, FireConfig(), WindConfig(), IgnitionConfig(fire_percentage=pct), num_envs=1, seed=1)
    sim.reset(); sim.step(100); record(sim)  # compiles
    sim.reset(); record(sim)
    series, t = [], time.perf_counter()
    for _ in range(1000):
        c = sim.step(100)
        series.append(record(sim, c) if takes_counters else record(sim))
    dt = time.perf_counter() - t
    print(json.dumps({"fire_percentage": pct, "steps": 100_000, "every": 100, "steps_per_s": 100_000 / dt,
                      "burning_end": series[-1]["burning"][0]}), flush=True)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pythons", nargs="+", help="python executables of the versions to compare")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    for r in range(args.rounds):
        for i, py in enumerate(args.pythons):
            out = subprocess.run([py, "-c", CHILD], capture_output=True, text=True, check=True, cwd="/tmp")
            for line in (ln for ln in out.stdout.splitlines() if ln.startswith("{")):  # not Taichi's banner
                print(json.dumps({"round": r, "version": i, "python": py, **json.loads(line)}), flush=True)


if __name__ == "__main__":
    sys.exit(main())
