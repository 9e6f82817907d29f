"""Scripted FlyAgent controllers: a straight-to-goal controller (the greedy baseline) and random actions.

The greedy baseline is the env's **complex** policy plus :func:`straight_to_goal`. The complex policy lives
in the kernels (:class:`roshan.kernels.tasks.GoalRules`, docs/model/agents.md §7 and §10.1): every drone holds the
nearest burning cell no other drone has reserved (the groundstation when there is none), drops water when it
arrives there and takes the next nearest unreserved fire. So the goals already encode the greedy
assignment, and a controller only has to fly each drone to its goal; this one does so without a network.

Both controllers are batched torch functions over (E, N) drones: no Python loop over envs or drones.
"""

import torch

from roshan.env.fly import FlyVectorEnv

GOAL_DELTA = slice(3, 5)  # features 3-4 of a frame: clip((goal - pos) / s, -1, 1), s = floor(view_range / 2)
# Gain on the goal-delta feature. An action a moves a drone a * v_max * dt metres per step, i.e. a * 0.1 cells
# with the default v_max = 10 m/s, dt = 0.1 s, 10 m cells; the feature is the distance r divided by s cells.
# So a = K r / s shrinks the remaining distance by the factor 1 - K * 0.1 / s per step: monotone (no
# overshoot, no oscillation) while K * 0.1 / s <= 1, i.e. K <= 10 s. K = 10 is that bound for the smallest
# view range (2 cells, s = 1); at the default s = 5 the drone flies at full speed until 0.5 cells from the
# goal, then the distance shrinks by a fifth per step, a geometric stop well inside the 0.25-cell tolerance
# (action bins of 0.05 only zero the command below 0.0125 cells). Checked by flying 512 drones with the real
# DroneSim physics for 800 steps at view ranges 2, 10 and 30: all arrive and never leave the tolerance again.
GOAL_GAIN = 10.0
POLICIES = ("greedy", "random")  # names for policy_actions (and `roshan simulate --policy`)


def straight_to_goal(obs_agent: torch.Tensor, gain: float = 1.0) -> torch.Tensor:
    """Velocity commands (E, N, 2) in [-1, 1] flying every drone straight at its goal, slowing down near it.

    Args:
        obs_agent: ``obs["agent"]`` of a :class:`~roshan.env.fly.FlyVectorEnv`, (E, N, T, 9); only the newest
            frame's goal delta (``[..., 0, 3:5]``) is read.
        gain: multiplies :data:`GOAL_GAIN`. With the default physics the approach stays monotone up to
            ``gain = s`` (5 at the default view range; see the comment on :data:`GOAL_GAIN`); above that the
            drone overshoots and settles with an offset, and a smaller gain starts braking further out.

    The command is ``gain * GOAL_GAIN * delta`` scaled down as a whole (not clipped per axis) when its larger
    component exceeds 1, so the direction is kept and the longer axis flies at ``v_max``. Far from the goal
    (beyond ``s`` cells on an axis) the feature itself is clipped per axis, so the heading is only exact once
    the goal is within the view's half width; the path bends towards the goal as it closes in.
    """
    delta = obs_agent[..., 0, GOAL_DELTA]
    a = delta * (gain * GOAL_GAIN)
    peak = a.abs().amax(dim=-1, keepdim=True).clamp_min(1.0)
    return (a / peak).clamp(-1.0, 1.0)


def random_actions(num_envs: int, num_drones: int, generator: torch.Generator | None = None,
                   device: torch.device | str | None = None) -> torch.Tensor:
    """Uniform float32 actions in [-1, 1], (num_envs, num_drones, 2), drawn on ``generator``'s device (repeatable
    for a seeded generator) and moved to ``device`` if given."""
    a = torch.rand((num_envs, num_drones, 2), generator=generator,
                   device=generator.device if generator is not None else device) * 2.0 - 1.0
    return a if device is None else a.to(device)


def policy_actions(policy: str, env: FlyVectorEnv, obs: dict, generator: torch.Generator | None = None):
    """Actions of a scripted policy of :data:`POLICIES` for ``env``: ``"greedy"`` (:func:`straight_to_goal`; the
    env should run the complex policy, see the module docstring) or ``"random"`` (:func:`random_actions`)."""
    if policy == "greedy":
        return straight_to_goal(obs["agent"])
    if policy == "random":
        return random_actions(env.num_envs, env.num_drones, generator, env.device)
    raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
