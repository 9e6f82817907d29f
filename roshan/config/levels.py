"""The level of the hierarchy a run trains, chosen once from ``train.algo``: what every layer asks of it.

FlyAgent runs (``ppo``, ``td3``, ``iql``) fly drones: every drone is a row of one shared policy, and the network
shapes follow the observation switches of ``fly``. A planner run (``planner``, the same PPO) picks a goal for each
drone of an env: one row per env, the drone count is in its network shapes, and it acts through trained FlyAgent
models. :func:`level_of` is the one place that maps an algo to its level; the layers above read the level's facts
(``cfg.train.level.flies``) and keep one table each for what only they can build (runs/envs: the env; runs/collect:
the row adapter; algos/agents: the agent, by algo).
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Level:
    """One level: its name (also who flies, in frame captions) and the facts that differ between levels."""

    name: str
    flies: bool  # its actions fly drones; else they choose goals for the drones of an env
    shape_keys: tuple[str, ...]  # config keys that decide the network shapes, besides the algo's own section keys
    section_shape_keys: tuple[str, ...]  # keys of the algo's section (ppo / td3 / iql) that decide them too
    frozen_models: tuple[str, ...]  # config keys of the trained models it acts through

    def model_keys(self, algo: str) -> tuple[str, ...]:
        """The config keys that decide the network shapes of ``algo`` at this level and the observations it serves."""
        section = ALGO_SECTIONS[algo]
        return ("train.algo", *self.shape_keys, *(f"{section}.{k}" for k in self.section_shape_keys))


FLY_AGENT = Level("FlyAgent", flies=True, shape_keys=("fly.collision", "fly.frames"),
                  section_shape_keys=("share_encoder",), frozen_models=())
# drones.energy.enabled (a property of the section): with a battery the observation has an energy part, whatever
# the preset (the charge is a fraction of a full battery), so a planner trained on `scenario` serves `realistic`.
PLANNER = Level("planner", flies=False, shape_keys=("planner.network", "drones.num_drones", "drones.energy.enabled",
                                                "planner.distance_prior"),
                section_shape_keys=(),
                frozen_models=("planner.fly_model", "planner.explorer_model"))

ALGO_LEVELS = {"ppo": FLY_AGENT, "td3": FLY_AGENT, "iql": FLY_AGENT, "planner": PLANNER}
# The section of each algo's hyperparameters: the planner is trained by the one PPO.
ALGO_SECTIONS = {"ppo": "ppo", "td3": "td3", "iql": "iql", "planner": "ppo"}


def level_of(algo: str) -> Level:
    """The level ``algo`` trains (``train.algo`` is validated against the same names)."""
    try:
        return ALGO_LEVELS[algo]
    except KeyError:
        raise ValueError(f"train.algo: unknown algo {algo!r}; expected one of {', '.join(ALGO_LEVELS)}") from None
