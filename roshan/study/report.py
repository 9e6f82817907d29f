"""The report of a study: the best trials, the thesis's mean of the top-k parameters (docs/model/learning.md §13) as
ready config YAMLs, a CSV of every trial and Optuna's plots.
"""

from __future__ import annotations

import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import optuna
import yaml
from optuna.trial import FrozenTrial, TrialState

from roshan.config import to_dict
from roshan.study.errors import StudyError
from roshan.study.recipe import recipe_of
from roshan.study.space import SearchSpace, with_values
from roshan.study.storage import JOURNAL_NAME, display_url, is_url, open_storage
from roshan.study.studies import load_study, study_dir


def best_trials(study: optuna.Study, k: int) -> list[FrozenTrial]:
    """The ``k`` best COMPLETE trials, best first."""
    done = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)) if t.value == t.value]
    sign = -1.0 if study.direction == optuna.study.StudyDirection.MAXIMIZE else 1.0
    return sorted(done, key=lambda t: (sign * t.value, t.number))[:k]


def mean_of_top_k(study: optuna.Study, k: int = 10) -> dict[str, Any]:
    """The thesis's method (docs/model/learning.md §13, Tables 5.5 / 5.9): the arithmetic mean of each parameter over
    the ``k`` best trials (ints rounded, categoricals: the most common, ties to the better trial), ties applied."""
    top = best_trials(study, k)
    if not top:
        raise StudyError(f"study {study.study_name!r} has no completed trial yet")
    space = _space_or_none(study)
    out: dict[str, Any] = {}
    for key in dict.fromkeys(k for t in top for k in t.params):
        values = [t.params[key] for t in top if key in t.params]
        dist = top[0].distributions.get(key) or next(t.distributions[key] for t in top if key in t.params)
        if isinstance(dist, optuna.distributions.CategoricalDistribution):
            out[key] = Counter(values).most_common(1)[0][0]
        elif isinstance(dist, optuna.distributions.IntDistribution):
            out[key] = int(round(sum(values) / len(values)))
        else:
            out[key] = float(sum(values) / len(values))
    return space.with_ties(out) if space is not None else out


def _space_or_none(study: optuna.Study) -> SearchSpace | None:
    try:
        return recipe_of(study).search_space()
    except StudyError:
        return None


def config_yaml(study: optuna.Study, values: dict[str, Any], header: str) -> str:
    """The study's base config with ``values`` set, as a YAML that ``roshan train`` takes."""
    cfg = with_values(recipe_of(study).run_config(), values, where=f"study {study.study_name}")
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    return comment + yaml.safe_dump(to_dict(cfg), sort_keys=False)


def format_best_table(study: optuna.Study, k: int) -> str:
    """A console table of the ``k`` best trials: value, evaluation metrics and parameters."""
    top = best_trials(study, k)
    keys = list(dict.fromkeys(key for t in top for key in t.params))
    short = [key.rsplit(".", 1)[-1] for key in keys]
    if len(set(short)) < len(short):
        short = keys
    head = ["rank", "trial", "value", "success", "reward", "tte", *short]
    rows = [[str(i + 1), str(t.number), f"{t.value:.4g}", _fmt(t.user_attrs.get("success_rate")),
             _fmt(t.user_attrs.get("reward")), _fmt(t.user_attrs.get("tte")), *(_fmt(t.params.get(k)) for k in keys)]
            for i, t in enumerate(top)]
    widths = [max(len(r[c]) for r in [head, *rows]) for c in range(len(head))]
    lines = ["  ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)) for r in [head, *rows]]
    return "\n".join([lines[0], "-" * len(lines[0]), *lines[1:]])


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def write_trials_csv(study: optuna.Study, path: Path) -> None:
    import csv

    trials = study.get_trials(deepcopy=False)
    keys = list(dict.fromkeys(k for t in trials for k in t.params))
    attrs = ["success_rate", "reward", "tte", "updates", "minutes", "machine", "host", "run_dir"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["number", "state", "value", *attrs, *keys, "retry_of"])
        for t in trials:
            w.writerow([t.number, t.state.name, t.value, *(t.user_attrs.get(a) for a in attrs),
                        *(t.params.get(k) for k in keys), t.system_attrs.get("failed_trial")])


def write_plots(study: optuna.Study, out_dir: Path) -> dict[str, str]:
    """Optuna's optimisation history, parameter importances and parallel coordinates as PNGs; a plot that
    cannot be drawn yet (e.g. importances need two finished trials) is skipped with the reason."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ovm

    out = {}
    for fname, plot in (("history", ovm.plot_optimization_history), ("importances", ovm.plot_param_importances),
                        ("parallel_coordinates", ovm.plot_parallel_coordinate)):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ax = plot(study)
            fig = ax.flat[0].figure if hasattr(ax, "flat") else ax.figure
            fig.set_size_inches(10, 6)
            fig.savefig(out_dir / f"{fname}.png", dpi=100, bbox_inches="tight")
            plt.close(fig)
            out[fname] = str(out_dir / f"{fname}.png")
        except Exception as exc:  # Optuna raises ValueError/RuntimeError for too few trials or params
            out[fname] = f"skipped ({type(exc).__name__}: {exc})"
    return out


def write_report(study: optuna.Study, out_dir: str | Path, k: int = 10, plots: bool = True) -> dict[str, Any]:
    """Files in ``out_dir``: ``trials.csv``, ``best_trial.yaml`` and ``top<k>_mean.yaml`` (ready configs), and the
    plots. Returns {"table", "files", "plots", "top_k": the averaged parameters}."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    recipe = recipe_of(study)
    top = best_trials(study, k)
    if not top:
        raise StudyError(f"study {study.study_name!r} has no completed trial yet ({len(study.trials)} trials)")
    n_done = len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    write_trials_csv(study, out_dir / "trials.csv")
    space = _space_or_none(study)
    best = space.with_ties(dict(top[0].params)) if space is not None else dict(top[0].params)
    best_path = out_dir / "best_trial.yaml"
    best_path.write_text(config_yaml(study, best, f"Study {study.study_name}: parameters of trial {top[0].number}, "
                                     f"the best of {n_done} completed ({recipe.objective} = {top[0].value:.6g})."))
    mean = mean_of_top_k(study, k)
    mean_path = out_dir / f"top{len(top)}_mean.yaml"
    mean_path.write_text(config_yaml(study, mean, (
        f"Study {study.study_name}: mean of the parameters of the {len(top)} best of {n_done} completed trials\n"
        f"(trials {', '.join(str(t.number) for t in top)}; objective {recipe.objective}); the thesis's method.")))
    return {"table": format_best_table(study, k), "files": [str(out_dir / "trials.csv"), str(best_path),
                                                            str(mean_path)],
            "plots": write_plots(study, out_dir) if plots else {}, "top_k": mean}


def open_for_report(target: str, root: str | Path = "runs", name: str | None = None) -> tuple[optuna.Study, Path]:
    """The study named by ``target`` (a study name under ``root``, a study folder, a journal file, or a storage
    URL with ``name`` or a single study) and the default report folder."""
    if is_url(target):
        storage = open_storage(target, heartbeat=None)
        names = optuna.get_all_study_names(storage)
        if name is None:
            if len(names) != 1:
                raise StudyError(f"{display_url(target)} holds {names or 'no studies'}; pick one with --name")
            name = names[0]
        study, _ = load_study(storage, name)
        return study, study_dir(root, name) / "report"
    path = Path(target)
    if not path.exists():
        path = Path(root) / target  # read, not written: a name that is no folder is "no study found" below
    journal = path / JOURNAL_NAME if path.is_dir() else path
    if not journal.is_file():
        raise StudyError(f"{target}: no study found (looked for {journal}); give a study name under --root, a study "
                         "folder, a journal file or a storage URL")
    storage = open_storage(str(journal), heartbeat=None, repair=False)  # a report never rewrites a journal
    names = optuna.get_all_study_names(storage)
    name = name or (names[0] if len(names) == 1 else journal.parent.name)
    study, _ = load_study(storage, name)
    return study, journal.parent / "report"
