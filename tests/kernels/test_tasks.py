"""The shared goal rules (roshan.kernels.tasks): one nearest-free-cell search over the two candidate sets, with
each set's order deciding ties and its own notion of a live reservation."""

import numpy as np
import pytest
import taichi as ti

from roshan.config import DroneConfig, IgnitionConfig
from roshan.kernels import tasks
from roshan.kernels.drones import DroneSim
from roshan.kernels.explore import ExploreMaps
from roshan.kernels.fire import FireSim
from roshan.maps import load_map

START = (10, 10)
A = (10, 12)  # both 2 cells from START: a tie, A first in row-major order
B = (12, 10)


@ti.data_oriented
class Search:
    """Every drone of env 0, in index order, takes the nearest free cell of ``candidates``."""

    def __init__(self, drones, candidates):
        self.drones, self.candidates = drones, candidates

    @ti.kernel
    def run(self):
        for e in range(1):
            for d in range(self.drones.num_drones):
                tasks.take_cell(self.drones, e, d, tasks.nearest_free_cell(self.drones, self.candidates, e, d))


@pytest.fixture(scope="module")
def world():
    fire = FireSim(load_map("35x36_Woods"), ignition=IgnitionConfig(fire_percentage=0.0), num_envs=1, seed=0)
    drones = DroneSim(fire, DroneConfig(num_drones=2))
    maps = ExploreMaps(fire, drones, 2, 10)
    return fire, drones, maps, Search(drones, tasks.BurningCells(fire)), Search(drones, tasks.KnownFires(fire, maps))


def setup(world, lit_in_order, put_out=()):
    """Drones at START; ``lit_in_order`` ignited one after another, seen by the drones, then ``put_out`` flooded."""
    fire, drones, maps, *_ = world
    fire.reset()
    drones.reset()
    maps.reset()
    for cell in lit_in_order:
        mask = np.zeros((1, fire.num_cells), np.int32)
        mask[0, cell[0] * fire.cols + cell[1]] = 1
        fire.ignite_cells(mask)
    pos = np.full((1, 2, 2), (START[0] + 0.5) * drones.cell, np.float32)
    drones.set_state(pos, np.zeros_like(pos))
    maps.observe_kernel(drones)
    if put_out:
        req = np.array([[i * fire.cols + j for i, j in put_out]], np.int32)
        fire.flood(req, np.zeros_like(req))
    drones.set_goals(np.zeros((1, 2, 2), np.float32))  # clears every reservation


def goal_cells(world):
    fire, drones = world[0], world[1]
    return [(c // fire.cols, c % fire.cols) if c >= 0 else None for c in drones.goal_cell.to_numpy()[0].tolist()]


def test_burning_cells_break_ties_in_burning_list_order(world):
    setup(world, [B, A])
    world[3].run()
    assert goal_cells(world) == [B, A]


def test_known_fires_break_ties_in_row_major_order(world):
    setup(world, [B, A])
    world[4].run()
    assert goal_cells(world) == [A, B]


def test_a_held_burning_cell_is_taken_and_the_next_drone_goes_home(world):
    for search in (3, 4):
        setup(world, [A])
        world[search].run()
        assert goal_cells(world) == [A, None]
        gs = world[1].bases.to_numpy()[:, 0][0] + 0.5
        np.testing.assert_allclose(world[1].goal.to_numpy()[0, 1], gs)


def test_a_known_fire_that_went_out_holds_no_reservation(world):
    # The map still lists A after the flood: both drones may take it; the burning list no longer has it.
    setup(world, [A], put_out=[A])
    world[4].run()
    assert goal_cells(world) == [A, A]
    setup(world, [A], put_out=[A])
    world[3].run()
    assert goal_cells(world) == [None, None]
