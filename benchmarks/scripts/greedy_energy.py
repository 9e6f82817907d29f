"""The greedy heuristic with and without watching its batteries (BENCHMARKS.md, "Endurance and payload").

    python benchmarks/scripts/greedy_energy.py CAPACITY MARGIN AWARE   # CAPACITY 0: no batteries; AWARE 1 or 0

35x36_Woods, 3 drones, 2 explorers, 5 % of the cells lit in 2 clusters, no wind, models/fly_simple flying,
8 episodes on 4 envs, env seed 3, the fixed greedy; prints each episode's figures.
"""

import sys
from pathlib import Path

import torch

from roshan.config import Config, DroneConfig, EnergyConfig, IgnitionConfig, PlannerConfig, WindConfig
from roshan.env.planner import PlannerVectorEnv
from roshan.runs.evaluate import run_episodes

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")


def main(capacity: float, margin: float, aware: bool) -> None:
    energy = EnergyConfig(preset="scenario", capacity=capacity) if capacity > 0 else EnergyConfig()
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05, clusters=2),
                 drones=DroneConfig(num_drones=3, energy=energy), wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, greedy_home="fixed",
                       greedy_resources=aware, greedy_energy_margin=margin)
    env = PlannerVectorEnv(4, cfg, pc, evaluation=True, controller="greedy", seed=3)
    out = run_episodes(env, lambda obs: torch.zeros((4, 3), dtype=torch.long), 8, seed=3)
    print(f"capacity {capacity}, margin {margin}, aware {aware}, step limit {env.t_max}")
    for key in ("reason", "time", "drones_lost", "battery_swaps", "base_time", "extinguished"):
        if key in out:
            print(key, out[key].tolist())
    env.close()


if __name__ == "__main__":
    main(float(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "1")
