"""Which drones leave the map, where and when (BENCHMARKS.md, "The collision FlyAgent's drift"): deterministic
episodes of a FlyAgent checkpoint; for every episode that ends with a drone outside, the drone's index, the edge
it crossed, the episode step and its pre-tanh mean on that step.

    PYTHONPATH=. python benchmarks/scripts/boundary_exits.py runs/RUN [latest|best|best_eval] [steps]
"""

import sys
from collections import Counter

import numpy as np
import torch

from roshan.algos.frozen import load_agent
from roshan.algos.networks import flatten_drones
from roshan.runs.envs import make_env
from roshan.runtime import init_taichi


def edge(p: np.ndarray, rows: int, cols: int) -> str:
    return ("top" if p[0] < 0 else "bottom" if p[0] >= rows else "") + ("left" if p[1] < 0 else
                                                                        "right" if p[1] >= cols else "")


def main(target: str, which: str = "latest", steps: int = 1200, envs: int = 50, seed: int = 10000) -> None:
    init_taichi("cpu", 1)
    cfg, agent, path = load_agent(target, which, torch.device("cpu"))
    env = make_env(cfg, envs, seed, evaluation=True)
    obs, _ = env.reset(seed=seed)
    dr, net, n = env.drones, agent.policy.net, env.num_drones
    episode_step = np.zeros(envs, dtype=int)
    episodes, exits = 0, []
    with torch.no_grad():
        for _ in range(steps):
            mu = net.actor(flatten_drones(obs))[0].view(envs, n, 2)
            pos = dr.pos.to_numpy() / dr.cell  # before the move: an exit needs two steps outside
            outside = dr.out_count.to_numpy() >= 1
            obs, _, term, trunc, _ = env.step(torch.tanh(mu))
            episode_step += 1
            for e in np.nonzero((term | trunc).numpy())[0]:
                episodes += 1
                for d in np.nonzero(outside[e])[0]:
                    exits.append((int(d), edge(pos[e, d], dr.rows, dr.cols), int(episode_step[e]),
                                  mu[e, d].abs().max().item()))
                episode_step[e] = 0
    print(f"{path}: {episodes} episodes, {len(exits)} ended with a drone outside")
    if exits:
        d, where, when, mu = zip(*exits, strict=True)
        print("  by drone:", dict(sorted(Counter(d).items())))
        print("  by edge:", dict(Counter(where)))
        print("  episode step of the exit: median", int(np.median(when)), "| most common", Counter(when).most_common(3))
        print(f"  largest |pre-tanh mean| of the exiting drone: median {np.median(mu):.1f}, max {max(mu):.1f}")


if __name__ == "__main__":
    main(sys.argv[1], *(sys.argv[2:3] or ["latest"]), *(int(a) for a in sys.argv[3:4]))
