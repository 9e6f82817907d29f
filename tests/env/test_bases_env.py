"""Several bases in the planner level's greedy episodes (``drones.bases``): drones sent home head for a base and
restock there, and the episode runs on with every kernel compiled for two bases."""

from pathlib import Path

import numpy as np
import pytest
import torch

from roshan.config import Config, DroneConfig, EnergyConfig, IgnitionConfig, PlannerConfig, WindConfig
from roshan.env.planner import PlannerVectorEnv

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")


def test_greedy_drones_go_home_to_either_base():
    drones = DroneConfig(num_drones=3, bases=2, use_water_limit=True, water_capacity=2.0,
                         energy=EnergyConfig(preset="scenario", capacity=6000.0))
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05, clusters=2), drones=drones, wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, greedy_home="fixed")
    env = PlannerVectorEnv(2, cfg, pc, evaluation=True, controller="greedy", seed=3)
    env.reset(seed=3)
    dr = env.drones
    # drone 0 of each env: 3 cells from the second base towards the middle of the map, its tank empty
    pos, vel = dr.pos.to_numpy(), dr.vel.to_numpy()
    second = dr.bases.to_numpy()[:, 1] + 0.5
    middle = np.array([dr.rows, dr.cols]) / 2.0
    pos[:, 0] = (second + 3.0 * np.sign(middle - second)) * dr.cell
    vel[:, 0] = 0.0
    dr.set_state(pos, vel)
    water = dr.water.to_numpy()
    water[:, 0] = 0.0
    dr.set_water(water)
    homes, refilled = set(), np.zeros(2, bool)
    for _ in range(120):
        env.step(torch.zeros((2, 3), dtype=torch.long))
        home, going = dr.home.to_numpy(), dr.refilling.to_numpy() == 1
        centres = np.take_along_axis(dr.bases.to_numpy(), home[..., None], axis=1) + 0.5
        np.testing.assert_allclose(dr.goal.to_numpy()[going], centres[going])  # flying home: to its home base
        homes |= set(home[:, 0][going[:, 0]].tolist())  # drone 0's
        refilled |= dr.water.to_numpy()[:, 0] == drones.water_capacity
        if refilled.all():
            break
    assert homes == {1} and refilled.all()  # drone 0 went to the base nearest to it and restocked there
    env.close()


def planner_env(bases: int, **drones):
    cfg = Config(ignition=IgnitionConfig(fire_percentage=0.05, clusters=2),
                 drones=DroneConfig(num_drones=3, bases=bases, **drones), wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, train_fires="true")
    return PlannerVectorEnv(2, cfg, pc, seed=3)


def test_each_base_is_a_candidate_and_a_drone_sent_to_one_makes_it_its_home():
    env = planner_env(2)
    obs, _ = env.reset(seed=3)
    dr = env.drones
    norm = 2.0 / max(dr.rows, dr.cols)
    bases = dr.bases.to_numpy()  # (E, 2, 2)
    np.testing.assert_allclose(obs["fires"][:, :2].numpy(), (bases + 0.5) * norm - 1.0, rtol=0, atol=1e-6)
    assert (obs["fires_mask"][:, :2] == 1).all()
    count = env.kernels.cand_count.to_numpy()
    fires = count - 2  # the candidates after the two bases
    assert (fires > 0).all()
    np.testing.assert_allclose(obs["globals"][:, 0].numpy(), np.log1p(fires) / np.log1p(dr.rows * dr.cols),
                               rtol=1e-6)
    assert env.single_action_space.nvec[0] == dr.rows * dr.cols + 2  # every cell after the bases
    # drone 0 to base 1, drone 1 to a fire, drone 2 past the list: its nearest base
    actions = torch.tensor([[1, 2, int(count.max())]] * 2)
    cells = env.kernels.cand_cell.to_numpy()[:, 2]
    pos = dr.pos.to_numpy()[:, 2] / dr.cell  # where drone 2 turns home
    env.step(actions)
    home, goal_cell, goal = dr.home.to_numpy(), dr.goal_cell.to_numpy(), dr.goal.to_numpy()
    assert (home[:, 0] == 1).all()
    np.testing.assert_allclose(goal[:, 0], bases[:, 1] + 0.5)
    np.testing.assert_array_equal(goal_cell[:, 1], cells)
    nearest = np.linalg.norm(pos[:, None] - (bases + 0.5), axis=-1).argmin(-1)
    np.testing.assert_array_equal(home[:, 2], nearest)
    env.close()


def test_a_candidate_list_shorter_than_the_bases_is_refused():
    cfg = Config(drones=DroneConfig(num_drones=3, bases=3))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, max_candidates=2)
    with pytest.raises(ValueError, match=r"planner.max_candidates = 2 is fewer than the bases \(drones.bases = 3\)"):
        PlannerVectorEnv(1, cfg, pc, seed=0)
