"""FlyAgent env: the finite water tank (docs/model/agents.md §14) and frame skipping (docs/model/agents.md §12) on
constructed scenes."""

import math

import numpy as np
import pytest

from roshan.config import Config, ConfigError, DroneConfig, FlyConfig, IgnitionConfig, WindConfig, from_dict
from roshan.env.fly import FlyVectorEnv
from roshan.env.heuristics import straight_to_goal
from roshan.episode import REASONS
from roshan.kernels.fly import time_limit
from roshan.maps import BURNING

EMPTY = IgnitionConfig(fire_percentage=0.0)
WATER = DroneConfig(num_drones=1, use_water_limit=True)  # capacity 4, recharge 2 s
COMPLEX = FlyConfig(policy="complex")
SKIP = 5
SKIPPING = FlyConfig(frame_skips=SKIP, k_turn=0.01)  # T_max = 24 physics steps on the 35x36 map

_ENVS: dict = {}


def make_env(drones: DroneConfig, fly: FlyConfig, seed: int = 0) -> FlyVectorEnv:
    """A one-env FlyVectorEnv of this configuration, freshly reset with ``seed`` (cached: one compile each)."""
    cfg = Config(ignition=EMPTY, drones=drones, wind=WindConfig(speed=0.0))
    key = (cfg, fly)
    if key not in _ENVS:
        _ENVS[key] = FlyVectorEnv(1, cfg, fly, seed=seed)
    env = _ENVS[key]
    env.reset(seed=seed)
    return env


def scene(env, pos_m, goal):
    """Put env 0's only drone at ``pos_m`` (metres), at rest, heading for ``goal`` (grid units)."""
    env.drones.set_state(np.asarray(pos_m, np.float32).reshape(1, 1, 2), np.zeros((1, 1, 2), np.float32))
    env.drones.set_goals(np.asarray(goal, np.float32).reshape(1, 1, 2))


def act(env, ax, ay):
    return env.step(np.array([[[ax, ay]]], np.float32))


def centre_m(cell):
    return (np.asarray(cell, np.float64) + 0.5) * 10.0


def ignite(env, *cells):
    """Ignite ``cells`` ((row, col) each; all must be able to burn) in env 0."""
    mask = np.zeros((1, env.fire.num_cells), np.int32)
    for i, j in cells:
        mask[0, i * env.fire.cols + j] = 1
    env.fire.ignite_cells(mask)
    state = env.fire.state(0)
    assert all(state[i, j] == BURNING for i, j in cells), "pick cells that can burn"


def inward(env):
    """The groundstation cell and the diagonal unit step (+-1, +-1) from it towards the map's interior."""
    gs = env.drones.bases.to_numpy()[:, 0][0]
    return gs, np.array([1 if gs[0] < env.fire.rows // 2 else -1, 1 if gs[1] < env.fire.cols // 2 else -1])


def expected_refill(steps: int, capacity=4.0, recharge=2.0, dt=0.1) -> np.float32:
    """The tank after ``steps`` refills from empty, accumulated in float32 like the kernel."""
    rate = np.float32(capacity * dt / (recharge + 1e-4))
    w = np.float32(0.0)
    for _ in range(steps):
        w = min(np.float32(capacity), np.float32(w + rate))
    return w


# ---------------------------------------------------------------------------------------------- defaults


def test_defaults_keep_the_infinite_tank_and_one_physics_step_per_action():
    assert FlyConfig().frame_skips == 1
    d = DroneConfig()
    assert (d.use_water_limit, d.water_capacity, d.recharge_time) == (False, 4.0, 2.0)
    with pytest.raises(ConfigError, match="frame_skips"):
        from_dict(FlyConfig, {"frame_skips": 0})
    with pytest.raises(ConfigError, match="frame_skips"):
        from_dict(FlyConfig, {"frame_skips": 17})
    with pytest.raises(ConfigError, match="water_capacity"):
        from_dict(DroneConfig, {"water_capacity": 0.0})


# ---------------------------------------------------------------------------------------------- water


@pytest.mark.slow
def test_each_drop_costs_one_unit_and_an_empty_tank_cannot_extinguish():
    env = make_env(WATER, COMPLEX)
    gs, step = inward(env)
    a, b, c, far = (gs + k * step for k in ((4, 4), (4, 7), (7, 4), (12, 12)))
    ignite(env, a, b, c, far)
    assert env.water.tolist() == [[4.0]], "full at reset"
    for n, cell in enumerate((a, b), start=1):
        scene(env, centre_m(cell), cell + 0.5)
        _, r, term, _, _ = act(env, 0.0, 0.0)
        assert env.fire.state(0)[tuple(cell)] != BURNING
        assert env.water.tolist() == [[4.0 - n]]
        assert r[0, 0].item() == pytest.approx(0.01)  # Extinguish (thesis coefficients); the next goal is further away
        assert not term[0]
    env.drones.set_water(np.zeros((1, 1), np.float32))
    scene(env, centre_m(c), c + 0.5)
    _, r, term, _, _ = act(env, 0.0, 0.0)
    assert env.fire.state(0)[tuple(c)] == BURNING, "an empty tank puts nothing out"
    assert env.water.tolist() == [[0.0]] and r[0, 0].item() == 0.0 and not term[0]
    assert env.drones.n_extinguished.to_numpy()[0, 0] == 2


def test_the_tank_refills_at_the_groundstation_only():
    env = make_env(WATER, COMPLEX)
    gs, step = inward(env)
    ignite(env, gs + 12 * step)  # keeps the episode going
    far_goal = gs + 10 * step + 0.5
    empty = np.zeros((1, 1), np.float32)
    env.drones.set_water(empty)
    scene(env, centre_m(gs + step), far_goal)  # the neighbouring cell: no refill
    for _ in range(25):
        act(env, 0.0, 0.0)
    assert env.water.tolist() == [[0.0]]
    scene(env, centre_m(gs) + 3.0 * step, far_goal)  # inside the groundstation cell, off its centre
    full_after = math.ceil((2.0 + 1e-4) / 0.1)  # 21: recharge_time / dt plus the reference's 1e-4
    for k in range(1, full_after + 1):
        act(env, 0.0, 0.0)
        assert env.water[0, 0].item() == pytest.approx(float(expected_refill(k)), rel=1e-6)
        if k < full_after:
            assert env.water[0, 0].item() < 4.0
    assert env.water.tolist() == [[4.0]]
    act(env, 0.0, 0.0)
    assert env.water.tolist() == [[4.0]], "capped at the capacity"


def test_complex_policy_sends_an_empty_drone_home_and_back_to_the_fires():
    env = make_env(WATER, COMPLEX)
    gs, step = inward(env)
    a, b = gs + 4 * step, gs + np.array([2, 6]) * step
    ignite(env, a, b)
    cols = env.fire.cols
    env.drones.set_water(np.ones((1, 1), np.float32))
    scene(env, centre_m(a), a + 0.5)
    obs, _, term, _, _ = act(env, 0.0, 0.0)  # the last drop empties the tank
    assert env.fire.state(0)[tuple(a)] != BURNING and not term[0]
    np.testing.assert_allclose(env.drones.goal.to_numpy()[0, 0], gs + 0.5)
    assert env.drones.goal_cell.to_numpy()[0, 0] == -1, "no reservation while flying home"
    in_station = 0
    for _ in range(300):
        obs, _, term, trunc, _ = env.step(straight_to_goal(obs["agent"]))
        assert not term[0] and not trunc[0]
        cell = np.floor(env.drones.pos.to_numpy()[0, 0] / 10.0).astype(int)
        in_station += int(np.array_equal(cell, gs))
        if env.drones.refilling.to_numpy()[0, 0] == 0:
            break
        np.testing.assert_allclose(env.drones.goal.to_numpy()[0, 0], gs + 0.5)
        assert env.fire.state(0)[tuple(b)] == BURNING
    else:
        pytest.fail("the drone never left the groundstation")
    assert env.water.tolist() == [[4.0]]
    assert in_station == math.ceil((2.0 + 1e-4) / 0.1), "it left on the step its tank was full"
    np.testing.assert_allclose(env.drones.goal.to_numpy()[0, 0], b + 0.5)
    assert env.drones.goal_cell.to_numpy()[0, 0] == b[0] * cols + b[1]


# ---------------------------------------------------------------------------------------------- frame skips


@pytest.mark.slow
def test_one_action_runs_frame_skips_fire_updates_and_physics_steps():
    env = make_env(DroneConfig(num_drones=1), SKIPPING)
    assert env.t_max == time_limit(35, 36, 10.0, 0.1, 10.0, 0.0, SKIPPING) == 24, "T_max counts physics steps"
    assert env.fire.steps_since_reset().tolist() == [0]
    scene(env, [100.0, 100.0], [10.0, 30.5])
    act(env, 0.0, 1.0)
    assert env.fire.steps_since_reset().tolist() == [SKIP]
    np.testing.assert_allclose(env.drones.pos.to_numpy()[0, 0], [100.0, 100.0 + SKIP * 1.0], atol=1e-4)
    act(env, 0.0, 1.0)
    assert env.fire.steps_since_reset().tolist() == [2 * SKIP]
    assert env.kernels.steps.to_numpy().tolist() == [2 * SKIP]
    assert env.kernels.remaining.to_numpy().tolist() == [24 - 2 * SKIP]


def test_one_frame_per_control_period_and_only_the_last_reward():
    env = make_env(DroneConfig(num_drones=1), SKIPPING)
    scene(env, [100.0, 100.0], [10.0, 30.5])  # straight along the column axis
    obs, r, *_ = act(env, 0.0, 1.0)
    # each physics step gains 0.1 cells; the reference keeps only the last one's progress reward, not 5 x that
    assert r[0, 0].item() == pytest.approx(0.1 * 0.1, rel=1e-3)
    before = obs["agent"][0, 0].clone()  # (T, 9), frame 0 the newest
    assert before[0, 2].item() == pytest.approx(0.2)  # velocity 10 m/s / (v_max * s)
    obs, r, *_ = act(env, 0.0, -1.0)  # away: the last step pays nothing, whatever came before
    assert r[0, 0].item() == 0.0
    after = obs["agent"][0, 0]
    np.testing.assert_array_equal(after[1:].numpy(), before[:-1].numpy())  # shifted once, not 5 times
    assert after[0, 2].item() == pytest.approx(-0.2)


def test_an_episode_ending_inside_the_period_ends_at_that_physics_step():
    env = make_env(DroneConfig(num_drones=1), SKIPPING)
    scene(env, [100.0, 100.0], [10.0, 10.48])  # 0.38, 0.28, 0.18 cells after steps 1-3: reached at step 3
    obs, r, term, trunc, info = act(env, 0.0, 1.0)
    assert bool(term[0]) and not bool(trunc[0])
    stats = info["episode_stats"]
    assert stats["steps"][0].item() == 3 and stats["success"][0].item() == 1.0
    assert r[0, 0].item() == pytest.approx(1.0 + 0.1 * 0.1, rel=1e-3)  # goal + the third step's progress
    assert stats["return"][0].item() == pytest.approx(r[0, 0].item())
    final = info["final_obs"]["agent"][0, 0, 0]
    assert final[8].item() == pytest.approx(0.18 / 5, abs=1e-4), "the drone stopped after step 3, not 5"
    assert env.fire.steps_since_reset().tolist() == [0], "reset in the same call"


def test_a_time_limit_that_is_no_multiple_of_the_period_truncates_at_the_exact_step():
    env = make_env(DroneConfig(num_drones=1), SKIPPING)
    periods = math.ceil(24 / SKIP)  # 5 calls: 4 x 5 physics steps, then 4 of the 5th period
    for k in range(periods):
        scene(env, [100.0, 100.0], [20.5, 20.5])
        _, r, term, trunc, info = act(env, 0.0, 0.0)
        if k < periods - 1:
            assert not term[0] and not trunc[0]
            assert env.fire.steps_since_reset().tolist() == [SKIP * (k + 1)]
    assert bool(trunc[0]) and not bool(term[0])
    stats = info["episode_stats"]
    assert REASONS[int(stats["reason"][0])] == "timeout" and stats["steps"][0].item() == 24
    assert r[0, 0].item() == pytest.approx(-1.0)
    assert stats["return"][0].item() == pytest.approx(-1.0), "the return sums the rewards the learner saw"
