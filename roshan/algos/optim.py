"""Optimisers and learning-rate schedules from config, shared by PPO, TD3 and IQL (docs/model/learning.md §6.3)."""


import torch

from roshan.config import OptimConfig

OPTIMIZERS = {"adam": torch.optim.Adam, "adamw": torch.optim.AdamW, "sgd": torch.optim.SGD,
              "rmsprop": torch.optim.RMSprop, "radam": torch.optim.RAdam}


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
