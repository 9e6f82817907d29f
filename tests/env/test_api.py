"""The public env APIs: Gymnasium registration, the single-env FlyEnv and the PettingZoo FlyParallelEnv.

Every new env compiles its Taichi kernels, so the envs are module-scoped and share one small config.
"""

import importlib
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import roshan.env
from roshan.config import Config, DroneConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.pettingzoo import FlyParallelEnv
from roshan.env.single import EPISODE_KEY, FlyEnv
from roshan.episode import REASONS

ENV_ID = "roshan/FlyAgent-v0"
N = 2
SMALL = Config(drones=DroneConfig(num_drones=N))
# Every drone flies to the lower corner: it leaves the map within a few hundred steps whatever the seed.
EXIT = -np.ones((N, 2), dtype=np.float32)


@pytest.fixture(scope="module")
def fly_env():
    env = gymnasium.make(ENV_ID, config=SMALL, render_mode="rgb_array")
    yield env
    env.close()


@pytest.fixture(scope="module")
def par_env():
    env = FlyParallelEnv(config=SMALL)
    yield env
    env.close()


def run_to_end(env, seed):
    """Reset with ``seed`` and fly out of the map; returns the last two observations, the steps and the last step."""
    prev, _ = env.reset(seed=seed)
    for steps in range(1, env.unwrapped.vector_env.t_max + 1):
        obs, reward, terminated, truncated, info = env.step(EXIT)
        if terminated or truncated:
            return prev, obs, steps, (reward, terminated, truncated, info)
        prev = obs
    raise AssertionError("the episode did not end within t_max steps")


def test_registration_is_idempotent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # gymnasium warns when an id is registered again
        importlib.reload(roshan.env)
    spec = gymnasium.spec(ENV_ID)
    assert spec.entry_point == "roshan.env.single:FlyEnv"
    assert spec.vector_entry_point == "roshan.env.fly:FlyVectorEnv"


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:.*A Box observation space")  # the spaces are unbounded on purpose
def test_check_env(fly_env):
    assert isinstance(fly_env.unwrapped, FlyEnv)
    check_env(fly_env.unwrapped)


@pytest.mark.slow
def test_make_vec_gives_the_vector_env():
    vec = gymnasium.make_vec(ENV_ID, num_envs=3, config=SMALL)
    try:
        assert isinstance(vec, FlyVectorEnv) and vec.num_envs == 3
        assert vec.action_space.shape == (3, N, 2)
        obs, _ = vec.reset(seed=1)
        frames = vec.fly_config.frames
        want = {"agent": (3, N, frames, 9), "neighbors": (3, N, frames, N, 4), "neighbors_mask": (3, N, frames, N)}
        assert {k: tuple(v.shape) for k, v in obs.items()} == want
        assert {k: s.shape for k, s in vec.observation_space.spaces.items()} == want
    finally:
        vec.close()


def test_reset_seed_is_deterministic(fly_env):
    first, _ = fly_env.reset(seed=7)
    for _ in range(5):
        fly_env.step(fly_env.action_space.sample())
    following, _ = fly_env.reset()
    again, _ = fly_env.reset(seed=7)
    assert gymnasium.utils.env_checker.data_equivalence(first, again, exact=True)
    assert gymnasium.utils.env_checker.data_equivalence(following, fly_env.reset()[0], exact=True)
    assert first in fly_env.observation_space and first["agent"].dtype == np.float32
    assert first["agent"].shape == (N, fly_env.unwrapped.vector_env.fly_config.frames, 9)


def test_terminal_step_returns_final_observation_and_record(fly_env):
    prev, obs, steps, (reward, terminated, truncated, info) = run_to_end(fly_env, seed=3)
    assert terminated is True and truncated is False
    # Frame 0 is the newest: the terminal observation continues the episode (it is not the auto-reset start).
    np.testing.assert_array_equal(obs["agent"][:, 1:], prev["agent"][:, :-1])
    assert obs in fly_env.observation_space
    assert reward == pytest.approx(float(info["rewards"].mean())) and info["rewards"].shape == (N,)
    record = info[EPISODE_KEY]
    assert record["reason"] in REASONS and record["steps"] == steps
    assert (record["success"] == 1.0) == (record["reason"] == "none")
    assert set(record) == {"success", "reason", "steps", "burned_fraction", "extinguished", "return"}
    assert all(isinstance(v, float) for k, v in record.items() if k not in ("reason", "steps"))
    with pytest.warns(UserWarning, match="after the episode ended"):
        fly_env.step(EXIT)
    start, _ = fly_env.reset()
    assert all(np.array_equal(v[:, 0], v[:, -1]) for v in start.values())  # a new stack: copies of one frame


def test_single_env_rejects_bad_actions(fly_env):
    fly_env.reset(seed=0)
    with pytest.raises(ValueError, match="expected shape"):
        fly_env.unwrapped.step(np.zeros((N + 1, 2)))


def test_parallel_api(par_env):
    parallel_api_test(par_env, num_cycles=300)


def test_parallel_agents_end_together(par_env):
    obs, infos = par_env.reset(seed=3)
    agents = [f"drone_{i}" for i in range(N)]
    assert par_env.agents == agents and set(obs) == set(infos) == set(agents)
    assert par_env.observation_space("drone_1") is par_env.observation_space("drone_1")
    assert obs["drone_1"] in par_env.observation_space("drone_1")
    for _ in range(par_env.vector_env.t_max):
        obs, rewards, terms, truncs, infos = par_env.step({a: EXIT[0] for a in par_env.agents})
        if not par_env.agents:
            break
    assert par_env.agents == [] and set(rewards) == set(terms) == set(infos) == set(agents)
    assert all(terms.values()) and not any(truncs.values())
    assert infos["drone_0"][EPISODE_KEY] == infos["drone_1"][EPISODE_KEY]
    assert infos["drone_0"][EPISODE_KEY]["reason"] in REASONS
    with pytest.warns(UserWarning, match="no live agents"):
        assert par_env.step({}) == ({}, {}, {}, {}, {})
    par_env.reset()
    assert par_env.agents == agents


@pytest.mark.slow
def test_an_env_says_how_many_steps_an_episode_may_last():
    """t_max counts physics steps; one step of the FlyAgent env runs frame_skips of them, one planner step interval."""
    import math

    from roshan.config import FlyConfig
    env = FlyVectorEnv(1, Config(), FlyConfig(frame_skips=3))
    assert env.physics_steps_per_step == 3 and env.max_env_steps == math.ceil(env.t_max / 3)
    env.close()


@pytest.mark.slow
def test_an_env_takes_its_task_section_from_the_config_unless_given_one():
    from roshan.config import FlyConfig

    env = FlyVectorEnv(1, Config(drones=DroneConfig(num_drones=N), fly=FlyConfig(frames=2)))
    assert env.fly_config.frames == 2 and env.observation_space["agent"].shape[2] == 2
    env.close()
    env = FlyVectorEnv(1, Config(drones=DroneConfig(num_drones=N), fly=FlyConfig(frames=2)), FlyConfig(frames=4))
    assert env.fly_config.frames == 4
    env.close()
