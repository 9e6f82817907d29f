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
from collections.abc import Callable, Iterator
from pathlib import Path

import torch

from roshan.config import Config, ConfigError, from_dict, to_dict, upgrade_agent_state, upgrade_saved_config
from roshan.io import atomic_file, inside, prepare_output, writing

CHECKPOINTS = ("latest", "best_reward", "best_objective", "best_eval")
# What "best" means for evaluation: the periodic deterministic evaluation when the run had one (it measures the
# policy that is shipped), else the training objective.
BEST_ORDER = ("best_eval", "best_objective")


# ------------------------------------------------------------------------------------------------ folders


def new_run_dir(root: str | Path, name: str) -> Path:
    """``root/name``, or ``root/name_2``, ``_3``... if taken (a run never overwrites another)."""
    path = inside(root, name, "the run folder")  # checked before --root is made: a bad name creates nothing
    root = prepare_output(root, "run folders")  # a read-only or full --root fails here, before any training
    k = 1
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


def newest_checkpoint(run_dir: str | Path) -> Path | None:
    """The checkpoint a resume continues from: ``latest``, or, in a run that lost it, the most recently written of
    the others (each holds the whole state of its update); None if the run has no checkpoint."""
    latest = checkpoint_path(run_dir, "latest")
    if latest.is_file():
        return latest
    others = [p for which in CHECKPOINTS if (p := checkpoint_path(run_dir, which)).is_file()]
    return max(others, key=lambda p: p.stat().st_mtime_ns, default=None)


class RunBusy(RuntimeError):
    """Another process is training in this run folder."""


@contextlib.contextmanager
def folder_lock(path: str | Path, busy: Callable[[str], Exception]) -> Iterator[None]:
    """Hold the lock file ``path`` while this process writes what it guards; where another process holds it,
    raise ``busy(holder)`` (holder: "pid N on HOST: COMMAND") before anything is written. The lock dies with its
    process (flock), so a killed process never leaves it held."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 4096, 0).decode(errors="replace").strip() or "another process"
        os.close(fd)
        raise busy(holder) from None
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}: {shlex.join(sys.argv)}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock


def run_lock(run_dir: str | Path) -> contextlib.AbstractContextManager[None]:
    """Hold ``run_dir/.lock`` while training in it: a second process (a second ``--resume``) is refused with
    who holds it (:class:`RunBusy`) instead of both writing checkpoints and event files."""
    return folder_lock(Path(run_dir) / ".lock", lambda holder: RunBusy(
        f"{run_dir}: a process is training in this run folder ({holder}); wait for it or stop it first"))


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
    :func:`roshan.config.upgrade_saved_config`, and the planner PPO's single ``optimizer`` /
    ``scheduler`` as the lists of the one PPO class (the network weights are untouched)."""
    state = {**state, "config": upgrade_saved_config(state["config"])}
    if "agent" in state:
        state["agent"] = upgrade_agent_state(state["algo"], state["agent"])
    return state


def config_of_checkpoint(state: dict, where: str) -> Config:
    try:
        return from_dict(Config, upgrade_saved_config(state["config"]), where=where)
    except ConfigError as exc:
        raise ValueError(f"{where}: the checkpoint's config does not fit this version ({exc})") from exc


class CheckpointMismatch(ValueError):
    """A checkpoint that does not fit the model, optimisers or setting it is loaded into."""


def setting(cfg: Config, key: str):
    """The value of a dotted config key (``ppo.optim.name``)."""
    value = cfg
    for part in key.split("."):
        value = getattr(value, part)
    return value


def model_keys(cfg: Config) -> tuple[str, ...]:
    """The config keys that decide the network shapes of ``cfg.train.algo`` and the observations it serves."""
    return cfg.train.level.model_keys(cfg)


def optimiser_keys(cfg: Config) -> tuple[str, ...]:
    """The config keys whose optimiser state a resume loads: another family (Adam's moments into SGD) or another
    count of optimisers cannot take it."""
    section = cfg.train.section
    if section == "ppo":  # a run without RND resumes from one with it (its RND state is not read)
        return "ppo.optim.name", "ppo.separate_optimizers", *(("rnd.enabled",) if cfg.rnd.enabled else ())
    return (f"{section}.optim.name",)


def config_differences(cfg: Config, saved: Config, keys) -> list[str]:
    pairs = {k: (setting(cfg, k), setting(saved, k)) for k in keys}
    return [f"{k} = {a!r} here but {b!r} in the checkpoint" for k, (a, b) in pairs.items() if a != b]


def is_optimiser_state(obj) -> bool:
    return isinstance(obj, dict) and set(obj) == {"state", "param_groups"}


def state_layout(obj, prefix: str = "", out: dict | None = None) -> dict[str, str]:
    """What of a (nested) state dict decides whether it loads, by dotted name: each tensor's shape, and each
    optimiser's parameter count per group (its per-parameter state is empty before the first step, so it is
    not compared). Counters, rates and schedules hold no tensors and are left out: they load into any model."""
    out = {} if out is None else out
    if isinstance(obj, torch.Tensor):
        out[prefix] = f"shape {tuple(obj.shape)}"
    elif is_optimiser_state(obj):
        for i, group in enumerate(obj["param_groups"]):
            out[f"{prefix}.param_groups[{i}]"] = f"{len(group['params'])} parameters"
    elif isinstance(obj, dict):
        for k, v in obj.items():
            state_layout(v, f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            state_layout(v, f"{prefix}[{i}]", out)
    return out


def layout_differences(here: dict, saved: dict) -> list[str]:
    """Every name whose shape or count differs between two state dicts, or that only one of them has."""
    a, b = state_layout(here), state_layout(saved)
    diffs = []
    for name in sorted(a.keys() | b.keys()):
        if name not in b:
            diffs.append(f"{name} not in the checkpoint")
        elif name not in a:
            diffs.append(f"{name} in the checkpoint only")
        elif a[name] != b[name]:
            diffs.append(f"{name} {a[name]} here but {b[name].removeprefix('shape ')} in the checkpoint")
    return diffs


def raise_mismatch(where: str, diffs: list[str], limit: int = 8) -> None:
    """One line naming the file and the differing keys (the first ``limit``: a whole network of another shape
    would otherwise fill the screen)."""
    if diffs:
        more = f"; and {len(diffs) - limit} more" if len(diffs) > limit else ""
        raise CheckpointMismatch(f"{where}: checkpoint from another config, it does not fit this one: "
                                 + "; ".join(diffs[:limit]) + more)


def check_same_model(cfg: Config, saved: Config, where: str) -> None:
    """Resuming or fine-tuning needs the same network shapes: compare the keys that decide them."""
    raise_mismatch(where, config_differences(cfg, saved, dict.fromkeys(model_keys(cfg) + model_keys(saved))))


def check_fits(agent, agent_state: dict, cfg: Config, saved: Config, where: str, weights_only: bool) -> None:
    """Refuse, before anything is loaded, a checkpoint (``agent_state``, its ``saved`` config) that does not fit
    ``agent`` built for ``cfg``: the config keys of its networks (and, unless ``weights_only``, of its
    optimisers), then every parameter name and shape; ``weights_only`` compares only ``agent.weight_keys``."""
    keys = model_keys(cfg) + model_keys(saved)
    if not weights_only and cfg.train.algo == saved.train.algo:
        keys += optimiser_keys(cfg)
    diffs = config_differences(cfg, saved, dict.fromkeys(keys))
    here = agent.state_dict()
    if weights_only:
        here = {k: v for k, v in here.items() if k in agent.weight_keys}
    agent_state = {k: v for k, v in agent_state.items() if k in here}  # what the agent does not load is not read
    if not diffs or cfg.train.algo == saved.train.algo:  # another algorithm: its names would only repeat that
        diffs += layout_differences(here, agent_state)
    raise_mismatch(where, diffs)


def config_dict(cfg: Config) -> dict:
    return to_dict(cfg)
