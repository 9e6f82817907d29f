"""Objects built before Taichi was reset hold dead fields: using them raises a clear error, not a segfault.

Its own module: resetting Taichi kills every env built before, so module-scoped env caches elsewhere must not
see it (conftest resets Taichi after each module anyway)."""

import numpy as np
import pytest

from roshan import runtime
from roshan.config import Config, DroneConfig, MapConfig
from roshan.env.fly import FlyVectorEnv
from roshan.kernels.fire import FireSim
from tests.conftest import make_map

SMALL = Config(map=MapConfig(name="uniform", uniform_rows=8, uniform_cols=8), drones=DroneConfig(num_drones=1))


@pytest.mark.slow
def test_an_env_built_before_reset_taichi_refuses_to_step():
    env = FlyVectorEnv(1, SMALL)
    env.reset(seed=0)
    actions = np.zeros((1, 1, 2), np.float32)
    env.step(actions)
    runtime.reset_taichi()
    runtime.init_taichi("cpu")
    with pytest.raises(RuntimeError, match=r"FlyVectorEnv\.step\(\): this env was built before Taichi was reset"):
        env.step(actions)
    with pytest.raises(RuntimeError, match=r"FlyVectorEnv\.reset\(\): this env was built before Taichi"):
        env.reset()
    env.close()  # closing a dead env is harmless: the pool forgot its generation


def test_a_fire_sim_built_before_a_reinit_refuses_to_run():
    sim = FireSim(make_map(np.full((4, 4), 2)), num_envs=1)
    sim.reset()
    runtime.init_taichi("cpu", threads=1)  # other arguments: Taichi re-initialises, the old fields die
    try:
        with pytest.raises(RuntimeError, match=r"FireSim\.step\(\): this simulator was built before Taichi"):
            sim.step()
        with pytest.raises(RuntimeError, match=r"FireSim\.reset\(\): this simulator was built before Taichi"):
            sim.reset()
    finally:
        runtime.init_taichi("cpu")
