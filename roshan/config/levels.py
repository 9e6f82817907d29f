"""The level of the hierarchy a run trains, chosen once from ``train.algo``: what every layer asks of it.

FlyAgent runs (``ppo``, ``td3``, ``iql``) fly drones: every drone is a row of one shared policy, and the network
shapes follow the observation switches of ``fly``. A planner run (``planner``, the same PPO) picks a goal for each
drone of an env: one row per env, the drone count is in its network shapes, and it acts through trained FlyAgent
models. :func:`level_of` is the one place that maps an algo to its level.

A level holds the facts and rules the config layer decides by (the keys that shape its networks, the keys it
refuses, the trained models it acts through, whether its drones put fires out). What only a higher layer can build
(the env, the rows of a rollout, the baselines of an evaluation) the level's :class:`~roshan.runs.levels.LevelKit`
builds, one per level, picked by name in ``roshan/runs/levels.py``. No module asks which level it is and branches.
"""

from collections.abc import Callable
from dataclasses import dataclass

from roshan.config.sim import DroneConfig

# The planner networks without drone ids: one set of weights flies any number of drones, so the fleet size
# (FLEET_SIZE) is not a model key of theirs (roshan/algos/planner_nets.py: FleetPlannerNet; a test keeps the two
# lists in step).
ANY_FLEET_NETWORKS = ("fleet",)
FLEET_SIZE = "drones.num_drones"
# The ppo keys that configure the FlyAgent policy (its distribution, its encoder): the planner's policy has its own
# network (planner.network) and refuses them rather than ignoring them.
FLY_ONLY_PPO_KEYS = ("log_std", "decay_rate", "share_encoder", "use_tanh_dist", "tanh_entropy", "mean_bound",
                     "mean_bound_coef", "separate_optimizers", "minibatch")


def _fights_fire_by_policy(cfg) -> bool:
    return cfg.fly.policy == "complex"  # the simple FlyAgent flies to goals; the complex one puts fires out


def _always(cfg) -> bool:
    return True


@dataclass(frozen=True)
class Level:
    """One level: its name (also who flies, in frame captions) and the facts that differ between levels."""

    name: str
    shape_keys: tuple[str, ...]  # config keys that decide the network shapes, besides the algo's own section keys
    section_shape_keys: tuple[str, ...]  # keys of the algo's section (ppo / td3 / iql) that decide them too
    frozen_models: tuple[str, ...]  # config keys of the trained models it acts through
    refused_keys: tuple[str, ...]  # dotted keys it does not read: a value other than the default is refused
    fights_fire: Callable[[object], bool]  # whether its drones put fires out under a config (else they fly to goals)
    training_note: str = ""  # where its training episodes differ from its evaluation by design, the curves say why

    def model_keys(self, cfg) -> tuple[str, ...]:
        """The config keys that decide the network shapes of ``cfg``'s algo at this level and the observations it
        serves; the number of drones is not one of them for a network that flies any fleet (ANY_FLEET_NETWORKS)."""
        section = ALGO_SECTIONS[cfg.train.algo]
        any_fleet = cfg.planner.network in ANY_FLEET_NETWORKS
        shape = (k for k in self.shape_keys if not (any_fleet and k == FLEET_SIZE))
        return ("train.algo", *shape, *(f"{section}.{k}" for k in self.section_shape_keys))


FLY_AGENT = Level("FlyAgent", shape_keys=("fly.collision", "fly.frames"), section_shape_keys=("share_encoder",),
                  frozen_models=(), refused_keys=(), fights_fire=_fights_fire_by_policy)
PLANNER = Level("planner", shape_keys=("planner.network", *DroneConfig.FLEET_SHAPE_KEYS, "planner.distance_prior"),
                section_shape_keys=(), frozen_models=("planner.fly_model", "planner.explorer_model"),
                refused_keys=tuple(f"ppo.{k}" for k in FLY_ONLY_PPO_KEYS), fights_fire=_always,
                training_note="Training episodes (Episodes/*) sample goals from the stochastic policy with the "
                              "explorers at the groundstation; evaluation (Evaluation/*) takes the argmax goal with "
                              "the explorers flying.")
# The level each trained model a run acts through must be: the planner's low level and its explorers fly, and a
# replay buffer records FlyAgent transitions.
MODEL_LEVELS = {"planner.fly_model": FLY_AGENT, "planner.explorer_model": FLY_AGENT, "buffer.model": FLY_AGENT}

ALGO_LEVELS = {"ppo": FLY_AGENT, "td3": FLY_AGENT, "iql": FLY_AGENT, "planner": PLANNER}
# The section of each algo's hyperparameters: the planner is trained by the one PPO.
ALGO_SECTIONS = {"ppo": "ppo", "td3": "td3", "iql": "iql", "planner": "ppo"}


def level_of(algo: str) -> Level:
    """The level ``algo`` trains (``train.algo`` is validated against the same names)."""
    try:
        return ALGO_LEVELS[algo]
    except KeyError:
        raise ValueError(f"train.algo: unknown algo {algo!r}; expected one of {', '.join(ALGO_LEVELS)}") from None


def check_model_level(key: str, level: Level, where: str) -> None:
    """Refuse a trained model of another level than ``key`` needs (:data:`MODEL_LEVELS`); ``where`` names it."""
    needed = MODEL_LEVELS[key]
    if level is not needed:
        raise ValueError(f"{where} is a {level.name} checkpoint; {key} needs a {needed.name} run")
