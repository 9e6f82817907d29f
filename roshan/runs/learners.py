"""The learners a training run steps: one iteration each collects data and updates once.

- :class:`PPOLearner` (both levels): a rollout of ``ppo.horizon`` transitions, then one PPO update;
- :class:`TD3Learner`: a few env steps into a replay buffer, each followed by an update;
- :class:`IQLLearner`: one offline pass over a saved dataset per iteration, then (optionally) online steps.

Each ``iterate(generator)`` returns the env steps it took, its metrics and the rows of the episodes that ended.
"""

import collections

import numpy as np
import torch

from roshan.algos.buffers import ReplayBuffer
from roshan.algos.networks import flatten_drones
from roshan.algos.ppo import PPO
from roshan.config import Config, apply_overrides
from roshan.env.fly import FlyVectorEnv
from roshan.episode import EPISODE_FIELDS
from roshan.runs.collect import RolloutCollector, ended_rows, next_observation, rollout_steps
from roshan.runs.envs import make_env
from roshan.runs.levels import kit_of


class PPOLearner:
    """One iteration = a rollout of ``ppo.horizon`` transitions, then one PPO update. Steps count env steps
    (planner: decisions, each ``planner.interval`` low-level steps of every env)."""

    counts_env_steps = True  # train.total_steps is a budget of env steps (IQL's offline updates take none)

    def __init__(self, cfg: Config, env, agent: PPO):
        self.rows = kit_of(cfg).rows(cfg)
        self.steps = rollout_steps(cfg, self.rows)
        self.collector = RolloutCollector(env, agent, self.rows, self.steps)
        self.agent, self.env = agent, env

    def iterate(self, generator: torch.Generator) -> tuple[int, dict, np.ndarray]:
        rollout = self.collector.collect(generator)
        metrics = self.agent.update(rollout, generator)
        rows = ended_rows(self.collector.ended, self.collector.stats)
        return self.steps * self.env.num_envs, metrics, rows


class OffPolicyCollector:
    """Steps the env with an off-policy agent's exploring actions (``act``) into a replay buffer, one transition
    per drone; ``not_done`` is 0 only at a real terminal (a timeout bootstraps from ``final_obs``)."""

    def __init__(self, env: FlyVectorEnv, agent, buffer):
        self.env, self.agent, self.buffer = env, agent, buffer
        self.obs, _ = env.reset()

    def step(self, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        env, N = self.env, self.env.num_drones
        o = {k: v.clone() for k, v in flatten_drones(self.obs).items()}
        actions = self.agent.act(o, generator=generator)
        self.obs, rewards, terms, truncs, info = env.step(actions.view(env.num_envs, N, 2))
        ended = info["_episode_stats"]
        nxt = next_observation(self.obs, info, ended.repeat_interleave(N))
        self.buffer.add(o, actions, rewards.flatten(), (~terms).repeat_interleave(N).float(), nxt)
        stats = torch.stack([info["episode_stats"][k] for k in EPISODE_FIELDS], dim=-1)
        return rewards, ended, stats


class TD3Learner:
    """One iteration = ``env_steps_per_iteration`` env steps, each followed by one TD3 update call (k_epochs
    gradient iterations) once the buffer holds ``min_memory_size`` transitions (docs/model/learning.md §7)."""

    counts_env_steps = True
    env_steps_per_iteration = 64

    def __init__(self, cfg: Config, env: FlyVectorEnv, agent):

        obs, _ = env.reset()
        shapes = {k: tuple(v.shape[2:]) for k, v in obs.items()}
        self.buffer = ReplayBuffer(cfg.td3.memory_size, shapes, device=env.device)
        self.collector = OffPolicyCollector(env, agent, self.buffer)
        self.agent, self.env = agent, env

    def iterate(self, generator: torch.Generator) -> tuple[int, dict, np.ndarray]:
        metrics: dict[str, list[float]] = collections.defaultdict(list)
        rows, rewards = [], []
        for _ in range(self.env_steps_per_iteration):
            r, ended, stats = self.collector.step(generator)
            rewards.append(float(r.mean()))
            if bool(ended.any()):
                rows.append(stats[ended].cpu().numpy())
            if self.agent.is_ready(self.buffer):
                for k, v in self.agent.update(self.buffer, generator).items():
                    metrics[k].append(v)
        out = {k: float(np.mean(v)) for k, v in metrics.items()}
        out["rewards_raw"] = float(np.mean(rewards))
        out["buffer"] = float(len(self.buffer))
        rows_arr = np.concatenate(rows) if rows else np.zeros((0, len(EPISODE_FIELDS)), np.float32)
        return self.env_steps_per_iteration * self.env.num_envs, out, rows_arr


class IQLLearner:
    """Iterations 1..offline_updates: one pass each over the saved dataset (no env steps); then, if
    ``online_updates`` > 0, one iteration = ``policy_freq`` env steps with the IQL actor appended to the
    buffer, then one update of ``k_epochs`` minibatches (docs/model/learning.md §8)."""

    counts_env_steps = False  # its progress bar counts updates: the offline ones take no env step

    def __init__(self, cfg: Config, env: FlyVectorEnv, agent):

        if not cfg.train.buffer_path:
            raise ValueError("train.buffer_path: IQL learns from a saved replay buffer; record one with "
                             "`roshan eval RUN --save-buffer N FILE`")
        self.buffer = ReplayBuffer.load(cfg.train.buffer_path, device=env.device)
        if cfg.iql.online_updates > 0:  # room for the online transitions after the dataset
            extra = cfg.iql.online_updates * cfg.iql.policy_freq * env.num_envs * env.num_drones
            self.buffer = ReplayBuffer.load(cfg.train.buffer_path, device=env.device,
                                            capacity=len(self.buffer) + extra)
        self.cfg, self.agent, self.env = cfg, agent, env
        self.collector = None
        self.offline_done = 0

    def iterate(self, generator: torch.Generator) -> tuple[int, dict, np.ndarray]:
        empty = np.zeros((0, len(EPISODE_FIELDS)), np.float32)
        if self.offline_done < self.cfg.iql.offline_updates:
            self.offline_done += 1
            metrics = self.agent.offline_pass(self.buffer, generator)
            metrics["rewards_raw"] = float(self.buffer.rewards[:len(self.buffer)].mean())
            return 0, metrics, empty
        if self.collector is None:
            self.collector = OffPolicyCollector(self.env, self.agent, self.buffer)
        rows = []
        for _ in range(self.cfg.iql.policy_freq):
            _, ended, stats = self.collector.step(generator)
            if bool(ended.any()):
                rows.append(stats[ended].cpu().numpy())
        metrics = self.agent.update(self.buffer, generator)
        metrics["rewards_raw"] = float("nan")
        return self.cfg.iql.policy_freq * self.env.num_envs, metrics, np.concatenate(rows) if rows else empty


LEARNERS = {"ppo": PPOLearner, "td3": TD3Learner, "iql": IQLLearner, "planner": PPOLearner}


def make_learner(cfg: Config, env, agent):
    return LEARNERS[cfg.train.algo](cfg, env, agent)


def check_learnable(cfg: Config) -> None:
    """Raise ValueError where ``cfg`` could not start training (checked before anything is built)."""
    fleets = fleet_configs(cfg)
    if LEARNERS[cfg.train.algo] is PPOLearner:
        for each in fleets:
            rollout_steps(each, kit_of(each).rows(each))  # a rollout must split over the rows of all envs
    if len(cfg.planner.fleets) > 1 and cfg.rnd.enabled:
        raise ValueError(f"planner.fleet_sizes = {cfg.planner.fleet_sizes!r} with rnd.enabled: the novelty network "
                         "reads a fixed number of drones; train one fleet size, or turn RND off")


def fleet_configs(cfg: Config) -> list[Config]:
    """The settings a run trains on in turn, an update each: one per fleet of ``planner.fleet_sizes`` and base count
    of ``planner.base_counts`` (each fleet with each count, fleet by fleet), else the run's own."""
    if not (cfg.planner.fleets or cfg.planner.bases_in_turn):
        return [cfg]
    fleets = cfg.planner.fleets or (cfg.drones.num_drones,)
    counts = cfg.planner.bases_in_turn or (cfg.drones.bases,)
    return [apply_overrides(cfg, [f"drones.num_drones={n}", f"drones.bases={b}"],
                            where="planner.fleet_sizes / planner.base_counts") for n in fleets for b in counts]


def fleet_turns(cfg: Config, agent, seed: int) -> list[tuple]:
    """(env, learner) of each setting of :func:`fleet_configs`, the i-th env seeded ``seed + 104729 i``."""
    turns = []
    for i, each in enumerate(fleet_configs(cfg)):
        env = make_env(each, each.sim.envs, seed=seed + 104_729 * i)
        turns.append((env, make_learner(each, env, agent)))
    return turns
