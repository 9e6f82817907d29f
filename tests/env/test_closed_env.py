"""A closed env refuses step, reset and render: its simulators went back to roshan.kernels.pool and belong to the
next env built, so stepping the closed handle would write into another env's state."""

from pathlib import Path

import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError

from roshan.algos.frozen import FrozenFlyPolicy
from roshan.config import Config, DroneConfig, IgnitionConfig, MapConfig, PlannerConfig, WindConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
SMALL = Config(map=MapConfig(name="uniform", uniform_rows=12, uniform_cols=12),
               ignition=IgnitionConfig(fire_percentage=0.05), drones=DroneConfig(num_drones=2))


def fly_env() -> FlyVectorEnv:
    return FlyVectorEnv(2, SMALL, seed=5)


def planner_env() -> PlannerVectorEnv:
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05, clusters=2), drones=DroneConfig(num_drones=4),
                 wind=WindConfig(speed=0.0), map=MapConfig(name="uniform", uniform_rows=20, uniform_cols=20))
    pc = PlannerConfig(interval=2, fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    policy = FrozenFlyPolicy(MODEL, "cpu")
    return PlannerVectorEnv(2, cfg, pc, evaluation=True, seed=3, fly_policy=policy, explorer_policy=policy)


def fly_actions(env) -> np.ndarray:
    return np.full((env.num_envs, env.num_drones, 2), 0.5, np.float32)


def planner_actions(env) -> np.ndarray:
    return np.ones((env.num_envs, env.num_drones), np.int64)


@pytest.mark.parametrize(("make", "actions"), [(fly_env, fly_actions), (planner_env, planner_actions)],
                         ids=["fly", "planner"])
@pytest.mark.slow
def test_a_closed_env_refuses_step_reset_and_render(make, actions):
    env = make()
    env.reset(seed=1)
    env.step(actions(env))
    env.close()
    name = type(env).__name__
    for call in (lambda: env.step(actions(env)), lambda: env.reset(seed=1), env.render):
        with pytest.raises(ClosedEnvironmentError, match=rf"{name}\.\w+\(\): this env was closed"):
            call()
    env.close()  # idempotent


def test_stepping_a_closed_env_leaves_the_env_that_reuses_its_simulators_alone():
    old = fly_env()
    old.reset(seed=1)
    old.close()
    new = fly_env()
    assert new.fire is old.fire  # the pool handed the closed env's simulators to the new one
    before = [v.clone() for v in new.reset(seed=2)[0].values()]
    with pytest.raises(ClosedEnvironmentError):
        old.step(fly_actions(old))
    after = list(new._obs.values())
    for a, b in zip(before, after, strict=True):
        assert (a == b).all()
    new.close()
