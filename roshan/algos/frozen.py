"""Trained agents loaded from a checkpoint for deterministic acting: evaluation, and the frozen low-level
FlyAgents that the planner level flies its drones and explorers with."""

from pathlib import Path

import torch

from roshan.algos.agent import Agent
from roshan.algos.agents import make_agent
from roshan.checkpoints import config_of_checkpoint, load_checkpoint, resolve_checkpoint

REPO_ROOT = Path(__file__).resolve().parents[2]


def load_agent(target: str | Path, which: str = "best", device: str | torch.device = "cpu"):
    """(config, agent, checkpoint path) of a run folder or a checkpoint file."""
    path = resolve_checkpoint(target, which)
    state = load_checkpoint(path)
    cfg = config_of_checkpoint(state, str(path))
    agent = make_agent(cfg, device)
    agent.load_state_dict(state["agent"], weights_only=True)
    return cfg, agent, path


def policy_fn(agent: Agent):
    """Deterministic actions from a batch of observations: (B, 2) from flattened drone observations for
    FlyAgents, (E, N) candidate indices for the planner."""
    return agent.act_deterministic


class FrozenFlyPolicy:
    """A trained FlyAgent (run folder or checkpoint) as a deterministic controller of a drone group."""

    def __init__(self, target: str | Path, device: str | torch.device = "cpu"):
        path = Path(target)
        if not path.exists() and not path.is_absolute() and (REPO_ROOT / path).exists():
            path = REPO_ROOT / path  # configs name the shipped models relative to the repository
        if not path.exists():
            raise FileNotFoundError(f"planner low-level FlyAgent {str(target)!r}: no such run folder or checkpoint "
                                    "(set planner.fly_model / planner.explorer_model)")
        self.config, agent, self.path = load_agent(path, device=device)
        self.frames = self.config.fly.frames
        self._act = policy_fn(agent)

    def __call__(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        e, n = obs["agent"].shape[:2]
        return self._act({k: v.flatten(0, 1) for k, v in obs.items()}).view(e, n, 2)
