"""PPO as in the reference (learning.md 6): clipped surrogate, GAE, reward scaling by a running std without
shift, per-minibatch advantage normalisation, KL early stop, gradient clipping per parameter group.

The rollout is stored as [T, B] tensors with B = envs x drones: every drone is a sample of the shared policy,
while the done flags come from the env (one episode per env), so an episode that ends because of one drone
ends every drone's trace (the reference keeps per-drone flags; learning.md 6.2 step 5 calls that a quirk).
"""

import math
from typing import NamedTuple

import torch
from torch import nn

from roshan.algos.distributions import ClippedGaussian, TanhNormal
from roshan.algos.networks import ActorCritic
from roshan.algos.normalize import RewardScaler
from roshan.algos.optim import make_optimizer, make_scheduler
from roshan.algos.returns import gae
from roshan.config import PPOConfig


class Rollout(NamedTuple):
    """One update's data, [T, B, ...] with B = envs x drones.

    ``next_values`` holds V of the true next state: the next row's state, the env's ``final_obs`` where an
    episode was truncated, or the bootstrap state after the last row.
    """

    obs: dict[str, torch.Tensor]
    actions: torch.Tensor  # [T, B, 2] as the distribution stores them (TanhNormal: the pre-tanh sample)
    log_probs: torch.Tensor  # [T, B]
    values: torch.Tensor  # [T, B]
    next_values: torch.Tensor  # [T, B]
    rewards: torch.Tensor  # [T, B] raw
    terminations: torch.Tensor  # [T, B] bool
    truncations: torch.Tensor  # [T, B] bool


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


def minibatch_loss(cfg, new_logp: torch.Tensor, old_logp: torch.Tensor, entropy: torch.Tensor, value: torch.Tensor,
                   adv: torch.Tensor, ret: torch.Tensor, stats: dict) -> torch.Tensor | None:
    """The PPO loss of one minibatch (clipped surrogate, entropy bonus, value loss; learning.md 6), its terms
    appended to ``stats``; None when the approx-KL early stop triggers (only the KL is logged then). ``cfg``
    is a PPO or planner PPO config (eps_clip, KL settings, coefficients)."""
    log_ratio = (new_logp - old_logp).clamp(-10.0, 10.0)
    ratio = log_ratio.exp()
    with torch.no_grad():
        kl = float(approx_kl(old_logp, new_logp, cfg.kl_estimator))
        clip_frac = float(((ratio - 1.0).abs() > cfg.eps_clip).float().mean())
    stats["approx_kl"].append(kl)
    if cfg.kl_early_stop and kl >= cfg.kl_target:
        return None
    actor_loss = clipped_surrogate(ratio, adv, cfg.eps_clip)
    entropy = entropy.mean()
    value_loss = (value - ret).pow(2).mean()
    for k, v in (("actor_loss", actor_loss), ("value_loss", value_loss), ("entropy", entropy)):
        stats[k].append(float(v.detach()))
    stats["clip_fraction"].append(clip_frac)
    return actor_loss - cfg.entropy_coeff * entropy + cfg.value_loss_coef * value_loss


def clip_gradients(groups: dict, max_norm: float) -> None:
    """Gradient-norm clipping per parameter group (actor, critic, encoders), as the reference does."""
    if max_norm > 0:
        for params in groups.values():
            nn.utils.clip_grad_norm_(params, max_norm)


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 - Var(R - V) / Var(R); NaN when the returns are constant."""
    var = returns.var()
    return float("nan") if float(var) == 0.0 else float(1.0 - (returns - values).var() / var)


def stack_index(restart: torch.Tensor, frames: int) -> torch.Tensor:
    """Where frame j of the stack at step t comes from, for drone columns of a rollout.

    The env pushes one frame per step and fills the whole stack with copies of the first frame of an episode,
    so frame j of obs[t] is frame 0 of obs[max(t - j, s)], s = the step the episode (re)started in this
    rollout; steps before the rollout are frames of obs[0]. Distinct frames are numbered F-1+t for frame 0 of
    obs[t] and F-1-j for frame j of obs[0].

    Args:
        restart: [T, B] bool, obs[t] is the first observation of an episode.
        frames: F, the stack depth.

    Returns:
        [T, B, F] long indices into the [T + F - 1] distinct frames of each column.
    """
    T = restart.shape[0]
    t = torch.arange(T, device=restart.device).unsqueeze(1).expand_as(restart)
    start = torch.where(restart, t, torch.full_like(t, -T - frames)).cummax(dim=0).values
    j = torch.arange(frames, device=restart.device)
    return frames - 1 + torch.maximum(t.unsqueeze(-1) - j, start.unsqueeze(-1))


def gather_stacks(distinct: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Stacks [T, c, F, D] from distinct frame embeddings [L, c, D] and :func:`stack_index` [T, c, F]."""
    L, c, D = distinct.shape
    T, _, F = index.shape
    idx = index.permute(1, 0, 2).reshape(c, T * F, 1).expand(c, T * F, D)
    return distinct.transpose(0, 1).gather(1, idx).view(c, T, F, D).transpose(0, 1)


class FrameCache:
    """Per-frame embeddings of the previous step's stacks, so acting encodes only the newest frame.

    Valid only while the parameters do not change: :meth:`clear` it after every update.
    """

    def __init__(self):
        self.za: torch.Tensor | None = None
        self.zc: torch.Tensor | None = None

    def clear(self) -> None:
        self.za = self.zc = None

    def encode(self, net: ActorCritic, obs: dict[str, torch.Tensor], restarted: torch.Tensor | None):
        if self.za is None:
            self.za, self.zc = net.encode_frames(obs)
            return self.za, self.zc
        na, nc = net.encode_frames({k: v[:, :1] for k, v in obs.items()})
        self.za = self._shift(self.za, na, restarted)
        self.zc = None if nc is None else self._shift(self.zc, nc, restarted)
        return self.za, self.zc

    @staticmethod
    def _shift(old: torch.Tensor, new: torch.Tensor, restarted: torch.Tensor | None) -> torch.Tensor:
        z = torch.cat([new, old[:, :-1]], dim=1)
        if restarted is not None:  # a restarted episode's stack is copies of its first frame
            z = torch.where(restarted[:, None, None], new.expand_as(z), z)
        return z


class PPO:
    """The FlyAgent actor-critic and its PPO update."""

    def __init__(self, cfg: PPOConfig, collision: bool, frames: int = 3, device: str | torch.device = "cpu"):
        if cfg.separate_optimizers and cfg.share_encoder:
            raise ValueError("ppo.separate_optimizers needs ppo.share_encoder = false (learning.md 6.2)")
        self.cfg = cfg
        self.device = torch.device(device)
        self.net = ActorCritic(collision, frames, share_encoder=cfg.share_encoder,
                               tanh_mean=not cfg.use_tanh_dist).to(self.device)
        self.net.log_std.requires_grad_(cfg.log_std == "learned")
        critic_params = list(self.net.value.parameters())
        if self.net.critic_encoder is not None:
            critic_params += list(self.net.critic_encoder.parameters())
        critic_ids = {id(p) for p in critic_params}
        # Lists, not generators: the thesis-era code clipped exhausted generators, i.e. never (learning.md 6.2).
        self.groups = {"actor": [p for p in self.net.parameters() if id(p) not in critic_ids and p.requires_grad],
                       "critic": critic_params}
        if cfg.separate_optimizers:
            self.optimizers = [make_optimizer(self.groups[g], cfg.lr, cfg.optim) for g in ("actor", "critic")]
        else:
            self.optimizers = [make_optimizer(self.groups["actor"] + self.groups["critic"], cfg.lr, cfg.optim)]
        self.schedulers = [make_scheduler(o, cfg.optim) for o in self.optimizers]
        self.scaler = RewardScaler(cfg.reward_eps)
        self.updates = 0
        self.gradient_steps = 0

    # ------------------------------------------------------------------------------------------ acting

    def distribution(self, mean: torch.Tensor, std: torch.Tensor):
        return TanhNormal(mean, std) if self.cfg.use_tanh_dist else ClippedGaussian(mean, std)

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor], deterministic: bool = False, cache: "FrameCache | None" = None,
            restarted: torch.Tensor | None = None):
        """Actions (B, 2), their log-probs (B,) and values (B,) for a batch of drone observations.

        With a :class:`FrameCache` only the newest frame is encoded (``restarted`` (B,) bool marks rows whose
        episode restarted since the previous call: their stack holds copies of one frame)."""
        actions, logp, value, _ = self.act_raw(obs, deterministic, cache, restarted)
        return actions, logp, value

    @torch.no_grad()
    def act_raw(self, obs: dict[str, torch.Tensor], deterministic: bool = False, cache: "FrameCache | None" = None,
                restarted: torch.Tensor | None = None):
        """:meth:`act` plus what a rollout stores for the update (the distribution's raw sample)."""
        if cache is None:
            mean, std, value = self.net(obs)
        else:
            mean, std, value = self.net.from_frames(*cache.encode(self.net, obs, restarted))
        dist = self.distribution(mean, std)
        if deterministic:
            return dist.mode, dist.log_prob(dist.mode), value, dist.mode
        raw = dist.sample_raw()
        return dist.to_action(raw), dist.log_prob_raw(raw), value, raw

    @torch.no_grad()
    def act_mode(self, obs: dict[str, torch.Tensor], cache: "FrameCache | None" = None,
                 restarted: torch.Tensor | None = None) -> torch.Tensor:
        """The deterministic actions (B, 2) alone: what evaluation needs, without log-probs or values (at a
        batch of a few drones the distribution's bookkeeping is a third of the inference time)."""
        if cache is None:
            mean = self.net.actor(obs)[0]
        else:
            mean = self.net.from_frames(*cache.encode(self.net, obs, restarted))[0]
        return (TanhNormal if self.cfg.use_tanh_dist else ClippedGaussian).mode_of(mean)

    @torch.no_grad()
    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.net.critic(obs)

    # ------------------------------------------------------------------------------------------ learning

    def decay_log_std(self) -> None:
        """The manual schedules of learning.md 4, applied before each update (k = finished updates)."""
        rho, k = self.cfg.decay_rate, self.updates
        with torch.no_grad():
            if self.cfg.log_std == "train_step_decay":
                self.net.log_std.fill_(-20.0 * (1.0 - (rho**k) ** 5))
            elif self.cfg.log_std == "log_step_decay":
                self.net.log_std.add_(math.log(rho))

    def advantages(self, rollout: Rollout) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Scale rewards by the running std (updated with this horizon first), then GAE. Returns the scaled
        rewards, advantages and returns, each [T, B]."""
        cfg = self.cfg
        self.scaler.update(rollout.rewards)
        rewards = self.scaler.scale(rollout.rewards)
        truncations = rollout.truncations
        terminations = rollout.terminations
        if not cfg.bootstrap_truncated:
            terminations, truncations = terminations | truncations, torch.zeros_like(truncations)
        adv, ret = gae(rewards, rollout.values, rollout.next_values, terminations, truncations, cfg.gamma, cfg.lam)
        return rewards, adv, ret

    def update(self, rollout: Rollout, generator: torch.Generator | None = None) -> dict[str, float]:
        """One PPO update over the rollout: ``k_epochs`` shuffled passes in minibatches of ``batch_size``."""
        cfg = self.cfg
        if cfg.log_std != "learned":
            self.decay_log_std()
        rewards, adv, ret = self.advantages(rollout)
        if cfg.minibatch == "sequences":
            stats = self._sequence_epochs(rollout, adv, ret, generator)
        else:
            stats = self._sample_epochs(rollout, adv, ret, generator)
        self.updates += 1
        out = {k: (sum(v) / len(v) if v else float("nan")) for k, v in stats.items()}
        out.update(rewards_raw=float(rollout.rewards.mean()), rewards_scaled=float(rewards.mean()),
                   returns=float(ret.mean()), advantages=float(adv.mean()), values=float(rollout.values.mean()),
                   explained_variance=explained_variance(rollout.values, ret),
                   std=float(self.net.log_std.detach().exp()[0]),
                   lr=self.optimizers[0].param_groups[0]["lr"], epochs_steps=len(stats["actor_loss"]))
        return out

    @staticmethod
    def _new_stats() -> dict[str, list[float]]:
        return {k: [] for k in ("actor_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")}

    def _sample_epochs(self, rollout: Rollout, adv, ret, generator) -> dict[str, list[float]]:
        """k epochs of minibatches of shuffled transitions (learning.md 6.2 step 6)."""
        cfg = self.cfg
        flat = lambda x: x.flatten(0, 1)  # noqa: E731  [T, B, ...] -> [T * B, ...]
        obs = {k: flat(v) for k, v in rollout.obs.items()}
        actions, old_logp, adv_f, ret_f = flat(rollout.actions), flat(rollout.log_probs), flat(adv), flat(ret)
        n = old_logp.shape[0]
        stats = self._new_stats()
        self.net.train()
        for _ in range(cfg.k_epochs):
            order = torch.randperm(n, generator=generator, device="cpu").to(self.device)
            for start in range(0, n, cfg.batch_size):
                idx = order[start:start + cfg.batch_size]
                mb_obs = {k: v[idx] for k, v in obs.items()}
                if not self._minibatch_step(lambda o=mb_obs: self.net(o), actions[idx], old_logp[idx], adv_f[idx],
                                            ret_f[idx], stats):
                    break  # KL early stop: abandon the rest of this epoch (later epochs still start)
        return stats

    def _sequence_epochs(self, rollout: Rollout, adv, ret, generator) -> dict[str, list[float]]:
        """k epochs of minibatches of whole drone columns [T, c]: each distinct frame of a column is encoded
        once and the stacks are gathered from those embeddings (:func:`stack_index`), which gives the same
        network outputs as encoding every stack, with a third of the encoder work for 3 frames."""
        cfg = self.cfg
        T, B = rollout.log_probs.shape
        frames = rollout.obs["agent"].shape[2]
        ended = rollout.terminations | rollout.truncations
        restart = torch.cat([torch.zeros_like(ended[:1]), ended[:-1]])  # obs[t] starts an episode
        index = stack_index(restart, frames)  # [T, B, F]
        cols_per_mb = max(1, cfg.batch_size // T)
        stats = self._new_stats()
        self.net.train()
        for _ in range(cfg.k_epochs):
            order = torch.randperm(B, generator=generator, device="cpu").to(self.device)
            for start in range(0, B, cols_per_mb):
                cols = order[start:start + cols_per_mb]
                obs = {k: v[:, cols] for k, v in rollout.obs.items()}
                pick = lambda x, c=cols: x[:, c].flatten(0, 1)  # noqa: E731
                forward = lambda o=obs, i=index[:, cols]: self._forward_columns(o, i)  # noqa: E731
                if not self._minibatch_step(forward, pick(rollout.actions), pick(rollout.log_probs), pick(adv),
                                            pick(ret), stats):
                    break
        return stats

    def _forward_columns(self, obs: dict[str, torch.Tensor], index: torch.Tensor):
        """Mean, std and value [T * c] of drone columns obs [T, c, F, ...] from their distinct frames."""
        newest = {k: v[:, :, 0] for k, v in obs.items()}  # frame 0 of every step: (T, c, ...)
        older = {k: v[0, :, 1:].flip(1) for k, v in obs.items()}  # frames F-1..1 of the first step: (c, F-1, ...)
        za_new, zc_new = self.net.encode_frames(newest)
        za_old, zc_old = self.net.encode_frames(older)
        za = gather_stacks(torch.cat([za_old.transpose(0, 1), za_new]), index)
        zc = None if zc_new is None else gather_stacks(torch.cat([zc_old.transpose(0, 1), zc_new]), index)
        mean, std, value = self.net.from_frames(za, zc)
        return mean.flatten(0, 1), std, value.flatten(0, 1)

    def _minibatch_step(self, forward, actions, old_logp, adv, ret, stats) -> bool:
        """One gradient step; returns False (and takes no step) when the KL early stop triggers."""
        mean, std, value = forward()
        dist = self.distribution(mean, std)
        loss = minibatch_loss(self.cfg, dist.log_prob_raw(actions), old_logp, dist.entropy(), value,
                              normalized_advantages(adv), ret, stats)
        if loss is None:
            return False
        for o in self.optimizers:
            o.zero_grad(set_to_none=True)
        loss.backward()
        clip_gradients(self.groups, self.cfg.max_grad_norm)
        for o, s in zip(self.optimizers, self.schedulers, strict=True):
            o.step()
            s.step()
        self.gradient_steps += 1
        return True

    # ------------------------------------------------------------------------------------------ state

    def state_dict(self) -> dict:
        return {"net": self.net.state_dict(), "optimizers": [o.state_dict() for o in self.optimizers],
                "schedulers": [s.state_dict() for s in self.schedulers], "scaler": self.scaler.state_dict(),
                "updates": self.updates, "gradient_steps": self.gradient_steps}

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        self.net.load_state_dict(state["net"])
        if weights_only:
            return
        for o, s in zip(self.optimizers, state["optimizers"], strict=True):
            o.load_state_dict(s)
        for o, s in zip(self.schedulers, state["schedulers"], strict=True):
            o.load_state_dict(s)
        self.scaler.load_state_dict(state["scaler"])
        self.updates, self.gradient_steps = state["updates"], state["gradient_steps"]
