"""Which agent a config asks for (``train.algo``), with fresh networks."""

import torch

from roshan.algos.agent import Agent
from roshan.algos.iql import IQL
from roshan.algos.policies import FlyPolicy, PlannerPolicy
from roshan.algos.ppo import PPO
from roshan.algos.td3 import TD3
from roshan.config import Config, PlannerConfig, PPOConfig, RNDConfig


def fly_ppo(cfg: PPOConfig, collision: bool, frames: int = 3, device: str | torch.device = "cpu",
            rnd: RNDConfig | None = None) -> PPO:
    """PPO over the FlyAgent actor-critic."""
    return PPO(cfg, FlyPolicy(cfg, collision, frames), device, rnd)


def planner_ppo(cfg: PPOConfig, planner: PlannerConfig, num_drones: int, device: str | torch.device = "cpu",
                rnd: RNDConfig | None = None, resources: bool = False, bases: int = 1) -> PPO:
    """PPO over the planner network ``planner`` (the section) describes for ``num_drones`` drones; ``resources``:
    their observation has its resource parts (both from :meth:`roshan.config.sim.DroneConfig.fleet_shape`);
    ``bases``: its candidate list starts with that many bases."""
    return PPO(cfg, PlannerPolicy(planner, num_drones, resources, bases), device, rnd)


def make_agent(cfg: Config, device: str | torch.device = "cpu", seed: int | None = None) -> Agent:
    """PPO (FlyAgent or planner policy), TD3 or IQL for ``cfg.train.algo``, with fresh networks; given ``seed``,
    their initial weights come from it and torch's global RNG is left as the caller had it."""
    if seed is None:
        return AGENTS[cfg.train.algo](cfg, device)
    # torch's layers draw their initial weights from the global RNG only; forked, the caller's stream is untouched.
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return AGENTS[cfg.train.algo](cfg, device)


AGENTS = {
    "ppo": lambda cfg, device: fly_ppo(cfg.ppo, cfg.fly.collision, cfg.fly.frames, device, cfg.rnd),
    "planner": lambda cfg, device: planner_ppo(cfg.ppo, cfg.planner, device=device, rnd=cfg.rnd,
                                               bases=cfg.drones.bases, **cfg.drones.fleet_shape()),
    "td3": lambda cfg, device: TD3(cfg.td3, cfg.fly.collision, cfg.fly.frames, device),
    "iql": lambda cfg, device: IQL(cfg.iql, cfg.fly.collision, cfg.fly.frames, device),
}
