"""ExploreAgent (docs/model/agents.md §11): the deterministic meander waypoints, how explorers advance along them, and
the per-env fire map that every drone's view overwrites.

Paths depend only on the map size, the number of explorers, the view range and the groundstation corner, so
they are computed once in Python for the four possible corners and uploaded; a step only reads them.
"""

import math

import numpy as np
import taichi as ti

from roshan.kernels.arrays import int32_array
from roshan.kernels.drones import DroneSim
from roshan.kernels.fire import FireSim

VERSIONS = ("newest", "thesis")
INDEX_BOUNDS = ("first", "longest")
NUM_CORNERS = 4  # groundstation cells (1, 1), (1, cols-2), (rows-2, 1), (rows-2, cols-2), in that order


# ---------------------------------------------------------------------------------------------- waypoints


def meander_paths(rows: int, cols: int, n: int, start_xy, vr: int, *, version: str = "newest",
                  reference_quirk: bool = False, cell_size: float = 10.0) -> list[np.ndarray]:
    """The ExploreAgent's waypoints (docs/model/agents.md §11.1): one boustrophedon path per explorer.

    Args:
        rows, cols: map size ``W, H`` in cells.
        n: number of explorers (one stripe each).
        start_xy: explorer 0's start position in grid units (row, col); it picks the sweep directions.
        vr: explorer view range in cells (the newest code uses ``max(vr, 2)``; the thesis-era code needs >= 2).
        version: ``"newest"`` (last stripe extends to the map edge, backward edge point ``(x0, y)``) or
            ``"thesis"`` (last stripe capped at ``x0 + sw``, backward edge point ``(x0, y - 1)``).
        reference_quirk: compare the start in metres (``start_xy * cell_size``) against half the map size in
            cells, as the reference does; by default grid units are compared, so the sweep starts on the
            groundstation's side.
        cell_size: metres per cell, only used with ``reference_quirk``.

    Returns:
        ``n`` int32 arrays of shape (L_i, 2): integer grid coordinates (cell corners, row then column), which
        may lie on the far map edge. Explorer 0's path is never longer than the others'.
    """
    if version not in VERSIONS:
        raise ValueError(f"version must be one of {', '.join(VERSIONS)}, got {version!r}")
    if n < 1:
        raise ValueError(f"number of explorers must be >= 1, got {n}")
    if version == "newest":
        vr = max(vr, 2)
    elif vr < 2:
        raise ValueError(f"the thesis-era meander divides by view_range - 1: view_range must be >= 2, got {vr}")
    scale = cell_size if reference_quirk else 1.0
    x_inc = start_xy[0] * scale < rows / 2
    y_inc = start_xy[1] * scale < cols / 2
    if rows >= cols:  # vertical stripes along the rows axis; meander lines indexed by the column
        stripes = _stripe_paths(rows, cols, n, vr, x_inc, y_inc, version)
        return [np.asarray(p, np.int32).reshape(-1, 2) for p in stripes]
    # horizontal stripes along the columns axis; lines indexed by the row; points come out as (col, row)
    stripes = _stripe_paths(cols, rows, n, vr, y_inc, x_inc, version)
    return [np.asarray(p, np.int32).reshape(-1, 2)[:, ::-1].copy() for p in stripes]


def _stripe_paths(size: int, lines_size: int, n: int, vr: int, sweep_inc: bool, lines_inc: bool,
                  version: str) -> list[list[tuple[int, int]]]:
    """Paths as (stripe-axis, line-axis) pairs: ``size`` is split into ``n`` stripes, each swept back and forth
    along meander lines ``0, step, ... <= lines_size`` (or from ``lines_size`` down)."""
    sw = size // n
    if sw < 1:
        raise ValueError(f"{n} explorers on a map side of {size} cells: stripes would be empty")
    s_step = max(1, sw // math.ceil(sw / (vr - 1)))
    l_step = max(1, lines_size // math.ceil(lines_size / (vr - 1)))
    lines = range(0, lines_size + 1, l_step) if lines_inc else range(lines_size, -1, -l_step)
    paths = []
    for i in range(n):
        s0 = i * sw
        s1 = size if (version == "newest" and i == n - 1) else min(s0 + sw, size)
        has_edge = (s1 - s0) % s_step != 0
        forward = sweep_inc
        path = []
        for line in lines:
            if forward:
                path += [(s, line) for s in range(s0, s1 + 1, s_step)]
                if has_edge:
                    path.append((s1 - 1, line))
            else:
                path += [(s, line) for s in range(s1, s0 - 1, -s_step)]
                if has_edge:
                    path.append((s0, line) if version == "newest" else (s0, line - 1))
            forward = not forward
        paths.append(path)
    return paths


def meander_length(rows: int, cols: int, n: int, vr: int, version: str = "newest") -> int:
    """The longest explorer path over the four groundstation corners (the waypoint table's length), from starts at
    the corner cells' centres: what ExploreMaps's table holds, give or take the explorers' start offset."""
    return max(len(p) for ci, cj in corner_cells(rows, cols)
               for p in meander_paths(rows, cols, n, (ci + 0.5, cj + 0.5), vr, version=version))


def corner_cells(rows: int, cols: int) -> list[tuple[int, int]]:
    """The four possible groundstation cells (docs/model/agents.md §4.1), indexed by corner id
    ``2 * (row != 1) + (col != 1)``."""
    return [(1, 1), (1, cols - 2), (rows - 2, 1), (rows - 2, cols - 2)]


def covered_cells(paths, rows: int, cols: int, vr: int) -> np.ndarray:
    """Cells an explorer sees when flying the paths: (rows, cols) bool.

    A drone at grid point ``p`` sees the square of half width ``floor(vr / 2)`` around its integer cell
    ``floor(p)`` (docs/model/agents.md §11.3). Samples are every waypoint and points every 0.25 cells (or closer) along
    the straight segments between consecutive waypoints of each path.
    """
    h = vr // 2
    samples = []
    for path in paths:
        p = np.asarray(path, np.float64).reshape(-1, 2)
        samples.append(p)
        for a, b in zip(p[:-1], p[1:], strict=True):
            k = max(1, math.ceil(np.linalg.norm(b - a) / 0.25))
            samples.append(a + np.linspace(0.0, 1.0, k + 1)[:, None] * (b - a))
    cells = np.floor(np.concatenate(samples)).astype(np.int64) + h  # centre c lands at index c + h
    keep = (cells[:, 0] >= 0) & (cells[:, 0] < rows + 2 * h) & (cells[:, 1] >= 0) & (cells[:, 1] < cols + 2 * h)
    hit = np.zeros((rows + 2 * h + 1, cols + 2 * h + 1), np.int64)  # leading zero row/col for the prefix sums
    hit[cells[keep, 0] + 1, cells[keep, 1] + 1] = 1
    s = hit.cumsum(0).cumsum(1)
    w = 2 * h + 1  # cell i is seen from centres i - h .. i + h, i.e. indices i .. i + 2h
    box = s[w:, w:] - s[:-w, w:] - s[w:, :-w] + s[:-w, :-w]
    return box > 0


# ---------------------------------------------------------------------------------------------- kernels


@ti.data_oriented
class ExploreMaps:
    """Fire map and meander waypoints of E envs (docs/model/agents.md §11).

    Args:
        fire: the simulator whose burning cells are observed.
        drones: the explorer group (a DroneSim with ``num_drones == n_explorers``); its groundstation picks
            the corner at reset and its ring offset gives explorer 0's start.
        n_explorers: number of explorers (stripes).
        view_range: explorer view range in cells: meander spacing, and the half width ``floor(vr / 2)`` of
            :meth:`observe`.
        version: meander of the ``"newest"`` or ``"thesis"``-era code (see :func:`meander_paths`).
        reference_quirk: sweep directions from the reference's metres-vs-cells comparison.
        cyclic: advance the index cyclically (thesis-era) instead of back and forth (newest); ``None`` = follow
            ``version``.
        index_bound: ``"first"`` (the reference): explorer 0's path length bounds the shared index, so the
            trailing waypoints of the newest code's wider last stripe are never flown and some cells are never
            seen; ``"longest"``: the longest path bounds it and explorers with shorter paths wait at their last
            waypoint, so the whole map is covered.

    Fields: ``fire_map`` (E, rows, cols) i8 (1 = seen burning when last seen), ``known_fires`` (E,) number of
    ones in it, ``corner`` (E,), ``wp_index`` (E,) next waypoint, ``wp_dir`` (E,) +1 / -1, ``assigned`` (E,)
    the waypoint the explorers fly to now.
    """

    def __init__(self, fire: FireSim, drones: DroneSim, n_explorers: int, view_range: int, *,
                 version: str = "newest", reference_quirk: bool = False, cyclic: bool | None = None,
                 index_bound: str = "first"):
        if drones.num_drones != n_explorers:
            raise ValueError(f"explorer DroneSim has {drones.num_drones} drones, expected n_explorers={n_explorers}")
        if drones.fire is not fire:
            raise ValueError("the explorer DroneSim must share this FireSim")
        if index_bound not in INDEX_BOUNDS:
            raise ValueError(f"index_bound must be one of {', '.join(INDEX_BOUNDS)}, got {index_bound!r}")
        if view_range < 1:
            raise ValueError(f"view_range must be >= 1, got {view_range}")
        self.fire, self.drones = fire, drones
        self.num_envs, self.rows, self.cols = fire.num_envs, fire.rows, fire.cols
        self.n_explorers = n_explorers
        self.view_range = view_range
        self.half = view_range // 2
        self.cyclic = (version == "thesis") if cyclic is None else bool(cyclic)
        # Explorer 0 spawns at ring angle 0: ring metres along the row axis from the groundstation centre.
        offset = drones.ring / drones.cell if n_explorers > 1 else 0.0
        self.paths = []  # per corner: the n paths
        for ci, cj in corner_cells(self.rows, self.cols):
            start = (ci + 0.5 + offset, cj + 0.5)
            self.paths.append(meander_paths(self.rows, self.cols, n_explorers, start, view_range, version=version,
                                            reference_quirk=reference_quirk, cell_size=drones.cell))
        self.lengths = np.array([[len(p) for p in corner] for corner in self.paths], np.int32)
        self.max_len = int(self.lengths.max())
        self.index_len = self.lengths[:, 0] if index_bound == "first" else self.lengths.max(axis=1)
        table = np.zeros((NUM_CORNERS, n_explorers, self.max_len, 2), np.int32)
        for c, corner in enumerate(self.paths):
            for d, p in enumerate(corner):
                table[c, d, : len(p)] = p
                table[c, d, len(p) :] = p[-1]

        E = self.num_envs
        self.fire_map = ti.field(ti.i8, (E, self.rows, self.cols))
        self.known_fires = ti.field(ti.i32, E)
        self.waypoints = ti.Vector.field(2, ti.i32, (NUM_CORNERS, n_explorers, self.max_len))
        self.path_len = ti.field(ti.i32, (NUM_CORNERS, n_explorers))
        self.bound = ti.field(ti.i32, NUM_CORNERS)  # waypoint count the shared index walks over, per corner
        self.corner = ti.field(ti.i32, E)
        self.wp_index = ti.field(ti.i32, E)
        self.wp_dir = ti.field(ti.i32, E)
        self.assigned = ti.field(ti.i32, E)
        self.waypoints.from_numpy(table)
        self.path_len.from_numpy(self.lengths)
        self.bound.from_numpy(np.ascontiguousarray(self.index_len, np.int32))
        self._all = np.ones(E, dtype=np.int32)

    # ------------------------------------------------------------------------------------------ public API

    def reset(self, mask=None) -> None:
        """Clear the fire map and restart the meander in the masked envs (after the explorers' reset)."""
        mask = self._all if mask is None else int32_array(mask, (self.num_envs,), "reset mask")
        self._reset(mask)

    def observe_kernel(self, group: DroneSim | None = None) -> None:
        """Every drone of ``group`` (default: the explorers) marks its view in the fire map (tests, scripts)."""
        self._observe(self.drones if group is None else group)

    def advance_kernel(self) -> None:
        """Advance the waypoints of every env whose explorers all reached theirs (tests, scripts)."""
        self._advance()

    @property
    def fire_map_tensor(self):
        """A torch copy of the fire map, (E, rows, cols) int8 (not for the step loop)."""
        return self.fire_map.to_torch()

    def memory_bytes_per_env(self) -> int:
        return self.rows * self.cols + 4 * 5

    @staticmethod
    def field_bytes(num_envs: int, rows: int, cols: int, n_explorers: int, max_len: int) -> int:
        """Bytes of the fields (and host arrays) ExploreMaps allocates, known before it is built: per env the fire
        map and five counters (and ``_all``); shared, the waypoint table of ``max_len`` waypoints per path
        (:func:`meander_length`) and the path lengths, twice (the simulator pool keeps a copy to restore them)."""
        shared = NUM_CORNERS * n_explorers * (8 * max_len + 4) + 4 * NUM_CORNERS
        return num_envs * (rows * cols + 4 * 5 + 4) + 2 * shared

    # ------------------------------------------------------------------------------------------ kernels

    @ti.kernel
    def _reset(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for e in range(self.num_envs):
            if mask[e] != 0:
                self.reset_env(e, self.drones)

    @ti.kernel
    def _observe(self, group: ti.template()):
        for e in range(self.num_envs):
            self.observe_all(e, group)

    @ti.kernel
    def _advance(self):
        for e in range(self.num_envs):
            self.advance_if_reached(e, self.drones)

    # ------------------------------------------------------------------------------------------ fire map

    @ti.func
    def is_known_fire(self, e, c) -> ti.i32:
        """1 if flat cell c is on env e's fire map."""
        return ti.cast(self.fire_map[e, c // self.cols, c % self.cols] != 0, ti.i32)

    @ti.func
    def forget_fire(self, e, c):
        """A drone put cell c out: take it off the fire map."""
        i = c // self.cols
        j = c % self.cols
        if self.fire_map[e, i, j] != 0:
            self.fire_map[e, i, j] = ti.i8(0)
            self.known_fires[e] -= 1

    @ti.func
    def observe_square(self, e, cx, cy, half: ti.template()):
        """docs/model/agents.md §11.3: overwrite the cells of [cx-half, cx+half] x [cy-half, cy+half] (clipped to the
        map) with 1 if burning now, else 0."""
        fm = ti.static(self.fire_map)
        for i in range(ti.max(cx - half, 0), ti.min(cx + half, self.rows - 1) + 1):
            for j in range(ti.max(cy - half, 0), ti.min(cy + half, self.cols - 1) + 1):
                now = self.fire.is_burning(e, i * self.cols + j)
                before = ti.cast(fm[e, i, j], ti.i32)
                if now != before:
                    fm[e, i, j] = ti.cast(now, ti.i8)
                    self.known_fires[e] += now - before

    @ti.func
    def observe(self, e, cx, cy):
        """The explorer view (half width floor(view_range / 2)) around integer cell (cx, cy)."""
        self.observe_square(e, cx, cy, self.half)

    @ti.func
    def observe_drone(self, e, group: ti.template(), d):
        """Drone d of ``group`` marks the square of its group's view range around its integer cell
        (docs/model/agents.md §3.1: call it right after the drone moved)."""
        p = group.pos[e, d] / group.cell
        self.observe_square(e, ti.cast(ti.floor(p[0]), ti.i32), ti.cast(ti.floor(p[1]), ti.i32),
                            ti.static(group.cfg.view_range // 2))

    @ti.func
    def observe_all(self, e, group: ti.template()):
        """Every drone of ``group`` marks its view (:meth:`observe_drone`)."""
        for d in range(group.num_drones):
            self.observe_drone(e, group, d)

    # ------------------------------------------------------------------------------------------ waypoints

    @ti.func
    def reset_env(self, e, explorers: ti.template()):
        """Clear env e's fire map, pick its corner from the groundstation and give every explorer waypoint 0
        (docs/model/agents.md §11.2: the index then moves to 1)."""
        for i, j in ti.ndrange(self.rows, self.cols):
            self.fire_map[e, i, j] = ti.i8(0)
        self.known_fires[e] = 0
        gs = explorers.bases[e, 0]
        corner = 2 * ti.cast(gs[0] != 1, ti.i32) + ti.cast(gs[1] != 1, ti.i32)
        self.corner[e] = corner
        self.wp_dir[e] = 1
        self.assigned[e] = 0
        self.wp_index[e] = ti.min(1, self.bound[corner] - 1)
        self.assign_waypoints(e, explorers)

    @ti.func
    def assign_waypoints(self, e, explorers: ti.template()):
        """Set every explorer's goal to its waypoint number ``assigned[e]`` (its last one if its path is shorter)."""
        corner = self.corner[e]
        k = self.assigned[e]
        for d in range(self.n_explorers):
            wp = self.waypoints[corner, d, ti.min(k, self.path_len[corner, d] - 1)]
            explorers.goal[e, d] = ti.cast(wp, ti.f32)
            explorers.goal_cell[e, d] = -1
            explorers.prev_dist[e, d] = explorers.distance_to_goal(e, d)

    @ti.func
    def advance_if_reached(self, e, explorers: ti.template()) -> ti.i32:
        """docs/model/agents.md §11.2: once all explorers are within 0.25 cells (per axis) of their waypoints, give them
        waypoint ``wp_index`` and move the index on, within the bound set by ``index_bound``. Returns 1 if the
        explorers got new waypoints."""
        reached = 1
        for d in range(self.n_explorers):
            if explorers.at_goal(e, d) == 0:
                reached = 0
        if reached != 0:
            k = self.wp_index[e]
            last = self.bound[self.corner[e]] - 1
            self.assigned[e] = k
            self.assign_waypoints(e, explorers)
            if ti.static(self.cyclic):
                self.wp_index[e] = ti.select(k >= last, 0, k + 1)
            elif self.wp_dir[e] > 0:  # ping-pong: at an end only the direction flips
                if k >= last:
                    self.wp_dir[e] = -1
                else:
                    self.wp_index[e] = k + 1
            elif k <= 0:
                self.wp_dir[e] = 1
            else:
                self.wp_index[e] = k - 1
        return reached
