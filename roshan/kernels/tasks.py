"""The goal and extinguish rules of a drone (docs/model/agents.md §7, §10.1, §10.2), one copy for both levels.

A FlyAgent drone and a drone flown under the planner run the same per-drone step: :meth:`GoalRules.drone_step`
moves it (:meth:`roshan.kernels.drones.DroneSim.move_drone`), lets an optional sensor (the planner's fire map)
look around it, then applies the rules at its goal. What differs between the levels is configuration:

- the candidate set of the nearest-fire search: every burning cell (:class:`BurningCells`, FlyAgent and the
  planner's initial goals) or the fires the drones know of (:class:`KnownFires`, the greedy heuristic);
- what a drone does where it is: drop water at its goal and take the next fire (``EXTINGUISH``, complex
  FlyAgent and the heuristic), count reaching the goal as the objective (``REACH``, simple FlyAgent), or drop
  water on every burning cell it flies over while the planner picks the goals (``DROP_ANYWHERE``).

The search is one loop over a candidate set whose members are tested by the set itself, so the two sets keep
their own order (the burning list's order vs row-major) and the first of equally near cells wins in both.
"""

import taichi as ti

REACH, EXTINGUISH, DROP_ANYWHERE = range(3)


@ti.data_oriented
class BurningCells:
    """Candidates: the fire's burning cells, in the order of its burning list. A reservation always holds
    (every candidate burns)."""

    forgets = False  # the fire itself drops a put-out cell from the list

    def __init__(self, fire):
        self.fire = fire

    @ti.func
    def count(self, e) -> ti.i32:
        return self.fire.burning_count(e)

    @ti.func
    def cell(self, e, k) -> ti.i32:
        return self.fire.burning_cell(e, k)

    @ti.func
    def reservation_holds(self, e, c) -> ti.i32:
        return 1

    @ti.func
    def any(self, e) -> ti.i32:
        return ti.cast(self.fire.burning_count(e) > 0, ti.i32)

    @ti.func
    def forget(self, e, c):
        pass


@ti.data_oriented
class KnownFires:
    """Candidates: the cells of the fire map (fires some drone has seen), in row-major order. Another drone's
    reservation holds only while its cell still burns: the map may list cells that went out unseen."""

    forgets = True

    def __init__(self, fire, maps):
        self.fire, self.maps = fire, maps

    @ti.func
    def count(self, e) -> ti.i32:
        return self.fire.num_cells

    @ti.func
    def cell(self, e, k) -> ti.i32:
        """Cell k if it is on the map, else -1 (not a candidate)."""
        return ti.select(self.maps.is_known_fire(e, k) != 0, k, -1)

    @ti.func
    def reservation_holds(self, e, c) -> ti.i32:
        return self.fire.is_burning(e, c)

    @ti.func
    def any(self, e) -> ti.i32:
        return ti.cast(self.maps.known_fires[e] > 0, ti.i32)

    @ti.func
    def forget(self, e, c):
        """Cell c was put out: no longer a known fire."""
        self.maps.forget_fire(e, c)


@ti.func
def nearest_free_cell(drones: ti.template(), cands: ti.template(), e, d) -> ti.i32:
    """docs/model/agents.md §10.1: the candidate nearest to drone d that no other drone holds, or -1.

    Distances are squared index distances from the drone's integer cell; the first of equals in the set's
    order wins.
    """
    p = drones.pos[e, d] / drones.cell
    pi = ti.floor(p[0])
    pj = ti.floor(p[1])
    best = -1
    best_d2 = 0.0
    for k in range(cands.count(e)):
        c = cands.cell(e, k)
        if c >= 0:
            free = 1
            for other in range(drones.num_drones):
                if other != d and drones.goal_cell[e, other] == c and cands.reservation_holds(e, c) != 0:
                    free = 0
            if free != 0:
                di = ti.cast(c // drones.cols, ti.f32) - pi
                dj = ti.cast(c % drones.cols, ti.f32) - pj
                d2 = di * di + dj * dj
                if best < 0 or d2 < best_d2:
                    best = c
                    best_d2 = d2
    return best


@ti.func
def take_cell(drones: ti.template(), e, d, c):
    """Reserve cell c as drone d's goal; c = -1 sends it to the groundstation."""
    drones.goal_cell[e, d] = c
    goal = drones.groundstation_centre(e)
    if c >= 0:
        goal = drones.cell_centre(c)
    drones.goal[e, d] = goal


@ti.data_oriented
class GoalRules:
    """What one group of drones does about goals and fires, for one level.

    Args:
        drones: the group.
        candidates: :class:`BurningCells` or :class:`KnownFires`.
        mode: ``REACH``, ``EXTINGUISH`` or ``DROP_ANYWHERE`` (module docstring).
        water_policy: with ``EXTINGUISH`` and a finite tank, a drone whose drop emptied it flies home and
            waits there until full (docs/model/agents.md §10.2, §14).
        sticky: keep the ``extinguished`` flag set after the step it was raised in (the reference's defect;
            the fix clears it every step, so Extinguish pays on the step water hits a fire only).
        wake_idle: a drone heading for the groundstation takes the nearest candidate as soon as there is one
            (the heuristic; a FlyAgent retries only when it arrives).
        wake_reserved: with ``wake_idle``, also a drone whose goal is a fire on the groundstation's own cell (the
            original: its goal's centre equals the groundstation's, so it re-takes that fire every step and never
            reaches the drop; the heuristic times out whenever that cell burns). False is the fix: only a drone
            without a reserved fire (``goal_cell < 0``) is idle.
        sensor: an object whose ``observe_drone(e, drones, d)`` runs right after the move (the planner's fire
            map), or None.
        resources: with a battery (``drones.energy``), the resource-aware heuristic: a drone flies home once its
            battery holds no more than (1 + ``energy_margin``) times what flying home takes plus what waiting there
            for every other drone's turn takes (:meth:`roshan.kernels.battery.Battery.base_queue_energy`), or its
            tank is empty, waits there until both are full, and then takes the nearest free fire (``DROP_ANYWHERE``:
            it waits there for the planner's next goal).
        queue: the reserve for the queue at the base (``planner.return_queue``): every other drone's turn
            (``all``), the turns of the other drones flying home or waiting there now (``waiting``), or none
            (``none``: landed drones swap side by side, so no drone waits for another's turn). With 16 drones and
            the realistic battery, fifteen 120 s swaps at full power ask for more than a full battery, so with
            ``all`` every drone would turn home as soon as it left.
        land: with a battery, a drone that waits at the groundstation lands on its cell (:meth:`is_landed`) instead
            of following the FlyAgent: the planner's level sets it for the planner and both heuristics alike.
    """

    def __init__(self, drones, candidates, *, mode: int, water_policy: bool = False, sticky: bool = False,
                 wake_idle: bool = False, wake_reserved: bool = True, sensor=None, resources: bool = False,
                 energy_margin: float = 0.25, queue: str = "all", land: bool = False):
        self.drones, self.candidates, self.mode = drones, candidates, mode
        if queue not in ("all", "waiting", "none"):
            raise ValueError(f"queue: expected all, waiting or none, got {queue!r}")
        self.queue = queue
        self.water_policy, self.sticky, self.wake_idle = water_policy, sticky, wake_idle
        self.wake_reserved = wake_reserved
        self.resources = resources and drones.use_energy
        self.land = land and drones.use_energy
        self.energy_margin = energy_margin
        self.sensor = sensor
        self.has_sensor = sensor is not None  # read in ti.static (no "is" in Taichi scope)

    @ti.func
    def retarget(self, e, d):
        """Take the nearest free candidate (the groundstation if none is free)."""
        take_cell(self.drones, e, d, nearest_free_cell(self.drones, self.candidates, e, d))

    @ti.func
    def drone_step(self, e, d, action) -> ti.i32:
        """Move drone d, let the sensor see, apply the goal rules; 1 if it put out the map's last fire."""
        a = action
        if ti.static(self.land):
            if self.is_landed(e, d) != 0:
                a = self.drones.hold_action(e, d)
            elif self.drones.landing.is_approaching(e, d) != 0:  # the last metres straight in, not by the FlyAgent
                a = self.drones.straight_to_base(e, d)
        self.drones.move_drone(e, d, a)
        if ti.static(self.has_sensor):
            self.sensor.observe_drone(e, self.drones, d)
        last = 0
        if self.drones.battery.is_lost(e, d) == 0:  # a lost drone follows no goal rule
            last = self.handle_goal(e, d)
        return last

    @ti.func
    def handle_goal(self, e, d) -> ti.i32:
        """docs/model/agents.md §7 at drone d's position; returns 1 if it put out the map's last fire."""
        dr = self.drones
        last = 0
        if ti.static(self.mode == DROP_ANYWHERE):
            if ti.static(self.resources):
                self.watch_resources(e, d)
            last = dr.extinguish_here(e, d)
        else:
            if ti.static(not self.sticky):
                dr.extinguished[e, d] = 0
            going_home = 0
            if ti.static(self.water_policy):
                going_home = dr.refilling[e, d]
                if going_home != 0 and dr.water[e, d] >= dr.capacity:  # refilled in move_drone this step
                    dr.refilling[e, d] = 0
                    self.retarget(e, d)
            if ti.static(self.resources):
                going_home = self.watch_resources(e, d)
            waking = 0
            if ti.static(self.wake_idle):
                idle = dr.heads_home(e, d)
                if ti.static(not self.wake_reserved):
                    idle = ti.cast(idle != 0 and dr.goal_cell[e, d] < 0, ti.i32)
                if ti.static(self.resources):
                    idle = ti.cast(idle != 0 and going_home == 0, ti.i32)  # a drone sent home stays there
                waking = ti.cast(idle != 0 and self.candidates.any(e) != 0, ti.i32)
            if waking != 0:
                self.retarget(e, d)
            elif going_home == 0 and dr.at_goal(e, d) != 0:
                if ti.static(self.mode == EXTINGUISH):
                    last = self.extinguish_at_goal(e, d)
                else:
                    dr.objective[e, d] = 1
        return last

    @ti.func
    def queue_reserve(self, e, d) -> ti.f32:
        """Joules drone d keeps for waiting its turn at the base (``queue``): every other drone's turn, the turns of
        the drones flying home or waiting there now (an env's drones step one after another, so the count is the
        same at any thread count), or none."""
        dr = self.drones
        reserve = dr.battery.queue_energy
        if ti.static(self.queue == "none"):
            reserve = 0.0
        if ti.static(self.queue == "waiting"):
            ahead = 0
            for o in range(dr.num_drones):
                if o != d and dr.refilling[e, o] != 0 and dr.battery.is_lost(e, o) == 0:
                    ahead += 1
            reserve = ahead * dr.battery.turn_energy
        return reserve

    @ti.func
    def watch_resources(self, e, d) -> ti.i32:
        """The resource-aware heuristic's rule (``resources``): 1 while drone d flies home or waits there."""
        dr = self.drones
        home = dr.refilling[e, d]
        if home != 0 and dr.is_stocked(e, d) != 0:  # a full battery and tank again: back to the fires
            dr.refilling[e, d] = 0
            home = 0
            if ti.static(self.mode != DROP_ANYWHERE):  # a planner drone waits there for its next goal
                self.retarget(e, d)
        elif home == 0:
            need = (1.0 + self.energy_margin) * dr.battery.energy_home(e, d) + self.queue_reserve(e, d)
            if dr.battery.is_low(e, d, need) != 0 or dr.has_water(e, d) == 0:
                dr.refilling[e, d] = 1
                home = 1
                take_cell(dr, e, d, -1)  # its fire is free for the others
        return home

    @ti.func
    def is_landed(self, e, d) -> ti.i32:
        """Drone d waits at the groundstation (sent home until stocked, or there without a fire: the planner's
        groundstation goal or an idle heuristic drone) and is on its cell: it stays put instead of following the
        FlyAgent (``land``). Issue 33: hovering there, the collision-trained FlyAgent jostled the drones that waited
        at once (and the ones lost beside the cell) off it and on again, so none stayed the swap's 3 s in a row; they
        waited 100-170 s beside the base and came down there (26 of 64 drones in 16 endurance episodes of the aware
        greedy)."""
        dr = self.drones
        waits = dr.refilling[e, d]
        if waits == 0:
            waits = ti.cast(dr.heads_home(e, d) != 0 and dr.goal_cell[e, d] < 0, ti.i32)
        return ti.cast(waits != 0 and dr.at_groundstation(e, d) != 0, ti.i32)

    @ti.func
    def extinguish_at_goal(self, e, d) -> ti.i32:
        """Drop water here, release the reservation and take the next fire, or fly home with an empty tank."""
        dr = self.drones
        last = 0
        if dr.extinguish_here(e, d) != 0:
            dr.objective[e, d] = 1
            last = 1
        if ti.static(self.candidates.forgets):
            if dr.extinguished[e, d] != 0:
                self.candidates.forget(e, dr.cell_of(e, d))
        dr.goal_cell[e, d] = -1
        empty = 0
        if ti.static(self.water_policy):
            empty = 1 - dr.has_water(e, d)
        if empty != 0:
            dr.refilling[e, d] = 1
            dr.goal[e, d] = dr.groundstation_centre(e)
        else:
            self.retarget(e, d)
        return last
