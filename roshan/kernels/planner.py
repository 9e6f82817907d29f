"""PlannerAgent level (docs/model/agents.md §10.2, §11, §13): goal assignment, the low-level steps of planner drones and
explorers, planner rewards, termination and the planner observation, batched over envs.

One planner step of env e is ``apply`` (the chosen candidates become the drones' goals), ``interval`` calls of
``low_step`` (the fire, the explorers and the planner drones each advance once; the env's Python side runs the
frozen FlyAgent policies in between), then ``finish`` (reward, termination, a fresh observation). With the
greedy controller (the heuristic baseline of docs/model/agents.md §10.2) ``apply`` is skipped, the drones pick their own
goals inside ``low_step`` and an episode may end at any low-level step. The low-level drone step and its goal
rules are :class:`roshan.kernels.tasks.PlannerDroneRules` and :class:`~roshan.kernels.tasks.GreedyRules`, which share
their parts with the FlyAgent level's; this module adds the decisions, the planner rewards and termination on top.

Deliberate differences from the reference (docs/model/agents.md §13.1, §13.5):
- the observation is built after the interval from the state it ends in (the reference shows the planner the
  fires of the previous decision and goals of the one before: the stale-observation defect);
- the reward of a decision pays what happened in the interval it started (extinguished cells, spread), not
  the interval before it.

The planner observation is one flat float row per env (see :func:`obs_layout`): drone positions, goals, water
fraction, the candidate list (index 0 = groundstation, then fire cells in row-major order), its validity mask
and 5 global features. Positions are normalised by the map: ``2 q / max(rows, cols) - 1``.
"""

import math

import numpy as np
import taichi as ti

from roshan.config import DroneConfig, PlannerConfig
from roshan.episode import BURNOUT, LOST, TIMEOUT
from roshan.kernels import observe
from roshan.kernels.battery import NoReturn
from roshan.kernels.drones import DroneSim
from roshan.kernels.episode import EpisodeKernels
from roshan.kernels.explore import ExploreMaps
from roshan.kernels.fire import FireSim
from roshan.kernels.rewards import PlannerCoefficients, planner_outcome_reward, planner_step_reward
from roshan.kernels.tasks import BurningCells, GreedyRules, KnownFires, PlannerDroneRules

GROUND_GOAL = -2  # goal_cell of a drone sent to the groundstation by the planner


def planner_time_limit(rows: int, cols: int, cell: float, dt: float, v_max: float, fire_percentage: float,
                       version: str, k_turn: float = 1.5) -> int:
    """T_max of a planner or heuristic episode (docs/model/agents.md §5): newest ``max(t_move + F, ceil(4 T_phys))``
    with ``beta = 0.42``; thesis-era ``max(ceil((t_move + F dt) / dt), ceil(2 T_phys))`` with ``beta = 0.3``."""
    area = rows * cols
    fires = math.ceil(float(np.float32(fire_percentage)) * area)
    t_phys = math.ceil(cell * math.sqrt(rows**2 + cols**2) / v_max * k_turn / dt)
    if version == "newest":
        length = 0.42 * math.sqrt(area * cell**2) * math.sqrt(fires)
        return max(math.ceil(length / v_max / dt) + fires, math.ceil(4 * t_phys))
    length = 0.3 * math.sqrt(area * cell**2) * math.sqrt(fires)
    return max(math.ceil((length / v_max + fires * dt) / dt), math.ceil(2 * t_phys))


def candidate_count(pc: PlannerConfig, drones: DroneConfig, num_cells: int) -> int:
    """K, the length of the candidate list: ``planner.max_candidates``, or with 0 every cell after the bases
    (``drones.bases`` of them, the list's first entries). A list too short to hold every base is refused."""
    if pc.max_candidates and pc.max_candidates < drones.bases:
        raise ValueError(f"planner.max_candidates = {pc.max_candidates} is fewer than the bases (drones.bases = "
                         f"{drones.bases}), which the candidate list starts with: set at least {drones.bases}, "
                         "or 0 for every cell")
    return pc.max_candidates or num_cells + drones.bases


# Every part of the planner observation in the order of the flat row: name -> (shape per row with n drones and k
# candidates, low, high). Positions leave [-1, 1] when a drone leaves the map; the globals' fire count is -2 .. 1.
def obs_parts(drones: DroneConfig, max_candidates: int) -> dict[str, tuple[tuple[int, ...], float, float]]:
    """The planner observation's parts for ``drones`` (its count and whether it carries a battery) and
    ``max_candidates`` K: name -> (shape, low, high). With a battery each drone's charge and the charge its quickest
    flight home needs, both as fractions of a full battery, follow the water."""
    n, k = drones.num_drones, max_candidates
    return {"drones": ((n, 2), -math.inf, math.inf), "goals": ((n, 2), -1.0, 1.0), "water": ((n, 1), 0.0, 1.0),
            **({"energy": ((n, 2), 0.0, 1.0)} if drones.energy.enabled else {}),
            "fires": ((k, 2), -1.0, 1.0), "fires_mask": ((k,), 0.0, 1.0), "globals": ((5,), -2.0, 1.0)}


def obs_layout(drones: DroneConfig, max_candidates: int) -> dict[str, tuple[int, int]]:
    """(start, end) column of every part of :func:`obs_parts` in the flat row."""
    out, start = {}, 0
    for name, (shape, _, _) in obs_parts(drones, max_candidates).items():
        out[name] = (start, start + math.prod(shape))
        start = out[name][1]
    return out


@ti.data_oriented
class PlannerKernels(EpisodeKernels):
    """The planner level over a FireSim, the planner drones and the explorer drones of the same envs.

    Args:
        fire, drones, explorers: the simulator and the two drone groups (same envs).
        maps: the fire map and meander waypoints (its drone group is ``explorers``).
        pc: the planner section (``interval``: low-level steps per planner step; ``rewards``; ``burnout``;
            ``max_candidates``: length K of the candidate list, bases included (:func:`candidate_count`);
            ``train_fires`` / ``eval_fires``; ``greedy_home``; the return rule of each controller,
            ``greedy_resources`` / ``planner_resources`` with ``greedy_energy_margin`` and ``return_queue``).
        controller: ``planner`` (the drones fly the planner's goals) or ``greedy`` (the heuristic state machine of
            docs/model/agents.md §10.2).
        evaluation: the explorers fly (in planner training they stay at the groundstation) and the candidates are
            ``pc.eval_fires``; the heuristic always flies them and lists the fire map's cells.
        t_max: low-level step limit of an episode.
        fly_frames, explore_frames: stacked FlyAgent frames of each group's policy.
    """

    def __init__(self, fire: FireSim, drones: DroneSim, explorers: DroneSim, maps: ExploreMaps, pc: PlannerConfig, *,
                 controller: str, evaluation: bool, t_max: int, fly_frames: int, explore_frames: int):
        super().__init__(fire, t_max)
        self.drones, self.explorers, self.maps = drones, explorers, maps
        self.interval, self.coef = pc.interval, PlannerCoefficients.resolve(pc.rewards)
        self.greedy = controller == "greedy"
        self.move_explorers = evaluation or self.greedy
        # the candidates: the fire map's cells (fires some drone has seen) or all burning cells (centralised training)
        self.detected = (pc.eval_fires if evaluation else pc.train_fires) == "detected" or self.greedy
        self.burnout = pc.burnout  # burned-out fraction of the map that fails the episode
        self.K = max_candidates = candidate_count(pc, drones.cfg, fire.num_cells)
        self.bases = drones.num_bases  # candidates 0 .. bases - 1 are the bases, the fires follow
        self.fly_frames, self.explore_frames = fly_frames, explore_frames
        self.use_water, self.use_energy = drones.use_water, drones.use_energy
        self.layout = obs_layout(drones.cfg, max_candidates)
        self.o_drones, self.o_goals, self.o_water, self.o_fires, self.o_mask, self.o_globals = (
            self.layout[k][0] for k in ("drones", "goals", "water", "fires", "fires_mask", "globals"))
        self.o_energy = self.layout["energy"][0] if self.use_energy else 0
        self.norm = 2.0 / max(fire.rows, fire.cols)  # norm(q) = q * norm - 1
        self.log_cells = math.log(1.0 + fire.num_cells)
        # The return rule: with a battery and the controller's setting, a drone flies home on its own once its battery
        # or tank runs low and stays there until stocked (for the planner's drones, choosing the groundstation for one
        # short of either sends it home too, and the planner's goals for it count again once it is stocked).
        aware = pc.greedy_resources if self.greedy else pc.planner_resources
        self.returns = (drones.battery.return_rule(pc.greedy_energy_margin, pc.return_queue) if aware
                        else NoReturn())
        # The low level: the heuristic's drones pick known fires themselves; planner drones drop water on every
        # burning cell they fly over (docs/model/agents.md §7) and keep the planner's goals.
        landing = drones.battery.landing_rule()
        if self.greedy:
            self.rules = GreedyRules(drones, KnownFires(fire, maps), maps, returns=self.returns, landing=landing,
                                     wake_reserved=pc.greedy_home == "original")
        else:
            self.rules = PlannerDroneRules(drones, BurningCells(fire), maps, returns=self.returns, landing=landing)
        E, N = fire.num_envs, drones.num_drones
        self.finished = ti.field(ti.i32, E)  # greedy: ended inside this planner step, skip the rest of it
        self.objective = ti.field(ti.i32, E)  # a drone put out the last burning cell in this planner step
        self.ext_count = ti.field(ti.i32, E)  # cells extinguished in this planner step
        self.step_terms = ti.field(ti.f32, E)  # goal-dependent reward terms of the current decision
        self.mean_dist = ti.field(ti.f32, E)  # newest DistanceProgress: mean goal distance after the last decision
        self.prev_burning = ti.field(ti.i32, E)
        self.decisions = ti.field(ti.i32, E)  # planner steps in this episode
        self.prev_water = ti.field(ti.f32, (E, N))
        self.prev_lost = ti.field(ti.i32, E)  # drones down at the previous decision (DroneLost pays the new ones)
        self.cand_cell = ti.field(ti.i32, (E, max_candidates))  # flat cell of candidate k (k >= bases)
        self.cand_count = ti.field(ti.i32, E)  # valid candidates, bases included

    @staticmethod
    def field_bytes(num_envs: int, num_drones: int, max_candidates: int) -> int:
        """Bytes of the fields PlannerKernels allocates (the episode fields included), known before it is built."""
        per_env = 9 * 4 + 4 * num_drones + 4 * max_candidates  # scalars, prev_water, cand_cell
        return EpisodeKernels.field_bytes(num_envs) + num_envs * per_env

    # ------------------------------------------------------------------------------------------ kernels

    @ti.kernel
    def apply(self, actions: ti.types.ndarray(dtype=ti.i64, ndim=2)):
        """The planner's candidate indices become the drones' goals; the goal-dependent reward terms are
        evaluated now, on the decision itself (docs/model/agents.md §13.5)."""
        ti.loop_config(serialize=self.fire.serial_envs)
        for e in range(self.fire.num_envs):
            self.assign_goals(actions, e)

    @ti.kernel
    def low_step(self, act_fly: ti.types.ndarray(dtype=ti.f32, ndim=3),
                 act_explore: ti.types.ndarray(dtype=ti.f32, ndim=3), obs_fly: ti.types.ndarray(dtype=ti.f32, ndim=4),
                 obs_explore: ti.types.ndarray(dtype=ti.f32, ndim=4), rewards: ti.types.ndarray(dtype=ti.f32, ndim=1),
                 dones: ti.types.ndarray(dtype=ti.u8, ndim=2), episode: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        ti.loop_config(serialize=self.fire.serial_envs)
        for v in range(self.fire.num_envs * self.fire.env_pad):
            e = v // self.fire.env_pad
            if v % self.fire.env_pad == 0 and self.finished[e] == 0:
                self.low_step_env(act_fly, act_explore, obs_fly, obs_explore, rewards, dones, episode, e)

    @ti.kernel
    def finish(self, obs: ti.types.ndarray(dtype=ti.f32, ndim=2), rewards: ti.types.ndarray(dtype=ti.f32, ndim=1),
               dones: ti.types.ndarray(dtype=ti.u8, ndim=2), episode: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """End of a planner step: reward and termination (planner controller), then a fresh observation."""
        ti.loop_config(serialize=self.fire.serial_envs)
        for e in range(self.fire.num_envs):
            if ti.static(not self.greedy):
                self.planner_outcome(rewards, dones, episode, e)
            if self.finished[e] != 0:
                self.ended[e] = 1
            self.finished[e] = 0
            self.build_obs(obs, e)

    @ti.kernel
    def begin(self, rewards: ti.types.ndarray(dtype=ti.f32, ndim=1), dones: ti.types.ndarray(dtype=ti.u8, ndim=2)):
        """Clear the per-step outputs and counters before the low-level steps of a planner step."""
        ti.loop_config(serialize=self.fire.serial_envs)
        for e in range(self.fire.num_envs):
            rewards[e] = 0.0
            dones[e, 0] = ti.u8(0)
            dones[e, 1] = ti.u8(0)
            self.objective[e] = 0
            self.ext_count[e] = 0
            self.finished[e] = 0

    # ------------------------------------------------------------------------------------------ episodes

    @ti.func
    def new_episode(self, obs: ti.template(), obs_fly: ti.template(), obs_explore: ti.template(), e,
                    seed_key: ti.u32):
        """docs/model/agents.md §4 (the fire is already reset): groundstation, drones (planner drones towards the
        nearest true fires, or the groundstation for the heuristic, whose fire map is empty), explorers on their
        first waypoint."""
        dr, ex = self.drones, self.explorers
        dr.place(e)
        ex.place(e)
        self.maps.reset_env(e, ex)
        for d in range(dr.num_drones):
            if ti.static(self.greedy):
                dr.goal[e, d] = dr.head_home(e, d)
                dr.goal_cell[e, d] = -1
            else:
                self.rules.retarget(e, d)
            dr.prev_dist[e, d] = dr.distance_to_goal(e, d)
            self.prev_water[e, d] = dr.water[e, d]
        dr.update_neighbours(e)
        ex.update_neighbours(e)
        self.maps.observe_all(e, ex)  # what the drones see where they start
        self.maps.observe_all(e, dr)
        for d in range(dr.num_drones):
            observe.fill_frames(obs_fly, dr, e, d, self.fly_frames)
        for d in range(ex.num_drones):
            observe.fill_frames(obs_explore, ex, e, d, self.explore_frames)
        self.start_counters(e)
        self.decisions[e] = 0
        self.finished[e] = 0
        self.prev_lost[e] = 0
        self.prev_burning[e] = self.fire.burning_count(e)
        self.mean_dist[e] = self.mean_goal_distance(e)
        self.build_obs(obs, e)

    @ti.func
    def record_episode(self, episode: ti.template(), dones: ti.template(), e, success, reason):
        """Write env e's episode record; a pure timeout truncates, every other end terminates."""
        self.close_episode(episode, dones, e, success, reason, ti.cast(reason == TIMEOUT, ti.i32))
        self.finished[e] = 1

    @ti.func
    def end_reason(self, e, timed_out) -> ti.types.vector(2, ti.i32):
        """docs/model/agents.md §13.6 (later rules overwrite the reason): (terminal, reason)."""
        terminal = self.objective[e]
        reason = 0
        if ti.cast(self.fire.burned_count(e), ti.f32) > self.burnout * self.fire.num_cells:
            terminal = 1
            reason = BURNOUT
        if self.drones.battery.all_lost(e) != 0:
            terminal = 1
            reason = LOST  # every drone came down with an empty battery
        if timed_out != 0:
            terminal = 1
            reason = TIMEOUT
        if self.fire.burning_count(e) == 0 and self.fire.lit_count(e) > 0:
            terminal = 1  # put out, or burned down on its own (a fire there was: no fire is no success)
        return ti.Vector([terminal, reason])

    @ti.func
    def planner_outcome(self, rewards: ti.template(), dones: ti.template(), episode: ti.template(), e):
        """Reward and termination of a planner decision after its interval."""
        self.remaining[e] -= self.interval
        self.decisions[e] += 1
        timed_out = ti.cast(self.remaining[e] <= 0, ti.i32)
        end = self.end_reason(e, timed_out)
        frac = ti.max(ti.cast(self.remaining[e], ti.f32), 0.0) / self.t_max
        r = planner_outcome_reward(self.coef, self.objective[e], timed_out, end[0], frac)
        burning = self.fire.burning_count(e)
        drop = ti.cast(self.prev_burning[e] - burning, ti.f32)
        self.prev_burning[e] = burning
        refilled = 0.0
        empty = 0
        dr = self.drones
        for d in range(dr.num_drones):
            if ti.static(self.use_water):
                refilled += ti.max(0.0, dr.water[e, d] - self.prev_water[e, d]) / dr.capacity
                empty += ti.cast(dr.water[e, d] <= 0.0, ti.i32)
            self.prev_water[e, d] = dr.water[e, d]
        r += self.step_terms[e] + planner_step_reward(self.coef, 0.0, 0, self.ext_count[e], 0.0, drop, refilled,
                                                      empty)
        if ti.static(self.use_energy):  # a term of the reward with a battery only (adding 0 would turn -0.0 into 0.0)
            lost = dr.battery.lost_count(e)
            r += self.coef.lost * (lost - self.prev_lost[e])  # DroneLost, for the drones down in this decision
            self.prev_lost[e] = lost
        rewards[e] = r
        self.ret[e] += r
        if end[0] != 0:
            self.record_episode(episode, dones, e, ti.cast(end[1] == 0, ti.i32), end[1])

    # ------------------------------------------------------------------------------------------ decisions

    @ti.func
    def assign_goals(self, actions: ti.template(), e):
        """docs/model/agents.md §13.4: candidate b < ``drones.bases`` is base b (candidate 0 the groundstation), any
        index past the valid list the drone's nearest base, and the others the listed fires."""
        dr = self.drones
        for d in range(dr.num_drones):
            k = ti.cast(actions[e, d], ti.i32)
            if self.returns.keeps_goal(e, d) != 0:
                continue  # on its way home or waiting there: its goal stays until it is stocked
            if k < self.bases or k >= self.cand_count[e]:
                self.returns.send_home(e, d)  # short of a full battery or tank, it stays there until stocked
            if k >= self.bases and k < self.cand_count[e]:
                c = self.cand_cell[e, k]
                dr.goal_cell[e, d] = c
                dr.goal[e, d] = dr.cell_centre(c)
            else:
                dr.goal_cell[e, d] = GROUND_GOAL
                dr.goal[e, d] = dr.head_home(e, d)  # its nearest base
                if k >= 0 and k < self.bases:  # a base the planner named: that one becomes its home
                    dr.home[e, d] = k
                    dr.goal[e, d] = dr.home_centre(e, d)
            dr.prev_dist[e, d] = dr.distance_to_goal(e, d)
        # FlyingTowardsGroundStation and SameGoalPenalty judge this decision.
        to_ground = 0.0
        duplicates = 0
        for d in range(dr.num_drones):
            ground = ti.cast(dr.goal_cell[e, d] == GROUND_GOAL, ti.i32)
            if ti.static(self.coef.newest):
                w = 1.0
                if ti.static(self.use_water):
                    w = ti.min(dr.water[e, d] / dr.capacity, 1.0)
                if ground != 0 and w > 0.5:
                    to_ground += w
            elif ground != 0:
                to_ground = 1.0
            skip = 0
            if ti.static(self.coef.newest):
                skip = ground  # the newest code lets several drones wait at the groundstation
            skip = ti.max(skip, self.returns.keeps_goal(e, d))  # flying home to restock: no fire shared with anyone
            if skip == 0:
                for j in range(d):  # a duplicate if an earlier drone has the same goal
                    if dr.goal_cell[e, j] == dr.goal_cell[e, d]:
                        duplicates += 1
                        break
        gain = 0.0
        if ti.static(self.coef.newest):
            m = self.mean_goal_distance(e)
            if self.decisions[e] > 0:
                gain = self.mean_dist[e] - m
            self.mean_dist[e] = m
        self.step_terms[e] = planner_step_reward(self.coef, to_ground, duplicates, 0, gain, 0.0, 0.0, 0)

    @ti.func
    def mean_goal_distance(self, e) -> ti.f32:
        dr = self.drones
        s = 0.0
        for d in range(dr.num_drones):
            s += dr.distance_to_goal(e, d)
        return s / dr.num_drones / max(self.fire.rows, self.fire.cols)

    # ------------------------------------------------------------------------------------------ low level

    @ti.func
    def low_step_env(self, act_fly: ti.template(), act_explore: ti.template(), obs_fly: ti.template(),
                     obs_explore: ti.template(), rewards: ti.template(), dones: ti.template(), episode: ti.template(),
                     e):
        """One fire update and one move of every active drone of env e (docs/model/agents.md §2, §13.1)."""
        dr, ex = self.drones, self.explorers
        self.fire.step_env(e)
        self.steps[e] += 1
        if ti.static(self.move_explorers):
            self.maps.advance_if_reached(e, ex)
            for x in range(ex.num_drones):
                ex.move_drone(e, x, ti.Vector([act_explore[e, x, 0], act_explore[e, x, 1]]))
                self.maps.observe_drone(e, ex, x)
            ex.update_neighbours(e)
            for x in range(ex.num_drones):
                observe.push_frame(obs_explore, ex, e, x, self.explore_frames)
        for d in range(dr.num_drones):
            if self.rules.drone_step(e, d, ti.Vector([act_fly[e, d, 0], act_fly[e, d, 1]])) != 0:
                self.objective[e] = 1
            self.ext_count[e] += dr.extinguished[e, d]
        dr.update_neighbours(e)
        for d in range(dr.num_drones):
            observe.push_frame(obs_fly, dr, e, d, self.fly_frames)
        if ti.static(self.greedy):
            self.remaining[e] -= 1
            end = self.end_reason(e, ti.cast(self.remaining[e] <= 0, ti.i32))
            if end[0] != 0:
                self.record_episode(episode, dones, e, ti.cast(end[1] == 0, ti.i32), end[1])

    # ------------------------------------------------------------------------------------------ observation

    @ti.func
    def build_obs(self, obs: ti.template(), e):
        """The planner observation of env e (docs/model/agents.md §13.3) and its candidate list."""
        dr = self.drones
        for d in range(dr.num_drones):
            p = dr.pos[e, d] / dr.cell
            g = dr.goal[e, d]
            for a in ti.static(range(2)):
                obs[e, self.o_drones + 2 * d + a] = p[a] * self.norm - 1.0
                obs[e, self.o_goals + 2 * d + a] = g[a] * self.norm - 1.0
            w = 1.0
            if ti.static(self.use_water):
                w = ti.math.clamp(dr.water[e, d] / dr.capacity, 0.0, 1.0)
            obs[e, self.o_water + d] = w
            dr.battery.observe(obs, e, d, self.o_energy + 2 * d)  # the observation's energy part (with a battery)
        f0 = self.o_fires
        m0 = self.o_mask
        for b in ti.static(range(self.bases)):  # the bases first, in order (candidate 0: the groundstation)
            gs = dr.base_centre(e, b)
            obs[e, f0 + 2 * b] = gs[0] * self.norm - 1.0
            obs[e, f0 + 2 * b + 1] = gs[1] * self.norm - 1.0
            obs[e, m0 + b] = 1.0
        k = self.bases
        cols = self.fire.cols
        centroid = ti.Vector([0.0, 0.0])
        for c in range(self.fire.num_cells):
            listed = 0
            if ti.static(self.detected):
                listed = ti.cast(self.maps.fire_map[e, c // cols, c % cols] != 0, ti.i32)
            else:
                listed = self.fire.is_burning(e, c)
            if listed != 0 and k < self.K:
                centre = dr.cell_centre(c)
                self.cand_cell[e, k] = c
                obs[e, f0 + 2 * k] = centre[0] * self.norm - 1.0
                obs[e, f0 + 2 * k + 1] = centre[1] * self.norm - 1.0
                obs[e, m0 + k] = 1.0
                centroid += centre
                k += 1
        self.cand_count[e] = k
        for j in range(k, self.K):
            obs[e, f0 + 2 * j] = 0.0
            obs[e, f0 + 2 * j + 1] = 0.0
            obs[e, m0 + j] = 0.0
        n_fires = k - self.bases
        g0 = self.o_globals
        obs[e, g0] = ti.math.clamp(ti.log(1.0 + n_fires) / self.log_cells, 0.0, 1.0)
        if n_fires > 0:
            centroid = centroid / n_fires * self.norm - 1.0
        else:
            centroid = ti.Vector([-2.0, -2.0])
        obs[e, g0 + 1] = centroid[0]
        obs[e, g0 + 2] = centroid[1]
        wind = ti.math.clamp(self.fire.wind[e] / 20.0, -1.0, 1.0)
        obs[e, g0 + 3] = wind[0]
        obs[e, g0 + 4] = wind[1]
