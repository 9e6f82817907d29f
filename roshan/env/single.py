"""One FlyAgent environment behind the plain Gymnasium ``Env`` API (numpy in, numpy out).

:class:`FlyEnv` wraps a :class:`~roshan.env.fly.FlyVectorEnv` with ``num_envs=1`` and is what
``gymnasium.make("roshan.env:roshan/FlyAgent-v0")`` returns. It exists for tools that expect one ``gymnasium.Env``
(``check_env``, SB3-style wrappers, notebooks); training uses the vector env directly, which is much faster.

The vector env resets an env in the same ``step`` call that ends its episode; this wrapper hides that: a step
that ends the episode returns the terminal observation, and the next ``reset()`` hands out the episode the
vector env has already started (so the episode sequence of a seeded ``FlyEnv`` is env 0's sequence in a
``FlyVectorEnv`` with the same seed).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from roshan.config import Config, FlyConfig
from roshan.config import replace as replace_validated
from roshan.env.fly import FlyVectorEnv
from roshan.episode import REASONS

# Not "episode": gymnasium's RecordEpisodeStatistics (and SB3's Monitor) write info["episode_stats"] themselves and
# refuse an env that already fills it.
EPISODE_KEY = "episode_record"


def build_configs(config: Config | None = None, fly: FlyConfig | None = None, *, map_name: str | None = None,
                  num_drones: int | None = None, policy: str | None = None,
                  collision: bool | None = None) -> tuple[Config, FlyConfig]:
    """The (Config, FlyConfig) pair of ``config``/``fly`` (defaults when None) with the shortcuts applied.

    Shortcuts are validated like YAML keys (a bad value raises :class:`roshan.config.ConfigError`).
    """
    cfg = config if config is not None else Config()
    task = fly if fly is not None else FlyConfig()
    if map_name is not None:
        cfg = dataclasses.replace(cfg, map=replace_validated(cfg.map, name=map_name))
    if num_drones is not None:
        cfg = dataclasses.replace(cfg, drones=replace_validated(cfg.drones, num_drones=num_drones))
    changes = {k: v for k, v in (("policy", policy), ("collision", collision)) if v is not None}
    if changes:
        task = replace_validated(task, **changes)
    return cfg, task


def episode_record(episode: dict, index: int = 0) -> dict[str, Any]:
    """Env ``index``'s row of the vector env's ``info["episode_stats"]`` as plain Python values (reason as a name)."""
    row = {k: float(v[index]) for k, v in episode.items()}
    row["reason"] = REASONS[int(row["reason"])]
    row["steps"] = int(row["steps"])
    return row


class _FlyCore:
    """A FlyVectorEnv with one env plus the episode bookkeeping both single-env front ends need.

    Observations come back as numpy copies of env 0 because the vector env overwrites its tensors in place.
    """

    def __init__(self, config: Config | None, fly: FlyConfig | None, render_mode: str | None,
                 render_modes: list[str], **shortcuts):
        """``render_modes``: the front end's; ``shortcuts``: :func:`build_configs`' keywords."""
        _check_render_mode(render_mode, render_modes)
        cfg, task = build_configs(config, fly, **shortcuts)
        # With rendering on, the vector env keeps the frame of an episode's final state, which render() shows
        # until the next reset (the vector env has already started the next episode by then).
        self.vec = FlyVectorEnv(num_envs=1, config=cfg, fly=task, render_mode=render_mode)
        self.num_drones = self.vec.num_drones
        self._obs: dict | None = None  # the vector env's live observation views (None before the first reset)
        self.ended = False  # the last step ended the episode; the vector env has already started the next one

    @staticmethod
    def numpy_obs(views: dict) -> dict[str, np.ndarray]:
        return {k: np.array(v[0].detach().cpu().numpy(), dtype=np.float32, copy=True) for k, v in views.items()}

    def reset(self, seed: int | None, options: dict | None) -> dict[str, np.ndarray]:
        if self.ended and seed is None and options is None:
            # The vector env reset this env when the episode ended; resetting again would skip an episode.
            self.ended = False
            return self.numpy_obs(self._obs)
        self._obs, _ = self.vec.reset(seed=seed, options=options)
        self.ended = False
        return self.numpy_obs(self._obs)

    def step(self, action, shape: tuple[int, ...]):
        """One step; returns (obs, per-drone rewards, terminated, truncated, episode record or None)."""
        if self._obs is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        if self.ended:
            gym.logger.warn("step() called after the episode ended without reset(): continuing in the episode "
                            "the environment started automatically (its first observation was never returned)")
        a = np.asarray(action, dtype=np.float32)
        if a.shape != shape:
            raise ValueError(f"action: expected shape {shape}, got {a.shape}")
        obs, rewards, term, trunc, info = self.vec.step(a[None])
        self.ended = bool(info["_episode_stats"][0])
        # On an episode end ``obs`` already holds the next episode's start; the caller gets the terminal frame.
        out = self.numpy_obs(info["final_obs"] if self.ended else obs)
        record = episode_record(info["episode_stats"]) if self.ended else None
        return out, rewards[0].detach().cpu().numpy().copy(), bool(term[0]), bool(trunc[0]), record

    def render(self, render_mode: str | None):
        if render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' at construction")
            return None
        if self.ended and self.vec.final_frame is not None:
            return self.vec.final_frame
        return self.vec.render()


def _check_render_mode(render_mode: str | None, modes: list[str]) -> None:
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode: expected None or one of {modes}, got {render_mode!r}")


class FlyEnv(gym.Env):
    """One FlyAgent environment (N drones sharing a policy) with numpy observations and actions.

    Observation: a dict of float32 arrays, ``agent`` (N, T, 9), ``neighbors`` (N, T, N, 4) and
    ``neighbors_mask`` (N, T, N) (T stacked frames, index 0 newest); action: (N, 2) in [-1, 1].

    The reward is the mean of the drones' rewards (a float); the per-drone rewards are in ``info["rewards"]``
    (numpy (N,)). A step that ends the episode returns the terminal observation, and its info holds
    ``info["episode_record"]``: success (1.0/0.0), reason (a name from :data:`roshan.episode.REASONS`),
    steps (int), burned_fraction, extinguished and return (the mean-over-drones return). A timeout
    truncates; every other end terminates.

    Call ``reset()`` after an episode ends. Stepping on instead warns and continues in the episode the
    environment started automatically. ``reset(seed=s)`` restarts every random stream, so the same seed gives
    the same episodes.

    Args:
        config: The simulation config (map, fire, drones...); ``Config()`` when None.
        fly: The FlyAgent task config; ``FlyConfig()`` when None.
        render_mode: None or ``"rgb_array"`` (``render()`` returns an (H, W, 3) uint8 frame of the fire).
        map_name: Shortcut for ``config.map.name``.
        num_drones: Shortcut for ``config.drones.num_drones``.
        policy: Shortcut for ``fly.policy`` (``"simple"`` or ``"complex"``).
        collision: Shortcut for ``fly.collision``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: Config | None = None, fly: FlyConfig | None = None, render_mode: str | None = None,
                 *, map_name: str | None = None, num_drones: int | None = None, policy: str | None = None,
                 collision: bool | None = None):
        self._core = _FlyCore(config, fly, render_mode, self.metadata["render_modes"], map_name=map_name,
                              num_drones=num_drones, policy=policy, collision=collision)
        self.render_mode = render_mode
        # One step is one fire time step, so real time plays at 1 / dt steps per second.
        self.metadata = {**FlyEnv.metadata, "render_fps": max(1, round(1.0 / self._core.vec.config.fire.dt))}
        self.observation_space = self._core.vec.single_observation_space
        self.action_space = self._core.vec.single_action_space

    @property
    def vector_env(self) -> FlyVectorEnv:
        """The wrapped one-env :class:`FlyVectorEnv` (config, ``t_max``, simulators)."""
        return self._core.vec

    @property
    def num_drones(self) -> int:
        return self._core.num_drones

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``seed`` restarts every random stream (same seed, same episode)."""
        super().reset(seed=seed)
        return self._core.reset(seed, options), {}

    def step(self, action):
        """Advance one step; see the class docstring for the reward and the episode-end info."""
        obs, rewards, terminated, truncated, record = self._core.step(action, self.action_space.shape)
        info: dict[str, Any] = {"rewards": rewards}
        if record is not None:
            info[EPISODE_KEY] = record
        return obs, float(rewards.mean()), terminated, truncated, info

    def render(self):
        """An (H, W, 3) uint8 frame of the fire when ``render_mode="rgb_array"``, else None (with a warning)."""
        return self._core.render(self.render_mode)

    def close(self):
        self._core.vec.close()
