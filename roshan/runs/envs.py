"""The vector env a run trains or evaluates on, built from its config."""

from roshan.config import Config
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv


def make_env(cfg: Config, num_envs: int, seed: int, evaluation: bool = False, controller: str = "planner"):
    """The run's vector env: FlyAgent, or planner (``evaluation``: explorers fly and the candidates are the
    detected fires; ``controller="greedy"``: the heuristic baseline)."""
    if cfg.train.algo == "planner":
        return PlannerVectorEnv(num_envs, cfg, cfg.planner, evaluation=evaluation, controller=controller, seed=seed)
    return FlyVectorEnv(num_envs=num_envs, config=cfg, fly=cfg.fly, seed=seed)
