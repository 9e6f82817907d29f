"""The drone battery (issue 33, config section ``drones.energy``): one component that owns the charge and its books
(lost drones, swaps, joules drawn, time on the base), its parameters and every rule about it: the fill at placement,
the per-step draw, the swap on the groundstation, the loss of a drone whose battery runs empty, and the energies the
return rules reserve (the flight home, the queue at the base).

A DroneSim holds a :class:`Battery` with ``drones.energy`` and a :class:`NoBattery` without: both answer the same
``ti.func``s, the second with the constants of a drone that flies forever, so that no caller branches on whether
there is a battery. The charge is in joules, per drone on the ``(E, N)`` axes of the DroneSim.

The rules of the planner level that a battery brings are strategy objects here too, which the goal rules of
:mod:`roshan.kernels.tasks` call: the return rule (:class:`ReturnWhenLow`, its queue reserve :class:`EveryOtherTurn`,
:class:`TurnsOfTheWaiting` or :class:`NoQueue`, and :class:`NoReturn` without a battery or with the rule off) and the
landing rule (:class:`LandAtBase`, :class:`NoLanding`), beside the final approach (:class:`FinalApproach`).
"""

import math

import taichi as ti

from roshan.config import EnergyConfig
from roshan.kernels.tasks import AWAY, HOME, RESTOCKED, take_cell

# The frames' bar of a drone's charge, the first under its disc (dark = empty): :class:`ChargeGauge`
BATTERY_COLOUR = (120, 230, 60)


@ti.data_oriented
class Battery:
    """The batteries of a DroneSim's drones.

    Args:
        drones: the DroneSim whose drones carry the batteries (its motion, tank and groundstation).
        energy: the battery's section (``enabled``), its preset and overrides.
    """

    def __init__(self, drones, energy: EnergyConfig):
        self.drones = drones
        values = energy.values()
        self.capacity = values["capacity"]
        self.hover_power = values["hover_power"]
        self.speed_power = values["speed_power"]
        self.payload_power = values["payload_power"]
        self.swap_steps = max(1, round(values["swap_time"] / drones.dt))  # steps landed for a full battery
        self.queue_energy = self.base_queue_energy()
        self.turn_energy = self.queue_energy / max(1, drones.num_drones - 1)  # one drone's turn on the cell
        # field_bytes() counts these: keep it in step with them. Zero when built: the pool restores them by zeroing.
        shape = (drones.num_envs, drones.num_drones)
        self.charge = ti.field(ti.f32, shape)  # joules left
        self.lost = ti.field(ti.i32, shape)  # ran empty away from the groundstation: down for the episode
        self.landed_steps = ti.field(ti.i32, shape)  # consecutive steps landed on the groundstation, not yet full
        self.swaps = ti.field(ti.i32, shape)  # batteries swapped this episode (returns to the base)
        self.used = ti.field(ti.f32, shape)  # joules drawn this episode
        self.base_steps = ti.field(ti.i32, shape)  # steps spent landed on the groundstation this episode

    @staticmethod
    def field_bytes(num_envs: int, num_drones: int) -> int:
        """Bytes of the fields a Battery of ``num_envs`` x ``num_drones`` allocates: six 4-byte values a drone."""
        return num_envs * num_drones * 6 * 4

    def base_queue_energy(self) -> float:
        """Joules a drone draws waiting at the groundstation while every other drone is served before it (issue 33):
        (N - 1) x the time one drone stays on the cell (a swap, or a refill with the water limit, whichever is longer)
        x the power of flying at v_max along one axis with a full tank (drones jostling beside the cell drew 135 W
        on average, 147 W at the 90th percentile, with the scenario battery: 145 W by this formula)."""
        dr = self.drones
        service = self.swap_steps
        if dr.use_water:
            service = max(service, math.ceil((dr.cfg.recharge_time + 1e-4) / dr.dt))
        power = self.hover_power + self.speed_power * dr.v_max * dr.v_max + self.payload_power
        return (dr.num_drones - 1) * service * dr.dt * power

    def return_rule(self, margin: float, queue: str):
        """The return rule of the resource-aware heuristic for these drones (:class:`ReturnWhenLow`)."""
        return ReturnWhenLow(self.drones, margin, queue)

    def landing_rule(self):
        """The planner level's landing rule for these drones (:class:`LandAtBase`)."""
        return LandAtBase(self.drones)

    def gauges(self) -> tuple:
        """What the frames show of it under each drone (:attr:`roshan.kernels.drones.DroneSim.gauges`): its charge."""
        return (ChargeGauge(self),)

    # ------------------------------------------------------------------------------------------ rules

    @ti.func
    def fill(self, e, d):
        """A new episode: a full battery and clean books."""
        self.charge[e, d] = self.capacity
        self.lost[e, d] = 0
        self.landed_steps[e, d] = 0
        self.swaps[e, d] = 0
        self.used[e, d] = 0.0
        self.base_steps[e, d] = 0

    @ti.func
    def draw(self, e, d):
        """After drone d moved: on the groundstation cell it is landed and draws nothing (and may get its swap);
        elsewhere it draws its flight's energy, and runs empty there at its peril."""
        if self.drones.at_groundstation(e, d) != 0:
            self.swap_when_due(e, d)
        else:
            self.landed_steps[e, d] = 0
            self.drain(e, d)

    @ti.func
    def swap_when_due(self, e, d):
        """Landed: after ``swap_steps`` steps in a row with a battery that is not full, a full one."""
        self.base_steps[e, d] += 1
        if self.charge[e, d] < self.capacity:
            self.landed_steps[e, d] += 1
            if self.landed_steps[e, d] >= self.swap_steps:
                self.charge[e, d] = self.capacity
                self.landed_steps[e, d] = 0
                self.swaps[e, d] += 1

    @ti.func
    def drain(self, e, d):
        """Draw P dt with P = hover_power + speed_power |v|^2 + payload_power * fill (the tank's; full without the
        water limit); a battery that runs empty loses its drone."""
        dr = self.drones
        v = dr.vel[e, d]
        fill = 1.0  # without the water limit the tank never empties
        if ti.static(dr.use_water):
            fill = dr.water[e, d] / dr.capacity
        drawn = (self.hover_power + self.speed_power * v.dot(v) + self.payload_power * fill) * dr.dt
        self.used[e, d] += ti.min(drawn, self.charge[e, d])  # never more than the battery held
        self.charge[e, d] -= drawn
        if self.charge[e, d] <= 0.0:
            self.lose(e, d)

    @ti.func
    def lose(self, e, d):
        """Drone d came down where its battery ran empty: it stops and drops its reserved fire, and neither moves
        nor puts out fires for the rest of the episode (its callers ask :meth:`is_lost`)."""
        self.charge[e, d] = 0.0
        self.lost[e, d] = 1
        self.drones.vel[e, d] = ti.Vector([0.0, 0.0])
        self.drones.goal_cell[e, d] = -1

    @ti.func
    def is_lost(self, e, d) -> ti.i32:
        return self.lost[e, d]

    @ti.func
    def is_full(self, e, d) -> ti.i32:
        return ti.cast(self.charge[e, d] >= self.capacity, ti.i32)

    @ti.func
    def is_low(self, e, d, need) -> ti.i32:
        """The battery holds no more than ``need`` joules (the return rule's threshold)."""
        return ti.cast(self.charge[e, d] <= need, ti.i32)

    @ti.func
    def is_grounded(self, e, d) -> ti.i32:
        """Drone d is down at the base: landed on the groundstation cell (it draws nothing there), or on its final
        approach (``energy.approach``, :meth:`roshan.kernels.drones.DroneSim.is_down`). On the ground a drone neither
        sees nor is seen by the others and collides with none (issue 33: three drones landed there kept a fourth,
        which the collision FlyAgent steered around them, 8-13 m off the cell until its battery ran out)."""
        return self.drones.is_down(e, d)

    @ti.func
    def charge_fraction(self, e, d) -> ti.f32:
        """The charge as a fraction of a full battery, in [0, 1] (observations, frames)."""
        return ti.math.clamp(self.charge[e, d] / self.capacity, 0.0, 1.0)

    @ti.func
    def energy_home(self, e, d) -> ti.f32:
        """Joules drone d draws on the quickest flight to its nearest base's centre with a full tank: each axis is
        clamped to v_max, so the longer one flies at v_max and the other in step with it (no detour counted)."""
        dr = self.drones
        gap = ti.abs(dr.base_centre(e, dr.nearest_base(e, d)) * dr.cell - dr.pos[e, d])
        long_axis = ti.max(gap[0], gap[1])
        ratio = ti.min(gap[0], gap[1]) / ti.max(long_axis, 1e-6)
        speed_sq = dr.v_max * dr.v_max * (1.0 + ratio * ratio)
        power = self.hover_power + self.speed_power * speed_sq + self.payload_power
        return power * long_axis / dr.v_max

    @ti.func
    def observe(self, obs: ti.template(), e, d, col):
        """The planner observation's energy part of drone d (``obs[e, col:col + 2]``): its charge and the charge its
        quickest flight home needs, both as fractions of a full battery."""
        obs[e, col] = self.charge_fraction(e, d)
        home = self.energy_home(e, d) / self.capacity
        obs[e, col + 1] = ti.math.clamp(home, 0.0, 1.0)

    # ------------------------------------------------------------------------------------------ per env

    @ti.func
    def lost_count(self, e) -> ti.i32:
        n = 0
        for d in range(self.drones.num_drones):
            n += self.lost[e, d]
        return n

    @ti.func
    def all_lost(self, e) -> ti.i32:
        """Every drone of env e came down with an empty battery."""
        return ti.cast(self.lost_count(e) == self.drones.num_drones, ti.i32)

    @ti.func
    def totals(self, e):
        """Env e's episode figures as f32: (drones lost, swaps, joules drawn, seconds landed on the base per drone)."""
        dr = self.drones
        lost = 0
        swaps = 0
        used = 0.0
        landed = 0
        for d in range(dr.num_drones):
            lost += self.lost[e, d]
            swaps += self.swaps[e, d]
            used += self.used[e, d]
            landed += self.base_steps[e, d]
        return ti.Vector([ti.cast(lost, ti.f32), ti.cast(swaps, ti.f32), used,
                          ti.cast(landed, ti.f32) * dr.dt / dr.num_drones])


@ti.data_oriented
class NoBattery:
    """The battery of a drone that flies forever (``drones.energy.preset = off``, the original): never lost, always
    full, never grounded, and nothing to fill, draw or reserve. It holds no fields (nothing to remember), so a
    DroneSim without a battery allocates none (:meth:`field_bytes`)."""

    queue_energy = 0.0  # no turn at the base to wait for
    turn_energy = 0.0

    @staticmethod
    def field_bytes(num_envs: int, num_drones: int) -> int:
        return 0

    def return_rule(self, margin: float, queue: str):
        check_queue(queue)
        return NoReturn()  # nothing runs low

    def landing_rule(self):
        return NoLanding()  # nothing to land for

    def gauges(self) -> tuple:
        return ()  # a charge that never changes is not worth a bar

    @ti.func
    def fill(self, e, d):
        pass

    @ti.func
    def draw(self, e, d):
        pass

    @ti.func
    def is_lost(self, e, d) -> ti.i32:
        return 0

    @ti.func
    def is_full(self, e, d) -> ti.i32:
        return 1

    @ti.func
    def is_low(self, e, d, need) -> ti.i32:
        return 0

    @ti.func
    def is_grounded(self, e, d) -> ti.i32:
        return 0  # it never lands: in the air, seen and colliding, wherever it is

    @ti.func
    def charge_fraction(self, e, d) -> ti.f32:
        return 1.0

    @ti.func
    def energy_home(self, e, d) -> ti.f32:
        return 0.0

    @ti.func
    def observe(self, obs: ti.template(), e, d, col):
        pass  # the planner observation has no energy part

    @ti.func
    def lost_count(self, e) -> ti.i32:
        return 0

    @ti.func
    def all_lost(self, e) -> ti.i32:
        return 0

    @ti.func
    def totals(self, e):
        return ti.Vector([0.0, 0.0, 0.0, 0.0])


@ti.data_oriented
class ChargeGauge:
    """A battery's gauge in the frames: a bar under each drone filled with its charge (``fraction``, in [0, 1])."""

    colour = BATTERY_COLOUR
    label = "battery (bar under a drone)"

    def __init__(self, battery: Battery):
        self.battery = battery

    @ti.func
    def fraction(self, e, d) -> ti.f32:
        return self.battery.charge_fraction(e, d)


@ti.data_oriented
class FinalApproach:
    """The last metres of a flight home (``drones.energy.approach`` cells; with a battery only): a drone flying home
    (``refilling``) that close to the groundstation's centre flies straight in instead of following its FlyAgent, and
    counts as down, like a landed drone: it neither sees nor is seen by the others, nor the map's edge (on Borkenberge
    with 16 drones, drones arriving together at a base in the map's corner hovered 1-2 cells off it until their
    batteries were empty)."""

    def __init__(self, drones, cells: float):
        self.drones, self.cells = drones, cells

    @ti.func
    def is_approaching(self, e, d) -> ti.i32:
        dr = self.drones
        near = 0
        if dr.refilling[e, d] != 0:
            gap = dr.pos[e, d] / dr.cell - dr.home_centre(e, d)
            near = ti.cast(gap.dot(gap) <= self.cells * self.cells, ti.i32)
        return near

    @ti.func
    def down(self, e, d, landed) -> ti.i32:
        """Down at the base: ``landed`` on its cell, or on the final approach."""
        return ti.max(landed, self.is_approaching(e, d))

    @ti.func
    def sees_edge(self, down) -> ti.i32:
        return 1 - down


@ti.data_oriented
class NoApproach:
    """No final approach: a drone flies home by its FlyAgent to the last metre, and is down only once landed."""

    @ti.func
    def is_approaching(self, e, d) -> ti.i32:
        return 0

    @ti.func
    def down(self, e, d, landed) -> ti.i32:
        return landed

    @ti.func
    def sees_edge(self, down) -> ti.i32:
        return 1


# ---------------------------------------------------------------------------------------------- the return rule


@ti.data_oriented
class EveryOtherTurn:
    """The queue reserve ``all``: every other drone's turn at the base (:meth:`Battery.base_queue_energy`)."""

    def __init__(self, drones):
        self.drones = drones

    @ti.func
    def reserve(self, e, d) -> ti.f32:
        return self.drones.battery.queue_energy


@ti.data_oriented
class TurnsOfTheWaiting:
    """The queue reserve ``waiting``: the turns of the other drones flying home or waiting there now, a turn each
    (:attr:`Battery.turn_energy`). An env's drones step one after another, so the count is the same at any thread
    count."""

    def __init__(self, drones):
        self.drones = drones

    @ti.func
    def reserve(self, e, d) -> ti.f32:
        dr = self.drones
        ahead = 0
        for o in range(dr.num_drones):
            if o != d and dr.refilling[e, o] != 0 and dr.battery.is_lost(e, o) == 0:
                ahead += 1
        return ahead * dr.battery.turn_energy


@ti.data_oriented
class NoQueue:
    """The queue reserve ``none``: landed drones swap side by side, so no drone waits for another's turn."""

    def __init__(self, drones):
        pass

    @ti.func
    def reserve(self, e, d) -> ti.f32:
        return 0.0


QUEUES = {"all": EveryOtherTurn, "waiting": TurnsOfTheWaiting, "none": NoQueue}  # planner.return_queue


def check_queue(queue: str) -> None:
    if queue not in QUEUES:
        raise ValueError(f"queue: expected {', '.join(QUEUES)}, got {queue!r}")


@ti.data_oriented
class ReturnWhenLow:
    """The resource-aware heuristic's return rule (issue 33): a drone flies home once its battery holds no more than
    (1 + ``margin``) times what its flight home takes (:meth:`Battery.energy_home`) plus its ``queue`` reserve, or
    its tank is empty; it waits there until both are full again (``refilling``). With 16 drones and the realistic
    battery, fifteen 120 s swaps at full power ask for more than a full battery, so with the ``all`` queue every drone
    would turn home as soon as it left.

    Args:
        drones: the group whose drones the rule sends home (with a battery).
        margin: ``planner.greedy_energy_margin``.
        queue: the reserve for the queue at the base, ``planner.return_queue``: ``all`` (:class:`EveryOtherTurn`),
            ``waiting`` (:class:`TurnsOfTheWaiting`) or ``none`` (:class:`NoQueue`).
    """

    def __init__(self, drones, margin: float, queue: str):
        check_queue(queue)
        self.drones, self.margin = drones, margin
        self.queue = QUEUES[queue](drones)

    @ti.func
    def watch(self, e, d) -> ti.i32:
        """Drone d's return this step, as :mod:`roshan.kernels.tasks` reads it: ``HOME`` while it flies home or
        waits there (sent home now, its fire freed for the others), ``RESTOCKED`` on the step it is stocked again
        (the caller gives it its next goal), else ``AWAY``."""
        dr = self.drones
        state = AWAY
        if dr.refilling[e, d] != 0:
            state = HOME
        if state == HOME and dr.is_stocked(e, d) != 0:  # a full battery and tank again: back to the fires
            dr.refilling[e, d] = 0
            state = RESTOCKED
        elif state == AWAY:
            need = (1.0 + self.margin) * dr.battery.energy_home(e, d) + self.queue.reserve(e, d)
            if dr.battery.is_low(e, d, need) != 0 or dr.has_water(e, d) == 0:
                dr.refilling[e, d] = 1
                state = HOME
                take_cell(dr, e, d, -1)  # its fire is free for the others
        return state

    @ti.func
    def keeps_goal(self, e, d) -> ti.i32:
        """Drone d flies home or waits there to restock: the planner's goals do not move it, nor share its fire."""
        return self.drones.refilling[e, d]

    @ti.func
    def send_home(self, e, d):
        """The planner chose the groundstation for drone d: short of a full battery or tank, it stays there until
        stocked."""
        if self.drones.is_stocked(e, d) == 0:
            self.drones.refilling[e, d] = 1


@ti.data_oriented
class NoReturn:
    """No return rule (no battery, or the rule off): no drone flies home by itself, and the groundstation is a goal
    like any other."""

    @ti.func
    def watch(self, e, d) -> ti.i32:
        return AWAY

    @ti.func
    def keeps_goal(self, e, d) -> ti.i32:
        return 0

    @ti.func
    def send_home(self, e, d):
        pass


# ---------------------------------------------------------------------------------------------- the landing rule


@ti.data_oriented
class LandAtBase:
    """The planner level's landing rule (with a battery; the planner and both heuristics alike): a drone that waits at
    the groundstation lands on its cell and stays put instead of following the FlyAgent (:meth:`is_landed`), and a
    drone on its final approach (:class:`FinalApproach`) flies the last metres straight in."""

    def __init__(self, drones):
        self.drones = drones

    @ti.func
    def is_landed(self, e, d) -> ti.i32:
        """Drone d waits at the groundstation (sent home until stocked, or there without a fire: the planner's
        groundstation goal or an idle heuristic drone) and is on its cell. Issue 33: hovering there, the
        collision-trained FlyAgent jostled the drones that waited at once (and the ones lost beside the cell) off it
        and on again, so none stayed the swap's 3 s in a row; they waited 100-170 s beside the base and came down
        there (26 of 64 drones in 16 endurance episodes of the aware greedy)."""
        dr = self.drones
        waits = dr.refilling[e, d]
        if waits == 0:
            waits = ti.cast(dr.heads_home(e, d) != 0 and dr.goal_cell[e, d] < 0, ti.i32)
        return ti.cast(waits != 0 and dr.at_groundstation(e, d) != 0, ti.i32)

    @ti.func
    def action(self, e, d, a):
        """The action drone d flies instead of its FlyAgent's ``a``: hold still once landed, straight in on the final
        approach, else ``a``."""
        dr = self.drones
        out = a
        if self.is_landed(e, d) != 0:
            out = dr.hold_action(e, d)
        elif dr.landing.is_approaching(e, d) != 0:  # the last metres straight in, not by the FlyAgent
            out = dr.straight_to_base(e, d)
        return out


@ti.data_oriented
class NoLanding:
    """No landing rule (no battery): every drone flies by its FlyAgent wherever it is."""

    @ti.func
    def action(self, e, d, a):
        return a
