"""ONE typed config tree: every section a run, an env, a simulation or a study reads, with YAML loading,
``--set`` overrides and validation (:mod:`roshan.config.schema`).

The sections live by subject: :mod:`roshan.config.sim` (map, fire, wind, ignition, drones, batch),
:mod:`roshan.config.agents` (the FlyAgent task, the planner level, rewards) and :mod:`roshan.config.learning`
(training loop and algorithms). :class:`Config` is the root; every layer takes it (or one of its sections).
"""

from dataclasses import dataclass, field
from pathlib import Path

from roshan.config import describe, schema
from roshan.config.agents import (
    CONTROLLERS,
    PLANNER_NEWEST_TERMS,
    PLANNER_PRESETS,
    PRESETS,
    FlyConfig,
    PlannerConfig,
    PlannerRewardConfig,
    RewardConfig,
)
from roshan.config.learning import (
    IQLConfig,
    OptimConfig,
    PPOConfig,
    RNDConfig,
    TD3Config,
    TrainConfig,
)
from roshan.config.levels import (
    ALGO_LEVELS,
    ANY_FLEET_NETWORKS,
    FLY_AGENT,
    FLY_ONLY_PPO_KEYS,
    PLANNER,
    Level,
    check_model_level,
    level_of,
)
from roshan.config.profiles import PROFILES, describe_profiles, profile_names, under_profile
from roshan.config.schema import (
    ConfigError,
    choice,
    dump_config,
    from_dict,
    num,
    replace,
    suggest,
    to_dict,
)
from roshan.config.sim import (
    ConvectionConfig,
    DroneConfig,
    EnergyConfig,
    FireConfig,
    IgnitionConfig,
    MapConfig,
    RadiationConfig,
    SimConfig,
    WindConfig,
)
from roshan.config.upgrade import MOVED_KEYS, fill_values_of_record, upgrade_agent_state, upgrade_config_dict


@dataclass(frozen=True)
class Config(schema.Section):
    """Everything: the simulator, the agents' tasks, the training loop and each algorithm's hyperparameters."""

    map: MapConfig = field(default_factory=MapConfig)
    fire: FireConfig = field(default_factory=FireConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    ignition: IgnitionConfig = field(default_factory=IgnitionConfig)
    drones: DroneConfig = field(default_factory=DroneConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    fly: FlyConfig = field(default_factory=FlyConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    td3: TD3Config = field(default_factory=TD3Config)
    iql: IQLConfig = field(default_factory=IQLConfig)
    rnd: RNDConfig = field(default_factory=RNDConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    profile: str = ""  # settings under a loaded file's: thesis, newest, original or several (thesis,original)

    def __post_init__(self):
        super().__post_init__()  # each section is a section of its class (they validated themselves)
        profile_names(self.profile)
        check_refused_keys(self)
        check_step_counts(self)


schema.register_tree(Config)  # errors of a section built in Python name its dotted key ("fly.frames")


def check_step_counts(cfg: Config) -> None:
    """Durations the kernels count in steps of ``fire.dt`` (:attr:`DroneConfig.step_durations`) must fit their
    int32 counters: ``swap_time=1e9`` used to end in Taichi's "Integer literal ... exceeded the range"."""
    for key, seconds in cfg.drones.step_durations.items():
        steps = (seconds + 1e-4) / cfg.fire.dt
        if steps > schema.INT32_MAX:
            most = schema.INT32_MAX * cfg.fire.dt
            raise ConfigError(f"{key} = {seconds!r} s is {steps:.3g} steps of fire.dt = {cfg.fire.dt!r} s, more than "
                              f"a step counter holds; expected at most {most:.4g} s")


def check_refused_keys(cfg: Config) -> None:
    """Refuse a key the run's level does not read (``Level.refused_keys``) at a value other than its default,
    rather than ignore it: the planner is trained by the same PPO as the FlyAgent, but the FlyAgent policy's keys
    mean nothing to it."""
    for dotted in cfg.train.level.refused_keys:
        section, key = dotted.split(".")
        value, default = getattr(getattr(cfg, section), key), getattr(type(getattr(cfg, section))(), key)
        if value != default:
            raise ConfigError(f"{dotted} = {value!r} applies to the FlyAgent policy only, not to train.algo = "
                              f"{cfg.train.algo} (leave it at {default!r}; the network is planner.network)")


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = (), cls: type = Config,
                flags: dict | None = None):
    """A YAML config (or the defaults) plus ``section.key=value`` overrides, validated (errors name the key and
    where its value came from: the file, ``--set``, or the command's option of ``flags``, a dict dotted key ->
    (option, value)); ``cls`` is the root :class:`Config` unless a caller loads one section on its own."""
    if cls is not Config:
        return schema.load_config(path, overrides, cls=cls, flags=flags)
    return schema.load_config(path, overrides, cls=cls, upgrade=upgrade_config_dict, moved=MOVED_KEYS, flags=flags,
                              base=under_profile)


def apply_overrides(cfg, overrides: list[str] | tuple[str, ...], where: str = "--set"):
    """A copy of ``cfg`` with ``section.key=value`` overrides applied and validated (keys of older layouts
    renamed as a file of that layout would be). A profile is a layer under a file's values, so it is chosen when
    the file is loaded (its ``profile`` key, or ``--set profile=...`` of the command), not over a loaded config."""
    for item in overrides:
        if isinstance(cfg, Config) and item.split("=", 1)[0].strip() == "profile":
            raise ConfigError(f"{where} {item!r}: a profile lies under the config file's values, so it cannot be "
                              "set over a loaded config; name it in the config file (profile: NAME) or in the "
                              "command's --set")
    return schema.apply_overrides(cfg, overrides, where, moved=MOVED_KEYS if isinstance(cfg, Config) else None)


def all_keys(cls: type = Config, prefix: str = "") -> list[str]:
    """Every dotted key of the tree (or of one section class)."""
    return schema.all_keys(cls, prefix)


def show_keys(section: str = "") -> str:
    """``roshan config show [SECTION]``: every key of ``section`` (a section, a key, or "" for all) with its
    default, type, allowed values and doc; an unknown section is a ConfigError with the closest name. ``profile``
    lists the profiles and their values; every key's listing ends with them."""
    if section == "profile":
        return describe_profiles()
    if not section:
        return describe.format_keys(Config, describe.describe_keys(Config)) + "\n\n" + describe_profiles()
    return describe.format_keys(Config, describe.describe_keys(Config, section))


load_run_config = load_config


def upgrade_saved_config(data: dict) -> dict:
    """A checkpoint's config dict in the current layout (:func:`upgrade_config_dict`), with the value of record of
    each key it predates (a field's ``was=``)."""
    return fill_values_of_record(upgrade_config_dict(data), schema.values_of_record(Config))


__all__ = [
    "ALGO_LEVELS", "ANY_FLEET_NETWORKS", "CONTROLLERS", "FLY_AGENT", "Level", "PLANNER", "PLANNER_NEWEST_TERMS",
    "PLANNER_PRESETS",
    "PRESETS", "PROFILES", "Config", "ConfigError",
    "ConvectionConfig", "DroneConfig", "EnergyConfig", "FireConfig", "FlyConfig", "IQLConfig", "IgnitionConfig",
    "MapConfig",
    "FLY_ONLY_PPO_KEYS", "OptimConfig", "PPOConfig", "PlannerConfig", "PlannerRewardConfig", "RNDConfig",
    "RadiationConfig", "RewardConfig", "SimConfig", "TD3Config", "TrainConfig", "WindConfig", "all_keys",
    "apply_overrides", "check_model_level", "choice", "dump_config", "from_dict", "load_config", "load_run_config",
    "num", "replace",
    "level_of", "show_keys", "suggest", "to_dict", "upgrade_agent_state", "upgrade_config_dict",
    "upgrade_saved_config",
]
