"""Evaluation frames show exactly one episode of env 0: frame 0 is the state right after the reset and the last
frame the episode's final state, not the next episode that the same-step autoreset has already started."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from roshan.config import Config, DroneConfig, IgnitionConfig, MapConfig, PlannerConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.runs.baselines import baseline_fn, planner_random_fn
from roshan.runs.evaluate import run_episodes

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
CFG = Config(map=MapConfig(name="15x15_Woods"), ignition=IgnitionConfig(fire_percentage=0.05),
             drones=DroneConfig(num_drones=2))
SEED = 4


def make_fly(render_mode="rgb_array"):
    return FlyVectorEnv(num_envs=2, config=CFG, seed=SEED, render_mode=render_mode)


def make_greedy():
    pc = PlannerConfig(fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    return PlannerVectorEnv(2, CFG, pc, evaluation=True, controller="greedy", seed=SEED, render_mode="rgb_array")


def make_planner():
    pc = PlannerConfig(fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    return PlannerVectorEnv(2, CFG, pc, evaluation=True, controller="planner", seed=SEED, render_mode="rgb_array")


def greedy_fly(obs):
    return baseline_fn("greedy", 2, 2, SEED)(obs)


def greedy_planner(obs):
    return np.zeros((2, 2), np.int64)  # the heuristic ignores the actions


def evaluate_with_frames(make, act, tmp_path):
    """Run the evaluation loop with frames; returns the frames, env 0's first-episode actions and its record."""
    env = make()
    actions, record = [], {}

    def on_step(obs, a, rewards, terms, truncs, info):
        if not record:
            actions.append(a.clone() if hasattr(a, "clone") else np.array(a))
            if bool(info["_episode_stats"][0]):
                record.update({k: float(v[0]) for k, v in info["episode_stats"].items()})

    run_episodes(env, act, 2, SEED, frames_dir=tmp_path, on_step=on_step)
    env.close()
    frames = [np.asarray(Image.open(p).convert("RGB")) for p in sorted(tmp_path.glob("frame_*.png"))]
    return frames, actions, record


def replay(make, actions):
    """The same seed and actions in a fresh env: env 0's frame at the reset, its frame after the last step but
    before the autoreset (the level's step body alone), and its frame once the autoreset ran."""
    env = make()
    env.reset(seed=SEED)
    first = env.render()
    for a in actions[:-1]:
        env.step(a)
    env._advance(actions[-1])
    final = env.render()
    env.kernels.restart(*env._kernel_obs(), env.fire.seed_key, 1)
    next_first = env.render()
    env.close()
    return first, final, next_first


@pytest.mark.parametrize("make, act", [(make_fly, greedy_fly), (make_greedy, greedy_planner),
                                       (make_planner, planner_random_fn(SEED))], ids=["fly", "greedy", "planner"])
@pytest.mark.slow
def test_frames_run_from_the_reset_to_the_final_state_of_one_episode(make, act, tmp_path):
    frames, actions, record = evaluate_with_frames(make, act, tmp_path)
    first, final, next_first = replay(make, actions)
    assert len(frames) == len(actions) + 1  # the reset, then one frame per step of the episode
    np.testing.assert_array_equal(frames[0], first)
    np.testing.assert_array_equal(frames[-1], final)
    assert not np.array_equal(frames[-1], next_first)  # the next episode's fires, groundstation and wind
    if make is make_fly:
        assert len(frames) == record["steps"] + 1  # FlyAgent steps are physics steps (frame_skips = 1)


def test_no_render_mode_no_final_frame_and_no_frames(tmp_path):
    env = make_fly(render_mode=None)
    env.reset(seed=SEED)
    for _ in range(3):
        env.step(np.zeros((2, 2, 2), np.float32))
    assert env.final_frame is None
    with pytest.raises(ValueError, match="built without render_mode='rgb_array'"):
        run_episodes(env, greedy_fly, 2, SEED, frames_dir=tmp_path)
    assert not list(tmp_path.iterdir())  # refused before the first frame
    env.close()
