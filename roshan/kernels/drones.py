"""Drone physics on the fire simulator's envs (docs/model/agents.md §3-4, §14): motion, boundary, neighbours, collisions
and the water tank. The battery is its own component (:mod:`roshan.kernels.battery`), held as ``battery``.

Drones live on the second axis of every field, ``(E, N)``. Positions and velocities are in metres and m/s
along (rows, cols); goals and neighbour offsets are in grid units (metres / cell size), as in the reference.
The motion and sensing rules are ``ti.func``s taking one env, so the FlyAgent step kernel can run them
serially per env inside the same launch as the fire update.
"""

import math

import numpy as np
import taichi as ti

from roshan.config import DroneConfig
from roshan.kernels import rng, tasks
from roshan.kernels.arrays import int32_array
from roshan.kernels.battery import Battery, FinalApproach, NoApproach, NoBattery
from roshan.kernels.fire import FireSim
from roshan.maps import MIN_BASES_MAP_SIDE

BIN = 0.05  # action resolution with use_vel_bins: 41 levels in [-1, 1]
# The corners of the bases after the first (docs/model/agents.md §4.1), as masks XORed onto the first base's corner id
# 2 * (row != 1) + (col != 1): the opposite corner, then the other corner of the first's row, then that of its column.
BASE_CORNER_MASKS = (0, 3, 1, 2)


def corner_bases(rows: int, cols: int, count: int) -> tuple[tuple[tuple[int, int], ...], ...]:
    """The cells (row, col) of ``count`` bases by the corner rule, for each first corner 0-3 in turn (the kernels'
    :meth:`DroneSim.place` draws which): where ``drones.bases`` puts them on a map of ``rows`` x ``cols`` cells."""
    def corner(k: int) -> tuple[int, int]:  # as DroneSim.corner_cell
        return (1 if k < 2 else rows - 2, 1 if k % 2 == 0 else cols - 2)

    return tuple(tuple(corner(first ^ BASE_CORNER_MASKS[b]) for b in range(count)) for first in range(4))


def cells_outside(cells, rows: int, cols: int) -> list[tuple[int, int]]:
    """The (row, col) cells of ``cells`` that lie outside a map of ``rows`` x ``cols`` cells."""
    return [c for c in cells if c[0] >= rows or c[1] >= cols]


def farthest_cell(placements, rows: int, cols: int, cell: float) -> float:
    """Metres from the farthest cell centre of a ``rows`` x ``cols`` map to its nearest base, the largest over
    ``placements`` (P, B, 2) base cells: the farthest a fire can be from where a drone restocks."""
    placed = np.unique(np.asarray(placements, np.int64).reshape(-1, np.shape(placements)[-2], 2), axis=0)
    centres = (placed.astype(np.float64) + 0.5) * cell
    rr, cc = np.meshgrid((np.arange(rows) + 0.5) * cell, (np.arange(cols) + 0.5) * cell, indexing="ij")
    cells = np.stack([rr.ravel(), cc.ravel()], axis=-1)
    far = 0.0
    for bases in centres:  # one placement at a time: cells x B distances
        far = max(far, float(np.linalg.norm(cells[:, None, :] - bases[None], axis=-1).min(axis=1).max()))
    return far


@ti.func
def bin_action(a: ti.f32) -> ti.f32:
    """round(a / 0.05) * 0.05 with halves away from zero (C++ std::round)."""
    q = ti.abs(a) / BIN
    return ti.math.sign(a) * ti.floor(q + 0.5) * BIN


@ti.data_oriented
class DroneSim:
    """N drones in each of the fire simulator's E envs.

    Args:
        fire: the simulator whose envs, map size, cell size and seed the drones share.
        cfg: drone physics and layout.
        lands: the group lands at the base (the planner level): with a battery, a drone flying home makes the final
            approach of ``cfg.energy.approach`` cells.
    """

    def __init__(self, fire: FireSim, cfg: DroneConfig | None = None, lands: bool = False):
        self.fire = fire
        self.cfg = cfg = cfg or DroneConfig()
        E, N = fire.num_envs, cfg.num_drones
        self.num_envs, self.num_drones = E, N
        self.rows, self.cols, self.cell = fire.rows, fire.cols, fire.cell_size
        self.dt = fire.dt
        self.v_max = cfg.max_speed
        self.accel = cfg.max_speed / 2.0  # a_max = v_max / 2 (m/s^2) in acceleration mode
        self.use_bins = cfg.use_vel_bins
        self.use_accel = cfg.use_velocity_change
        self.view = float(cfg.view_range)
        self.half_view = cfg.view_range / 2.0
        self.s_norm = float(cfg.view_range // 2)  # own-feature normaliser floor(r_view / 2)
        self.collide_sq = (2.0 * cfg.drone_size / self.cell) ** 2  # centres within 2 x size (grid units^2)
        margin = max(0.05 * self.cell, 0.1)
        self.ring = min(self.cell / 2.0 - margin, max(2.0 * cfg.drone_size, 0.35 * self.cell))
        self.start_gs = cfg.groundstation_start_percentage
        self.num_bases = B = cfg.bases
        self.base_cells = cfg.explicit_bases  # () for the corner rule
        outside = cells_outside(self.base_cells, self.rows, self.cols)
        if outside:
            raise ValueError(f"drones.base_cells = {cfg.base_cells!r}: cell(s) {outside} lie outside the map of "
                             f"{self.rows} x {self.cols} cells (rows 0-{self.rows - 1}, columns 0-{self.cols - 1})")
        if B > 1 and not self.base_cells and min(self.rows, self.cols) < MIN_BASES_MAP_SIDE:
            side = MIN_BASES_MAP_SIDE
            raise ValueError(f"drones.bases = {B} needs a map of at least {side} x {side} cells (the bases sit one "
                             f"cell inside distinct corners); this one has {self.rows} x {self.cols}: "
                             "set drones.bases = 1")
        # Water (docs/model/agents.md §14, newest code). Every use sits behind ti.static(self.use_water), so without the
        # limit the kernels are the ones of an infinite tank.
        self.use_water = cfg.use_water_limit
        self.capacity = cfg.water_capacity
        self.refill_rate = cfg.water_capacity * self.dt / (cfg.recharge_time + 1e-4)  # per step at the station
        # A battery (issue 33) or none: the rules ask it either way (battery.py), so use_energy is left for what
        # differs in shape with a battery (the planner observation's energy part).
        self.use_energy = cfg.energy.enabled
        # cells: a drone flying home within them of the base's centre is on its final approach (0 = off). Only where
        # the group lands at the base (``lands``: the planner level's landing rule flies that approach straight in); a
        # FlyAgent drone flies home by its policy all the way, and stays in its neighbours' view.
        self.approach = cfg.energy.approach if self.use_energy and lands else 0.0

        # field_bytes() counts these: keep it in step with them
        self.pos = ti.Vector.field(2, ti.f32, (E, N))
        self.vel = ti.Vector.field(2, ti.f32, (E, N))
        self.out_count = ti.field(ti.i32, (E, N))  # consecutive steps outside the grid
        self.collided = ti.field(ti.i32, (E, N))  # sticky until reset
        self.bases = ti.Vector.field(2, ti.i32, (E, B))  # groundstation cells (row, col); base 0 is the drones' start
        self.home = ti.field(ti.i32, (E, N))  # the base each drone last headed home to (its nearest then)
        self.neighbours = ti.Vector.field(4, ti.f32, (E, N, N))  # slot 0: nearest boundary; then other drones
        self.neighbour_mask = ti.field(ti.i32, (E, N, N))
        self.goal = ti.Vector.field(2, ti.f32, (E, N))  # grid units (a cell centre)
        self.goal_cell = ti.field(ti.i32, (E, N))  # the burning cell this drone reserved, -1 for none
        self.extinguished = ti.field(ti.i32, (E, N))  # extinguished_fire flag (docs/model/agents.md §7.1)
        self.n_extinguished = ti.field(ti.i32, (E, N))
        self.objective = ti.field(ti.i32, (E, N))  # objective_reached
        self.prev_dist = ti.field(ti.f32, (E, N))  # distance to the goal at the previous reward (grid units)
        self.water = ti.field(ti.f32, (E, N))  # drops left in the tank; always full without use_water_limit
        self.refilling = ti.field(ti.i32, (E, N))  # complex policy: flying home because the tank ran empty
        self.battery = Battery(self, cfg.energy) if self.use_energy else NoBattery()  # its fields are its own
        # the last metres of a flight home, straight in (energy.approach cells; with a battery only)
        self.landing = FinalApproach(self, self.approach) if self.approach > 0.0 else NoApproach()
        # What the frames draw under each drone, one bar each in this order: its battery's gauges, then its tank's
        # fill with the water limit. Each has a colour, a legend label and a ti.func fraction(e, d) in [0, 1].
        self.gauges = self.battery.gauges() + ((TankGauge(self),) if self.use_water else ())
        self.water.fill(cfg.water_capacity)
        self._all = np.ones(E, dtype=np.int32)
        self._burning = tasks.BurningCells(fire)  # assign_fire_goals' candidates

    @staticmethod
    def field_bytes(num_envs: int, cfg: DroneConfig) -> int:
        """Bytes of the fields (and host arrays) a DroneSim of ``num_envs`` envs of ``cfg`` drones allocates, known
        before it is built, its battery's included (``drones.energy``); the water tanks, full once built, once more
        for the pristine copy of the simulator pool."""
        n = cfg.num_drones
        per_drone = 8 + 8 + 4 + 4 + 8 + 4 + 4 + 4 + 4 + 4 + 4 + 4 + 4  # pos ... refilling, home
        per_env = n * per_drone + n * n * (16 + 4) + 8 * cfg.bases + 4  # + neighbours, their mask, bases, _all
        return num_envs * (per_env + 4 * n) + (Battery if cfg.energy.enabled else NoBattery).field_bytes(num_envs, n)

    def parts(self) -> list:
        """The components that hold fields of their own (its battery): the simulator pool restores them too."""
        return [self.battery]

    # ------------------------------------------------------------------------------------------ public API

    def reset(self, mask=None) -> None:
        """Place the bases and the drones of the masked envs (call after the fire's reset)."""
        mask = self._all if mask is None else int32_array(mask, (self.num_envs,), "reset mask")
        self._reset(mask)

    def farthest_from_bases(self) -> float:
        """:func:`farthest_cell` for the bases the envs have now (read after a reset has placed them)."""
        return farthest_cell(self.bases.to_numpy(), self.rows, self.cols, self.cell)

    def move(self, actions) -> None:
        """Apply (E, N, 2) float32 actions to every drone and refresh neighbours and collisions."""
        self._move_all(actions)

    def assign_fire_goals(self) -> None:
        """Give every drone, in index order, the nearest burning cell no other drone holds (tests, baselines)."""
        self._assign_fire_goals()

    def set_goals(self, goals) -> None:
        """Set goals ((E, N, 2) grid units; no reservation) and restart the progress reference distance."""
        self.goal.from_numpy(np.ascontiguousarray(goals, dtype=np.float32))
        self._restart_progress()

    def set_state(self, pos, vel) -> None:
        """Place drones directly ((E, N, 2) metres and m/s) and refresh neighbours (tests, scripted scenes)."""
        self.pos.from_numpy(np.ascontiguousarray(pos, dtype=np.float32))
        self.vel.from_numpy(np.ascontiguousarray(vel, dtype=np.float32))
        self._refresh_neighbours()

    def set_water(self, water) -> None:
        """Set every tank ((E, N) drops; tests, scripted scenes). Without ``use_water_limit`` nothing reads it."""
        self.water.from_numpy(np.ascontiguousarray(water, dtype=np.float32))

    # ------------------------------------------------------------------------------------------ kernels

    @ti.kernel
    def _reset(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for e in range(self.num_envs):
            if mask[e] != 0:
                self.place(e)
                self.update_neighbours(e)

    @ti.kernel
    def _move_all(self, actions: ti.types.ndarray(dtype=ti.f32, ndim=3)):
        for e in range(self.num_envs):
            for d in range(self.num_drones):
                self.move_drone(e, d, ti.Vector([actions[e, d, 0], actions[e, d, 1]]))
            self.update_neighbours(e)

    @ti.kernel
    def _assign_fire_goals(self):
        for e in range(self.num_envs):
            for d in range(self.num_drones):
                tasks.take_cell(self, e, d, tasks.nearest_free_cell(self, self._burning, e, d))

    @ti.kernel
    def _restart_progress(self):
        for e, d in ti.ndrange(self.num_envs, self.num_drones):
            self.goal_cell[e, d] = -1
            self.prev_dist[e, d] = self.distance_to_goal(e, d)

    @ti.kernel
    def _refresh_neighbours(self):
        for e in range(self.num_envs):
            self.update_neighbours(e)

    # ------------------------------------------------------------------------------------------ rules

    @ti.func
    def place(self, e):
        """The first base one cell inside a random corner, the others in the corners after it
        (:data:`BASE_CORNER_MASKS`), or all at ``drones.base_cells``; drones on a ring around their start cell (the
        first base's)."""
        k = rng.key(self.fire.env_key[e], rng.DOMAIN_DRONES, 0)
        if ti.static(self.base_cells):  # drones.base_cells: where the user put them, the same in every env
            for b in ti.static(range(self.num_bases)):
                self.bases[e, b] = ti.Vector([self.base_cells[b][0], self.base_cells[b][1]])
        else:
            gi = ti.select(rng.uniform(rng.key(k, 0, 0)) < 0.5, 1, self.rows - 2)  # row drawn first
            gj = ti.select(rng.uniform(rng.key(k, 1, 0)) < 0.5, 1, self.cols - 2)
            self.bases[e, 0] = ti.Vector([gi, gj])
            if ti.static(self.num_bases > 1):
                first = 2 * ti.cast(gi != 1, ti.i32) + ti.cast(gj != 1, ti.i32)
                for b in ti.static(range(1, self.num_bases)):
                    self.bases[e, b] = self.corner_cell(first ^ BASE_CORNER_MASKS[b])
        gi, gj = self.bases[e, 0][0], self.bases[e, 0][1]
        for d in range(self.num_drones):
            ci = gi
            cj = gj
            if rng.uniform(rng.key(k, 2, d)) >= self.start_gs:
                c = rng.uniform_int(rng.key(k, 3, d), self.rows * self.cols)
                ci = c // self.cols
                cj = c % self.cols
            offset = ti.Vector([0.0, 0.0])
            if ti.static(self.num_drones > 1):
                theta = 2.0 * math.pi * d / self.num_drones
                offset = self.ring * ti.Vector([ti.cos(theta), ti.sin(theta)])
            self.pos[e, d] = (ti.Vector([ci, cj], ti.f32) + 0.5) * self.cell + offset
            self.vel[e, d] = ti.Vector([0.0, 0.0])
            self.out_count[e, d] = 0
            self.collided[e, d] = 0
            self.goal_cell[e, d] = -1
            self.extinguished[e, d] = 0
            self.n_extinguished[e, d] = 0
            self.objective[e, d] = 0
            self.refilling[e, d] = 0  # the tank's or the battery's return: a new episode starts none
            self.home[e, d] = self.nearest_base(e, d)
            if ti.static(self.use_water):
                self.water[e, d] = self.capacity
            self.battery.fill(e, d)

    @ti.func
    def move_drone(self, e, d, a):
        """Fly drone d by action a and draw its battery; a lost drone stays where it came down."""
        if self.battery.is_lost(e, d) == 0:
            self.fly(e, d, a)
            self.battery.draw(e, d)

    @ti.func
    def fly(self, e, d, a):
        """docs/model/agents.md §3.1: bins, velocity or acceleration mode, per-axis clamp, integrate, out-of-area count;
        with the water limit, refill at the groundstation (docs/model/agents.md §14)."""
        a = ti.math.clamp(a, -1.0, 1.0)
        if ti.static(self.use_bins):
            a = ti.Vector([bin_action(a[0]), bin_action(a[1])])
        v = a * self.v_max
        if ti.static(self.use_accel):
            v = self.vel[e, d] + a * self.accel * self.dt
        v = ti.math.clamp(v, -self.v_max, self.v_max)
        p = self.pos[e, d] + v * self.dt
        self.vel[e, d] = v
        self.pos[e, d] = p
        if self.is_outside(p):
            self.out_count[e, d] += 1
        else:
            self.out_count[e, d] = 0
        if ti.static(self.use_water):
            self.refill(e, d)

    @ti.func
    def hold_action(self, e, d):
        """The action that keeps drone d where it is: no velocity command, or in acceleration mode the one that brakes
        it (landed at the groundstation, :meth:`roshan.kernels.battery.LandAtBase.is_landed`)."""
        a = ti.Vector([0.0, 0.0])
        if ti.static(self.use_accel):
            a = ti.math.clamp(-self.vel[e, d] / (self.accel * self.dt), -1.0, 1.0)
        return a

    @ti.func
    def is_stocked(self, e, d) -> ti.i32:
        """A full battery, and a full tank with the water limit."""
        full = self.battery.is_full(e, d)
        if ti.static(self.use_water):
            full = ti.cast(full != 0 and self.water[e, d] >= self.capacity, ti.i32)
        return full

    @ti.func
    def at_groundstation(self, e, d) -> ti.i32:
        """Drone d is on a base's cell (any base: a drone restocks at each)."""
        c = self.cell_of(e, d)
        on = 0
        for b in ti.static(range(self.num_bases)):
            gs = self.bases[e, b]
            if c == gs[0] * self.cols + gs[1]:
                on = 1
        return on

    @ti.func
    def refill(self, e, d):
        """Newest code: min(capacity, w + capacity * dt / (recharge_time + 1e-4)) while the drone's cell is a
        base's (full after ceil((recharge_time + 1e-4) / dt) steps from empty: 21 with the defaults)."""
        if self.at_groundstation(e, d) != 0:
            self.water[e, d] = ti.min(self.capacity, self.water[e, d] + self.refill_rate)

    @ti.func
    def is_outside(self, p) -> ti.i32:
        i = ti.floor(p[0] / self.cell)
        j = ti.floor(p[1] / self.cell)
        return ti.cast(i < 0 or i >= self.rows or j < 0 or j >= self.cols, ti.i32)

    @ti.func
    def update_neighbours(self, e):
        """docs/model/agents.md §3.3: per drone, the nearest boundary and every other drone within half the view
        range. A drone grounded at the base (:meth:`roshan.kernels.battery.Battery.is_grounded`: with a battery, landed
        on the groundstation cell) neither sees nor is seen by the others and collides with none. A drone on its
        final approach (:class:`~roshan.kernels.battery.FinalApproach`) is down too, and no longer sees the map's
        edge."""
        for i in range(self.num_drones):
            x = self.pos[e, i] / self.cell
            b = self.nearest_boundary(x)
            i_down = self.battery.is_grounded(e, i)
            near_edge = ti.abs(b[0]) <= self.half_view and ti.abs(b[1]) <= self.half_view
            if self.landing.sees_edge(i_down) != 0 and near_edge:
                self.neighbours[e, i, 0] = ti.Vector([b[0] / self.half_view, b[1] / self.half_view, 0.0, 0.0])
                self.neighbour_mask[e, i, 0] = 1
            else:
                self.neighbours[e, i, 0] = ti.Vector([0.0, 0.0, 0.0, 0.0])
                self.neighbour_mask[e, i, 0] = 0
            slot = 1
            for j in range(self.num_drones):
                if j != i:
                    dxy = self.pos[e, j] / self.cell - x
                    airborne = ti.cast(i_down + self.battery.is_grounded(e, j) == 0, ti.i32)  # both in the air
                    if airborne != 0 and ti.abs(dxy[0]) < self.half_view and ti.abs(dxy[1]) < self.half_view:
                        vn = self.vel[e, j] / (self.v_max * self.s_norm)
                        self.neighbours[e, i, slot] = ti.Vector([dxy[0] / self.view, dxy[1] / self.view, vn[0], vn[1]])
                        self.neighbour_mask[e, i, slot] = 1
                        if dxy.dot(dxy) <= self.collide_sq:
                            self.collided[e, i] = 1
                            self.collided[e, j] = 1
                    else:
                        self.neighbours[e, i, slot] = ti.Vector([0.0, 0.0, 0.0, 0.0])
                        self.neighbour_mask[e, i, slot] = 0
                    slot += 1

    @ti.func
    def nearest_boundary(self, x):
        """Displacement (grid units) to the nearest of the four map edges; ties keep the first in the order
        row 0, row edge, column 0, column edge."""
        best = ti.Vector([-x[0], 0.0])
        for cand in ti.static(range(3)):
            c = ti.Vector([0.0, 0.0])
            if ti.static(cand == 0):
                c = ti.Vector([self.rows - x[0], 0.0])
            elif ti.static(cand == 1):
                c = ti.Vector([0.0, -x[1]])
            else:
                c = ti.Vector([0.0, self.cols - x[1]])
            if ti.abs(c[0]) + ti.abs(c[1]) < ti.abs(best[0]) + ti.abs(best[1]):
                best = c
        return best

    # ------------------------------------------------------------------------------------------ goals

    @ti.func
    def is_lost(self, e, d) -> ti.i32:
        """Drone d came down where its battery ran empty: down for the rest of the episode."""
        return self.battery.is_lost(e, d)

    @ti.func
    def is_down(self, e, d) -> ti.i32:
        """Landed on the groundstation cell, or on its final approach: out of the other drones' way."""
        return self.landing.down(e, d, self.at_groundstation(e, d))

    @ti.func
    def straight_to_base(self, e, d):
        """The velocity command that flies drone d straight to its home base's centre, as fast as allowed and
        no further (the final approach; in acceleration mode the command that brakes towards it)."""
        want = ti.math.clamp((self.home_centre(e, d) * self.cell - self.pos[e, d]) / self.dt,
                             -self.v_max, self.v_max)
        a = want / self.v_max
        if ti.static(self.use_accel):
            a = ti.math.clamp((want - self.vel[e, d]) / (self.accel * self.dt), -1.0, 1.0)
        return a

    @ti.func
    def base_centre(self, e, b):
        """Grid coordinates (row, col) of the centre of env e's base b."""
        return ti.cast(self.bases[e, b], ti.f32) + 0.5

    @ti.func
    def home_centre(self, e, d):
        """The centre of drone d's home: the base it last headed home to (:meth:`head_home`)."""
        return self.base_centre(e, self.home[e, d])

    @ti.func
    def nearest_base(self, e, d) -> ti.i32:
        """The base whose centre is nearest to drone d (Euclidean, grid units; ties to the lower index)."""
        best = 0
        if ti.static(self.num_bases > 1):
            x = self.pos[e, d] / self.cell
            gap = self.base_centre(e, 0) - x
            best_sq = gap.dot(gap)
            for b in ti.static(range(1, self.num_bases)):
                gap = self.base_centre(e, b) - x
                if gap.dot(gap) < best_sq:
                    best_sq = gap.dot(gap)
                    best = b
        return best

    @ti.func
    def head_home(self, e, d):
        """Drone d heads home: its nearest base becomes its home. Returns that base's centre (its goal)."""
        self.home[e, d] = self.nearest_base(e, d)
        return self.home_centre(e, d)

    @ti.func
    def corner_cell(self, corner):
        """The cell one cell inside the map's corner ``corner`` = 2 * (bottom row) + (right column)."""
        return ti.Vector([ti.select(corner < 2, 1, self.rows - 2), ti.select(corner % 2 == 0, 1, self.cols - 2)])

    @ti.func
    def cell_of(self, e, d) -> ti.i32:
        """Flat index of the cell under drone d, or -1 outside the grid."""
        c = -1
        p = self.pos[e, d]
        if self.is_outside(p) == 0:
            c = ti.cast(ti.floor(p[0] / self.cell), ti.i32) * self.cols + ti.cast(ti.floor(p[1] / self.cell), ti.i32)
        return c

    @ti.func
    def cell_centre(self, c):
        """Grid coordinates (row, col) of the centre of flat cell c."""
        return ti.Vector([ti.cast(c // self.cols, ti.f32), ti.cast(c % self.cols, ti.f32)]) + 0.5

    @ti.func
    def heads_home(self, e, d) -> ti.i32:
        """Drone d's goal is its home base's centre (within 0.25 cells on both axes)."""
        gs = self.home_centre(e, d)
        g = self.goal[e, d]
        return ti.cast(ti.abs(g[0] - gs[0]) < 0.25 and ti.abs(g[1] - gs[1]) < 0.25, ti.i32)

    @ti.func
    def random_corner_goal(self, e, d, h: ti.u32):
        """A random one of the three corner cells other than the first base's (centre, grid units)."""
        gs = self.bases[e, 0]
        pick = rng.uniform_int(h, 3)
        n = 0
        goal = self.base_centre(e, 0)
        for corner in ti.static(range(4)):
            cell = self.corner_cell(corner)
            if cell[0] != gs[0] or cell[1] != gs[1]:
                if n == pick:
                    goal = ti.cast(cell, ti.f32) + 0.5
                n += 1
        self.goal_cell[e, d] = -1
        self.goal[e, d] = goal

    @ti.func
    def distance_to_goal(self, e, d) -> ti.f32:
        return (self.goal[e, d] - self.pos[e, d] / self.cell).norm()

    @ti.func
    def at_goal(self, e, d) -> ti.i32:
        """Within 0.25 cells of the goal on both axes."""
        g = self.goal[e, d] - self.pos[e, d] / self.cell
        return ti.cast(ti.abs(g[0]) < 0.25 and ti.abs(g[1]) < 0.25, ti.i32)

    @ti.func
    def has_water(self, e, d) -> ti.i32:
        """1 unless the water limit is on and the tank is empty."""
        has = 1
        if ti.static(self.use_water):
            has = ti.cast(self.water[e, d] > 0.0, ti.i32)
        return has

    @ti.func
    def extinguish_here(self, e, d) -> ti.i32:
        """docs/model/agents.md §7.1: drop water on the cell under the drone if it burns (with the water limit: only
        from a non-empty tank, which loses one unit, clamped at 0). Returns 1 if that was the last burning cell of the
        map (the drone reached the complex policy's objective)."""
        c = self.cell_of(e, d)
        last = 0
        self.extinguished[e, d] = 0
        if c >= 0 and self.battery.is_lost(e, d) == 0:
            if self.fire.is_burning(e, c) != 0 and self.has_water(e, d) != 0:
                if ti.static(self.use_water):
                    self.water[e, d] = ti.max(self.water[e, d] - 1.0, 0.0)
                self.fire.drop_water(e, c)
                self.extinguished[e, d] = 1
                self.n_extinguished[e, d] += 1
                if self.fire.burning_count(e) == 0:
                    last = 1
        return last

    @ti.func
    def record_totals(self, e):
        """Env e's figures for the record's extra columns (:data:`roshan.episode.EXTRA_COLUMNS`, in order)."""
        return self.battery.totals(e)


# The frames' bar of a drone's water, under its battery's (dark = empty): :class:`TankGauge`
TANK_COLOUR = (40, 120, 255)


@ti.data_oriented
class TankGauge:
    """The tank's gauge in the frames (with the water limit): a bar under each drone filled with its water."""

    colour = TANK_COLOUR
    label = "water in its tank (bar)"

    def __init__(self, drones: DroneSim):
        self.drones = drones

    @ti.func
    def fraction(self, e, d) -> ti.f32:
        return ti.math.clamp(self.drones.water[e, d] / self.drones.capacity, 0.0, 1.0)
