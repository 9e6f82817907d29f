"""Degenerate maps (issue 32, item 7): a map too small for drones, or one where no fire can start, is refused with
an error naming the map and why; an episode in which no fire was ever lit never counts as a success.

Before, a 1 x 1 map or a map of water reported "success rate 100.0 %" with drones and with the planner, 0 cells
ever lit, and no warning.
"""

from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from roshan.cli import main
from roshan.config import Config, DroneConfig, FlyConfig, IgnitionConfig, MapConfig, PlannerConfig, WindConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.maps import MapError
from tests.test_maps import write_tif

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
COMPLEX = FlyConfig(policy="complex")
NO_FIRE = IgnitionConfig(fire_percentage=0.0)


def uniform(rows: int, cols: int, **sections) -> Config:
    return Config(map=MapConfig(name="uniform", uniform_rows=rows, uniform_cols=cols), **sections)


def planner_config() -> PlannerConfig:
    return PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2)


@pytest.fixture
def lake(tmp_path) -> str:
    """A 20 x 20 GeoTIFF of water only (CLC+ class 10): nothing can burn."""
    return str(write_tif(tmp_path / "lake.tif", np.full((20, 20), 10, np.uint8)))


@pytest.mark.parametrize("fly", [FlyConfig(), COMPLEX])
def test_a_map_smaller_than_3x3_is_refused_for_every_drone_env(fly):
    with pytest.raises(MapError, match=r"^map 'uniform' \(1 x 1 cells\) is too small for FlyVectorEnv "
                                       rf"\({fly.policy} policy\): the groundstation sits one cell inside a corner"):
        FlyVectorEnv(1, uniform(1, 1), fly)
    with pytest.raises(MapError, match=r"\(2 x 40 cells\) is too small .* at least 3 x 3 cells"):
        FlyVectorEnv(1, uniform(2, 40), fly)


def test_a_map_where_nothing_burns_is_refused_for_firefighting(lake):
    with pytest.raises(MapError, match=r"^map 'lake' \(20 x 20 cells\) has no cell that can burn \(its cells: "
                                       r"Water \(400\)\): FlyVectorEnv \(complex policy\) would have no fire"):
        FlyVectorEnv(1, Config(map=MapConfig(name=lake)), COMPLEX)
    with pytest.raises(MapError, match=r"no cell that can burn .*PlannerVectorEnv \(greedy\) would have no fire"):
        PlannerVectorEnv(1, Config(map=MapConfig(name=lake)), planner_config(), controller="greedy")


def test_a_map_too_small_for_the_fire_percentage_is_refused_for_firefighting():
    # 64 cells x 1.5 % = 0.96: the generator lights no fire
    with pytest.raises(MapError, match=r"^map 'uniform' \(8 x 8 cells\) is too small for ignition.fire_percentage "
                                       r"= 0.015: 64 cells x 0.015 lights no fire, so FlyVectorEnv \(complex policy\) "
                                       r"would have nothing to put out; use a map of at least 67 cells or "
                                       r"ignition.fire_percentage >= 0.0157"):
        FlyVectorEnv(1, uniform(8, 8), COMPLEX)
    with pytest.raises(MapError, match=r"PlannerVectorEnv \(planner\) would have nothing to put out"):
        PlannerVectorEnv(1, uniform(8, 8), planner_config())


def test_simulate_with_drones_refuses_a_1x1_map_with_one_line():
    r = CliRunner().invoke(main, ["simulate", "--map", "uniform", "--set", "map.uniform_rows=1", "--set",
                                  "map.uniform_cols=1", "--drones", "2", "--steps", "10", "--quiet"])
    assert r.exit_code == 1, r.output
    assert r.output.strip().splitlines()[-1].startswith("Error: map 'uniform' (1 x 1 cells) is too small for "
                                                        "FlyVectorEnv (complex policy)")
    assert "success rate" not in r.output


@pytest.mark.slow
def test_a_firefighting_episode_without_any_fire_never_succeeds():
    cfg = Config(ignition=NO_FIRE, drones=DroneConfig(num_drones=1), wind=WindConfig(speed=0.0))
    with pytest.warns(UserWarning, match=r"ignition.fire_percentage = 0 lights no fire at a reset"):
        env = FlyVectorEnv(1, cfg, COMPLEX)
    env.reset(seed=0)
    for _ in range(20):  # the drone hovers at the groundstation: only a success could end the episode
        _, _, term, trunc, info = env.step(np.zeros((1, 1, 2), np.float32))
        assert not bool(term[0] | trunc[0]), "an episode with no fire lit ended (as a success)"
    env.close()


@pytest.mark.slow
def test_a_planner_episode_without_any_fire_never_succeeds():
    cfg = Config(ignition=NO_FIRE, drones=DroneConfig(num_drones=2), wind=WindConfig(speed=0.0))
    with pytest.warns(UserWarning, match=r"PlannerVectorEnv \(greedy\): ignition.fire_percentage = 0"):
        env = PlannerVectorEnv(1, cfg, planner_config(), evaluation=True, controller="greedy")
    env.reset(seed=0)
    for _ in range(5):
        _, _, term, trunc, _ = env.step(torch.zeros(1, 2, dtype=torch.long))
        assert not bool(term[0] | trunc[0]), "a planner episode with no fire lit ended (as a success)"
    env.close()


@pytest.mark.slow
def test_the_simple_flyagent_needs_no_fire():
    # its objective is a goal (a fire or a corner): a small map without fires stays valid
    env = FlyVectorEnv(1, uniform(8, 8, drones=DroneConfig(num_drones=1)))
    env.close()


def test_more_explorers_than_a_map_side_names_the_map_and_the_fix():
    # issue 52: a 3x3 map read "12 explorers on a map side of 3 cells", naming neither the map nor the fix
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=12)
    with pytest.raises(MapError, match=r"map 'uniform' \(3 x 3 cells\): planner.num_explorers = 12 explorers cannot "
                                       r"share its longer side of 3 cells .*set planner.num_explorers to at most 3"):
        PlannerVectorEnv(1, uniform(3, 3, ignition=IgnitionConfig(fire_percentage=0.5)), pc, evaluation=True,
                         controller="greedy", seed=0)
