"""FlyAgent networks (learning.md 2): encoders, actor and critic heads, and the reference initialisation.

Observations arrive as the env's dict: ``agent`` (B, T, 9), ``neighbors`` (B, T, K, 4) and ``neighbors_mask``
(B, T, K) (1 = valid), with B = envs x drones flattened. Each frame is encoded with the same weights and the
T frame embeddings are concatenated (no recurrence), giving 64 * T = 192 features for T = 3.
"""

import math

import torch
from torch import nn

RELU_GAIN = math.sqrt(2.0)


def layer_init(layer: nn.Linear, gain: float = RELU_GAIN) -> nn.Linear:
    """Orthogonal weight with ``gain`` and zero bias, as the reference initialises every Linear."""
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


def mlp(sizes: list[int], final_activation: bool = True) -> nn.Sequential:
    """Linear-ReLU stack; the last Linear is followed by ReLU only if ``final_activation``."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(layer_init(nn.Linear(a, b)))
        if final_activation or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class SimpleEncoder(nn.Module):
    """Collision-free encoder: per frame [v, dg - v] -> 64 (learning.md 2.1); ignores id, heading, neighbours."""

    def __init__(self, frames: int = 3, hidden: int = 64):
        super().__init__()
        self.net = mlp([4, hidden, hidden])
        self.out_features = hidden * frames

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        a = obs["agent"]
        v, dg = a[..., 1:3], a[..., 3:5]
        return self.net(torch.cat([v, dg - v], dim=-1)).flatten(-2)


class CollisionEncoder(nn.Module):
    """Own features plus attention-pooled neighbours with the NoNeighbor flag (learning.md 2.2)."""

    def __init__(self, frames: int = 3, hidden: int = 256, embed: int = 64):
        super().__init__()
        self.own = mlp([9, hidden, hidden])
        self.neighbour = mlp([4, hidden, hidden, embed], final_activation=False)
        self.score = nn.Sequential(layer_init(nn.Linear(embed, embed)), nn.Tanh(), layer_init(nn.Linear(embed, 1)))
        self.norm = nn.LayerNorm(embed)
        self.fusion = mlp([hidden + embed + 1, hidden, embed])
        self.out_features = embed * frames

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        mask = obs["neighbors_mask"] > 0.5  # (B, T, K)
        h = self.neighbour(obs["neighbors"]) * mask.unsqueeze(-1)  # invalid slots are zeroed
        scores = self.score(h).squeeze(-1).masked_fill(~mask, float("-inf"))
        any_valid = mask.any(dim=-1, keepdim=True)
        # softmax over valid slots only; a frame without any valid slot pools to zeros (not NaN)
        weights = torch.softmax(scores.masked_fill(~any_valid, 0.0), dim=-1) * mask
        pooled = self.norm((weights.unsqueeze(-1) * h).sum(dim=-2))
        pooled = pooled * any_valid  # LayerNorm of a zero vector is its bias: keep "no neighbour" at zero
        no_neighbour = (~any_valid).float()
        x = torch.cat([self.own(obs["agent"]), pooled, no_neighbour], dim=-1)
        return self.fusion(x).flatten(-2)


def make_encoder(collision: bool, frames: int = 3) -> nn.Module:
    return CollisionEncoder(frames) if collision else SimpleEncoder(frames)


class ActorCritic(nn.Module):
    """Stochastic actor (mean head, gain 0.1, state-independent log_std) and value head (gain 1.0).

    With ``share_encoder`` the critic reads the actor's encoding; otherwise it owns a second encoder.
    ``tanh_mean`` squashes the mean (the Gaussian + clip distribution); TanhNormal uses the raw mean.
    """

    def __init__(self, collision: bool, frames: int = 3, share_encoder: bool = True, tanh_mean: bool = True):
        super().__init__()
        self.encoder = make_encoder(collision, frames)
        self.critic_encoder = None if share_encoder else make_encoder(collision, frames)
        width = self.encoder.out_features
        self.mu = layer_init(nn.Linear(width, 2), gain=0.1)
        self.value = layer_init(nn.Linear(width, 1), gain=1.0)
        self.log_std = nn.Parameter(torch.zeros(2))
        self.tanh_mean = tanh_mean

    def actor(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean (B, 2) and std (2,) of the action distribution."""
        mu = self.mu(self.encoder(obs))
        return (torch.tanh(mu) if self.tanh_mean else mu), self.log_std.exp()

    def critic(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        enc = self.critic_encoder if self.critic_encoder is not None else self.encoder
        return self.value(enc(obs)).squeeze(-1)


def flatten_drones(obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """(E, N, ...) env observations as a (E * N, ...) batch: the shared policy sees drones as samples."""
    return {k: v.flatten(0, 1) for k, v in obs.items()}
