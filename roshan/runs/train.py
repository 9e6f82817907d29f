"""The training loop: a vector env (FlyAgent or planner), an algorithm, TensorBoard, checkpoints, resume and evaluation.

One *iteration* collects data and updates once (PPO: a rollout of ``horizon`` transitions, then k epochs;
TD3: a few env steps, each followed by an update; IQL: one offline pass over the dataset). After every
iteration the loop logs, writes ``latest`` (and ``best_*`` when their metric ties or improves) and checks the
budget. A killed run resumes from ``latest`` with its counters, optimisers, reward scaler and RNG states.
"""

import contextlib
import math
import shlex
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.tensorboard import SummaryWriter

from roshan import reproducible
from roshan.algos.agents import make_agent
from roshan.algos.frozen import policy_fn
from roshan.checkpoints import (
    check_fits,
    checkpoint_path,
    config_dict,
    config_of_checkpoint,
    load_checkpoint,
    resolve_checkpoint,
    run_lock,
    save_checkpoint,
)
from roshan.config import Config, dump_config
from roshan.io import OutputError, prepare_output, progress_bar, writing
from roshan.runs.budget import budget_total
from roshan.runs.envs import make_env
from roshan.runs.episode_log import EpisodeLog
from roshan.runs.evaluate import evaluate_run, run_episodes
from roshan.runs.learners import check_learnable, fleet_turns
from roshan.runs.report.stats import evaluation_scalars, summarize
from roshan.runs.resume import resume_config, resume_state  # noqa: F401  (resume_config: cli's name)
from roshan.runs.tboard import EpisodeFrames, add_config, add_hparams, add_video, log_episodes, log_update
from roshan.runtime import current_arch, ensure_taichi, init_taichi, torch_device

# ------------------------------------------------------------------------------------------------ the loop


@dataclass
class Progress:
    """Counters saved with every checkpoint."""

    updates: int = 0
    env_steps: int = 0
    seconds: float = 0.0
    best_reward: float = -math.inf
    best_objective: float = -math.inf
    best_eval: float = -math.inf

    def state_dict(self) -> dict:
        return dict(self.__dict__)


class TrainingStopped(ValueError):
    """A training run stopped because something could not be written; the message says what and how to resume."""


class Trainer:
    """One training run in ``run_dir`` (new or resumed)."""

    def __init__(self, cfg: Config, run_dir: Path, resume_state: dict | None = None, progress_bar: bool = True,
                 on_update: Callable[[dict], None] | None = None, resumed_from: Path | None = None):
        self.cfg, self.run_dir = cfg, Path(run_dir)
        self.resumed_from = resumed_from or checkpoint_path(run_dir, "latest")  # the file resume_state came from
        self.progress_bar, self.on_update = progress_bar, on_update
        tc = cfg.train
        check_learnable(cfg)  # e.g. a PPO horizon that does not split over the rows: before anything is built
        self.generator = torch.Generator().manual_seed(cfg.sim.seed)
        self.agent = make_agent(cfg, torch_device(), seed=cfg.sim.seed)
        self.progress = Progress()
        self.episodes = EpisodeLog(window=tc.objective_window)
        self.saved_update: int | None = None  # the update of the last latest.pt this process knows is whole
        self.machines: list[dict] = []  # what trained each stretch of the run (reproducible.machine, from_update)
        if resume_state is not None:
            self._restore(resume_state)
            self.saved_update = self.progress.updates
        elif tc.init_from:
            self._init_weights(tc.init_from)
        # A resumed run starts fresh episodes from a seed that depends on where it stopped. An env and a learner per
        # fleet of planner.fleet_sizes, each taking its turn for an update; else one.
        self.turns = fleet_turns(cfg, self.agent, seed=cfg.sim.seed + 7919 * self.progress.updates)
        self.env, self.learner = self.turns[self.progress.updates % len(self.turns)]
        self.eval_env = None
        self.last_eval: dict | None = None  # the summary of the last periodic evaluation
        self.stopped_by: str | None = None  # the budget that ended the run (stop_reason)
        self.writer = self._open_writer(resumed=resume_state is not None)

    @property
    def log_step(self) -> int:
        """The TensorBoard step of the last update: env steps, or updates where none were taken (IQL offline)."""
        return self.progress.env_steps or self.progress.updates

    def _open_writer(self, resumed: bool) -> SummaryWriter:
        """The run's TensorBoard writer. A resumed run drops only what a killed process logged after its last
        checkpoint (steps above that checkpoint's, which the resumed run logs again), never the checkpoint's own
        step, and records the resume with its command line."""
        purge = self.log_step + 1 if self.progress.updates else None
        writer = SummaryWriter(str(self.run_dir / "tb"), purge_step=purge)
        if resumed:
            writer.add_text("Run/resumed", f"resumed at update {self.progress.updates} ({self.progress.env_steps:,} "
                                           f"env steps): `{shlex.join(sys.argv)}`", self.log_step)
        add_config(writer, config_dict(self.cfg), self.log_step)
        if self.cfg.train.level.training_note:
            writer.add_text("Run/note", self.cfg.train.level.training_note, self.log_step)
        return writer

    def _final_metrics(self) -> dict[str, float]:
        """The HParams tab's metrics: the best and last evaluation, the training objective, the budget spent."""
        p, last = self.progress, self.last_eval or {}
        out = {"best_eval_success": p.best_eval, "objective": self.episodes.objective,
               "env_steps": float(p.env_steps), "minutes": p.seconds / 60.0}
        if last:
            out["last_eval_success"] = last["success_rate"]
            out["last_eval_tte"] = last["tte"]["mean"]
            out.update({f"last_eval_{r}_rate": v for r, v in last["failure_rates"].items()})
        return out

    def _init_weights(self, target: str) -> None:
        """Fine-tuning: the networks (not optimisers, counters or the reward scaler) of another run's checkpoint."""
        path = resolve_checkpoint(target)
        state = load_checkpoint(path)
        saved = config_of_checkpoint(state, str(path))
        check_fits(self.agent, state["agent"], self.cfg, saved, str(path), weights_only=True)
        self.agent.load_state_dict(state["agent"], weights_only=True)
        scaler = getattr(self.agent, "scaler", None)
        if scaler is not None and "scaler" in state["agent"]:  # the values were learned on that reward scale
            scaler.load_state_dict(state["agent"]["scaler"])

    def _restore(self, state: dict) -> None:
        # the whole state (optimisers too) is checked first: torch would fail halfway, or at the first step
        where = str(self.resumed_from)
        check_fits(self.agent, state["agent"], self.cfg, config_of_checkpoint(state, where), where, weights_only=False)
        self.agent.load_state_dict(state["agent"])
        for k, v in state["progress"].items():
            setattr(self.progress, k, v)
        self.episodes.load_state_dict(state["episodes"])
        self.generator.set_state(state["rng"]["generator"])
        torch.set_rng_state(state["rng"]["torch"])
        np.random.set_state(state["rng"]["numpy"])
        self.machines = list(state.get("machines", []))  # checkpoints before provenance have none

    def state_dict(self) -> dict:
        return {"algo": self.cfg.train.algo, "config": config_dict(self.cfg), "agent": self.agent.state_dict(),
                "progress": self.progress.state_dict(), "episodes": self.episodes.state_dict(),
                "rng": {"generator": self.generator.get_state(), "torch": torch.get_rng_state(),
                        "numpy": np.random.get_state()},
                "machines": self.machines}

    # ------------------------------------------------------------------------------------------ budget

    def done(self) -> bool:
        return self.stop_reason() is not None

    def stop_reason(self) -> str | None:
        """Which budget is spent, in words naming its key (None while none is)."""
        tc, p = self.cfg.train, self.progress
        if tc.total_steps > 0 and p.env_steps >= tc.total_steps:
            return f"train.total_steps = {tc.total_steps:,} reached ({p.env_steps:,} env steps)"
        if tc.max_updates > 0 and p.updates >= tc.max_updates:
            return f"train.max_updates = {tc.max_updates} reached"
        if tc.max_minutes > 0 and p.seconds >= 60.0 * tc.max_minutes:
            return f"train.max_minutes = {tc.max_minutes:g} reached ({p.seconds / 60.0:.1f} min)"
        return None

    def _bar(self):
        counts_steps = self.learner.counts_env_steps
        total = budget_total(self.cfg.train, self.progress, 0, counts_steps)
        return progress_bar(total=total, initial=self.progress.env_steps if counts_steps else self.progress.updates,
                    unit="step" if counts_steps else "update", dynamic_ncols=True,
                    disable=not self.progress_bar, desc=self.run_dir.name)

    # ------------------------------------------------------------------------------------------ run

    def run(self) -> Progress:
        """Train until the budget is spent. A write that fails (full disk, read-only folder) stops the run with a
        :class:`TrainingStopped` that says what could not be written and how to resume: the checkpoints are
        written atomically, so the last good one is whole."""
        self._note_machine()
        bar = self._bar()
        try:
            while not self.done():
                self._update(bar)
            self.stopped_by = self.stop_reason()
            bar.total = bar.n  # the bar ends where training ended
            bar.refresh()
            if self.progress_bar:
                bar.write(f"{self.run_dir.name}: training stopped: {self.stopped_by}")
            with writing("TensorBoard events", self.run_dir / "tb"):
                self.writer.add_text("Run/stopped", f"training stopped at update {self.progress.updates}: "
                                                    f"{self.stopped_by}", self.log_step)
                add_hparams(self.writer, config_dict(self.cfg), self._final_metrics())
                self.writer.close()  # flushes the last events: a full disk can show only here
        except OutputError as exc:
            raise self._stopped(exc) from None
        finally:
            bar.close()
            with contextlib.suppress(OSError):  # after a failure: the events written so far stay, nothing more can
                self.writer.close()
        return self.progress

    def _note_machine(self) -> None:
        """Record the machine (CPU, torch kernels, mode) that trains from here, unless it trained the last stretch:
        a run resumed elsewhere, or outside the reproducible mode, says so in its result."""
        here = reproducible.machine()
        last = self.machines[-1] if self.machines else None
        if last is None or {k: v for k, v in last.items() if k != "from_update"} != here:
            self.machines.append({**here, "from_update": self.progress.updates})

    def _update(self, bar) -> None:
        """One update: collect and learn, log, evaluate now and then, checkpoint."""
        t0 = time.perf_counter()
        self.env, self.learner = self.turns[self.progress.updates % len(self.turns)]
        steps, metrics, rows = self.learner.iterate(self.generator)
        self.episodes.add(rows)
        dt = time.perf_counter() - t0
        p = self.progress
        p.updates, p.env_steps, p.seconds = p.updates + 1, p.env_steps + steps, p.seconds + dt
        metrics["steps_per_s"] = steps / dt
        metrics["updates_per_s"] = 1.0 / dt
        with writing("TensorBoard events", self.run_dir / "tb"):
            self._log(metrics)
        if self.cfg.train.eval_every and p.updates % self.cfg.train.eval_every == 0:
            self._periodic_eval()  # before _checkpoint, so that latest carries the new best_eval
        self._checkpoint(metrics["rewards_raw"])
        counts_steps = self.learner.counts_env_steps
        bar.total = budget_total(self.cfg.train, p, steps, counts_steps)  # where the budget that binds stops it
        bar.update(steps if counts_steps else 1)
        # one speed readout: tqdm's own rate (steps/s, or updates/s where the bar counts updates)
        bar.set_postfix(success=f"{self.episodes.success_so_far:.2f}", R=f"{metrics['rewards_raw']:+.3f}",
                        refresh=False)
        if self.on_update is not None:
            self.on_update({"updates": p.updates, "env_steps": p.env_steps,
                            "objective": self.episodes.objective, "reward": metrics["rewards_raw"]})

    def _stopped(self, exc: OutputError) -> "TrainingStopped":
        if self.saved_update is None:
            how = "no checkpoint was written yet: start the run again"
        else:
            how = (f"`roshan train --resume {self.run_dir}` continues from the last checkpoint "
                   f"(update {self.saved_update})")
        return TrainingStopped(f"{exc}; training stopped at update {self.progress.updates}; {how}")

    def _save(self, state: dict, which: str) -> None:
        path = checkpoint_path(self.run_dir, which)
        with writing(f"checkpoint {which}", path):
            save_checkpoint(state, path)
        if which == "latest":
            self.saved_update = state["progress"]["updates"]

    def _log(self, m: dict) -> None:
        log_update(self.writer, self.log_step, m)
        ep = self.episodes.drain()
        if ep:
            log_episodes(self.writer, self.log_step, ep, self.env.failure_reasons)
        if len(self.episodes.recent) >= self.episodes.window:
            self.writer.add_scalar("Training/Objective", self.episodes.objective, self.log_step)

    def _periodic_eval(self) -> None:
        """Deterministic episodes with the current weights on a separate batch of envs (fixed seed, so the
        same fire layouts every time), logged as Evaluation/* scalars."""
        tc, seed = self.cfg.train, self.cfg.sim.seed + 10_000
        if self.eval_env is None:
            self.eval_env = make_env(self.cfg, min(tc.eval_envs, tc.eval_episodes), seed=seed, evaluation=True)
        env = self.eval_env
        frames = None
        if tc.eval_video_frames > 0:  # env 0's first episode, every k-th step
            frames = EpisodeFrames(env, tc.eval_video_frames, env.max_env_steps)
        episodes = run_episodes(env, policy_fn(self.agent), tc.eval_episodes, seed=seed, progress_bar=False,
                                on_step=frames.on_step if frames else None)
        summary = self.last_eval = summarize(episodes, reasons=env.failure_reasons, dt=self.cfg.fire.dt)
        with writing("TensorBoard events", self.run_dir / "tb"):  # the writer thread's failure shows at any add
            for tag, value in evaluation_scalars(summary).items():
                self.writer.add_scalar(tag, value, self.log_step)
            if frames is not None and frames.frames:
                add_video(self.writer, "Evaluation/episode_env0", frames.frames, self.log_step)
        # The deterministic policy is what gets shipped, and in the collision setting it can be much better or worse
        # than the stochastic training objective says: keep the weights that evaluated best.
        if summary["success_rate"] >= self.progress.best_eval:
            self.progress.best_eval = summary["success_rate"]
            self._save(self.state_dict(), "best_eval")

    def _checkpoint(self, batch_reward: float) -> None:
        """latest always; best_reward / best_objective when the metric ties or improves (docs/model/learning.md §9)."""
        p, state = self.progress, self.state_dict()
        self._save(state, "latest")
        if batch_reward == batch_reward and batch_reward >= p.best_reward:
            p.best_reward = batch_reward
            self._save(self.state_dict(), "best_reward")
        objective = self.episodes.objective
        if objective >= p.best_objective:
            p.best_objective = objective
            self._save(self.state_dict(), "best_objective")
        if state["progress"] != p.state_dict():  # the bests changed after latest was written
            self._save(self.state_dict(), "latest")


# ------------------------------------------------------------------------------------------------ entry points


def train(cfg: Config, run_dir: Path, resume: bool = False, progress_bar: bool = True,
          on_update: Callable[[dict], None] | None = None, evaluate_at_end: bool = True) -> dict:
    """Train one run in ``run_dir`` (continuing from its newest checkpoint if ``resume`` and it has one; ``cfg``
    goes to ``config.yaml`` where it differs from that checkpoint's), then evaluate its best checkpoint
    (``best_eval`` if periodic evaluation ran, else ``best_objective``) on episodes other than the periodic
    evaluation's, which chose it. Returns the evaluation summary plus the run's counters."""
    ensure_taichi_for(cfg)
    torch.set_num_threads(reproducible.torch_threads(cfg.train.torch_threads))
    prepare_output(Path(run_dir) / "checkpoints", "checkpoints")  # a read-only run folder fails before training
    with run_lock(run_dir):  # taken before anything is written: a refused process changes nothing
        state, path = resume_state(run_dir, cfg) if resume else (None, None)
        trainer = Trainer(cfg, run_dir, state, progress_bar, on_update, resumed_from=path)
        if state is not None and config_dict(cfg) != config_dict(config_of_checkpoint(state, str(path))):
            with writing("the run's config", Path(run_dir) / "config.yaml"):  # a later resume keeps the overrides
                dump_config(cfg, Path(run_dir) / "config.yaml")
        progress = trainer.run()
    result = {"run_dir": str(run_dir), **progress.state_dict(), "train_episodes": trainer.episodes.episodes,
              "stopped_by": trainer.stopped_by, "machines": trainer.machines}
    if evaluate_at_end:
        # the run's own evaluation sits in RUN/eval itself (a resume re-evaluates and replaces it); `roshan eval`
        # writes named folders next to it
        summary = evaluate_run(run_dir, episodes=cfg.train.eval_episodes, seed=cfg.sim.seed + 20_000,
                               num_envs=cfg.train.eval_envs, progress_bar=progress_bar, out_dir=Path(run_dir) / "eval",
                               replace=True)
        result["eval"] = summary
    return result


def ensure_taichi_for(cfg: Config) -> None:
    """Initialise Taichi from ``sim.arch`` / ``sim.threads`` unless the process already did."""

    if current_arch() is None:
        init_taichi(cfg.sim.arch, cfg.sim.threads or None)
    ensure_taichi()
