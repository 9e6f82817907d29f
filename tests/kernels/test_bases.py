"""Several bases (``drones.bases``, docs/model/agents.md §4.1): their placement, the nearest base a drone heads home
to, and a restock (tank and battery) at a base other than the first."""

import numpy as np
import pytest
import taichi as ti

from roshan.config import ConfigError, DroneConfig, EnergyConfig, IgnitionConfig
from roshan.config.schema import from_dict
from roshan.kernels.drones import DroneSim
from roshan.kernels.fire import FireSim
from roshan.kernels.render import GROUNDSTATION_COLOUR, DroneOverlay, FrameRenderer
from roshan.maps import MapError, check_drone_map, load_map, uniform_map

CORNERS = {(1, 1), (1, 34), (33, 1), (33, 34)}  # one cell inside the corners of 35x36_Woods
OPPOSITE = {(1, 1): (33, 34), (1, 34): (33, 1), (33, 1): (1, 34), (33, 34): (1, 1)}
AWAY = (150.0, 150.0)  # metres: the middle of the map, far from every base


def make(bases=1, envs=1, seed=0, **kw):
    fire = FireSim(load_map("35x36_Woods"), ignition=IgnitionConfig(fire_percentage=0.0), num_envs=envs, seed=seed)
    fire.reset()
    drones = DroneSim(fire, DroneConfig(num_drones=1, use_vel_bins=False, bases=bases, **kw))
    drones.reset()
    return drones


def put(drones, pos):
    drones.set_state(np.array([[pos]], np.float32), np.zeros((1, 1, 2), np.float32))


def fly_still(drones, steps):
    for _ in range(steps):
        drones.move(np.zeros((1, 1, 2), np.float32))


def centre_m(drones, b):
    return tuple((drones.bases.to_numpy()[0, b] + 0.5) * drones.cell)


@ti.kernel
def energy_home(drones: ti.template()) -> ti.f32:
    return drones.battery.energy_home(0, 0)


def test_the_key_is_an_int_from_1_to_4():
    assert DroneConfig().bases == 1
    for bad in (0, 5, -1):
        with pytest.raises(ConfigError, match="bases"):
            from_dict(DroneConfig, {"bases": bad})


@pytest.mark.parametrize("count", [1, 2, 4])
def test_bases_sit_in_distinct_corners_the_first_where_one_base_would(count):
    one = make(bases=1, envs=16, seed=5).bases.to_numpy()[:, 0]
    bases = make(bases=count, envs=16, seed=5).bases.to_numpy()
    assert bases.shape == (16, count, 2)
    np.testing.assert_array_equal(bases[:, 0], one)  # the same draws: one base is where it always was
    for env in bases:
        cells = set(map(tuple, env))
        assert len(cells) == count and cells <= CORNERS  # distinct, each one cell inside a corner of the map
        if count > 1:
            assert tuple(env[1]) == OPPOSITE[tuple(env[0])]  # the second base: the first's opposite corner


def test_the_drones_start_at_the_first_base_and_call_it_home():
    d = make(bases=4, envs=8, seed=2)
    cells = d.bases.to_numpy()[:, 0]
    np.testing.assert_array_equal(np.floor(d.pos.to_numpy()[:, 0] / d.cell).astype(int), cells)
    assert np.all(d.home.to_numpy() == 0)


def test_a_drone_with_no_fire_heads_for_its_nearest_base():
    d = make(bases=4)
    for b in range(4):
        x = np.array(centre_m(d, b))
        put(d, tuple(x + (np.array(AWAY) - x) * 0.3))  # a third of the way from base b to the middle
        d.assign_fire_goals()  # no burning cell: each drone is sent home
        assert d.home.to_numpy()[0, 0] == b
        np.testing.assert_allclose(d.goal.to_numpy()[0, 0], d.bases.to_numpy()[0, b] + 0.5)


def test_the_tank_refills_at_a_second_base():
    d = make(bases=2, use_water_limit=True)
    d.set_water(np.zeros((1, 1), np.float32))
    put(d, AWAY)
    fly_still(d, 5)
    assert d.water.to_numpy()[0, 0] == 0.0
    put(d, centre_m(d, 1))
    fly_still(d, 30)
    assert d.water.to_numpy()[0, 0] == d.capacity


def test_the_battery_is_swapped_at_a_second_base_and_the_way_home_is_to_the_nearest():
    d = make(bases=2, energy=EnergyConfig(preset="scenario", swap_time=2.0))
    b = d.battery
    put(d, AWAY)
    fly_still(d, 10)
    left = float(b.charge.to_numpy()[0, 0])
    assert left < 15000.0
    put(d, centre_m(d, 1))
    fly_still(d, 20)
    assert float(b.charge.to_numpy()[0, 0]) == 15000.0 and int(b.swaps.to_numpy()[0, 0]) == 1
    one = make(bases=1, energy=EnergyConfig(preset="scenario"))

    def near(drones, b):  # 30 m from base b on both axes, towards the middle of the map
        c = np.array(centre_m(drones, b))
        return tuple(c + 30.0 * np.sign(np.array(AWAY) - c))

    put(one, near(one, 0))
    near_one = energy_home(one)
    put(d, near(d, 1))
    assert energy_home(d) == pytest.approx(near_one, rel=1e-6)  # home to the second base, the nearer
    put(one, near(d, 1))  # the same place, where the only base is the far one
    assert energy_home(one) > 5.0 * near_one


def test_several_bases_need_a_map_of_4_x_4_cells():
    fire = FireSim(uniform_map(3, 5), ignition=IgnitionConfig(fire_percentage=0.0))
    with pytest.raises(ValueError, match="drones.bases = 2"):
        DroneSim(fire, DroneConfig(num_drones=1, bases=2))
    DroneSim(fire, DroneConfig(num_drones=1, bases=1))
    with pytest.raises(MapError, match="drones.bases = 2"):  # the envs' check, before any simulator is built
        check_drone_map(uniform_map(3, 5), 0.0, False, "a test", bases=2)
    check_drone_map(uniform_map(3, 5), 0.0, False, "a test", bases=1)
    check_drone_map(uniform_map(4, 4), 0.0, False, "a test", bases=4)


def test_the_frames_outline_every_base():
    d = make(bases=4)
    frame = FrameRenderer(d.fire, env=0, cell_px=10, particles=False, backend="raster", wind_arrow=False).render(
        overlay=DroneOverlay(d, 0))
    white = np.all(frame == GROUNDSTATION_COLOUR, axis=-1)  # the bases' outlines, nothing else is white
    cells = np.zeros_like(white)
    for i, j in d.bases.to_numpy()[0]:
        assert white[i * 10, j * 10 + 5] and white[i * 10 + 9, j * 10 + 5], (i, j)  # its top and bottom edges
        cells[i * 10:(i + 1) * 10, j * 10:(j + 1) * 10] = True
    assert not np.any(white & ~cells)


@pytest.mark.parametrize("count, far_cells", [(1, np.hypot(33, 34)),  # base (1,1) centre to cell (34,35)'s
                                              (2, np.hypot(33, 1)),  # bases (1,1), (33,34): cell (34,0)'s
                                              (4, np.hypot(16, 16))])  # the four corners: cell (17,17)'s
def test_the_farthest_cell_is_measured_to_its_nearest_base(count, far_cells):
    """What the battery's range note compares with (35 x 36 cells of 10 m, bases one cell inside corners; the
    distances from the cell centres worked out by hand, equal for every first corner by the map's symmetry)."""
    assert make(bases=count, envs=8, seed=3).farthest_from_bases() == pytest.approx(10.0 * far_cells)


def test_base_cells_place_the_bases_in_every_env_and_the_drones_start_at_the_first():
    d = make(bases=3, envs=4, seed=1, base_cells="10,20; 30,5;2,33")
    np.testing.assert_array_equal(d.bases.to_numpy(), np.tile([[10, 20], [30, 5], [2, 33]], (4, 1, 1)))
    np.testing.assert_array_equal(np.floor(d.pos.to_numpy()[:, 0] / d.cell).astype(int), [[10, 20]] * 4)
    put(d, (5.0 * d.cell, 30.0 * d.cell))  # nearest to the third base
    d.assign_fire_goals()
    assert d.home.to_numpy()[0, 0] == 2


@pytest.mark.parametrize("settings, words", [
    ({"base_cells": "1,2; 3,4"}, "lists 2 cell(s) ('1,2; 3,4') but drones.bases = 1: set drones.bases = 2"),
    ({"base_cells": "1;2", "bases": 2}, "expected cells as 'row,col; row,col' (whole numbers), got '1'"),
    ({"base_cells": "1,2.5"}, "got '1,2.5'"),
    ({"base_cells": "-1,2"}, "cell '-1,2' has a negative index"),
    ({"base_cells": "1,2;1,2", "bases": 2}, "names a cell twice")])
def test_malformed_base_cells_are_refused_by_name(settings, words):
    with pytest.raises(ConfigError, match="drones.base_cells") as caught:
        from_dict(DroneConfig, settings)
    assert words in str(caught.value)


def test_base_cells_outside_the_map_are_refused_with_its_size():
    with pytest.raises(ValueError, match=r"drones.base_cells = '1,1; 35,2': cell\(s\) \[\(35, 2\)\] lie outside "
                                         r"the map of 35 x 36 cells \(rows 0-34, columns 0-35\)"):
        make(bases=2, base_cells="1,1; 35,2")


def test_maps_show_prints_where_the_bases_go_as_the_kernels_put_them():
    """`roshan maps show MAP --bases N` lists the corner rule's placements for each first corner: the kernels'
    placements over many envs are exactly those rows, and the farthest distance is the kernels' figure."""
    from click.testing import CliRunner

    from roshan.cli import main
    from roshan.kernels.drones import corner_bases

    d = make(bases=3, envs=32, seed=4)
    placed = {tuple(map(tuple, env)) for env in d.bases.to_numpy()}
    assert placed == set(corner_bases(35, 36, 3))  # 32 envs draw each of the four first corners
    out = CliRunner().invoke(main, ["maps", "show", "35x36_Woods", "--bases", "3"])
    assert out.exit_code == 0, out.output
    for placement in corner_bases(35, 36, 3):
        assert "  " + ", ".join(f"({r}, {c})" for r, c in placement) + "\n" in out.output
    assert f"Farthest:   {d.farthest_from_bases():.0f} m from a cell to its nearest base" in out.output
    given = CliRunner().invoke(main, ["maps", "show", "35x36_Woods", "--base-cells", "10,20; 30,5"])
    assert given.exit_code == 0 and "  (10, 20), (30, 5)\n" in given.output
    outside = CliRunner().invoke(main, ["maps", "show", "35x36_Woods", "--base-cells", "10,20; 40,5"])
    assert outside.exit_code == 1 and "cell(s) [(40, 5)] lie outside 35x36_Woods (35 x 36 cells" in outside.output
    assert "Map:" not in outside.output  # refused before anything is printed
