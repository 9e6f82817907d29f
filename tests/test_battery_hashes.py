"""The battery's behaviour pinned bit for bit: the env hashes of tests/test_behaviour_hashes.py run without a
battery, so these cover its rules (the draw, the swap, a drone lost, the return rules and their reserves, the final
approach, the landed drones) with hashes of observations, rewards, episode records and the battery's fields.

Recorded when the battery became one component (roshan/kernels/battery.py), from the code before it and after it
(the same hashes). A changed hash is a changed trajectory: say so in the commit and re-record with
``python tests/test_battery_hashes.py``.
"""

import hashlib
import sys
from pathlib import Path

import pytest
import torch

from roshan.config import Config, DroneConfig, EnergyConfig, FlyConfig, IgnitionConfig, PlannerConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.kernels.render import EnvZeroFrames
from tests.test_behaviour_hashes import feed

ROOT = Path(__file__).resolve().parents[1]
FLIER = ROOT / "tests" / "data" / "fly_collision_v1"  # not the shipped model: a new one must not change the pins

EXPECTED = {
    "fly": "74df99984dd0f12e204ab741809287da92cf21129cea4b71e2c6c89233332a6f",
    "planner_rules_waiting": "89ffc0ac053e7dc35c50c9e4378e90108c6d70ce436dc6c92bde33f1b34ddd9f",
    "planner_plain_tiny": "fe68504d6b871adabc2d6acc9860fdddc3a223a484873decb4292b8c264b170c",
    "greedy_aware_all": "51dc513fd290db3bc6833b3d4ee85e97d259823cc51cefc34eec59bf2b2f45ae",
    "greedy_aware_none": "df0b7bad69a71b2bff4517e7c21dbdbaea9e365cf25ed62a4502fc2d80c024a8",
}


def battery_fields(drones) -> list:
    b = drones.battery
    return [b.charge, b.lost, b.landed_steps, b.swaps, b.used, b.base_steps]


def step_all(h, env, act, steps: int, frames=None) -> None:
    obs, _ = env.reset(seed=5)
    feed(h, obs)
    for t in range(steps):
        obs, rewards, terms, truncs, info = env.step(act(obs))
        feed(h, obs, rewards, terms, truncs, info["episode_stats"], info["episode_energy"], info["_episode_stats"])
        if t % 25 == 0:
            for f in battery_fields(env.drones):
                feed(h, f.to_numpy())
            feed(h, env.drones.pos.to_numpy(), env.drones.refilling.to_numpy())
            if frames is not None:
                feed(h, frames.render())


def fly() -> str:
    """Random actions of three collision FlyAgents with a small battery and tank: drones lost, swaps, frames."""
    h = hashlib.sha256()
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05),
                 drones=DroneConfig(num_drones=3, use_water_limit=True, water_capacity=2.0,
                                    groundstation_start_percentage=0.5,
                                    energy=EnergyConfig(preset="scenario", capacity=900.0, swap_time=1.0)))
    env = FlyVectorEnv(num_envs=4, config=cfg, fly=FlyConfig(policy="complex", collision=True), seed=5)
    g = torch.Generator().manual_seed(1)
    frames = EnvZeroFrames(env.drones)
    step_all(h, env, lambda obs: torch.rand((4, 3, 2), generator=g) * 2.0 - 1.0, 300, frames)
    env.close()
    return h.hexdigest()


def planner(controller: str, energy: EnergyConfig, water: bool = True, **pc) -> str:
    """Random planner goals (or the greedy heuristic) for three drones with a battery, over 250 decisions."""
    h = hashlib.sha256()
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.03),
                 drones=DroneConfig(num_drones=3, use_water_limit=water, energy=energy))
    pcfg = PlannerConfig(fly_model=str(FLIER), explorer_model=str(ROOT / "models" / "fly_simple"), interval=2,
                         num_explorers=2, **pc)
    env = PlannerVectorEnv(3, cfg, pcfg, evaluation=True, controller=controller, seed=2)
    g = torch.Generator().manual_seed(3)

    def act(obs):
        count = obs["fires_mask"].sum(-1, keepdim=True)
        return (torch.rand((3, 3), generator=g) * count).long()

    step_all(h, env, act, 250)
    env.close()
    return h.hexdigest()


SCENARIOS = {
    "fly": fly,
    "planner_rules_waiting": lambda: planner("planner", EnergyConfig(preset="scenario", capacity=3000.0, approach=2.0),
                                             planner_resources=True, return_queue="waiting"),
    # pinned when no final approach and the reserve for every other drone's turn were the defaults
    "planner_plain_tiny": lambda: planner("planner", EnergyConfig(preset="scenario", capacity=300.0, approach=0.0),
                                          water=False),
    "greedy_aware_all": lambda: planner("greedy", EnergyConfig(preset="scenario", capacity=3000.0, approach=0.0),
                                        greedy_resources=True, greedy_home="fixed", return_queue="all"),
    "greedy_aware_none": lambda: planner("greedy", EnergyConfig(preset="scenario", capacity=3000.0, approach=1.5),
                                         greedy_resources=True, return_queue="none"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_the_battery_behaves_as_pinned(name):
    assert SCENARIOS[name]() == EXPECTED[name], f"{name}: the battery's trajectory changed"


if __name__ == "__main__":
    from roshan.runtime import init_taichi

    init_taichi("cpu")
    for name in sys.argv[1:] or SCENARIOS:
        print(f'    "{name}": "{SCENARIOS[name]()}",', flush=True)
