"""One trial, as a worker process runs it: sample the space, train in ``<root>/<name>/trial_<n>/``, report the
training objective for pruning, evaluate and return the objective. A worker runs one trial and exits (Taichi
fields and compiled kernels are not freed inside a process).
"""

from __future__ import annotations

import math
import signal
import socket
import threading
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import optuna
from optuna.trial import TrialState

from roshan import reproducible
from roshan.config import Config
from roshan.io import progress_bar
from roshan.runs.resume import start_run
from roshan.runs.train import train
from roshan.study.recipe import Recipe
from roshan.study.space import with_values
from roshan.study.storage import WORKER_ATTR, RetryStaleTrial, experimental, is_url, open_storage, worker_record
from roshan.study.studies import budget, fail_stale, load_study, study_dir, tpe_sampler


def local_values(arch: str | None, threads: int | None) -> dict[str, Any]:
    """Per-machine config values of a worker (not part of the recipe)."""
    out: dict[str, Any] = {"sim.arch": arch} if arch else {}
    return {**out, "sim.threads": threads, "train.torch_threads": threads} if threads else out


def objective_value(summary: dict, objective: str) -> float:
    """The trial's value from an evaluation summary (roshan.runs.report.stats.summarize)."""
    if objective == "success":
        return float(summary["success_rate"])
    stats = summary["reward" if objective == "reward" else "tte"]
    if stats["mean"] is None:
        return -math.inf if objective == "reward" else math.inf
    return float(stats["mean"])


class TrialDisplay:
    """The worker's progress line: trial, updates (or env steps) of the budget, training objective, reward."""

    def __init__(self, number: int, cfg: Config, slot: int, quiet: bool):
        tc = cfg.train
        self.by_steps = tc.max_updates == 0 and tc.total_steps > 0
        self.bar = progress_bar(total=tc.max_updates or tc.total_steps or None, position=slot, leave=False,
                        desc=f"w{slot} trial {number}", unit="step" if self.by_steps else "update", disable=quiet,
                        dynamic_ncols=True, mininterval=1.0)

    def update(self, m: dict) -> None:
        self.bar.n = m["env_steps"] if self.by_steps else m["updates"]
        done = self.bar.total is not None and self.bar.n >= self.bar.total
        self.bar.set_postfix_str("evaluating" if done else f"obj={m['objective']:.2f} R={m['reward']:+.3f}")

    def close(self) -> None:
        self.bar.close()


def make_objective(recipe: Recipe, root: str | Path, name: str, slot: int = 0, local: dict | None = None,
                   quiet: bool = False) -> Callable[[optuna.Trial], float]:
    """The Optuna objective: sample the space, train in ``<root>/<name>/trial_<n>/`` (forced to one run, no
    auto-train), report the training objective after every update for pruning, evaluate, return the value."""
    base, space = recipe.run_config(), recipe.search_space()

    def objective(trial: optuna.Trial) -> float:
        trial.set_user_attr(WORKER_ATTR, worker_record())
        values = space.sample(trial)
        cfg = with_values(base, {**values, **(local or {}), "train.auto_train": 1}, where=f"trial {trial.number}")
        run_dir = start_run(cfg, study_dir(root, name), f"trial_{trial.number}")
        trial.set_user_attr("run_dir", str(run_dir.resolve()))
        trial.set_user_attr("host", socket.gethostname())
        display = TrialDisplay(trial.number, cfg, slot, quiet)

        def on_update(m: dict) -> None:
            display.update(m)
            if recipe.objective == "tte":
                return
            value = m["objective"] if recipe.objective == "success" else m["reward"]
            if value == value:  # NaN (no batch reward): nothing to report
                trial.report(value, m["updates"])
            if trial.should_prune():
                raise optuna.TrialPruned(f"update {m['updates']}: {value:.4g} is below the median of other trials")

        try:
            result = train(cfg, run_dir, progress_bar=False, on_update=on_update, evaluate_at_end=True)
        finally:
            display.close()
        ev = result["eval"]
        for key in ("success_rate", "reward", "tte"):
            trial.set_user_attr(key, objective_value(ev, "success" if key == "success_rate" else key))
        trial.set_user_attr("updates", result["updates"])
        trial.set_user_attr("minutes", round(result["seconds"] / 60.0, 3))
        trial.set_user_attr("machine", "; ".join(reproducible.label(m) for m in result["machines"]))
        return objective_value(ev, recipe.objective)

    return objective


def watch_interrupts() -> list[int]:
    """A list that records each SIGINT this process receives from now on (each still raises KeyboardInterrupt);
    empty and unwatched off the main thread, where no signal handler can be set."""
    received: list[int] = []
    if threading.current_thread() is threading.main_thread():
        def on_sigint(signum, frame):
            received.append(signum)
            raise KeyboardInterrupt

        signal.signal(signal.SIGINT, on_sigint)
    return received


def run_worker(storage_url: str, name: str, root: str | Path, slot: int = 0, local: dict | None = None,
               quiet: bool = False, heartbeat: int | None = 60, max_retry: int | None = 3) -> int:
    """Run one trial of the study (or nothing when its budget is spent) and return the exit code: 0, or 130
    when interrupted (the trial is failed and queued again)."""
    storage = open_storage(storage_url, heartbeat, max_retry)
    study, recipe = load_study(storage, name)
    fail_stale(study)
    b = budget(study, recipe.trials)
    if b.to_start <= 0:
        return 0
    host = socket.gethostname() if is_url(storage_url) else ""  # machines sharing a database sample differently
    seed = zlib.crc32(f"{recipe.seed}/{len(study.trials)}/{slot}/{host}".encode())
    study.sampler = tpe_sampler(recipe, seed)
    interrupted = watch_interrupts()
    try:
        # A sampled combination the config rejects (ValueError, e.g. horizon vs num_envs) fails only its trial.
        study.optimize(make_objective(recipe, root, name, slot, local, quiet), n_trials=1, catch=(ValueError,))
    except BaseException as e:
        # A Ctrl-C that lands inside Optuna's journal lock surfaces as that lock's cleanup error (its release
        # retries an unlink the interrupted one already did): the flag, not the exception's type, says why.
        if not (isinstance(e, KeyboardInterrupt) or interrupted):
            raise
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the requeue short
        me = worker_record()
        for t in study.get_trials(deepcopy=False, states=(TrialState.FAIL,)):
            if t.user_attrs.get(WORKER_ATTR) == me:
                with experimental():
                    RetryStaleTrial(max_retry=None)(study, t)
        return 130
    return 0
