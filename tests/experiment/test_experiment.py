"""The experiment runner: a spec expands to the right runs, a killed runner resumes without redoing finished runs,
two workers sharing one storage never run the same (condition, seed) twice, and the report's mean ± std (median)
match a hand computation. The runs here are fakes (a function that records what it was asked to run); one test
trains and evaluates a real (tiny) run through the command line."""

import csv
import json
import multiprocessing as mp
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import optuna
import pytest

from roshan.experiment.findings import Verdict, verdict
from roshan.experiment.report import (
    condition_rows,
    done_results,
    markdown,
    per_seed_csv,
    rate,
    report_experiment,
)
from roshan.experiment.runner import (
    RERUN_ATTR,
    STUDY_ATTR,
    carry_results,
    check_runs,
    check_sources,
    check_trainable,
    claim_folder,
    load_experiment,
    prepare_experiment,
    progress,
    queue_reruns,
    results_of,
    run_dir,
    run_experiment,
    run_key,
    run_storage,
    run_worker,
)
from roshan.experiment.spec import Reference, SpecError, load_spec
from roshan.io import OutputError
from roshan.study.storage import open_storage

REPO = Path(__file__).resolve().parents[2]

SPEC = """
name: demo
seeds: 2
eval: {{episodes: 4, seed: 9}}
conditions:
  fast:
    config: {config}
    set: {{train.max_updates: 3, sim.envs: 4}}
    thesis_set: {{train.max_updates: 300}}
    thesis: {{success: 91.15 ± 17.46 (100.0), timeout: [8.65, 17.31, 0.0]}}
  more_seeds:
    config: {config}
    seeds: [5, 7, 11]
  greedy:
    config: {planner}
    controller: greedy
    seeds: 1
    eval: {{episodes: 100, envs: 100}}
"""


def write_spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(text.format(config=REPO / "configs" / "fly_simple.yaml", planner=REPO / "configs" / "planner.yaml"))
    return path


def test_spec_expands_to_conditions_times_seeds(tmp_path):
    spec = load_spec(write_spec(tmp_path))
    assert [r.key for r in spec.runs()] == ["fast/seed_0", "fast/seed_1", "more_seeds/seed_5", "more_seeds/seed_7",
                                            "more_seeds/seed_11", "greedy/seed_0"]
    fast, more, greedy = spec.conditions
    cfg = fast.run_config(1)
    assert (cfg.sim.seed, cfg.sim.envs, cfg.train.max_updates) == (1, 4, 3)
    assert more.run_config(7).sim.seed == 7 and more.run_config(7).sim.envs == 64  # the config's own value
    assert (fast.eval_episodes, fast.eval_seed, greedy.eval_envs) == (4, 9, 100)
    assert not greedy.trains and fast.trains
    assert fast.thesis["success"] == Reference(91.15, 17.46, 100.0)
    assert fast.thesis["timeout"] == Reference(8.65, 17.31, 0.0)
    thesis = load_spec(write_spec(tmp_path), budget="thesis")
    assert thesis.name == "demo-thesis-budget" and thesis.conditions[0].run_config(0).train.max_updates == 300
    assert thesis.fingerprints()["fast/seed_0"] != spec.fingerprints()["fast/seed_0"]
    assert thesis.fingerprints()["greedy/seed_0"] == spec.fingerprints()["greedy/seed_0"]


BASED = """
conditions:
  a:
    config: {config}
    set: {{train.max_updates: 3, sim.envs: 4}}
    eval: {{episodes: 4, seed: 9}}
    thesis: {{success: 91.15}}
    note: about a
  b:
    base: a
    set: [train.max_updates=5]
  c:
    base: b
    seeds: [4]
    set: {{ppo.max_grad_norm: 0}}
    eval: {{envs: 2}}
"""

BASE_ERRORS = [
    (("base: a", "base: c"), "conditions.b.base: expected a condition listed before this one, got 'c' "
                             "(listed before: a)"),
    (("base: a", "base: b"), "conditions.b.base: expected a condition listed before this one, got 'b'"),
    (("base: b", "bass: b"), "conditions.c: unknown key(s) bass; expected base, buffer"),
    (("set: [train.max_updates=5]", "set: [train.max_updates]"), "conditions.b.set: expected a mapping"),
]

WRITTEN_OUT = BASED[: BASED.index("  b:")] + """  b:
    config: {config}
    set: {{sim.envs: 4, train.max_updates: 5}}
    eval: {{episodes: 4, seed: 9}}
    thesis: {{success: 91.15}}
  c:
    config: {config}
    seeds: [4]
    set: {{train.max_updates: 5, sim.envs: 4, ppo.max_grad_norm: 0}}
    eval: {{episodes: 4, seed: 9, envs: 2}}
    thesis: {{success: 91.15}}
"""


def test_a_condition_with_a_base_is_the_base_written_out_with_its_own_keys_over_it(tmp_path):
    based = load_spec(write_spec(tmp_path, BASED))
    (tmp_path / "out").mkdir()
    written = load_spec(write_spec(tmp_path / "out", WRITTEN_OUT))
    assert based.fingerprints() == written.fingerprints()
    assert list(based.fingerprints()) == ["a/seed_0", "a/seed_1", "a/seed_2", "b/seed_0", "b/seed_1", "b/seed_2",
                                          "c/seed_4"]
    a, b, c = based.conditions
    assert b.run_config(0).train.max_updates == 5 and b.run_config(0).sim.envs == 4  # set merged, b's value wins
    assert c.run_config(4).ppo.max_grad_norm == 0 and c.run_config(4).train.max_updates == 5  # through b
    assert (c.eval_episodes, c.eval_seed, c.eval_envs) == (4, 9, 2)
    assert b.thesis == a.thesis and (a.note, b.note, c.note) == ("about a", "", "")
    assert based.fingerprints()["b/seed_0"] != based.fingerprints()["a/seed_0"]


@pytest.mark.parametrize("text, change, message", [(SPEC, *c) for c in [
    (("seeds: 2", "seeds: 0"), "conditions.fast.seeds: expected a number of seeds"),
    (("controller: greedy", "controller: heuristic"), "conditions.greedy.controller: expected one of policy, greedy"),
    (("thesis_set:", "thesis_sets:"), "conditions.fast: unknown key(s) thesis_sets"),
    (("(100.0)", "(100.0"), "conditions.fast.thesis.success: expected 'mean ± std (median)'"),
    (("sim.envs: 4", "sim.envz: 4"), "conditions.fast: "),
    (("seeds: [5, 7, 11]", "seeds: [5, 5]"), "a seed is listed twice"),
    (("conditions:", "departures: [{{what: a flier of our own, why: the thesis's is lost}}]\nconditions:"),
     "departures[0]: expected what, why and effect"),
]] + [(BASED, *c) for c in BASE_ERRORS])
def test_bad_specs_name_the_condition_and_key(tmp_path, text, change, message):
    path = write_spec(tmp_path, text.replace(*change))
    with pytest.raises(SpecError) as err:
        load_spec(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_a_missing_config_file_is_named(tmp_path):
    path = tmp_path / "spec.yaml"
    path.write_text("conditions:\n  a:\n    config: nowhere.yaml\n")
    with pytest.raises(SpecError, match=r"conditions.a.config: nowhere.yaml not found"):
        load_spec(path)


@pytest.mark.slow
@pytest.mark.parametrize("name,runs", [("thesis", 100), ("planner_stable_flier", 40)])
def test_a_committed_spec_still_means_what_its_journal_ran(tmp_path, name, runs):
    """The committed spec against the runs its journal recorded: a row rewritten (e.g. with a ``base``, or moved
    to a spec of its own) must keep every started run's settings, or ``roshan experiment run`` would refuse the
    journal."""
    journal = tmp_path / "experiment.journal"
    journal.write_bytes((REPO / "benchmarks" / "results" / name / "experiment.journal").read_bytes())
    spec = load_spec(REPO / "configs" / "experiments" / f"{name}.yaml")
    study = optuna.load_study(study_name=spec.name, storage=open_storage(str(journal), heartbeat=None))
    started = {run_key(t) for t in study.get_trials(deepcopy=False) if t.state != optuna.trial.TrialState.WAITING}
    assert len(started & set(spec.fingerprints())) > runs  # the check below has runs to hold the spec against
    check_runs(spec, study.user_attrs[STUDY_ATTR], study)  # what `roshan experiment run` does: raises if changed


def test_the_low_level_model_enters_a_runs_fingerprint_by_its_contents(tmp_path, monkeypatch):
    """A planner row means the FlyAgent its drones fly: a changed model file is another run, while the models the
    stored runs flew (the same setting, the same bytes: MODELS_OF_RECORD) keep their stored fingerprints."""
    import shutil

    import roshan.experiment.spec as spec_module
    from roshan.experiment.report import low_level

    fly = tmp_path / "fly"
    shutil.copytree(REPO / "models" / "fly_collision", fly)
    setting = "    set: {{planner.fly_model: " + str(fly) + "}}\n"  # doubled braces: write_spec formats SPEC
    text = SPEC.replace("    controller: greedy\n", "    controller: greedy\n" + setting)
    (greedy,) = [r for r in load_spec(write_spec(tmp_path, text)).runs() if r.condition.name == "greedy"]
    setting, digest = greedy.models()["planner.fly_model"]
    assert (setting, digest) == (str(fly), spec_module.MODELS_OF_RECORD["models/fly_collision"])  # same bytes
    before = greedy.fingerprint()
    with open(fly / "checkpoints" / "best_eval.pt", "ab") as fh:
        fh.write(b"\0")  # another file under the same name
    assert greedy.models()["planner.fly_model"][1] != digest and greedy.fingerprint() != before

    stable = load_spec(REPO / "configs" / "experiments" / "planner_stable_flier.yaml")  # flies models/fly_collision
    row = stable.runs(("greedy",))[0]
    stored = row.fingerprint()
    monkeypatch.setitem(spec_module.MODELS_OF_RECORD, "models/fly_collision", "0" * 16)  # as if the file changed
    assert row.fingerprint() != stored
    thesis = load_spec(REPO / "configs" / "experiments" / "thesis.yaml")
    assert thesis.runs(("E1_ppo",))[0].models() == {}  # a FlyAgent that trains loads no model
    flier = thesis.runs(("greedy",))[0].models()["planner.fly_model"]  # the thesis's rows fly its E6-grade agent
    assert flier == ("models/fly_collision_thesis", spec_module.model_digest("models/fly_collision_thesis",
                                                                             "planner.fly_model"))
    assert set(thesis.runs(("E7",))[0].models()) == {"buffer.model"}
    # per_seed.csv's low_level column: the digest the result recorded, '?' where it recorded none
    assert low_level(row, {"models": {"planner.fly_model": {"setting": "models/fly_collision",
                                                            "digest": "ab" * 8}}}) == "ab" * 8
    assert low_level(row, {}) == "?" and low_level(thesis.runs(("E1_ppo",))[0], {}) == ""


# ------------------------------------------------------------------------------------------ running (fakes)


def fake_result(run) -> dict:
    """A result as execute_run returns it, with a success rate that depends on the seed."""
    return {"run": run.key, "condition": run.condition.name, "seed": run.seed, "episodes": 4, "eval_seed": 9,
            "success_rate": 0.25 * (run.seed % 5), "failure_rates": {"timeout": 1 - 0.25 * (run.seed % 5)},
            "tte": {}, "tte_episodes": [100 + run.seed, 200], "minutes": 0.0,
            "code": {"version": "0.1", "commit": "abcdef0123456789", "dirty": False},
            "machine": {"cpu": "AMD EPYC", "torch": "2.13.0+cpu", "isa": "AVX2", "torch_threads": 1,
                        "mode": "reproducible"}}


def recording_execute(log: Path, pause: float = 0.0):
    def execute(run, folder):
        with open(log, "a") as f:  # O_APPEND: whole lines even from several processes
            f.write(f"start {run.key} {os.getpid()}\n")
        time.sleep(pause)
        if (log.parent / "hang").exists() and run.key == "more_seeds/seed_5":
            time.sleep(3600)  # the test kills this worker here
        with open(log, "a") as f:
            f.write(f"done {run.key} {os.getpid()}\n")
        return fake_result(run)
    return execute


def lines(log: Path, what: str) -> list[str]:
    return [ln.split()[1] for ln in log.read_text().splitlines() if ln.startswith(what)]


def drain(spec_path: Path, url: str, root: Path, log: Path, pause: float) -> None:
    """A worker process: run experiment runs one after another until none is waiting."""
    spec = load_spec(spec_path)
    storage = open_storage(url, heartbeat=60)
    while True:
        study = optuna.load_study(study_name=spec.name, storage=storage)
        if progress(study)["waiting"] == 0:
            return
        run_worker(spec, url, root, execute=recording_execute(log, pause))


def start(spec_path, tmp_path):
    spec = load_spec(spec_path)
    url = str(tmp_path / "experiment.journal")
    study = prepare_experiment(open_storage(url, heartbeat=60), spec)
    return spec, url, study


def test_a_rerun_makes_finished_runs_again_in_their_own_folders_and_its_result_is_reported(tmp_path):
    spec, url, study = start(write_spec(tmp_path), tmp_path)
    log, folders = tmp_path / "log", []

    def execute(run, folder):
        folders.append(folder.relative_to(tmp_path).as_posix())
        return recording_execute(log)(run, folder)

    while run_worker(spec, url, tmp_path, execute=execute, only=("fast",)) == 0 and progress(study)["waiting"] > 4:
        pass
    first = results_of(study)["fast/seed_1"]
    assert queue_reruns(study, spec, ("fa*",), echo=lambda _: None) == 2
    assert queue_reruns(study, spec, ("fast",), echo=lambda _: None) == 0  # already queued: not twice
    assert progress(study, {"fast/seed_0", "fast/seed_1"}) == {"done": 0, "running": 0, "waiting": 2, "failed": 0}
    for _ in range(2):
        assert run_worker(spec, url, tmp_path, execute=execute, only=("fast",)) == 0
    assert lines(log, "done") == ["fast/seed_0", "fast/seed_1"] * 2  # each made twice: not taken as a duplicate
    assert folders[2:] == ["demo/fast/seed_0.rerun-0", "demo/fast/seed_1.rerun-1"]  # fresh folders, no resume
    newest = [t for t in study.get_trials() if t.user_attrs.get(RERUN_ATTR) == 1]
    assert results_of(study)["fast/seed_1"] == newest[0].user_attrs["result"] == first  # the fake is deterministic
    assert progress(study, {"fast/seed_0", "fast/seed_1"})["done"] == 2


def test_remake_retires_a_changed_runs_results_and_makes_it_again_under_the_new_settings(tmp_path):
    """A condition changed on purpose (the thesis's planner rows given the thesis's own flier): --remake takes the
    new settings, its old results leave the report but stay in the journal, and its runs are made again in folders
    of their own; without it the changed spec is refused as before."""
    spec_path = write_spec(tmp_path)
    spec, url, study = start(spec_path, tmp_path)
    log, folders = tmp_path / "log", []

    def execute(run, folder):
        folders.append(folder.relative_to(tmp_path).as_posix())
        return recording_execute(log)(run, folder)

    while run_worker(spec, url, tmp_path, execute=execute, only=("fast",)) == 0 \
            and progress(study, {"fast/seed_0", "fast/seed_1"})["waiting"]:
        pass
    assert {"fast/seed_0", "fast/seed_1"} <= set(results_of(study))
    spec_path.write_text(spec_path.read_text().replace("train.max_updates: 3", "train.max_updates: 4"))
    changed = load_spec(spec_path)
    storage = open_storage(url, heartbeat=60)
    with pytest.raises(SpecError, match="--remake"):
        prepare_experiment(storage, changed)
    trials_before = len(study.get_trials())
    study = prepare_experiment(storage, changed, echo=lambda _: None, remake=changed.select_runs(("fast",)))
    assert not {"fast/seed_0", "fast/seed_1"} & set(results_of(study))  # retired: out of the report
    assert progress(study, {"fast/seed_0", "fast/seed_1"})["waiting"] == 2
    check_runs(changed, study.user_attrs[STUDY_ATTR], study)  # the journal now means the new settings
    prepare_experiment(storage, changed, echo=lambda _: None)  # and a later call needs no --remake
    assert progress(study, {"fast/seed_0", "fast/seed_1"})["waiting"] == 2  # queued once
    for _ in range(2):
        assert run_worker(changed, url, tmp_path, execute=execute, only=("fast",)) == 0
    assert lines(log, "done") == ["fast/seed_0", "fast/seed_1"] * 2
    assert folders[2:] == ["demo/fast/seed_0.rerun-0", "demo/fast/seed_1.rerun-1"]
    assert {"fast/seed_0", "fast/seed_1"} <= set(results_of(study))
    assert len(study.get_trials()) == trials_before + 2  # the old trials stay in the journal


def test_rows_moving_to_an_experiment_of_their_own_carry_their_results(tmp_path):
    spec, url, study = start(write_spec(tmp_path), tmp_path)
    while run_worker(spec, url, tmp_path, execute=recording_execute(tmp_path / "log")) == 0 \
            and progress(study)["waiting"]:
        pass
    moved_dir = tmp_path / "moved"
    moved_dir.mkdir()
    text = SPEC.replace("name: demo", "name: moved")
    moved = load_spec(write_spec(moved_dir, text))
    target = open_storage(str(tmp_path / "moved.journal"), heartbeat=None)
    assert carry_results(study, moved, target, ("fast", "greedy"), echo=lambda _: None) == 3
    kept = load_experiment(target, "moved")
    assert results_of(kept)["fast/seed_1"]["success_rate"] == results_of(study)["fast/seed_1"]["success_rate"]
    assert results_of(kept)["fast/seed_1"]["carried_from"] == "demo"
    assert progress(kept) == {"done": 3, "running": 0, "waiting": 3, "failed": 0}  # more_seeds: still to run
    assert carry_results(study, moved, target, echo=lambda _: None) == 3  # again: only what is not there yet
    changed = load_spec(write_spec(moved_dir, text.replace("train.max_updates: 3", "train.max_updates: 4")))
    with pytest.raises(SpecError, match=r"fast/seed_0, fast/seed_1 would mean something else"):
        carry_results(study, changed, open_storage(str(tmp_path / "other.journal"), heartbeat=None))


def test_a_rerun_can_name_single_runs_of_a_condition(tmp_path):
    spec, url, study = start(write_spec(tmp_path), tmp_path)
    assert spec.select_runs(("more_seeds/seed_[57]", "fast")) == ("fast/seed_0", "fast/seed_1", "more_seeds/seed_5",
                                                                 "more_seeds/seed_7")
    with pytest.raises(SpecError, match=r"--rerun 'more_seeds/seed_6' matches no condition or run"):
        spec.select_runs(("more_seeds/seed_6",))
    log = tmp_path / "log"
    while run_worker(spec, url, tmp_path, execute=recording_execute(log), only=("more_seeds",)) == 0 \
            and progress(study, {r.key for r in spec.runs(("more_seeds",))})["waiting"]:
        pass
    assert queue_reruns(study, spec, ("more_seeds/seed_7",), echo=lambda _: None) == 1  # seed 7 alone
    assert progress(study, {"more_seeds/seed_5", "more_seeds/seed_7", "more_seeds/seed_11"})["waiting"] == 1
    assert run_worker(spec, url, tmp_path, execute=recording_execute(log), only=("more_seeds",)) == 0
    assert lines(log, "done") == ["more_seeds/seed_5", "more_seeds/seed_7", "more_seeds/seed_11", "more_seeds/seed_7"]


def test_two_workers_sharing_a_storage_never_run_the_same_run_twice(tmp_path):
    spec_path = write_spec(tmp_path)
    spec, url, _ = start(spec_path, tmp_path)
    log = tmp_path / "log"
    ctx = mp.get_context("fork")
    workers = [ctx.Process(target=drain, args=(spec_path, url, tmp_path, log, 0.2)) for _ in range(2)]
    for w in workers:
        w.start()
    for w in workers:
        w.join(120)
        assert w.exitcode == 0
    done = lines(log, "done")
    assert sorted(done) == sorted(r.key for r in spec.runs())  # every run once, none twice
    pids = {ln.split()[2] for ln in log.read_text().splitlines()}
    assert len(pids) == 2, "both workers should have taken runs"
    _, _, study = start(spec_path, tmp_path)  # joining again enqueues nothing new
    assert progress(study) == {"done": 6, "running": 0, "waiting": 0, "failed": 0}


def test_a_killed_runner_resumes_without_redoing_finished_runs(tmp_path):
    spec_path = write_spec(tmp_path)
    spec, url, _ = start(spec_path, tmp_path)
    log = tmp_path / "log"
    (tmp_path / "hang").touch()
    worker = mp.get_context("fork").Process(target=drain, args=(spec_path, url, tmp_path, log, 0.0))
    worker.start()
    deadline = time.time() + 60
    while "more_seeds/seed_5" not in (lines(log, "start") if log.exists() else []):
        assert time.time() < deadline and worker.is_alive()
        time.sleep(0.05)
    os.kill(worker.pid, signal.SIGKILL)  # as a crash, a lost machine or `kill -9` would
    worker.join()
    finished_before = lines(log, "done")
    assert finished_before == ["fast/seed_0", "fast/seed_1"]
    (tmp_path / "hang").unlink()
    spec, url, study = start(spec_path, tmp_path)  # `roshan experiment run SPEC` again
    drain(spec_path, url, tmp_path, log, 0.0)
    done = lines(log, "done")
    assert sorted(done) == sorted(r.key for r in spec.runs())  # the two finished runs were not run again
    assert done[2] == "more_seeds/seed_5"  # its retry keeps its place in the spec's order
    assert lines(log, "start").count("more_seeds/seed_5") == 2  # the killed one was
    assert progress(study)["done"] == 6


def test_a_spec_may_grow_but_not_change_a_started_run(tmp_path):
    spec_path = write_spec(tmp_path)
    _, url, _ = start(spec_path, tmp_path)
    spec_path.write_text(spec_path.read_text().replace("seeds: [5, 7, 11]", "seeds: [5, 7, 11, 13]"))
    spec, _, study = start(spec_path, tmp_path)  # one more seed joins the queue
    assert progress(study)["waiting"] == 7
    run_worker(spec, url, tmp_path, execute=recording_execute(tmp_path / "log"))  # fast/seed_0 has run
    spec_path.write_text(spec_path.read_text().replace("train.max_updates: 3", "train.max_updates: 4"))
    with pytest.raises(SpecError, match=r"runs made with other settings under the same keys \(fast/seed_0\)"):
        start(spec_path, tmp_path)
    spec_path.write_text(spec_path.read_text().replace("train.max_updates: 4", "train.max_updates: 3").replace(
        "controller: greedy", "controller: greedy\n    set: {planner.greedy_home: fixed}"))
    start(spec_path, tmp_path)  # greedy has not started: it may change


def test_waiting_runs_of_a_removed_condition_are_dropped_and_a_spec_that_has_them_queues_them_again(tmp_path):
    spec_path = write_spec(tmp_path)
    _, url, study = start(spec_path, tmp_path)
    full = spec_path.read_text()
    spec_path.write_text(full[: full.index("  more_seeds:")] + full[full.index("  greedy:"):])
    spec, _, study = start(spec_path, tmp_path)  # more_seeds is gone from the spec
    assert progress(study, set(spec.fingerprints())) == {"done": 0, "running": 0, "waiting": 3, "failed": 0}
    assert progress(study)["waiting"] == 3  # the three orphans no longer wait
    dropped = [t for t in study.get_trials(deepcopy=False) if "dropped" in t.user_attrs]
    assert sorted(run_key(t) for t in dropped) == ["more_seeds/seed_11", "more_seeds/seed_5", "more_seeds/seed_7"]
    spec_path.write_text(full)
    _, _, study = start(spec_path, tmp_path)  # a spec that has them (another machine's) queues them again
    assert progress(study)["waiting"] == 6


@pytest.mark.slow
@pytest.mark.parametrize("spec_name", ["thesis", "planner_stable_flier"])
def test_the_readme_report_command_gives_the_committed_report(tmp_path, spec_name):
    """On a fresh clone `roshan experiment report configs/experiments/thesis.yaml --out out/thesis` (the README's
    command) reads the committed journal and writes the committed report, table for table. The journal is read
    from a copy here (the report never writes to it, but a running experiment may append to the checkout's)."""
    journal = tmp_path / "experiment.journal"
    journal.write_bytes((REPO / "benchmarks" / "results" / spec_name / "experiment.journal").read_bytes())
    out = subprocess.run([sys.executable, "-m", "roshan", "experiment", "report",
                          f"configs/experiments/{spec_name}.yaml", "--storage", str(journal), "--out",
                          str(tmp_path / spec_name)], capture_output=True, text=True, timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr[-3000:]
    committed = REPO / "benchmarks" / "results" / spec_name
    for name in ("report.md", "per_seed.csv"):
        assert (tmp_path / spec_name / name).read_text() == (committed / name).read_text(), (
            f"benchmarks/results/{spec_name}/{name} is not what the committed journal gives: regenerate it with "
            f"`roshan experiment report configs/experiments/{spec_name}.yaml --out benchmarks/results/{spec_name} "
            "--replace`")


@pytest.mark.slow
def test_a_spec_names_its_storage_and_the_report_finds_it_from_any_root(tmp_path):
    """The thesis spec names its committed journal, so the README's report command works on a fresh clone."""
    journal = tmp_path / "committed" / "experiment.journal"
    journal.parent.mkdir()
    spec_path = write_spec(tmp_path, SPEC.replace("name: demo", f"name: demo\nstorage: {journal}"))
    spec = load_spec(spec_path)
    assert spec.storage == str(journal)
    assert load_spec(REPO / "configs" / "experiments" / "thesis.yaml").storage == \
        "benchmarks/results/thesis/experiment.journal"
    study = prepare_experiment(open_storage(str(journal), heartbeat=60), spec)
    run_worker(spec, str(journal), tmp_path, execute=recording_execute(tmp_path / "log"))
    out = subprocess.run([sys.executable, "-m", "roshan", "experiment", "report", str(spec_path), "--root",
                          str(tmp_path / "elsewhere"), "--out", str(tmp_path / "report")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "experiment demo: 1/6 runs done" in out.stdout
    assert (tmp_path / "report" / "report.md").is_file() and progress(study)["done"] == 1


def test_only_runs_the_chosen_conditions_and_leaves_the_rest_queued(tmp_path):
    spec, url, study = start(write_spec(tmp_path), tmp_path)
    assert spec.select(("more_*", "greedy")) == ("more_seeds", "greedy")
    assert spec.select(()) == ()
    with pytest.raises(SpecError, match=r"--only 'E2_\*' matches no condition; it has fast, more_seeds, greedy"):
        spec.select(("E2_*",))
    log = tmp_path / "log"
    for _ in range(4):  # one more call than there are chosen runs: it finds none and returns
        assert run_worker(spec, url, tmp_path, execute=recording_execute(log), only=("more_seeds",)) == 0
    assert lines(log, "done") == ["more_seeds/seed_5", "more_seeds/seed_7", "more_seeds/seed_11"]
    assert progress(study) == {"done": 3, "running": 0, "waiting": 3, "failed": 0}
    run_worker(spec, url, tmp_path, execute=recording_execute(log))  # without --only: the spec's order again
    assert lines(log, "done")[-1] == "fast/seed_0"


def test_a_run_failed_as_stale_while_it_worked_records_its_result_on_its_retry(tmp_path):
    """Another machine saw the worker silent past the grace period (paused, cut off) and failed its trial; the
    finished run's result goes to the queued retry, so it is not run again."""
    from optuna.trial import TrialState

    from roshan.study.storage import RetryStaleTrial, experimental

    spec, url, study = start(write_spec(tmp_path), tmp_path)
    log = tmp_path / "log"

    def failed_meanwhile(run, folder):
        running = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))[0]
        study._storage.set_trial_state_values(running._trial_id, state=TrialState.FAIL)
        with experimental():  # what fail_stale does on the other machine
            RetryStaleTrial(max_retry=3)(study, study._storage.get_trial(running._trial_id))
        return recording_execute(log)(run, folder)

    assert run_worker(spec, url, tmp_path, execute=failed_meanwhile, only=("fast",)) == 0
    trials = study.get_trials(deepcopy=False)
    assert [t.state for t in trials if t.user_attrs.get("run") == "fast/seed_0"] == [TrialState.FAIL,
                                                                                     TrialState.COMPLETE]
    retry = [t for t in trials if t.state == TrialState.COMPLETE][0]
    assert retry.user_attrs["result"]["run"] == "fast/seed_0" and retry.value == 0.0
    assert lines(log, "done") == ["fast/seed_0"]
    assert progress(study) == {"done": 1, "running": 0, "waiting": 5, "failed": 0}  # the retry did it



def test_a_retry_that_carries_its_runs_result_is_completed_not_run_again(tmp_path):
    """The worker stored the result and was cut off before the tell; the next runner failed the trial as stale and
    queued a retry, which carries the result (a 90-minute E7 seed was about to be trained again this way)."""
    from optuna.trial import TrialState

    from roshan.study.storage import RetryStaleTrial, experimental

    spec, url, study = start(write_spec(tmp_path), tmp_path)
    log = tmp_path / "log"
    first = [t for t in study.get_trials(deepcopy=False) if t.user_attrs.get("run") == "fast/seed_0"][0]
    study._storage.set_trial_state_values(first._trial_id, state=TrialState.RUNNING)
    result = {**fake_result(spec.runs(("fast",))[0]), "success_rate": 0.75}
    study._storage.set_trial_user_attr(first._trial_id, "result", result)
    study._storage.set_trial_state_values(first._trial_id, state=TrialState.FAIL)
    with experimental():
        RetryStaleTrial(max_retry=3)(study, study._storage.get_trial(first._trial_id))

    assert run_worker(spec, url, tmp_path, execute=recording_execute(log), only=("fast",)) == 0
    assert not log.exists()  # nothing was trained or evaluated
    retry = [t for t in study.get_trials(deepcopy=False)
             if t.user_attrs.get("run") == "fast/seed_0" and t.state == TrialState.COMPLETE]
    assert len(retry) == 1 and retry[0].value == 0.75 and retry[0].user_attrs["result"] == result
    assert progress(study)["done"] == 1


# ------------------------------------------------------------------------------------------ the report


def test_the_reports_header_lists_each_departure_with_its_reason_and_effect(tmp_path):
    text = SPEC.replace("conditions:", "departures:\n  - what: drones fly our flier.\n    why: the thesis's is lost.\n"
                        "    effect: >-\n      2 points more\n      success.\nconditions:")
    spec = load_spec(write_spec(tmp_path, text))
    header = markdown(spec, condition_rows(spec, {})).split("| condition |")[0]
    assert "- **drones fly our flier.** Why: the thesis's is lost. Effect: 2 points more success." in header
    assert "Departures" not in markdown(load_spec(write_spec(tmp_path)), condition_rows(load_spec(
        write_spec(tmp_path)), {}))


def test_report_is_mean_std_median_over_seeds_beside_the_thesis(tmp_path):
    spec = load_spec(write_spec(tmp_path))
    results = {r.key: fake_result(r) for r in spec.runs() if r.condition.name != "greedy"}
    results["more_seeds/seed_7"]["failure_rates"] = {"timeout": 0.25, "collision": 0.25}
    rows = {r["condition"]: r for r in condition_rows(spec, results)}
    # more_seeds: seeds 5, 7, 11 -> success 0 %, 50 %, 25 %; by hand: mean 25, std sqrt((625 + 625 + 0) / 3)
    s = rows["more_seeds"]["success"]
    assert (s.mean, s.median) == (25.0, 25.0) and s.std == pytest.approx(np.sqrt(1250 / 3))
    c = rows["more_seeds"]["collision"]
    assert c.mean == pytest.approx(25 / 3) and c.median == 0.0
    t = rows["more_seeds"]["tte"]  # over all six episodes: 105, 200, 107, 200, 111, 200
    assert t.mean == pytest.approx(923 / 6) and t.median == pytest.approx((111 + 200) / 2)
    assert rows["greedy"]["seeds"] == 0 and rows["fast"]["seeds"] == 2
    assert rate(results["fast/seed_1"], "success") == 25.0
    table = markdown(spec, list(rows.values()))
    assert ("| fast | 2/2 | abcdef0 | AMD EPYC | success % | 12.5 ± 12.5 (12.5) | - | - | 91.15 ± 17.46 (100) |"
            in table)
    assert "| greedy | 0/1 | | | - | not run yet | | | - |" in table
    assert "collision %" not in table.split("| more_seeds")[0]  # fast never collided: no collision row


def test_report_shows_last_and_objective_weights_and_which_code_made_each_row(tmp_path):
    spec = load_spec(write_spec(tmp_path))
    results = {r.key: fake_result(r) for r in spec.runs() if r.condition.name == "fast"}
    for r in results.values():  # last: 50 % and TTE 300, 400 in both seeds; objective in seed 0 only
        r["last"] = {"success_rate": 0.5, "failure_rates": {"timeout": 0.5}, "tte_median": 350.0,
                     "tte_episodes": [300, 400]}
    results["fast/seed_0"]["objective"] = results["fast/seed_0"]["last"]
    results["fast/seed_1"]["code"] = {"commit": "1234567890", "dirty": True}
    # seed 1 trained on a Xeon outside the mode, then was evaluated on the EPYC
    results["fast/seed_1"]["trained_on"] = [{"cpu": "Intel Xeon", "isa": "AVX512", "mode": "vendor", "from_update": 0}]
    table = markdown(spec, condition_rows(spec, results))
    assert ("| fast | 2/2 | mixed: abcdef0, 1234567+ | AMD EPYC; Intel Xeon (AVX512, vendor kernels) | success % "
            "| 12.5 ± 12.5 (12.5) | 50.0 ± 0.0 (50.0) | 50.0 ± 0.0 (50.0) [1 of 2] | 91.15 ± 17.46 (100) |") in table
    assert "|  |  |  |  | TTE (steps) | 150 ± 50 (150) | 350 ± 50 (350) | 350 ± 50 (350) [1 of 2] | - |" in table
    rows = per_seed_csv(spec, results)
    assert "fast,0,4,0.00,0.00,0.00,100.00,0.00,150.0,150.0,50.00,50.00,,,,0.00,AMD EPYC,abcdef0" in rows
    assert ',"Intel Xeon (AVX512, vendor kernels); AMD EPYC",1234567+' in rows
    del results["fast/seed_1"]["machine"], results["fast/seed_1"]["trained_on"]  # a run from before: the host only
    assert "| AMD EPYC; ? |" in markdown(spec, condition_rows(spec, results))
    del results["fast/seed_0"]["objective"]  # no seed has it: no figure
    assert "| 50.0 ± 0.0 (50.0) | - | 91.15 ± 17.46 (100) |" in markdown(spec, condition_rows(spec, results))


def test_the_report_states_the_compute_spent_and_estimates_what_is_left(tmp_path):
    spec = load_spec(write_spec(tmp_path))
    results = {"fast/seed_0": {**fake_result(spec.runs(("fast",))[0]), "minutes": 30.0},
               "more_seeds/seed_5": {**fake_result(spec.runs(("more_seeds",))[0]), "minutes": 60.0}}
    # fast: 1 of 2 left at 30 min; more_seeds: 2 of 3 left at 60 min; greedy: no result, not estimated
    assert ("Compute: 2 finished runs took 1.5 h (one run per worker, summed); the 3 runs still to make of "
            "conditions with results take ~2.5 h more at their condition's mean, and 1 runs of conditions without "
            "any result are not estimated.") in markdown(spec, condition_rows(spec, results))


FINDINGS = """
findings:
  - claim: more seeds succeed more
    source: Table X
    holds: [more_seeds.success > fast.success]
  - claim: fast ends early
    source: Table Y
    holds: [fast.success >= 0, fast.tte_median < 150]
  - claim: greedy wins
    holds: [greedy.success > fast.success]
"""


def test_findings_are_judged_from_the_figures_with_each_set_of_weights(tmp_path):
    spec = load_spec(write_spec(tmp_path, SPEC + FINDINGS))
    results = {r.key: fake_result(r) for r in spec.runs() if r.condition.name != "greedy"}
    for r in results.values():
        r["last"] = {"success_rate": 0.0, "failure_rates": {}, "tte_median": 100.0, "tte_episodes": [100]}
    results["more_seeds/seed_5"]["last"]["success_rate"] = 0.75  # mean over 0.75, 0, 0 = 25 % > fast's 0 %
    by_cond = {c.name: done_results(spec, results, c) for c in spec.conditions}
    more, early, greedy = spec.findings
    # best: more_seeds 25 % (0, 50, 25) > fast 12.5 %, each seed over 4 episodes: far inside the noise
    v = verdict(more, by_cond, "best")
    assert (v.label, v.reasons) == ("not resolved", "a tie within noise")
    assert v.checks[0].startswith("more_seeds.success 25.0 [") and "> fast.success 12.5 [" in v.checks[0]
    # fast's TTE median over 100, 200, 101, 200 is 150.5, every bootstrap median above 100: not below 150 either
    assert verdict(early, by_cond, "best").label == "not resolved"
    v = verdict(early, by_cond, "last")  # last weights: fast at 0 % of 8 episodes (saturated), TTE 100 < 150
    assert (v.label, v.reasons) == ("not resolved", "saturated, both at 0 %")
    assert v.checks[1] == ("fast.tte_median 100 [100, 100] < 150: difference -50 steps, 95 % CI [-50, -50]: holds")
    assert verdict(more, by_cond, "objective").label == "untested"  # no seed has objective weights
    assert verdict(greedy, by_cond, "best") == Verdict("untested", "no figures yet for greedy", ())
    text = markdown(spec, condition_rows(spec, results), results)
    assert "- **fast ends early** (Table Y)" in text and "  - best: **not resolved** (a tie within noise): " in text
    assert "- **greedy wins** ()" in text and "seeds short: greedy 0/1" in text
    assert "  - best, last: **untested**: no figures yet for greedy\n" in text  # one line: the same verdict
    assert "  - objective: **untested**: no figures yet for greedy, fast\n" in text


def test_findings_are_not_part_of_any_run_s_settings(tmp_path):
    """A finding may be added, dropped or rewritten without changing a condition's fingerprint (the journal's
    runs stay the spec's)."""
    bare = load_spec(write_spec(tmp_path, SPEC)).fingerprints()
    assert load_spec(write_spec(tmp_path, SPEC + FINDINGS)).fingerprints() == bare


@pytest.mark.parametrize("check, message", [
    ("fast.success >> 3", "is not a check"),
    ("nope.success > 3", "no condition 'nope'"),
    ("fast.speed > 3", "unknown figure 'speed'"),
])
def test_a_bad_finding_is_refused_naming_it(tmp_path, check, message):
    text = SPEC + f"findings:\n  - claim: c\n    holds: ['{check}']\n"
    with pytest.raises(SpecError, match=rf"spec.yaml: findings\[0\].holds: .*{message}"):
        load_spec(write_spec(tmp_path, text))


# ------------------------------------------------------------------------------------------ a real run


@pytest.mark.slow
def test_the_command_trains_evaluates_and_reports_a_tiny_experiment(tmp_path):
    spec = tmp_path / "tiny.yaml"
    spec.write_text(f"""
name: tiny
seeds: 1
eval: {{episodes: 2, seed: 3, envs: 2}}
conditions:
  simple:
    config: {REPO / "configs" / "fly_simple.yaml"}
    set: {{sim.envs: 4, train.max_updates: 1, train.total_steps: 0, train.max_minutes: 0, ppo.horizon: 64,
          ppo.batch_size: 32}}
    thesis: {{success: 91.15 ± 17.46 (100.0)}}
""")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-m", "roshan", "experiment"]
    out = subprocess.run([*cmd, "run", str(spec), "--root", str(tmp_path / "runs"), "--threads", "1"], env=env,
                         capture_output=True, text=True, timeout=900, cwd=REPO)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "simple/seed_0: success" in out.stdout
    result = json.loads((tmp_path / "runs" / "tiny" / "simple" / "seed_0" / "result.json").read_text())
    assert result["episodes"] == 2 and result["train"]["updates"] == 1
    # One update: the last weights are the best, so the same episodes give the same result.
    assert result["last"]["success_rate"] == result["success_rate"]
    assert result["last"]["failure_rates"] == result["failure_rates"]
    # ... and the training-objective checkpoint (the thesis's rule) is evaluated on them too
    assert result["objective"]["tte_episodes"] == result["last"]["tte_episodes"] == result["tte_episodes"]
    assert result["code"]["commit"] is not None  # which code made the row
    rep = subprocess.run([*cmd, "report", str(spec), "--root", str(tmp_path / "runs")], env=env,
                         capture_output=True, text=True, timeout=300, cwd=REPO)
    assert rep.returncode == 0, rep.stderr[-3000:]
    assert "1/1 runs done" in rep.stdout
    # with its commit and its machine (the runner's worker trained in the reproducible mode)
    assert re.search(r"\| simple \| 1/1 \| [0-9a-f]{7}\+? \| [^|(]+ \| success % \|", rep.stdout), rep.stdout
    assert [m["mode"] for m in result["trained_on"]] == ["reproducible"] and result["machine"]["isa"] == "AVX2"
    report = tmp_path / "runs" / "tiny" / "report"
    assert (report / "success.png").stat().st_size > 0
    assert (report / "runs" / "simple" / "seed_0.json").is_file()
    rows = list(csv.DictReader((report / "per_seed.csv").open()))
    assert rows[0]["last_success_pct"] == rows[0]["success_pct"]
    assert result["models"] == {} and rows[0]["low_level"] == ""  # a FlyAgent that trains flies no frozen model
    again = subprocess.run([*cmd, "run", str(spec), "--root", str(tmp_path / "runs")], env=env,
                           capture_output=True, text=True, timeout=300, cwd=REPO)
    assert again.returncode == 0 and "1/1 runs done, 0 waiting" in again.stdout  # nothing is run twice


def fire_layouts(cfg, num_envs: int, seed: int, episodes: int) -> set[bytes]:
    """The initial fire layouts (burning-cell masks) of the first ``episodes`` episodes of each of ``num_envs`` envs
    of a FlyVectorEnv built and reset with ``seed``, as the buffer recorder and the evaluation build theirs."""
    from roshan.env.fly import FlyVectorEnv
    from roshan.kernels.fire import BURNING
    env = FlyVectorEnv(num_envs=num_envs, config=cfg, fly=cfg.fly, seed=seed)
    try:
        env.reset(seed=seed)
        layouts = set()
        for _ in range(episodes):
            layouts |= {np.packbits(s == BURNING).tobytes() for s in env.fire.states()}
            env.reset()
        return layouts
    finally:
        env.close()


@pytest.mark.slow
def test_the_e7_buffer_shares_no_fire_layout_with_its_evaluation():
    """E7 learns offline from a buffer: its episodes must not be the ones it is evaluated on. The buffer's ~200k
    transitions take ~3 episodes in each of its 50 envs and the evaluation's 200 episodes ~4 in each of 50; 6 each
    cover both."""
    from roshan.config import load_config
    (e7,) = [c for c in load_spec(REPO / "configs" / "experiments" / "thesis.yaml").conditions if c.name == "E7"]
    cfg = load_config(str(REPO / e7.buffer.model / "config.yaml"))
    envs = cfg.train.eval_envs  # the recorder's env count (save_buffer) and the evaluation's (eval envs 50)
    buffer = fire_layouts(cfg, envs, e7.buffer.seed, 6)
    evaluation = fire_layouts(cfg, envs, e7.eval_seed, 6)
    assert len(buffer) > 0.95 * envs * 6 and len(evaluation) > 0.95 * envs * 6  # distinct layouts, all lit
    assert not buffer & evaluation
    assert fire_layouts(cfg, envs, e7.eval_seed, 2) <= evaluation  # the same seed gives the same layouts


REPRODUCED = "E1_ppo"  # a cheap row (~15 s a seed), made again in the reproducible mode at deaf51d (`--rerun E1_ppo`)


@pytest.mark.slow
def test_a_committed_cheap_row_is_reproduced_by_this_code(tmp_path):
    """Results are claims about code: rerunning a finished seed of a cheap committed row here gives its figures
    exactly (same machine kind). A change of behaviour fails this; then rerun the row (`roshan experiment run
    configs/experiments/thesis.yaml --only E1_ppo --rerun E1_ppo --threads 1`) and commit the journal."""
    journal = tmp_path / "committed.journal"
    journal.write_bytes((REPO / "benchmarks" / "results" / "thesis" / "experiment.journal").read_bytes())
    thesis = load_spec(REPO / "configs" / "experiments" / "thesis.yaml")
    study = optuna.load_study(study_name=thesis.name, storage=open_storage(str(journal), heartbeat=None))
    cond = thesis.condition(REPRODUCED)
    seed = cond.seeds[-1]
    committed = results_of(study)[f"{REPRODUCED}/seed_{seed}"]
    assert committed["code"]["commit"] and not committed["code"]["dirty"]
    spec = tmp_path / "repro.yaml"
    spec.write_text(json.dumps({"name": "repro", "eval": {"episodes": cond.eval_episodes, "seed": cond.eval_seed,
                                                          "envs": cond.eval_envs},
                                "conditions": {REPRODUCED: {"config": str(REPO / cond.config), "seeds": [seed],
                                                            "set": list(cond.sets)}}}))
    out = subprocess.run([sys.executable, "-m", "roshan", "experiment", "run", str(spec), "--root",
                          str(tmp_path / "runs"), "--threads", "1"], env={**os.environ, "PYTHONPATH": str(REPO)},
                         capture_output=True, text=True, timeout=900, cwd=REPO)
    assert out.returncode == 0, out.stderr[-3000:]
    again = json.loads((tmp_path / "runs" / "repro" / REPRODUCED / f"seed_{seed}" / "result.json").read_text())
    for key in ("success_rate", "failure_rates", "tte_episodes", "episodes", "last", "objective"):
        assert again[key] == committed[key], f"{key} differs from the committed row (made at {committed['code']})"
    assert again["train"]["updates"] == committed["train"]["updates"]


def test_a_changed_default_leaves_stored_fingerprints_alone(tmp_path, monkeypatch):
    """planner.greedy_home's default became `fixed` after the thesis rows ran with `original`: fingerprints
    compare with the default of record, so those runs keep theirs, and a run that differs from it still differs."""
    import dataclasses

    import roshan.experiment.spec as spec_module
    spec = load_spec(write_spec(tmp_path, SPEC.replace("    controller: greedy\n", "    controller: greedy\n"
                                                       "    set: {{planner.greedy_home: original}}\n")))
    plain = load_spec(write_spec(tmp_path))
    fixed = load_spec(write_spec(tmp_path, SPEC.replace("    controller: greedy\n", "    controller: greedy\n"
                                                        "    set: {{planner.greedy_home: fixed}}\n")))
    before = [s.fingerprints()["greedy/seed_0"] for s in (spec, plain, fixed)]
    # a condition that leaves the key to its default is fingerprinted with the default of record (spec.py says
    # why, and the one case that cannot be told apart)
    assert before[0] == before[1] != before[2]
    real = spec_module.Config
    for default in ("original", "fixed"):  # whatever the code's default is now
        config = lambda d=default: dataclasses.replace(real(), planner=dataclasses.replace(  # noqa: E731
            real().planner, greedy_home=d))
        monkeypatch.setattr(spec_module, "Config", config)
        assert spec_module.to_dict(spec_module.Config())["planner"]["greedy_home"] == default
        assert [s.fingerprints()["greedy/seed_0"] for s in (spec, fixed)] == [before[0], before[2]]
    monkeypatch.setattr(spec_module, "DEFAULTS_OF_RECORD", {})  # without the record, the changed default shows
    assert spec.fingerprints()["greedy/seed_0"] != before[0]


def test_a_condition_that_cannot_train_is_refused_before_any_worker_starts(tmp_path):
    """A rollout that does not split over the envs (horizon 8,192 over 3 envs x 4 drones) was found by each worker
    in turn, failing every seed; the runner now refuses it up front, naming the condition, and records nothing."""
    text = SPEC.replace("set: {{train.max_updates: 3, sim.envs: 4}}", "set: {{train.max_updates: 3, sim.envs: 3}}")
    spec = load_spec(write_spec(tmp_path, text))
    storage = tmp_path / "journal"
    with pytest.raises(SpecError, match=r"spec.yaml: condition fast: ppo.horizon = \d+ must be a positive multiple "
                                        r"of sim.envs x drones.num_drones = 12"):
        run_experiment(spec, tmp_path, str(storage), echo=lambda _: None)
    assert not storage.exists()
    check_trainable(load_spec(write_spec(tmp_path)))  # the spec as it was trains


def test_a_run_that_only_failed_may_change_and_its_old_folder_is_set_aside(tmp_path):
    """P2_i5's seeds failed at their start (a horizon that did not split over 32 envs); its condition then had to
    change. A run whose every trial failed has no result, so it may take new settings; its old folder is kept
    under another name instead of being continued with the new ones."""
    spec_path = write_spec(tmp_path)
    spec, url, study = start(spec_path, tmp_path)

    def fail(run, folder):
        claim_folder(folder, run.fingerprint())
        raise RuntimeError("a config it could not train")

    with pytest.raises(RuntimeError):
        run_worker(spec, url, tmp_path, execute=fail)  # fast/seed_0 failed
    folder = run_dir(tmp_path, spec.name, spec.runs()[0])
    old = (folder / "fingerprint").read_text().strip()
    spec_path.write_text(spec_path.read_text().replace("train.max_updates: 3", "train.max_updates: 4"))
    spec, _, _ = start(spec_path, tmp_path)  # accepted: the run never finished
    new = spec.runs()[0].fingerprint()
    assert new != old
    claim_folder(folder, new)
    assert (folder / "fingerprint").read_text().strip() == new
    assert (folder.with_name(f"seed_0.superseded-{old}") / "fingerprint").read_text().strip() == old
    claim_folder(folder, new)  # its own folder is continued
    assert not folder.with_name(f"seed_0.superseded-{new}").exists()


def test_the_success_plot_stays_one_page_wide_and_names_conditions_not_run(tmp_path):
    """The thesis report's success.png was 4,004 px wide with 40 conditions side by side, and a condition without
    results showed nothing. One row per condition now: the width is fixed, and such a condition says "not run"."""
    import matplotlib.pyplot as plt

    from roshan.experiment.report import condition_rows, success_figure

    text = SPEC + "".join(f"  extra_{i}:\n    config: {{config}}\n    seeds: 1\n" for i in range(40))
    spec = load_spec(write_spec(tmp_path, text))
    results = {"fast/seed_0": fake_result(spec.runs()[0])}
    rows = condition_rows(spec, results)
    fig = success_figure(spec, rows)
    try:
        width, height = fig.get_size_inches() * 110
        assert width <= 1600 and height > width / 2  # it grows down, not across
        ax = fig.axes[0]
        assert [t.get_text() for t in ax.get_yticklabels()][:3] == ["fast", "more_seeds", "greedy"]
        not_run = [t for t in ax.texts if t.get_text() == "not run"]
        assert len(not_run) == len(spec.conditions) - 1  # every condition but `fast`
    finally:
        plt.close(fig)


def test_a_folder_set_aside_twice_under_one_fingerprint_gets_a_name_of_its_own(tmp_path):
    # issue 52: a failed run whose condition went A -> B -> A -> C failed from then on with "[Errno 39] Directory not
    # empty: '.../seed_0' -> '...superseded-<A>'" and "fix the cause and continue" looped
    folder = tmp_path / "fast" / "seed_0"
    for fingerprint in ("A", "B", "A", "C"):
        claim_folder(folder, fingerprint)
    assert (folder / "fingerprint").read_text().strip() == "C"
    assert sorted(p.name for p in folder.parent.iterdir()) == [
        "seed_0", "seed_0.superseded-A", "seed_0.superseded-A.2", "seed_0.superseded-B"]


def test_the_report_refuses_a_spec_changed_under_its_runs_as_run_does(tmp_path):
    # issue 52: `experiment report` printed the old runs under the new settings, with no warning
    spec_path = write_spec(tmp_path)
    spec, url, _ = start(spec_path, tmp_path)
    run_worker(spec, url, tmp_path, execute=recording_execute(tmp_path / "log"))  # fast/seed_0 has run
    spec_path.write_text(spec_path.read_text().replace("train.max_updates: 3", "train.max_updates: 4"))
    with pytest.raises(SpecError, match=r"runs made with other settings under the same keys \(fast/seed_0\)"):
        report_experiment(spec_path, "local", url, tmp_path, tmp_path / "report")
    assert not (tmp_path / "report").exists()


def test_the_report_overwrites_nothing_unless_replace(tmp_path):
    # issue 52: `experiment report SPEC --out DIR` into an evaluation's folder replaced its summary.json
    spec_path = write_spec(tmp_path)
    spec, url, _ = start(spec_path, tmp_path)
    run_worker(spec, url, tmp_path, execute=recording_execute(tmp_path / "log"))
    evaluation = tmp_path / "eval"
    evaluation.mkdir()
    (evaluation / "summary.json").write_text('{"episodes": 100}\n')
    with pytest.raises(OutputError, match=r"it holds summary\.json of something other than a report of experiment "
                                          r"'demo'; give --replace"):
        report_experiment(spec_path, "local", url, tmp_path, evaluation)
    assert (evaluation / "summary.json").read_text() == '{"episodes": 100}\n'
    report_experiment(spec_path, "local", url, tmp_path, evaluation, replace=True)
    assert (evaluation / "report.md").read_text().startswith("Experiment `demo` (")
    with pytest.raises(OutputError, match=r"an earlier report of experiment 'demo'; give --replace"):
        report_experiment(spec_path, "local", url, tmp_path, evaluation)  # its own report too: only with --replace
    report_experiment(spec_path, "local", url, tmp_path, evaluation, replace=True)


def test_a_committed_journal_is_written_only_when_named_as_storage(tmp_path):
    # issue 52: `experiment run configs/experiments/endurance.yaml --only ...` on a finished condition added records to
    # the committed, tracked journal, because the spec names it as its storage
    journal = tmp_path / "committed" / "experiment.journal"
    journal.parent.mkdir()
    spec_path = write_spec(tmp_path, SPEC.replace("name: demo", f"name: demo\nstorage: {journal}"))
    spec = load_spec(spec_path)
    prepare_experiment(open_storage(str(journal), heartbeat=60), spec)
    run_worker(spec, str(journal), tmp_path, execute=recording_execute(tmp_path / "log"))
    committed = journal.read_bytes()
    said = []
    url = run_storage(spec, tmp_path / "root", echo=said.append)
    assert url == str((tmp_path / "root" / "demo" / "experiment.journal").resolve())
    assert said == [f"experiment demo: runs are recorded in {url}, a copy of the spec's journal {journal} (to add "
                    f"them to that one, give --storage {journal})"]
    study = prepare_experiment(open_storage(url, heartbeat=60), spec)
    run_worker(spec, url, tmp_path, execute=recording_execute(tmp_path / "log"))
    assert progress(study)["done"] == 2  # the committed journal's finished run is kept in the copy
    assert journal.read_bytes() == committed
    assert run_storage(spec, tmp_path / "root", echo=said.append) == url and len(said) == 1  # made once
    assert run_storage(spec, tmp_path / "root", str(journal)) == str(journal)  # named: written


def test_a_cut_journal_names_the_experiment_command_that_repairs_it(tmp_path):
    # issue 52: `experiment report` suggested `roshan study run --resume --name j --root .`, a study command with the
    # wrong name; the repair is `roshan experiment run SPEC`
    spec_path = write_spec(tmp_path)
    spec, url, _ = start(spec_path, tmp_path)
    with open(url, "ab") as f:
        f.write(b'{"op_code": 5, "cut')
    with pytest.raises(ValueError,
                       match=rf"of the study journal is cut .*; `roshan experiment run {re.escape(str(spec_path))} "
                             rf"--storage {re.escape(url)}` drops it"):
        report_experiment(spec_path, "local", url, tmp_path, tmp_path / "report")


@pytest.mark.parametrize("change, message", [
    ("config: {planner}\n    controller: greedy", None),  # the spec as it is
    ("config: {planner}\n    controller: greedy\n    set: {{map.name: no_such_map}}",
     r"spec.yaml: condition greedy: map.name: .*no_such_map"),
    ("config: {planner}\n    controller: greedy\n    set: {{planner.fly_model: models/nothing}}",
     r"spec.yaml: condition greedy: planner.fly_model: models/nothing: no such run folder or checkpoint file"),
])
def test_a_bad_map_or_model_in_a_spec_is_refused_before_any_worker_starts(tmp_path, change, message, monkeypatch):
    # issue 52: a bad map or fly_model in a spec was found only by the worker
    monkeypatch.chdir(REPO)  # the configs' models/ paths are relative to the checkout
    spec = load_spec(write_spec(tmp_path, SPEC.replace("config: {planner}\n    controller: greedy", change)))
    if message is None:
        check_sources(spec)
        return
    storage = tmp_path / "journal"
    with pytest.raises(SpecError, match=message):
        run_experiment(spec, tmp_path, str(storage), echo=lambda _: None)
    assert not storage.exists()
