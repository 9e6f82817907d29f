"""How far a TanhNormal FlyAgent's pre-tanh means sit in tanh's flat tails (BENCHMARKS.md, "The collision
FlyAgent's drift"): deterministic steps of 16 evaluation envs, then statistics of |mu|.

    python benchmarks/scripts/tanh_saturation.py models/fly_collision
"""

import sys

import numpy as np
import torch

from roshan.algos.frozen import load_agent
from roshan.algos.networks import flatten_drones
from roshan.algos.policies import SATURATED
from roshan.runs.envs import make_env
from roshan.runtime import init_taichi


def main(target: str, envs: int = 16, steps: int = 300, seed: int = 5) -> None:
    init_taichi("cpu", 1)
    cfg, agent, path = load_agent(target, "best", torch.device("cpu"))
    env = make_env(cfg, envs, seed, evaluation=True)
    obs, _ = env.reset(seed=seed)
    net, mus = agent.policy.net, []
    with torch.no_grad():
        for _ in range(steps):
            mu = net.actor(flatten_drones(obs))[0]
            mus.append(mu.abs().numpy())
            obs, *_ = env.step(torch.tanh(mu).view(envs, env.num_drones, 2))
    m = np.concatenate(mus)
    print(f"{path}: std {net.log_std.exp().tolist()}, |mu| median {np.median(m):.2f}, p90 {np.percentile(m, 90):.2f}, "
          f"max {m.max():.2f}; beyond atanh(0.975) = {SATURATED}: {(m > SATURATED).mean():.1%}")


if __name__ == "__main__":
    main(sys.argv[1])
