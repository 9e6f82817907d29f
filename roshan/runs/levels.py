"""What each level of the hierarchy builds in a run: its vector env, the rows of its rollouts, the checks of a map
it is evaluated on, and its evaluation's baselines.

The level itself (:mod:`roshan.config.levels`) is chosen once from ``train.algo`` and holds what the config layer
decides by; it cannot build an env, because the config layer imports nothing above it. Its builders are here, one
:class:`LevelKit` per level, and :func:`kit_of` is the one place that picks a level's kit. Everything else asks the
kit and never which level it is.
"""

from collections.abc import Callable
from dataclasses import dataclass

from roshan.config import FLY_AGENT, PLANNER, Config
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.maps import LandCoverMap, check_explorer_map
from roshan.runs.baselines import fly_baseline, fly_baseline_name, planner_baseline, planner_baseline_name
from roshan.runs.collect import DroneRows, EnvRows


@dataclass(frozen=True)
class LevelKit:
    """A level's builders (each takes the run's config first)."""

    env: Callable  # (cfg, num_envs, seed, evaluation, controller, render_mode) -> the vector env
    rows: Callable[[Config], DroneRows | EnvRows]  # the rows of a rollout: a drone each, or an env each
    check_map: Callable[[LandCoverMap, Config], None]  # refuse a map the level cannot be evaluated on
    baseline: Callable  # (cfg, env, name, num_envs, seed, make_env) -> (env it plays in, actions)
    baseline_name: Callable[[str, Config], tuple[str, str, dict]]  # (column name, note, JSON extras)


def _fly_env(cfg: Config, num_envs: int, seed: int, evaluation: bool = False, controller: str = "planner",
             render_mode: str | None = None) -> FlyVectorEnv:
    return FlyVectorEnv(num_envs=num_envs, config=cfg, seed=seed, render_mode=render_mode)


def _planner_env(cfg: Config, num_envs: int, seed: int, evaluation: bool = False, controller: str = "planner",
                 render_mode: str | None = None) -> PlannerVectorEnv:
    return PlannerVectorEnv(num_envs, cfg, evaluation=evaluation, controller=controller, seed=seed,
                            render_mode=render_mode)


def _no_map_check(land: LandCoverMap, cfg: Config) -> None:
    pass


def _explorer_room(land: LandCoverMap, cfg: Config) -> None:
    check_explorer_map(land, cfg.planner.num_explorers)


KITS = {
    FLY_AGENT.name: LevelKit(env=_fly_env, rows=lambda cfg: DroneRows(cfg.drones.num_drones), check_map=_no_map_check,
                             baseline=fly_baseline, baseline_name=fly_baseline_name),
    PLANNER.name: LevelKit(env=_planner_env, rows=lambda cfg: EnvRows(), check_map=_explorer_room,
                           baseline=planner_baseline, baseline_name=planner_baseline_name),
}


def kit_of(cfg: Config) -> LevelKit:
    """The builders of the level ``cfg`` trains."""
    return KITS[cfg.train.level.name]
