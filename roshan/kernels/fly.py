"""FlyAgent task kernels: E fire maps with N drones each, stepped by one kernel launch.

One physics step of env e (agents.md 2), serially inside the launch: the fire update; then every drone moves,
handles its goal (complex policy: extinguish and take the nearest unreserved fire; simple: reaching the goal is
the objective), is checked for termination and rewarded; then neighbours and collisions are recomputed. One
env step (a control period, agents.md 12) runs ``frame_skips`` physics steps with the same actions, fewer if
the episode ends, and then pushes one observation frame. A second launch copies the observation of every env
whose episode ended to ``final_obs`` and resets it (Gymnasium's same-step autoreset). Resetting in its own
kernel, shared with ``reset()``, compiles the reset code once instead of inlining it into the step kernel too
(a fresh machine compiled the fused version for ~25 s).
"""

import math

import numpy as np
import taichi as ti

from roshan.config import FlyConfig
from roshan.episode import BOUNDARY, COLLISION, TIMEOUT
from roshan.kernels import observe, rng
from roshan.kernels.drones import DroneSim
from roshan.kernels.episode import write_record
from roshan.kernels.fire import N_BURNING, N_CONV, N_RAD, FireSim
from roshan.kernels.rewards import RewardCoefficients, fly_reward, proximity_sum


def time_limit(rows: int, cols: int, cell: float, dt: float, v_max: float, fire_percentage: float,
               cfg: FlyConfig) -> int:
    """T_max of agents.md 5 for a FlyAgent run (newest: ceil(4 T_phys); thesis-era: 2 T_phys, complex x beta1)."""
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
class FlyKernels:
    """The fused reset and step kernels over a FireSim and a DroneSim."""

    def __init__(self, fire: FireSim, drones: DroneSim, cfg: FlyConfig, t_max: int):
        self.fire, self.drones, self.cfg = fire, drones, cfg
        self.coef = RewardCoefficients.resolve(cfg.rewards, cfg.policy == "complex", cfg.collision)
        self.is_complex = cfg.policy == "complex"
        self.collision_on = cfg.collision
        self.sticky = cfg.sticky_extinguish
        self.frames = cfg.frames
        self.frame_skips = cfg.frame_skips
        if not 1 <= cfg.frame_skips <= 16:
            raise ValueError(f"fly.frame_skips = {cfg.frame_skips!r}; expected an integer in [1, 16]")
        # Complex policy with a finite tank: an empty drone flies home and waits there until full.
        self.water_policy = self.is_complex and drones.use_water
        self.t_max = t_max
        self.goal_fire_p = cfg.fire_goal_percentage
        E = fire.num_envs
        self.ended = ti.field(ti.i32, E)  # the episode ended in this step: restart() resets the env
        self.remaining = ti.field(ti.i32, E)  # physics steps left
        self.steps = ti.field(ti.i32, E)  # physics steps so far
        self.ret = ti.field(ti.f32, E)

    def reset_all(self, obs, final_obs, seed_key: int) -> None:
        self.ended.fill(1)
        self.restart(obs, final_obs, seed_key, 0)

    @ti.kernel
    def restart(self, obs: ti.types.ndarray(dtype=ti.f32, ndim=4), final_obs: ti.types.ndarray(dtype=ti.f32, ndim=4),
                seed_key: ti.u32, keep_final: ti.i32):
        """Reset the envs flagged in ``ended``, first copying their observation to ``final_obs``."""
        for v in range(self.fire.num_envs * self.fire.env_pad):
            e = v // self.fire.env_pad
            if v % self.fire.env_pad == 0 and self.ended[e] != 0:
                if keep_final != 0:
                    for d, t, k in ti.ndrange(self.drones.num_drones, self.frames, obs.shape[3]):
                        final_obs[e, d, t, k] = obs[e, d, t, k]
                self.new_episode(obs, e, seed_key)
                self.ended[e] = 0

    @ti.kernel
    def step(self, actions: ti.types.ndarray(dtype=ti.f32, ndim=3), obs: ti.types.ndarray(dtype=ti.f32, ndim=4),
             rewards: ti.types.ndarray(dtype=ti.f32, ndim=2), dones: ti.types.ndarray(dtype=ti.u8, ndim=2),
             episode: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        for v in range(self.fire.num_envs * self.fire.env_pad):
            if v % self.fire.env_pad == 0:
                self.step_env(actions, obs, rewards, dones, episode, v // self.fire.env_pad)

    @ti.func
    def new_episode(self, obs: ti.template(), e, seed_key: ti.u32):
        """Reset env e: fire, drones, initial goals, step limit, and a full frame stack."""
        dr = self.drones
        self.fire.reset_env(e, seed_key)
        dr.place(e)
        k = rng.key(self.fire.env_key[e], rng.DOMAIN_DRONES, 1)
        for d in range(dr.num_drones):
            if rng.uniform(rng.key(k, d, 0)) < self.goal_fire_p:
                dr.next_fire(e, d)
            else:
                dr.random_corner_goal(e, d, rng.key(k, d, 1))
            dr.prev_dist[e, d] = dr.distance_to_goal(e, d)
        dr.update_neighbours(e)
        for d in range(dr.num_drones):
            observe.fill_frames(obs, dr, e, d, self.frames)
        self.remaining[e] = self.t_max
        self.steps[e] = 0
        self.ret[e] = 0.0

    @ti.func
    def step_env(self, actions: ti.template(), obs: ti.template(), rewards: ti.template(), dones: ti.template(),
                 episode: ti.template(), e):
        """One control period of env e (agents.md 12): ``frame_skips`` physics steps with the same actions,
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
            dr.move_drone(e, d, ti.Vector([actions[e, d, 0], actions[e, d, 1]]))
            goal_flag |= self.handle_goal(e, d)
            succeeded = self.has_succeeded(e, d)
            reason = self.failure_reason(e, d, 0)
            real_end |= ti.cast(reason != 0 or succeeded != 0, ti.i32)
            if timed_out != 0:
                reason = TIMEOUT  # agents.md 9: the timeout overwrites the other reasons in the record
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
            dones[e, 0] = ti.cast(real_end, ti.u8)
            dones[e, 1] = ti.cast(1 - real_end, ti.u8)
            write_record(episode, self.fire, e, 1 - any_failed, last_reason, self.steps[e], self.ret[e])
            self.ended[e] = 1

    @ti.func
    def handle_goal(self, e, d) -> ti.i32:
        """agents.md 7: at its goal a complex-policy drone extinguishes and takes the next fire; a simple-policy
        drone has reached its objective. Returns 1 if this drone put out the map's last fire.

        With the water limit (complex policy) a drop that empties the tank sends the drone to the groundstation
        centre (no reservation); it takes the next fire once its tank is full again (agents.md 10.2, 14).
        """
        dr = self.drones
        if ti.static(not self.sticky):
            dr.extinguished[e, d] = 0  # the fix: Extinguish pays on the step water hits a fire only
        last = 0
        going_home = 0
        if ti.static(self.water_policy):
            going_home = dr.refilling[e, d]
            if going_home != 0 and dr.water[e, d] >= dr.capacity:  # refilled in move_drone this step
                dr.refilling[e, d] = 0
                dr.next_fire(e, d)
        if going_home == 0 and dr.at_goal(e, d) != 0:
            if ti.static(self.is_complex):
                if dr.extinguish_here(e, d) != 0:
                    dr.objective[e, d] = 1
                    last = 1
                dr.goal_cell[e, d] = -1
                empty = 0
                if ti.static(self.water_policy):
                    empty = 1 - dr.has_water(e, d)
                if empty != 0:
                    dr.refilling[e, d] = 1
                    dr.goal[e, d] = dr.groundstation_centre(e)
                else:
                    dr.next_fire(e, d)
            else:
                dr.objective[e, d] = 1
        return last

    @ti.func
    def failure_reason(self, e, d, timed_out) -> ti.i32:
        """agents.md 9: later rules overwrite earlier ones (timeout > collision > boundary)."""
        reason = 0
        if self.drones.out_count[e, d] > 1:
            reason = BOUNDARY
        if ti.static(self.collision_on):
            if self.drones.collided[e, d] != 0:
                reason = COLLISION
        if timed_out != 0:
            reason = TIMEOUT
        return reason

    @ti.func
    def has_succeeded(self, e, d) -> ti.i32:
        """Simple: reached the goal. Complex: put out the last fire, or nothing burns and no particle lives."""
        success = self.drones.objective[e, d]
        if ti.static(self.is_complex):
            fc = ti.static(self.fire.counts)
            if fc[e, N_BURNING] == 0 and fc[e, N_CONV] + fc[e, N_RAD] == 0:
                success = 1
        return success

    @ti.func
    def reward(self, e, d, goal_flag, terminal, timed_out) -> ti.f32:
        """agents.md 8.1 for drone d, with the neighbour list of the previous step (proximity)."""
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
