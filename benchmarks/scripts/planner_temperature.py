"""Outcomes of a planner's *training* episodes (centralised candidates, sampled goals) at a temperature
(BENCHMARKS.md, "Planner training that sees success"): 32 envs, one episode each.

    python benchmarks/scripts/planner_temperature.py models/planner 0.3
"""

import sys

import numpy as np
import torch

from roshan.algos.frozen import load_agent
from roshan.algos.planner_nets import trim_candidates
from roshan.config import load_config
from roshan.runs.envs import make_env
from roshan.runs.evaluate import run_episodes
from roshan.runtime import init_taichi


def main(target: str, temperature: float, config: str = "configs/thesis/planner.yaml", envs: int = 32,
         seed: int = 5) -> None:
    init_taichi("cpu", 2)
    _, agent, _ = load_agent(target, "best", torch.device("cpu"))
    net = agent.policy.net
    net.temperature = temperature
    env = make_env(load_config(config), envs, seed, evaluation=False)
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        ep = run_episodes(env, lambda o: net.forward_act(trim_candidates(o), generator=g)[0], envs, seed)
    reasons = dict(zip(*np.unique(ep["reason"], return_counts=True), strict=True))
    print(f"T={temperature}: success {ep['success'].mean():.0%}, reasons {reasons}, TTE median {np.median(ep['time'])}")


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]))
