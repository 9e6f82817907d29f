"""PPO as in the reference (docs/model/learning.md §6): clipped surrogate, GAE, reward scaling by a running std without
shift, per-minibatch advantage normalisation, KL early stop, gradient clipping per parameter group.

One class trains both levels; the policy is plugged in (:mod:`roshan.algos.policies`): the FlyAgent
actor-critic, whose rollout rows are drones (B = envs x drones; the done flags come from the env, one episode
per env, so an episode that ends because of one drone ends every drone's trace: the reference keeps per-drone
flags, docs/model/learning.md §6.2 step 5 calls that a quirk), or a planner network, whose rows are envs (B = envs).
"""

import copy
from collections.abc import Callable, Iterator
from functools import partial
from typing import NamedTuple

import torch
from torch import nn

from roshan.algos.frames import stack_index
from roshan.algos.normalize import RewardScaler
from roshan.algos.optim import make_optimizer, make_scheduler
from roshan.algos.policies import FlyPolicy, PlannerPolicy, Sample, Scored
from roshan.algos.returns import gae
from roshan.algos.rnd import RND
from roshan.config import PPOConfig, RNDConfig

Policy = FlyPolicy | PlannerPolicy


class Rollout(NamedTuple):
    """One update's data, [T, B, ...] with B rows per env step (FlyAgent: envs x drones; planner: envs).

    ``next_values`` holds V of the true next state: the next row's state, the env's ``final_obs`` where an
    episode was truncated, or the bootstrap state after the last row.
    """

    obs: dict[str, torch.Tensor]
    actions: torch.Tensor  # [T, B, ...] as the policy stores them (TanhNormal: the pre-tanh sample)
    log_probs: torch.Tensor  # [T, B]
    values: torch.Tensor  # [T, B]
    next_values: torch.Tensor  # [T, B]
    rewards: torch.Tensor  # [T, B] raw
    terminations: torch.Tensor  # [T, B] bool
    truncations: torch.Tensor  # [T, B] bool


class Minibatch(NamedTuple):
    """One minibatch: ``score()`` evaluates its stored actions under the current policy (with gradients)."""

    score: Callable[[], Scored]
    old_log_probs: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor


def approx_kl(old_logp: torch.Tensor, new_logp: torch.Tensor, estimator: str) -> torch.Tensor:
    """KL(old || new) estimated from samples of the old policy (Schulman, "Approximating KL divergence", 2020):
    k1 = mean(old - new) (unbiased, high variance), k2 = mean((r - 1) - log r) with r = new / old (always >= 0)."""
    log_ratio = new_logp - old_logp
    if estimator == "k1":
        return (-log_ratio).mean()
    return ((log_ratio.exp() - 1.0) - log_ratio).mean()


def clipped_surrogate(ratio: torch.Tensor, advantages: torch.Tensor, eps: float) -> torch.Tensor:
    """L_clip = -mean(min(r A, clip(r, 1 - eps, 1 + eps) A)) (Schulman et al. 2017, eq. 7)."""
    return -torch.min(ratio * advantages, ratio.clamp(1.0 - eps, 1.0 + eps) * advantages).mean()


def normalized_advantages(adv: torch.Tensor) -> torch.Tensor:
    """Per-minibatch advantage normalisation (zero for a single sample, whose std is undefined)."""
    return (adv - adv.mean()) / (adv.std(unbiased=False) + 1e-8) if adv.numel() > 1 else adv * 0.0


def policy_change(new_logp: torch.Tensor, old_logp: torch.Tensor, cfg) -> tuple[torch.Tensor, float, float]:
    """The probability ratios new / old (log-ratio clamped to +-10), the approx KL(old || new) that the early stop
    reads, and the share of ratios outside the clip range."""
    ratio = (new_logp - old_logp).clamp(-10.0, 10.0).exp()
    with torch.no_grad():
        kl = float(approx_kl(old_logp, new_logp, cfg.kl_estimator))
        return ratio, kl, float(((ratio - 1.0).abs() > cfg.eps_clip).float().mean())


def ppo_loss(cfg, ratio: torch.Tensor, scored: Scored, adv: torch.Tensor, ret: torch.Tensor
             ) -> tuple[torch.Tensor, dict[str, float]]:
    """The loss of one minibatch (docs/model/learning.md §6): clipped surrogate - entropy bonus + value loss, plus
    the policy's own term; and the terms' values for the logs."""
    actor_loss = clipped_surrogate(ratio, adv, cfg.eps_clip)
    entropy = scored.entropy.mean()
    value_loss = (scored.value - ret).pow(2).mean()
    loss = actor_loss - cfg.entropy_coeff * entropy + cfg.value_loss_coef * value_loss + scored.penalty
    return loss, {"actor_loss": float(actor_loss.detach()), "value_loss": float(value_loss.detach()),
                  "entropy": float(entropy.detach())}


def clip_gradients(groups: dict, max_norm: float) -> dict[str, torch.Tensor]:
    """Gradient-norm clipping per parameter group (actor, critic), as the reference does; returns each group's
    norm before clipping (also with clipping off, so the logs show what a bound would cut)."""
    norms = {}
    for name, params in groups.items():
        norms[name] = nn.utils.get_total_norm([p.grad for p in params if p.grad is not None])
        if max_norm > 0:
            nn.utils.clip_grads_with_norm_(params, max_norm, norms[name])
    return norms


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 - Var(R - V) / Var(R); NaN when the returns are constant."""
    var = returns.var()
    return float("nan") if float(var) == 0.0 else float(1.0 - (returns - values).var() / var)


class WeightAverage:
    """An exponential moving average of a policy's network, stepped once per update, and a copy of the policy
    that acts with it. The deterministic policy is what gets evaluated and shipped; in the collision setting its
    success moves by several points between neighbouring updates even at a small rate (BENCHMARKS, "E6"), and an
    average over the last ~1 / (1 - decay) updates is a point that no single minibatch step chose."""

    def __init__(self, policy: Policy, decay: float):
        self.decay = decay
        self.policy = copy.copy(policy)  # the same distribution and settings, acting through its own network
        self.policy.net = copy.deepcopy(policy.net).requires_grad_(False)

    @staticmethod
    def _floats(net: nn.Module) -> list[torch.Tensor]:
        return [t for t in net.state_dict().values() if t.is_floating_point()]

    @torch.no_grad()
    def update(self, net: nn.Module) -> None:
        torch._foreach_lerp_(self._floats(self.policy.net), self._floats(net), 1.0 - self.decay)

    def reset(self, net: nn.Module) -> None:
        self.policy.net.load_state_dict(net.state_dict())


class PPO:
    """A policy and its PPO update: optimisers, schedules, the reward scaler, GAE and the minibatch epochs."""

    weight_keys = ("net",)

    def __init__(self, cfg: PPOConfig, policy: Policy, device: str | torch.device = "cpu",
                 rnd: RNDConfig | None = None):
        if cfg.separate_optimizers and policy.shares_encoder:
            raise ValueError("ppo.separate_optimizers needs ppo.share_encoder = false (docs/model/learning.md §6.2)")
        self.cfg = cfg
        self.device = torch.device(device)
        self.policy = policy
        self.net = policy.net.to(self.device)
        critic_params = policy.critic_parameters()
        critic_ids = {id(p) for p in critic_params}
        # Lists, not generators: the thesis-era code clipped exhausted generators, i.e. never
        # (docs/model/learning.md §6.2).
        self.groups = {"actor": [p for p in self.net.parameters() if id(p) not in critic_ids and p.requires_grad],
                       "critic": critic_params}
        if cfg.separate_optimizers:
            self.optimizers = [make_optimizer(self.groups[g], cfg.lr, cfg.optim) for g in ("actor", "critic")]
        else:
            self.optimizers = [make_optimizer(self.groups["actor"] + self.groups["critic"], cfg.lr, cfg.optim)]
        self.schedulers = [make_scheduler(o, cfg.optim) for o in self.optimizers]
        self.scaler = RewardScaler(cfg.reward_eps)
        # built after the networks, so that with RND off the parameter initialisation draws stay as they were
        self.rnd = RND(policy.novelty_dim, rnd, self.device) if rnd is not None and rnd.enabled else None
        self.average = WeightAverage(policy, cfg.ema_decay) if cfg.ema_decay > 0 else None
        self.updates = 0
        self.gradient_steps = 0

    # ------------------------------------------------------------------------------------------ acting

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """Sampled actions for a batch of rows (FlyAgent: (B, 2); planner: (B, N) candidate indices)."""
        return self.policy.sample(obs, generator).action

    @torch.no_grad()
    def act_deterministic(self, obs: dict[str, torch.Tensor], cache=None) -> torch.Tensor:
        """The policy's deterministic actions (the distribution's mode; planner: per-drone argmax), with the
        averaged weights where ``ppo.ema_decay`` > 0; ``cache``: :meth:`new_cache`'s, for those weights only."""
        return (self.policy if self.average is None else self.average.policy).act_deterministic(obs, cache)

    @torch.no_grad()
    def sample(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None,
               cache=None) -> Sample:
        """What a rollout step needs: env actions, the stored actions, their log-probs and the values.
        ``cache`` is the policy's :meth:`new_cache` object, kept by the collector between steps."""
        return self.policy.sample(obs, generator, cache)

    def new_cache(self):
        """The acting cache a collector keeps between steps (FlyAgent: :class:`FrameCache`)."""
        return self.policy.new_cache()

    @torch.no_grad()
    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.policy.value(obs)

    def evaluate(self, obs: dict[str, torch.Tensor], actions: torch.Tensor):
        """Log-prob (B,), entropy (B,) and value (B,) of stored actions, with gradients."""
        return self.policy.evaluate(obs, actions)

    # ------------------------------------------------------------------------------------------ learning

    def advantages(self, rollout: Rollout, intrinsic: torch.Tensor | None = None
                   ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Scale rewards by the running std (updated with this horizon first), add the ``intrinsic`` rewards
        [T, B] (scaled already) if any, then GAE. Returns the rewards, advantages and returns, each [T, B]."""
        cfg = self.cfg
        self.scaler.update(rollout.rewards)
        rewards = self.scaler.scale(rollout.rewards)
        if intrinsic is not None:
            rewards = rewards + intrinsic
        truncations = rollout.truncations
        terminations = rollout.terminations
        if not cfg.bootstrap_truncated:
            terminations, truncations = terminations | truncations, torch.zeros_like(truncations)
        adv, ret = gae(rewards, rollout.values, rollout.next_values, terminations, truncations, cfg.gamma, cfg.lam)
        return rewards, adv, ret

    def update(self, rollout: Rollout, generator: torch.Generator | None = None) -> dict[str, float]:
        """One PPO update over the rollout: ``k_epochs`` shuffled passes in minibatches of ``batch_size``;
        ``generator`` (CPU) drives the shuffling."""
        cfg = self.cfg
        self.policy.before_update(self.updates)
        intrinsic = self._intrinsic(rollout, generator) if self.rnd is not None else {}
        rewards, adv, ret = self.advantages(rollout, intrinsic.pop("rewards", None))
        epoch = self._column_epoch if cfg.minibatch == "sequences" else self._sample_epoch
        stats: dict[str, list[float]] = {k: [] for k in ("actor_loss", "value_loss", "entropy", "approx_kl",
                                                          "clip_fraction", *(f"grad_norm_{g}" for g in self.groups))}
        self.net.train()
        for _ in range(cfg.k_epochs):
            for score, old_logp, mb_adv, mb_ret in epoch(rollout, adv, ret, generator):
                scored = score()
                ratio, kl, clip_fraction = policy_change(scored.log_prob, old_logp, cfg)
                stats["approx_kl"].append(kl)
                if cfg.kl_early_stop and kl >= cfg.kl_target:
                    break  # the rest of this epoch is skipped; the next epoch still starts
                loss, terms = ppo_loss(cfg, ratio, scored, normalized_advantages(mb_adv), mb_ret)
                norms = self._gradient_step(loss)
                for k, v in {**terms, "clip_fraction": clip_fraction, **norms}.items():
                    stats[k].append(v)
        if self.average is not None:
            self.average.update(self.net)
        self.updates += 1
        out = {k: (sum(v) / len(v) if v else float("nan")) for k, v in stats.items()}
        out.update(rewards_raw=float(rollout.rewards.mean()), rewards_scaled=float(rewards.mean()),
                   returns=float(ret.mean()), advantages=float(adv.mean()), values=float(rollout.values.mean()),
                   explained_variance=explained_variance(rollout.values, ret), **self.policy.update_metrics(),
                   lr=self.optimizers[0].param_groups[0]["lr"], epochs_steps=len(stats["actor_loss"]), **intrinsic)
        return out

    def _gradient_step(self, loss: torch.Tensor) -> dict[str, float]:
        """Backward, clip each parameter group, step every optimiser and schedule; the groups' norms."""
        for o in self.optimizers:
            o.zero_grad(set_to_none=True)
        loss.backward()
        norms = clip_gradients(self.groups, self.cfg.max_grad_norm)
        for o, s in zip(self.optimizers, self.schedulers, strict=True):
            o.step()
            s.step()
        self.gradient_steps += 1
        return {f"grad_norm_{name}": float(norm) for name, norm in norms.items()}

    def _intrinsic(self, rollout: Rollout, generator: torch.Generator | None) -> dict:
        """RND (docs/model/learning.md §15): ``rnd.coef`` x the scaled novelty of each row's observation (the rollout
        keeps no next observations, so the state the action was taken in stands for it), then one pass of predictor
        training over the rollout in minibatches of ``ppo.batch_size``. Returns the [T, B] rewards to add and
        the metrics."""
        T, B = rollout.log_probs.shape
        features = self.policy.novelty_features({k: v.flatten(0, 1) for k, v in rollout.obs.items()})
        bonus = self.rnd.cfg.coef * self.rnd.scaled_intrinsic(features).view(T, B).to(rollout.rewards.device)
        loss = self.rnd.update(features, self.cfg.batch_size, generator)
        return {"rewards": bonus, "rnd_intrinsic": float(bonus.mean()), "rnd_loss": loss}

    def _sample_epoch(self, rollout: Rollout, adv, ret, generator) -> Iterator[Minibatch]:
        """One epoch of minibatches of shuffled transitions (docs/model/learning.md §6.2 step 6)."""
        flat = lambda x: x.flatten(0, 1)  # noqa: E731  [T, B, ...] -> [T * B, ...]
        obs = {k: flat(v) for k, v in rollout.obs.items()}
        actions, old_logp, adv, ret = flat(rollout.actions), flat(rollout.log_probs), flat(adv), flat(ret)
        order = torch.randperm(old_logp.shape[0], generator=generator, device="cpu").to(self.device)
        for idx in order.split(self.cfg.batch_size):
            score = partial(self.policy.evaluate, {k: v[idx] for k, v in obs.items()}, actions[idx])
            yield Minibatch(score, old_logp[idx], adv[idx], ret[idx])

    def _column_epoch(self, rollout: Rollout, adv, ret, generator) -> Iterator[Minibatch]:
        """One epoch of minibatches of whole FlyAgent drone columns [T, c]: each distinct frame of a column is
        encoded once and the stacks are gathered from those embeddings (:func:`stack_index`), which gives the
        same network outputs as encoding every stack, with a third of the encoder work for 3 frames."""
        T, B = rollout.log_probs.shape
        ended = rollout.terminations | rollout.truncations
        restart = torch.cat([torch.zeros_like(ended[:1]), ended[:-1]])  # obs[t] starts an episode
        index = stack_index(restart, rollout.obs["agent"].shape[2])  # [T, B, F]
        order = torch.randperm(B, generator=generator, device="cpu").to(self.device)
        for cols in order.split(max(1, self.cfg.batch_size // T)):
            pick = lambda x, c=cols: x[:, c].flatten(0, 1)  # noqa: E731
            score = partial(self.policy.evaluate_columns, {k: v[:, cols] for k, v in rollout.obs.items()},
                            index[:, cols], pick(rollout.actions))
            yield Minibatch(score, pick(rollout.log_probs), pick(adv), pick(ret))

    # ------------------------------------------------------------------------------------------ state

    def state_dict(self) -> dict:
        state = {"net": self.net.state_dict(), "optimizers": [o.state_dict() for o in self.optimizers],
                 "schedulers": [s.state_dict() for s in self.schedulers], "scaler": self.scaler.state_dict(),
                 "updates": self.updates, "gradient_steps": self.gradient_steps}
        if self.rnd is not None:
            state["rnd"] = self.rnd.state_dict()
        if self.average is not None:
            state["net_average"] = self.average.policy.net.state_dict()
        return state

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        """``weights_only`` (evaluation, fine-tuning) loads the weights that act deterministically: the average
        where the checkpoint has one."""
        if weights_only:
            self.net.load_state_dict(state.get("net_average", state["net"]))
            if self.average is not None:
                self.average.reset(self.net)
            return
        self.net.load_state_dict(state["net"])
        if self.average is not None:
            if "net_average" not in state:
                raise ValueError("ppo.ema_decay > 0, but this checkpoint was saved without the weight average")
            self.average.policy.net.load_state_dict(state["net_average"])
        if self.rnd is not None:
            if "rnd" not in state:
                raise ValueError("rnd.enabled = true, but this checkpoint was saved without RND")
            self.rnd.load_state_dict(state["rnd"])
        for o, s in zip(self.optimizers, state["optimizers"], strict=True):
            o.load_state_dict(s)
        for o, s in zip(self.schedulers, state["schedulers"], strict=True):
            o.load_state_dict(s)
        self.scaler.load_state_dict(state["scaler"])
        self.updates, self.gradient_steps = state["updates"], state["gradient_steps"]
