"""FlyAgent task kernels: E fire maps with N drones each, stepped by one kernel launch.

One physics step of env e (docs/model/agents.md §2), serially inside the launch: the fire update; then every drone
moves, handles its goal (complex policy: extinguish and take the nearest unreserved fire; simple: reaching the goal is
the objective), is checked for termination and rewarded; then neighbours and collisions are recomputed. One
env step (a control period, docs/model/agents.md §12) runs ``frame_skips`` physics steps with the same actions, fewer if
the episode ends, and then pushes one observation frame. A second launch copies the observation of every env
whose episode ended to ``final_obs`` and resets it (Gymnasium's same-step autoreset,
:class:`roshan.kernels.episode.EpisodeKernels`). The goal rules are :class:`roshan.kernels.tasks.FlyRules`, whose
shared parts the planner level's rules use too.
"""

import math

import numpy as np
import taichi as ti

from roshan.config import FlyConfig
from roshan.episode import BOUNDARY, COLLISION, LOST, TIMEOUT
from roshan.kernels import observe, rng
from roshan.kernels.drones import DroneSim
from roshan.kernels.episode import EpisodeKernels
from roshan.kernels.fire import FireSim
from roshan.kernels.rewards import RewardCoefficients, fly_reward, proximity_sum
from roshan.kernels.tasks import BurningCells, FlyRules


def time_limit(rows: int, cols: int, cell: float, dt: float, v_max: float, fire_percentage: float,
               cfg: FlyConfig) -> int:
    """T_max of docs/model/agents.md §5 for a FlyAgent run (newest: ceil(4 T_phys); thesis-era: 2 T_phys, complex x
    beta1)."""
    diag = cell * math.sqrt(rows**2 + cols**2)
    t_phys = math.ceil(diag / v_max * cfg.k_turn / dt)
    if cfg.time_limit == "newest":
        return math.ceil(4 * t_phys)
    limit = math.ceil(2 * t_phys)
    if cfg.policy == "complex":
        area = rows * cols
        fires = math.ceil(float(np.float32(fire_percentage)) * area)
        limit *= math.ceil(0.32 * math.sqrt(area) * math.sqrt(fires) / v_max)
    return limit


@ti.data_oriented
class FlyKernels(EpisodeKernels):
    """The fused reset and step kernels over a FireSim and a DroneSim."""

    def __init__(self, fire: FireSim, drones: DroneSim, cfg: FlyConfig, t_max: int):
        super().__init__(fire, t_max)
        self.drones, self.cfg = drones, cfg
        self.coef = RewardCoefficients.resolve(cfg.rewards, cfg.policy == "complex", cfg.collision)
        self.is_complex = cfg.policy == "complex"
        self.collision_on = cfg.collision
        self.frames = cfg.frames
        self.frame_skips = cfg.frame_skips
        if not 1 <= cfg.frame_skips <= 16:
            raise ValueError(f"fly.frame_skips = {cfg.frame_skips!r}; expected an integer in [1, 16]")
        # Complex policy with a finite tank: an empty drone flies home and waits there until full.
        self.rules = FlyRules(drones, BurningCells(fire), extinguish=self.is_complex, sticky=cfg.sticky_extinguish)
        self.goal_fire_p = cfg.fire_goal_percentage

    @ti.kernel
    def step(self, actions: ti.types.ndarray(dtype=ti.f32, ndim=3), obs: ti.types.ndarray(dtype=ti.f32, ndim=4),
             rewards: ti.types.ndarray(dtype=ti.f32, ndim=2), dones: ti.types.ndarray(dtype=ti.u8, ndim=2),
             episode: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        ti.loop_config(serialize=self.fire.serial_envs)
        for v in range(self.fire.num_envs * self.fire.env_pad):
            if v % self.fire.env_pad == 0:
                self.step_env(actions, obs, rewards, dones, episode, v // self.fire.env_pad)

    @ti.func
    def new_episode(self, obs: ti.template(), frames: ti.template(), explore_frames: ti.template(), e,
                    seed_key: ti.u32):
        """Reset env e, whose fire is already reset: drones, initial goals, step limit, and a full frame stack
        (``frames``)."""
        dr = self.drones
        dr.place(e)
        k = rng.key(self.fire.env_key[e], rng.DOMAIN_DRONES, 1)
        for d in range(dr.num_drones):
            if rng.uniform(rng.key(k, d, 0)) < self.goal_fire_p:
                self.rules.retarget(e, d)
            else:
                dr.random_corner_goal(e, d, rng.key(k, d, 1))
            dr.prev_dist[e, d] = dr.distance_to_goal(e, d)
        dr.update_neighbours(e)
        for d in range(dr.num_drones):
            observe.fill_frames(frames, dr, e, d, self.frames)
        self.start_counters(e)

    @ti.func
    def step_env(self, actions: ti.template(), obs: ti.template(), rewards: ti.template(), dones: ti.template(),
                 episode: ti.template(), e):
        """One control period of env e (docs/model/agents.md §12): ``frame_skips`` physics steps with the same actions,
        stopping at the step that ends the episode, then one new observation frame. ``rewards`` and ``dones``
        are the last executed step's: like the reference, the rewards of the steps before it are dropped."""
        if ti.static(self.frame_skips == 1):
            self.physics_step(actions, rewards, dones, episode, e, 1)
        else:
            for s in range(self.frame_skips):
                if self.ended[e] == 0:  # 0 on entry: restart() clears it for every env that ended
                    self.physics_step(actions, rewards, dones, episode, e,
                                      ti.cast(s == self.frame_skips - 1, ti.i32))
        for d in range(self.drones.num_drones):
            observe.push_frame(obs, self.drones, e, d, self.frames)

    @ti.func
    def physics_step(self, actions: ti.template(), rewards: ti.template(), dones: ti.template(),
                     episode: ti.template(), e, is_last):
        """One fire update and drone step of env e; the episode return counts the step if ``is_last`` of its
        control period or if the episode ends here (the reward the learner sees)."""
        dr = self.drones
        self.fire.step_env(e)
        self.remaining[e] -= 1
        self.steps[e] += 1
        timed_out = ti.cast(self.remaining[e] <= 0, ti.i32)
        goal_flag = 0  # set by the drone that put out the last fire; pays it and the drones after it
        any_terminal = 0
        any_failed = 0
        last_reason = 0
        real_end = 0  # some drone ended for a reason other than the clock (goal, fires out, crash, exit)
        reward_sum = 0.0
        for d in range(dr.num_drones):
            goal_flag |= self.rules.drone_step(e, d, ti.Vector([actions[e, d, 0], actions[e, d, 1]]))
            succeeded = self.has_succeeded(e, d)
            reason = self.failure_reason(e, d, 0)
            real_end |= ti.cast(reason != 0 or succeeded != 0, ti.i32)
            if timed_out != 0:
                reason = TIMEOUT  # docs/model/agents.md §9: the timeout overwrites the other reasons in the record
            terminal = ti.cast(reason != 0 or succeeded != 0, ti.i32)
            if terminal != 0:
                any_terminal = 1
                if reason != 0:
                    any_failed = 1
                    last_reason = reason
            r = self.reward(e, d, goal_flag, terminal, timed_out)
            rewards[e, d] = r
            reward_sum += r
        dr.update_neighbours(e)
        if is_last != 0 or any_terminal != 0:
            self.ret[e] += reward_sum / dr.num_drones
        dones[e, 0] = ti.u8(0)
        dones[e, 1] = ti.u8(0)
        if any_terminal != 0:
            # A state that really ends the task terminates even on the last allowed step (no bootstrapping
            # from a crash or a success); only a pure time-out truncates.
            self.close_episode(episode, dones, e, 1 - any_failed, last_reason, 1 - real_end)
            self.ended[e] = 1

    @ti.func
    def failure_reason(self, e, d, timed_out) -> ti.i32:
        """docs/model/agents.md §9: later rules overwrite earlier ones (timeout > lost > collision > boundary)."""
        reason = 0
        if self.drones.out_count[e, d] > 1:
            reason = BOUNDARY
        if ti.static(self.collision_on):
            if self.drones.collided[e, d] != 0:
                reason = COLLISION
        if self.drones.is_lost(e, d) != 0:
            reason = LOST
        if timed_out != 0:
            reason = TIMEOUT
        return reason

    @ti.func
    def has_succeeded(self, e, d) -> ti.i32:
        """Simple: reached the goal. Complex: put out the last fire, or nothing burns and no particle lives once a
        fire was lit (an episode without any fire, fire_percentage = 0 and none lit by hand, never succeeds)."""
        success = self.drones.objective[e, d]
        if ti.static(self.is_complex):
            if self.fire.burning_count(e) == 0 and self.fire.particle_count(e) == 0 and self.fire.lit_count(e) > 0:
                success = 1
        return success

    @ti.func
    def reward(self, e, d, goal_flag, terminal, timed_out) -> ti.f32:
        """docs/model/agents.md §8.1 for drone d, with the neighbour list of the previous step (proximity)."""
        dr = self.drones
        dist = dr.distance_to_goal(e, d)
        progress = dr.prev_dist[e, d] - dist
        dr.prev_dist[e, d] = dist
        prox = 0.0
        for j in range(dr.num_drones):
            prox += proximity_sum(dr.neighbours[e, d, j])
        reached = ti.cast(dr.objective[e, d] != 0 or goal_flag != 0, ti.i32)
        left_map = ti.cast(terminal != 0 and dr.is_outside(dr.pos[e, d]) != 0, ti.i32)
        out_of_time = ti.cast(terminal != 0 and timed_out != 0, ti.i32)
        return fly_reward(self.coef, reached, left_map, out_of_time, dr.extinguished[e, d], dr.collided[e, d],
                          progress, prox)
