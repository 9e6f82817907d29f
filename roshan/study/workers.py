"""Worker processes on this machine: ``roshan study --workers W`` keeps W of them busy, one trial each, while the
study has trials to start, and reports each trial as it finishes.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import optuna
from optuna.trial import FrozenTrial, TrialState

from roshan.runtime import share_cores
from roshan.study.errors import StudyError
from roshan.study.recipe import Recipe
from roshan.study.storage import HOST_ID
from roshan.study.studies import budget, fail_stale


def worker_args(workers: int, arch: str | None, threads: int | None, quiet: bool, heartbeat: int | None,
                max_retry: int | None) -> list[str]:
    """The options a worker process gets: this machine's arch and threads (W workers share the cores unless
    ``threads`` is given), display and heartbeat settings."""
    _, threads = share_cores(workers, threads)
    args = ["--arch", arch] if arch else []
    args += ["--threads", str(threads)] if threads else []
    args += ["--heartbeat", str(heartbeat)] if heartbeat else []
    args += ["--max-retry", str(max_retry)] if max_retry is not None else []
    return args + (["--quiet"] if quiet else [])


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

    def continue_hint(self) -> str:
        """The command that continues after an interruption or a crash."""
        return f"roshan study run --resume --name {self.name} --root {self.root}"

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
                             f"`{self.continue_hint()}`") from None
        self.report_finished(study, recipe)
        if self.crashed:
            raise StudyError(f"{self.crashed} (see above); nothing finished is lost: fix the cause and continue "
                             f"with `{self.continue_hint()}`")

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
