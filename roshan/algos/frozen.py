"""Trained agents loaded from a checkpoint for deterministic acting: evaluation, and the frozen low-level
FlyAgents that the planner level flies its drones and explorers with."""

from pathlib import Path

import torch

from roshan.algos.agent import Agent
from roshan.algos.agents import make_agent
from roshan.checkpoints import (
    CheckpointMismatch,
    check_fits,
    config_differences,
    config_of_checkpoint,
    load_checkpoint,
    model_keys,
    resolve_checkpoint,
    setting,
)
from roshan.config import Config, apply_overrides, check_model_level

REPO_ROOT = Path(__file__).resolve().parents[2]


def load_agent(target: str | Path, which: str = "best", device: str | torch.device = "cpu"):
    """(config, agent, checkpoint path) of a run folder or a checkpoint file."""
    path = resolve_checkpoint(target, which)
    state = load_checkpoint(path)
    cfg = config_of_checkpoint(state, str(path))
    agent = make_agent(cfg, device)
    # the networks are built from the checkpoint's own config, so only an edited or foreign file fails here
    check_fits(agent, state["agent"], cfg, cfg, str(path), weights_only=True)
    agent.load_state_dict(state["agent"], weights_only=True)
    return cfg, agent, path


def fly_model_path(target: str | Path, key: str) -> Path:
    """A planner's low-level FlyAgent (``key``: planner.fly_model / planner.explorer_model): a run folder or
    checkpoint, relative to the repository when it is not found where the command runs."""
    path = Path(target)
    if not path.exists() and not path.is_absolute() and (REPO_ROOT / path).exists():
        path = REPO_ROOT / path  # configs name the shipped models relative to the repository
    if not path.exists():
        raise FileNotFoundError(f"planner low-level FlyAgent {str(target)!r}: no such run folder or checkpoint "
                                f"(set {key})")
    return path


def check_fly_model(target: str | Path, key: str = "planner.fly_model") -> None:
    """Refuse a planner checkpoint as a low-level FlyAgent before any env is built: it would be asked to act on
    drone observations it has never seen."""
    path = resolve_checkpoint(fly_model_path(target, key))
    refuse_other_level(config_of_checkpoint(load_checkpoint(path), str(path)), target, path, key)


def refuse_other_level(cfg: Config, target: str | Path, path: Path, key: str) -> None:
    check_model_level(key, cfg.train.level, f"{key} = {str(target)!r}: {path}")


def check_setting(trained: Config, cfg: Config, where: str | Path) -> None:
    """Refuse, before any env is built, an evaluation setting (``cfg``: the checkpoint's config plus --set) that
    the network trained under ``trained`` cannot serve: other observation shapes (drones of a planner, frames or
    collision of a FlyAgent), or a planner checkpoint as the planner's low-level FlyAgents."""
    diffs = config_differences(cfg, trained, model_keys(trained))
    if diffs:
        raise CheckpointMismatch(f"{where}: the network cannot serve this setting: " + "; ".join(diffs))
    for key in cfg.train.level.frozen_models:
        check_fly_model(setting(cfg, key), key)


def load_for_acting(target: str | Path, which: str, overrides, device: str | torch.device = "cpu"):
    """(trained config, acting config, agent, checkpoint path): a checkpoint loaded for deterministic acting under
    ``overrides`` (``section.key=value``), refused before any env is built where its network cannot serve them."""
    trained, agent, path = load_agent(target, which, device)
    cfg = apply_overrides(trained, overrides) if overrides else trained
    check_setting(trained, cfg, path)
    return trained, cfg, agent, path


def policy_fn(agent: Agent):
    """Deterministic actions from a batch of observations: (B, 2) from flattened drone observations for
    FlyAgents, (E, N) candidate indices for the planner."""
    return agent.act_deterministic


class FrozenFlyPolicy:
    """A trained FlyAgent (run folder or checkpoint) as a deterministic controller of a drone group."""

    def __init__(self, target: str | Path, device: str | torch.device = "cpu", key: str = "planner.fly_model"):
        path = fly_model_path(target, key)
        self.config, agent, self.path = load_agent(path, device=device)
        refuse_other_level(self.config, target, self.path, key)
        self.frames = self.config.fly.frames
        self._agent = agent
        self._act = policy_fn(agent)

    def new_cache(self):
        """An acting cache for one drone group (``__call__``'s ``cache``): the env that owns the group keeps it
        and marks the rows (envs x drones) whose stacks it restarted."""
        return self._agent.new_cache()

    def __call__(self, obs: dict[str, torch.Tensor], cache=None) -> torch.Tensor:
        """Actions (E, N, 2) for stacked frames (E, N, F, ...); with ``cache`` (:meth:`new_cache`, kept for these
        rows between consecutive env steps) only the newest frame is encoded, which gives the same actions."""
        e, n = obs["agent"].shape[:2]
        return self._act({k: v.flatten(0, 1) for k, v in obs.items()}, cache).view(e, n, 2)
