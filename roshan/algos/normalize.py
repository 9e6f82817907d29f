"""Reward scaling by a running standard deviation, without shifting (docs/model/learning.md §6.2 step 1)."""

import torch


class RewardScaler:
    """Running mean and variance of raw rewards (parallel-variance merge, Chan et al. 1979); rewards are divided
    by ``sqrt(var + eps)`` and never shifted, so the sign of every reward survives the scaling.

    The reference starts at mean 0, variance 1 and count 1e-4 and uses ``eps`` = 1e-8 (thesis-era) or 1e-4
    (newest code).
    """

    def __init__(self, eps: float = 1e-8, count: float = 1e-4):
        self.mean = 0.0
        self.var = 1.0
        self.count = count
        self.eps = eps

    def update(self, rewards: torch.Tensor) -> None:
        """Merge a batch of raw rewards (any shape) into the running moments."""
        x = rewards.detach().double().flatten()
        n = x.numel()
        if n == 0:
            return
        batch_mean = float(x.mean())
        batch_var = float(x.var(unbiased=False))
        delta = batch_mean - self.mean
        total = self.count + n
        m2 = self.var * self.count + batch_var * n + delta * delta * self.count * n / total
        self.mean += delta * n / total
        self.var = m2 / total
        self.count = total

    @property
    def std(self) -> float:
        return (self.var + self.eps) ** 0.5

    def scale(self, rewards: torch.Tensor) -> torch.Tensor:
        return rewards / self.std

    def state_dict(self) -> dict:
        return {"mean": self.mean, "var": self.var, "count": self.count, "eps": self.eps}

    def load_state_dict(self, state: dict) -> None:
        self.mean, self.var, self.count, self.eps = state["mean"], state["var"], state["count"], state["eps"]
