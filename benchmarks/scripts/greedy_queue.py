"""The resource-aware greedy under each queue reserve of the return rule (``planner.return_queue``), on the fleet
recipe's settings (configs/fleet.yaml: every other rule at its default, the final approach included):

    python benchmarks/scripts/greedy_queue.py small planner.return_queue=waiting        # 35x36_Woods, 100 episodes
    python benchmarks/scripts/greedy_queue.py small planner.return_queue=none drones.num_drones=16
    python benchmarks/scripts/greedy_queue.py borkenberge planner.return_queue=waiting drones.bases=4

``small``: the endurance scenario's 100 test episodes (env seed 7, 100 envs). ``borkenberge``: the realistic
operation of BENCHMARKS.md (Borkenberge, the ``realistic`` battery, a 5-drop tank refilled in 60 s, 0.1 % ignition,
16 drones, one 90-minute episode of env seed 7). Prints the episodes' mean success, median TTE, drones lost, battery
swaps, cells put out and seconds at a base per drone. One torch and one Taichi thread.
"""

import sys
import time

import numpy as np
import torch

from roshan.config import load_config
from roshan.env.planner import PlannerVectorEnv
from roshan.runs.evaluate import run_episodes
from roshan.runtime import init_taichi

SETTINGS = {"small": ((), 100),
            "borkenberge": (("map.name=Borkenberge", "ignition.fire_percentage=0.001", "drones.water_capacity=5",
                             "drones.recharge_time=60", "drones.energy.preset=realistic", "drones.num_drones=16"), 1)}


def main(argv: list[str]) -> None:
    setting, sets = argv[0], argv[1:]
    base, episodes = SETTINGS[setting]
    init_taichi("cpu", 1)
    torch.set_num_threads(1)
    cfg = load_config("configs/fleet.yaml", [*base, "sim.seed=7", *sets])
    env = PlannerVectorEnv(episodes, cfg, evaluation=True, controller="greedy", seed=7)
    n, t = cfg.drones.num_drones, time.time()
    eps = run_episodes(env, lambda obs: torch.zeros((episodes, n), dtype=torch.long), episodes, 7)
    env.close()
    row = {"success": float(np.mean(eps["success"])), "tte_median": float(np.median(eps["time"])),
           **{k: float(np.mean(eps[k])) for k in ("drones_lost", "battery_swaps", "extinguished", "base_time")}}
    print(setting, " ".join(sets), {k: round(v, 3) for k, v in row.items()}, f"({time.time() - t:.0f} s)")


if __name__ == "__main__":
    main(sys.argv[1:])
