"""Optimisers and learning-rate schedules from config, shared by PPO, TD3 and IQL (learning.md 6.3)."""

from dataclasses import dataclass

import torch

from roshan.config import choice, num

OPTIMIZERS = {"adam": torch.optim.Adam, "adamw": torch.optim.AdamW, "sgd": torch.optim.SGD,
              "rmsprop": torch.optim.RMSprop, "radam": torch.optim.RAdam}
SCHEDULERS = ("cosine", "cosine_restarts", "step", "exponential", "constant", "none")


@dataclass(frozen=True)
class OptimConfig:
    """Optimiser and schedule. Defaults are the thesis-era ones: Adam(0.9, 0.999, eps 1e-5) with a cosine
    schedule of T_max 1e6 steps, stepped per gradient step (effectively constant over a run)."""

    name: str = choice("adam", tuple(OPTIMIZERS))
    beta1: float = num(0.9, 0.0, 1.0, hi_open=True)
    beta2: float = num(0.999, 0.0, 1.0, hi_open=True)
    eps: float = num(1e-5, 0.0, lo_open=True)
    weight_decay: float = num(0.0, 0.0)
    momentum: float = num(0.0, 0.0, 1.0, doc="SGD / RMSprop momentum")
    scheduler: str = choice("cosine", SCHEDULERS)
    t_max: int = num(1_000_000, 1, doc="cosine: steps per half period")
    step_size: int = num(10_000, 1, doc="step: steps between decays")
    decay: float = num(0.99, 0.0, 1.0, lo_open=True, doc="step / exponential: factor per decay")
    min_lr: float = num(0.0, 0.0, doc="cosine: eta_min")


def make_optimizer(params, lr: float, cfg: OptimConfig) -> torch.optim.Optimizer:
    """The optimiser of ``cfg`` over ``params`` (a list of tensors or of parameter-group dicts)."""
    cls = OPTIMIZERS[cfg.name]
    if cfg.name in ("adam", "adamw", "radam"):
        return cls(params, lr=lr, betas=(cfg.beta1, cfg.beta2), eps=cfg.eps, weight_decay=cfg.weight_decay)
    if cfg.name == "rmsprop":
        return cls(params, lr=lr, eps=cfg.eps, weight_decay=cfg.weight_decay, momentum=cfg.momentum)
    return cls(params, lr=lr, weight_decay=cfg.weight_decay, momentum=cfg.momentum)


def make_scheduler(optimizer: torch.optim.Optimizer, cfg: OptimConfig) -> torch.optim.lr_scheduler.LRScheduler:
    """The schedule of ``cfg``, stepped once per gradient step; ``none`` and ``constant`` keep the rate."""
    s = torch.optim.lr_scheduler
    if cfg.scheduler == "cosine":
        return s.CosineAnnealingLR(optimizer, T_max=cfg.t_max, eta_min=cfg.min_lr)
    if cfg.scheduler == "cosine_restarts":
        return s.CosineAnnealingWarmRestarts(optimizer, T_0=cfg.t_max, eta_min=cfg.min_lr)
    if cfg.scheduler == "step":
        return s.StepLR(optimizer, step_size=cfg.step_size, gamma=cfg.decay)
    if cfg.scheduler == "exponential":
        return s.ExponentialLR(optimizer, gamma=cfg.decay)
    return s.ConstantLR(optimizer, factor=1.0, total_iters=0)
