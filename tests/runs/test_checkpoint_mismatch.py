"""A checkpoint that does not fit the model, optimiser or setting it is loaded into is refused before loading,
with one line that names the file and the differing keys (never a traceback from deep inside torch)."""

from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

from roshan.checkpoints import checkpoint_path
from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "sim.envs=4", "--set", "ppo.horizon=128", "--set", "ppo.batch_size=64",
        "--set", "train.total_steps=0", "--set", "train.max_minutes=0"]


def cli(*args):
    # catch_exceptions=False: an uncaught exception (a traceback for the user) fails the test instead of exit 1
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def refused(res, *names: str) -> str:
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output
    for name in names:
        assert name in res.output, res.output
    return res.output


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """One tiny FlyAgent PPO run that made a step (so its Adam optimiser has state)."""
    root = tmp_path_factory.mktemp("runs")
    res = cli("train", ROOT / "configs/fly_simple.yaml", "--root", root, "--name", "r", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=1")
    assert res.exit_code == 0, res.output
    return root / "r"


@pytest.mark.slow
def test_resume_with_another_optimiser_family_is_refused(run):
    before = (run / "config.yaml").read_text()
    out = refused(cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "ppo.optim.name=sgd",
                      "--set", "train.max_updates=2"), "latest.pt", "ppo.optim.name", "'sgd'", "'adam'")
    assert "momentum" not in out
    assert (run / "config.yaml").read_text() == before  # a refused resume leaves the run folder as it was


def test_resume_with_separate_optimizers_is_refused(run):
    refused(cli("train", "--resume", run, "--no-eval", "--quiet", "--set", "ppo.separate_optimizers=true",
                "--set", "train.max_updates=2"), "latest.pt", "ppo.separate_optimizers")


def test_a_checkpoint_with_changed_weight_shapes_is_refused(run, tmp_path):
    path = checkpoint_path(run, "latest")
    state = torch.load(path, map_location="cpu", weights_only=False)
    state["agent"]["net"]["log_std"] = torch.zeros(3)
    bad = tmp_path / "bad.pt"
    torch.save(state, bad)
    out = refused(cli("eval", bad, "--episodes", 1, "--envs", 1, "--quiet", "--out", tmp_path / "eval"),
                  "bad.pt", "net.log_std", "(2,) here but (3,) in the checkpoint")
    assert "size mismatch" not in out


def test_planner_eval_with_another_drone_count_is_refused(tmp_path):
    refused(cli("eval", ROOT / "models/planner", "--episodes", 1, "--envs", 1, "--quiet", "--out", tmp_path,
                "--set", "drones.num_drones=2"), "drones.num_drones", "2", "4")


def test_flyagent_eval_with_other_frames_is_refused(tmp_path):
    refused(cli("eval", ROOT / "models/fly_simple", "--episodes", 1, "--envs", 1, "--quiet", "--out", tmp_path,
                "--set", "fly.frames=2"), "fly.frames")


def test_a_planner_checkpoint_as_fly_model_is_refused(tmp_path):
    refused(cli("eval", ROOT / "models/planner", "--episodes", 1, "--envs", 1, "--quiet", "--out", tmp_path,
                "--set", "planner.fly_model=models/planner"),
            "planner.fly_model", "is a planner checkpoint", "needs a FlyAgent run")


def test_save_buffer_of_a_planner_is_refused(tmp_path):
    refused(cli("eval", ROOT / "models/planner", "--quiet", "--save-buffer", 10, tmp_path / "b.pt"),
            "replay buffers record FlyAgent transitions")
    assert not (tmp_path / "b.pt").exists()
