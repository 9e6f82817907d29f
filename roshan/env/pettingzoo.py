"""One FlyAgent environment as a PettingZoo ``ParallelEnv``: every drone is an agent.

For multi-agent libraries that speak PettingZoo. The drones act simultaneously and their episode ends together
(it ends when any drone is terminal, docs/model/agents.md §9), so every step either keeps all agents or removes all of
them.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from pettingzoo import ParallelEnv

from roshan.config import Config, FlyConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.single import EPISODE_KEY, _FlyCore


def _drop_first_axis(space: gym.spaces.Box) -> gym.spaces.Box:
    return gym.spaces.Box(space.low[0], space.high[0], space.shape[1:], space.dtype)


class FlyParallelEnv(ParallelEnv):
    """One FlyAgent environment whose drones are the PettingZoo agents ``drone_0`` .. ``drone_{N-1}``.

    Per agent: observation a dict of float32 arrays ``agent`` (T, 9), ``neighbors`` (T, N, 4) and
    ``neighbors_mask`` (T, N) (that drone's slice of :class:`~roshan.env.single.FlyEnv`'s observation); action
    (2,) in [-1, 1]; reward that drone's reward. Terminations/truncations are the environment's, the same for
    every agent (a timeout truncates). A step that ends the episode returns the terminal observations, puts the
    episode record (see :class:`~roshan.env.single.FlyEnv`) in every agent's ``info["episode_record"]`` and
    empties :attr:`agents`; call ``reset()`` to start the next episode.

    Args:
        config: The simulation config; ``Config()`` when None.
        fly: The FlyAgent task config; ``FlyConfig()`` when None.
        render_mode: None or ``"rgb_array"``.
        map_name: Shortcut for ``config.map.name``.
        num_drones: Shortcut for ``config.drones.num_drones``.
        policy: Shortcut for ``fly.policy``.
        collision: Shortcut for ``fly.collision``.
    """

    metadata = {"name": "roshan_fly_v0", "render_modes": ["rgb_array"]}

    def __init__(self, config: Config | None = None, fly: FlyConfig | None = None, render_mode: str | None = None,
                 *, map_name: str | None = None, num_drones: int | None = None, policy: str | None = None,
                 collision: bool | None = None):
        self._core = _FlyCore(config, fly, render_mode, self.metadata["render_modes"], map_name=map_name,
                              num_drones=num_drones, policy=policy, collision=collision)
        self.render_mode = render_mode
        self.possible_agents = [f"drone_{i}" for i in range(self._core.num_drones)]
        self.agents: list[str] = []
        single = self._core.vec.single_observation_space
        # One space object per agent, built once: PettingZoo requires the same object on every call (seeding).
        self.observation_spaces = {
            a: gym.spaces.Dict({k: _drop_first_axis(s) for k, s in single.spaces.items()})
            for a in self.possible_agents}
        self.action_spaces = {a: gym.spaces.Box(-1.0, 1.0, (2,), np.float32) for a in self.possible_agents}

    @property
    def vector_env(self) -> FlyVectorEnv:
        """The wrapped one-env :class:`FlyVectorEnv` (config, ``t_max``, simulators)."""
        return self._core.vec

    def observation_space(self, agent: str) -> gym.spaces.Dict:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> gym.spaces.Box:
        return self.action_spaces[agent]

    def _split(self, obs: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
        return {a: {k: v[i] for k, v in obs.items()} for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode with every drone alive; ``seed`` restarts every random stream."""
        obs = self._core.reset(seed, options)
        self.agents = list(self.possible_agents)
        return self._split(obs), {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]):
        """Advance every drone one step; ``actions`` must hold one (2,) action per live agent."""
        if not self.agents:
            # After the episode ended (or before reset): nothing is alive, so there is nothing to return.
            gym.logger.warn("step() called with no live agents; call reset() to start an episode")
            return {}, {}, {}, {}, {}
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions: missing an action for {missing} (every live drone must act)")
        joint = np.zeros((len(self.possible_agents), 2), dtype=np.float32)
        for i, a in enumerate(self.possible_agents):
            act = np.asarray(actions[a], dtype=np.float32)
            if act.shape != (2,):
                raise ValueError(f"actions[{a!r}]: expected shape (2,), got {act.shape}")
            joint[i] = act
        obs, rewards, terminated, truncated, record = self._core.step(joint, joint.shape)
        agents = self.agents  # all drones: they live and end together
        observations = self._split(obs)
        rew = {a: float(rewards[i]) for i, a in enumerate(self.possible_agents)}
        terms = dict.fromkeys(agents, terminated)
        truncs = dict.fromkeys(agents, truncated)
        infos: dict[str, dict] = {a: {} if record is None else {EPISODE_KEY: dict(record)} for a in agents}
        if record is not None:
            self.agents = []
        return observations, rew, terms, truncs, infos

    def render(self):
        """An (H, W, 3) uint8 frame of the fire when ``render_mode="rgb_array"``, else None (with a warning)."""
        return self._core.render(self.render_mode)

    def close(self):
        self._core.vec.close()
