"""The PlannerAgent: attention networks that assign every drone a candidate goal (learning.md 3) and their PPO
update (learning.md 6), with the joint action of N drones as one sample (log-prob and entropy summed over drones).

A planner observation is a dict of float tensors with the batch first: ``drones`` (B, N, 2), ``goals`` (B, N, 2),
``water`` (B, N, 1), ``fires`` (B, K, 2) (index 0 = the groundstation, then fire cells, zero padding after the
valid prefix), ``fires_mask`` (B, K) (1 = valid) and ``globals`` (B, 5) (fire count, centroid (2), wind (2)).
An action is (B, N) long: one candidate index per drone.
"""

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from roshan.algos.networks import layer_init
from roshan.algos.normalize import RewardScaler
from roshan.algos.optim import make_optimizer, make_scheduler
from roshan.algos.ppo import clip_gradients, explained_variance, minibatch_loss, normalized_advantages
from roshan.algos.returns import gae
from roshan.config import PlannerPPOConfig

HIDDEN = 64
HEADS = 4
PROB_EPS = 1e-8  # attention weights are clamped to this before the log, so a valid candidate keeps a finite log-prob


def trim_candidates(obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``obs`` with ``fires`` and ``fires_mask`` cut to the longest valid prefix in the batch (at least 1).

    Masked candidates never change a network's output, so this only saves work (K is up to 1261 in the env,
    while few cells burn at a time). Action indices are unchanged because the valid entries are a prefix.
    """
    mask = obs["fires_mask"]
    position = torch.arange(1, mask.shape[-1] + 1, device=mask.device)
    k = max(1, int(((mask > 0) * position).max())) if mask.numel() else 1
    out = dict(obs)
    out["fires"], out["fires_mask"] = obs["fires"][:, :k], mask[:, :k]
    return out


def candidate_validity(fires_mask: torch.Tensor) -> torch.Tensor:
    """(B, K) bool, True = selectable; the groundstation (index 0) is always valid."""
    valid = fires_mask > 0
    valid[:, 0] = True
    return valid


def sample_rows(logits: torch.Tensor, deterministic: bool, generator: torch.Generator | None) -> torch.Tensor:
    """One index per row of (..., K) logits (-inf = masked): argmax, or a categorical sample. A masked entry has
    probability exactly 0 and is never drawn."""
    if deterministic:
        return logits.argmax(-1)
    probs = torch.softmax(logits, -1)
    flat = probs.reshape(-1, probs.shape[-1])
    return torch.multinomial(flat, 1, generator=generator).view(probs.shape[:-1])


def score(logits: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Joint log-prob and entropy of per-drone categoricals.

    Args:
        logits: (B, N, K) per-drone logits, -inf where a candidate is masked.
        actions: (B, N) long candidate indices.

    Returns:
        (log_prob, entropy), both (B,): sums over the N drones.
    """
    logp = torch.log_softmax(logits, -1)
    allowed = torch.isfinite(logits)
    # -p log p with 0 for masked entries (0 * -inf would be NaN); the where keeps the gradient finite as well
    entropy = -(logp.exp() * torch.where(allowed, logp, torch.zeros_like(logp))).sum(-1)
    log_prob = logp.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
    return log_prob.sum(-1), entropy.sum(-1)


def init_weights(module: nn.Module) -> None:
    """Orthogonal weights with the ReLU gain and zero biases on every Linear, including the output projection
    inside ``nn.MultiheadAttention`` (learning.md 1); embeddings, LayerNorms and attention input projections
    keep PyTorch's defaults. Value output layers are re-initialised with gain 1.0 by their owners."""
    for m in module.modules():
        if isinstance(m, nn.Linear):
            layer_init(m)


# ---------------------------------------------------------------------------------------------- thesis-era net


class ThesisPlannerNet(nn.Module):
    """Thesis-era planner (learning.md 3.1): one attention layer from drones to fire candidates whose head-averaged
    weights are the per-drone categorical probabilities; the value is the mean over drones of a linear head on the
    attention output.

    Deviation from the reference: the reference masks only the groundstation when acting and only the padding
    during the update, so the update evaluates a different distribution than the one that sampled the action.
    Here acting and updating use the same mask: padding is masked, and index 0 (groundstation) is masked whenever
    at least one fire is valid, so it is chosen only when no fire is listed (which is what acting does in the
    reference).
    """

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS):
        super().__init__()
        self.pos_emb = nn.Linear(2, hidden)
        self.goal_emb = nn.Linear(2, hidden)
        self.fire_emb = nn.Linear(2, hidden)
        self.id_emb = nn.Embedding(num_drones, hidden)
        self.attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.value_head = nn.Linear(hidden, 1)
        init_weights(self)
        layer_init(self.value_head, gain=1.0)
        self.register_buffer("drone_ids", torch.arange(num_drones), persistent=False)

    @staticmethod
    def allowed(fires_mask: torch.Tensor) -> torch.Tensor:
        """(B, K) bool: valid fires, or only the groundstation when no fire is valid."""
        allowed = fires_mask > 0
        allowed[:, 0] = ~allowed[:, 1:].any(-1)
        return allowed

    def attend(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Attention weights averaged over heads (B, N, K), attention output (B, N, H) and the mask (B, K)."""
        allowed = self.allowed(obs["fires_mask"])
        query = self.pos_emb(obs["drones"]) + self.goal_emb(obs["goals"]) + self.id_emb(self.drone_ids)
        fires = self.fire_emb(obs["fires"])
        out, weights = self.attn(query, fires, fires, key_padding_mask=~allowed, need_weights=True,
                                 average_attn_weights=True)
        return weights, out, allowed

    def probs(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B, N, K) per-drone probabilities as the reference defines them (exactly 0 where masked)."""
        return self.attend(obs)[0]

    def heads(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-drone logits (B, N, K) (-inf where masked) and the value (B,)."""
        weights, out, allowed = self.attend(obs)
        # the clamp keeps the log finite where a weight underflows; log_softmax renormalises after it
        logits = weights.clamp_min(PROB_EPS).log().masked_fill(~allowed.unsqueeze(1), float("-inf"))
        return logits, self.value_head(out).squeeze(-1).mean(-1)

    def forward_act(self, obs: dict[str, torch.Tensor], deterministic: bool = False,
                    generator: torch.Generator | None = None):
        """Actions (B, N), joint log-prob (B,), entropy (B,) and value (B,); drones choose independently."""
        logits, value = self.heads(obs)
        actions = sample_rows(logits, deterministic, generator)
        log_prob, entropy = score(logits, actions)
        return actions, log_prob, entropy, value

    def evaluate(self, obs: dict[str, torch.Tensor], actions: torch.Tensor):
        """Joint log-prob (B,), entropy (B,) and value (B,) of given actions (B, N)."""
        logits, value = self.heads(obs)
        return (*score(logits, actions), value)

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        _, out, _ = self.attend(obs)
        return self.value_head(out).squeeze(-1).mean(-1)

    def critic_parameters(self) -> list[nn.Parameter]:
        """The value head: the encoder is shared with the actor (thesis Table 5.8)."""
        return list(self.value_head.parameters())


# ---------------------------------------------------------------------------------------------- newest net


def embed(in_features: int, hidden: int = HIDDEN) -> nn.Sequential:
    return nn.Sequential(nn.Linear(in_features, hidden), nn.ReLU())


class PlannerEncoder(nn.Module):
    """Drone tokens from position, goal, id, velocity and water, plus the global fire context; self-attention
    among drones, then cross-attention to the fire candidates, each with a residual and LayerNorm
    (learning.md 3.2)."""

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS):
        super().__init__()
        self.pos_emb, self.goal_emb, self.vel_emb = embed(2), embed(2), embed(2)
        self.water_emb, self.fire_emb = embed(1), embed(2)
        self.count_emb, self.centroid_emb, self.wind_emb = embed(1), embed(2), embed(2)
        self.id_emb = nn.Embedding(num_drones, hidden)
        self.fusion = nn.Sequential(nn.Linear(5 * hidden, 2 * hidden), nn.ReLU(), nn.Linear(2 * hidden, hidden),
                                    nn.ReLU())
        self.self_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.self_norm = nn.LayerNorm(hidden)
        self.cross_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.cross_norm = nn.LayerNorm(hidden)
        self.register_buffer("drone_ids", torch.arange(num_drones), persistent=False)

    def forward(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Drone representations (B, N, H), fire embeddings (B, K, H) and candidate validity (B, K)."""
        pos, g = obs["drones"], obs["globals"]
        valid = candidate_validity(obs["fires_mask"])
        # velocity = pos_t - pos_{t-1}: always 0, the planner keeps one frame (learning.md 3.2)
        tokens = torch.cat([self.pos_emb(pos), self.goal_emb(obs["goals"]),
                            self.id_emb(self.drone_ids).expand(pos.shape[0], -1, -1),
                            self.vel_emb(torch.zeros_like(pos)), self.water_emb(obs["water"])], dim=-1)
        context = self.count_emb(g[:, 0:1]) + self.centroid_emb(g[:, 1:3]) + self.wind_emb(g[:, 3:5])
        d = self.fusion(tokens) + context.unsqueeze(1)
        d = self.self_norm(d + self.self_attn(d, d, d, need_weights=False)[0])
        fires = self.fire_emb(obs["fires"])
        cross = self.cross_attn(d, fires, fires, key_padding_mask=~valid, need_weights=False)[0]
        return self.cross_norm(d + cross), fires, valid


class PointerPlannerNet(nn.Module):
    """Newest planner (learning.md 3.2): the encoder above, a pointer actor decoded autoregressively over drones
    (each fire at most once per decision, the groundstation any number of times, a learnable soft penalty on
    repeats) and an attention-pooled critic on the shared encoder."""

    def __init__(self, num_drones: int, hidden: int = HIDDEN, heads: int = HEADS):
        super().__init__()
        self.encoder = PlannerEncoder(num_drones, hidden, heads)
        self.query_proj = nn.Linear(hidden, hidden)
        self.key_proj = nn.Linear(hidden, hidden)
        self.log_temperature = nn.Parameter(torch.zeros(1))
        self.log_penalty = nn.Parameter(torch.tensor([1.6]))  # c = e^1.6 ~ 4.95
        self.pool_query = nn.Parameter(torch.randn(1, 1, hidden))
        self.pool_attn = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.value_head = nn.Sequential(nn.Linear(hidden, 2 * hidden), nn.ReLU(), nn.Linear(2 * hidden, 1))
        init_weights(self)
        layer_init(self.value_head[-1], gain=1.0)

    def base_logits(self, d: torch.Tensor, fires: torch.Tensor) -> torch.Tensor:
        """(Wq d_i) . (Wk f_j) / (sqrt(H) T), shape (B, N, K)."""
        temperature = self.log_temperature.clamp(-3.0, 3.0).exp()
        scale = math.sqrt(d.shape[-1]) * temperature
        return torch.bmm(self.query_proj(d), self.key_proj(fires).transpose(1, 2)) / scale

    def penalty(self) -> torch.Tensor:
        return self.log_penalty.clamp(-3.0, 3.0).exp()

    @staticmethod
    def blocked(invalid: torch.Tensor, used: torch.Tensor) -> torch.Tensor:
        """Invalid or already taken candidates; a row with nothing left falls back to the groundstation."""
        blocked = invalid | used
        blocked[..., 0] &= ~blocked.all(-1)
        return blocked

    def decode_logits(self, base: torch.Tensor, valid: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Teacher-forced per-drone logits (B, N, K): drone i sees the choices of drones 0..i-1 in ``actions``."""
        onehot = F.one_hot(actions, base.shape[-1]).to(base.dtype)
        counts = onehot.cumsum(1) - onehot  # how many earlier drones chose j
        used = counts > 0
        used[..., 0] = False  # the groundstation may repeat
        blocked = self.blocked(~valid.unsqueeze(1), used)
        return (base - self.penalty() * counts).masked_fill(blocked, float("-inf"))

    def critic(self, d: torch.Tensor) -> torch.Tensor:
        pooled = self.pool_attn(self.pool_query.expand(d.shape[0], -1, -1), d, d, need_weights=False)[0]
        return self.value_head(pooled.squeeze(1)).squeeze(-1)

    def forward_act(self, obs: dict[str, torch.Tensor], deterministic: bool = False,
                    generator: torch.Generator | None = None):
        """Actions (B, N), joint log-prob (B,), entropy (B,) and value (B,), decoding drones in id order."""
        d, fires, valid = self.encoder(obs)
        base = self.base_logits(d, fires)
        B, N, K = base.shape
        c = self.penalty()
        counts = base.new_zeros(B, K)
        used = torch.zeros(B, K, dtype=torch.bool, device=base.device)
        actions = torch.empty(B, N, dtype=torch.long, device=base.device)
        with torch.no_grad():
            for i in range(N):
                row = (base[:, i] - c * counts).masked_fill(self.blocked(~valid, used), float("-inf"))
                a = sample_rows(row, deterministic, generator)
                actions[:, i] = a
                counts.scatter_add_(1, a.unsqueeze(1), torch.ones_like(counts[:, :1]))
                used.scatter_(1, a.unsqueeze(1), (a != 0).unsqueeze(1))
        # score the chosen actions with the same teacher-forced computation as evaluate(), so both agree exactly
        log_prob, entropy = score(self.decode_logits(base, valid, actions), actions)
        return actions, log_prob, entropy, self.critic(d)

    def evaluate(self, obs: dict[str, torch.Tensor], actions: torch.Tensor):
        """Joint log-prob (B,), entropy (B,) and value (B,) of given actions (B, N), teacher-forced."""
        d, fires, valid = self.encoder(obs)
        logits = self.decode_logits(self.base_logits(d, fires), valid, actions)
        return (*score(logits, actions), self.critic(d))

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.critic(self.encoder(obs)[0])

    def critic_parameters(self) -> list[nn.Parameter]:
        """Pooling query, pooling attention and value MLP: the encoder is shared with the actor."""
        return [self.pool_query, *self.pool_attn.parameters(), *self.value_head.parameters()]


PLANNER_NETS = {"thesis": ThesisPlannerNet, "pointer": PointerPlannerNet}


# ---------------------------------------------------------------------------------------------- PPO


class PlannerRollout(NamedTuple):
    """One update's planner data, [T, E, ...] with E = envs (one planner per env).

    ``next_values`` holds V of the true next state: the next row's state, the env's ``final_obs`` where an
    episode was truncated, or the bootstrap state after the last row (as :class:`roshan.algos.ppo.Rollout`).
    """

    obs: dict[str, torch.Tensor]  # each [T, E, ...]; fires padded to one K
    actions: torch.Tensor  # [T, E, N] long candidate indices
    log_probs: torch.Tensor  # [T, E] joint (sum over drones)
    values: torch.Tensor  # [T, E]
    next_values: torch.Tensor  # [T, E]
    rewards: torch.Tensor  # [T, E] raw
    terminations: torch.Tensor  # [T, E] bool
    truncations: torch.Tensor  # [T, E] bool


class PlannerPPO:
    """The planner network and its PPO update (learning.md 6.2 with the joint action of all drones)."""

    def __init__(self, cfg: PlannerPPOConfig, num_drones: int, device: str | torch.device = "cpu"):
        self.cfg = cfg
        self.device = torch.device(device)
        self.net = PLANNER_NETS[cfg.network](num_drones).to(self.device)
        critic = self.net.critic_parameters()
        critic_ids = {id(p) for p in critic}
        self.groups = {"actor": [p for p in self.net.parameters() if id(p) not in critic_ids], "critic": critic}
        self.optimizer = make_optimizer(self.groups["actor"] + critic, cfg.lr, cfg.optim)
        self.scheduler = make_scheduler(self.optimizer, cfg.optim)
        self.scaler = RewardScaler(cfg.reward_eps)
        self.updates = 0
        self.gradient_steps = 0

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor], deterministic: bool = False,
            generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Actions (B, N), joint log-probs (B,) and values (B,). ``generator`` must live on the net's device."""
        actions, log_prob, _, value = self.net.forward_act(trim_candidates(obs), deterministic, generator)
        return actions, log_prob, value

    @torch.no_grad()
    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.net.value(trim_candidates(obs))

    def advantages(self, rollout: PlannerRollout) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Scaled rewards, advantages and returns, each [T, E] (the running std is updated with this horizon)."""
        cfg = self.cfg
        self.scaler.update(rollout.rewards)
        rewards = self.scaler.scale(rollout.rewards)
        terminations, truncations = rollout.terminations, rollout.truncations
        if not cfg.bootstrap_truncated:
            terminations, truncations = terminations | truncations, torch.zeros_like(truncations)
        adv, ret = gae(rewards, rollout.values, rollout.next_values, terminations, truncations, cfg.gamma, cfg.lam)
        return rewards, adv, ret

    def update(self, rollout: PlannerRollout, generator: torch.Generator | None = None) -> dict[str, float]:
        """One PPO update: ``k_epochs`` passes over the shuffled transitions in minibatches of ``batch_size``.
        ``generator`` (CPU) drives the shuffling."""
        cfg = self.cfg
        rewards, adv, ret = self.advantages(rollout)
        flat = lambda x: x.flatten(0, 1)  # noqa: E731  [T, E, ...] -> [T * E, ...]
        obs = {k: flat(v) for k, v in rollout.obs.items()}
        actions, old_logp, b_adv, b_ret = flat(rollout.actions), flat(rollout.log_probs), flat(adv), flat(ret)
        n = old_logp.shape[0]
        stats: dict[str, list[float]] = {k: [] for k in ("actor_loss", "value_loss", "entropy", "approx_kl",
                                                          "clip_fraction")}
        self.net.train()
        for _ in range(cfg.k_epochs):
            order = torch.randperm(n, generator=generator, device="cpu").to(self.device)
            for start in range(0, n, cfg.batch_size):
                idx = order[start:start + cfg.batch_size]
                mb_obs = trim_candidates({k: v[idx] for k, v in obs.items()})
                if not self._minibatch_step(mb_obs, actions[idx], old_logp[idx], b_adv[idx], b_ret[idx], stats):
                    break  # KL early stop: abandon the rest of this epoch (later epochs still start)
        self.updates += 1
        out = {k: (sum(v) / len(v) if v else float("nan")) for k, v in stats.items()}
        out.update(rewards_raw=float(rollout.rewards.mean()), rewards_scaled=float(rewards.mean()),
                   returns=float(ret.mean()), advantages=float(adv.mean()), values=float(rollout.values.mean()),
                   explained_variance=explained_variance(rollout.values, ret),
                   lr=self.optimizer.param_groups[0]["lr"], epochs_steps=len(stats["actor_loss"]))
        return out

    def _minibatch_step(self, obs, actions, old_logp, adv, ret, stats) -> bool:
        """One gradient step; returns False (and takes no step) when the KL early stop triggers."""
        new_logp, entropy, value = self.net.evaluate(obs, actions)
        loss = minibatch_loss(self.cfg, new_logp, old_logp, entropy, value, normalized_advantages(adv), ret, stats)
        if loss is None:
            return False
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        clip_gradients(self.groups, self.cfg.max_grad_norm)
        self.optimizer.step()
        self.scheduler.step()
        self.gradient_steps += 1
        return True

    def state_dict(self) -> dict:
        return {"net": self.net.state_dict(), "optimizer": self.optimizer.state_dict(),
                "scheduler": self.scheduler.state_dict(), "scaler": self.scaler.state_dict(),
                "updates": self.updates, "gradient_steps": self.gradient_steps}

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        self.net.load_state_dict(state["net"])
        if weights_only:
            return
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        self.scaler.load_state_dict(state["scaler"])
        self.updates, self.gradient_steps = state["updates"], state["gradient_steps"]
