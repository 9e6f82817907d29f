"""Implicit Q-learning (Kostrikov et al. 2021, arXiv:2110.06169) on a saved replay buffer (docs/model/learning.md §8).

Per minibatch: expectile value loss, Q loss towards r + gamma * not_done * V(s'), advantage-weighted regression
of a fixed-std policy, then a soft update of the target critic. Offline passes sweep the whole dataset.
"""

import copy
import math
from collections import defaultdict
from collections.abc import Iterable

import torch

from roshan.algos.buffers import ReplayBatch, ReplayBuffer
from roshan.algos.distributions import ClippedGaussian, TanhNormal
from roshan.algos.frames import NoCache
from roshan.algos.networks import MeanActor, TwinQ, ValueNet, check_meta, frozen_copy, soft_update, to_device
from roshan.algos.normalize import RewardScaler
from roshan.algos.optim import make_optimizer, make_scheduler
from roshan.config import IQLConfig

POLICY_LOG_STD = -3.0  # the AWR policy's fixed std exp(-3) ~ 0.0498 (docs/model/learning.md §4)


def expectile_loss(u: torch.Tensor, tau: float) -> torch.Tensor:
    """Asymmetric L2 mean(|tau - 1(u < 0)| * u^2) of residuals u = Q(s, a) - V(s), any shape -> scalar."""
    weight = torch.where(u > 0, tau, 1.0 - tau)
    return (weight * u.pow(2)).mean()


def awr_weights(advantages: torch.Tensor, temperature: float, max_weight: float) -> torch.Tensor:
    """Advantage weights min(exp(temperature * A), max_weight), (B,) -> (B,); exp overflow to inf clips too."""
    return torch.exp(temperature * advantages).clamp(max=max_weight)


def iql_q_loss(q1: torch.Tensor, q2: torch.Tensor, rewards: torch.Tensor, not_done: torch.Tensor,
               next_v: torch.Tensor, gamma: float, broadcast_defect: bool = False) -> torch.Tensor:
    """mean((Q1 - y)^2 + (Q2 - y)^2) with y = r + gamma * not_done * V(s'); every input (B,).

    With ``broadcast_defect`` the reference's shapes are reproduced: V(s') and Q come as (B, 1), r and not_done
    as (B,), so y[i, j] = r[j] + gamma * not_done[j] * V(s'_i) is (B, B) and every Q_i regresses towards a
    mixture of all rewards of the minibatch (docs/model/learning.md §8).
    """
    if broadcast_defect:
        q1, q2, next_v = q1.unsqueeze(-1), q2.unsqueeze(-1), next_v.unsqueeze(-1)
    y = rewards + gamma * not_done * next_v
    return ((q1 - y).pow(2) + (q2 - y).pow(2)).mean()


class IQL:
    """Mean actor, twin critic with a target copy, and a value net; three optimisers with a scheduler each."""

    weight_keys = ("actor", "critic", "value")  # the target critic is copied from the critic

    def __init__(self, cfg: IQLConfig, collision: bool, frames: int = 3, device: str | torch.device = "cpu"):
        self.cfg = cfg
        self.collision, self.frames = collision, frames
        self.device = torch.device(device)
        self.actor = MeanActor(collision, frames).to(self.device)
        shared = self.actor.encoder if cfg.share_encoder else None
        self.critic = TwinQ(collision, frames, encoder=shared).to(self.device)
        self.value = ValueNet(collision, frames, encoder=shared).to(self.device)
        self.critic_target = frozen_copy(self.critic)
        # with sharing the encoder is in all three parameter lists and every loss steps it (docs/model/learning.md §8)
        self.actor_optimizer = make_optimizer(list(self.actor.parameters()), cfg.lr, cfg.optim)
        self.critic_optimizer = make_optimizer(list(self.critic.parameters()), cfg.lr, cfg.optim)
        self.value_optimizer = make_optimizer(list(self.value.parameters()), cfg.lr, cfg.optim)
        self.actor_scheduler = make_scheduler(self.actor_optimizer, cfg.optim)
        self.critic_scheduler = make_scheduler(self.critic_optimizer, cfg.optim)
        self.value_scheduler = make_scheduler(self.value_optimizer, cfg.optim)
        self.reward_scaler = RewardScaler()
        self.passes = 0  # offline passes done
        self.iterations = 0  # gradient steps (minibatches) done

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """The online-phase actions: :meth:`act_deterministic`, ``generator`` unused. The reference computes a
        noisy copy and then executes the noise-free action (docs/model/learning.md §4)."""
        return self.act_deterministic(obs)

    @torch.no_grad()
    def act_deterministic(self, obs: dict[str, torch.Tensor], cache: NoCache | None = None) -> torch.Tensor:
        """tanh(mu) (B, 2): the TanhNormal mode, and in Gaussian mode the mean, which is tanh(mu) too
        (docs/model/learning.md §2.3)."""
        return torch.tanh(self.actor(to_device(obs, self.device)))

    def new_cache(self) -> NoCache:
        return NoCache()

    def log_prob(self, obs: dict[str, torch.Tensor], actions: torch.Tensor) -> torch.Tensor:
        """log pi(a|s) (B,) under the fixed-std policy: TanhNormal(mu, e^-3) or ClippedGaussian(tanh(mu), e^-3)."""
        mu = self.actor(obs)
        std = mu.new_full((mu.shape[-1],), math.exp(POLICY_LOG_STD))
        dist = TanhNormal(mu, std) if self.cfg.use_tanh_dist else ClippedGaussian(torch.tanh(mu), std)
        return dist.log_prob(actions)

    def update_batch(self, batch: ReplayBatch, reward_std: float = 1.0) -> dict[str, torch.Tensor]:
        """One IQL step on ``batch`` with rewards divided by ``reward_std``. Each stage reads the networks as the
        previous stage left them (value first, as in the paper's reference code). Returns detached scalars."""
        cfg = self.cfg
        batch = batch.to(self.device)  # the buffer may live on another device (e.g. a large one in host memory)
        rewards = batch.rewards / reward_std
        # 1. value: expectile regression of V(s) towards the target critic's min(Q1, Q2)(s, a)
        with torch.no_grad():
            target_q = torch.minimum(*self.critic_target(batch.obs, batch.actions))
        v = self.value(batch.obs)
        value_loss = expectile_loss(target_q - v, cfg.expectile)
        self._step(self.value_optimizer, self.value_scheduler, value_loss)

        # 2. Q: regress both heads towards r + gamma * not_done * V(s')
        with torch.no_grad():
            next_v = self.value(batch.next_obs)
        q1, q2 = self.critic(batch.obs, batch.actions)
        critic_loss = iql_q_loss(q1, q2, rewards, batch.not_done, next_v, cfg.gamma, cfg.broadcast_defect)
        self._step(self.critic_optimizer, self.critic_scheduler, critic_loss)

        # 3. actor: advantage-weighted regression onto the dataset actions
        with torch.no_grad():
            advantages = target_q - self.value(batch.obs)
            weights = awr_weights(advantages, cfg.temperature, cfg.max_weight)
        actor_loss = -(weights * self.log_prob(batch.obs, batch.actions)).mean()
        self._step(self.actor_optimizer, self.actor_scheduler, actor_loss)

        # 4. target critic
        soft_update(self.critic_target, self.critic, cfg.tau)
        self.iterations += 1
        return {"loss/value": value_loss.detach(), "loss/critic": critic_loss.detach(),
                "loss/actor": actor_loss.detach(), "v": v.detach().mean(), "q1": q1.detach().mean(),
                "q2": q2.detach().mean(), "advantage": advantages.mean(), "weight": weights.mean()}

    @staticmethod
    def _step(optimizer: torch.optim.Optimizer, scheduler, loss: torch.Tensor) -> None:
        optimizer.zero_grad()
        loss.backward()  # no gradient clipping in the reference
        optimizer.step()
        scheduler.step()

    def offline_pass(self, buffer: ReplayBuffer, generator: torch.Generator | None = None) -> dict[str, float]:
        """One full pass over ``buffer`` in random order, in minibatches of ``batch_size``.

        Reward scaling as the reference (docs/model/learning.md §8): the first pass divides by the initial std (~1, so
        raw rewards); every later pass first merges the whole dataset into the running estimator again (its count
        keeps growing) and divides by the resulting std.
        """
        if self.passes > 0:
            self.reward_scaler.update(buffer.rewards[:len(buffer)])
        reward_std = self.reward_scaler.std
        metrics = self._run(buffer.iterate(self.cfg.batch_size, generator), reward_std)
        self.passes += 1
        return metrics

    def update(self, buffer: ReplayBuffer, generator: torch.Generator | None = None) -> dict[str, float]:
        """Online phase: ``k_epochs`` uniformly sampled minibatches, rewards divided by the current std."""
        batches = (buffer.sample(self.cfg.batch_size, generator) for _ in range(self.cfg.k_epochs))
        return self._run(batches, self.reward_scaler.std)

    def _run(self, batches: Iterable[ReplayBatch], reward_std: float) -> dict[str, float]:
        sums: dict[str, list[torch.Tensor]] = defaultdict(list)
        for batch in batches:
            for key, value in self.update_batch(batch, reward_std).items():
                sums[key].append(value)
        metrics = {key: torch.stack(values).mean().item() for key, values in sums.items()}
        metrics["reward_std"] = reward_std
        for name, opt in (("actor", self.actor_optimizer), ("critic", self.critic_optimizer),
                          ("value", self.value_optimizer)):
            metrics[f"lr/{name}"] = opt.param_groups[0]["lr"]
        return metrics

    # ------------------------------------------------------------------------------------------ checkpoints

    def _meta(self) -> dict:
        return {"algo": "iql", "collision": self.collision, "frames": self.frames,
                "share_encoder": self.cfg.share_encoder}

    def state_dict(self) -> dict:
        """Networks, target critic, optimisers, schedulers, reward scaler and counters."""
        return {"meta": self._meta(), "passes": self.passes, "iterations": self.iterations,
                "reward_scaler": self.reward_scaler.state_dict(),
                "actor": self.actor.state_dict(), "critic": self.critic.state_dict(),
                "value": self.value.state_dict(), "critic_target": self.critic_target.state_dict(),
                "actor_optimizer": self.actor_optimizer.state_dict(),
                "critic_optimizer": self.critic_optimizer.state_dict(),
                "value_optimizer": self.value_optimizer.state_dict(),
                "actor_scheduler": self.actor_scheduler.state_dict(),
                "critic_scheduler": self.critic_scheduler.state_dict(),
                "value_scheduler": self.value_scheduler.state_dict()}

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        """Restore everything :meth:`state_dict` saved; ``weights_only`` (evaluation) restores the networks and
        re-copies the target critic from the critic.

        Raises:
            ValueError: if the checkpoint was made for another algorithm, encoder or frame count.
        """
        check_meta(state.get("meta"), self._meta())
        for name in ("actor", "critic", "value"):
            getattr(self, name).load_state_dict(state[name])
        self.critic_target.load_state_dict(state["critic" if weights_only else "critic_target"])
        if weights_only:
            return
        for name in ("actor_scheduler", "critic_scheduler", "value_scheduler"):
            getattr(self, name).load_state_dict(state[name])
        # torch's Optimizer.load_state_dict keeps (does not copy) state tensors already on the right device, so an
        # in-memory state dict would be shared with, and mutated by, the optimiser it came from
        for name in ("actor_optimizer", "critic_optimizer", "value_optimizer"):
            getattr(self, name).load_state_dict(copy.deepcopy(state[name]))
        self.reward_scaler.load_state_dict(state["reward_scaler"])
        self.passes, self.iterations = state["passes"], state["iterations"]
