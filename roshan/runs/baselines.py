"""The scripted controllers an evaluation compares a trained policy with (``roshan eval --baseline``), per level.

A FlyAgent's baselines act on its drone observations: ``greedy`` flies straight to the goal, ``random`` takes
uniform actions. A planner's play the same episodes in their own env: ``greedy`` is the env's heuristic controller
(a second env with the same seed and env count: identical fire layouts and wind), ``random`` picks valid candidates
uniformly, and ``clairvoyant`` is the reference of how good a controller can be here (:func:`clairvoyant_fn`).
"""

import numpy as np
import torch

from roshan.config import Config, apply_overrides
from roshan.env.heuristics import straight_to_goal

BASELINES = ("random", "greedy", "clairvoyant")
PLANNER_ONLY = ("clairvoyant",)
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
    if name in PLANNER_ONLY:
        raise ValueError(f"--baseline {name} plays the planner's level; a FlyAgent's baselines are random and greedy")
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


def clairvoyant_fn(margin: float, bases: int = 1):
    """The clairvoyant reference's goals on planner observations whose candidates are every burning cell (no
    exploration: ``planner.eval_fires: true``). Each decision it solves the assignment of drones to fires that
    minimises their summed flight times (scipy's ``linear_sum_assignment``: each fire to at most one drone; a drone
    left over when fewer fires burn than drones fly takes its nearest fire). A drone flies the quickest path at
    ``v_max`` per axis, so its time to a fire is the larger of the two axis distances (Chebyshev). A drone goes to
    its nearest base (of the first ``bases`` candidates; candidate 0, the groundstation, with one) instead when its
    tank is empty or, with a battery, when its charge is at most (1 + ``margin``) times what the flight home takes,
    and stays there until both are full, as the resource-aware greedy does. It looks at every env on the host each
    decision: an evaluation reference, not a trained controller.
    """

    def act(obs: dict[str, torch.Tensor]) -> torch.Tensor:
        drones, fires = obs["drones"].cpu().numpy(), obs["fires"].cpu().numpy()
        valid = obs["fires_mask"].cpu().numpy() > 0
        home = obs["water"].cpu().numpy()[..., 0] <= 0.0
        if "energy" in obs:
            charge, needed = np.moveaxis(obs["energy"].cpu().numpy().reshape(*drones.shape[:2], 2), -1, 0)
            at_base = needed <= 1e-6
            home |= charge <= (1.0 + margin) * needed
            home |= at_base & (charge < 1.0)  # landed: wait for the full battery
        goals = np.zeros(drones.shape[:2], dtype=np.int64)
        for b in range(drones.shape[0]):
            goals[b] = _assign(drones[b], fires[b], valid[b], home[b], bases)
        return torch.from_numpy(goals)

    return act


def _assign(drones: np.ndarray, fires: np.ndarray, valid: np.ndarray, home: np.ndarray,
            bases: int = 1) -> np.ndarray:
    """One env's goals (N,): the nearest base for drones sent home (Euclidean, ties to the lower index, as the
    kernels' nearest base), else the min-sum assignment of flight times."""
    from scipy.optimize import linear_sum_assignment  # only this reference needs scipy (0.3 s to import)

    gaps = np.linalg.norm(drones[:, None, :] - fires[None, :bases, :], axis=-1)  # (N, bases)
    goals = gaps.argmin(-1).astype(np.int64)  # with one base: candidate 0, the groundstation
    burning = np.flatnonzero(valid[bases:]) + bases  # the candidates after the bases
    flying = np.flatnonzero(~home)
    if not len(burning) or not len(flying):
        return goals
    time = np.abs(drones[flying, None, :] - fires[None, burning, :]).max(-1)  # Chebyshev, normalised units
    rows, cols = linear_sum_assignment(time)
    goals[flying[rows]] = burning[cols]
    left = np.setdiff1d(np.arange(len(flying)), rows)  # more drones than fires: each to its nearest
    goals[flying[left]] = burning[time[left].argmin(-1)]
    return goals


def planner_baseline(cfg: Config, env, name: str, num_envs: int, seed: int, make_env):
    """(env, actions) of a planner's baseline: greedy plays in its own env of the same seed (``make_env``, the
    level's env builder), random picks candidates in the evaluated env, and the clairvoyant reference plays in an
    env of the same seed whose candidates are every burning cell."""
    check_baseline(name)
    if name == "greedy":
        return make_env(cfg, num_envs, seed, evaluation=True, controller="greedy"), \
            (lambda obs: torch.zeros(num_envs, env.num_drones))
    if name == "clairvoyant":
        seeing = apply_overrides(cfg, ["planner.eval_fires='true'"], where="the clairvoyant reference")
        return make_env(seeing, num_envs, seed, evaluation=True), clairvoyant_fn(cfg.planner.greedy_energy_margin,
                                                                                 cfg.drones.bases)
    return env, planner_random_fn(seed)


def fly_baseline_name(name: str, cfg: Config) -> tuple[str, str, dict]:
    """(column name, note, what the JSON adds) of a FlyAgent's baseline: its name, nothing more."""
    return name, "", {}


def planner_baseline_name(name: str, cfg: Config) -> tuple[str, str, dict]:
    """(column name, note, what the JSON adds) of a planner's baseline: greedy says which heuristic it plays
    (``greedy (original)`` or ``greedy (fixed)``, :data:`GREEDY_HOME_NOTES`), and ``resource-aware greedy (...)``
    where it watches its batteries (a battery with ``planner.greedy_resources``); random is its name."""
    if name == "clairvoyant":
        return name, ("clairvoyant reference: it sees every burning cell from the start and assigns drones to fires "
                      "by the least summed flight time each decision, keeping the battery's reserve for the flight "
                      "home"), {}
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
