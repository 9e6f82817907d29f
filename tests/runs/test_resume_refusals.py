"""`roshan train --resume RUN` never trains from zero over a run's files: without checkpoints/latest.pt it continues
from the newest checkpoint there and says so on stderr; without any checkpoint it is refused with one line and
leaves the folder as it was; a resume refused because another process trains in RUN writes nothing either."""

import os
import shutil
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

from roshan.checkpoints import checkpoint_path, load_checkpoint, run_lock
from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "sim.envs=4", "--set", "ppo.horizon=128", "--set", "ppo.batch_size=64",
        "--set", "train.total_steps=0", "--set", "train.max_minutes=0"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def files(run: Path) -> dict[str, bytes]:
    """Every file of the run folder but its lock, by relative path."""
    return {str(p.relative_to(run)): p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()
            and p.name != ".lock"}


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("runs")
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", root, "--name", "r", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=2")
    assert res.exit_code == 0, res.output
    return root / "r"


@pytest.fixture
def run(trained, tmp_path) -> Path:
    """A copy of the trained run (each test changes its own)."""
    return Path(shutil.copytree(trained, tmp_path / "r"))


def test_resume_without_any_checkpoint_is_refused_and_touches_nothing(run):
    for p in (run / "checkpoints").glob("*.pt"):
        p.unlink()
    before = files(run)
    res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=1")
    assert res.exit_code == 1 and "Traceback" not in res.output
    (line,) = res.output.strip().splitlines()
    assert str(run) in line and "no checkpoint" in line and f"roshan train {run / 'config.yaml'}" in line
    assert files(run) == before


def test_resume_without_latest_continues_from_the_newest_checkpoint_and_says_which(run):
    checkpoint_path(run, "latest").unlink()
    newest = checkpoint_path(run, "best_objective")
    state = torch.load(newest, weights_only=False)
    state["progress"]["env_steps"] += 1000  # marks the file: a run from zero would count 3 * 32 env steps
    torch.save(state, newest)
    os.utime(checkpoint_path(run, "best_reward"), ns=(10**18, 10**18))  # older than best_objective
    os.utime(newest, ns=(2 * 10**18, 2 * 10**18))
    res = CliRunner().invoke(main, ["train", "--resume", str(run), "--no-eval", "--quiet",
                                    "--set", "train.max_updates=3"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    (line,) = res.stderr.strip().splitlines()
    assert str(newest) in line and "latest.pt" in line and "update 2" in line
    progress = load_checkpoint(checkpoint_path(run, "latest"))["progress"]
    assert progress["updates"] == 3 and progress["env_steps"] == state["progress"]["env_steps"] + 32


def test_a_resume_refused_because_the_run_is_busy_writes_nothing(run):
    before = files(run)
    with run_lock(run):
        res = cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=3",
                  "--set", "ppo.entropy_coeff=0.05")
    assert res.exit_code == 1 and f"pid {os.getpid()}" in res.output and "Traceback" not in res.output
    assert files(run) == before  # config.yaml above all: it does not take the refused command's --set
