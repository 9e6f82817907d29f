"""Which algorithm object a config asks for (``train.algo``), with fresh networks."""

import torch

from roshan.algos.iql import IQL
from roshan.algos.planner import PlannerPPO
from roshan.algos.ppo import PPO
from roshan.algos.td3 import TD3
from roshan.config import Config


def make_agent(cfg: Config, device: str | torch.device = "cpu"):
    """PPO, TD3, IQL or the planner's PPO for ``cfg.train.algo``."""
    collision, frames = cfg.fly.collision, cfg.fly.frames
    if cfg.train.algo == "ppo":
        return PPO(cfg.ppo, collision, frames, device)
    if cfg.train.algo == "planner":
        return PlannerPPO(cfg.planner_ppo, cfg.drones.num_drones, device)
    if cfg.train.algo == "td3":
        return TD3(cfg.td3, collision, frames, device)
    return IQL(cfg.iql, collision, frames, device)
