"""TD3 (Fujimoto et al. 2018, arXiv:1802.09477) for the FlyAgent, as the reference implements it
(docs/model/learning.md §7).

Target policy smoothing, clipped double Q on raw rewards, a delayed actor and soft target updates. The reference's
(B, 1)-vs-(B,) critic MSE broadcast is available behind ``broadcast_defect`` for fidelity runs.
"""

import copy
from collections import defaultdict

import torch

from roshan.algos.buffers import ReplayBatch, ReplayBuffer
from roshan.algos.frames import NoCache
from roshan.algos.networks import DeterministicActor, TwinQ, check_meta, frozen_copy, soft_update, to_device
from roshan.algos.optim import make_optimizer, make_scheduler
from roshan.config import TD3Config


def smooth_target_actions(next_actions: torch.Tensor, noise: torch.Tensor, noise_clip: float) -> torch.Tensor:
    """Target policy smoothing a' = clip(mu_target(s') + clip(noise, -c, c), -1, 1); all (B, 2)."""
    return (next_actions + noise.clamp(-noise_clip, noise_clip)).clamp(-1.0, 1.0)


def td3_target(rewards: torch.Tensor, not_done: torch.Tensor, next_q1: torch.Tensor, next_q2: torch.Tensor,
               gamma: float) -> torch.Tensor:
    """Clipped double-Q target y = r + gamma * not_done * min(Q1'(s', a'), Q2'(s', a')); all (B,)."""
    return rewards + gamma * not_done * torch.minimum(next_q1, next_q2)


def critic_mse(q: torch.Tensor, y: torch.Tensor, broadcast_defect: bool = False) -> torch.Tensor:
    """MSE of Q (B,) against targets y (B,).

    With ``broadcast_defect`` the reference's shapes are reproduced: Q (B, 1) minus y (B,) broadcasts to (B, B),
    so every Q value regresses towards every target of the minibatch (docs/model/learning.md §7).
    """
    if broadcast_defect:
        return (q.unsqueeze(-1) - y.unsqueeze(0)).pow(2).mean()
    return (q - y).pow(2).mean()


def randn(shape: tuple[int, ...], generator: torch.Generator | None, device: torch.device) -> torch.Tensor:
    """Standard normal noise drawn on the generator's device (a generator is tied to one), moved to ``device``."""
    source = generator.device if generator is not None else device
    return torch.randn(shape, generator=generator, device=source).to(device)


class TD3:
    """Deterministic actor, twin critic and their target copies, with one optimiser and scheduler each."""

    weight_keys = ("actor", "critic")  # the targets are copied from them on a weights-only load

    def __init__(self, cfg: TD3Config, collision: bool, frames: int = 3, device: str | torch.device = "cpu"):
        self.cfg = cfg
        self.collision, self.frames = collision, frames
        self.device = torch.device(device)
        self.actor = DeterministicActor(collision, frames).to(self.device)
        shared = self.actor.encoder if cfg.share_encoder else None
        self.critic = TwinQ(collision, frames, encoder=shared).to(self.device)
        # separate deep copies, as the reference: with sharing each target keeps its own copy of the encoder,
        # and soft-updating both never moves one target encoder twice
        self.actor_target = frozen_copy(self.actor)
        self.critic_target = frozen_copy(self.critic)
        # with sharing the encoder is in both parameter lists and both losses step it (docs/model/learning.md §2.3)
        self.actor_optimizer = make_optimizer(list(self.actor.parameters()), cfg.lr, cfg.optim)
        self.critic_optimizer = make_optimizer(list(self.critic.parameters()), cfg.lr, cfg.optim)
        self.actor_scheduler = make_scheduler(self.actor_optimizer, cfg.optim)
        self.critic_scheduler = make_scheduler(self.critic_optimizer, cfg.optim)
        self.iterations = 0  # critic gradient steps so far; the actor steps on every policy_freq-th

    def is_ready(self, buffer: ReplayBuffer) -> bool:
        """Whether ``buffer`` holds enough transitions for updates to start (``min_memory_size``)."""
        return len(buffer) >= self.cfg.min_memory_size

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """Exploring actions (B, 2) in [-1, 1]: mu(s) plus N(0, exploration_noise^2) noise, clipped."""
        actions = self.actor(to_device(obs, self.device))
        noise = self.cfg.exploration_noise * randn(tuple(actions.shape), generator, self.device)
        return (actions + noise).clamp(-1.0, 1.0)

    @torch.no_grad()
    def act_deterministic(self, obs: dict[str, torch.Tensor], cache: NoCache | None = None) -> torch.Tensor:
        """mu(s) (B, 2) in [-1, 1]."""
        return self.actor(to_device(obs, self.device))

    def new_cache(self) -> NoCache:
        return NoCache()

    @torch.no_grad()
    def compute_target(self, batch: ReplayBatch, generator: torch.Generator | None = None) -> torch.Tensor:
        """Critic targets y (B,) from the target networks, with smoothing noise N(0, policy_noise^2)."""
        batch = batch.to(self.device)
        noise = self.cfg.policy_noise * randn(tuple(batch.actions.shape), generator, self.device)
        next_actions = smooth_target_actions(self.actor_target(batch.next_obs), noise, self.cfg.noise_clip)
        next_q1, next_q2 = self.critic_target(batch.next_obs, next_actions)
        return td3_target(batch.rewards, batch.not_done, next_q1, next_q2, self.cfg.gamma)

    def update(self, buffer: ReplayBuffer, generator: torch.Generator | None = None) -> dict[str, float]:
        """``k_epochs`` gradient iterations on uniformly sampled minibatches; returns the mean metrics."""
        sums: dict[str, list[torch.Tensor]] = defaultdict(list)
        for _ in range(self.cfg.k_epochs):
            batch = buffer.sample(self.cfg.batch_size, generator)
            for key, value in self.update_batch(batch, generator).items():
                sums[key].append(value)
        metrics = {key: torch.stack(values).mean().item() for key, values in sums.items()}
        metrics["lr/actor"] = self.actor_optimizer.param_groups[0]["lr"]
        metrics["lr/critic"] = self.critic_optimizer.param_groups[0]["lr"]
        return metrics

    def update_batch(self, batch: ReplayBatch, generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """One TD3 iteration on ``batch``: critic step, and every ``policy_freq``-th time the actor step and the
        soft target updates. Returns detached scalar tensors (no device sync here)."""
        cfg = self.cfg
        self.iterations += 1
        batch = batch.to(self.device)  # the buffer may live on another device (e.g. a large one in host memory)
        y = self.compute_target(batch, generator)
        q1, q2 = self.critic(batch.obs, batch.actions)
        critic_loss = critic_mse(q1, y, cfg.broadcast_defect) + critic_mse(q2, y, cfg.broadcast_defect)
        self.critic_optimizer.zero_grad()
        critic_loss.backward()  # no gradient clipping in the reference
        self.critic_optimizer.step()
        self.critic_scheduler.step()
        metrics = {"loss/critic": critic_loss.detach(), "q/q1": q1.detach().mean(), "q/target": y.mean()}

        if self.iterations % cfg.policy_freq == 0:
            actor_loss = -self.critic.q1_value(batch.obs, self.actor(batch.obs)).mean()
            self.actor_optimizer.zero_grad()
            actor_loss.backward()
            self.actor_optimizer.step()
            self.actor_scheduler.step()
            soft_update(self.actor_target, self.actor, cfg.tau)
            soft_update(self.critic_target, self.critic, cfg.tau)
            metrics["loss/actor"] = actor_loss.detach()
        return metrics

    # ------------------------------------------------------------------------------------------ checkpoints

    def _meta(self) -> dict:
        return {"algo": "td3", "collision": self.collision, "frames": self.frames,
                "share_encoder": self.cfg.share_encoder}

    def state_dict(self) -> dict:
        """Networks, target networks, optimisers, schedulers and the iteration counter."""
        return {"meta": self._meta(), "iterations": self.iterations,
                "actor": self.actor.state_dict(), "critic": self.critic.state_dict(),
                "actor_target": self.actor_target.state_dict(), "critic_target": self.critic_target.state_dict(),
                "actor_optimizer": self.actor_optimizer.state_dict(),
                "critic_optimizer": self.critic_optimizer.state_dict(),
                "actor_scheduler": self.actor_scheduler.state_dict(),
                "critic_scheduler": self.critic_scheduler.state_dict()}

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        """Restore everything :meth:`state_dict` saved; ``weights_only`` (evaluation) restores actor and critic
        and re-copies the targets from them, as the reference does on load.

        Raises:
            ValueError: if the checkpoint was made for another algorithm, encoder or frame count.
        """
        check_meta(state.get("meta"), self._meta())
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state["actor" if weights_only else "actor_target"])
        self.critic_target.load_state_dict(state["critic" if weights_only else "critic_target"])
        if weights_only:
            return
        # torch's Optimizer.load_state_dict keeps (does not copy) state tensors already on the right device, so an
        # in-memory state dict would be shared with, and mutated by, the optimiser it came from
        self.actor_optimizer.load_state_dict(copy.deepcopy(state["actor_optimizer"]))
        self.critic_optimizer.load_state_dict(copy.deepcopy(state["critic_optimizer"]))
        self.actor_scheduler.load_state_dict(state["actor_scheduler"])
        self.critic_scheduler.load_state_dict(state["critic_scheduler"])
        self.iterations = state["iterations"]
