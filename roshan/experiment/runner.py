"""Running an experiment: every (condition, seed) of a spec is a trial with one fixed parameter (``run``, its key)
in an Optuna study, in the same storages as ``roshan study`` (a journal file by default, PostgreSQL to spread the
runs over machines).

- Creating the experiment enqueues one WAITING trial per run. A worker process claims the first waiting run in
  the spec's order by the storage's atomic state change from WAITING to RUNNING (what ``study.ask()`` does), so
  each run goes to exactly one worker; it trains and evaluates the run and tells the trial COMPLETE with its
  results as user attributes.
- A worker that dies (killed, machine lost) leaves its trial RUNNING; it is found stale as in a study (its process
  is gone, or its heartbeat is older than the grace period), failed, and queued again with the same ``run``. The
  retry continues the training from the run folder's latest checkpoint; finished runs are never redone.
- A worker runs one run and exits (Taichi fields are not freed inside a process); ``--workers W`` keeps W busy.

Run folders: ``<root>/<experiment>/<condition>/seed_<s>/`` on the machine that ran them, each with its
``result.json``; the results themselves live in the storage, so ``roshan experiment report`` works anywhere.
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import optuna
import torch
from optuna.exceptions import UpdateFinishedTrialError
from optuna.storages._heartbeat import get_heartbeat_thread
from optuna.trial import TrialState

from roshan import reproducible
from roshan.algos.frozen import load_agent, policy_fn
from roshan.checkpoints import checkpoint_path, resolve_checkpoint
from roshan.config import Config, dump_config
from roshan.experiment.spec import Run, Spec, SpecError
from roshan.io import prepare_output, write_atomic, writing
from roshan.maps import MapError, load_map
from roshan.runs.envs import make_env
from roshan.runs.evaluate import run_episodes, save_buffer, summarize, write_outputs
from roshan.runs.learners import check_learnable
from roshan.runs.provenance import code_version
from roshan.runs.train import ensure_taichi_for, train
from roshan.runtime import torch_device
from roshan.study.storage import (
    HOST_ID,
    WORKER_ATTR,
    RetryStaleTrial,
    display_url,
    experimental,
    open_storage,
    worker_record,
)
from roshan.study.studies import fail_stale
from roshan.study.workers import Launcher

STUDY_ATTR = "roshan_experiment"  # study user attribute: {"spec": path, "runs": {key: fingerprint}}
RESULT_ATTR = "result"  # trial user attribute: the run's result dict
RUN_ATTR = "run"  # trial user attribute: the run's key, set when it is queued (a retry inherits it)
RERUN_ATTR = "rerun_of"  # trial user attribute: the finished trial a rerun supersedes (a retry inherits it)
JOURNAL_NAME = "experiment.journal"


def experiment_dir(root: str | Path, name: str) -> Path:
    return Path(root) / name


def default_storage(root: str | Path, name: str) -> str:
    return str((experiment_dir(root, name) / JOURNAL_NAME).resolve())


def spec_storage(spec: Spec, root: str | Path, storage: str | None = None) -> str:
    """Where ``spec``'s runs are recorded: ``--storage``, else the spec's own ``storage`` (a committed journal),
    else ``ROOT/NAME/experiment.journal``."""
    return storage or spec.storage or default_storage(root, spec.name)


def run_storage(spec: Spec, root: str | Path, storage: str | None = None,
                echo: Callable[[str], None] = print) -> str:
    """Where ``experiment run`` records ``spec``'s runs: ``--storage``; else a spec's committed journal is never
    written (a plain ``run`` or ``--only`` would add records to a tracked file): the runs go to
    ROOT/NAME/experiment.journal, made as a copy of it the first time, so its finished runs are kept. A spec whose
    storage is a URL (a database the machines share) uses it."""
    if storage or not spec.storage or "://" in spec.storage:
        return spec_storage(spec, root, storage)
    copy = Path(default_storage(root, spec.name))
    committed = Path(spec.storage)
    if not copy.exists() and committed.is_file():
        with writing("a copy of the experiment journal", copy):
            copy.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(copy, committed.read_bytes())
        echo(f"experiment {spec.name}: runs are recorded in {copy}, a copy of the spec's journal {committed} (to add "
             f"them to that one, give --storage {committed})")
    return str(copy)


def run_dir(root: str | Path, name: str, run: Run) -> Path:
    return experiment_dir(root, name) / run.condition.name / f"seed_{run.seed}"


def run_key(t: optuna.trial.FrozenTrial) -> str | None:
    """The run a trial stands for (None for a spare trial, see :func:`claim`)."""
    return t.user_attrs.get(RUN_ATTR)


# ------------------------------------------------------------------------------------------ the study


def prepare_experiment(storage, spec: Spec, echo: Callable[[str], None] = print,
                       remake: tuple[str, ...] = ()) -> optuna.Study:
    """Create the experiment's study with one waiting trial per run, or continue it. Runs the study lacks (new
    conditions or seeds, a creator killed while enqueueing, a run that failed) are queued; a stored run whose
    settings differ from the spec's is refused, unless ``remake`` (run keys) names it: then its results so far are
    retired (they stay in the journal, out of the report) and it is queued to be made under the new settings."""
    prints = spec.fingerprints()
    try:
        study = optuna.create_study(study_name=spec.name, storage=storage, direction="maximize")
        study.set_user_attr(STUDY_ATTR, {"spec": spec.path, "runs": prints})
    except optuna.exceptions.DuplicatedStudyError:
        study = optuna.load_study(study_name=spec.name, storage=storage)
        stored = _wait_for_meta(study)
        if remake:
            stored = retire_runs(study, stored, remake, echo)
        check_runs(spec, stored, study)
        study.set_user_attr(STUDY_ATTR, {**stored, "spec": spec.path, "runs": {**stored["runs"], **prints}})
    drop_orphans(study, spec, echo)
    retired = retired_before(study)
    queued = {run_key(t) for t in study.get_trials(deepcopy=False)
              if t.state != TrialState.FAIL and t.number >= retired.get(run_key(t), 0)}
    newest = newest_trials(study)
    for key in prints:
        if key not in queued:
            attrs = {RUN_ATTR: key}
            if key in newest:  # a remade run: a folder of its own (its old one holds the other settings' run)
                attrs[RERUN_ATTR] = newest[key].number
            study.enqueue_trial({}, user_attrs=attrs)
    return study


def retire_runs(study: optuna.Study, stored: dict, keys: tuple[str, ...], echo: Callable[[str], None]) -> dict:
    """The study's meta with the runs ``keys`` retired: every trial of theirs made so far leaves the report and
    the settings check (the trial numbers below ``retired[key]``). A retired run that is running is refused."""
    trials = study.get_trials(deepcopy=False)
    busy = sorted({run_key(t) for t in trials if run_key(t) in keys and t.state == TrialState.RUNNING})
    if busy:
        raise SpecError(f"experiment {study.study_name!r}: {', '.join(busy)} running now; remake them once they end")
    for t in trials:  # their waiting trials (a rerun or retry queued under the old settings) must not run
        if run_key(t) in keys and t.state == TrialState.WAITING:
            study._storage.set_trial_user_attr(t._trial_id, "dropped", "remade under new settings")
            study._storage.set_trial_state_values(t._trial_id, state=TrialState.FAIL)
    cut = max((t.number for t in trials), default=-1) + 1
    echo(f"experiment {study.study_name}: {len(keys)} run(s) to be made again under new settings; their earlier "
         "results stay in the journal, out of the report")
    return {**stored, "retired": {**stored.get("retired", {}), **{k: cut for k in keys}}}


def retired_before(study: optuna.Study) -> dict[str, int]:
    """run key -> the trial number below which its trials are retired (``--remake``); {} where none is."""
    return (study.user_attrs.get(STUDY_ATTR) or {}).get("retired", {})


def results_of(study: optuna.Study) -> dict[str, dict]:
    """run key -> result of every finished run (its newest, leaving out results retired by ``--remake``)."""
    retired = retired_before(study)
    return {run_key(t): t.user_attrs[RESULT_ATTR] for t in study.get_trials(deepcopy=False)
            if t.state.is_finished() and RESULT_ATTR in t.user_attrs and t.number >= retired.get(run_key(t), 0)}


def newest_trials(study: optuna.Study) -> dict[str, optuna.trial.FrozenTrial]:
    """run key -> its newest trial (any state)."""
    newest = {}
    for t in study.get_trials(deepcopy=False):  # trials come in number order
        if run_key(t) is not None:
            newest[run_key(t)] = t
    return newest


def drop_orphans(study: optuna.Study, spec: Spec, echo: Callable[[str], None] = print) -> int:
    """Fail the waiting runs of conditions ``spec`` no longer has (a condition removed or renamed), so that they are
    neither run nor counted; a spec that still has them queues them again. Returns how many were dropped."""
    keys = set(spec.fingerprints())
    storage = study._storage
    orphans = [t for t in storage.get_all_trials(study._study_id, deepcopy=False, states=(TrialState.WAITING,))
               if run_key(t) not in keys]
    for t in orphans:
        storage.set_trial_user_attr(t._trial_id, "dropped", f"not in {spec.path}")
        storage.set_trial_state_values(t._trial_id, state=TrialState.FAIL)
    if orphans:
        echo(f"experiment {spec.name}: dropped {len(orphans)} waiting run(s) of conditions {spec.path} no longer has")
    return len(orphans)


def queue_reruns(study: optuna.Study, spec: Spec, patterns: tuple[str, ...],
                 echo: Callable[[str], None] = print) -> int:
    """Queue the finished runs that ``patterns`` name (conditions, or runs ``CONDITION/seed_S``:
    :meth:`Spec.select_runs`) once more, to be made by the code that runs them now (in a folder of their own); the
    newest result of a run is the one reported, the earlier ones stay in the journal. A run whose rerun is already
    queued or running is left alone. Returns how many were queued."""
    newest = newest_trials(study)
    queued = 0
    for key in spec.select_runs(patterns):
        t = newest.get(key)
        if t is not None and t.state == TrialState.COMPLETE:
            study.enqueue_trial({}, user_attrs={RUN_ATTR: key, RERUN_ATTR: t.number})
            queued += 1
    echo(f"experiment {spec.name}: {queued} finished run(s) of {', '.join(patterns)} queued again")
    return queued


def check_runs(spec: Spec, stored: dict, study: optuna.Study) -> None:
    """Refuse a spec under which a run that has started would mean something else (config, controller,
    evaluation); runs still waiting may change."""
    trials = study.get_trials(deepcopy=False)
    retired = stored.get("retired", {})
    # a run whose every trial failed has no result to mean something else: it may take new settings (its folder,
    # made under the old ones, is set aside when it starts again: claim_folder); nor has a run whose results were
    # retired (--remake)
    started = {run_key(t) for t in trials if t.state not in (TrialState.WAITING, TrialState.FAIL)
               and t.number >= retired.get(run_key(t), 0)}
    changed = [k for k, fp in spec.fingerprints().items() if stored["runs"].get(k, fp) != fp and k in started]
    if changed:
        raise SpecError(f"{spec.path}: experiment {spec.name!r} holds runs made with other settings under the same "
                        f"keys ({', '.join(changed[:6])}{' ...' if len(changed) > 6 else ''}): keep their conditions "
                        "as they were (add new conditions instead), give the spec another name, or make them again "
                        "under the new settings with --remake")


def _wait_for_meta(study: optuna.Study, wait: float = 10.0) -> dict:
    deadline = time.time() + wait
    while STUDY_ATTR not in study.user_attrs:  # its creator is still writing it
        if time.time() > deadline:
            raise SpecError(f"study {study.study_name!r} in this storage is not an experiment (no {STUDY_ATTR})")
        time.sleep(0.5)
    return study.user_attrs[STUDY_ATTR]


def load_experiment(storage, name: str) -> optuna.Study:
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        names = optuna.get_all_study_names(storage)
        raise SpecError(f"no experiment {name!r} in this storage; it holds {names or 'none'}") from None
    _wait_for_meta(study)
    return study


def progress(study: optuna.Study, keys=None) -> dict[str, int]:
    """Runs (of ``keys``, default all) by the state of their newest trial: done (COMPLETE), running, waiting, and
    failed (a run that failed and was not queued again; the next ``experiment run`` queues it)."""
    newest: dict[str, optuna.trial.FrozenTrial] = {}
    for t in study.get_trials(deepcopy=False):
        k = run_key(t)
        if k is not None and (keys is None or k in keys) and (k not in newest or t.number > newest[k].number):
            newest[k] = t
    names = {TrialState.COMPLETE: "done", TrialState.RUNNING: "running", TrialState.WAITING: "waiting",
             TrialState.FAIL: "failed"}
    out = {"done": 0, "running": 0, "waiting": 0, "failed": 0}
    for t in newest.values():
        if t.state in names:
            out[names[t.state]] += 1
    return out


def carry_results(source: optuna.Study, spec: Spec, storage, only: tuple[str, ...] = (),
                  echo: Callable[[str], None] = print) -> int:
    """Record the finished runs of ``source`` (another experiment's study) as ``spec``'s, for the conditions both
    hold (``only``: these of them): rows moving to an experiment of their own keep their results. Each run must mean
    the same in both, its fingerprint under ``spec`` the one ``source`` stored, else nothing is recorded. Runs that
    ``spec``'s study already finished are left alone. Returns how many were recorded."""
    stored = _wait_for_meta(source)["runs"]
    results = results_of(source)
    prints = {k: fp for k, fp in spec.fingerprints().items() if k in results and (not only or k.split("/")[0] in only)}
    differ = [k for k, fp in prints.items() if stored.get(k) != fp]
    if differ:
        raise SpecError(f"{spec.path}: {', '.join(differ[:6])}{' ...' if len(differ) > 6 else ''} would mean "
                        f"something else than in experiment {source.study_name!r}: their settings differ")
    study = prepare_experiment(storage, spec, echo)
    done = {run_key(t) for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE}
    order = {k: i for i, k in enumerate(k for k in prints if k not in done)}
    carried = 0
    while (got := claim(study, order)) is not None:
        trial, key = got
        record_result(study, trial, {**results[key], "carried_from": source.study_name})
        carried += 1
    echo(f"experiment {spec.name}: {carried} finished run(s) carried over from experiment {source.study_name}")
    return carried


# ------------------------------------------------------------------------------------------ one worker


def claim(study: optuna.Study, order: dict[str, int]) -> tuple[optuna.Trial, str] | None:
    """The first waiting run in the spec's order (``order``: key -> position; a retried run keeps its place, runs
    this spec does not know are left to the machine whose spec has them), or None. Taking it is the storage's
    atomic WAITING -> RUNNING change that ``study.ask()`` makes too, so each run goes to exactly one worker."""
    storage = study._storage
    waiting = [t for t in storage.get_all_trials(study._study_id, deepcopy=False, states=(TrialState.WAITING,))
               if run_key(t) in order]
    for t in sorted(waiting, key=lambda t: (order[run_key(t)], t.number)):
        try:
            if not storage.set_trial_state_values(t._trial_id, state=TrialState.RUNNING):
                continue  # another worker took it a moment ago
        except UpdateFinishedTrialError:
            continue
        return optuna.Trial(study, t._trial_id), run_key(t)
    return None


def _taken_elsewhere(study: optuna.Study, trial: optuna.Trial, key: str) -> bool:
    """Another live or finished trial holds the same run (a second guard: the queue has each run once)."""
    superseded = study._storage.get_trial(trial._trial_id).user_attrs.get(RERUN_ATTR, -1)
    return any(t.number != trial.number and run_key(t) == key and (
        t.state == TrialState.RUNNING or (t.state == TrialState.COMPLETE and t.number > superseded))
        for t in study.get_trials(deepcopy=False))


Execute = Callable[[Run, Path], dict]


def run_worker(spec: Spec, storage_url: str, root: str | Path, execute: Execute | None = None,
               heartbeat: int | None = 60, max_retry: int | None = 3, extra: tuple[str, ...] = (),
               only: tuple[str, ...] = ()) -> int:
    """Claim one run of ``spec``'s experiment (of the conditions ``only`` names, when given), execute it and
    record its result; returns the exit code (0, or 130 when interrupted: the run is failed and queued again, and
    continues from its checkpoint)."""
    storage = open_storage(storage_url, heartbeat, max_retry)
    study = load_experiment(storage, spec.name)
    check_runs(spec, study.user_attrs[STUDY_ATTR], study)
    fail_stale(study)
    runs = {r.key: r for r in spec.runs(only)}
    got = claim(study, {k: i for i, k in enumerate(runs)})
    if got is None:
        return 0
    trial, key = got
    trial.set_user_attr(WORKER_ATTR, worker_record())
    trial.set_user_attr("host", socket.gethostname())
    if _taken_elsewhere(study, trial, key):
        trial.set_user_attr("duplicate", True)
        study.tell(trial, state=TrialState.FAIL)
        return 0
    carried = study._storage.get_trial(trial._trial_id).user_attrs.get(RESULT_ATTR)
    if carried is not None:
        # The retry of a run that finished: its result was stored, then its trial was failed as stale before the
        # tell (the worker cut off in between). Running it again would only repeat it.
        record_result(study, trial, carried)
        return 0
    run = runs[key]
    folder = run_dir(root, spec.name, run)
    rerun_of = study._storage.get_trial(trial._trial_id).user_attrs.get(RERUN_ATTR)
    if rerun_of is not None:  # a fresh folder: the first run's checkpoints would only be evaluated again
        folder = folder.with_name(f"{folder.name}.rerun-{rerun_of}")
    execute = execute or (lambda r, d: execute_run(r, d, extra=extra))
    try:
        with get_heartbeat_thread(trial._trial_id, storage):
            result = execute(run, folder)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the requeue short
        study.tell(trial, state=TrialState.FAIL)
        with experimental():
            RetryStaleTrial(max_retry=None)(study, study._storage.get_trial(trial._trial_id))
        return 130
    except Exception:
        study.tell(trial, state=TrialState.FAIL)  # failed for good: the traceback says why; retry by hand
        raise
    try:
        record_result(study, trial, result)
    except UpdateFinishedTrialError:
        # Found stale while it worked (silent past the grace period, seen from another machine): the trial is
        # failed and its retry queued. The result is not lost: the retry, when still waiting, gets it.
        retry = claim(study, {key: 0})
        if retry is not None:
            retry[0].set_user_attr(WORKER_ATTR, worker_record())
            record_result(study, retry[0], result)
    return 0


def record_result(study: optuna.Study, trial: optuna.Trial, result: dict) -> None:
    trial.set_user_attr(RESULT_ATTR, result)
    study.tell(trial, float(result.get("success_rate", 0.0)))


# ------------------------------------------------------------------------------------------ one run


def execute_run(run: Run, folder: Path, extra: tuple[str, ...] = (), progress_bar: bool = False) -> dict:
    """Train (continuing from the folder's latest checkpoint, if any) and evaluate one run; write and return its
    result. A scripted controller only plays the evaluation episodes."""
    cond = run.condition
    extra = tuple(extra)
    if cond.buffer is not None:
        extra += (f"train.buffer_path={ensure_buffer(cond, folder.parent.parent / 'buffers')}",)
    cfg = cond.run_config(run.seed, extra)
    claim_folder(folder, run.fingerprint())
    prepare_output(folder / "checkpoints", "the run folder")
    ensure_taichi_for(cfg)
    start = time.time()
    trained = {}
    if cond.trains:
        if not checkpoint_path(folder, "latest").is_file():
            dump_config(cfg, folder / "config.yaml")
        trained = train(cfg, folder, resume=True, progress_bar=progress_bar, evaluate_at_end=False)
    episodes, reasons = evaluate(run, cfg, folder)
    # the thesis reports the training-objective checkpoint; best_eval is a maximum over periodic evaluations
    others = {key: evaluate_weights(run, cfg, folder, reasons, which)
              for key, which in (("last", "latest"), ("objective", "best_objective"))
              if cond.trains and checkpoint_path(folder, which).is_file()}
    ev_dir = folder / "eval" / f"{cond.eval_seed}-{cond.eval_episodes}"
    provenance = {"experiment": str(folder.parent.parent.name), "run": run.key, "config": cond.config,
                  "overrides": [*cond.sets, *extra, f"sim.seed={run.seed}"], "code": code_version()}
    who = f"{cfg.train.algo} policy" if cond.trains else cond.controller
    summary = write_outputs(episodes, ev_dir, f"{run.key} ({len(episodes['time'])} episodes, seed {cond.eval_seed})",
                            provenance, reasons, cfg.fire.dt, who)
    result = {
        "run": run.key, "condition": cond.name, "seed": run.seed, "controller": cond.controller,
        "episodes": summary["episodes"], "eval_seed": cond.eval_seed, "success_rate": summary["success_rate"],
        "failure_rates": summary["failure_rates"], "tte": summary["tte"],
        "tte_episodes": [int(t) for t in episodes["time"]],
        "train": {k: trained[k] for k in ("updates", "env_steps", "seconds") if k in trained},
        "minutes": round((time.time() - start) / 60.0, 3), "run_dir": str(folder), "code": provenance["code"],
        "machine": reproducible.machine(), "trained_on": trained.get("machines", []),
        "models": {key: {"setting": target, "digest": digest} for key, (target, digest) in run.models().items()},
    }
    result.update(others)
    with writing("the run's result", folder / "result.json"):
        write_atomic(folder / "result.json", (json.dumps(result, indent=2) + "\n").encode())
    return result


def claim_folder(folder: Path, fingerprint: str) -> None:
    """Mark ``folder`` as the run with ``fingerprint``; a folder another fingerprint made (a failed run whose
    condition has changed since) is renamed aside, ``<folder>.superseded-<its fingerprint>``, not continued."""
    mark = folder / "fingerprint"
    if mark.is_file() and (old := mark.read_text().strip()) != fingerprint:
        aside = folder.with_name(f"{folder.name}.superseded-{old}")
        n = 1
        while aside.exists():  # set aside before (settings A -> B -> A -> C): a name of its own, never a collision
            n += 1
            aside = folder.with_name(f"{folder.name}.superseded-{old}.{n}")
        folder.rename(aside)
        print(f"{folder}: made under other settings (fingerprint {old}); set aside as {aside}", file=sys.stderr)
    if not mark.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        write_atomic(mark, (fingerprint + "\n").encode())


def evaluate_weights(run: Run, cfg: Config, folder: Path, reasons: tuple[str, ...], which: str) -> dict:
    """The same episodes with the run's ``which`` checkpoint (``latest``: are the last weights as good as the best?
    ``best_objective``: the thesis's rule): success and failure rates, the TTE median and every episode's TTE."""
    episodes = evaluate(run, cfg, folder, which)[0]
    summary = summarize(episodes, reasons=reasons, dt=cfg.fire.dt)
    return {"success_rate": summary["success_rate"], "failure_rates": summary["failure_rates"],
            "tte_median": summary["tte"]["median"], "tte_episodes": [int(t) for t in episodes["time"]]}


def evaluate(run: Run, cfg: Config, folder: Path, weights: str = "best") -> tuple[dict, tuple[str, ...]]:
    """The condition's evaluation episodes (the same for every seed) with the run's ``best`` (or ``latest``)
    weights, or the scripted controller; and the failures its records can hold."""
    cond = run.condition
    E = max(1, min(cond.eval_envs or cfg.train.eval_envs, cond.eval_episodes))
    if cond.trains:
        _, agent, _ = load_agent(folder, weights, torch_device())
        env, act = make_env(cfg, E, cond.eval_seed, evaluation=True), policy_fn(agent)
    else:
        env = make_env(cfg, E, cond.eval_seed, evaluation=True, controller=cond.controller)
        act = _idle(E, env.num_drones)
    try:
        return run_episodes(env, act, cond.eval_episodes, cond.eval_seed), env.failure_reasons
    finally:
        env.close()


def _idle(num_envs: int, num_drones: int):
    zeros = torch.zeros(num_envs, num_drones, dtype=torch.long)
    return lambda obs: zeros  # the heuristic ignores its actions


def ensure_buffer(cond, folder: Path) -> Path:
    """The condition's replay buffer, recorded once (under a lock: the seeds' workers share it)."""
    b = cond.buffer
    path = folder / f"{Path(b.model).name}-{b.transitions}-{b.seed}.pt"
    prepare_output(folder, "replay buffers")
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not path.is_file():
            save_buffer(b.model, b.transitions, path, seed=b.seed, progress_bar=False)
    return path


# ------------------------------------------------------------------------------------------ the launcher


class ExperimentLauncher(Launcher):
    """Keeps ``workers`` worker processes (one run each) busy while runs are waiting."""

    def __init__(self, spec: Spec, storage_url: str, root: str | Path, workers: int, worker_args: list[str],
                 echo: Callable[[str], None] = print, poll: float = 1.0, only: tuple[str, ...] = ()):
        super().__init__(storage_url, spec.name, root, workers, worker_args + [a for n in only for a in ("--only", n)],
                         echo, poll)
        self.spec = spec
        self.keys = {r.key for r in spec.runs(only)}

    def continue_hint(self) -> str:
        return f"roshan experiment run {self.spec.path} --root {self.root}" + (
            f" --budget {self.spec.budget}" if self.spec.budget != "local" else "")

    def spawn(self, slot: int):
        cmd = [sys.executable, "-m", "roshan", "experiment", "run", self.spec.path, "--worker", "--slot", str(slot),
               "--budget", self.spec.budget, "--storage", self.storage_url, "--root", self.root, *self.worker_args]
        paths = [str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")]
        return subprocess.Popen(cmd, env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)})

    def report_finished(self, study: optuna.Study, _=None) -> None:
        trials = study.get_trials(deepcopy=False)
        retried = {n for t in trials for n in t.system_attrs.get("retry_history", [])}
        for t in trials:
            if not t.state.is_finished() or t.number in self.reported or run_key(t) is None:
                continue
            self.reported.add(t.number)
            if t.state == TrialState.COMPLETE:
                r = t.user_attrs.get(RESULT_ATTR, {})
                self.echo(f"{run_key(t)}: success {r.get('success_rate', float('nan')):.1%} over {r.get('episodes')} "
                          f"episodes ({r.get('minutes', 0):.1f} min)")
            elif not t.user_attrs.get("duplicate"):
                self.echo(f"{run_key(t)}: failed" + (" (its worker died or was interrupted; queued again)"
                                                      if t.number in retried else ""))

    def tick(self, study: optuna.Study, _=None) -> None:
        fail_stale(study)
        self.reap()
        self.report_finished(study)
        waiting = progress(study, self.keys)["waiting"]  # runs another machine's larger spec added are its own
        running = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
        mine = {(t.user_attrs.get(WORKER_ATTR) or {}).get("pid") for t in running
                if (t.user_attrs.get(WORKER_ATTR) or {}).get("host") == HOST_ID}
        starting = sum(p.pid not in mine for p in self.procs.values())  # spawned, run not claimed yet
        free = [s for s in range(self.workers) if s not in self.procs]
        if self.crashed is None:
            for slot in free[:max(0, waiting - starting)]:
                self.procs[slot] = self.spawn(slot)


def check_trainable(spec: Spec, only: tuple[str, ...] = ()) -> None:
    """Refuse, before any worker starts, a condition whose runs could not start training (a rollout that does not
    split over its envs): found here it names the condition, found by a worker it fails each seed in turn."""
    for condition in spec.conditions:
        if condition.trains and (not only or condition.name in only):
            try:
                check_learnable(condition.run_config(condition.seeds[0]))
            except ValueError as e:
                raise SpecError(f"{spec.path}: condition {condition.name}: {e}") from None


def check_sources(spec: Spec, only: tuple[str, ...] = ()) -> None:
    """Refuse, before any worker starts, a condition whose map cannot be loaded or whose frozen FlyAgent models
    (``planner.fly_model`` / ``explorer_model``, for the planner level and the scripted controllers) are missing:
    found by a worker they failed each seed in turn, naming neither the spec nor the condition."""
    maps: dict[tuple, str | None] = {}  # a map shared by conditions is read once
    for condition in spec.conditions:
        if only and condition.name not in only:
            continue
        cfg = condition.run_config(condition.seeds[0])
        key = (cfg.map.name, cfg.map.band, cfg.map.uniform_rows, cfg.map.uniform_cols)
        if key not in maps:
            try:
                load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows, cols=cfg.map.uniform_cols)
                maps[key] = None
            except MapError as e:
                maps[key] = str(e)
        if maps[key] is not None:
            raise SpecError(f"{spec.path}: condition {condition.name}: map.name: {maps[key]}")
        for key in cfg.train.level.frozen_models:
            try:
                resolve_checkpoint(getattr(cfg.planner, key.split(".", 1)[1]))
            except FileNotFoundError as e:
                raise SpecError(f"{spec.path}: condition {condition.name}: {key}: {e}") from None


def run_experiment(spec: Spec, root: str | Path = "runs", storage: str | None = None, workers: int = 1,
                   worker_args: list[str] | tuple = (), heartbeat: int | None = 60, max_retry: int | None = 3,
                   echo: Callable[[str], None] = print, poll: float = 1.0, only: tuple[str, ...] = (),
                   rerun: tuple[str, ...] = (), remake: tuple[str, ...] = ()) -> optuna.Study:
    """``roshan experiment run``: create or continue the experiment and run its waiting runs with ``workers``
    processes on this machine (only the runs of the conditions ``only`` names, when given: the whole spec is
    still created, so other runs keep their place for a later call), after queueing the finished runs that
    ``rerun`` names (conditions or runs ``CONDITION/seed_S``) again, and after retiring the results of the runs
    ``remake`` names, to be made under the settings the spec now gives them; returns the study."""
    check_trainable(spec, only)
    check_sources(spec, only)
    url = run_storage(spec, root, storage, echo)
    store = open_storage(url, heartbeat, max_retry, repair=True, echo=echo)
    study = prepare_experiment(store, spec, echo, remake)
    if rerun:
        queue_reruns(study, spec, rerun, echo)
    keys = {r.key for r in spec.runs(only)}
    p = progress(study, keys)
    total = len(keys)
    chosen = f" of {', '.join(only)}" if only else ""
    echo(f"experiment {spec.name}: {p['done']}/{total} runs{chosen} done, {p['waiting']} waiting, {workers} "
         f"worker(s), storage {display_url(url)}")
    launcher = ExperimentLauncher(spec, url, root, workers, list(worker_args), echo, poll, only)
    launcher.reported = {t.number for t in study.get_trials(deepcopy=False) if t.state.is_finished()}
    launcher.run(study, spec)
    p = progress(study, keys)
    echo(f"experiment {spec.name}: {p['done']}/{total} runs{chosen} done"
         + (f", {p['failed']} failed" if p["failed"] else ""))
    return study
