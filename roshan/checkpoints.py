"""A training run's folder and its checkpoint files (DESIGN.md, "Training and runs").

```
runs/<name>/
  config.yaml                 the resolved Config
  checkpoints/latest.pt       everything needed to resume (networks, optimisers, schedulers, reward scaler,
  checkpoints/best_reward.pt  RNG states, counters); best_* are written when their metric ties or improves
  checkpoints/best_objective.pt
  tb/                         TensorBoard events
  eval/                       episodes.csv, summary.json, plots
```
Checkpoints are written to a temporary file in the same folder and renamed over the old one, so a run killed
at any moment leaves the previous checkpoint intact.
"""

import contextlib
import fcntl
import os
import shlex
import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import torch

from roshan.config import Config, ConfigError, from_dict, to_dict, upgrade_config_dict
from roshan.io import atomic_file, prepare_output, writing

CHECKPOINTS = ("latest", "best_reward", "best_objective", "best_eval")
# What "best" means for evaluation: the periodic deterministic evaluation when the run had one (it measures the
# policy that is shipped), else the training objective.
BEST_ORDER = ("best_eval", "best_objective")


# ------------------------------------------------------------------------------------------------ folders


def new_run_dir(root: str | Path, name: str) -> Path:
    """``root/name``, or ``root/name_2``, ``_3``... if taken (a run never overwrites another)."""
    root = prepare_output(root, "run folders")  # a read-only or full --root fails here, before any training
    path, k = root / name, 1
    while path.exists():
        k += 1
        path = root / f"{name}_{k}"
    with writing("the run folder", path):
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


class RunBusy(RuntimeError):
    """Another process is training in this run folder."""


@contextlib.contextmanager
def run_lock(run_dir: str | Path) -> Iterator[None]:
    """Hold ``run_dir/.lock`` while training in it: a second process (a second ``--resume``) is refused with
    who holds it instead of both writing checkpoints and event files. The lock dies with its process (flock),
    so a killed run never leaves the folder locked."""
    path = Path(run_dir) / ".lock"
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 4096, 0).decode(errors="replace").strip() or "another process"
        os.close(fd)
        raise RunBusy(f"{run_dir}: a process is training in this run folder ({holder}); wait for it or stop it "
                      "first") from None
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}: {shlex.join(sys.argv)}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock


# ------------------------------------------------------------------------------------------------ checkpoints


def save_checkpoint(state: dict, path: Path) -> None:
    """``torch.save`` to ``path`` atomically: a run killed at any moment leaves the previous checkpoint whole."""
    with atomic_file(path) as f:
        torch.save(state, f)


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
    return upgrade_checkpoint(state)


def upgrade_checkpoint(state: dict) -> dict:
    """A checkpoint of an earlier version in the current layout: the config dict through
    :func:`roshan.config.upgrade_config_dict`, and the planner PPO's single ``optimizer`` / ``scheduler`` as the
    lists of the one PPO class (the network weights are untouched)."""
    state = {**state, "config": upgrade_config_dict(state["config"])}
    agent = state.get("agent")
    if state["algo"] == "planner" and isinstance(agent, dict) and "optimizer" in agent:
        agent = {k: v for k, v in agent.items() if k not in ("optimizer", "scheduler")}
        state["agent"] = {**agent, "optimizers": [state["agent"]["optimizer"]],
                          "schedulers": [state["agent"]["scheduler"]]}
    return state


def config_of_checkpoint(state: dict, where: str) -> Config:
    try:
        return from_dict(Config, upgrade_config_dict(state["config"]), where=where)
    except ConfigError as exc:
        raise ValueError(f"{where}: the checkpoint's config does not fit this version ({exc})") from exc


def check_same_model(cfg: Config, saved: Config, where: str) -> None:
    """Resuming or fine-tuning needs the same network shapes: compare the keys that decide them."""
    keys = {"fly.collision": (cfg.fly.collision, saved.fly.collision),
            "fly.frames": (cfg.fly.frames, saved.fly.frames),
            "drones.num_drones": (cfg.drones.num_drones, saved.drones.num_drones),
            "train.algo": (cfg.train.algo, saved.train.algo),
            "ppo.share_encoder": (cfg.ppo.share_encoder, saved.ppo.share_encoder),
            "planner.network": (cfg.planner.network, saved.planner.network)}
    bad = [f"{k} = {a!r} here but {b!r} in the checkpoint" for k, (a, b) in keys.items() if a != b]
    if bad:
        raise ValueError(f"{where}: checkpoint from another config: " + "; ".join(bad))


def config_dict(cfg: Config) -> dict:
    return to_dict(cfg)
