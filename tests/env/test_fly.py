"""FlyAgent env: each reward term on a constructed scene, T_max, features, zero-copy, bad actions, seeds."""

import numpy as np
import pytest
import torch

from roshan.config import Config, DroneConfig, FlyConfig, IgnitionConfig, WindConfig
from roshan.env.fly import FlyVectorEnv
from roshan.episode import REASONS
from roshan.kernels.fly import time_limit
from roshan.maps import BURNING

EMPTY = IgnitionConfig(fire_percentage=0.0)


_ENVS: dict = {}


def make_env(num_drones=1, envs=1, fly=None, ignition=EMPTY, seed=0):
    """An env of this configuration, freshly reset with ``seed``.

    Envs are cached per configuration: each one compiles its fused step kernel once (several seconds), and
    ``reset(seed=...)`` restarts every random stream, so reusing one is the same as building a new one.
    """
    cfg = Config(ignition=ignition, drones=DroneConfig(num_drones=num_drones), wind=WindConfig(speed=0.0))
    key = (cfg, envs, fly or FlyConfig())
    if key not in _ENVS:
        _ENVS[key] = FlyVectorEnv(envs, cfg, fly or FlyConfig(), seed=seed)
    env = _ENVS[key]
    env.reset(seed=seed)
    return env


def scene(env, pos_m, goals, vel=None):
    """Put drones at positions (metres) with goals (grid units), env 0."""
    pos = np.asarray(pos_m, np.float32).reshape(1, env.num_drones, 2)
    env.drones.set_state(pos, np.zeros_like(pos) if vel is None else np.asarray(vel, np.float32).reshape(pos.shape))
    env.drones.set_goals(np.asarray(goals, np.float32).reshape(1, env.num_drones, 2))


def act(env, *a):
    return env.step(np.asarray(a, np.float32).reshape(1, env.num_drones, 2))


@pytest.mark.parametrize("rows, cols, version, policy, pct, expected", [
    (35, 36, "newest", "simple", 0.015, 3016),
    (35, 36, "thesis", "simple", 0.015, 1508),
    (35, 36, "thesis", "complex", 0.01, 7540),
    (35, 36, "thesis", "complex", 0.05, 15080),
    (50, 50, "newest", "complex", 0.01, 4244),
    (50, 50, "thesis", "simple", 0.01, 2122),
    (50, 50, "thesis", "complex", 0.01, 16976),
    (50, 50, "thesis", "complex", 0.05, 38196),
])
def test_time_limit_matches_the_worked_values(rows, cols, version, policy, pct, expected):
    assert time_limit(rows, cols, 10.0, 0.1, 10.0, pct, FlyConfig(policy=policy, time_limit=version)) == expected


@pytest.mark.slow
def test_progress_pays_improvements_only():
    env = make_env()
    scene(env, [[100.0, 100.0]], [[10.5, 20.5]])
    _, r, term, trunc, _ = act(env, 0.0, 1.0)  # 1 m (0.1 cells) towards the goal
    d0 = np.hypot(0.5, 10.5)
    d1 = np.hypot(0.5, 10.4)
    assert r[0, 0].item() == pytest.approx(0.1 * (d0 - d1), rel=1e-4)
    _, r, _, _, _ = act(env, 0.0, -1.0)  # away: nothing, not a penalty
    assert r[0, 0].item() == 0.0
    assert not term[0] and not trunc[0]


def test_goal_reached_ends_the_episode_successfully_and_autoresets():
    env = make_env()
    scene(env, [[104.0, 204.0]], [[10.5, 20.5]])  # 0.1 cells from the goal on both axes
    obs, r, term, trunc, info = act(env, 0.0, 0.0)
    assert r[0, 0].item() == pytest.approx(1.0)
    assert bool(term[0]) and not bool(trunc[0]) and bool(info["_episode_stats"][0])
    assert info["episode_stats"]["success"][0].item() == 1.0 and info["episode_stats"]["steps"][0].item() == 1
    final = info["final_obs"]["agent"][0, 0, 0]
    assert final[8].item() == pytest.approx(np.hypot(0.1, 0.1) / 5, rel=1e-3)  # distance feature at the end
    gs = env.drones.bases.to_numpy()[:, 0][0]
    assert np.linalg.norm(env.drones.pos.to_numpy()[0, 0] - (gs + 0.5) * 10) == pytest.approx(0.0, abs=1e-4), \
        "the env was reset in the same step: one drone starts on the groundstation centre"


def test_boundary_exit_after_two_steps_outside():
    env = make_env()
    scene(env, [[0.5, 100.0]], [[20.5, 10.5]])
    _, r, term, _, _ = act(env, -1.0, 0.0)  # x = -0.5 m: outside once
    assert not term[0]
    _, r, term, trunc, info = act(env, -1.0, 0.0)
    assert bool(term[0]) and not bool(trunc[0])
    assert REASONS[int(info["episode_stats"]["reason"][0])] == "boundary"
    assert r[0, 0].item() == pytest.approx(-1.0)  # boundary; moving away earns no progress
    assert info["episode_stats"]["success"][0].item() == 0.0


@pytest.mark.slow
def test_timeout_truncates_with_the_penalty():
    fly = FlyConfig(k_turn=0.01)
    env = make_env(fly=fly)
    limit = env.t_max
    assert limit == time_limit(35, 36, 10.0, 0.1, 10.0, 0.0, fly)
    for k in range(limit):
        scene(env, [[100.0, 100.0]], [[20.5, 20.5]])
        _, r, term, trunc, info = act(env, 0.0, 0.0)
        if k < limit - 1:
            assert not term[0] and not trunc[0]
    assert bool(trunc[0]) and not bool(term[0])
    assert REASONS[int(info["episode_stats"]["reason"][0])] == "timeout"
    assert r[0, 0].item() == pytest.approx(-1.0)


@pytest.mark.slow
def test_collision_terminates_with_penalty_and_proximity():
    env = make_env(num_drones=2, fly=FlyConfig(collision=True))
    scene(env, [[150.0, 150.0], [153.0, 150.0]], [[30.5, 30.5], [30.5, 5.5]])  # 3 m apart < 4 m
    _, r, term, _, info = act(env, 0.0, 0.0, 0.0, 0.0)
    assert bool(term[0]) and REASONS[int(info["episode_stats"]["reason"][0])] == "collision"
    # previous neighbour entry of each: (+-0.3 cells / 10 = 0.03, 0) -> proximity 0.03 (the 0 adds nothing)
    expected = -1.0 + -0.05 * 0.03
    np.testing.assert_allclose(r[0].numpy(), [expected, expected], rtol=1e-4)


def complex_scene(sticky):
    fly = FlyConfig(policy="complex", sticky_extinguish=sticky)
    env = make_env(fly=fly)
    cols = env.fire.cols
    mask = np.zeros((1, env.fire.num_cells), np.int32)
    mask[0, [10 * cols + 20, 10 * cols + 30]] = 1
    env.fire.ignite_cells(mask)
    scene(env, [[105.0, 205.0]], [[10.5, 20.5]])  # on the first fire's centre
    return env, cols


@pytest.mark.slow
@pytest.mark.parametrize("sticky", [False, True])
def test_extinguish_pays_once_unless_the_original_sticky_flag_is_reproduced(sticky):
    env, cols = complex_scene(sticky)
    _, r, term, _, _ = act(env, 0.0, 0.0)
    assert env.fire.state(0)[10, 20] != BURNING
    assert not term[0], "one fire is left"
    assert r[0, 0].item() == pytest.approx(0.01)  # Extinguish; the new goal is further away (no progress)
    np.testing.assert_allclose(env.drones.goal.to_numpy()[0, 0], [10.5, 30.5])  # next fire taken
    _, r, _, _, _ = act(env, 0.0, 0.0)
    assert r[0, 0].item() == pytest.approx(0.01 if sticky else 0.0)


def test_putting_out_the_last_fire_succeeds():
    env, cols = complex_scene(False)
    act(env, 0.0, 0.0)
    scene(env, [[105.0, 305.0]], [[10.5, 30.5]])
    _, r, term, _, info = act(env, 0.0, 0.0)
    assert bool(term[0]) and info["episode_stats"]["success"][0].item() == 1.0
    assert r[0, 0].item() == pytest.approx(1.0 + 0.01)
    assert info["episode_stats"]["extinguished"][0].item() == 2.0


@pytest.mark.slow
def test_greedy_assignment_takes_the_nearest_unreserved_fire_then_the_groundstation():
    env = make_env(num_drones=3)
    cols = env.fire.cols
    scene(env, [[105.0, 105.0]] * 3, [[0.0, 0.0]] * 3)
    mask = np.zeros((1, env.fire.num_cells), np.int32)
    mask[0, [12 * cols + 10, 10 * cols + 13]] = 1  # 2 and 3 cells away from the drones' cell (10, 10)
    env.fire.ignite_cells(mask)
    env.drones.assign_fire_goals()
    gs = env.drones.bases.to_numpy()[:, 0][0] + 0.5
    np.testing.assert_allclose(env.drones.goal.to_numpy()[0], [[12.5, 10.5], [10.5, 13.5], gs])
    assert env.drones.goal_cell.to_numpy()[0].tolist() == [12 * cols + 10, 10 * cols + 13, -1]


@pytest.mark.slow
def test_observation_features_against_a_hand_computation():
    env = make_env(num_drones=2)
    scene(env, [[100.0, 100.0], [130.0, 100.0]], [[14.0, 13.0], [20.0, 20.0]])
    obs, *_ = act(env, 0.5, 0.5, 0.0, 0.0)
    p = np.array([100.5, 100.5]) / 10  # after the move: v = (5, 5) m/s for 0.1 s
    g = np.array([14.0, 13.0])
    v = np.array([5.0, 5.0])
    delta = g - p
    ug, uv = delta / np.linalg.norm(delta), v / np.linalg.norm(v)
    expected = [0, 5 / 50, 5 / 50, min(delta[0] / 5, 1), min(delta[1] / 5, 1), uv @ ug,
                uv @ np.array([-ug[1], ug[0]]), np.hypot(0.5, 0.5), min(np.linalg.norm(delta) / 5, 1)]
    np.testing.assert_allclose(obs["agent"][0, 0, 0].numpy(), expected, atol=1e-5)
    # drone 1 sees drone 0 at (-2.95, +0.05) cells: slot 1 = (dx / 10, dy / 10, v / (v_max * 5))
    np.testing.assert_allclose(obs["neighbors"][0, 1, 0, 1].numpy(), [-0.295, 0.005, 0.1, 0.1], atol=1e-5)
    assert obs["neighbors_mask"][0, 1, 0].tolist() == [0.0, 1.0]
    before = obs["agent"][0, 0, 0].clone()
    obs, *_ = act(env, 0.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(obs["agent"][0, 0, 1].numpy(), before.numpy())  # frames shift, 0 = newest


@pytest.mark.slow
def test_step_returns_the_same_tensors_and_writes_into_them():
    env = make_env(num_drones=2, envs=3, ignition=IgnitionConfig(fire_percentage=0.02))
    obs, _ = env.reset(seed=1)
    ptrs = {k: v.data_ptr() for k, v in obs.items()}
    before = obs["agent"].clone()
    for _ in range(3):
        obs2, r, term, trunc, info = env.step(torch.full((3, 2, 2), 0.3))
    assert {k: v.data_ptr() for k, v in obs2.items()} == ptrs and obs2["agent"] is obs["agent"]
    assert not torch.equal(before, obs["agent"])
    assert r.shape == (3, 2) and term.shape == (3,) and term.dtype == torch.bool


@pytest.mark.slow
def test_bad_actions_are_rejected_with_env_and_drone():
    env = make_env(num_drones=2, envs=2)
    bad = np.zeros((2, 2, 2), np.float32)
    bad[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match="env 1, drone 0"):
        env.step(bad)
    with pytest.raises(ValueError, match=r"expected shape \(2, 2, 2\)"):
        env.step(np.zeros((2, 2), np.float32))


def test_out_of_range_actions_are_clipped():
    env = make_env(seed=3)
    oa = env.step(np.array([[[5.0, -7.0]]], np.float32))[0]["agent"].clone()
    env.reset(seed=3)
    ob = env.step(np.array([[[1.0, -1.0]]], np.float32))[0]["agent"]
    assert torch.equal(oa, ob)


@pytest.mark.slow
def test_same_seed_same_trajectory():
    def rollout(seed):
        env = make_env(num_drones=2, envs=2, fly=FlyConfig(policy="complex"),
                       ignition=IgnitionConfig(fire_percentage=0.02), seed=seed)
        g = torch.Generator().manual_seed(0)
        out = []
        for _ in range(150):
            obs, r, term, trunc, _ = env.step(torch.rand((2, 2, 2), generator=g) * 2 - 1)
            out.append(torch.cat([obs["agent"].flatten(), r.flatten(), term.float(), trunc.float()]).clone())
        return torch.stack(out)

    assert torch.equal(rollout(5), rollout(5))
    assert not torch.equal(rollout(5), rollout(6))


def test_a_real_end_on_the_last_allowed_step_terminates_instead_of_truncating():
    env = make_env(fly=FlyConfig(k_turn=0.01))
    for _ in range(env.t_max - 1):
        scene(env, [[100.0, 100.0]], [[20.5, 20.5]])
        act(env, 0.0, 0.0)
    scene(env, [[104.0, 204.0]], [[10.5, 20.5]])  # reaches its goal exactly when the clock runs out
    _, _, term, trunc, info = act(env, 0.0, 0.0)
    assert bool(term[0]) and not bool(trunc[0])
    assert REASONS[int(info["episode_stats"]["reason"][0])] == "timeout"  # the precedence of docs/model/agents.md §9


@pytest.mark.slow
def test_step_before_reset_is_an_error():
    import gymnasium as gym

    env = FlyVectorEnv(1, Config(ignition=EMPTY, drones=DroneConfig(num_drones=1), wind=WindConfig(speed=0.0)))
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((1, 1, 2), np.float32))


@pytest.mark.slow
def test_one_env_flies_as_env_0_of_a_batch():
    """E = 1 runs its kernels serially on the calling thread (roshan.kernels.fire_layout.env_loop_serial), a batch
    through Taichi's thread pool; env 0's trajectory, episode ends and autoresets included, is the same."""
    def rollout(envs):
        env = make_env(num_drones=2, envs=envs, fly=FlyConfig(policy="complex"),
                       ignition=IgnitionConfig(fire_percentage=0.02), seed=4)
        assert env.fire.serial_envs == (envs == 1)
        g = torch.Generator().manual_seed(1)
        out, ends = [], 0
        for _ in range(400):
            a = torch.zeros((envs, 2, 2))  # the other envs' actions play no part in env 0's trajectory
            a[0] = (torch.rand((2, 2), generator=g) * 2 - 0.6).clamp(max=1.0)  # a drift: boundary exits
            obs, r, term, trunc, info = env.step(a)
            ends += int(term[0] | trunc[0])
            out.append(torch.cat([obs["agent"][0].flatten(), r[0], info["final_obs"]["agent"][0].flatten(),
                                  env._episode[0]]).clone())
        return torch.stack(out), ends

    one, ends = rollout(1)
    assert ends >= 2, "the rollout should cross episode ends (autoresets)"
    batched, _ = rollout(3)
    assert torch.equal(one, batched)


def test_actions_of_any_dtype_and_kind_are_taken_as_float32():
    env = make_env(num_drones=2, envs=2, seed=2)
    a64 = np.array([[[0.1, -0.2], [0.3, 0.4]], [[-0.5, 0.6], [0.7, -0.8]]])  # float64
    ref = env.step(torch.tensor(a64, dtype=torch.float32))[0]["agent"].clone()
    for given in (a64, a64.tolist(), torch.tensor(a64)):
        env.reset(seed=2)
        assert torch.equal(env.step(given)[0]["agent"], ref)
