"""The ``roshan study`` command: Optuna studies over any config keys (docs/model/learning.md §13).

A study lives in its storage together with its *recipe*: the base config, the search space, the objective and
the trial budget. The default storage is an Optuna journal file, ``<root>/<name>/study.journal``; any SQLAlchemy
URL (PostgreSQL) works too, and then workers on several machines share the study. A worker process runs one
trial and exits (Taichi fields and compiled kernels are not freed inside a process); ``roshan study --workers
W`` keeps W of them busy. Each trial trains in ``<root>/<name>/trial_<n>/`` on the machine that ran it.

The trades live next door: ``space`` (search spaces), ``recipe``, ``storage`` (storages, heartbeats, process
liveness), ``studies`` (create, join, budget), ``trial`` (one trial in a worker), ``workers`` (the launcher) and
``report``; this module only strings them together.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import optuna

from roshan.study.errors import StudyError
from roshan.study.recipe import make_recipe, recipe_of
from roshan.study.report import best_trials
from roshan.study.storage import display_url, open_storage
from roshan.study.studies import budget, default_name, default_storage, load_study, prepare_study
from roshan.study.workers import Launcher, worker_args


def run_study(storage_url: str, name: str, root: str | Path, workers: int = 1, args: list[str] | tuple = (),
              heartbeat: int | None = 60, max_retry: int | None = 3, echo: Callable[[str], None] = print,
              poll: float = 1.0) -> optuna.Study:
    """Run the study ``name`` (already created) with ``workers`` worker processes on this machine until its
    trial budget is spent; returns the study."""
    storage = open_storage(storage_url, heartbeat, max_retry)
    study, recipe = load_study(storage, name)
    b = budget(study, recipe.trials)
    echo(f"study {name}: {b.finished}/{recipe.trials} trials finished, objective {recipe.objective} "
         f"({recipe.direction}), {workers} worker(s), storage {display_url(storage_url)}")
    Launcher(storage_url, name, root, workers, list(args), echo, poll).run(study, recipe)
    return study


def start_study(config_path: str | Path | None, space_path: str | Path | None, overrides: list[str] | tuple = (),
                *, name: str | None = None, root: str | Path = "runs", storage: str | None = None,
                resume: bool = False, trials: int | None = None, workers: int = 1, arch: str | None = None,
                threads: int | None = None, quiet: bool = False, heartbeat: int | None = 60,
                max_retry: int | None = 3, echo: Callable[[str], None] = print, **settings) -> optuna.Study:
    """``roshan study``: create (or with ``resume`` continue or join) a study and run it with ``workers``
    processes on this machine. ``settings`` are the other :class:`Recipe` fields (None = default/stored)."""
    recipe = None
    if config_path is not None or space_path is not None or overrides:
        if space_path is None:
            raise StudyError("--space SPACE.yaml is needed to start a study (see configs/spaces/)")
        if trials is None and not resume:
            raise StudyError("--trials N is needed to start a study")
        recipe = make_recipe(config_path, overrides, space_path, trials=trials, **settings)
        name = name or default_name(config_path, space_path)
    elif not resume:
        raise StudyError("give CONFIG --space SPACE.yaml --trials N to start a study, or --resume --name NAME to "
                         "continue one")
    if name is None:
        raise StudyError("--name NAME is needed to continue a study without CONFIG --space")
    url = storage or default_storage(root, name)
    store = open_storage(url, heartbeat, max_retry, repair=resume, echo=echo)
    prepare_study(store, name, recipe, resume, settings, trials, where=display_url(url))
    args = worker_args(workers, arch, threads, quiet, heartbeat, max_retry)
    study = run_study(url, name, root, workers, args, heartbeat, max_retry, echo)
    top = best_trials(study, 1)
    if top:
        echo(f"best: trial {top[0].number}, {recipe_of(study).objective} = {top[0].value:.4g}, {top[0].params}")
    where = f"{display_url(url)} --name {name}" if storage else f"{name} --root {root}"
    echo(f"report: roshan study report {where}")
    return study
