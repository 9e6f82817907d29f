"""A study's recipe: the base config, the search space, the objective and the trial budget, stored in the study
itself so that a worker needs only the storage and the study name.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import optuna

from roshan.config import Config, from_dict, load_run_config, to_dict
from roshan.runs.learners import check_learnable
from roshan.study.errors import StudyError
from roshan.study.space import SearchSpace, load_space, parse_space

OBJECTIVES = {"success": "maximize", "reward": "maximize", "tte": "minimize"}  # docs/model/learning.md §13
RECIPE_ATTR = "roshan_recipe"  # study user attribute holding the recipe


@dataclass(frozen=True)
class Recipe:
    """What every worker of a study needs, stored in the study itself (so a worker needs only storage + name)."""

    config: dict  # the base Config as a nested dict
    space: dict  # SearchSpace.to_dict()
    objective: str = "success"  # success (mean evaluation success) | reward (mean episode reward) | tte (minimised)
    trials: int = 100  # trials to finish; a trial retried after its worker died counts once
    seed: int = 42  # TPE seed (mixed with the trial count and worker slot in each worker process)
    startup_trials: int = 15  # random trials before TPE models the results (thesis 15)
    prune: bool = True  # MedianPruner on the training objective (never with tte)
    prune_startup: int = 5  # trials that finish before any is pruned
    prune_warmup: int = 10  # updates of a trial before it can be pruned

    def run_config(self) -> Config:
        return from_dict(Config, self.config, where="study recipe")

    def search_space(self) -> SearchSpace:
        return parse_space(self.space, self.run_config(), where="study recipe")

    @property
    def direction(self) -> str:
        return OBJECTIVES[self.objective]


def make_recipe(config_path: str | Path | None, overrides: list[str] | tuple[str, ...], space_path: str | Path,
                **settings) -> Recipe:
    """Load and validate the base config and the search space; ``settings`` are :class:`Recipe` fields (None =
    default)."""
    base = load_run_config(config_path, overrides)
    check_learnable(base)  # a base config every trial would fail with is an error now, not N failures later
    space = load_space(space_path, base)
    fields = {k: v for k, v in settings.items() if v is not None}
    if fields.get("objective", "success") not in OBJECTIVES:
        raise StudyError(f"--objective: {fields['objective']!r}; expected one of {', '.join(OBJECTIVES)}")
    if fields.get("trials", 1) < 1:
        raise StudyError("--trials must be at least 1")
    return Recipe(config=to_dict(base), space=space.to_dict(), **fields)


def recipe_of(study: optuna.Study) -> Recipe:
    data = study.user_attrs.get(RECIPE_ATTR)
    if data is None:
        raise StudyError(f"study {study.study_name!r} has no roshan recipe (was it made by `roshan study`?)")
    return Recipe(**data)
