"""FlyAgent action distributions (docs/model/learning.md §4): Gaussian with clipping, and the tanh-squashed Gaussian."""

import math

import numpy as np
import torch
from torch.nn import functional as F

EDGE = 1e-6  # stored actions are clamped to +-(1 - EDGE) before atanh


def normal(base: torch.distributions.Normal, generator: torch.Generator | None) -> torch.Tensor:
    """A sample of ``base`` from ``generator``: ``Normal.sample`` takes none, and with ``generator = None`` this is
    the same ``torch.normal`` call on the same global RNG stream."""
    with torch.no_grad():
        return torch.normal(base.loc, base.scale, generator=generator)


class ClippedGaussian:
    """a ~ N(mean, std) clamped to [-1, 1]; the log-prob is the Gaussian density at the clamped action."""

    def __init__(self, mean: torch.Tensor, std: torch.Tensor):
        self.base = torch.distributions.Normal(mean, std.expand_as(mean))

    def sample(self) -> torch.Tensor:
        return self.base.sample().clamp(-1.0, 1.0)

    # The "raw" interface: what a learner stores is the clamped action itself.
    def sample_raw(self, generator: torch.Generator | None = None) -> torch.Tensor:
        """A clamped sample; without ``generator`` it draws from torch's global RNG, exactly as ``sample``."""
        return normal(self.base, generator).clamp(-1.0, 1.0)

    def log_prob_raw(self, raw: torch.Tensor) -> torch.Tensor:
        return self.log_prob(raw)

    @staticmethod
    def to_action(raw: torch.Tensor) -> torch.Tensor:
        return raw

    def log_prob(self, actions: torch.Tensor) -> torch.Tensor:
        """Summed over the action dimensions: [B, A] -> [B]."""
        return self.base.log_prob(actions.clamp(-1.0, 1.0)).sum(-1)

    def entropy(self) -> torch.Tensor:
        """Entropy of the diagonal Normal, summed over dimensions: [B]."""
        return self.base.entropy().sum(-1)

    @property
    def mode(self) -> torch.Tensor:
        return self.mode_of(self.base.mean)

    @staticmethod
    def mode_of(mean: torch.Tensor) -> torch.Tensor:
        """The deterministic action of a mean, without building the distribution."""
        return mean.clamp(-1.0, 1.0)


# Gauss-Hermite nodes and weights for E[f(Z)], Z ~ N(0, 1): sqrt(2) x_i and w_i / sqrt(pi) of the 5-point rule.
# Written out (numpy.polynomial.hermite.hermgauss(5), to the last bit), not computed at import: numpy finds them with
# its LAPACK, whose kernels are chosen by CPU, and training must not depend on which CPU imported this module
# (roshan/reproducible.py). tests/algos pin them against hermgauss.
_GH_X = np.array([-2.0201828704560856, -0.9585724646138185, 0.0, 0.9585724646138185, 2.0201828704560856])
_GH_W = np.array([0.019953242059045917, 0.3936193231522411, 0.9453087204829418, 0.3936193231522411,
                  0.019953242059045917])
_GH_NODES = torch.tensor(_GH_X * math.sqrt(2.0), dtype=torch.float32)
_GH_WEIGHTS = torch.tensor(_GH_W / math.sqrt(math.pi), dtype=torch.float32)


class TanhNormal:
    """a = tanh(u), u ~ N(mu, std): the exact squashed-Gaussian density, reparameterised sampling."""

    def __init__(self, mu: torch.Tensor, std: torch.Tensor):
        self.base = torch.distributions.Normal(mu, std.expand_as(mu))

    def rsample(self) -> torch.Tensor:
        return torch.tanh(self.base.rsample())

    def sample(self) -> torch.Tensor:
        return torch.tanh(self.base.sample())

    # The "raw" interface: a learner stores the pre-tanh sample u and computes log p exactly from it. Inverting
    # a stored tanh(u) breaks once |u| > ~7.3, where tanh(u) rounds to 1 in float32 and the clamp to 1 - 1e-6
    # maps every such u to 7.25: old and new log-probs then disagree wildly (our first collision run collapsed
    # with approx KL ~1e5 after 1.5M steps; the reference inverts the clamped action, docs/model/learning.md §4).
    def sample_raw(self, generator: torch.Generator | None = None) -> torch.Tensor:
        return normal(self.base, generator)

    def log_prob_raw(self, u: torch.Tensor) -> torch.Tensor:
        """log p(tanh(u)) from u itself: [B, A] -> [B]."""
        log_det = 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))
        return (self.base.log_prob(u) - log_det).sum(-1)

    @staticmethod
    def to_action(u: torch.Tensor) -> torch.Tensor:
        return torch.tanh(u)

    def log_prob(self, actions: torch.Tensor) -> torch.Tensor:
        """log p(a) = log N(u) - log(1 - tanh(u)^2), u = atanh(a), summed over dimensions: [B, A] -> [B].

        log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)) is the form that stays finite for large |u|.
        """
        a = actions.clamp(-1.0 + EDGE, 1.0 - EDGE)
        u = torch.atanh(a)
        log_det = 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))
        return (self.base.log_prob(u) - log_det).sum(-1)

    def entropy(self) -> torch.Tensor:
        """Entropy of the base Normal averaged over dimensions (the reference's choice; no closed form
        exists for the squashed density): [B]."""
        return self.base.entropy().mean(-1)

    def squashed_entropy(self) -> torch.Tensor:
        """Entropy of the actions themselves, H[tanh(u)] = H[u] + E[log(1 - tanh(u)^2)], averaged over dimensions
        like :meth:`entropy`: [B]. The expectation is a 5-node Gauss-Hermite quadrature (deterministic, smooth in
        the mean and std). Unlike the base entropy it falls as the mean moves into tanh's flat tails, where
        every sample gives the same action: its bonus pulls a saturating mean back (see ``ppo.tanh_entropy``)."""
        mu, std = self.base.mean, self.base.stddev
        u = mu.unsqueeze(-1) + std.unsqueeze(-1) * _GH_NODES.to(mu)  # [B, A, 5]
        log_det = 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))
        return (self.base.entropy() + (log_det * _GH_WEIGHTS.to(mu)).sum(-1)).mean(-1)

    @property
    def mode(self) -> torch.Tensor:
        return self.mode_of(self.base.mean)

    @staticmethod
    def mode_of(mu: torch.Tensor) -> torch.Tensor:
        """The deterministic action of a pre-squash mean, without building the distribution."""
        return torch.tanh(mu)
