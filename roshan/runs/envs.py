"""The vector env a run trains or evaluates on, built from its config, and how its frames name who flies."""

import os
from pathlib import Path

from roshan.config import Config
from roshan.runs.levels import kit_of


def make_env(cfg: Config, num_envs: int, seed: int, evaluation: bool = False, controller: str = "planner",
             render_mode: str | None = None):
    """The run's vector env: FlyAgent, or planner (``evaluation``: explorers fly and the candidates are the
    detected fires; ``controller="greedy"``: the heuristic baseline). ``render_mode="rgb_array"``: frames,
    with env 0's final frame of each episode kept."""
    return kit_of(cfg).env(cfg, num_envs, seed, evaluation, controller, render_mode)


def caption_name(level: str, run_dir: Path) -> str:
    """Who flies, for the caption of a trained run's frames: the level (``FlyAgent``, ``planner``) and the run
    folder it was trained in, relative to the working directory where it lies below it (``planner from
    models/planner``, not "planner model planner")."""
    run_dir = Path(run_dir)
    try:
        where = Path(os.path.relpath(run_dir.resolve(), Path.cwd().resolve()))
    except ValueError:  # another drive (Windows)
        where = run_dir
    if where.parts[:1] == ("..",):
        where = Path(run_dir.name)
    return f"{level} from {where.as_posix()}"
