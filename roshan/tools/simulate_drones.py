"""``roshan simulate --drones N``: every env a FlyAgent episode (:class:`~roshan.env.fly.FlyVectorEnv`, complex
policy: drones extinguish the nearest unreserved fire) flown by a scripted policy of :mod:`roshan.env.heuristics`;
one env step is one fire update, and envs whose episode ends restart at once (same-step autoreset). Records add,
per env, :data:`roshan.tools.simulate.DRONE_SERIES_KEYS`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from roshan.config import Config, ConfigError, FlyConfig, replace, to_dict
from roshan.env.fly import FlyVectorEnv
from roshan.env.heuristics import POLICIES, policy_actions
from roshan.runtime import init_taichi
from roshan.tools.simulate import (
    SERIES_KEYS,
    SimulationResult,
    check_steps,
    finish_frames,
    frame_name,
    frames_dir_or_scratch,
    progress_bar,
    timing,
)


class _EpisodeTally:
    """Per-env running totals of finished episodes, successes and extinguished cells, kept as torch tensors so
    the step loop never waits on a host copy."""

    def __init__(self, env):
        self.env = env
        self.episodes, self.successes, self.extinguished = (
            torch.zeros(env.num_envs, dtype=torch.int64, device=env.device) for _ in range(3))

    def add(self, info: dict) -> None:
        # info's tensors are overwritten by the next step, so they are folded in right away.
        ended = info["_episode_stats"]
        ep = info["episode_stats"]
        self.episodes += ended
        self.successes += ended & (ep["success"] > 0.5)
        self.extinguished += ended * ep["extinguished"].round().long()

    def record(self, done: int) -> dict:
        """A series record after ``done`` steps: the fire's SERIES_KEYS plus DRONE_SERIES_KEYS, per env."""
        fire = self.env.fire
        stats = fire.stats()
        rec = {"step": done, "time_s": round(done * fire.dt, 6)}
        rec.update({k: stats[k].tolist() for k in SERIES_KEYS})
        current = stats["extinguished"]
        rec.update(episodes=self.episodes.tolist(), successes=self.successes.tolist(), extinguished=current.tolist(),
                   extinguished_total=(self.extinguished.cpu().numpy() + current).tolist(),
                   episode_step=fire.steps_since_reset().tolist())
        return rec


def run_drone_simulation(cfg: Config, steps: int, drones: int, policy: str = "greedy", every: int = 100,
                         frames_dir: Path | None = None, gif: Path | None = None,
                         progress: bool = True) -> SimulationResult:
    """``run_simulation`` with ``drones`` drones per env, each env a FlyVectorEnv episode (complex policy).

    ``policy``: ``"greedy"`` (the greedy baseline: the complex policy's nearest-unreserved-fire goals flown by
    :func:`~roshan.env.heuristics.straight_to_goal`) or ``"random"`` (uniform actions, seeded by
    ``cfg.sim.seed``). Records add, per env, :data:`DRONE_SERIES_KEYS`; ``step`` counts the run's steps
    (every env has made that many, across episodes). Frames show env 0 with its drones; its episode number
    is in the file name, since env 0 carries on into a new episode whenever one ends.
    """
    check_steps(steps, every)
    if isinstance(drones, bool) or not isinstance(drones, int | np.integer) or drones < 1:
        raise ValueError(f"--drones: expected a positive number of drones per env, got {drones!r} "
                         "(leave --drones out to simulate the fire alone)")
    if policy not in POLICIES:
        raise ValueError(f"--policy: expected one of {', '.join(POLICIES)}, got {policy!r}")
    try:
        cfg = replace(cfg, drones={**to_dict(cfg.drones), "num_drones": int(drones)})
    except ConfigError as exc:
        raise ConfigError(f"--drones: {exc}") from exc
    init_taichi(cfg.sim.arch, cfg.sim.threads or None)
    env, fly = _build_fly_env(cfg)
    rendering, scratch = frames_dir is not None or gif is not None, None
    if rendering:  # env 0's frames as every env renders them: caption above the map, legend below
        frames_dir, scratch = frames_dir_or_scratch(frames_dir)
        env.caption_name = f"{drones} {policy} drone{'s' * (drones != 1)} (scripted)"
    result = SimulationResult()
    tally = _EpisodeTally(env)
    t0 = time.perf_counter()
    obs, _ = env.reset()
    result.series.append(tally.record(0))
    t_reset = time.perf_counter() - t0

    def save_frame(rec: dict) -> None:
        if rendering:
            name = frame_name(rec["step"], rec["time_s"], episode=rec["episodes"][0] + 1)
            result.frames.append(save_png(env.render(), frames_dir / name))

    save_frame(result.series[0])
    step_seconds = 0.0
    bar = progress_bar(steps, progress)
    generator = _generator(cfg.sim.seed, env.device)
    done = 0
    while done < steps:
        n = min(every, steps - done)
        t1 = time.perf_counter()
        obs = _fly(env, obs, n, policy, generator, tally)
        rec = tally.record(done + n)  # host copies wait for the kernels, so the timing is honest
        step_seconds += time.perf_counter() - t1
        done += n
        result.series.append(rec)
        save_frame(rec)
        if bar is not None:
            bar.update(n)
            bar.set_postfix({"burning/env": f"{np.mean(rec['burning']):.1f}", "episodes": int(np.sum(rec["episodes"]))})
    if bar is not None:
        bar.close()
    env.close()
    finish_frames(rendering, result, gif, scratch, progress)
    result.timing = timing(steps, cfg.sim.envs, t_reset, step_seconds, env.fire.memory_bytes_per_env(), t0)
    result.drones = _drone_summary(result.series[-1], int(drones), policy, fly, env.t_max)
    return result


def save_png(frame: np.ndarray, path: Path) -> Path:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(frame).save(path)
    return path


def _build_fly_env(cfg: Config):
    fly = FlyConfig(policy="complex")
    return FlyVectorEnv(num_envs=cfg.sim.envs, config=cfg, fly=fly, seed=cfg.sim.seed), fly


def _fly(env, obs: dict, n: int, policy: str, generator, tally: _EpisodeTally) -> dict:
    """Advance every env ``n`` steps under ``policy``, counting the episodes that end."""
    for _ in range(n):
        obs, _, _, _, info = env.step(policy_actions(policy, env, obs, generator))
        tally.add(info)
    return obs


def _generator(seed: int, device):
    return torch.Generator(device=device).manual_seed(int(seed))


def _drone_summary(last: dict, drones: int, policy: str, fly, t_max: int) -> dict:
    episodes, successes = int(np.sum(last["episodes"])), int(np.sum(last["successes"]))
    return {"drones": drones, "policy": policy, "fly_policy": fly.policy, "t_max": t_max, "episodes": episodes,
            "successes": successes, "success_rate": successes / episodes if episodes else None,
            "extinguished": int(np.sum(last["extinguished_total"]))}
