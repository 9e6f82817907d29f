"""Training runs end to end: the run folder, checkpoints, resume after SIGKILL, evaluation and clear errors."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

from roshan.checkpoints import checkpoint_path, load_checkpoint
from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "sim.envs=4", "--set", "ppo.horizon=128", "--set", "ppo.batch_size=64",
        "--set", "train.total_steps=0", "--set", "train.max_minutes=0"]


def cli(*args):
    result = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return result


def counters(run: Path, which: str = "latest") -> dict:
    return load_checkpoint(checkpoint_path(run, which))["progress"]


def test_train_writes_the_run_folder_and_resume_continues(tmp_path):
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "r", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=2")
    assert res.exit_code == 0, res.output
    run = tmp_path / "r"
    assert (run / "config.yaml").is_file()
    for which in ("latest", "best_reward", "best_objective"):
        assert checkpoint_path(run, which).is_file()
    assert list((run / "tb").glob("events.out.tfevents.*"))
    first = counters(run)
    assert first["updates"] == 2 and first["env_steps"] == 2 * 128 // 4  # 128 transitions = 32 env steps
    res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=3")
    assert res.exit_code == 0, res.output
    after = counters(run)
    assert after["updates"] == 3 and after["env_steps"] == first["env_steps"] + 32
    assert after["seconds"] > first["seconds"]


@pytest.mark.slow
def test_sigkill_mid_run_then_resume(tmp_path):
    """Kill -9 a training process while it writes checkpoints; the latest one loads and the run resumes from it
    with its counters."""
    cmd = [sys.executable, "-m", "roshan", "train", str(ROOT / "configs/fly_simple.yaml"), "--root", str(tmp_path),
           "--name", "k", "--no-eval", "--quiet", *TINY, "--set", "train.max_updates=100000"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    run = tmp_path / "k"
    try:
        deadline = time.time() + 240
        while time.time() < deadline:
            if checkpoint_path(run, "latest").is_file() and counters(run)["updates"] >= 5:
                break
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.2)
        else:
            pytest.fail("the training process wrote no checkpoint in time")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    saved = counters(run)  # loads: the file is whole
    assert saved["updates"] >= 5
    res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", f"train.max_updates={saved['updates'] + 2}")
    assert res.exit_code == 0, res.output
    after = counters(run)
    assert after["updates"] == saved["updates"] + 2
    assert after["env_steps"] == saved["env_steps"] + 2 * 32
    assert not list((run / "checkpoints").glob("*.tmp")), "stale temporary checkpoint files"


def test_resume_refuses_a_checkpoint_from_another_model(tmp_path):
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "m", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=1")
    assert res.exit_code == 0, res.output
    res = cli("train", "--resume", tmp_path / "m", "--no-eval", "--quiet", "--set", "fly.collision=true")
    assert res.exit_code != 0
    assert "fly.collision" in res.output and "another config" in res.output


def test_corrupt_checkpoint_is_named(tmp_path):
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "c", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=1")
    assert res.exit_code == 0, res.output
    checkpoint_path(tmp_path / "c").write_bytes(b"not a checkpoint")
    res = cli("train", "--resume", tmp_path / "c", "--no-eval", "--quiet")
    assert res.exit_code != 0 and "latest.pt" in res.output and "not a readable" in res.output


def test_bad_config_key_is_named(tmp_path):
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--set", "ppo.lrr=0.1")
    assert res.exit_code != 0 and "ppo.lrr" in res.output and "did you mean 'ppo.lr'" in res.output


def test_horizon_must_fit_the_batch(tmp_path):
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--no-eval", *TINY,
              "--set", "ppo.horizon=100")
    assert res.exit_code != 0 and "ppo.horizon" in res.output


def test_eval_of_a_folder_without_checkpoints(tmp_path):
    res = cli("eval", tmp_path)
    assert res.exit_code != 0 and "no checkpoints" in res.output


@pytest.mark.slow
def test_shipped_simple_model_evaluates_and_writes_files(tmp_path):
    out, js = tmp_path / "eval", tmp_path / "e.json"
    res = cli("eval", ROOT / "models/fly_simple", "--episodes", 20, "--envs", 10, "--seed", 1, "--out", out,
              "--json", js, "--quiet")
    assert res.exit_code == 0, res.output
    summary = json.loads(js.read_text())
    assert set(summary) == {"episodes", "success_rate", "failure_rates", "tte", "provenance"}
    assert summary["episodes"] == 20
    assert summary["success_rate"] >= 0.9
    assert set(summary["failure_rates"]) == {"collision", "boundary", "timeout"}
    for name in ("episodes.csv", "summary.json", "failure_reasons_bar.png", "time_to_end_hist.png"):
        assert (out / name).is_file()
    assert "Success rate" in res.output


@pytest.mark.slow
def test_eval_is_repeatable_under_a_seed(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for js in (a, b):
        res = cli("eval", ROOT / "models/fly_simple", "--episodes", 6, "--envs", 3, "--seed", 5, "--out",
                  tmp_path / js.stem, "--json", js, "--quiet")
        assert res.exit_code == 0, res.output
    results = [json.loads(js.read_text()) for js in (a, b)]
    assert [r.pop("provenance")["seed"] for r in results] == [5, 5]  # the rest is the same
    assert results[0] == results[1]


@pytest.mark.slow
def test_td3_and_iql_run_end_to_end(tmp_path):
    res = cli("train", ROOT / "configs/td3_simple.yaml", "--root", tmp_path, "--name", "td3", "--quiet",
              "--set", "sim.envs=4", "--set", "td3.min_memory_size=256", "--set", "train.max_updates=2",
              "--set", "train.total_steps=0", "--set", "train.eval_episodes=4", "--set", "train.eval_envs=4")
    assert res.exit_code == 0, res.output
    assert counters(tmp_path / "td3")["env_steps"] == 2 * 64 * 4
    buf = tmp_path / "buffer.pt"
    res = cli("eval", ROOT / "models/fly_simple", "--save-buffer", 600, buf, "--envs", 5, "--quiet")
    assert res.exit_code == 0 and buf.is_file(), res.output
    res = cli("train", ROOT / "configs/iql_offline.yaml", "--root", tmp_path, "--name", "iql", "--quiet",
              "--set", f"train.buffer_path={buf}", "--set", "iql.offline_updates=2", "--set", "train.max_updates=2",
              "--set", "train.eval_episodes=4", "--set", "train.eval_envs=4", "--set", "sim.envs=4",
              "--set", "fly.collision=false", "--set", "fly.policy=simple")
    assert res.exit_code == 0, res.output
    state = load_checkpoint(checkpoint_path(tmp_path / "iql"))
    assert state["progress"]["updates"] == 2 and state["progress"]["env_steps"] == 0
    assert torch.is_tensor(next(iter(state["agent"]["actor"].values())))


@pytest.mark.slow
def test_auto_train_seeds_and_periodic_evaluation(tmp_path):
    from roshan.runs.report.scalars import read_tensorboard_scalars

    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "auto", "--quiet", *TINY,
              "--set", "train.max_updates=2", "--set", "train.auto_train=2", "--set", "sim.seed=7",
              "--set", "train.eval_every=1", "--set", "train.eval_episodes=2", "--set", "train.eval_envs=2")
    assert res.exit_code == 0, res.output
    parent = tmp_path / "auto"
    summary = json.loads((parent / "auto_train.json").read_text())
    assert len(summary["success_rates"]) == 2
    for seed in (7, 8):
        run = parent / f"seed_{seed}"
        assert (run / "eval" / "summary.json").is_file()
        assert load_checkpoint(checkpoint_path(run))["config"]["sim"]["seed"] == seed
        scalars = read_tensorboard_scalars(run / "tb")
        assert len(scalars["Evaluation/Success_rate"]) == 2  # after each of the 2 updates


def test_resume_keeps_the_tensorboard_history_up_to_its_checkpoint(tmp_path):
    """A resume drops only what a killed process logged after its last checkpoint, never the checkpoint's own
    step (it used to purge that one too), and records itself as a text entry."""
    from torch.utils.tensorboard import SummaryWriter

    from roshan.runs.report.scalars import read_tensorboard_scalars

    def run_three_then_resume(name: str, killed_after: bool) -> dict:
        res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", name, "--no-eval",
                  "--quiet", *TINY, "--set", "train.max_updates=3")
        assert res.exit_code == 0, res.output
        run = tmp_path / name
        if killed_after:  # what a process killed between its last checkpoint and the next one had logged
            with SummaryWriter(str(run / "tb")) as w:
                w.add_scalar("Rewards/Rewards_Raw", 999.0, counters(run)["env_steps"] + 32)
        res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=5")
        assert res.exit_code == 0, res.output
        return {k: v for k, v in read_tensorboard_scalars(run / "tb").items() if not k.startswith("Perf/")}

    clean = run_three_then_resume("clean", killed_after=False)
    killed = run_three_then_resume("killed", killed_after=True)
    steps = [s for s, _ in clean["Rewards/Rewards_Raw"]]
    assert steps == [32, 64, 96, 128, 160]  # the checkpoint's step (96) survives the resume
    assert killed == clean  # the killed process's point is gone; every other value step for step (not timings)
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(tmp_path / "clean" / "tb"))
    acc.Reload()
    texts = acc.Tensors("Run/resumed/text_summary")
    assert len(texts) == 1 and b"resumed at update 3" in texts[0].tensor_proto.string_val[0]


def test_resume_trusts_the_checkpoint_and_keeps_earlier_resume_overrides(tmp_path):
    """An emptied config.yaml (what a full disk at start leaves) does not reset the run to defaults, and a
    plain resume keeps what an earlier resume set with --set."""
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "r", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=1", "--set", "ppo.lr=0.002")
    assert res.exit_code == 0, res.output
    run = tmp_path / "r"
    (run / "config.yaml").write_text("")
    res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=2",
              "--set", "ppo.entropy_coeff=0.02")
    assert res.exit_code == 0, res.output
    saved = load_checkpoint(checkpoint_path(run))["config"]
    assert saved["ppo"]["lr"] == 0.002 and saved["sim"]["envs"] == 4  # the checkpoint's, not the defaults
    res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=3")
    assert res.exit_code == 0, res.output
    saved = load_checkpoint(checkpoint_path(run))["config"]
    assert counters(run)["updates"] == 3 and saved["ppo"]["entropy_coeff"] == 0.02  # the first resume's --set
    assert "entropy_coeff: 0.02" in (run / "config.yaml").read_text()


def test_a_run_folder_is_locked_while_a_process_trains_in_it(tmp_path):
    from roshan.checkpoints import run_lock

    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "r", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=1")
    assert res.exit_code == 0, res.output
    with run_lock(tmp_path / "r"):
        res = CliRunner().invoke(main, ["train", "--resume", str(tmp_path / "r"), "--no-eval", "--quiet",
                                        "--set", "train.max_updates=2"])
    assert res.exit_code == 1 and f"pid {os.getpid()}" in res.output and "Traceback" not in res.output
    assert counters(tmp_path / "r")["updates"] == 1
