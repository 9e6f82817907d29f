"""What the progress bar, train --help and maps crop say (issue 32, item 17): whole episodes without a terminal,
the planner named in train's help, and a bundled map's name taken by maps crop as by every other command."""

import re

import numpy as np
import pytest
from click.testing import CliRunner

from roshan.cli import main
from roshan.config import Config, DroneConfig, IgnitionConfig, MapConfig


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.mark.slow
def test_the_progress_bar_counts_whole_episodes_without_a_terminal(capsys):
    from roshan.env.fly import FlyVectorEnv
    from roshan.runs.baselines import baseline_fn
    from roshan.runs.evaluate import run_episodes

    cfg = Config(map=MapConfig(name="15x15_Woods"), ignition=IgnitionConfig(fire_percentage=0.05),
                 drones=DroneConfig(num_drones=2))
    env = FlyVectorEnv(num_envs=2, config=cfg, seed=4)
    run_episodes(env, baseline_fn("greedy", 2, 2, 4), 4, 4, progress_bar=True)
    env.close()
    err = capsys.readouterr().err
    counts = re.findall(r"([\d.]+)/4 episodes", err)
    assert counts and counts[-1] == "4", err
    assert all("." not in c for c in counts), f"fractional episodes without a terminal: {counts}"


def test_train_help_names_the_planner():
    out = cli("train", "--help").output
    assert "planner" in out and "train.algo" in out


def test_maps_crop_takes_a_bundled_name(tmp_path):
    from roshan.maps import load_map

    src = load_map("35x36_Woods")
    a, _, c, _, e, f = src.transform
    bounds = (c + 5 * a, f + 15 * e, c + 15 * a, f + 5 * e)  # rows 5..15, columns 5..15
    out = tmp_path / "crop.tif"
    r = cli("maps", "crop", "35x36_Woods", "--bounds", *bounds, "-o", out)
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(load_map(out).classes, src.classes[5:15, 5:15])
    r = CliRunner().invoke(main, ["maps", "crop", "35x36_Wods", "--bounds", *map(str, bounds), "-o", str(out)])
    assert r.exit_code == 1 and "did you mean '35x36_Woods'" in r.output
