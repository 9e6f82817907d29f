"""FlyAgent reward terms and their coefficient sets (agents.md 8): the one place rewards are defined.

The coefficients are compile-time constants of the step kernel; :func:`fly_reward` is the ``ti.func`` it
calls once per drone per step.
"""

from dataclasses import dataclass, fields

import taichi as ti

from roshan.config import choice, num

# Thesis Table 5.3 (defaults), Table 5.4 (best single Optuna trial), Table 5.5 (mean of the top-10 trials).
PRESETS: dict[str, dict[str, float]] = {
    "thesis": {"goal": 1.0, "boundary": -1.0, "extinguish": 0.01, "timeout": -1.0, "collision": -1.0,
               "progress": 0.1, "proximity": -0.05},
    "optuna_best": {"goal": 0.230, "boundary": -4.737, "extinguish": 0.0128, "timeout": -3.050,
                    "collision": -4.737, "progress": 0.278, "proximity": -0.189},
    "optuna_top10": {"goal": 0.8785929835, "boundary": -4.3280085652, "extinguish": 0.0072352109,
                     "timeout": -3.7322366112, "collision": -4.3280085652, "progress": 0.2955909834,
                     "proximity": -0.1150000819},
}
PROXIMITY_THRESHOLD = 0.1  # normalised neighbour offset below which the proximity term counts


@dataclass(frozen=True)
class RewardConfig:
    """A preset of coefficients; any field set here overrides the preset's value."""

    preset: str = choice("thesis", tuple(PRESETS))
    goal: float | None = None  # GoalReached
    boundary: float | None = None  # BoundaryTerminal
    extinguish: float | None = None  # Extinguish (complex policy)
    timeout: float | None = None  # TimeOut
    collision: float | None = None  # Collision (collision mode)
    progress: float | None = num(None, 0.0, doc="DistanceImprovement per grid unit of progress")
    proximity: float | None = None  # ProximityPenalty (collision mode)


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
    """Sum of the present terms for one drone (agents.md 8.1).

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
