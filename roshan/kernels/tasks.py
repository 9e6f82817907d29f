"""The goal and extinguish rules of a drone (docs/model/agents.md §7, §10.1, §10.2), one copy for both levels.

Each role has its rules, whose ``drone_step`` moves a drone (:meth:`roshan.kernels.drones.DroneSim.move_drone`)
and applies the rules at its goal, unless the drone is down for good:

- :class:`FlyRules`, the FlyAgent's: count reaching the goal as the objective (simple policy), or drop water at the
  goal and take the next fire, flying home to refill when the drop emptied the tank (complex policy);
- :class:`GreedyRules`, the greedy heuristic's: the fires the drones know of, an idle drone takes one as soon as
  there is one, and a return rule may send a drone home to restock;
- :class:`PlannerDroneRules`, the planner's drones: they drop water on every burning cell they fly over while the
  planner picks their goals, and a return rule may send one home.

The two rules of the planner level also let a landing rule take over a drone's action near the groundstation and
the fire map (their sensor) look around each drone after its move. The return and landing rules are strategy
objects (``ReturnWhenLow`` / ``NoReturn``, ``LandAtBase`` / ``NoLanding``) that answer :data:`AWAY`, :data:`HOME`
or :data:`RESTOCKED` for a drone and the action it flies.

The candidate set of the nearest-fire search is every burning cell (:class:`BurningCells`, FlyAgent and the
planner's initial goals) or the fires the drones know of (:class:`KnownFires`, the greedy heuristic). The search is
one loop over a candidate set whose members are tested by the set itself, so the two sets keep their own order (the
burning list's order vs row-major) and the first of equally near cells wins in both.
"""

import taichi as ti

AWAY, HOME, RESTOCKED = range(3)  # what a return rule says of a drone this step (ReturnWhenLow.watch)


@ti.data_oriented
class BurningCells:
    """Candidates: the fire's burning cells, in the order of its burning list. A reservation always holds
    (every candidate burns)."""

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
        pass  # the fire itself drops a put-out cell from the list


@ti.data_oriented
class KnownFires:
    """Candidates: the cells of the fire map (fires some drone has seen), in row-major order. Another drone's
    reservation holds only while its cell still burns: the map may list cells that went out unseen."""

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
    """Reserve cell c as drone d's goal; c = -1 sends it home to its nearest base."""
    drones.goal_cell[e, d] = c
    if c >= 0:
        drones.goal[e, d] = drones.cell_centre(c)
    else:
        drones.goal[e, d] = drones.head_home(e, d)


@ti.func
def retarget(drones: ti.template(), cands: ti.template(), e, d):
    """Take the nearest free candidate (the groundstation if none is free)."""
    take_cell(drones, e, d, nearest_free_cell(drones, cands, e, d))


@ti.func
def drop_at_goal(drones: ti.template(), cands: ti.template(), e, d) -> ti.i32:
    """Drop water at drone d's goal and release its reservation (the candidate set forgets a fire put out);
    returns 1 if that put out the map's last fire (the objective)."""
    last = 0
    if drones.extinguish_here(e, d) != 0:
        drones.objective[e, d] = 1
        last = 1
    if drones.extinguished[e, d] != 0:
        cands.forget(e, drones.cell_of(e, d))
    drones.goal_cell[e, d] = -1
    return last


@ti.func
def follow_goal(rules: ti.template(), e, d) -> ti.i32:
    """The rules at drone d's goal (``rules.handle_goal``), unless it is down for good: a lost drone follows none."""
    last = 0
    if rules.drones.is_lost(e, d) == 0:
        last = rules.handle_goal(e, d)
    return last


@ti.func
def move_and_look(rules: ti.template(), e, d, action):
    """The planner level's move: the landing rule may fly drone d instead of its FlyAgent's ``action``, then the
    sensor (the fire map) looks around it."""
    rules.drones.move_drone(e, d, rules.landing.action(e, d, action))
    rules.sensor.observe_drone(e, rules.drones, d)


@ti.data_oriented
class FlyRules:
    """The FlyAgent's goal rules (docs/model/agents.md §7).

    Args:
        drones: the group.
        candidates: :class:`BurningCells`.
        extinguish: the complex policy: drop water at the goal and take the next fire; with the water limit, a drone
            whose drop emptied its tank flies home and waits there until full (docs/model/agents.md §10.2, §14).
            Otherwise the simple policy: reaching the goal is the objective.
        sticky: keep the ``extinguished`` flag set after the step it was raised in (the reference's defect; the fix
            clears it every step, so Extinguish pays on the step water hits a fire only).
    """

    def __init__(self, drones, candidates, *, extinguish: bool, sticky: bool = False):
        self.drones, self.candidates = drones, candidates
        self.extinguish, self.sticky = extinguish, sticky

    @ti.func
    def retarget(self, e, d):
        retarget(self.drones, self.candidates, e, d)

    @ti.func
    def drone_step(self, e, d, action) -> ti.i32:
        """Move drone d and apply the goal rules; 1 if it put out the map's last fire."""
        self.drones.move_drone(e, d, action)
        return follow_goal(self, e, d)

    @ti.func
    def handle_goal(self, e, d) -> ti.i32:
        """docs/model/agents.md §7 at drone d's position; returns 1 if it put out the map's last fire."""
        dr = self.drones
        last = 0
        if ti.static(not self.sticky):
            dr.extinguished[e, d] = 0
        refilling = dr.refilling[e, d]  # set by extinguish_at_goal only: an empty tank (complex, water limit)
        if refilling != 0 and dr.water[e, d] >= dr.capacity:  # refilled in move_drone this step
            dr.refilling[e, d] = 0
            self.retarget(e, d)
        if refilling == 0 and dr.at_goal(e, d) != 0:
            if ti.static(self.extinguish):
                last = self.extinguish_at_goal(e, d)
            else:
                dr.objective[e, d] = 1
        return last

    @ti.func
    def extinguish_at_goal(self, e, d) -> ti.i32:
        """Drop water here and take the next fire, or fly home if the tank is empty (only with the water limit)."""
        dr = self.drones
        last = drop_at_goal(dr, self.candidates, e, d)
        if dr.has_water(e, d) == 0:
            dr.refilling[e, d] = 1
            dr.goal[e, d] = dr.head_home(e, d)
        else:
            self.retarget(e, d)
        return last


@ti.data_oriented
class GreedyRules:
    """The greedy heuristic's goal rules (docs/model/agents.md §10.2): drop water at the goal and take the nearest
    known fire; a drone heading for the groundstation takes one as soon as there is one (a FlyAgent retries only
    when it arrives).

    Args:
        drones: the group.
        candidates: :class:`KnownFires`.
        sensor: the fire map: its ``observe_drone(e, drones, d)`` runs right after each move.
        returns: the return rule (``ReturnWhenLow``: the resource-aware heuristic; ``NoReturn``). A drone it sends
            home stays there until it is stocked, then takes the nearest free fire.
        landing: the landing rule (``LandAtBase`` or ``NoLanding``).
        wake_reserved: also wake a drone whose goal is a fire on the groundstation's own cell (the original: its
            goal's centre equals the groundstation's, so it re-takes that fire every step and never reaches the drop;
            the heuristic times out whenever that cell burns). False is the fix: only a drone without a reserved
            fire (``goal_cell < 0``) is idle.
    """

    def __init__(self, drones, candidates, sensor, *, returns, landing, wake_reserved: bool = True):
        self.drones, self.candidates, self.sensor = drones, candidates, sensor
        self.returns, self.landing, self.wake_reserved = returns, landing, wake_reserved

    @ti.func
    def retarget(self, e, d):
        retarget(self.drones, self.candidates, e, d)

    @ti.func
    def drone_step(self, e, d, action) -> ti.i32:
        """Move drone d, let the sensor see, apply the goal rules; 1 if it put out the map's last fire."""
        move_and_look(self, e, d, action)
        return follow_goal(self, e, d)

    @ti.func
    def handle_goal(self, e, d) -> ti.i32:
        dr = self.drones
        last = 0
        dr.extinguished[e, d] = 0
        state = self.returns.watch(e, d)
        if state == RESTOCKED:
            self.retarget(e, d)
        going_home = ti.cast(state == HOME, ti.i32)  # a drone sent home stays there
        idle = dr.heads_home(e, d)
        if ti.static(not self.wake_reserved):
            idle = ti.cast(idle != 0 and dr.goal_cell[e, d] < 0, ti.i32)
        if idle != 0 and going_home == 0 and self.candidates.any(e) != 0:
            self.retarget(e, d)
        elif going_home == 0 and dr.at_goal(e, d) != 0:
            last = drop_at_goal(dr, self.candidates, e, d)
            self.retarget(e, d)
        return last


@ti.data_oriented
class PlannerDroneRules:
    """The planner's drones: the planner picks their goals (:meth:`retarget` only for the first), and they drop water
    on every burning cell they fly over (docs/model/agents.md §7).

    Args:
        drones: the group.
        candidates: :class:`BurningCells` (the first goals).
        sensor: the fire map: its ``observe_drone(e, drones, d)`` runs right after each move.
        returns: the return rule (``ReturnWhenLow``, ``planner.planner_resources``, or ``NoReturn``): a drone it sends
            home waits there for the planner's next goal once stocked.
        landing: the landing rule (``LandAtBase`` or ``NoLanding``).
    """

    def __init__(self, drones, candidates, sensor, *, returns, landing):
        self.drones, self.candidates, self.sensor = drones, candidates, sensor
        self.returns, self.landing = returns, landing

    @ti.func
    def retarget(self, e, d):
        retarget(self.drones, self.candidates, e, d)

    @ti.func
    def drone_step(self, e, d, action) -> ti.i32:
        """Move drone d, let the sensor see, apply the goal rules; 1 if it put out the map's last fire."""
        move_and_look(self, e, d, action)
        return follow_goal(self, e, d)

    @ti.func
    def handle_goal(self, e, d) -> ti.i32:
        self.returns.watch(e, d)
        return self.drones.extinguish_here(e, d)
