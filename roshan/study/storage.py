"""Where a study lives and how its dead trials are found: Optuna storages (a journal file by default, any
SQLAlchemy URL such as PostgreSQL so workers on several machines share the study) with heartbeats, and the
liveness of worker processes.

A trial whose worker died (killed, out of memory, machine lost) stays RUNNING in the storage until it is found
stale: at once when its worker was a process on this machine that no longer exists, otherwise when its
heartbeat is older than the grace period and its worker is not a process that still runs here (a paused
worker keeps its run). It is then marked FAIL and queued again with the same parameters.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import shutil
import socket
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import optuna
from optuna.exceptions import ExperimentalWarning, UpdateFinishedTrialError
from optuna.storages import RDBStorage, RetryHeartbeatStaleTrialCallback
from optuna.storages._heartbeat import BaseHeartbeat  # the storages' heartbeat interface (RDBStorage uses it)
from optuna.storages.journal import JournalFileBackend, JournalFileSymlinkLock, JournalStorage
from optuna.storages.journal._file import get_lock_file  # the lock Optuna's appends take
from optuna.trial import FrozenTrial, TrialState

from roshan.io import write_atomic, writing
from roshan.study.errors import StudyError

WORKER_ATTR = "roshan_worker"  # trial user attribute: {"host", "pid", "start"} of the process running it
HEARTBEAT_ATTR = "roshan_heartbeat"  # trial user attribute: last heartbeat (journal storage), Unix time
JOURNAL_NAME = "study.journal"


def quiet_optuna() -> None:
    """Optuna's INFO lines would interleave with the workers' progress bars."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)


@contextlib.contextmanager
def experimental():
    """Heartbeats, stale-trial retries and the matplotlib plots are 'experimental' in Optuna (since 2.x) and
    warn at every use."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        yield


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


def is_alive_here(record: dict | None) -> bool:
    """True when ``record`` names a process of this machine that still runs. Such a trial is never stale,
    however old its heartbeat: a paused worker (SIGSTOP, a suspended machine) still owns its run, and failing
    it would start the run a second time beside it."""
    return bool(record) and record.get("host") == HOST_ID and not is_dead_here(record)


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
            worker = t.user_attrs.get(WORKER_ATTR)
            if is_dead_here(worker) or (now - last > self.grace_period and not is_alive_here(worker)):
                stale.append(t._trial_id)
        return stale

    def get_heartbeat_interval(self) -> int | None:
        return self.heartbeat_interval

    def get_heartbeat_stale_trial_callback(self) -> Callable | None:
        return self.callback


class HeartbeatRDBStorage(RDBStorage):
    """Optuna's RDB storage (heartbeats in the database), plus: a trial whose worker was a process on this
    machine that no longer exists is stale at once, and one whose worker still runs here is never stale."""

    def _get_stale_trial_ids(self, study_id: int) -> list[int]:
        stale = set(super()._get_stale_trial_ids(study_id))
        for t in self.get_all_trials(study_id, deepcopy=False, states=(TrialState.RUNNING,)):
            worker = t.user_attrs.get(WORKER_ATTR)
            if is_dead_here(worker):
                stale.add(t._trial_id)
            elif is_alive_here(worker):
                stale.discard(t._trial_id)
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


def _cut_line(path: Path) -> int | None:
    """The number (1-based) of the journal's cut or unreadable last record, None if the journal is whole.
    A damage on an earlier line is refused: dropping it would lose trials (and Optuna would misread the rest)."""
    lines = path.read_bytes().split(b"\n")
    tail = lines.pop()  # b"" when the file ends with a newline, as every whole journal does
    for number, line in enumerate(lines, 1):
        try:
            json.loads(line)
        except ValueError:
            if number < len(lines) or tail:
                raise StudyError(f"{path}: line {number} of the study journal is damaged (not a JSON record) and "
                                 "is not its last line, so it cannot be dropped safely; restore the journal from a "
                                 "backup, or mend that line by hand") from None
            return number
    return len(lines) + 1 if tail else None


def check_journal(path: str | Path, repair: bool = False, echo: Callable[[str], None] | None = None,
                  repair_hint: str | None = None) -> None:
    """Find a journal whose last record was cut (a full disk or a killed write leaves one; once another record
    is appended after it the journal is unreadable for good). With ``repair`` the original is copied to
    ``<journal>.damaged-<time>`` and the cut line dropped; otherwise a StudyError names the journal and the fix
    (``repair_hint``: the command that repairs it, default the study's)."""
    path = Path(path)
    if not path.is_file():
        return
    if not repair:  # no lock: a report may read a journal in a folder it cannot write
        number = _cut_line(path)
        if number is not None:
            _repair_journal(path, number, repair, echo, repair_hint)
        return
    # Under the journal's own lock, so that another worker's append in progress is not taken for a cut record.
    with writing("the study journal's lock", path), get_lock_file(JournalFileSymlinkLock(str(path))):
        number = _cut_line(path)
        if number is not None:
            _repair_journal(path, number, repair, echo)


def _repair_journal(path: Path, number: int, repair: bool, echo: Callable[[str], None] | None,
                    repair_hint: str | None = None) -> None:
    if not repair:
        hint = repair_hint or (f"`roshan study run --resume --name {path.parent.name} --root {path.parent.parent}` "
                               f"(with --storage {path} if it is not the default journal)")
        raise StudyError(f"{path}: the last record (line {number}) of the study journal is cut (a full disk or a "
                         f"killed write?); {hint} drops it, keeping a copy of the original")
    data = path.read_bytes()
    whole = data[:data.rstrip(b"\n").rfind(b"\n") + 1]  # up to and including the last whole line's newline
    copy_path = path.with_name(f"{path.name}.damaged-{time.strftime('%Y%m%d-%H%M%S')}")
    with writing("a copy of the damaged study journal", copy_path):
        shutil.copy2(path, copy_path)
    with writing("the repaired study journal", path):
        write_atomic(path, whole)
    (echo or print)(f"{path}: its last record (line {number}) was cut; dropped it ({len(data) - len(whole)} bytes), "
                    f"the original is kept as {copy_path}")


def open_storage(storage: str, heartbeat: int | None = 60, max_retry: int | None = 3, repair: bool | None = None,
                 echo: Callable[[str], None] | None = None, repair_hint: str | None = None):
    """A journal file (a path) or an RDB storage (a SQLAlchemy URL such as ``postgresql://user:pw@host/db``),
    with heartbeats every ``heartbeat`` s (None: off) and up to ``max_retry`` retries of stale trials.
    A journal's cut last record is dropped (``repair=True``, told to ``echo``) or refused (``False``, see
    :func:`check_journal`); None skips the check (a worker: the study's launcher checked it).

    Raises:
        StudyError: the database cannot be reached, the driver is missing, the file cannot be written, or the
            journal is damaged.
    """
    quiet_optuna()
    with experimental():
        callback = RetryStaleTrial(max_retry=max_retry)
    grace = 5 * heartbeat if heartbeat else None
    if not is_url(storage):
        path = Path(storage)
        if repair is not None:
            check_journal(path, repair, echo, repair_hint)
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
        with experimental():
            return HeartbeatRDBStorage(url, engine_kwargs=kwargs, **(hb if heartbeat else {}))
    except ImportError as exc:
        raise StudyError(f"{display_url(storage)}: the database driver is missing ({exc.__cause__ or exc}); for "
                         "PostgreSQL: pip install psycopg2-binary") from exc
    except Exception as exc:  # sqlalchemy errors: unreachable server, bad credentials, unknown dialect
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise StudyError(f"cannot open the study storage {display_url(storage)}: {first}. Is the server running "
                         "and reachable, and do the database and user exist? (README: Multi-machine Optuna study)"
                         ) from exc
