"""PPO rollouts at either level: one collector and one learner; a small row adapter says how env observations
map to the rows of the policy's batch.

FlyAgent (:class:`DroneRows`): every drone is a row of the shared policy (B = envs x drones) and the env's done
flags repeat per drone. Planner (:class:`EnvRows`): one row per env (B = envs), whose action is the joint choice
of its drones.
"""

import numpy as np
import torch

from roshan.algos.networks import flatten_drones
from roshan.algos.ppo import PPO, Rollout
from roshan.config import Config
from roshan.episode import EPISODE_FIELDS


class DroneRows:
    """FlyAgent rows: drones flattened into the batch."""

    def __init__(self, num_drones: int):
        self.per_env = num_drones
        self.what = "sim.envs x drones.num_drones"

    def obs(self, obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        return flatten_drones(obs)

    def rewards(self, rewards: torch.Tensor) -> torch.Tensor:
        """Per-drone rewards (E, N) as rows (E * N,)."""
        return rewards.flatten()

    def flags(self, flags: torch.Tensor) -> torch.Tensor:
        """Per-env flags (E,) repeated for each drone row."""
        return flags.repeat_interleave(self.per_env)

    def env_actions(self, actions: torch.Tensor, num_envs: int) -> torch.Tensor:
        return actions.view(num_envs, self.per_env, *actions.shape[1:])


class EnvRows:
    """Planner rows: one per env; observations, rewards and flags are the env's own."""

    per_env = 1
    what = "sim.envs"

    @staticmethod
    def obs(obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        return obs

    @staticmethod
    def rewards(rewards: torch.Tensor) -> torch.Tensor:
        return rewards

    @staticmethod
    def flags(flags: torch.Tensor) -> torch.Tensor:
        return flags

    @staticmethod
    def env_actions(actions: torch.Tensor, num_envs: int) -> torch.Tensor:
        return actions


def rollout_steps(cfg: Config, rows: DroneRows | EnvRows) -> int:
    """Env steps per rollout: ``ppo.horizon`` transitions spread over the rows of all envs (``rows``: the level's
    adapter, ``kit_of(cfg).rows(cfg)``)."""
    per_step = cfg.sim.envs * rows.per_env
    steps = cfg.ppo.horizon // per_step
    if steps < 1 or steps * per_step != cfg.ppo.horizon:
        raise ValueError(f"ppo.horizon = {cfg.ppo.horizon} must be a positive multiple of {rows.what} = {per_step}")
    return steps


def ended_rows(ended: torch.Tensor, stats: torch.Tensor) -> np.ndarray:
    """Episode records [n, len(EPISODE_FIELDS)] of the (t, env) entries flagged in ``ended`` [T, E]."""
    return stats[ended].cpu().numpy()


class RolloutCollector:
    """Rollout storage [T, B, ...] allocated once (the stored actions at the first step, when their shape and
    dtype are known), filled by stepping the env with the current policy."""

    def __init__(self, env, agent: PPO, rows: DroneRows | EnvRows, steps: int):
        self.env, self.agent, self.rows, self.T = env, agent, rows, steps
        E = env.num_envs
        B = E * rows.per_env
        obs, _ = env.reset()
        self.obs = obs
        dev = env.device
        self.buf_obs = {k: torch.zeros((steps, *v.shape), device=dev) for k, v in rows.obs(obs).items()}
        z = lambda *s, dt=torch.float32: torch.zeros(s, dtype=dt, device=dev)  # noqa: E731
        self.actions: torch.Tensor | None = None
        self.log_probs, self.values, self.rewards, self.trunc_values = (z(steps, B) for _ in range(4))
        self.term, self.trunc = z(steps, B, dt=torch.bool), z(steps, B, dt=torch.bool)
        self.ended = z(steps, E, dt=torch.bool)
        self.stats = z(steps, E, len(EPISODE_FIELDS))
        self.cache = agent.new_cache()

    def reset(self, seed: int) -> None:
        self.obs, _ = self.env.reset(seed=seed)

    def collect(self, generator: torch.Generator | None = None) -> Rollout:
        env, agent, rows = self.env, self.agent, self.rows
        bootstrap = agent.cfg.bootstrap_truncated
        self.trunc_values.zero_()
        self.cache.clear()  # the parameters changed in the last update
        for t in range(self.T):
            o = rows.obs(self.obs)
            sample = agent.sample(o, generator, self.cache)  # the trainer's generator: no global RNG
            self._store(t, o, sample)
            self.obs, r, term, trunc, info = env.step(rows.env_actions(sample.action, env.num_envs))
            self.rewards[t] = rows.rewards(r)
            self.term[t], self.trunc[t] = rows.flags(term), rows.flags(trunc)
            ended = info["_episode_stats"]
            self.ended[t] = ended
            self.cache.restart(rows.flags(ended))
            if bool(ended.any()):
                self.stats[t] = torch.stack([info["episode_stats"][k] for k in EPISODE_FIELDS], dim=-1)
                if bootstrap and bool(trunc.any()):
                    self.trunc_values[t] = agent.value(rows.obs(info["final_obs"]))
        last = agent.value(rows.obs(self.obs))
        next_values = torch.cat([self.values[1:], last.unsqueeze(0)])
        next_values = torch.where(self.trunc, self.trunc_values, next_values)
        return Rollout(self.buf_obs, self.actions, self.log_probs, self.values, next_values, self.rewards,
                       self.term, self.trunc)

    def _store(self, t: int, obs: dict[str, torch.Tensor], sample) -> None:
        if self.actions is None:
            self.actions = torch.zeros((self.T, *sample.stored.shape), dtype=sample.stored.dtype,
                                       device=self.log_probs.device)
        for k, x in obs.items():
            self.buf_obs[k][t].copy_(x)
        self.actions[t], self.log_probs[t], self.values[t] = sample.stored, sample.log_prob, sample.value


def next_observation(obs: dict, info: dict, ended: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-drone next observations (E*N, ...): the env's ``final_obs`` where the episode ended this step."""
    out = {}
    for (k, v), f in zip(flatten_drones(obs).items(), flatten_drones(info["final_obs"]).values(), strict=True):
        out[k] = torch.where(ended.view(-1, *[1] * (v.dim() - 1)), f, v)
    return out
