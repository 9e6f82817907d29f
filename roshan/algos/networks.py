"""FlyAgent networks (docs/model/learning.md §2): encoders, actor and critic heads, and the reference initialisation.

Observations arrive as the env's dict: ``agent`` (B, T, 9), ``neighbors`` (B, T, K, 4) and ``neighbors_mask``
(B, T, K) (1 = valid), with B = envs x drones flattened. Each frame is encoded with the same weights and the
T frame embeddings are concatenated (no recurrence), giving 64 * T = 192 features for T = 3.
"""

import copy
import math

import torch
from torch import nn

from roshan.algos.linear import Linear

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
        layers.append(layer_init(Linear(a, b)))
        if final_activation or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class SimpleEncoder(nn.Module):
    """Collision-free encoder: per frame [v, dg - v] -> 64 (docs/model/learning.md §2.1); ignores id, heading,
    neighbours."""

    def __init__(self, frames: int = 3, hidden: int = 64):
        super().__init__()
        self.net = mlp([4, hidden, hidden])
        self.out_features = hidden * frames

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.encode_frames(obs).flatten(-2)

    def encode_frames(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """Per-frame embeddings (..., T, 64); frames never mix, so a frame can be encoded on its own."""
        a = obs["agent"]
        v, dg = a[..., 1:3], a[..., 3:5]
        return self.net(torch.cat([v, dg - v], dim=-1))


class CollisionEncoder(nn.Module):
    """Own features plus attention-pooled neighbours with the NoNeighbor flag (docs/model/learning.md §2.2)."""

    def __init__(self, frames: int = 3, hidden: int = 256, embed: int = 64):
        super().__init__()
        self.own = mlp([9, hidden, hidden])
        self.neighbour = mlp([4, hidden, hidden, embed], final_activation=False)
        self.score = nn.Sequential(layer_init(Linear(embed, embed)), nn.Tanh(), layer_init(Linear(embed, 1)))
        self.norm = nn.LayerNorm(embed)
        self.fusion = mlp([hidden + embed + 1, hidden, embed])
        self.out_features = embed * frames

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.encode_frames(obs).flatten(-2)

    def encode_frames(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """Per-frame embeddings (..., T, 64); frames never mix, so a frame can be encoded on its own."""
        mask = obs["neighbors_mask"] > 0.5  # (B, T, K)
        h = self.encode_neighbours(obs["neighbors"], mask)
        scores = self.score(h).squeeze(-1).masked_fill(~mask, float("-inf"))
        any_valid = mask.any(dim=-1, keepdim=True)
        # softmax over valid slots only; a frame without any valid slot pools to zeros (not NaN)
        weights = torch.softmax(scores.masked_fill(~any_valid, 0.0), dim=-1) * mask
        pooled = self.norm((weights.unsqueeze(-1) * h).sum(dim=-2))
        pooled = pooled * any_valid  # LayerNorm of a zero vector is its bias: keep "no neighbour" at zero
        no_neighbour = (~any_valid).float()
        x = torch.cat([self.own(obs["agent"]), pooled, no_neighbour], dim=-1)
        return self.fusion(x)

    def encode_neighbours(self, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """h_k (B, T, K, embed), zero for invalid slots. Only valid slots go through the MLP: the branch is two
        thirds of the encoder's arithmetic and most slots are empty when drones are spread out, so gathering
        them is the same function (an invalid slot's output is discarded either way) at a fraction of the cost."""
        n_valid = int(mask.sum())
        if n_valid == mask.numel():
            return self.neighbour(neighbours)
        h = neighbours.new_zeros((*mask.shape, self.norm.normalized_shape[0]))
        if n_valid:
            h = h.index_put((mask,), self.neighbour(neighbours[mask]))
        return h


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
        self.mu = layer_init(Linear(width, 2), gain=0.1)
        self.value = layer_init(Linear(width, 1), gain=1.0)
        self.log_std = nn.Parameter(torch.zeros(2))
        self.tanh_mean = tanh_mean

    def actor(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean (B, 2) and std (2,) of the action distribution."""
        mu = self.mu(self.encoder(obs))
        return (torch.tanh(mu) if self.tanh_mean else mu), self.log_std.exp()

    def critic(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        enc = self.critic_encoder if self.critic_encoder is not None else self.encoder
        return self.value(enc(obs)).squeeze(-1)

    def forward(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Mean (B, 2), std (2,) and value (B,); a shared encoder runs once for both heads."""
        return self.from_frames(*self.encode_frames(obs))

    def encode_frames(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Per-frame embeddings (..., T, 64) of the actor's encoder and of the critic's own (None if shared)."""
        za = self.encoder.encode_frames(obs)
        return za, (None if self.critic_encoder is None else self.critic_encoder.encode_frames(obs))

    def from_frames(self, za: torch.Tensor, zc: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor,
                                                                                torch.Tensor]:
        """The heads on per-frame embeddings (..., T, 64), concatenated in frame order."""
        z = za.flatten(-2)
        mu = self.mu(z)
        mean = torch.tanh(mu) if self.tanh_mean else mu
        value = self.value(z if zc is None else zc.flatten(-2)).squeeze(-1)
        return mean, self.log_std.exp(), value


def flatten_drones(obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """(E, N, ...) env observations as a (E * N, ...) batch: the shared policy sees drones as samples."""
    return {k: v.flatten(0, 1) for k, v in obs.items()}


# ---------------------------------------------------------------------------------------------- off-policy heads


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    """Polyak averaging ``target <- tau * source + (1 - tau) * target`` over matching parameters."""
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters(), strict=True):
            t.lerp_(s, tau)


def to_device(obs: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    """The observation dict with every tensor on ``device`` (no copy when it is already there)."""
    return {k: v.to(device) for k, v in obs.items()}


def check_meta(saved: dict | None, expected: dict) -> None:
    """Raise a ValueError naming every mismatching field between a checkpoint's ``meta`` and this learner's."""
    if saved is None:
        raise ValueError(f"checkpoint has no 'meta' entry; expected one for {expected}")
    diff = [f"{k}: checkpoint {saved.get(k)!r}, this run {v!r}" for k, v in expected.items() if saved.get(k) != v]
    if diff:
        raise ValueError("checkpoint made for another configuration (" + "; ".join(diff) + ")")


def frozen_copy(net: nn.Module) -> nn.Module:
    """A deep copy for use as a target network: no gradients, eval mode (docs/model/learning.md §7)."""
    target = copy.deepcopy(net)
    target.requires_grad_(False)
    return target.eval()


def _head(sizes: list[int], gain: float) -> nn.Sequential:
    """ReLU hidden layers (gain sqrt 2) and a linear output layer with its own ``gain`` (docs/model/learning.md §1)."""
    return nn.Sequential(*mlp(sizes[:-1]), layer_init(Linear(sizes[-2], sizes[-1]), gain=gain))


class DeterministicActor(nn.Module):
    """TD3 actor mu(s) = tanh(MLP 400-300-2 on the encoding) (docs/model/learning.md §2.3): (obs dict) -> (B, 2)
    in [-1, 1]."""

    def __init__(self, collision: bool, frames: int = 3):
        super().__init__()
        self.encoder = make_encoder(collision, frames)
        self.net = _head([self.encoder.out_features, 400, 300, 2], gain=0.1)

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return torch.tanh(self.net(self.encoder(obs)))


class MeanActor(nn.Module):
    """IQL actor: the mean head Linear(192, 2) (gain 0.1) on an encoder, (obs dict) -> raw mean mu (B, 2).

    The std is fixed by the algorithm (IQL: exp(-3)), so there is no ``log_std`` parameter.
    """

    def __init__(self, collision: bool, frames: int = 3):
        super().__init__()
        self.encoder = make_encoder(collision, frames)
        self.mu = layer_init(Linear(self.encoder.out_features, 2), gain=0.1)

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.mu(self.encoder(obs))


class TwinQ(nn.Module):
    """Two Q heads Q_i(s, a) = MLP 256-256-1 on [encoder_i(s), a] (docs/model/learning.md §2.3).

    ``encoder`` given: both heads read that (shared, e.g. the actor's) encoder object, and it is encoded once.
    Otherwise each head owns its encoder.
    """

    def __init__(self, collision: bool, frames: int = 3, encoder: nn.Module | None = None):
        super().__init__()
        self.encoder1 = encoder if encoder is not None else make_encoder(collision, frames)
        self.encoder2 = encoder if encoder is not None else make_encoder(collision, frames)
        width = self.encoder1.out_features + 2
        self.q1 = _head([width, 256, 256, 1], gain=1.0)
        self.q2 = _head([width, 256, 256, 1], gain=1.0)

    def forward(self, obs: dict[str, torch.Tensor], actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(obs dict, actions (B, 2)) -> (Q1, Q2), each (B,)."""
        h1 = self.encoder1(obs)
        h2 = h1 if self.encoder2 is self.encoder1 else self.encoder2(obs)
        q1 = self.q1(torch.cat([h1, actions], dim=-1)).squeeze(-1)
        q2 = self.q2(torch.cat([h2, actions], dim=-1)).squeeze(-1)
        return q1, q2

    def q1_value(self, obs: dict[str, torch.Tensor], actions: torch.Tensor) -> torch.Tensor:
        """Q1 alone, (B,): the TD3 actor loss needs only the first head."""
        return self.q1(torch.cat([self.encoder1(obs), actions], dim=-1)).squeeze(-1)


class ValueNet(nn.Module):
    """IQL state value V(s) = MLP 256-256-1 on an encoder (docs/model/learning.md §2.3): (obs dict) -> (B,).

    ``encoder`` given: read that (shared) encoder object; otherwise own one.
    """

    def __init__(self, collision: bool, frames: int = 3, encoder: nn.Module | None = None):
        super().__init__()
        self.encoder = encoder if encoder is not None else make_encoder(collision, frames)
        self.net = _head([self.encoder.out_features, 256, 256, 1], gain=1.0)

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.net(self.encoder(obs)).squeeze(-1)
