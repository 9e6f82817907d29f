"""Microseconds per FlyVectorEnv step at E = 1, N = 4 drones, random actions, 1.5 % ignition (2 threads)."""

import time

import torch

from roshan.config import Config, DroneConfig, IgnitionConfig
from roshan.env.fly import FlyVectorEnv
from roshan.runtime import init_taichi

init_taichi("cpu")
env = FlyVectorEnv(num_envs=1, config=Config(ignition=IgnitionConfig(fire_percentage=0.015),
                                             drones=DroneConfig(num_drones=4)), seed=0)
env.reset(seed=0)
g = torch.Generator().manual_seed(0)
actions = [torch.rand((1, 4, 2), generator=g) * 2 - 1 for _ in range(5000)]
for a in actions[:500]:
    env.step(a)
t = time.perf_counter()
for a in actions:
    env.step(a)
print(f"{(time.perf_counter() - t) / len(actions) * 1e6:.1f}")
