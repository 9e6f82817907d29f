"""Config loading: defaults, YAML files, --set overrides and the errors for bad input."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from roshan.config import (
    Config,
    ConfigError,
    DroneConfig,
    EnergyConfig,
    FlyConfig,
    IgnitionConfig,
    MapConfig,
    OptimConfig,
    PPOConfig,
    SimConfig,
    all_keys,
    from_dict,
    load_config,
    to_dict,
)
from roshan.kernels.episode import EpisodeKernels

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_defaults_are_the_spec_values():
    cfg = load_config()
    assert cfg.fire.dt == 0.1 and cfg.fire.flood_duration == 5.0
    assert (cfg.fire.convection.fl, cfg.fire.convection.c0, cfg.fire.convection.lt) == (0.15, 1.98, 80.0)
    assert cfg.fire.radiation.y_lim == 0.165 and cfg.wind.turbulence == 0.314
    assert cfg.ignition.spread_prob == 0.5 and cfg.ignition.noise == 1.0


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("fire_*.yaml")), ids=lambda p: p.name)
def test_shipped_configs_load(path):
    assert isinstance(load_config(path), Config)


def test_set_overrides_nested_keys_and_parses_values():
    cfg = load_config(CONFIGS / "fire_planner.yaml", ["fire.convection.enabled=false", "wind.direction=90",
                                                      "sim.envs=8"])
    assert cfg.fire.convection.enabled is False and cfg.wind.direction == 90.0 and cfg.sim.envs == 8
    assert cfg.ignition.fire_percentage == 0.35


def test_exponent_without_a_dot_is_a_float():
    # YAML 1.1 reads "3e-5" as a string; a float field takes it anyway.
    assert load_config(None, ["fire.dt=5e-2"]).fire.dt == pytest.approx(0.05)


@pytest.mark.parametrize("override, words", [
    ("fire.dtt=0.1", ["unknown key", "'fire.dtt'", "did you mean 'fire.dt'"]),
    ("ignition.fire_percentag=0.1", ["did you mean 'ignition.fire_percentage'"]),
    ("fire.dt=0", ["fire.dt", "out of range", "(0.0, 10.0]"]),
    ("fire.dt=-1", ["fire.dt", "out of range"]),
    ("ignition.fire_percentage=1.5", ["ignition.fire_percentage", "[0.0, 1.0]"]),
    ("ignition.pattern=blob", ["ignition.pattern", "cluster, scattered, ring, random"]),
    ("sim.envs=0", ["sim.envs", ">= 1"]),
    ("wind.speed=fast", ["wind.speed must be float"]),
    ("sim.envs=2.5", ["sim.envs must be int"]),
    ("fire.dt=.nan", ["fire.dt is NaN"]),
    ("noequals", ["expected section.key=value"]),
])
def test_bad_overrides_name_the_key_and_the_allowed_values(override, words):
    with pytest.raises(ConfigError) as err:
        load_config(None, [override])
    for w in words:
        assert w in str(err.value)


def test_bad_yaml_files_name_the_file(tmp_path):
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("fire:\n  convection:\n    tau_memm: 3\n")
    with pytest.raises(ConfigError, match=r"unknown\.yaml: unknown key 'fire\.convection\.tau_memm'.*tau_mem"):
        load_config(unknown)
    section = tmp_path / "section.yaml"
    section.write_text("fyre:\n  dt: 0.1\n")
    with pytest.raises(ConfigError, match="did you mean 'fire'"):
        load_config(section)
    broken = tmp_path / "broken.yaml"
    broken.write_text("fire: [1, 2\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml: not valid YAML"):
        load_config(broken)
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_config(scalar)
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_config(tmp_path / "missing.yaml")


def test_all_keys_lists_dotted_leaves():
    keys = all_keys()
    assert "fire.convection.tau_mem" in keys and "ignition.pattern" in keys and "fire" not in keys


@pytest.mark.parametrize("build, words", [
    (lambda: FlyConfig(frames=0), ["FlyConfig: fly.frames = 0 is out of range", "[1, 8]"]),
    (lambda: FlyConfig(policy="bogus"), ["FlyConfig: fly.policy = 'bogus'", "simple, complex"]),
    (lambda: IgnitionConfig(fire_percentage=2.0), ["IgnitionConfig: ignition.fire_percentage = 2.0", "[0.0, 1.0]"]),
    (lambda: SimConfig(envs=2.5), ["SimConfig: sim.envs must be int"]),
    (lambda: OptimConfig(eps=0.0), ["OptimConfig: eps = 0.0 is out of range"]),  # at three places: no prefix
    (lambda: dataclasses.replace(FlyConfig(), frames=100), ["fly.frames = 100 is out of range"]),
    (lambda: Config(fly=IgnitionConfig()), ["Config: fly must be a FlyConfig, got IgnitionConfig("]),
    (lambda: Config(fly={"frames": 2}), ["Config: fly must be a FlyConfig"]),
])
def test_configs_built_in_python_are_validated_like_yaml(build, words):
    with pytest.raises(ConfigError) as err:
        build()
    for w in words:
        assert w in str(err.value)


def test_a_config_built_in_python_equals_the_yaml_one(tmp_path):
    path = tmp_path / "small.yaml"
    path.write_text("map:\n  name: uniform\n  uniform_rows: 12\nfly:\n  frames: 2\n  k_turn: 2\n"
                    "ppo:\n  lr: 3e-5\n")
    built = Config(map=MapConfig(name="uniform", uniform_rows=12), fly=FlyConfig(frames=2, k_turn=2),
                   ppo=PPOConfig(lr="3e-5"))
    assert built == load_config(path)
    assert type(built.fly.k_turn) is float and type(SimConfig(envs=np.int64(3)).envs) is int  # coerced as YAML is


@pytest.mark.parametrize("text", ["", "# only a comment\n"])
def test_an_empty_config_file_is_an_error(tmp_path, text):
    path = tmp_path / "empty.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"empty\.yaml: the config file is empty; expected sections such as map"):
        load_config(path)


def test_other_libraries_key_names_suggest_ours():
    with pytest.raises(ConfigError, match="did you mean 'ppo.lr'"):
        load_config(None, ["ppo.learning_rate=1e-4"])


# issue 52: infinities passed every range check of the form "> 0" and ended in an OverflowError in the drone kernels
# (swap_time, recharge_time) or in a battery that never drains (capacity, 1e40 being inf in float32).
@pytest.mark.parametrize("override, words", [
    ("drones.energy.swap_time=inf", ["drones.energy.swap_time = inf is infinite", ">= 0.0"]),
    ("drones.recharge_time=inf", ["drones.recharge_time = inf is infinite"]),
    ("drones.energy.capacity=inf", ["drones.energy.capacity = inf is infinite", "> 0.0"]),
    ("drones.energy.capacity=-.inf", ["drones.energy.capacity = -inf is infinite"]),
    ("drones.energy.capacity=1e40", ["drones.energy.capacity = 1e+40 is beyond float32"]),
    ("drones.energy.hover_power=inf", ["drones.energy.hover_power = inf is infinite"]),
    ("drones.max_speed=inf", ["drones.max_speed = inf is infinite"]),
    ("fly.rewards.goal=inf", ["fly.rewards.goal = inf is infinite", "a finite number"]),  # a field with no range
    ("fly.rewards.goal=.nan", ["fly.rewards.goal is NaN"]),
])
def test_infinities_are_refused_naming_the_key(override, words):
    with pytest.raises(ConfigError) as err:
        load_config(None, ["drones.energy.preset=scenario", override])
    for w in words:
        assert w in str(err.value)


@pytest.mark.parametrize("override, words", [
    ("drones.energy.swap_time=1e9", ["drones.energy.swap_time = 1000000000.0 s", "fire.dt = 0.1", "at most"]),
    ("drones.recharge_time=1e9", ["drones.recharge_time = 1000000000.0 s"]),
    ("drones.view_range=3000000000", ["drones.view_range", "out of range", "2147483647"]),
    ("ignition.clusters=3000000000", ["ignition.clusters", "out of range"]),
])
def test_settings_counted_in_kernel_integers_have_an_upper_bound(override, words):
    with pytest.raises(ConfigError) as err:
        load_config(None, ["drones.energy.preset=scenario", override])
    for w in words:
        assert w in str(err.value)


def test_battery_values_without_a_preset_are_refused():
    # issue 52: they were ignored and the drones flew forever, although the README says any value can be set alone
    with pytest.raises(ConfigError, match=r"drones\.energy\.capacity = 1\.0 is set but drones\.energy\.preset is off"
                                          r".*scenario or realistic"):
        load_config(None, ["drones.energy.capacity=1"])
    assert load_config(None, ["drones.energy.preset=scenario", "drones.energy.capacity=1"]).drones.energy.values()[
        "capacity"] == 1.0


def test_off_unquoted_reads_as_the_preset_off(tmp_path):
    # issue 52: YAML 1.1 reads an unquoted off as false, refused as "must be str, got False"
    path = tmp_path / "off.yaml"
    path.write_text("drones:\n  energy:\n    preset: off\n")
    assert load_config(path).drones.energy.preset == "off"
    cfg = load_config(None, ["drones.energy.preset=scenario", "drones.energy.preset=off"])
    assert cfg.drones.energy.preset == "off"
    with pytest.raises(ConfigError, match="drones.energy.preset must be str, got True"):  # no choice named "on"
        load_config(None, ["drones.energy.preset=yes"])


def test_a_step_limit_beyond_int32_is_refused():
    # a drone of 1e-30 m/s gave a T_max of 3e34 steps, wrapped in the kernels' int32 counters
    with pytest.raises(ConfigError, match="step limit T_max = 3e.34 steps.*raise drones.max_speed"):
        EpisodeKernels(None, 3 * 10**34)


def test_a_checkpoint_saved_before_a_key_existed_keeps_the_behaviour_it_had():
    """The return rule's reserve and the final approach changed default after runs were saved without those keys:
    such a checkpoint's config loads with the rule its run had, while a config file that leaves them out (and a
    checkpoint that has them) takes what it says."""
    from roshan.config import upgrade_saved_config
    from roshan.config.schema import values_of_record

    saved = to_dict(Config(drones=DroneConfig(energy=EnergyConfig(preset="scenario"))))
    del saved["planner"]["return_queue"], saved["drones"]["energy"]["approach"]
    cfg = from_dict(Config, upgrade_saved_config(saved))
    assert (cfg.planner.return_queue, cfg.drones.energy.approach) == ("all", 0.0)
    assert values_of_record(Config) == {"drones.energy.approach": 0.0, "planner.greedy_home": "original",
                                        "planner.return_queue": "all"}  # the fields' was=
    assert "return_queue" not in saved["planner"]  # the caller's dict is left alone
    fresh = Config(drones=DroneConfig(energy=EnergyConfig(preset="scenario")))
    assert (fresh.planner.return_queue, fresh.drones.energy.approach) == ("waiting", 2.0)
    assert from_dict(Config, upgrade_saved_config(to_dict(fresh))) == fresh
