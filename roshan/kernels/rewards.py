"""FlyAgent (docs/model/agents.md §8) and PlannerAgent (docs/model/agents.md §13.5) reward terms: the one place rewards
are paid.

The presets and the config sections that choose them are in :mod:`roshan.config.agents`.

The coefficients are compile-time constants of the step kernel; :func:`fly_reward` is the ``ti.func`` it
calls once per drone per step.
"""

from dataclasses import dataclass, fields

import taichi as ti

from roshan.config.agents import (
    PLANNER_NEWEST_TERMS,
    PLANNER_PRESETS,
    PLANNER_RESOURCE_TERMS,
    PRESETS,
    PlannerRewardConfig,
    RewardConfig,
)

PROXIMITY_THRESHOLD = 0.1  # normalised neighbour offset below which the proximity term counts


@dataclass(frozen=True)
class RewardCoefficients:
    """Resolved coefficients; which terms apply follows the policy and collision switches (thesis 4.2.4)."""

    goal: float
    boundary: float
    extinguish: float
    timeout: float
    collision: float
    progress: float
    proximity: float
    is_complex: bool
    has_collision: bool

    @classmethod
    def resolve(cls, cfg: RewardConfig, is_complex: bool, has_collision: bool) -> "RewardCoefficients":
        values = dict(PRESETS[cfg.preset])
        for f in fields(RewardConfig):
            v = getattr(cfg, f.name)
            if f.name != "preset" and v is not None:
                values[f.name] = float(v)
        return cls(**values, is_complex=is_complex, has_collision=has_collision)

    @property
    def mode(self) -> str:
        """R_simple, R_simple_collision, R_complex or R_complex_collision."""
        return f"R_{'complex' if self.is_complex else 'simple'}{'_collision' if self.has_collision else ''}"


@ti.func
def fly_reward(coef: ti.template(), reached: ti.i32, outside_and_terminal: ti.i32, timed_out: ti.i32,
               extinguished: ti.i32, collided: ti.i32, progress: ti.f32, proximity: ti.f32) -> ti.f32:
    """Sum of the present terms for one drone (docs/model/agents.md §8.1).

    ``progress`` is d_{t-1} - d_t (only improvements pay); ``proximity`` the sum of the previous frame's
    neighbour offset components below :data:`PROXIMITY_THRESHOLD`.
    """
    r = 0.0
    if reached != 0:
        r += coef.goal
    if outside_and_terminal != 0:
        r += coef.boundary
    if timed_out != 0:
        r += coef.timeout
    if ti.static(coef.is_complex):
        if extinguished != 0:
            r += coef.extinguish
    if ti.static(coef.has_collision):
        if collided != 0:
            r += coef.collision
        r += coef.proximity * proximity
    if progress > 0.0:
        r += coef.progress * progress
    return r


@ti.func
def proximity_sum(entry) -> ti.f32:
    """Below-threshold components of one neighbour entry (invisible entries are zeros and add nothing)."""
    s = 0.0
    for k in ti.static(range(2)):
        if ti.abs(entry[k]) < PROXIMITY_THRESHOLD:
            s += ti.abs(entry[k])
    return s


# ---------------------------------------------------------------------------------------------- PlannerAgent
@dataclass(frozen=True)
class PlannerCoefficients:
    goal: float
    burned: float
    ground: float
    timeout: float
    same: float
    extinguish: float
    fast: float
    distance: float
    spread: float
    refill: float
    empty: float
    lost: float
    newest: bool

    @classmethod
    def resolve(cls, cfg: PlannerRewardConfig) -> "PlannerCoefficients":
        values = {**PLANNER_PRESETS[cfg.preset], **PLANNER_NEWEST_TERMS, **PLANNER_RESOURCE_TERMS}
        for f in fields(PlannerRewardConfig):
            v = getattr(cfg, f.name)
            if f.name not in ("preset", "version") and v is not None:
                values[f.name] = float(v)
        return cls(**values, newest=cfg.version == "newest")


@ti.func
def planner_outcome_reward(coef: ti.template(), objective: ti.i32, timed_out: ti.i32, terminal: ti.i32,
                           remaining_fraction: ti.f32) -> ti.f32:
    """The exclusive outcome terms of docs/model/agents.md §13.5: GoalReached + FastExtinguish, else TimeOut, else
    MapBurnedTooMuch (burnout, or the fires died out on their own)."""
    r = 0.0
    if objective != 0:
        r = coef.goal + coef.fast * remaining_fraction
    elif timed_out != 0:
        r = coef.timeout
    elif terminal != 0:
        r = coef.burned
    return r


@ti.func
def planner_step_reward(coef: ti.template(), to_ground: ti.f32, duplicates: ti.i32, extinguished: ti.i32,
                        distance_gain: ti.f32, burning_drop: ti.f32, refilled: ti.f32, empty_tanks: ti.i32) -> ti.f32:
    """The terms paid at every planner step. Thesis-era: ``to_ground`` is 1 if any drone's goal is the
    groundstation; newest: the sum over such drones of their water fraction where it exceeds 0.5.
    ``duplicates`` = N - distinct goals (newest: among goals other than the groundstation)."""
    r = coef.ground * to_ground + coef.same * duplicates + coef.extinguish * extinguished
    if ti.static(coef.newest):
        r += coef.distance * distance_gain + coef.spread * burning_drop + coef.refill * refilled
        r += coef.empty * empty_tanks
    return r
