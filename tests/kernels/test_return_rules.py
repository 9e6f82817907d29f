"""The battery's rules at the planner level (roshan/kernels/battery.py): the queue reserves in joules worked out by
hand, the return rule's threshold, its restock and the planner's send-home, their null objects, and the landing
rule's choice of action."""

import numpy as np
import pytest
import taichi as ti

from roshan.config import DroneConfig, EnergyConfig, IgnitionConfig
from roshan.kernels.battery import (
    EveryOtherTurn,
    LandAtBase,
    NoLanding,
    NoQueue,
    NoReturn,
    ReturnWhenLow,
    TurnsOfTheWaiting,
)
from roshan.kernels.drones import DroneSim
from roshan.kernels.fire import FireSim
from roshan.kernels.tasks import AWAY, HOME, RESTOCKED
from roshan.maps import load_map

# scenario battery: 15 kJ, P = 100 W + 0.25 |v|^2 + 20 W x fill, a 3 s swap; 10 m/s, dt = 0.1 s
FULL = 15000.0
TURN = 3.0 * (100.0 + 0.25 * 10.0**2 + 20.0)  # one drone's turn on the cell: 3 s at 145 W = 435 J
OFF_BASE = np.array([80.0, 60.0])  # metres from the groundstation's centre, towards the map's middle (inward)
HOME_JOULES = 8.0 * (100.0 + 0.25 * 156.25 + 20.0)  # 80 m at 10 m/s beside 60 m at 7.5 m/s: 1272.5 J


@ti.data_oriented
class Probe:
    """Kernels that ask one rule about drone ``d`` of env 0."""

    def __init__(self, rule):
        self.rule = rule

    @ti.kernel
    def reserve(self, d: ti.i32) -> ti.f32:
        return self.rule.reserve(0, d)

    @ti.kernel
    def watch(self, d: ti.i32) -> ti.i32:
        return self.rule.watch(0, d)

    @ti.kernel
    def keeps_goal(self, d: ti.i32) -> ti.i32:
        return self.rule.keeps_goal(0, d)

    @ti.kernel
    def send_home(self, d: ti.i32):
        self.rule.send_home(0, d)

    @ti.kernel
    def action(self, d: ti.i32, a0: ti.f32, a1: ti.f32, out: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        a = self.rule.action(0, d, ti.Vector([a0, a1]))
        out[0] = a[0]
        out[1] = a[1]


@pytest.fixture(scope="module")
def fire():
    sim = FireSim(load_map("35x36_Woods"), ignition=IgnitionConfig(fire_percentage=0.0), num_envs=1, seed=0)
    sim.reset()
    return sim


def drones(fire, n=4, water=False, **energy):
    d = DroneSim(fire, DroneConfig(num_drones=n, use_vel_bins=False, use_water_limit=water,
                                   energy=EnergyConfig(preset="scenario", **energy)), lands=True)
    d.reset()
    return d


def base_centre(d) -> np.ndarray:
    return (d.bases.to_numpy()[:, 0][0] + 0.5) * d.cell


def place(d, offsets):
    """Drones at the groundstation's centre plus ``offsets`` (metres, one row per drone), at rest."""
    pos = base_centre(d) + np.asarray(offsets, np.float32)
    d.set_state(pos[None].astype(np.float32), np.zeros((1, len(offsets), 2), np.float32))


def inward(d) -> np.ndarray:
    """The sign of the way from the groundstation's corner towards the map's middle, per axis."""
    return np.sign(np.array([d.rows, d.cols]) / 2 * d.cell - base_centre(d))


def set_field(field, values, dtype):
    field.from_numpy(np.array([values], dtype))


def test_the_queue_reserves_in_joules(fire):
    """all: every other drone's turn, 3 x 435 J with 4 drones; waiting: a turn for each other drone flying home or
    waiting there now and not lost; none: nothing."""
    d = drones(fire)
    set_field(d.refilling, [0, 1, 1, 1], np.int32)
    set_field(d.battery.lost, [0, 0, 0, 1], np.int32)  # drone 3 came down on its way home: no turn of its own
    every, waiting, none = Probe(EveryOtherTurn(d)), Probe(TurnsOfTheWaiting(d)), Probe(NoQueue(d))
    assert every.reserve(0) == pytest.approx(3 * TURN) and every.reserve(3) == pytest.approx(3 * TURN)
    assert waiting.reserve(0) == pytest.approx(2 * TURN)  # drones 1 and 2
    assert waiting.reserve(1) == pytest.approx(TURN)  # drone 2: not itself, not the lost drone 3
    assert waiting.reserve(3) == pytest.approx(2 * TURN)
    set_field(d.refilling, [0, 0, 0, 0], np.int32)
    assert waiting.reserve(0) == 0.0 and none.reserve(0) == 0.0


@pytest.mark.parametrize("queue, reserve", [("none", 0.0), ("all", 3 * TURN)])
def test_a_drone_turns_home_once_its_battery_holds_its_flight_home_with_the_margin_and_the_queue(fire, queue,
                                                                                                 reserve):
    d = drones(fire)
    far = inward(d) * OFF_BASE
    place(d, [far, far + inward(d) * 20.0, far + inward(d) * 40.0, far + inward(d) * 60.0])
    set_field(d.goal_cell, [17, 18, 19, 20], np.int32)
    rule = Probe(ReturnWhenLow(d, 0.25, queue))
    need = 1.25 * HOME_JOULES + reserve
    set_field(d.battery.charge, [need + 2.0, FULL, FULL, FULL], np.float32)
    assert rule.watch(0) == AWAY and d.refilling.to_numpy()[0, 0] == 0 and d.goal_cell.to_numpy()[0, 0] == 17
    set_field(d.battery.charge, [need - 2.0, FULL, FULL, FULL], np.float32)
    assert rule.watch(0) == HOME
    assert d.refilling.to_numpy()[0, 0] == 1 and d.goal_cell.to_numpy()[0, 0] == -1  # its fire is free for others
    np.testing.assert_allclose(d.goal.to_numpy()[0, 0], d.bases.to_numpy()[:, 0][0] + 0.5)
    assert rule.watch(0) == HOME and rule.keeps_goal(0) == 1  # waits there until stocked
    set_field(d.battery.charge, [FULL, FULL, FULL, FULL], np.float32)
    assert rule.watch(0) == RESTOCKED and d.refilling.to_numpy()[0, 0] == 0 and rule.keeps_goal(0) == 0


def test_an_empty_tank_sends_a_drone_home_with_a_full_battery_and_the_planner_may_send_one_short_of_either(fire):
    d = drones(fire, n=2, water=True)
    place(d, [inward(d) * OFF_BASE, inward(d) * (OFF_BASE + 20.0)])
    rule = Probe(ReturnWhenLow(d, 0.25, "all"))
    d.set_water(np.array([[0.0, d.capacity]], np.float32))
    assert rule.watch(0) == HOME and rule.watch(1) == AWAY
    rule.send_home(1)  # stocked: the groundstation is a goal like any other
    assert d.refilling.to_numpy()[0, 1] == 0
    set_field(d.battery.charge, [FULL, FULL - 1.0], np.float32)
    rule.send_home(1)  # short of a full battery: it stays there until stocked
    assert d.refilling.to_numpy()[0, 1] == 1


def test_without_the_return_rule_no_drone_goes_home_by_itself(fire):
    d = drones(fire, n=2, water=True)
    place(d, [inward(d) * OFF_BASE, inward(d) * (OFF_BASE + 20.0)])
    set_field(d.battery.charge, [1.0, 1.0], np.float32)
    d.set_water(np.array([[0.0, 0.0]], np.float32))
    rule = Probe(NoReturn())
    assert rule.watch(0) == AWAY and rule.keeps_goal(0) == 0
    rule.send_home(0)
    assert d.refilling.to_numpy()[0].tolist() == [0, 0]
    assert isinstance(DroneSim(fire, DroneConfig()).battery.return_rule(0.25, "waiting"), NoReturn)
    with pytest.raises(ValueError, match="queue"):
        ReturnWhenLow(d, 0.25, "some")


def test_the_landing_rule_holds_a_landed_drone_and_flies_the_final_approach_straight_in(fire):
    d = drones(fire, n=3, approach=2.0)
    gs = d.bases.to_numpy()[:, 0][0]
    place(d, [(0.0, 0.0), inward(d) * d.cell, inward(d) * 4.0 * d.cell])
    set_field(d.refilling, [1, 1, 1], np.int32)
    land, out = Probe(LandAtBase(d)), np.zeros(2, np.float32)
    land.action(0, 0.7, -0.3, out)
    np.testing.assert_array_equal(out, [0.0, 0.0])  # landed: hold still (velocity mode)
    land.action(1, 0.7, -0.3, out)  # 1.4 cells off: straight in, as fast as allowed
    np.testing.assert_allclose(out, -inward(d), atol=1e-6)
    land.action(2, 0.7, -0.3, out)  # 5.7 cells off: its FlyAgent flies it
    np.testing.assert_allclose(out, [0.7, -0.3])
    set_field(d.refilling, [0, 0, 0], np.int32)
    d.set_goals(np.broadcast_to(gs + 0.5, (1, 3, 2)).astype(np.float32))  # heading home, no fire: waits there
    land.action(0, 0.7, -0.3, out)
    np.testing.assert_array_equal(out, [0.0, 0.0])
    Probe(NoLanding()).action(0, 0.7, -0.3, out)
    np.testing.assert_allclose(out, [0.7, -0.3])
    assert isinstance(DroneSim(fire, DroneConfig()).battery.landing_rule(), NoLanding)
