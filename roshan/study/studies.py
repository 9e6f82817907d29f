"""A study in its storage: where it lives by default, creating it from a recipe or joining it (the stored recipe
must match), loading it with its recipe's sampler and pruner, and how much of its trial budget is spent.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import optuna
from optuna.trial import TrialState

from roshan.io import inside
from roshan.study.errors import StudyError
from roshan.study.recipe import RECIPE_ATTR, Recipe, recipe_of
from roshan.study.storage import JOURNAL_NAME, WORKER_ATTR, experimental


def study_dir(root: str | Path, name: str) -> Path:
    return inside(root, name, "the study folder")


def default_storage(root: str | Path, name: str) -> str:
    return str((study_dir(root, name) / JOURNAL_NAME).resolve())


def default_name(config_path: str | Path | None, space_path: str | Path) -> str:
    return f"{Path(config_path).stem if config_path else 'defaults'}-{Path(space_path).stem}"


def tpe_sampler(recipe: Recipe, seed: int | None = None) -> optuna.samplers.BaseSampler:
    return optuna.samplers.TPESampler(n_startup_trials=recipe.startup_trials, seed=seed, multivariate=True,
                                      constant_liar=True)  # running trials count as bad: workers spread out


def _pruner(recipe: Recipe) -> optuna.pruners.BasePruner:
    if not recipe.prune or recipe.objective == "tte":  # docs/model/learning.md §13: no pruning with time_to_end
        return optuna.pruners.NopPruner()
    return optuna.pruners.MedianPruner(n_startup_trials=recipe.prune_startup, n_warmup_steps=recipe.prune_warmup)


def load_study(storage, name: str) -> tuple[optuna.Study, Recipe]:
    """An existing study of ``storage`` with the sampler and pruner of its recipe."""
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        names = optuna.get_all_study_names(storage)
        raise StudyError(f"no study {name!r} in this storage; it holds {names or 'none'}") from None
    recipe = recipe_of(study)
    study.sampler, study.pruner = tpe_sampler(recipe), _pruner(recipe)
    return study, recipe


def _load_when_ready(storage, name: str, wait: float = 10.0) -> tuple[optuna.Study, Recipe]:
    """Like :func:`load_study`, waiting a little for a recipe that the study's creator is still writing."""
    deadline = time.time() + wait
    while True:
        try:
            return load_study(storage, name)
        except StudyError:
            if time.time() > deadline:
                raise
            time.sleep(0.5)


def _plain(x: Any) -> Any:
    """``x`` as it comes back from a storage (JSON: tuples become lists)."""
    return json.loads(json.dumps(x))


def _differences(a: dict, b: dict, prefix: str = "") -> list[str]:
    out = []
    for key in sorted(set(a) | set(b)):
        x, y = a.get(key), b.get(key)
        if isinstance(x, dict) and isinstance(y, dict):
            out += _differences(x, y, f"{prefix}{key}.")
        elif x != y:
            out.append(f"{prefix}{key}: {y!r} in the study, {x!r} here")
    return out


def prepare_study(storage, name: str, recipe: Recipe | None, resume: bool, settings: dict | None = None,
                  trials: int | None = None, where: str = "") -> tuple[optuna.Study, Recipe]:
    """Create the study ``name`` from ``recipe``, or with ``resume`` continue it (creating it if it is missing,
    so every machine may run the same command). On resume a given recipe's config and space, and the given
    ``settings`` (Recipe fields), must match the stored ones; ``trials`` changes the stored budget."""
    names = optuna.get_all_study_names(storage)
    if name in names and not resume:
        n = len(optuna.load_study(study_name=name, storage=storage).trials)
        raise StudyError(f"study {name!r} already exists in {where or 'the storage'} ({n} trials): continue it, "
                         "or join it from another machine, with --resume; or choose another --name")
    if name not in names:
        if recipe is None or trials is None:
            raise StudyError(f"no study {name!r} in {where or 'the storage'} yet: start it with CONFIG --space "
                             "SPACE.yaml --trials N")
        try:
            study = optuna.create_study(study_name=name, storage=storage, direction=recipe.direction)
            study.set_user_attr(RECIPE_ATTR, _plain(dataclasses.asdict(recipe)))
        except optuna.exceptions.DuplicatedStudyError:  # another machine created it a moment ago
            pass
    study, stored = _load_when_ready(storage, name)
    given = {k: v for k, v in (settings or {}).items() if v is not None and k != "trials"}
    if recipe is not None:
        given.update(config=recipe.config, space=recipe.space)
    diff = _differences(_plain(given), _plain({k: getattr(stored, k) for k in given}))
    if diff:
        raise StudyError(f"study {name!r} was made with another recipe; leave out CONFIG/--space/--set and the "
                         "study options to use the stored one, or choose another --name. Differences: "
                         + "; ".join(diff[:8]))
    if trials is not None and trials != stored.trials:
        stored = dataclasses.replace(stored, trials=trials)
        study.set_user_attr(RECIPE_ATTR, _plain(dataclasses.asdict(stored)))
    return study, stored


@dataclass(frozen=True)
class Budget:
    """How far a study is: trials counted against ``target`` (a stale trial that was retried is not counted,
    its retry is), trials queued (WAITING) and the worker records of running trials."""

    target: int
    used: int
    waiting: int
    finished: int
    running: tuple[dict, ...]

    @property
    def to_start(self) -> int:
        return max(self.target - self.used, self.waiting)


def budget(study: optuna.Study, target: int) -> Budget:
    trials = study.get_trials(deepcopy=False)
    retried = {n for t in trials for n in t.system_attrs.get("retry_history", [])}
    counted = [t for t in trials if t.state != TrialState.WAITING and t.number not in retried]
    return Budget(target=target, used=len(counted), waiting=sum(t.state == TrialState.WAITING for t in trials),
                  finished=sum(t.state.is_finished() for t in counted),
                  running=tuple(t.user_attrs.get(WORKER_ATTR) or {} for t in trials if t.state == TrialState.RUNNING))


def fail_stale(study: optuna.Study) -> None:
    """Mark stale trials FAIL and queue their retries (what Optuna does before each trial)."""
    with experimental():
        optuna.storages.fail_stale_trials(study)
