"""Env lifetime: closed envs give their simulators to roshan.kernels.pool, so building, stepping and closing
envs in a loop allocates no new Taichi fields, does not grow memory, compiles nothing after the first env of a
build, and a reused simulator replays a brand-new one's trajectory bit for bit."""

import functools
import os
import time
from pathlib import Path

import numpy as np
import pytest

from roshan import runtime
from roshan.algos.frozen import FrozenFlyPolicy
from roshan.config import Config, DroneConfig, IgnitionConfig, MapConfig, PlannerConfig, WindConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.kernels import pool

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
SMALL = Config(map=MapConfig(name="uniform", uniform_rows=12, uniform_cols=12),
               ignition=IgnitionConfig(fire_percentage=0.05), drones=DroneConfig(num_drones=2))
REBUILD_S = 1.0  # a rebuild compiles nothing and allocates no fields: milliseconds, far below this


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def fly_actions(env, step: int) -> np.ndarray:
    """Deterministic actions that vary per step, drone and env (so drones leave the map and episodes end)."""
    e, d, k = np.meshgrid(np.arange(env.num_envs), np.arange(env.num_drones), np.arange(2), indexing="ij")
    return np.sin(1.7 * step + 2.3 * e + 1.1 * d + 0.7 * k).astype(np.float32)


def build_step_close(make, actions) -> float:
    """Seconds to build an env, reset it and take one step; the env is closed afterwards."""
    t = time.perf_counter()
    env = make()
    env.reset()
    env.step(actions(env, 0))
    seconds = time.perf_counter() - t
    env.close()
    return seconds


def record(env, steps: int, actions, seed: int) -> list[np.ndarray]:
    """Copies of everything the env returns over ``steps`` steps from ``reset(seed=seed)``."""
    obs, _ = env.reset(seed=seed)
    out = [v.numpy().copy() for v in obs.values()]
    for t in range(steps):
        obs, rewards, terms, truncs, info = env.step(actions(env, t))
        out += [v.numpy().copy() for v in obs.values()]
        out += [rewards.numpy().copy(), terms.numpy().copy(), truncs.numpy().copy()]
        out += [v.numpy().copy() for v in info["episode_stats"].values()]
    return out


def assert_same(a: list[np.ndarray], b: list[np.ndarray]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_rebuilt_fly_env_replays_a_fresh_one_bit_for_bit():
    fresh = FlyVectorEnv(2, SMALL, seed=5)
    expected = record(fresh, 50, fly_actions, seed=5)
    fresh_fire = fresh.fire
    fresh.close()
    other = FlyVectorEnv(2, SMALL, seed=9)  # dirties the pooled simulators with another seed, mid-episode
    assert other.fire is fresh_fire
    record(other, 30, fly_actions, seed=9)
    other.close()
    again = FlyVectorEnv(2, SMALL, seed=5)
    assert again.fire is fresh_fire
    assert_same(record(again, 50, fly_actions, seed=5), expected)
    again.close()


def test_500_fly_envs_built_and_closed_reuse_memory_fields_and_kernels():
    make = lambda: FlyVectorEnv(2, SMALL)  # noqa: E731
    build_step_close(make, fly_actions)  # compiles (unless an earlier test of this module did)
    trees = runtime.field_trees()
    seconds, rss_after_100 = [], None
    for i in range(500):
        seconds.append(build_step_close(make, fly_actions))
        if i == 99:
            rss_after_100 = rss_mb()
    growth = rss_mb() - rss_after_100
    assert runtime.field_trees() == trees
    assert growth < 100, f"RSS grew {growth:.0f} MB from env 100 to env 500"
    assert max(seconds) < REBUILD_S, f"slowest rebuild {max(seconds):.2f} s (median {np.median(seconds):.3f} s)"


@pytest.mark.slow
def test_envs_alive_together_each_hold_their_own_simulators():
    a, b = FlyVectorEnv(2, SMALL), FlyVectorEnv(2, SMALL)
    assert a.fire is not b.fire and a.kernels is not b.kernels
    a.close()
    a.close()  # closing twice gives the simulators back once
    c, d = FlyVectorEnv(2, SMALL), FlyVectorEnv(2, SMALL)
    assert c.fire is a.fire and d.fire is not a.fire
    for env in (b, c, d):
        env.close()


@pytest.mark.slow
def test_live_envs_still_stop_before_the_field_tree_limit(monkeypatch):
    live = [FlyVectorEnv(2, SMALL) for _ in range(pool.pooled_count() + 1)]  # the pool has none left now
    used = runtime.field_trees()
    monkeypatch.setattr(runtime, "MAX_FIELD_TREES", used + runtime.TREE_HEADROOM - 1)
    with pytest.raises(RuntimeError, match="FireSim: this process already holds"):
        FlyVectorEnv(2, SMALL)
    live.pop().close()
    FlyVectorEnv(2, SMALL).close()  # the closed env's simulators: no new trees needed
    for env in live:
        env.close()


@pytest.mark.slow
def test_rendering_a_rebuilt_env_allocates_nothing():
    env = FlyVectorEnv(2, SMALL)
    env.reset(seed=1)
    first = env.render()
    env.close()
    trees = runtime.field_trees()
    env = FlyVectorEnv(2, SMALL)
    env.reset(seed=1)
    np.testing.assert_array_equal(env.render(), first)
    env.close()
    assert runtime.field_trees() == trees


@functools.cache
def shipped_policy() -> FrozenFlyPolicy:
    """The shipped FlyAgent, loaded once: loading is torch work outside the pool (~0.2 s, mostly the network's
    orthogonal initialisation before the checkpoint overwrites it)."""
    return FrozenFlyPolicy(MODEL, "cpu")


def planner_env(seed: int = 3) -> PlannerVectorEnv:
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05, clusters=2), drones=DroneConfig(num_drones=4),
                 wind=WindConfig(speed=0.0), map=MapConfig(name="uniform", uniform_rows=20, uniform_cols=20))
    pc = PlannerConfig(interval=2, fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    return PlannerVectorEnv(2, cfg, pc, evaluation=True, seed=seed, fly_policy=shipped_policy(),
                            explorer_policy=shipped_policy())


def planner_actions(env, step: int) -> np.ndarray:
    return (np.arange(env.num_envs * env.num_drones).reshape(env.num_envs, env.num_drones) + step) % 3


@pytest.mark.slow
def test_20_planner_envs_rebuild_without_compiling_and_replay_a_fresh_one():
    fresh = planner_env()
    expected = record(fresh, 10, planner_actions, seed=3)
    fresh.close()
    trees = runtime.field_trees()
    seconds = [build_step_close(lambda: planner_env(seed=11), planner_actions) for _ in range(20)]
    assert runtime.field_trees() == trees
    assert max(seconds) < REBUILD_S, f"planner rebuilds took {np.round(seconds, 2).tolist()} s"
    again = planner_env()
    assert_same(record(again, 10, planner_actions, seed=3), expected)
    again.close()


def test_reset_taichi_empties_the_pool():
    FlyVectorEnv(2, SMALL).close()
    assert pool.pooled_count() >= 1
    runtime.reset_taichi()
    assert pool.pooled_count() == 0
