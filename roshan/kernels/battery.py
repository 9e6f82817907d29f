"""The drone battery (issue 33, config section ``drones.energy``): one component that owns the charge and its books
(lost drones, swaps, joules drawn, time on the base), its parameters and every rule about it: the fill at placement,
the per-step draw, the swap on the groundstation, the loss of a drone whose battery runs empty, and the energies the
return rules reserve (the flight home, the queue at the base).

A DroneSim holds a :class:`Battery` with ``drones.energy`` and a :class:`NoBattery` without: both answer the same
``ti.func``s, the second with the constants of a drone that flies forever, so that no caller branches on whether
there is a battery. The charge is in joules, per drone on the ``(E, N)`` axes of the DroneSim.
"""

import math

import taichi as ti

from roshan.config import EnergyConfig


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
        """Joules drone d draws on the quickest flight to the groundstation's centre with a full tank: each axis is
        clamped to v_max, so the longer one flies at v_max and the other in step with it (no detour counted)."""
        dr = self.drones
        gap = ti.abs(dr.groundstation_centre(e) * dr.cell - dr.pos[e, d])
        long_axis = ti.max(gap[0], gap[1])
        ratio = ti.min(gap[0], gap[1]) / ti.max(long_axis, 1e-6)
        speed_sq = dr.v_max * dr.v_max * (1.0 + ratio * ratio)
        power = self.hover_power + self.speed_power * speed_sq + self.payload_power
        return power * long_axis / dr.v_max

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
    def lost_count(self, e) -> ti.i32:
        return 0

    @ti.func
    def all_lost(self, e) -> ti.i32:
        return 0

    @ti.func
    def totals(self, e):
        return ti.Vector([0.0, 0.0, 0.0, 0.0])


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
            gap = dr.pos[e, d] / dr.cell - dr.groundstation_centre(e)
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
