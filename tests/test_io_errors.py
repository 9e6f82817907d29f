"""I/O faults give one line naming the path and what was being written, checked before the work starts where
possible; a full disk during training stops after the last good checkpoint, which resumes."""

import contextlib
import errno
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

import roshan.runs.auto_train
import roshan.runs.evaluate
import roshan.runs.train
import roshan.tools.simulate
from roshan.checkpoints import checkpoint_path, load_checkpoint
from roshan.cli import main

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--set", "sim.envs=4", "--set", "ppo.horizon=128", "--set", "ppo.batch_size=64",
        "--set", "train.total_steps=0", "--set", "train.max_minutes=0"]


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_error(result, path) -> str:
    """The command failed with exit code 1 and a single ``Error:`` line naming ``path``, no traceback."""
    assert result.exit_code == 1, result.output
    # CliRunner turns an uncaught exception into exit code 1 too: only a ClickException ends in SystemExit.
    assert isinstance(result.exception, SystemExit) and "Traceback" not in result.output, result.exception
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and str(path) in errors[0] and "cannot write" in errors[0], result.output
    return errors[0]


@contextlib.contextmanager
def read_only_folder(tmp_path: Path):
    """A read-only tmpfs (root ignores permission bits, not a read-only mount); skipped where mount fails."""
    where = tmp_path / "ro"
    where.mkdir()
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(where)], check=True,
                       capture_output=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        pytest.skip(f"cannot mount a read-only tmpfs here ({exc})")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], check=False)


@pytest.fixture(params=["file_in_the_way", "read_only"])
def unwritable(request, tmp_path):
    """A folder path that cannot be written: under a plain file, or inside a read-only mount."""
    if request.param == "file_in_the_way":
        (tmp_path / "afile").write_text("x")
        yield tmp_path / "afile" / "out"
        return
    with read_only_folder(tmp_path) as ro:
        yield ro / "out"


def never(*args, **kwargs):
    raise AssertionError("the work started although its output cannot be written")


# ------------------------------------------------------------------------------------------------ up front


def test_simulate_json_into_a_missing_folder_creates_it(tmp_path):
    out = tmp_path / "nodir" / "deeper" / "s.json"
    r = invoke("simulate", "--map", "21x21_Field", "--envs", "1", "--steps", "2", "--every", "1", "--quiet",
               "--json", out)
    assert r.exit_code == 0, r.output
    assert out.is_file() and f"json: {out}" in r.output


def test_simulate_json_to_an_unwritable_folder_fails_before_simulating(unwritable, monkeypatch):
    monkeypatch.setattr(roshan.tools.simulate, "run_simulation", never)
    out = unwritable / "s.json"
    line = one_line_error(invoke("simulate", "--map", "21x21_Field", "--steps", "2", "--quiet", "--json", out), out)
    assert "the JSON series" in line


def test_simulate_frames_and_gif_to_an_unwritable_folder_fail_before_simulating(unwritable, monkeypatch):
    monkeypatch.setattr(roshan.tools.simulate, "run_simulation", never)
    one_line_error(invoke("simulate", "--steps", "2", "--quiet", "--frames", unwritable), unwritable)
    one_line_error(invoke("simulate", "--steps", "2", "--quiet", "--gif", unwritable / "a.gif"), unwritable)


def test_eval_out_and_json_to_an_unwritable_folder_fail_before_any_episode(unwritable, monkeypatch, tmp_path):
    monkeypatch.setattr(roshan.runs.evaluate, "run_episodes", never)
    line = one_line_error(invoke("eval", ROOT / "models/fly_simple", "--quiet", "--out", unwritable), unwritable)
    assert "evaluation files" in line
    js = unwritable / "e.json"
    one_line_error(invoke("eval", ROOT / "models/fly_simple", "--quiet", "--out", tmp_path / "ev", "--json", js), js)
    assert not (tmp_path / "ev" / "episodes.csv").exists()


def test_train_root_unwritable_fails_before_training(unwritable, monkeypatch):
    # the CLI trains through roshan.runs.auto_train, which holds its own name for train (imported above, so the
    # patch is undone for every later test; patching roshan.runs.train.train would leak into auto_train when this
    # test is the first to import it)
    monkeypatch.setattr(roshan.runs.auto_train, "train", never)
    line = one_line_error(invoke("train", ROOT / "configs/fly_simple.yaml", "--root", unwritable, "--quiet", *TINY),
                          unwritable)
    assert "run folders" in line


# ------------------------------------------------------------------------------------------------ full disk


def _disk_full_from(update: int, monkeypatch, target: str):
    """From ``update`` on, writing a checkpoint (``target="checkpoint"``) or TensorBoard events raises ENOSPC."""
    real_save, real_log = roshan.runs.train.save_checkpoint, roshan.runs.train.Trainer._log

    def save(state, path):
        if state["progress"]["updates"] >= update:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_save(state, path)

    def log(self, metrics):
        if self.progress.updates >= update:
            raise OSError(errno.ENOSPC, "No space left on device", str(self.run_dir / "tb" / "events.out"))
        real_log(self, metrics)

    if target == "checkpoint":
        monkeypatch.setattr(roshan.runs.train, "save_checkpoint", save)
    else:
        monkeypatch.setattr(roshan.runs.train.Trainer, "_log", log)


@pytest.mark.slow
@pytest.mark.parametrize("target", ["checkpoint", "tensorboard"])
def test_a_full_disk_stops_training_after_the_last_good_checkpoint(tmp_path, monkeypatch, target):
    _disk_full_from(2, monkeypatch, target)
    run = tmp_path / "r"
    r = invoke("train", ROOT / "configs/fly_simple.yaml", "--root", tmp_path, "--name", "r", "--no-eval", "--quiet",
               *TINY, "--set", "train.max_updates=3")
    line = one_line_error(r, run)
    assert "No space left on device" in line and "training stopped at update 2" in line
    assert f"roshan train --resume {run}" in line and "last checkpoint (update 1)" in line
    assert load_checkpoint(checkpoint_path(run, "latest"))["progress"]["updates"] == 1
    monkeypatch.undo()  # space freed: the run continues from its checkpoint
    r = invoke("train", "--resume", run, "--no-eval", "--quiet", "--set", "train.max_updates=2")
    assert r.exit_code == 0, r.output
    assert load_checkpoint(checkpoint_path(run, "latest"))["progress"]["updates"] == 2
