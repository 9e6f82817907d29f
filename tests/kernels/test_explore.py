"""ExploreAgent meander, waypoint advancing and the fire map (docs/model/agents.md §11) against hand-worked values."""

import numpy as np
import pytest
import torch

from roshan.config import DroneConfig, IgnitionConfig
from roshan.kernels.drones import DroneSim
from roshan.kernels.explore import ExploreMaps, corner_cells, covered_cells, meander_paths
from roshan.kernels.fire import FireSim
from roshan.maps import load_map, uniform_map

NO_FIRE = IgnitionConfig(fire_percentage=0.0)


def make(land, envs=2, n=3, vr=20, seed=0, **kw):
    fire = FireSim(land, ignition=NO_FIRE, num_envs=envs, seed=seed)
    fire.reset()
    explorers = DroneSim(fire, DroneConfig(num_drones=n, view_range=vr, max_speed=20.0))
    explorers.reset()
    maps = ExploreMaps(fire, explorers, n, vr, **kw)
    maps.reset()
    return fire, explorers, maps


def place(drones, pos_cells):
    """Put drones at grid positions (E, N, 2) (converted to metres), at rest."""
    pos = np.asarray(pos_cells, np.float32).reshape(drones.num_envs, drones.num_drones, 2) * drones.cell
    drones.set_state(pos, np.zeros_like(pos))


def cell_mask(fire, cells_by_env):
    mask = np.zeros((fire.num_envs, fire.num_cells), np.int32)
    for e, cells in enumerate(cells_by_env):
        for i, j in cells:
            mask[e, i * fire.cols + j] = 1
    return mask


def flood(fire, cells_by_env):
    m = max(len(c) for c in cells_by_env)
    req = np.full((fire.num_envs, m), -1, np.int32)
    for e, cells in enumerate(cells_by_env):
        req[e, : len(cells)] = [i * fire.cols + j for i, j in cells]
    out = np.zeros_like(req)
    fire.flood(req, out)
    return out


# ---------------------------------------------------------------------------------------------- waypoints


def test_worked_example_of_the_spec():
    # 35x36, 3 explorers, vr 20, groundstation (1, 1): explorer 0 starts 4 m along the rows from the centre,
    # i.e. (19 m, 15 m); the reference compares metres with cells: x_inc = 19 < 17.5 false, y_inc = 15 < 18 true.
    # W < H: horizontal stripes of 12 columns; y_step = 12 // ceil(12/19) = 12; x_step = 35 // ceil(35/19) = 17.
    paths = meander_paths(35, 36, 3, (1.9, 1.5), 20, reference_quirk=True)
    assert [p.tolist() for p in paths] == [
        [[35, 0], [35, 12], [18, 12], [18, 0], [1, 0], [1, 12]],
        [[35, 12], [35, 24], [18, 24], [18, 12], [1, 12], [1, 24]],
        [[35, 24], [35, 36], [18, 36], [18, 24], [1, 24], [1, 36]],
    ]
    thesis = meander_paths(35, 36, 3, (1.9, 1.5), 20, reference_quirk=True, version="thesis")
    assert [p.tolist() for p in thesis] == [p.tolist() for p in paths]  # no edge points, no stripe remainder


def test_grid_comparison_sweeps_from_the_groundstation_side():
    near = meander_paths(35, 36, 3, (1.9, 1.5), 20)[0]
    assert near.tolist() == [[0, 0], [0, 12], [17, 12], [17, 0], [34, 0], [34, 12]]
    far = meander_paths(35, 36, 3, (33.9, 34.5), 20)[0]  # groundstation (33, 34): both directions reversed
    assert far.tolist() == [[35, 12], [35, 0], [18, 0], [18, 12], [1, 12], [1, 0]]


def test_edge_points_newest_versus_thesis():
    # W = 20 >= H = 7, 2 explorers, vr 5: sw = 10, x_step = 10 // ceil(10/4) = 3, y_step = 7 // ceil(7/4) = 3.
    # 10 % 3 != 0: forward rows end with (x1 - 1, y), backward rows with (x0, y) (thesis-era (x0, y - 1)).
    newest = meander_paths(20, 7, 2, (1.9, 1.5), 5)
    assert newest[0].tolist() == [[0, 0], [3, 0], [6, 0], [9, 0], [9, 0],
                                  [10, 3], [7, 3], [4, 3], [1, 3], [0, 3],
                                  [0, 6], [3, 6], [6, 6], [9, 6], [9, 6]]
    assert newest[1][:10].tolist() == [[10, 0], [13, 0], [16, 0], [19, 0], [19, 0],
                                       [20, 3], [17, 3], [14, 3], [11, 3], [10, 3]]
    thesis = meander_paths(20, 7, 2, (1.9, 1.5), 5, version="thesis")
    assert thesis[0][9].tolist() == [0, 2] and thesis[1][9].tolist() == [10, 2]
    assert np.delete(thesis[0], 9, axis=0).tolist() == np.delete(newest[0], 9, axis=0).tolist()


def test_last_stripe_extends_to_the_edge_only_in_the_newest_code():
    # W = 23, 2 explorers, vr 5: sw = 11, x_step = 11 // ceil(11/4) = 3. Newest: stripe 1 is [11, 23]
    # (12 % 3 == 0, no edge point); thesis-era: [11, 22] with edge point 21.
    newest = meander_paths(23, 7, 2, (1.9, 1.5), 5)[1]
    thesis = meander_paths(23, 7, 2, (1.9, 1.5), 5, version="thesis")[1]
    assert newest[:5].tolist() == [[11, 0], [14, 0], [17, 0], [20, 0], [23, 0]]
    assert thesis[:5].tolist() == [[11, 0], [14, 0], [17, 0], [20, 0], [21, 0]]


def test_covered_cells_marks_view_squares_around_integer_cells():
    one = covered_cells([np.array([[5, 5]])], 12, 12, 4)  # half width 2
    want = np.zeros((12, 12), bool)
    want[3:8, 3:8] = True
    np.testing.assert_array_equal(one, want)
    seg = covered_cells([np.array([[2, 2], [2, 8]])], 12, 12, 2)  # half width 1 along a segment
    want = np.zeros((12, 12), bool)
    want[1:4, 1:10] = True
    np.testing.assert_array_equal(seg, want)
    outside = covered_cells([np.array([[-1.5, 5.0]])], 12, 12, 3)  # cell (-2, 5), half width 1: nothing
    assert not outside.any()
    edge = covered_cells([np.array([[-1, 5]])], 12, 12, 3)  # cell (-1, 5): row 0, columns 4..6
    assert np.argwhere(edge).tolist() == [[0, 4], [0, 5], [0, 6]]


@pytest.mark.parametrize("rows, cols", [(35, 36), (21, 21), (81, 129), (10, 50)])
@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_meander_covers_every_cell(rows, cols, n):
    for vr in range(2, 21):
        for start in [(1.9, 1.5), (rows - 1.5, cols - 1.5)]:
            for quirk in (False, True):
                paths = meander_paths(rows, cols, n, start, vr, reference_quirk=quirk)
                seen = covered_cells(paths, rows, cols, vr)
                assert seen.all(), f"{rows}x{cols} n={n} vr={vr} start={start}: {(~seen).sum()} cells unseen"


def test_reference_index_bound_skips_the_wider_last_stripe():
    # 21x21, 2 explorers, vr 6: explorer 1's stripe is 11 wide, explorer 0's 10, so its path is longer; the
    # reference bounds the shared index by explorer 0's length and never flies explorer 1's last 6 waypoints.
    paths = meander_paths(21, 21, 2, (1.9, 1.5), 6)
    assert [len(p) for p in paths] == [18, 24]
    assert covered_cells(paths, 21, 21, 6).all()
    assert (~covered_cells([p[:18] for p in paths], 21, 21, 6)).sum() == 15


# ---------------------------------------------------------------------------------------------- advancing


def fly_to_goals_and_advance(explorers, maps, steps):
    """Teleport every explorer onto its goal, advance, and record the assigned waypoint index per env."""
    seq = []
    for _ in range(steps):
        place(explorers, explorers.goal.to_numpy())
        maps.advance_kernel()
        seq.append(maps.assigned.to_numpy().copy())
    return np.stack(seq, axis=1)  # (E, steps)


def expected_goals(explorers, maps, index):
    gs = explorers.bases.to_numpy()[:, 0]
    corners = [corner_cells(maps.rows, maps.cols).index(tuple(g)) for g in gs]
    goals = [[p[min(k, len(p) - 1)] for p in maps.paths[c]] for c, k in zip(corners, index, strict=True)]
    return np.asarray(goals, np.float32)


def test_reset_assigns_waypoint_zero_of_the_groundstation_corner():
    fire, explorers, maps = make(load_map("35x36_Woods"), envs=16, seed=5)
    gs = explorers.bases.to_numpy()[:, 0]
    assert len(set(map(tuple, gs))) > 1
    corners = maps.corner.to_numpy()
    for e in range(16):
        assert corner_cells(35, 36)[corners[e]] == tuple(gs[e])
    np.testing.assert_array_equal(explorers.goal.to_numpy(), expected_goals(explorers, maps, np.zeros(16, int)))
    assert maps.wp_index.to_numpy().tolist() == [1] * 16 and maps.assigned.to_numpy().tolist() == [0] * 16
    # groundstation (1, 1) sweeps from row 0; (33, 34) from row 35 (the grid-unit comparison)
    assert maps.paths[0][0][0].tolist() == [0, 0] and maps.paths[3][0][0].tolist() == [35, 12]


def test_ping_pong_index_sequence_and_the_quarter_cell_tolerance():
    fire, explorers, maps = make(load_map("35x36_Woods"), envs=2)
    assert maps.lengths[:, 0].tolist() == [6, 6, 6, 6]
    seq = fly_to_goals_and_advance(explorers, maps, 15)
    want = [1, 2, 3, 4, 5, 5, 4, 3, 2, 1, 0, 0, 1, 2, 3]  # after the reset's 0
    assert seq.tolist() == [want, want]
    np.testing.assert_array_equal(explorers.goal.to_numpy(), expected_goals(explorers, maps, [3, 3]))
    # one explorer 0.3 cells off on one axis: nobody advances; 0.2 cells off: all advance
    goals = explorers.goal.to_numpy()
    off = goals.copy()
    off[:, 2, 1] += 0.3
    place(explorers, off)
    maps.advance_kernel()
    assert maps.assigned.to_numpy().tolist() == [3, 3] and maps.wp_index.to_numpy().tolist() == [4, 4]
    off[:, 2, 1] -= 0.1
    place(explorers, off)
    maps.advance_kernel()
    assert maps.assigned.to_numpy().tolist() == [4, 4]
    np.testing.assert_array_equal(explorers.goal.to_numpy(), expected_goals(explorers, maps, [4, 4]))


def test_cyclic_index_of_the_thesis_era_code():
    fire, explorers, maps = make(load_map("35x36_Woods"), envs=1, cyclic=True)
    seq = fly_to_goals_and_advance(explorers, maps, 8)
    assert seq.tolist() == [[1, 2, 3, 4, 5, 0, 1, 2]]


def test_longest_index_bound_flies_every_waypoint():
    fire, explorers, maps = make(load_map("21x21_Field"), envs=1, n=2, vr=6, index_bound="longest")
    assert maps.lengths.tolist() == [[18, 24]] * 4
    seq = fly_to_goals_and_advance(explorers, maps, 25)
    assert seq[0].tolist() == [*range(1, 24), 23, 22]
    corner = maps.corner.to_numpy()[0]
    place(explorers, explorers.goal.to_numpy())
    for _ in range(4):  # back down to 18 while explorer 0 still waits at its last waypoint
        maps.advance_kernel()
        place(explorers, explorers.goal.to_numpy())
    assert maps.assigned.to_numpy()[0] == 18
    np.testing.assert_array_equal(explorers.goal.to_numpy()[0], [maps.paths[corner][0][17], maps.paths[corner][1][18]])


# ---------------------------------------------------------------------------------------------- fire map


def test_fire_map_sees_fires_in_the_view_square_and_keeps_stale_values():
    fire, explorers, maps = make(uniform_map(30, 30), envs=2, n=1, vr=4)  # view half width 2
    block = [(i, j) for i in range(6, 17) for j in range(6, 19)]
    fire.ignite_cells(cell_mask(fire, [block, block]))
    place(explorers, [[[10.5, 12.5]], [[25.5, 25.5]]])  # env 0: cell (10, 12); env 1: far from the fire
    maps.observe_kernel()
    fm = maps.fire_map_tensor
    assert fm.dtype == torch.int8 and tuple(fm.shape) == (2, 30, 30)
    want = np.zeros((30, 30), np.int8)
    want[8:13, 10:15] = 1
    np.testing.assert_array_equal(fm[0].numpy(), want)
    assert not fm[1].any()
    assert maps.known_fires.to_numpy().tolist() == [25, 0]

    # put two seen fires out and look again: they turn 0
    assert flood(fire, [[(10, 12), (9, 11)], [(10, 12)]]).tolist() == [[1, 1], [1, 0]]
    maps.observe_kernel()
    want[10, 12] = want[9, 11] = 0
    np.testing.assert_array_equal(maps.fire_map_tensor[0].numpy(), want)
    assert maps.known_fires.to_numpy().tolist() == [23, 0]

    # fly away, put out a fire seen before: the map keeps the stale 1; new views add their cells
    flood(fire, [[(8, 10)], []])
    place(explorers, [[[15.0, 6.0]], [[25.5, 25.5]]])  # cell (15, 6): rows 13..17, cols 4..8
    maps.observe_kernel()
    want[13:17, 6:9] = 1
    fm = maps.fire_map_tensor[0].numpy()
    assert fm[8, 10] == 1, "a fire put out outside every view stays known"
    np.testing.assert_array_equal(fm, want)
    assert maps.known_fires.to_numpy()[0] == 23 + 12

    # reset clears only the masked env
    place(explorers, [[[2.5, 2.5]], [[10.5, 12.5]]])
    maps.observe_kernel()
    assert maps.known_fires.to_numpy()[1] == 24  # (10, 12) was flooded in env 1
    maps.reset(np.array([1, 0], np.int32))
    fm = maps.fire_map_tensor.numpy()
    assert not fm[0].any() and fm[1].sum() == 24
    assert maps.known_fires.to_numpy().tolist() == [0, 24]


def test_fire_map_square_is_clipped_at_the_map_edge():
    fire, explorers, maps = make(uniform_map(12, 12), envs=1, n=1, vr=5)  # half width 2
    fire.ignite_cells(cell_mask(fire, [[(0, 0), (2, 2), (3, 3), (0, 11)]]))
    place(explorers, [[[0.5, 0.5]]])
    maps.observe_kernel()
    assert np.argwhere(maps.fire_map_tensor[0].numpy()).tolist() == [[0, 0], [2, 2]]
    maps.reset()
    place(explorers, [[[-1.5, 12.2]]])  # cell (-2, 12), outside: sees row 0, columns 10..11
    maps.observe_kernel()
    assert np.argwhere(maps.fire_map_tensor[0].numpy()).tolist() == [[0, 11]]


def test_other_groups_observe_with_their_own_view_range():
    fire, explorers, maps = make(uniform_map(30, 30), envs=1, n=1, vr=4)
    planners = DroneSim(fire, DroneConfig(num_drones=2, view_range=10))  # half width 5
    planners.reset()
    fire.ignite_cells(cell_mask(fire, [[(15, 20), (15, 21), (21, 10)]]))
    pos = np.array([[[15.5, 15.5], [26.5, 2.5]]], np.float32) * 10.0  # cells (15, 15) and (26, 2)
    planners.set_state(pos, np.zeros_like(pos))
    maps.observe_kernel(planners)
    assert np.argwhere(maps.fire_map_tensor[0].numpy()).tolist() == [[15, 20]]  # (15, 21): 6 columns; (21, 10): 6 rows
    assert maps.known_fires.to_numpy()[0] == 1
