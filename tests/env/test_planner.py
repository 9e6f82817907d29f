"""Planner env (docs/model/agents.md §13): step limit, action -> goal mapping, each reward term on a constructed
decision, candidates from the detected-fire map, the heuristic baseline on the same episodes as the planner."""

from pathlib import Path

import numpy as np
import pytest
import taichi as ti
import torch

from roshan.config import (
    PLANNER_PRESETS,
    Config,
    DroneConfig,
    IgnitionConfig,
    PlannerConfig,
    PlannerRewardConfig,
    WindConfig,
)
from roshan.env.planner import PlannerVectorEnv
from roshan.kernels.planner import planner_time_limit
from roshan.kernels.rewards import PlannerCoefficients, planner_outcome_reward, planner_step_reward
from roshan.maps import BURNING

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
FIRES = IgnitionConfig(fire_percentage=0.05, clusters=2)
ZERO = {k: 0.0 for k in ("goal", "burned", "ground", "timeout", "same", "extinguish", "fast")}
_ENVS: dict = {}


def make_env(envs=2, evaluation=False, controller="planner", interval=1, seed=3, **rewards):
    """A planner env over the shipped simple FlyAgent, freshly reset with ``seed`` (cached per configuration:
    each one compiles its kernels once)."""
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=4), wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=interval, fly_model=MODEL, explorer_model=MODEL, num_explorers=2,
                       rewards=PlannerRewardConfig(**{**ZERO, **rewards}) if rewards else PlannerRewardConfig())
    key = (cfg, pc, envs, evaluation, controller)
    if key not in _ENVS:
        _ENVS[key] = PlannerVectorEnv(envs, cfg, pc, evaluation=evaluation, controller=controller, seed=seed)
    env = _ENVS[key]
    env.reset(seed=seed)
    return env


def candidates(env, e=0):
    """(count, candidate centres in grid units) of env e as the planner sees them."""
    n = int(env.candidate_counts[e])
    f = env._obs["fires"][e, :n].numpy()
    return n, (f + 1.0) / (2.0 / max(env.fire.rows, env.fire.cols))


@pytest.mark.parametrize("version, pct, expected", [("newest", 0.35, 3572), ("thesis", 0.35, 2678)])
def test_time_limit_matches_the_worked_values(version, pct, expected):
    assert planner_time_limit(35, 36, 10.0, 0.1, 10.0, pct, version) == expected


@pytest.mark.slow
def test_actions_become_goals_and_index_zero_or_padding_is_the_groundstation():
    env = make_env(same=-1.0)
    n, cand = candidates(env)
    assert n > 4 and env._obs["fires_mask"][0, :n].eq(1).all() and env._obs["fires_mask"][0, n:].eq(0).all()
    gs = cand[0]
    actions = torch.tensor([[1, 3, 0, n + 5], [0, 0, 0, 0]])
    env.kernels.apply(actions)  # the goals before any drone moves
    goals = env.goals()
    np.testing.assert_allclose(goals[0, 0], cand[1], atol=1e-4)
    np.testing.assert_allclose(goals[0, 1], cand[3], atol=1e-4)
    np.testing.assert_allclose(goals[0, 2], gs, atol=1e-4)
    np.testing.assert_allclose(goals[0, 3], gs, atol=1e-4)  # past the valid list
    assert np.all(np.abs(cand[1:] - np.floor(cand[1:]) - 0.5) < 1e-4)  # fire candidates are cell centres


@pytest.mark.slow
def test_bad_actions_name_the_problem():
    env = make_env()
    with pytest.raises(ValueError, match="expected shape"):
        env.step(torch.zeros(2, 3, dtype=torch.long))
    with pytest.raises(ValueError, match="integer candidate indices"):
        env.step(torch.zeros(2, 4))
    with pytest.raises(ValueError, match="env 1, drone 2"):
        env.step(torch.tensor([[0, 0, 0, 0], [0, 0, env.max_candidates, 0]]))


@pytest.mark.parametrize("actions, duplicates", [([1, 2, 3, 4], 0), ([1, 1, 2, 3], 1), ([5, 5, 5, 5], 3),
                                                 ([0, 0, 1, 2], 1)])
def test_same_goal_penalty_counts_drones_beyond_the_distinct_goals(actions, duplicates):
    env = make_env(same=-1.0)
    _, r, *_ = env.step(torch.tensor([actions, actions]))
    assert r.tolist() == pytest.approx([-float(duplicates)] * 2)


@pytest.mark.slow
@pytest.mark.parametrize("actions, expected", [([1, 2, 3, 4], 0.0), ([0, 2, 3, 4], -1.0), ([0, 0, 0, 1], -1.0)])
def test_groundstation_term_is_paid_once_per_decision_in_the_thesis_code(actions, expected):
    env = make_env(ground=-1.0)
    _, r, *_ = env.step(torch.tensor([actions, actions]))
    assert r.tolist() == pytest.approx([expected] * 2)


@pytest.mark.slow
def test_extinguish_term_pays_each_cell_put_out_in_the_interval():
    env = make_env(interval=1, extinguish=1.0)
    put_out = np.zeros(2)
    total = np.zeros(2)
    before = env.fire.stats()["extinguished"].astype(float)
    for _ in range(60):  # drones on their initial fire goals: they reach and flood them
        _, r, *_ = env.step(torch.ones(2, 4, dtype=torch.long) * torch.arange(1, 5))
        total += r.numpy()
    put_out = env.fire.stats()["extinguished"].astype(float) - before
    assert put_out.sum() > 0
    np.testing.assert_allclose(total, put_out)


@pytest.mark.slow
def test_timeout_truncates_and_pays_the_timeout_term():
    env = make_env(timeout=-1.0)
    env.kernels.remaining.from_numpy(np.array([1, 500], np.int32))
    _, r, term, trunc, info = env.step(torch.ones(2, 4, dtype=torch.long))
    assert r.tolist() == pytest.approx([-1.0, 0.0])
    assert trunc.tolist() == [True, False] and term.tolist() == [False, False]
    assert info["episode_stats"]["reason"][0] == 1 and info["episode_stats"]["success"][0] == 0  # timeout


@ti.kernel
def _outcome(objective: ti.i32, timed_out: ti.i32, terminal: ti.i32, frac: ti.f32) -> ti.f32:
    return planner_outcome_reward(_COEF, objective, timed_out, terminal, frac)


@ti.kernel
def _step_terms(ground: ti.f32, dup: ti.i32, ext: ti.i32, dist: ti.f32, drop: ti.f32) -> ti.f32:
    return planner_step_reward(_COEF_NEWEST, ground, dup, ext, dist, drop, 0.0, 0)


_COEF = PlannerCoefficients.resolve(PlannerRewardConfig())
_COEF_NEWEST = PlannerCoefficients.resolve(PlannerRewardConfig(version="newest"))


def test_outcome_terms_are_exclusive_in_the_reference_order():
    p = PLANNER_PRESETS["optuna_top10"]
    make_env()  # Taichi initialised
    assert _outcome(1, 1, 1, 0.25) == pytest.approx(p["goal"] + 0.25 * p["fast"], rel=1e-6)  # goal wins
    assert _outcome(0, 1, 1, 0.0) == pytest.approx(p["timeout"], rel=1e-6)
    assert _outcome(0, 0, 1, 0.5) == pytest.approx(p["burned"], rel=1e-6)  # burnout or burned down alone
    assert _outcome(0, 0, 0, 0.5) == 0.0


def test_newest_terms_add_distance_and_spread():
    p = PLANNER_PRESETS["optuna_top10"]
    make_env()
    got = _step_terms(1.0, 2, 3, 0.5, 4.0)
    want = p["ground"] + 2 * p["same"] + 3 * p["extinguish"] + 0.1 * 0.5 + 0.05 * 4.0
    assert got == pytest.approx(want, rel=1e-5)


@pytest.mark.slow
def test_evaluation_candidates_are_the_fires_some_drone_has_seen():
    env = make_env(evaluation=True)
    for _ in range(3):
        known = env.maps.known_fires.to_numpy()
        assert env.candidate_counts.tolist() == (known + 1).tolist()
        fire_map = env.maps.fire_map.to_numpy()
        for e in range(2):
            n, cand = candidates(env, e)
            cells = np.floor(cand[1:]).astype(int)
            assert np.all(fire_map[e, cells[:, 0], cells[:, 1]] == 1)
        env.step(torch.zeros(2, 4, dtype=torch.long))
    burning = env.fire.stats()["burning"]
    assert np.all(env.maps.known_fires.to_numpy() <= burning + 50)  # stale entries are possible, not a flood


def test_training_candidates_are_all_burning_cells_in_row_major_order():
    env = make_env()
    n, cand = candidates(env, 1)
    assert n - 1 == env.fire.stats()["burning"][1]
    cells = np.floor(cand[1:]).astype(int)
    flat = cells[:, 0] * env.fire.cols + cells[:, 1]
    assert np.all(np.diff(flat) > 0)


@pytest.mark.slow
def test_greedy_and_planner_evaluations_see_identical_fire_layouts():
    planner = make_env(evaluation=True, seed=11)
    greedy = make_env(evaluation=True, controller="greedy", seed=11)
    for _ in range(2):  # the first episodes, then the next ones (reset again without a seed)
        for e in range(2):
            np.testing.assert_array_equal(planner.fire.state(e), greedy.fire.state(e))
        np.testing.assert_array_equal(planner.drones.bases.to_numpy()[:, 0], greedy.drones.bases.to_numpy()[:, 0])
        np.testing.assert_array_equal(planner.fire.wind_vectors(), greedy.fire.wind_vectors())
        planner.reset()
        greedy.reset()


def test_greedy_heuristic_sends_drones_to_known_fires_without_sharing_one():
    env = make_env(evaluation=True, controller="greedy", seed=5)
    for _ in range(40):
        env.step(torch.zeros(2, 4, dtype=torch.long))
    cells = env.drones.goal_cell.to_numpy()
    fire_map = env.maps.fire_map.to_numpy()
    for e in range(2):
        held = cells[e][cells[e] >= 0]
        assert len(set(held.tolist())) == len(held)  # one drone per fire
        for c in held:
            assert fire_map[e, c // env.fire.cols, c % env.fire.cols] == 1  # a known fire
        if env.maps.known_fires.to_numpy()[e] >= 4:
            assert len(held) == 4  # nobody waits at the groundstation while free fires are known


@pytest.mark.slow
@pytest.mark.parametrize("home", ["original", "fixed"])
def test_greedy_fire_on_the_groundstation_cell_is_put_out_only_with_the_fix(home):
    # docs/model/agents.md §10.2: the fire's centre equals the groundstation's, so the original's "wait at the
    # groundstation" branch re-takes that fire every step and the drop is never reached; the fix lets the drone drop.
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.0), drones=DroneConfig(num_drones=4),
                 wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, greedy_home=home)
    env = PlannerVectorEnv(2, cfg, pc, evaluation=True, controller="greedy", seed=3)
    env.reset(seed=3)
    gs = env.drones.bases.to_numpy()[:, 0]
    cells = gs[:, 0] * env.fire.cols + gs[:, 1]
    mask = np.zeros((2, env.fire.num_cells), np.int32)
    mask[[0, 1], cells] = 1
    env.fire.ignite_cells(mask)
    for _ in range(80):
        env.step(torch.zeros(2, 4, dtype=torch.long))
    burning = [env.fire.state(e)[tuple(gs[e])] == BURNING for e in range(2)]
    assert burning == ([True, True] if home == "original" else [False, False])
    env.close()


@pytest.mark.slow
def test_a_planner_step_counts_interval_physics_steps():
    env = make_env(interval=4)
    assert env.physics_steps_per_step == 4 and env.max_env_steps == -(-env.t_max // 4)


@pytest.mark.slow
def test_the_planner_env_takes_its_section_from_the_config_unless_given_one():
    pc = PlannerConfig(interval=3, fly_model=MODEL, explorer_model=MODEL, num_explorers=1)
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=2), planner=pc)
    env = PlannerVectorEnv(1, cfg, controller="greedy")
    assert env.planner_config is pc and env.physics_steps_per_step == 3
    env.close()


@pytest.mark.slow
def test_frozen_fliers_encode_only_the_newest_frame_and_fly_as_with_whole_stacks():
    """The env's frame caches (the frozen collision FlyAgent's 3-frame stacks, the explorers' too) give the drones
    bit for bit the actions of encoding every stack at every low-level step, through episode ends and restarts."""
    collision = str(Path(MODEL).parent / "fly_collision")
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.02), drones=DroneConfig(num_drones=3))
    pc = PlannerConfig(fly_model=collision, explorer_model=MODEL, num_explorers=2)
    env = PlannerVectorEnv(2, cfg, pc, evaluation=True, controller="greedy", seed=5)
    actions = torch.zeros((2, 3), dtype=torch.long)

    def play(decisions: int) -> tuple[list, torch.Tensor]:
        env.reset(seed=5)
        stacks, ended = [], torch.zeros(2, dtype=torch.long)
        for _ in range(decisions):
            _, _, terminated, truncated, _ = env.step(actions)
            stacks.append((env._fly_buf.clone(), env._explore_buf.clone()))
            ended += terminated | truncated
        return stacks, ended

    cached, ended = play(150)
    assert env._fly_cache.za is not None and env._fly_cache.za.shape[1] == 3  # the cache was used
    assert bool((ended >= 1).all()), f"episodes ended per env: {ended.tolist()}: the restarts were not exercised"
    env._fly_cache = env._explore_cache = None  # every stack encoded whole, as before the caches
    whole, _ = play(150)
    for step, (a, b) in enumerate(zip(cached, whole, strict=True)):
        assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1]), f"decision {step}"
    env.close()
