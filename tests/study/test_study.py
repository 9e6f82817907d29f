"""Optuna study runner: search-space validation, storages and stale trials, pruning, top-k averaging, and tiny
studies run by worker processes (a worker killed mid-trial, a killed study resumed) on a journal file and on a
real PostgreSQL server."""

import dataclasses
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from glob import glob
from pathlib import Path

import optuna
import pytest
import yaml
from click.testing import CliRunner
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.trial import TrialState

from roshan.cli import main
from roshan.config import Config, load_run_config, to_dict
from roshan.study.errors import StudyError
from roshan.study.recipe import RECIPE_ATTR, Recipe, make_recipe
from roshan.study.report import best_trials, mean_of_top_k, write_report
from roshan.study.space import load_space, parse_space
from roshan.study.storage import (
    HEARTBEAT_ATTR,
    HOST_ID,
    WORKER_ATTR,
    HeartbeatJournalStorage,
    RetryStaleTrial,
    open_storage,
    worker_record,
)
from roshan.study.studies import _plain, _pruner, budget, fail_stale, load_study, prepare_study, tpe_sampler
from roshan.study.trial import TrialDisplay, make_objective, objective_value

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "fly_simple.yaml"
# A trial trains 2 PPO updates of 4 envs x 4 drones and evaluates 4 episodes of at most 100 steps.
TINY = ["sim.envs=4", "ppo.horizon=256", "ppo.batch_size=128", "train.max_updates=2", "train.eval_episodes=4",
        "train.eval_envs=4", "fly.k_turn=0.1", "fly.time_limit=thesis"]
SPACE = {"params": {"fly.rewards.goal": {"type": "float", "low": 0.2, "high": 5.0, "log": True},
                    "fly.rewards.boundary": {"type": "float", "low": -5.0, "high": -0.2},
                    "ppo.k_epochs": {"type": "int", "low": 1, "high": 3}},
         "tie": {"fly.rewards.collision": "fly.rewards.boundary"}}


def parse(space: dict):
    return parse_space(space, Config(), where="space.yaml")


def one_param(spec: dict, key: str = "fly.rewards.goal") -> dict:
    return {"params": {key: spec}}


# ------------------------------------------------------------------------------------------------ bad input


@pytest.mark.parametrize("space, message", [
    (one_param({"type": "float", "low": 0.2, "high": 5.0}, "fly.rewards.gaol"),
     "unknown key 'fly.rewards.gaol'; did you mean 'fly.rewards.goal'?"),
    (one_param({"type": "float", "low": 1.0, "high": 1.0}), "empty range [1.0, 1.0]"),
    (one_param({"type": "float", "low": 2.0, "high": -2.0}), "empty range [2.0, -2.0]"),
    (one_param({"type": "float", "low": -1.0, "high": 1.0, "log": True}), "a log range needs low > 0"),
    (one_param({"type": "float", "lo": 0.1, "high": 1.0}), "unknown field(s) ['lo'] for type float"),
    (one_param({"type": "gaussian"}), "expected {type: float|int|categorical"),
    (one_param({"type": "categorical", "choices": []}), "'choices' must be a non-empty list"),
    (one_param({"type": "float", "low": 1.0, "high": 4.0}, "ppo.k_epochs"), "the config field is int"),
    (one_param({"type": "float", "low": -1.0, "high": 0.5}, "fly.rewards.progress"), "is not accepted by the config"),
    (one_param({"type": "categorical", "choices": ["thesis", "best"]}, "fly.rewards.preset"), "'best' is not accepted"),
    ({"params": {}}, "non-empty 'params' section"),
    ({**SPACE, "fixed": {}}, "unknown section(s) ['fixed']"),
    ({**SPACE, "tie": {"fly.rewards.collision": "fly.rewards.timeout"}}, "'fly.rewards.timeout' is not one of"),
    ({**SPACE, "tie": {"fly.rewards.goal": "fly.rewards.boundary"}}, "this key is sampled itself"),
])
def test_bad_search_spaces_are_rejected_with_the_key_and_the_reason(space, message):
    with pytest.raises(StudyError) as err:
        parse(space)
    assert message in str(err.value) and str(err.value).startswith("space.yaml")


def test_shipped_search_spaces():
    base = load_run_config(REPO / "configs" / "fly_collision.yaml")
    fly = load_space(REPO / "configs" / "spaces" / "fly_rewards.yaml", base)
    ranges = {p.key.rsplit(".", 1)[1]: (p.low, p.high, p.log) for p in fly.params}
    assert ranges == {"goal": (0.2, 5.0, True), "boundary": (-5.0, -0.2, False), "extinguish": (1e-3, 0.2, True),
                      "timeout": (-5.0, -0.2, False), "progress": (1e-3, 0.5, True), "proximity": (-0.5, -1e-3, False)}
    assert fly.tie == (("fly.rewards.collision", "fly.rewards.boundary"),)
    sampled = fly.sample(optuna.create_study().ask())
    assert sampled["fly.rewards.collision"] == sampled["fly.rewards.boundary"]
    assert len(load_space(REPO / "configs" / "spaces" / "ppo.yaml", base).params) == 10
    planner = load_space(REPO / "configs" / "spaces" / "planner_rewards.yaml",
                            load_run_config(REPO / "configs" / "planner.yaml"))
    assert {p.key for p in planner.params} == {f"planner.rewards.{k}" for k in
                                               ("goal", "burned", "ground", "timeout", "same", "extinguish", "fast")}


def test_yaml_numbers_without_a_dot_are_read_as_numbers(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("params:\n  ppo.lr: {type: float, low: 1e-5, high: 1e-3, log: true}\n")
    (p,) = load_space(path, Config()).params
    assert (p.low, p.high) == (1e-5, 1e-3)


def test_cli_rejects_bad_space_and_unreachable_storage_before_creating_anything(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("params:\n  fly.rewards.goal: {type: float, low: 5.0, high: 0.2}\n")
    r = CliRunner().invoke(main, ["study", str(CONFIG), "--space", str(bad), "--trials", "1", "--root", str(tmp_path)])
    assert r.exit_code != 0 and "fly.rewards.goal: empty range [5.0, 0.2]" in r.output
    bad.write_text("params:\n  planner.rewards.gaol: {type: float, low: 0.1, high: 5.0}\n")
    r = CliRunner().invoke(main, ["study", str(CONFIG), "--space", str(bad), "--trials", "1", "--root", str(tmp_path)])
    assert r.exit_code != 0 and "unknown key 'planner.rewards.gaol'" in r.output
    url = "postgresql://roshan:s3cret@127.0.0.1:1/roshan"  # nothing listens on port 1
    r = CliRunner().invoke(main, ["study", str(CONFIG), "--space", str(REPO / "configs/spaces/fly_rewards.yaml"),
                                  "--trials", "1", "--storage", url, "--root", str(tmp_path)])
    assert r.exit_code != 0 and "s3cret" not in r.output
    assert "cannot open the study storage postgresql://roshan:***@127.0.0.1:1/roshan" in r.output
    with pytest.raises(StudyError, match="cannot open the study storage nosuchdb://"):
        open_storage("nosuchdb://host/db")
    r = CliRunner().invoke(main, ["study", "--resume", "--name", "nope", "--root", str(tmp_path)])
    assert r.exit_code != 0 and "no study 'nope'" in r.output and "--trials N" in r.output
    assert not list(tmp_path.glob("*/trial_*"))


# ------------------------------------------------------------------------------------------------ stale trials


@pytest.mark.filterwarnings("ignore::optuna.exceptions.ExperimentalWarning", "ignore:Heartbeat of storage")
def test_stale_trials_are_failed_and_queued_again_with_their_parameters(tmp_path):
    storage = HeartbeatJournalStorage(str(tmp_path / "s.journal"), heartbeat_interval=1, grace_period=30,
                                         callback=RetryStaleTrial(max_retry=3))
    study = optuna.create_study(storage=storage)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    now = time.time()
    cases = {"remote, silent": ({"host": "elsewhere/1", "pid": 1}, now - 100),
             "remote, beating": ({"host": "elsewhere/1", "pid": 1}, now),
             "here, dead": ({"host": HOST_ID, "pid": dead.pid, "start": None}, now),
             "here, alive": (worker_record(), now)}
    trials = {}
    for case, (worker, beat) in cases.items():
        trial = study.ask({"x": FloatDistribution(0.0, 1.0)})
        trial.set_user_attr(WORKER_ATTR, worker)
        trial.set_user_attr(HEARTBEAT_ATTR, beat)
        trials[case] = trial.number
    fail_stale(study)
    by_number = {t.number: t for t in study.trials}
    states = {case: by_number[n].state for case, n in trials.items()}
    assert states == {"remote, silent": TrialState.FAIL, "remote, beating": TrialState.RUNNING,
                      "here, dead": TrialState.FAIL, "here, alive": TrialState.RUNNING}
    waiting = [t for t in study.trials if t.state == TrialState.WAITING]
    assert sorted(t.system_attrs["failed_trial"] for t in waiting) == [trials["remote, silent"], trials["here, dead"]]
    for t in waiting:  # same parameters, none of the dead worker's liveness records
        assert t.params == by_number[t.system_attrs["failed_trial"]].params
        assert WORKER_ATTR not in t.user_attrs and HEARTBEAT_ATTR not in t.user_attrs
    b = budget(study, target=4)
    assert (b.used, b.waiting, b.to_start) == (2, 2, 2)  # the two retried trials do not count, their retries do


@pytest.mark.filterwarnings("ignore::optuna.exceptions.ExperimentalWarning", "ignore:Heartbeat of storage")
def test_a_paused_worker_of_this_machine_keeps_its_trial_however_old_its_heartbeat(tmp_path):
    storage = HeartbeatJournalStorage(str(tmp_path / "s.journal"), heartbeat_interval=1, grace_period=30,
                                         callback=RetryStaleTrial(max_retry=3))
    study = optuna.create_study(storage=storage)
    for worker in (worker_record(), {"host": "elsewhere/1", "pid": os.getpid()}):  # SIGSTOPped here / silent there
        trial = study.ask({"x": FloatDistribution(0.0, 1.0)})
        trial.set_user_attr(WORKER_ATTR, worker)
        trial.set_user_attr(HEARTBEAT_ATTR, time.time() - 3600)
    fail_stale(study)
    assert [t.state for t in study.trials] == [TrialState.RUNNING, TrialState.FAIL, TrialState.WAITING]


# ------------------------------------------------------------------------------------------------ top-k, report


def constructed_study(direction="maximize"):
    """Six trials with known values; trial 4 failed and trial 5 was pruned (neither may count)."""
    recipe = Recipe(config=to_dict(load_run_config(CONFIG)), space=SPACE, trials=6)
    study = optuna.create_study(direction=direction)
    study.set_user_attr(RECIPE_ATTR, _plain(dataclasses.asdict(recipe)))
    dists = {"fly.rewards.goal": FloatDistribution(0.2, 5.0, log=True),
             "fly.rewards.boundary": FloatDistribution(-5.0, -0.2), "ppo.k_epochs": IntDistribution(1, 3),
             "ppo.minibatch": CategoricalDistribution(["samples", "sequences"])}
    rows = [(0.1, 1.0, -1.0, 1, "samples"), (0.5, 2.0, -2.0, 1, "sequences"), (0.9, 3.0, -3.0, 3, "samples"),
            (0.7, 5.0, -5.0, 3, "samples"), (None, 4.9, -4.9, 3, "sequences"), (None, 4.8, -4.8, 3, "sequences")]
    for i, (value, goal, boundary, epochs, minibatch) in enumerate(rows):
        state = TrialState.COMPLETE if value is not None else (TrialState.FAIL if i == 4 else TrialState.PRUNED)
        study.add_trial(optuna.create_trial(
            state=state, value=value, distributions=dists, user_attrs={"success_rate": value, "reward": -1.0},
            params={"fly.rewards.goal": goal, "fly.rewards.boundary": boundary, "ppo.k_epochs": epochs,
                    "ppo.minibatch": minibatch}))
    return study


def test_mean_of_top_k_trials_is_a_ready_config(tmp_path):
    study = constructed_study()
    assert [t.number for t in best_trials(study, 3)] == [2, 3, 1]
    top3 = mean_of_top_k(study, 3)
    assert top3["fly.rewards.goal"] == pytest.approx((3.0 + 5.0 + 2.0) / 3)
    assert top3["fly.rewards.boundary"] == pytest.approx(-10.0 / 3)
    assert top3["fly.rewards.collision"] == top3["fly.rewards.boundary"]  # the space's tie
    assert top3["ppo.k_epochs"] == 2 and top3["ppo.minibatch"] == "samples"  # (3+3+1)/3 rounded; most common
    assert mean_of_top_k(study, 100)["fly.rewards.goal"] == pytest.approx(11.0 / 4)  # all 4 completed

    rep = write_report(study, tmp_path, k=3, plots=True)
    cfg = load_run_config(tmp_path / "top3_mean.yaml")
    assert cfg.fly.rewards.goal == pytest.approx(10.0 / 3) and cfg.fly.rewards.collision == pytest.approx(-10.0 / 3)
    assert cfg.ppo.k_epochs == 2 and cfg.train.max_minutes == load_run_config(CONFIG).train.max_minutes
    assert "mean of the parameters of the 3 best of 4 completed trials" in (tmp_path / "top3_mean.yaml").read_text()
    assert load_run_config(tmp_path / "best_trial.yaml").fly.rewards.goal == 3.0
    lines = rep["table"].splitlines()
    assert lines[0].split()[:4] == ["rank", "trial", "value", "success"] and [r.split()[1] for r in lines[2:]] == [
        "2", "3", "1"]
    assert len((tmp_path / "trials.csv").read_text().splitlines()) == 7
    for name in ("history", "importances", "parallel_coordinates"):
        assert (tmp_path / f"{name}.png").stat().st_size > 1000, rep["plots"][name]

    low = constructed_study("minimize")  # e.g. time to end
    assert [t.number for t in best_trials(low, 2)] == [0, 1]


# ------------------------------------------------------------------------------------------------ recipe


def test_objectives_directions_and_pruners():
    summary = {"success_rate": 0.25, "reward": {"mean": -0.5}, "tte": {"mean": 120.0}}
    assert [objective_value(summary, o) for o in ("success", "reward", "tte")] == [0.25, -0.5, 120.0]
    assert objective_value({"tte": {"mean": None}}, "tte") == float("inf")  # no episode: the worst time
    recipe = Recipe(config={}, space=SPACE, objective="tte")
    assert recipe.direction == "minimize" and isinstance(_pruner(recipe), optuna.pruners.NopPruner)
    pruner = _pruner(dataclasses.replace(recipe, objective="success", prune_startup=3, prune_warmup=7))
    assert isinstance(pruner, optuna.pruners.MedianPruner)
    assert (pruner._n_startup_trials, pruner._n_warmup_steps) == (3, 7)
    sampler = tpe_sampler(recipe, seed=1)
    assert sampler._multivariate and sampler._constant_liar and sampler._n_startup_trials == 15


def test_resume_checks_the_recipe_and_may_change_the_budget(tmp_path):
    storage = optuna.storages.InMemoryStorage()
    recipe = make_recipe(CONFIG, TINY, _space_file(tmp_path), trials=3)
    prepare_study(storage, "r", recipe, resume=False, trials=3)
    with pytest.raises(StudyError, match="already exists"):
        prepare_study(storage, "r", recipe, resume=False, trials=3)
    other = make_recipe(CONFIG, [*TINY, "ppo.lr=0.001"], _space_file(tmp_path), trials=3)
    with pytest.raises(StudyError, match=r"another recipe.*config.ppo.lr: 0.0001575 in the study, 0.001 here"):
        prepare_study(storage, "r", other, resume=True, trials=3)
    with pytest.raises(StudyError, match="objective: 'success' in the study, 'reward' here"):
        prepare_study(storage, "r", None, resume=True, settings={"objective": "reward"})
    _, stored = prepare_study(storage, "r", None, resume=True, settings={"objective": "success"}, trials=5)
    assert stored.trials == 5 and load_study(storage, "r")[1].trials == 5


def test_each_worker_shows_its_trial_on_its_own_line(capsys):
    cfg = load_run_config(CONFIG, TINY)
    display = TrialDisplay(7, cfg, slot=1, quiet=False)
    display.update({"updates": 1, "env_steps": 16, "objective": 0.25, "reward": -0.125})
    display.bar.refresh()
    out = capsys.readouterr().err
    assert "w1 trial 7" in out and "1/2" in out and "obj=0.25 R=-0.125" in out
    display.update({"updates": 2, "env_steps": 32, "objective": 0.25, "reward": -0.125})
    display.bar.refresh()
    assert "evaluating" in capsys.readouterr().err
    display.close()


# ------------------------------------------------------------------------------------------------ pruning


@pytest.mark.slow
def test_a_trial_below_the_median_is_pruned_and_train_stops_cleanly(tmp_path):
    recipe = make_recipe(CONFIG, TINY, _space_file(tmp_path), trials=2, prune_startup=1, prune_warmup=0)
    storage = optuna.storages.InMemoryStorage()
    prepare_study(storage, "p", recipe, resume=False, trials=2)
    study, _ = load_study(storage, "p")
    assert isinstance(study.pruner, optuna.pruners.MedianPruner)
    assert isinstance(study.sampler, optuna.samplers.TPESampler)
    study.add_trial(optuna.create_trial(state=TrialState.COMPLETE, value=1.0, intermediate_values={1: 1.0, 2: 1.0}))
    study.optimize(make_objective(recipe, tmp_path, "p", quiet=True), n_trials=1)
    trial = study.trials[-1]
    assert trial.state == TrialState.PRUNED and trial.intermediate_values == {1: 0.0}  # pruned after update 1
    run_dir = Path(trial.user_attrs["run_dir"])
    assert run_dir == (tmp_path / "p" / "trial_1").resolve() and (run_dir / "checkpoints" / "latest.pt").is_file()
    assert not (run_dir / "eval").exists() and "success_rate" not in trial.user_attrs
    cfg = load_run_config(run_dir / "config.yaml")
    assert cfg.fly.rewards.goal == trial.params["fly.rewards.goal"] and cfg.train.max_updates == 2


def _space_file(tmp_path: Path) -> Path:
    path = tmp_path / "space.yaml"
    path.write_text(yaml.safe_dump(SPACE))
    return path


# ------------------------------------------------------------------------------------------------ worker processes


def launch(tmp_path: Path, name: str, *args: str) -> subprocess.Popen:
    """``roshan study`` in its own session (so the test can kill it with its workers), output to a log file."""
    cmd = [sys.executable, "-m", "roshan", "study", str(CONFIG), "--space", str(_space_file(tmp_path)),
           "--root", str(tmp_path), "--name", name, "--quiet", *args]
    for s in TINY:
        cmd += ["--set", s]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    log = open(tmp_path / f"{name}.log", "w")  # noqa: SIM115 - the process owns it
    return subprocess.Popen(cmd, cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True,
                            preexec_fn=_default_sigint)


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # a test run in the background inherits SIGINT ignored


def wait_until(condition, proc: subprocess.Popen, log: Path, timeout: float = 150.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        result = condition()
        if result:
            return result
        if proc.poll() is not None:
            pytest.fail(f"the study exited ({proc.returncode}) too early:\n{log.read_text()[-3000:]}")
        time.sleep(0.2)
    pytest.fail(f"timed out:\n{log.read_text()[-3000:]}")


def running_workers(storage, name: str) -> list[dict]:
    if name not in optuna.get_all_study_names(storage):
        return []
    study = optuna.load_study(study_name=name, storage=storage)
    return [t.user_attrs[WORKER_ATTR] for t in study.get_trials(states=(TrialState.RUNNING,))
            if WORKER_ATTR in t.user_attrs]


def trial_has_all_params(storage, name: str) -> bool:
    """A running trial of the study holds a value for every parameter of the space."""
    if not running_workers(storage, name):
        return False
    study = optuna.load_study(study_name=name, storage=storage)
    return any(len(t.params) == len(SPACE["params"]) for t in study.get_trials(states=(TrialState.RUNNING,)))


def run_study_killing_a_worker(tmp_path: Path, name: str, storage_url: str | None):
    """3 trials, 2 workers; once both run a trial, one worker is killed with SIGKILL; the other carries on."""
    args = ["--trials", "3", "--workers", "2"] + (["--storage", storage_url] if storage_url else [])
    proc = launch(tmp_path, name, *args)
    log = tmp_path / f"{name}.log"
    url = storage_url or str(tmp_path / name / "study.journal")
    try:
        wait_until(lambda: storage_url or Path(url).exists(), proc, log)
        reader = open_storage(url, heartbeat=None)
        workers = wait_until(lambda: (w := running_workers(reader, name)) and len(w) == 2 and w, proc, log)
        os.kill(workers[0]["pid"], signal.SIGKILL)
        assert proc.wait(timeout=240) == 0, log.read_text()[-3000:]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    study = optuna.load_study(study_name=name, storage=reader)
    return study, workers[0], log.read_text()


def check_study_survived_the_kill(study: optuna.Study, killed: dict, log: str) -> None:
    by_state = {s: [t for t in study.trials if t.state == s] for s in TrialState}
    assert len(by_state[TrialState.COMPLETE]) == 3 and len(by_state[TrialState.FAIL]) == 1, log[-3000:]
    (failed,) = by_state[TrialState.FAIL]
    assert failed.user_attrs[WORKER_ATTR]["pid"] == killed["pid"]
    (retry,) = [t for t in by_state[TrialState.COMPLETE] if t.system_attrs.get("failed_trial") == failed.number]
    assert retry.params == failed.params and retry.user_attrs[WORKER_ATTR]["pid"] != killed["pid"]
    assert len({t.user_attrs[WORKER_ATTR]["pid"] for t in study.trials}) == 4  # a process per trial
    assert f"was killed by signal {int(signal.SIGKILL)}" in log and f"trial {failed.number}: failed" in log
    for t in by_state[TrialState.COMPLETE]:
        run_dir = Path(t.user_attrs["run_dir"])
        cfg = load_run_config(run_dir / "config.yaml")
        assert cfg.fly.rewards.goal == t.params["fly.rewards.goal"] and cfg.ppo.k_epochs == t.params["ppo.k_epochs"]
        assert cfg.fly.rewards.collision == t.params["fly.rewards.boundary"] and cfg.sim.threads >= 1
        assert (run_dir / "eval" / "summary.json").is_file() and t.value == t.user_attrs["success_rate"]
        assert sorted(t.intermediate_values) == [1, 2]  # the training objective after each update


@pytest.mark.slow
def test_two_workers_share_a_journal_study_and_survive_a_killed_worker(tmp_path):
    study, killed, log = run_study_killing_a_worker(tmp_path, "s", None)
    check_study_survived_the_kill(study, killed, log)
    assert all(HEARTBEAT_ATTR in t.user_attrs for t in study.trials if t.state == TrialState.COMPLETE)
    r = CliRunner().invoke(main, ["study", "report", "s", "--root", str(tmp_path), "--top-k", "2"])
    assert r.exit_code == 0, r.output
    mean = load_run_config(tmp_path / "s" / "report" / "top2_mean.yaml")
    top = best_trials(study, 2)
    assert mean.fly.rewards.goal == pytest.approx(sum(t.params["fly.rewards.goal"] for t in top) / 2)
    assert "top2_mean.yaml" in r.output and (tmp_path / "s" / "report" / "history.png").is_file()


@pytest.mark.slow
def test_a_killed_study_resumes_where_it_stopped(tmp_path):
    proc = launch(tmp_path, "k", "--trials", "1")
    journal, log = tmp_path / "k" / "study.journal", tmp_path / "k.log"
    try:
        wait_until(journal.exists, proc, log)
        reader = open_storage(str(journal), heartbeat=None)
        # killed once the trial has drawn all its parameters: the retry must ask for the same ones
        wait_until(lambda: trial_has_all_params(reader, "k"), proc, log)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the launcher and its worker, mid-trial
        proc.wait()
    again = CliRunner().invoke(main, ["study", str(CONFIG), "--space", str(_space_file(tmp_path)), "--trials", "1",
                                      "--root", str(tmp_path), "--name", "k", *sum((["--set", s] for s in TINY), [])])
    assert again.exit_code != 0 and "already exists" in again.output and "--resume" in again.output
    r = CliRunner().invoke(main, ["study", "--resume", "--name", "k", "--root", str(tmp_path), "--quiet"])
    assert r.exit_code == 0, r.output
    study = optuna.load_study(study_name="k", storage=reader)
    assert [t.state for t in study.trials] == [TrialState.FAIL, TrialState.COMPLETE], log.read_text()[-3000:]
    assert study.trials[1].system_attrs["failed_trial"] == 0 and study.trials[1].params == study.trials[0].params
    assert "trial 0: failed (its worker died or was interrupted; queued again)" in r.output
    assert "trial 1: success = " in r.output and "best: trial 1" in r.output


@pytest.mark.slow
def test_a_journal_with_a_cut_last_record_is_named_and_repaired_by_resume(tmp_path):
    sets = sum((["--set", s] for s in TINY), [])
    r = CliRunner().invoke(main, ["study", str(CONFIG), "--space", str(_space_file(tmp_path)), "--trials", "1",
                                  "--root", str(tmp_path), "--name", "j", "--quiet", *sets])
    assert r.exit_code == 0, r.output
    journal = tmp_path / "j" / "study.journal"
    with open(journal, "r+b") as f:  # what a full disk leaves: the last record cut (truncate -s -40)
        f.truncate(journal.stat().st_size - 40)
    cut = journal.read_bytes()
    report = ["study", "report", "j", "--root", str(tmp_path), "--no-plots"]
    r = CliRunner().invoke(main, report)
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), r.output
    assert str(journal) in r.output and "is cut" in r.output and "--resume --name j" in r.output
    assert journal.read_bytes() == cut  # a report never rewrites the journal
    r = CliRunner().invoke(main, ["study", "--resume", "--name", "j", "--trials", "2", "--root", str(tmp_path),
                                  "--quiet"])
    assert r.exit_code == 0, r.output
    (copy,) = journal.parent.glob("study.journal.damaged-*")
    assert copy.read_bytes() == cut and f"the original is kept as {copy}" in r.output
    assert "was cut; dropped it" in r.output
    r = CliRunner().invoke(main, report)
    assert r.exit_code == 0, r.output
    study = optuna.load_study(study_name="j", storage=open_storage(str(journal), heartbeat=None))
    assert len([t for t in study.trials if t.state == TrialState.COMPLETE]) >= 1


def test_a_journal_damaged_before_its_last_line_is_refused_with_the_line(tmp_path):
    journal = tmp_path / "s.journal"
    storage = open_storage(str(journal), heartbeat=None)
    for name in ("a", "b", "c"):
        optuna.create_study(study_name=name, storage=storage)
    lines = journal.read_bytes().splitlines(keepends=True)
    lines[1] = lines[1][:10] + b"\n"
    journal.write_bytes(b"".join(lines))
    damaged = journal.read_bytes()
    for repair in (True, False):
        with pytest.raises(StudyError, match=f"{journal}: line 2 of the study journal is damaged"):
            open_storage(str(journal), heartbeat=None, repair=repair)
    assert journal.read_bytes() == damaged and not list(tmp_path.glob("*.damaged-*"))


@pytest.mark.slow
def test_ctrl_c_fails_the_running_trial_and_queues_it_again(tmp_path):
    proc = launch(tmp_path, "c", "--trials", "1")
    journal, log = tmp_path / "c" / "study.journal", tmp_path / "c.log"
    try:
        wait_until(journal.exists, proc, log)
        reader = open_storage(str(journal), heartbeat=None)
        wait_until(lambda: running_workers(reader, "c"), proc, log)
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in the terminal does
        assert proc.wait(timeout=120) != 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    study = optuna.load_study(study_name="c", storage=reader)
    assert [t.state for t in study.trials] == [TrialState.FAIL, TrialState.WAITING], log.read_text()[-3000:]
    assert study.trials[1].params == study.trials[0].params and study.trials[1].system_attrs["failed_trial"] == 0
    assert "interrupted" in log.read_text() and "--resume" in log.read_text()


# ------------------------------------------------------------------------------------------------ PostgreSQL


def _postgres_binaries() -> Path | None:
    found = shutil.which("initdb") and shutil.which("pg_ctl")
    if found:
        return Path(shutil.which("initdb")).resolve().parent
    dirs = sorted(glob("/usr/lib/postgresql/*/bin"), key=lambda d: int(d.split("/")[-2]) if d.split("/")[-2].isdigit()
                  else 0)
    return Path(dirs[-1]) if dirs and (Path(dirs[-1]) / "initdb").exists() else None


@pytest.fixture(scope="module")
def postgres_url():
    """ROSHAN_TEST_POSTGRES_URL (CI sets it), else a throwaway cluster on loopback, else a skip that says why."""
    pytest.importorskip("psycopg2", reason="psycopg2 is missing: pip install -e '.[dev]'")
    if os.environ.get("ROSHAN_TEST_POSTGRES_URL"):
        yield os.environ["ROSHAN_TEST_POSTGRES_URL"]
        return
    bin_dir = _postgres_binaries()
    if bin_dir is None:
        pytest.skip("no PostgreSQL server: set ROSHAN_TEST_POSTGRES_URL or install postgresql (initdb, pg_ctl)")
    as_user: list[str] = []
    if os.geteuid() == 0:  # initdb refuses to run as root
        if shutil.which("runuser") is None or subprocess.run(["id", "postgres"], capture_output=True).returncode:
            pytest.skip("no PostgreSQL server: running as root without a 'postgres' user to start one")
        as_user = ["runuser", "-u", "postgres", "--"]
    base = Path(tempfile.mkdtemp(prefix="roshan-pg-"))
    if as_user:
        shutil.chown(base, "postgres")
    data, port = base / "data", 20000 + os.getpid() % 20000
    init = subprocess.run([*as_user, str(bin_dir / "initdb"), "-D", str(data), "-U", "roshan", "--auth=trust"],
                          capture_output=True, text=True)
    start = init.returncode == 0 and subprocess.run(
        [*as_user, str(bin_dir / "pg_ctl"), "-D", str(data), "-w", "-l", str(base / "log"), "-o",
         f"-p {port} -k {base} -c listen_addresses=127.0.0.1", "start"], capture_output=True, text=True)
    if not start or start.returncode != 0:
        shutil.rmtree(base, ignore_errors=True)
        why = (init.stderr if init.returncode else start.stderr)[-300:]
        pytest.skip(f"no PostgreSQL server: could not start one ({why})")
    try:
        yield f"postgresql://roshan@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([*as_user, str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop"],
                       capture_output=True)
        shutil.rmtree(base, ignore_errors=True)


@pytest.mark.slow
def test_two_workers_share_a_postgresql_study_and_survive_a_killed_worker(tmp_path, postgres_url):
    name = f"roshan-test-{uuid.uuid4().hex[:8]}"
    try:
        study, killed, log = run_study_killing_a_worker(tmp_path, name, postgres_url)
        check_study_survived_the_kill(study, killed, log)
        r = CliRunner().invoke(main, ["study", "report", postgres_url, "--name", name, "--root", str(tmp_path),
                                      "--top-k", "3", "--no-plots"])
        assert r.exit_code == 0, r.output
        assert (tmp_path / name / "report" / "top3_mean.yaml").is_file() and "trial" in r.output
    finally:
        storage = open_storage(postgres_url, heartbeat=None)
        if name in optuna.get_all_study_names(storage):
            optuna.delete_study(study_name=name, storage=storage)
