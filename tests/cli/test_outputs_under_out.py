"""The README's eval and watch commands leave the checkout clean (issue 32, items 13 and 14): a shipped model's
evaluation goes to out/eval/<model>/ (not into the tracked models/<model>/eval/), watch's GIF to out/watch.gif,
and without a display --screenshot is the GIF's last frame instead of nothing."""

import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from roshan.cli import main
from roshan.io import OutputError
from roshan.kernels.annotate import BAND_COLOUR
from roshan.kernels.render import drone_colours
from roshan.runs.evaluate import eval_root
from roshan.study.studies import study_dir

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "fly_simple"
SMALL = ["--set", "map.name=15x15_Woods", "--set", "ignition.fire_percentage=0.05"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def test_shipped_models_evaluate_under_out_and_runs_in_their_folder(tmp_path):
    for model in ("fly_simple", "fly_collision", "planner"):
        assert eval_root(ROOT / "models" / model) == Path("out/eval") / model
    assert eval_root(tmp_path / "runs" / "mine") == tmp_path / "runs" / "mine" / "eval"


@pytest.mark.slow
def test_readme_eval_and_watch_commands_write_only_under_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    shipped = files(ROOT / "models")
    # README: roshan eval models/fly_collision --episodes 200 --seed 1 --json out/eval.json --gif out/episode.gif
    res = cli("eval", MODEL, "--episodes", 2, "--envs", 2, "--seed", 1, "--json", "out/eval.json", "--gif",
              "out/episode.gif", "--quiet", *SMALL)
    assert res.exit_code == 0, res.output
    (folder,) = (tmp_path / "out" / "eval" / "fly_simple").iterdir()
    assert folder.name.startswith("1-2-") and f"files: {Path('out/eval/fly_simple') / folder.name}" in res.output
    # README: roshan watch models/fly_simple --steps 200 --fps 20 --screenshot out/watch.png (here without a display)
    res = cli("watch", MODEL, "--steps", 3, "--screenshot", "out/watch.png", *SMALL)
    assert res.exit_code == 0, res.output
    assert "out/watch.gif" in res.output and "screenshot (its last frame): out/watch.png" in res.output
    written = files(tmp_path)
    assert {"out/eval.json", "out/episode.gif", "out/watch.gif", "out/watch.png"} <= written
    assert all(p.startswith("out/") for p in written), sorted(written)
    assert files(ROOT / "models") == shipped, "an evaluation wrote into the tracked models/ folder"
    assert not os.path.exists(ROOT / "watch.gif")
    # the screenshot is a whole frame: caption band, the map with the drones, the legend
    shot = np.asarray(Image.open(tmp_path / "out" / "watch.png").convert("RGB"))
    with Image.open(tmp_path / "out" / "watch.gif") as gif:
        gif.seek(gif.n_frames - 1)
        assert gif.size == (shot.shape[1], shot.shape[0])
    assert (shot[:6] == BAND_COLOUR).all(-1).mean() > 0.5
    for colour in drone_colours(2):
        assert (shot == colour).all(-1).sum() >= 20, f"drone colour {colour} missing from the screenshot"


@pytest.mark.parametrize("name", ["../../escape", "a/b", "..", ".", "/tmp/abs"])
def test_a_run_name_stays_inside_root(tmp_path, name):
    # issue 52: `roshan train configs/fly_simple.yaml --root R --name ../../escape` wrote a whole run outside R
    root = tmp_path / "deep" / "R"
    res = cli("train", ROOT / "configs" / "fly_simple.yaml", "--root", root, "--name", name, "--set",
              "train.max_updates=1")
    assert res.exit_code == 1 and f"--name {name!r} must be one folder name inside {root}" in res.output
    assert not (tmp_path / "deep").exists() and not (tmp_path / "escape").exists()


def test_a_study_name_stays_inside_root(tmp_path):
    with pytest.raises(OutputError, match=r"--name '\.\./x' must be one folder name inside"):
        study_dir(tmp_path, "../x")
    assert study_dir(tmp_path, "fly-ppo") == tmp_path / "fly-ppo"


def test_init_from_weights_that_do_not_fit_leave_no_run_folder(tmp_path):
    # issue 52: train.init_from refused for a battery mismatch still left an empty run folder
    res = cli("train", ROOT / "configs" / "planner.yaml", "--root", tmp_path / "R", "--name", "x", "--set",
              f"train.init_from={ROOT / 'models' / 'planner_endurance'}")
    assert res.exit_code == 1 and "drones.energy.enabled = False here but True in the checkpoint" in res.output
    assert not (tmp_path / "R").exists()
    res = cli("train", ROOT / "configs" / "fly_simple.yaml", "--root", tmp_path / "R", "--set", "ppo.horizon=40",
              "--set", "sim.envs=4")  # a rollout that does not split over the envs: refused before the folder too
    assert res.exit_code == 1 and "ppo.horizon = 40 must be a positive multiple" in res.output
    assert not (tmp_path / "R").exists()
