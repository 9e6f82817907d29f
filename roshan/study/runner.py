"""Optuna studies over any config keys (learning.md 13): search spaces, storages that survive crashes and span
machines, worker processes that pull trials, and the report (best trials, the thesis's mean of the top-k, plots).

A study lives in its storage together with its *recipe*: the base config, the search space, the objective and
the trial budget. The default storage is an Optuna journal file, ``<root>/<name>/study.journal``; any SQLAlchemy
URL (PostgreSQL) works too, and then workers on several machines share the study. A worker process runs one
trial and exits (Taichi fields and compiled kernels are not freed inside a process); ``roshan study --workers
W`` keeps W of them busy. Each trial trains in ``<root>/<name>/trial_<n>/`` on the machine that ran it.

A trial whose worker died (killed, out of memory, machine lost) stays RUNNING in the storage until it is found
stale: at once when its worker was a process on this machine that no longer exists, otherwise when its
heartbeat is older than the grace period. It is then marked FAIL and queued again with the same parameters.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
import typing
import warnings
import zlib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import optuna
import yaml
from optuna.exceptions import ExperimentalWarning, UpdateFinishedTrialError
from optuna.storages import RDBStorage, RetryHeartbeatStaleTrialCallback
from optuna.storages._heartbeat import BaseHeartbeat  # the storages' heartbeat interface (RDBStorage uses it)
from optuna.storages.journal import JournalFileBackend, JournalStorage
from optuna.trial import FrozenTrial, TrialState

from roshan.config import Config, ConfigError, all_keys, from_dict, load_run_config, suggest, to_dict
from roshan.runs.train import rollout_steps, start_run, train

OBJECTIVES = {"success": "maximize", "reward": "maximize", "tte": "minimize"}  # learning.md 13
RECIPE_ATTR = "roshan_recipe"  # study user attribute holding the recipe
WORKER_ATTR = "roshan_worker"  # trial user attribute: {"host", "pid", "start"} of the process running it
HEARTBEAT_ATTR = "roshan_heartbeat"  # trial user attribute: last heartbeat (journal storage), Unix time
JOURNAL_NAME = "study.journal"
PARAM_FIELDS = {"float": {"low", "high", "log", "step"}, "int": {"low", "high", "log", "step"},
                "categorical": {"choices"}}


class StudyError(ValueError):
    """A study cannot be created, joined or reported; the message says what to change."""


def _quiet_optuna() -> None:
    """Optuna's INFO lines would interleave with the workers' progress bars."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)


@contextlib.contextmanager
def _experimental():
    """Heartbeats, stale-trial retries and the matplotlib plots are 'experimental' in Optuna (since 2.x) and
    warn at every use."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        yield


# ------------------------------------------------------------------------------------------------ search space


@dataclass(frozen=True)
class Param:
    """One sampled config key: ``float`` / ``int`` in [low, high] (optionally log-uniform or stepped), or
    ``categorical`` over ``choices``."""

    key: str
    type: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    step: float | None = None
    choices: tuple = ()

    def suggest(self, trial: optuna.Trial):
        if self.type == "float":
            return trial.suggest_float(self.key, self.low, self.high, log=self.log, step=self.step)
        if self.type == "int":
            return trial.suggest_int(self.key, int(self.low), int(self.high), log=self.log, step=int(self.step or 1))
        return trial.suggest_categorical(self.key, list(self.choices))

    def spec(self) -> dict:
        if self.type == "categorical":
            return {"type": "categorical", "choices": list(self.choices)}
        out = {"type": self.type, "low": self.low, "high": self.high, "log": self.log}
        return out if self.step is None else {**out, "step": self.step}


@dataclass(frozen=True)
class SearchSpace:
    """The sampled keys plus ``tie``: keys that copy a sampled key's value (the reference copies the sampled
    BoundaryTerminal coefficient into Collision)."""

    params: tuple[Param, ...]
    tie: tuple[tuple[str, str], ...] = ()  # (copied key, sampled key)

    def sample(self, trial: optuna.Trial) -> dict[str, Any]:
        values = {p.key: p.suggest(trial) for p in self.params}
        return self.with_ties(values)

    def with_ties(self, values: dict[str, Any]) -> dict[str, Any]:
        return {**values, **{dst: values[src] for dst, src in self.tie if src in values}}

    def to_dict(self) -> dict:
        return {"params": {p.key: p.spec() for p in self.params}, "tie": dict(self.tie)}


def load_space(path: str | Path, base: Config) -> SearchSpace:
    """Read and validate a search-space YAML (see ``configs/spaces/``) against the config ``base``."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise StudyError(f"{path}: cannot read search space ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise StudyError(f"{path}: not valid YAML ({exc})") from exc
    return parse_space(data, base, where=str(path))


def parse_space(data: Any, base: Config, where: str = "search space") -> SearchSpace:
    """``{"params": {dotted.key: spec, ...}, "tie": {dotted.key: sampled.key}}`` -> :class:`SearchSpace`.

    Raises:
        StudyError: unknown keys (with the closest valid one), unknown spec fields, empty or invalid ranges, and
            bounds or choices the config itself rejects.
    """
    if not isinstance(data, dict) or not isinstance(data.get("params"), dict) or not data["params"]:
        raise StudyError(f"{where}: expected a mapping with a non-empty 'params' section "
                         "(dotted.config.key: {type: float, low: .., high: ..}) and optionally 'tie'")
    unknown = set(data) - {"params", "tie"}
    if unknown:
        raise StudyError(f"{where}: unknown section(s) {sorted(unknown)}; expected 'params' and 'tie'")
    params = tuple(_parse_param(key, spec, base, where) for key, spec in data["params"].items())
    tie = data.get("tie") or {}
    if not isinstance(tie, dict):
        raise StudyError(f"{where}: 'tie' must map a config key to a sampled key, got {tie!r}")
    sampled = {p.key: p for p in params}
    for dst, src in tie.items():
        _check_key(dst, f"{where}: tie")
        if src not in sampled:
            raise StudyError(f"{where}: tie {dst}: {src!r} is not one of the sampled keys {sorted(sampled)}")
        if dst in sampled:
            raise StudyError(f"{where}: tie {dst}: this key is sampled itself; list it in 'params' or 'tie', not both")
        _check_values(base, dst, _probe_values(sampled[src]), f"{where}: tie {dst} (copies {src})")
    return SearchSpace(params, tuple(tie.items()))


def _parse_param(key: str, spec: Any, base: Config, where: str) -> Param:
    _check_key(key, where)
    at = f"{where}: {key}"
    if not isinstance(spec, dict) or spec.get("type") not in PARAM_FIELDS:
        raise StudyError(f"{at}: expected {{type: float|int|categorical, ...}}, got {spec!r}")
    kind = spec["type"]
    extra = set(spec) - PARAM_FIELDS[kind] - {"type"}
    if extra:
        raise StudyError(f"{at}: unknown field(s) {sorted(extra)} for type {kind}; "
                         f"expected {sorted(PARAM_FIELDS[kind])}")
    _check_field_type(key, kind, at)
    if kind == "categorical":
        choices = spec.get("choices")
        if not isinstance(choices, list) or not choices:
            raise StudyError(f"{at}: 'choices' must be a non-empty list")
        param = Param(key, kind, choices=tuple(choices))
    else:
        param = _parse_range(key, kind, spec, at)
    _check_values(base, key, _probe_values(param), at)
    return param


def _parse_range(key: str, kind: str, spec: dict, at: str) -> Param:
    low, high = _number(spec, "low", at), _number(spec, "high", at)
    step = _number(spec, "step", at) if spec.get("step") is not None else None
    log = spec.get("log", False)
    if not isinstance(log, bool):
        raise StudyError(f"{at}: 'log' must be true or false, got {log!r}")
    if not low < high:
        raise StudyError(f"{at}: empty range [{low}, {high}]; 'low' must be below 'high' "
                         "(to fix a value, use --set instead)")
    if log and low <= 0:
        raise StudyError(f"{at}: a log range needs low > 0, got [{low}, {high}]")
    if step is not None and (step <= 0 or log):
        raise StudyError(f"{at}: 'step' must be > 0 and cannot be combined with log: true")
    if kind == "int" and not all(float(v).is_integer() for v in (low, high, step or 1)):
        raise StudyError(f"{at}: an int range needs whole-number low/high/step, got [{low}, {high}]")
    return Param(key, kind, low=low, high=high, log=log, step=step)


def _number(spec: dict, name: str, at: str) -> float:
    value = spec.get(name)
    try:  # YAML 1.1 reads 1e-3 (no dot) as a string
        if isinstance(value, bool):
            raise ValueError
        out = float(value)
    except (TypeError, ValueError):
        raise StudyError(f"{at}: '{name}' must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise StudyError(f"{at}: '{name}' must be finite, got {value!r}")
    return out


def _check_key(key: str, where: str) -> None:
    if key in all_keys(Config):
        return
    raise StudyError(f"{where}: unknown key {key!r}{suggest(str(key), all_keys(Config))}")


def _leaf_type(key: str) -> type:
    cls: Any = Config
    for part in key.split("."):
        hint = typing.get_type_hints(cls)[part]
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        cls = args[0] if args else hint
    return cls


def _check_field_type(key: str, kind: str, at: str) -> None:
    leaf = _leaf_type(key)
    allowed = {float: ("float", "int", "categorical"), int: ("int", "categorical")}.get(leaf, ("categorical",))
    if kind not in allowed:
        raise StudyError(f"{at}: the config field is {leaf.__name__}; use type {' or '.join(allowed)}")


def _probe_values(p: Param) -> list:
    if p.type == "categorical":
        return list(p.choices)
    return [int(p.low), int(p.high)] if p.type == "int" else [p.low, p.high]


def _check_values(base: Config, key: str, values: list, at: str) -> None:
    """Every bound or choice must be a value the config accepts for ``key``."""
    for v in values:
        try:
            with_values(base, {key: v})
        except ConfigError as exc:
            raise StudyError(f"{at}: {v!r} is not accepted by the config ({exc})") from None


def with_values(cfg: Config, values: dict[str, Any], where: str = "study") -> Config:
    """A validated copy of ``cfg`` with dotted keys set to (already typed) values."""
    data = to_dict(cfg)
    for key, value in values.items():
        node = data
        *parents, leaf = key.split(".")
        for p in parents:
            node = node[p]
        node[leaf] = value
    return from_dict(type(cfg), data, where=where)


# ------------------------------------------------------------------------------------------------ recipe


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
    if base.train.algo == "ppo":  # a base config every trial would fail with is an error now, not N failures later
        rollout_steps(base)
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


# ------------------------------------------------------------------------------------------------ storages


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


HOST_ID = f"{socket.gethostname()}/{_boot_id()}"  # a reboot makes every old pid dead


def _process_start(pid: int) -> str | None:
    """Start time of ``pid`` in clock ticks since boot (Linux), so a reused pid is not taken for the old one;
    ``"zombie"`` for a process that exited but was not reaped; None where /proc is missing."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return "zombie" if fields[0] in "ZX" else fields[19]


def worker_record() -> dict:
    return {"host": HOST_ID, "pid": os.getpid(), "start": _process_start(os.getpid())}


def is_dead_here(record: dict | None) -> bool:
    """True when ``record`` names a process of this machine that no longer runs."""
    if not record or record.get("host") != HOST_ID:
        return False
    pid = int(record["pid"])
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # alive, owned by someone else
        pass
    start = _process_start(pid)
    return start == "zombie" or (record.get("start") is not None and start is not None and start != record["start"])


class RetryStaleTrial(RetryHeartbeatStaleTrialCallback):
    """Optuna's retry of a stale trial (same parameters, ``retry_history`` kept), minus the dead worker's
    liveness attributes, which would make the retry look stale before its new worker writes its own."""

    def __call__(self, study: optuna.Study, trial: FrozenTrial) -> None:
        trial = copy.deepcopy(trial)
        trial.user_attrs = {k: v for k, v in trial.user_attrs.items() if k not in (WORKER_ATTR, HEARTBEAT_ATTR)}
        super().__call__(study, trial)


class HeartbeatJournalStorage(JournalStorage, BaseHeartbeat):
    """A journal-file storage with the heartbeat of :class:`optuna.storages.RDBStorage`: a running trial's worker
    writes a timestamp every ``heartbeat_interval`` s; Optuna fails (and our callback retries) stale trials."""

    def __init__(self, path: str, heartbeat_interval: int, grace_period: int, callback: Callable):
        super().__init__(JournalFileBackend(path))
        self.heartbeat_interval, self.grace_period, self.callback = heartbeat_interval, grace_period, callback

    def record_heartbeat(self, trial_id: int) -> None:
        try:
            self.set_trial_user_attr(trial_id, HEARTBEAT_ATTR, time.time())
        except UpdateFinishedTrialError:  # another worker found the trial stale; the trial result is refused
            pass

    def _get_stale_trial_ids(self, study_id: int) -> list[int]:
        now, stale = time.time(), []
        for t in self.get_all_trials(study_id, deepcopy=False, states=(TrialState.RUNNING,)):
            last = t.user_attrs.get(HEARTBEAT_ATTR) or (t.datetime_start.timestamp() if t.datetime_start else now)
            if is_dead_here(t.user_attrs.get(WORKER_ATTR)) or now - last > self.grace_period:
                stale.append(t._trial_id)
        return stale

    def get_heartbeat_interval(self) -> int | None:
        return self.heartbeat_interval

    def get_heartbeat_stale_trial_callback(self) -> Callable | None:
        return self.callback


class HeartbeatRDBStorage(RDBStorage):
    """Optuna's RDB storage (heartbeats in the database), plus: a trial whose worker was a process on this
    machine that no longer exists is stale at once."""

    def _get_stale_trial_ids(self, study_id: int) -> list[int]:
        stale = set(super()._get_stale_trial_ids(study_id))
        for t in self.get_all_trials(study_id, deepcopy=False, states=(TrialState.RUNNING,)):
            if is_dead_here(t.user_attrs.get(WORKER_ATTR)):
                stale.add(t._trial_id)
        return sorted(stale)


def is_url(storage: str) -> bool:
    return "://" in str(storage)


def display_url(storage: str) -> str:
    """The storage without its password, for messages."""
    if not is_url(storage):
        return str(storage)
    try:
        from sqlalchemy.engine import make_url

        return make_url(storage).render_as_string(hide_password=True)
    except Exception:  # not parseable: show only the scheme
        return storage.split("://", 1)[0] + "://..."


def _with_postgres_driver(url: str) -> str:
    """``postgresql://`` with the driver that is installed: SQLAlchemy 2.0 means psycopg2 by it, 2.1 psycopg 3."""
    if not url.startswith("postgresql://"):
        return url
    import importlib.util

    for module, dialect in (("psycopg2", "postgresql+psycopg2"), ("psycopg", "postgresql+psycopg")):
        if importlib.util.find_spec(module) is not None:
            return dialect + url[len("postgresql"):]
    return url  # SQLAlchemy's ImportError below names the missing driver


def open_storage(storage: str, heartbeat: int | None = 60, max_retry: int | None = 3):
    """A journal file (a path) or an RDB storage (a SQLAlchemy URL such as ``postgresql://user:pw@host/db``),
    with heartbeats every ``heartbeat`` s (None: off) and up to ``max_retry`` retries of stale trials.

    Raises:
        StudyError: the database cannot be reached, the driver is missing, or the file cannot be written.
    """
    _quiet_optuna()
    with _experimental():
        callback = RetryStaleTrial(max_retry=max_retry)
    grace = 5 * heartbeat if heartbeat else None
    if not is_url(storage):
        path = Path(storage)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if heartbeat:
                return HeartbeatJournalStorage(str(path), heartbeat, grace, callback)
            return JournalStorage(JournalFileBackend(str(path)))
        except OSError as exc:
            raise StudyError(f"{path}: cannot open the study journal ({exc.strerror})") from exc
    url = _with_postgres_driver(storage)
    kwargs: dict[str, Any] = {"pool_pre_ping": True}  # trials last hours: connections may go stale meanwhile
    if url.startswith("postgresql"):
        kwargs["connect_args"] = {"connect_timeout": 10}
    hb = {"heartbeat_interval": heartbeat, "grace_period": grace, "heartbeat_stale_trial_callback": callback}
    try:
        with _experimental():
            return HeartbeatRDBStorage(url, engine_kwargs=kwargs, **(hb if heartbeat else {}))
    except ImportError as exc:
        raise StudyError(f"{display_url(storage)}: the database driver is missing ({exc.__cause__ or exc}); for "
                         "PostgreSQL: pip install psycopg2-binary") from exc
    except Exception as exc:  # sqlalchemy errors: unreachable server, bad credentials, unknown dialect
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise StudyError(f"cannot open the study storage {display_url(storage)}: {first}. Is the server running "
                         "and reachable, and do the database and user exist? (README: Multi-machine Optuna study)"
                         ) from exc


# ------------------------------------------------------------------------------------------------ studies


def study_dir(root: str | Path, name: str) -> Path:
    return Path(root) / name


def default_storage(root: str | Path, name: str) -> str:
    return str((study_dir(root, name) / JOURNAL_NAME).resolve())


def _sampler(recipe: Recipe, seed: int | None = None) -> optuna.samplers.BaseSampler:
    return optuna.samplers.TPESampler(n_startup_trials=recipe.startup_trials, seed=seed, multivariate=True,
                                      constant_liar=True)  # running trials count as bad: workers spread out


def _pruner(recipe: Recipe) -> optuna.pruners.BasePruner:
    if not recipe.prune or recipe.objective == "tte":  # learning.md 13: no pruning with time_to_end
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
    study.sampler, study.pruner = _sampler(recipe), _pruner(recipe)
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


def default_name(config_path: str | Path | None, space_path: str | Path) -> str:
    return f"{Path(config_path).stem if config_path else 'defaults'}-{Path(space_path).stem}"


def worker_args(workers: int, arch: str | None, threads: int | None, quiet: bool, heartbeat: int | None,
                max_retry: int | None) -> list[str]:
    """The options a worker process gets: this machine's arch and threads (W workers share the cores unless
    ``threads`` is given), display and heartbeat settings."""
    threads = threads or (max(1, (os.cpu_count() or 1) // workers) if workers > 1 else None)
    args = ["--arch", arch] if arch else []
    args += ["--threads", str(threads)] if threads else []
    args += ["--heartbeat", str(heartbeat)] if heartbeat else []
    args += ["--max-retry", str(max_retry)] if max_retry is not None else []
    return args + (["--quiet"] if quiet else [])


def local_values(arch: str | None, threads: int | None) -> dict[str, Any]:
    """Per-machine config values of a worker (not part of the recipe)."""
    out: dict[str, Any] = {"sim.arch": arch} if arch else {}
    return {**out, "sim.threads": threads, "train.torch_threads": threads} if threads else out


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
    with _experimental():
        optuna.storages.fail_stale_trials(study)


# ------------------------------------------------------------------------------------------------ one trial


def objective_value(summary: dict, objective: str) -> float:
    """The trial's value from an evaluation summary (roshan.report.summarize)."""
    if objective == "success":
        return float(summary["success_rate"])
    stats = summary["reward" if objective == "reward" else "tte"]
    if stats["mean"] is None:
        return -math.inf if objective == "reward" else math.inf
    return float(stats["mean"])


class TrialDisplay:
    """The worker's progress line: trial, updates (or env steps) of the budget, training objective, reward."""

    def __init__(self, number: int, cfg: Config, slot: int, quiet: bool):
        from tqdm import tqdm

        tc = cfg.train
        self.by_steps = tc.max_updates == 0 and tc.total_steps > 0
        self.bar = tqdm(total=tc.max_updates or tc.total_steps or None, position=slot, leave=False,
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
        return objective_value(ev, recipe.objective)

    return objective


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
    study.sampler = _sampler(recipe, seed)
    try:
        # A sampled combination the config rejects (ValueError, e.g. horizon vs num_envs) fails only its trial.
        study.optimize(make_objective(recipe, root, name, slot, local, quiet), n_trials=1, catch=(ValueError,))
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the requeue short
        me = worker_record()
        for t in study.get_trials(deepcopy=False, states=(TrialState.FAIL,)):
            if t.user_attrs.get(WORKER_ATTR) == me:
                with _experimental():
                    RetryStaleTrial(max_retry=None)(study, t)
        return 130
    return 0


# ------------------------------------------------------------------------------------------------ launcher


def _trial_line(t: FrozenTrial, recipe: Recipe, retried: bool) -> str:
    a = t.user_attrs
    if t.state == TrialState.COMPLETE:
        what = (f"{recipe.objective} = {t.value:.4g} (success {a.get('success_rate', float('nan')):.2f}, "
                f"reward {a.get('reward', float('nan')):+.3f}, {a.get('minutes', 0):.1f} min)")
    elif t.state == TrialState.PRUNED:
        what = f"pruned at update {t.last_step}"
    else:
        what = "failed" + (" (its worker died or was interrupted; queued again)" if retried else "")
    return f"trial {t.number}: {what}"


class Launcher:
    """Keeps ``workers`` worker processes (one trial each) running while the study has trials to start."""

    def __init__(self, storage_url: str, name: str, root: str | Path, workers: int, worker_args: list[str],
                 echo: Callable[[str], None] = print, poll: float = 1.0):
        self.storage_url, self.name, self.root, self.workers = storage_url, name, str(root), workers
        self.worker_args, self.echo, self.poll = worker_args, echo, poll
        self.procs: dict[int, subprocess.Popen] = {}
        self.crashed: str | None = None
        self.reported: set[int] = set()

    def spawn(self, slot: int) -> subprocess.Popen:
        cmd = [sys.executable, "-m", "roshan", "study", "run", "--worker", "--slot", str(slot), "--storage",
               self.storage_url, "--name", self.name, "--root", self.root, *self.worker_args]
        # The workers import this very roshan, installed or not.
        paths = [str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")]
        return subprocess.Popen(cmd, env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)})

    def reap(self) -> None:
        for slot, p in list(self.procs.items()):
            rc = p.poll()
            if rc is None:
                continue
            del self.procs[slot]
            if rc < 0:
                self.echo(f"worker {slot} (pid {p.pid}) was killed by signal {-rc}: its trial is failed and retried")
            elif rc == 130:
                self.crashed = self.crashed or "interrupted"
            elif rc != 0:
                self.crashed = self.crashed or f"worker {slot} (pid {p.pid}) failed with exit code {rc}"

    def report_finished(self, study: optuna.Study, recipe: Recipe) -> None:
        trials = study.get_trials(deepcopy=False)
        retried = {n for t in trials for n in t.system_attrs.get("retry_history", [])}
        for t in trials:
            if t.state.is_finished() and t.number not in self.reported:
                self.reported.add(t.number)
                self.echo(_trial_line(t, recipe, t.number in retried))

    def tick(self, study: optuna.Study, recipe: Recipe) -> None:
        fail_stale(study)
        self.reap()
        self.report_finished(study, recipe)
        b = budget(study, recipe.trials)
        mine = {r.get("pid") for r in b.running if r.get("host") == HOST_ID}
        starting = sum(p.pid not in mine for p in self.procs.values())  # spawned, trial not asked for yet
        free = [s for s in range(self.workers) if s not in self.procs]
        if self.crashed is None:
            for slot in free[:max(0, b.to_start - starting)]:
                self.procs[slot] = self.spawn(slot)

    def run(self, study: optuna.Study, recipe: Recipe) -> None:
        self.reported = {t.number for t in study.get_trials(deepcopy=False) if t.state.is_finished()}
        try:
            while True:
                self.tick(study, recipe)
                if not self.procs:
                    break
                time.sleep(self.poll)
        except KeyboardInterrupt:
            self.stop()
            raise StudyError(f"interrupted; the running trials were failed and queued again. Continue with "
                             f"`roshan study --resume --name {self.name}`") from None
        self.report_finished(study, recipe)
        if self.crashed:
            raise StudyError(f"{self.crashed} (see above); the study is intact: fix the cause and continue it "
                             f"with --resume")

    def stop(self) -> None:
        """After Ctrl-C: the workers got SIGINT from the terminal too and queue their trials again; wait for them.
        A second Ctrl-C stops waiting and terminates them (their trials are then retried as stale)."""
        self.echo(f"stopping {len(self.procs)} worker(s) (Ctrl-C again to terminate them)")
        try:
            for p in self.procs.values():
                p.wait()
        except KeyboardInterrupt:
            for p in self.procs.values():
                p.terminate()


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
    store = open_storage(url, heartbeat, max_retry)
    prepare_study(store, name, recipe, resume, settings, trials, where=display_url(url))
    args = worker_args(workers, arch, threads, quiet, heartbeat, max_retry)
    study = run_study(url, name, root, workers, args, heartbeat, max_retry, echo)
    top = best_trials(study, 1)
    if top:
        echo(f"best: trial {top[0].number}, {recipe_of(study).objective} = {top[0].value:.4g}, {top[0].params}")
    where = f"{display_url(url)} --name {name}" if storage else f"{name} --root {root}"
    echo(f"report: roshan study report {where}")
    return study


# ------------------------------------------------------------------------------------------------ report


def best_trials(study: optuna.Study, k: int) -> list[FrozenTrial]:
    """The ``k`` best COMPLETE trials, best first."""
    done = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)) if t.value == t.value]
    sign = -1.0 if study.direction == optuna.study.StudyDirection.MAXIMIZE else 1.0
    return sorted(done, key=lambda t: (sign * t.value, t.number))[:k]


def mean_of_top_k(study: optuna.Study, k: int = 10) -> dict[str, Any]:
    """The thesis's method (learning.md 13, Tables 5.5 / 5.9): the arithmetic mean of each parameter over the
    ``k`` best trials (ints rounded, categoricals: the most common, ties to the better trial), ties applied."""
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
    attrs = ["success_rate", "reward", "tte", "updates", "minutes", "host", "run_dir"]
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
        path = study_dir(root, target)
    journal = path / JOURNAL_NAME if path.is_dir() else path
    if not journal.is_file():
        raise StudyError(f"{target}: no study found (looked for {journal}); give a study name under --root, a study "
                         "folder, a journal file or a storage URL")
    storage = open_storage(str(journal), heartbeat=None)
    names = optuna.get_all_study_names(storage)
    name = name or (names[0] if len(names) == 1 else journal.parent.name)
    study, _ = load_study(storage, name)
    return study, journal.parent / "report"
