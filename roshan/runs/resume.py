"""A run's folder: starting one, and what a resume continues from (its newest whole checkpoint and config)."""

import sys
import time
from pathlib import Path

from roshan.algos.agents import make_agent
from roshan.checkpoints import (
    check_fits,
    check_same_model,
    checkpoint_path,
    config_of_checkpoint,
    load_checkpoint,
    new_run_dir,
    newest_checkpoint,
    resolve_checkpoint,
)
from roshan.config import Config, apply_overrides, dump_config
from roshan.runs.learners import check_learnable


def start_run(cfg: Config, root: str | Path = "runs", name: str | None = None) -> Path:
    """Create the run folder and write the resolved config, once what the run starts from is known to fit
    (:func:`check_init_from`) and its rollout can be collected (``check_learnable``): a refused start leaves no
    empty run folder behind."""
    check_learnable(cfg)
    check_init_from(cfg)
    run_dir = new_run_dir(root, name or f"{cfg.train.algo}_{time.strftime('%Y%m%d-%H%M%S')}")
    dump_config(cfg, run_dir / "config.yaml")
    return run_dir


def check_init_from(cfg: Config) -> None:
    """Refuse ``train.init_from`` weights that cannot serve ``cfg`` (another level or network shape, the parts of
    the observation it reads included) before the run folder is made; the trainer loads them again when it starts."""
    if not cfg.train.init_from:
        return
    path = resolve_checkpoint(cfg.train.init_from)
    state = load_checkpoint(path)
    check_fits(make_agent(cfg), state["agent"], cfg, config_of_checkpoint(state, str(path)), str(path),
               weights_only=True)


def resume_config(run_dir: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """The config a resumed run continues with: its newest checkpoint's (:func:`newest_checkpoint`: the truth,
    ``config.yaml`` may be damaged or stale), plus ``overrides``. Writes nothing: :func:`train` records the result
    in ``config.yaml`` once it holds the run's lock, so that a later resume keeps these overrides. A folder without
    any checkpoint is refused (FileNotFoundError) rather than trained from zero over its files."""
    run_dir = Path(run_dir)
    path = newest_checkpoint(run_dir)
    if path is None:
        if not run_dir.is_dir():
            raise FileNotFoundError(f"{run_dir}: no such run folder to resume")
        config = run_dir / "config.yaml"
        start = (f"roshan train {config}" if config.is_file() and config.read_text().strip()
                 else "roshan train CONFIG")
        raise FileNotFoundError(f"{run_dir}: no checkpoint to resume from (checkpoints/ holds no latest.pt or "
                                f"best_*.pt); start a new run instead: {start}")
    state = load_checkpoint(path)
    saved = config_of_checkpoint(state, str(path))
    cfg = apply_overrides(saved, overrides)
    # the whole state is checked here, before training starts: a refused resume leaves the run folder as it was
    check_fits(make_agent(cfg), state["agent"], cfg, saved, str(path), weights_only=False)
    return cfg


def resume_state(run_dir: Path, cfg: Config) -> tuple[dict | None, Path | None]:
    """The newest checkpoint of ``run_dir`` (:func:`newest_checkpoint`) after checking it fits ``cfg``, and its
    path; (None, None) if there is none yet. Where it is not ``latest`` one line on stderr says which it is."""
    latest = checkpoint_path(run_dir, "latest")
    for stale in latest.parent.glob(".*.tmp"):  # a write the killed run did not finish; the old file is whole
        stale.unlink()
    path = newest_checkpoint(run_dir)
    if path is None:
        return None, None
    state = load_checkpoint(path)
    check_same_model(cfg, config_of_checkpoint(state, str(path)), str(path))
    if path != latest:
        print(f"{run_dir}: no checkpoints/latest.pt; resuming from the newest checkpoint, {path} (update "
              f"{state['progress']['updates']})", file=sys.stderr)
    return state, path
