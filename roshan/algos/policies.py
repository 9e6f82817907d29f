"""The two policies PPO trains: what differs between the FlyAgent level and the planner level is the network,
its action distribution and how a batch of observations is prepared; the PPO update around them is one
(:class:`roshan.algos.ppo.PPO`).

A policy has ``net`` (the ``nn.Module`` whose parameters PPO optimises), ``shares_encoder`` and:

- ``critic_parameters()``: the value-only parameters (PPO clips the actor and critic groups separately);
- ``sample(obs, generator, cache)``: a :class:`Sample` (env action, what the rollout stores, log-prob, value);
- ``act_deterministic(obs, cache)``, ``value(obs)``, ``evaluate(obs, stored)``: a :class:`Scored` (log-prob,
  entropy, value, and the policy's own loss term beside PPO's);
- ``before_update(updates)`` (the manual log-std schedules), ``update_metrics()`` and ``new_cache()``;
- ``novelty_dim`` and ``novelty_features(obs)``: the flat vector RND reads (docs/model/learning.md §15).
"""

import math
from typing import NamedTuple

import torch
from torch import nn
from torch.nn import functional as F

from roshan.algos.distributions import ClippedGaussian, TanhNormal
from roshan.algos.frames import FrameCache, NoCache, gather_stacks
from roshan.algos.networks import ActorCritic
from roshan.algos.planner_nets import PLANNER_NETS, fleet_features, fleet_features_dim, trim_candidates
from roshan.config import PlannerConfig, PPOConfig

AGENT_FEATURES = 9  # per frame of a FlyAgent's own observation (roshan.algos.networks)


class Sample(NamedTuple):
    """One stochastic step of a policy for a batch of rows."""

    action: torch.Tensor  # what the env receives
    stored: torch.Tensor  # what the rollout keeps for the update (TanhNormal: the pre-tanh sample)
    log_prob: torch.Tensor  # (B,)
    value: torch.Tensor  # (B,)


class Scored(NamedTuple):
    """A policy's view of stored actions, with gradients: what the PPO loss needs."""

    log_prob: torch.Tensor  # (B,)
    entropy: torch.Tensor  # (B,)
    value: torch.Tensor  # (B,)
    penalty: torch.Tensor | float  # a loss term of the policy's own, added to PPO's (0.0 when it has none)


SATURATED = 2.185  # atanh(0.975): a pre-tanh mean beyond it gives the action +-1 after the 41-level rounding


class FlyPolicy:
    """The FlyAgent actor-critic (:class:`ActorCritic`) with its ClippedGaussian or TanhNormal distribution,
    the frame cache for acting and the manual log-std schedules of docs/model/learning.md §4."""

    def __init__(self, cfg: PPOConfig, collision: bool, frames: int = 3):
        self.cfg = cfg
        self.net = ActorCritic(collision, frames, share_encoder=cfg.share_encoder, tanh_mean=not cfg.use_tanh_dist)
        self.net.log_std.requires_grad_(cfg.log_std == "learned")
        self.shares_encoder = cfg.share_encoder
        self.dist_class = TanhNormal if cfg.use_tanh_dist else ClippedGaussian
        self.squashed_entropy = cfg.use_tanh_dist and cfg.tanh_entropy == "squashed"
        self._saturated: list[float] = []
        self.bounds_mean = cfg.use_tanh_dist and cfg.mean_bound > 0.0
        self._excess_log: list[float] = []
        self.novelty_dim = frames * AGENT_FEATURES

    @staticmethod
    def novelty_features(obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """The drone's own stacked features ``agent`` (B, F, 9) flattened (docs/model/learning.md §15)."""
        return obs["agent"].flatten(1)

    def critic_parameters(self) -> list[nn.Parameter]:
        critic = list(self.net.value.parameters())
        if self.net.critic_encoder is not None:
            critic += list(self.net.critic_encoder.parameters())
        return critic

    def new_cache(self) -> FrameCache:
        return FrameCache()

    def _heads(self, obs: dict[str, torch.Tensor], cache: FrameCache | None):
        return self.net(obs) if cache is None else self.net.from_frames(*cache.encode(self.net, obs))

    def sample(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None,
               cache: FrameCache | None = None) -> Sample:
        """Actions (B, 2) for a batch of drone observations; with a :class:`FrameCache` only the newest frame
        is encoded."""
        mean, std, value = self._heads(obs, cache)
        dist = self.dist_class(mean, std)
        raw = dist.sample_raw(generator)
        return Sample(dist.to_action(raw), raw, dist.log_prob_raw(raw), value)

    def act_deterministic(self, obs: dict[str, torch.Tensor], cache: FrameCache | None = None) -> torch.Tensor:
        """The distribution's mode (B, 2) without log-probs or values (at a batch of a few drones the
        distribution's bookkeeping is a third of the inference time)."""
        mean = self.net.actor(obs)[0] if cache is None else self._heads(obs, cache)[0]
        return self.dist_class.mode_of(mean)

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.net.critic(obs)

    def evaluate(self, obs: dict[str, torch.Tensor], stored: torch.Tensor) -> Scored:
        """Log-prob (B,), entropy (B,), value (B,) of stored actions, and the mean-bound penalty."""
        mean, std, value = self.net(obs)
        return self._score(mean, std, value, stored)

    def evaluate_columns(self, obs: dict[str, torch.Tensor], index: torch.Tensor, stored: torch.Tensor) -> Scored:
        """:meth:`evaluate` of drone columns obs [T, c, F, ...] (stored [T * c, 2]) from their distinct frames
        (:func:`roshan.algos.frames.stack_index` gives ``index``): the same outputs as encoding every stack."""
        mean, std, value = self.forward_columns(obs, index)
        return self._score(mean, std, value, stored)

    def forward_columns(self, obs: dict[str, torch.Tensor], index: torch.Tensor):
        """Mean, std and value [T * c] of drone columns obs [T, c, F, ...] from their distinct frames."""
        newest = {k: v[:, :, 0] for k, v in obs.items()}  # frame 0 of every step: (T, c, ...)
        older = {k: v[0, :, 1:].flip(1) for k, v in obs.items()}  # frames F-1..1 of the first step: (c, F-1, ...)
        za_new, zc_new = self.net.encode_frames(newest)
        za_old, zc_old = self.net.encode_frames(older)
        za = gather_stacks(torch.cat([za_old.transpose(0, 1), za_new]), index)
        zc = None if zc_new is None else gather_stacks(torch.cat([zc_old.transpose(0, 1), zc_new]), index)
        mean, std, value = self.net.from_frames(za, zc)
        return mean.flatten(0, 1), std, value.flatten(0, 1)

    def _score(self, mean, std, value, stored) -> Scored:
        dist = self.dist_class(mean, std)
        if self.dist_class is TanhNormal:  # the share of pre-tanh means in tanh's flat tails, for the logs
            self._saturated.append(float((mean.detach().abs() > SATURATED).float().mean()))
        entropy = dist.squashed_entropy() if self.squashed_entropy else dist.entropy()
        return Scored(dist.log_prob_raw(stored), entropy, value, self._mean_bound_penalty(mean))

    def _mean_bound_penalty(self, mean: torch.Tensor) -> torch.Tensor | float:
        """0.0 unless ``ppo.mean_bound``: the mean squared excess of the pre-tanh means over the bound, times
        ``ppo.mean_bound_coef``. Beyond |mu| ~ 2.2 every sample is the same full-speed action, so the surrogate has
        no gradient there and nothing else stops a mean that neighbouring states push outwards (the collision
        FlyAgent's drift, BENCHMARKS)."""
        if not self.bounds_mean:
            return 0.0
        excess = F.relu(mean.abs() - self.cfg.mean_bound).pow(2).sum(-1).mean()
        self._excess_log.append(float(excess.detach()))
        return self.cfg.mean_bound_coef * excess

    def before_update(self, updates: int) -> None:
        """The manual schedules of docs/model/learning.md §4, applied before each update (k = finished updates); nothing
        for a learned log-std."""
        rho, k = self.cfg.decay_rate, updates
        with torch.no_grad():
            if self.cfg.log_std == "train_step_decay":
                self.net.log_std.fill_(-20.0 * (1.0 - (rho**k) ** 5))
            elif self.cfg.log_std == "log_step_decay":
                self.net.log_std.add_(math.log(rho))

    def update_metrics(self) -> dict[str, float]:
        out = {"std": float(self.net.log_std.detach().exp()[0])}
        if self._saturated:
            out["saturated"] = sum(self._saturated) / len(self._saturated)
            self._saturated.clear()
        if self._excess_log:
            out["mean_excess"] = sum(self._excess_log) / len(self._excess_log)
            self._excess_log.clear()
        return out


class PlannerPolicy:
    """A planner network (thesis or pointer, :mod:`roshan.algos.planner_nets`): one row per env, the joint
    candidate choice of its N drones as one action (B, N) long. Candidate lists are trimmed to the longest valid
    prefix of the batch before every forward pass (which changes no output)."""

    # both planner critics read the actor's encoder (thesis Table 5.8, docs/model/learning.md §3.2)
    shares_encoder = True

    def __init__(self, planner: PlannerConfig, num_drones: int, resources: bool = False, bases: int = 1):
        """``planner``: the section (network, temperature, distance_prior, distinct_goals); ``resources``: the
        drones' observation has its resource parts, which the network reads (:mod:`roshan.algos.planner_nets`);
        ``bases``: the candidate list starts with that many bases (``drones.bases``)."""
        # the pointer nets always decode distinct goals; the thesis net on request (planner.distinct_goals)
        distinct = {"distinct_goals": planner.distinct_goals} if planner.network == "thesis" else {}
        self.net = PLANNER_NETS[planner.network](num_drones, temperature=planner.temperature, resources=resources,
                                                 distance_prior=planner.distance_prior, bases=bases, **distinct)
        self.novelty_dim = fleet_features_dim(num_drones, resources)

    novelty_features = staticmethod(fleet_features)

    def critic_parameters(self) -> list[nn.Parameter]:
        return self.net.critic_parameters()

    def new_cache(self) -> NoCache:
        return NoCache()

    def sample(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None,
               cache: NoCache | None = None) -> Sample:
        """``generator`` must live on the net's device."""
        actions, log_prob, _, value = self.net.forward_act(trim_candidates(obs), False, generator)
        return Sample(actions, actions, log_prob, value)

    def act_deterministic(self, obs: dict[str, torch.Tensor], cache: NoCache | None = None) -> torch.Tensor:
        return self.net.forward_act(trim_candidates(obs), deterministic=True)[0]

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.net.value(trim_candidates(obs))

    def evaluate(self, obs: dict[str, torch.Tensor], stored: torch.Tensor) -> Scored:
        return Scored(*self.net.evaluate(trim_candidates(obs), stored), 0.0)

    def before_update(self, updates: int) -> None:
        pass

    def update_metrics(self) -> dict[str, float]:
        return {}
