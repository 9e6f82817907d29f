"""A training run: its typed config, its folder and its checkpoints (DESIGN.md, "Training and runs").

```
runs/<name>/
  config.yaml                 the resolved RunConfig
  checkpoints/latest.pt       everything needed to resume (networks, optimisers, schedulers, reward scaler,
  checkpoints/best_reward.pt  RNG states, counters); best_* are written when their metric ties or improves
  checkpoints/best_objective.pt
  tb/                         TensorBoard events
  eval/                       episodes.csv, summary.json, plots
```
Checkpoints are written to a temporary file in the same folder and renamed over the old one, so a run killed
at any moment leaves the previous checkpoint intact.
"""

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import torch

from roshan.algos.iql import IQLConfig
from roshan.algos.planner import PlannerPPOConfig
from roshan.algos.ppo import PPOConfig
from roshan.algos.rnd import RNDConfig
from roshan.algos.td3 import TD3Config
from roshan.config import (
    Config,
    ConfigError,
    DroneConfig,
    FireConfig,
    IgnitionConfig,
    MapConfig,
    SimConfig,
    WindConfig,
    choice,
    from_dict,
    load_config,
    num,
    to_dict,
)
from roshan.env.fly import FlyConfig
from roshan.env.planner import PlannerConfig

CHECKPOINTS = ("latest", "best_reward", "best_objective", "best_eval")
# What "best" means for evaluation: the periodic deterministic evaluation when the run had one (it measures the
# policy that is shipped), else the training objective.
BEST_ORDER = ("best_eval", "best_objective")


@dataclass(frozen=True)
class TrainConfig:
    """The training loop: batch of envs, budget, evaluation and seeds."""

    algo: str = choice("ppo", ("ppo", "td3", "iql", "planner"), doc="planner: PPO on the PlannerAgent level")
    num_envs: int = num(64, 1, doc="environments stepped together")
    total_steps: int = num(1_000_000, 0, doc="env steps (each moves every drone once; planner: decisions); "
                                                "0 = no limit")
    max_updates: int = num(0, 0, doc="updates; 0 = no limit")
    max_minutes: float = num(0.0, 0.0, doc="wall-clock budget of one run; 0 = no limit")
    seed: int = num(0, 0, 2**31 - 1)
    objective_window: int = num(100, 1, doc="training episodes in the success-rate objective")
    eval_every: int = num(0, 0, doc="evaluate every K updates; 0 = only at the end")
    eval_episodes: int = num(200, 1)
    eval_envs: int = num(50, 1)
    auto_train: int = num(1, 1, doc="independent runs (seeds seed, seed+1, ...) in sequence, then evaluation")
    torch_threads: int = num(0, 0, doc="torch intra-op threads; 0 = torch's default")
    buffer_path: str = ""  # IQL: the replay buffer to learn from (``roshan eval --save-buffer``)
    init_from: str = ""  # start from these network weights (a run folder's best or a checkpoint): fine-tuning


@dataclass(frozen=True)
class RunConfig:
    """Everything a run needs: the simulator sections of :class:`roshan.config.Config`, the FlyAgent task, the
    training loop and each algorithm's hyperparameters."""

    map: MapConfig = field(default_factory=MapConfig)
    fire: FireConfig = field(default_factory=FireConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    ignition: IgnitionConfig = field(default_factory=IgnitionConfig)
    drones: DroneConfig = field(default_factory=DroneConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    fly: FlyConfig = field(default_factory=FlyConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    td3: TD3Config = field(default_factory=TD3Config)
    iql: IQLConfig = field(default_factory=IQLConfig)
    rnd: RNDConfig = field(default_factory=RNDConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    planner_ppo: PlannerPPOConfig = field(default_factory=PlannerPPOConfig)

    def env_config(self) -> Config:
        return Config(map=self.map, fire=self.fire, wind=self.wind, ignition=self.ignition, drones=self.drones,
                      sim=self.sim)


def load_run_config(path: str | Path | None, overrides: list[str] | tuple[str, ...] = ()) -> RunConfig:
    """A YAML run config plus ``section.key=value`` overrides, validated (errors name the file and key)."""
    return load_config(path, overrides, cls=RunConfig)


def run_config_from_dict(data: dict, where: str = "checkpoint") -> RunConfig:
    return from_dict(RunConfig, data, where=where)


# ------------------------------------------------------------------------------------------------ folders


def new_run_dir(root: str | Path, name: str) -> Path:
    """``root/name``, or ``root/name_2``, ``_3``... if taken (a run never overwrites another)."""
    root = Path(root)
    path, k = root / name, 1
    while path.exists():
        k += 1
        path = root / f"{name}_{k}"
    (path / "checkpoints").mkdir(parents=True)
    return path


def checkpoint_path(run_dir: Path, which: str = "latest") -> Path:
    return Path(run_dir) / "checkpoints" / f"{which}.pt"


def resolve_checkpoint(target: str | Path, which: str = "best") -> Path:
    """A checkpoint file, or a run folder's ``which`` checkpoint (falling back to ``latest``); ``best`` is the
    first of ``BEST_ORDER`` the run has."""
    target = Path(target)
    if target.is_file():
        return target
    if not target.is_dir():
        raise FileNotFoundError(f"{target}: no such run folder or checkpoint file")
    for name in (*(BEST_ORDER if which == "best" else (which,)), "latest"):
        p = checkpoint_path(target, name)
        if p.is_file():
            return p
    raise FileNotFoundError(f"{target}: no checkpoints/{which}.pt or checkpoints/latest.pt in this run folder")


# ------------------------------------------------------------------------------------------------ checkpoints


def save_checkpoint(state: dict, path: Path) -> None:
    """``torch.save`` to a temporary file next to ``path``, fsync, then rename over ``path`` (atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_checkpoint(path: str | Path) -> dict:
    """A checkpoint written by :func:`save_checkpoint`; a clear error names the file if it is not one."""
    path = Path(path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except FileNotFoundError:
        raise
    except Exception as exc:  # truncated, not a torch file, ...
        raise ValueError(f"{path}: not a readable ROSHAN checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(state, dict) or "config" not in state or "algo" not in state:
        raise ValueError(f"{path}: not a ROSHAN checkpoint (no 'config'/'algo' entries)")
    return state


def config_of_checkpoint(state: dict, where: str) -> RunConfig:
    try:
        return run_config_from_dict(state["config"], where=where)
    except ConfigError as exc:
        raise ValueError(f"{where}: the checkpoint's config does not fit this version ({exc})") from exc


def check_same_model(cfg: RunConfig, saved: RunConfig, where: str) -> None:
    """Resuming or fine-tuning needs the same network shapes: compare the keys that decide them."""
    keys = {"fly.collision": (cfg.fly.collision, saved.fly.collision),
            "fly.frames": (cfg.fly.frames, saved.fly.frames),
            "drones.num_drones": (cfg.drones.num_drones, saved.drones.num_drones),
            "train.algo": (cfg.train.algo, saved.train.algo),
            "ppo.share_encoder": (cfg.ppo.share_encoder, saved.ppo.share_encoder)}
    bad = [f"{k} = {a!r} here but {b!r} in the checkpoint" for k, (a, b) in keys.items() if a != b]
    if bad:
        raise ValueError(f"{where}: checkpoint from another config: " + "; ".join(bad))


def config_dict(cfg: RunConfig) -> dict:
    return to_dict(cfg)
