"""The scripted controllers an evaluation compares a trained policy with (``roshan eval --baseline``), per level.

A FlyAgent's baselines act on its drone observations: ``greedy`` flies straight to the goal, ``random`` takes
uniform actions. A planner's play the same episodes in their own env: ``greedy`` is the env's heuristic controller
(a second env with the same seed and env count: identical fire layouts and wind), ``random`` picks valid candidates
uniformly.
"""

import torch

from roshan.config import Config
from roshan.env.heuristics import straight_to_goal

BASELINES = ("random", "greedy")
# Which greedy heuristic a planner evaluation plays (planner.greedy_home), as its tables and JSON name it.
GREEDY_HOME_NOTES = {
    "original": "the original's heuristic, defect included: a fire on the groundstation cell is re-taken every step "
                "and never put out, so the heuristic times out whenever that cell burns "
                "(--set planner.greedy_home=fixed plays the fixed one)",
    "fixed": "the heuristic with the original's groundstation defect fixed: a fire on the groundstation cell is put "
             "out like any other",
}


def check_baseline(name: str) -> None:
    if name not in BASELINES:
        raise ValueError(f"--baseline: expected one of {', '.join(BASELINES)}, got {name!r}")


def baseline_fn(name: str, num_envs: int, num_drones: int, seed: int):
    """Scripted actions on flattened drone observations: ``random`` (uniform, seeded) or ``greedy`` (straight to
    the goal, roshan.env.heuristics)."""
    check_baseline(name)
    if name == "greedy":
        return lambda obs: straight_to_goal(obs["agent"].unsqueeze(1)).squeeze(1)
    g = torch.Generator().manual_seed(seed)
    return lambda obs: torch.rand(obs["agent"].shape[0], 2, generator=g) * 2.0 - 1.0


def planner_random_fn(seed: int):
    """Uniformly random valid candidates per drone (the planner's random baseline)."""
    g = torch.Generator().manual_seed(seed)

    def act(obs):
        count = obs["fires_mask"].sum(-1, keepdim=True)  # valid prefix length, groundstation included
        u = torch.rand(obs["drones"].shape[:2], generator=g)
        return (u * count).long().clamp(max=obs["fires_mask"].shape[-1] - 1)

    return act


def fly_baseline(cfg: Config, env, name: str, num_envs: int, seed: int, make_env):
    """(env, actions) of a FlyAgent's baseline: the evaluated env itself, scripted actions."""
    return env, baseline_fn(name, num_envs, env.num_drones, seed)


def planner_baseline(cfg: Config, env, name: str, num_envs: int, seed: int, make_env):
    """(env, actions) of a planner's baseline: greedy plays in its own env of the same seed (``make_env``, the
    level's env builder), random picks candidates in the evaluated env."""
    check_baseline(name)
    if name == "greedy":
        return make_env(cfg, num_envs, seed, evaluation=True, controller="greedy"), \
            (lambda obs: torch.zeros(num_envs, env.num_drones))
    return env, planner_random_fn(seed)


def fly_baseline_name(name: str, cfg: Config) -> tuple[str, str, dict]:
    """(column name, note, what the JSON adds) of a FlyAgent's baseline: its name, nothing more."""
    return name, "", {}


def planner_baseline_name(name: str, cfg: Config) -> tuple[str, str, dict]:
    """(column name, note, what the JSON adds) of a planner's baseline: greedy says which heuristic it plays
    (``greedy (original)`` or ``greedy (fixed)``, :data:`GREEDY_HOME_NOTES`), and ``resource-aware greedy (...)``
    where it watches its batteries (a battery with ``planner.greedy_resources``); random is its name."""
    if name != "greedy":
        return name, "", {}
    home = cfg.planner.greedy_home
    aware = cfg.planner.greedy_resources and cfg.drones.energy.enabled
    column = f"resource-aware greedy ({home})" if aware else f"greedy ({home})"
    note = f"{column}, planner.greedy_home = {home}: {GREEDY_HOME_NOTES[home]}"
    if aware:
        note += ("; it sends a drone home when its battery or tank runs low and waits there until both are full "
                 "(planner.greedy_resources)")
    return column, note, {"greedy_home": home}
