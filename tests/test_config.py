"""Config loading: defaults, YAML files, --set overrides and the errors for bad input."""

from pathlib import Path

import pytest

from roshan.config import Config, ConfigError, all_keys, load_config

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


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
