"""Drone physics against hand-computed steps (docs/model/agents.md §3-4)."""

import numpy as np
import pytest

from roshan.config import DroneConfig, IgnitionConfig
from roshan.kernels.drones import DroneSim
from roshan.kernels.fire import FireSim
from roshan.maps import load_map

DT = 0.1


def make(num_drones=4, envs=2, seed=0, **kw):
    fire = FireSim(load_map("35x36_Woods"), ignition=IgnitionConfig(fire_percentage=0.0), num_envs=envs, seed=seed)
    fire.reset()
    drones = DroneSim(fire, DroneConfig(num_drones=num_drones, **kw))
    drones.reset()
    return drones


def place(drones, pos, vel=None):
    pos = np.asarray(pos, np.float32).reshape(drones.num_envs, drones.num_drones, 2)
    vel = np.zeros_like(pos) if vel is None else np.asarray(vel, np.float32).reshape(pos.shape)
    drones.set_state(pos, vel)


def test_velocity_mode_with_bins_matches_a_hand_computed_step():
    d = make(num_drones=1, envs=1)
    place(d, [[100.0, 100.0]])
    # 0.5 stays 0.5; -0.26 / 0.05 = -5.2 -> -5 -> -0.25; 0.025 / 0.05 = 0.5 rounds away from zero -> 0.05
    d.move(np.array([[[0.5, -0.26]]], np.float32))
    np.testing.assert_allclose(d.vel.to_numpy()[0, 0], [5.0, -2.5], atol=1e-5)
    np.testing.assert_allclose(d.pos.to_numpy()[0, 0], [100.5, 99.75], atol=1e-4)
    d.move(np.array([[[0.025, -0.024]]], np.float32))
    np.testing.assert_allclose(d.vel.to_numpy()[0, 0], [0.5, 0.0], atol=1e-5)


def test_actions_are_clipped_to_the_unit_box():
    d = make(num_drones=1, envs=1, use_vel_bins=False)
    place(d, [[100.0, 100.0]])
    d.move(np.array([[[3.0, -0.123]]], np.float32))
    np.testing.assert_allclose(d.vel.to_numpy()[0, 0], [10.0, -1.23], atol=1e-5)


def test_acceleration_mode_integrates_and_clamps_each_axis():
    d = make(num_drones=1, envs=1, use_velocity_change=True, use_vel_bins=False)
    place(d, [[100.0, 100.0]], [[9.9, 0.0]])
    d.move(np.array([[[1.0, -0.4]]], np.float32))
    # v += a * (v_max / 2) * dt = (0.5, -0.2); x clamped to v_max = 10
    np.testing.assert_allclose(d.vel.to_numpy()[0, 0], [10.0, -0.2], atol=1e-5)
    np.testing.assert_allclose(d.pos.to_numpy()[0, 0], [101.0, 99.98], atol=1e-4)
    for _ in range(200):
        d.move(np.array([[[1.0, 1.0]]], np.float32))
    np.testing.assert_allclose(d.vel.to_numpy()[0, 0], [10.0, 10.0], atol=1e-5)  # diagonal speed sqrt(2) v_max


def test_boundary_counter_counts_consecutive_steps_outside():
    d = make(num_drones=1, envs=1, use_vel_bins=False)
    place(d, [[1.0, 50.0]])  # 1 m inside the northern edge
    up = np.array([[[-1.0, 0.0]]], np.float32)  # 1 m per step towards row 0
    d.move(up)  # x = 0.0: still inside
    assert d.out_count.to_numpy()[0, 0] == 0
    d.move(up)
    d.move(up)
    assert d.out_count.to_numpy()[0, 0] == 2  # outside twice in a row: terminal (> 1) for the env layer
    d.move(-up)
    d.move(-up)
    assert d.out_count.to_numpy()[0, 0] == 0


def test_groundstation_corner_and_ring_start():
    d = make(num_drones=4, envs=32, seed=3)
    gs = d.bases.to_numpy()[:, 0]
    assert set(map(tuple, gs)) <= {(1, 1), (1, 34), (33, 1), (33, 34)}
    assert len(set(map(tuple, gs))) > 1, "the corner is random per env"
    pos = d.pos.to_numpy()
    centre = (gs + 0.5) * 10.0
    radius = np.linalg.norm(pos - centre[:, None, :], axis=-1)
    np.testing.assert_allclose(radius, 4.0, atol=1e-4)  # R = min(4.5, max(4, 3.5))
    gaps = np.linalg.norm(pos[:, 0] - pos[:, 1], axis=-1)
    np.testing.assert_allclose(gaps, 4.0 * np.sqrt(2.0), atol=1e-4)  # 5.66 m > the 4 m collision distance
    assert d.collided.to_numpy().sum() == 0 and np.all(d.vel.to_numpy() == 0)


def test_neighbour_features_and_mask_on_a_constructed_layout():
    d = make(num_drones=3, envs=1)
    # grid units: drone 0 at (12, 14), drone 1 at (14, 11) (dx=2, dy=-3 -> visible: < 5), drone 2 at (12, 20)
    place(d, [[120.0, 140.0], [140.0, 110.0], [120.0, 200.0]], [[0, 0], [5.0, -10.0], [0, 0]])
    nb = d.neighbours.to_numpy()[0]
    mask = d.neighbour_mask.to_numpy()[0]
    assert mask[0].tolist() == [0, 1, 0]  # boundary far away; drone 1 visible; drone 2 at dy = 6 is not
    # (dx / vr, dy / vr, v / (v_max * s)) with vr = 10, s = 5
    np.testing.assert_allclose(nb[0, 1], [0.2, -0.3, 0.1, -0.2], atol=1e-6)
    np.testing.assert_allclose(nb[0, 2], [0, 0, 0, 0])
    assert mask[2].tolist() == [0, 0, 0]
    assert d.collided.to_numpy().sum() == 0


def test_boundary_entry_is_the_nearest_edge_scaled_by_half_the_view():
    d = make(num_drones=1, envs=1)
    place(d, [[330.0, 180.0]])  # grid (33, 18): row edge 35 is 2 away
    nb = d.neighbours.to_numpy()[0, 0, 0]
    assert d.neighbour_mask.to_numpy()[0, 0, 0] == 1
    np.testing.assert_allclose(nb, [2.0 / 5.0, 0.0, 0.0, 0.0], atol=1e-6)
    place(d, [[180.0, 170.0]])  # 17..18 cells from every edge: beyond h = 5
    assert d.neighbour_mask.to_numpy()[0, 0, 0] == 0


@pytest.mark.parametrize("gap_m, collides", [(3.9, True), (3.99, True), (4.01, False), (4.1, False)])
def test_collision_when_centres_are_within_two_drone_sizes(gap_m, collides):
    d = make(num_drones=2, envs=1)
    place(d, [[100.0, 100.0], [100.0 + gap_m * 0.6, 100.0 + gap_m * 0.8]])
    assert d.collided.to_numpy()[0].tolist() == ([1, 1] if collides else [0, 0])
    place(d, [[100.0, 100.0], [150.0, 100.0]])
    assert d.collided.to_numpy()[0].tolist() == ([1, 1] if collides else [0, 0]), "the flag is sticky"
    d.reset()
    assert d.collided.to_numpy().sum() == 0
