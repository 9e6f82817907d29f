"""Profiles (roshan/config/profiles.py): named settings under a config file's values, chosen in one place."""

from pathlib import Path

import pytest
import yaml

from roshan.config import (
    PROFILES,
    Config,
    ConfigError,
    apply_overrides,
    dump_config,
    load_config,
    show_keys,
    to_dict,
)
from roshan.experiment.spec import load_spec

REPO = Path(__file__).resolve().parents[2]


def _write(tmp_path: Path, data: dict, name: str = "c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def _get(cfg, dotted: str):
    for part in dotted.split("."):
        cfg = getattr(cfg, part)
    return cfg


@pytest.mark.parametrize("name", list(PROFILES))
def test_a_profile_sets_each_of_its_keys_and_each_differs_from_a_default_somewhere(name):
    cfg = load_config(None, [f"profile={name}"])
    for dotted, value in PROFILES[name].values.items():
        assert _get(cfg, dotted) == value, dotted
    assert cfg.profile == name
    # a profile that only restated the defaults would be a name for nothing
    assert any(_get(Config(), k) != v for k, v in PROFILES[name].values.items())


def test_the_file_and_the_overrides_win_over_the_profile(tmp_path):
    path = _write(tmp_path, {"profile": "thesis", "ignition": {"reseed": True}, "planner": {"meander": "newest"}})
    cfg = load_config(path, ["planner.time_limit=newest"])
    assert cfg.ignition.reseed is True  # the file's
    assert cfg.planner.meander == "newest"  # the file's, in a section the profile also fills
    assert cfg.planner.time_limit == "newest"  # the override's
    assert cfg.fly.time_limit == "thesis" and cfg.ppo.max_grad_norm == 0.0  # the profile's, left alone by both


def test_several_profiles_apply_in_the_order_named():
    both = load_config(None, ["profile=thesis,original"])
    assert both.ignition.reseed is False and both.fly.sticky_extinguish is True
    later_wins = load_config(None, ["profile=thesis,newest"])
    assert later_wins.planner.time_limit == "newest" and later_wins.ppo.reward_eps == 1e-4


def test_a_run_folders_config_reloads_the_same_and_records_the_profile(tmp_path):
    cfg = load_config(_write(tmp_path, {"profile": "newest", "ppo": {"max_grad_norm": 0.25}}))
    dump_config(cfg, tmp_path / "config.yaml")
    assert yaml.safe_load((tmp_path / "config.yaml").read_text())["profile"] == "newest"
    again = load_config(tmp_path / "config.yaml")
    assert again == cfg and again.ppo.max_grad_norm == 0.25


def test_an_unknown_profile_is_refused_with_the_closest_name(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown profile 'thesys'; did you mean 'thesis'\?"):
        load_config(None, ["profile=thesys"])
    with pytest.raises(ConfigError, match="unknown profile 'nope'"):
        load_config(_write(tmp_path, {"profile": "thesis, nope"}))


def test_a_profile_cannot_be_set_over_a_loaded_config():
    """Over a loaded config every key has a value, so the profile would change its name and nothing else."""
    with pytest.raises(ConfigError, match="profile lies under the config file's values"):
        apply_overrides(Config(), ["profile=thesis"])


def test_a_planner_run_takes_every_profile():
    """No profile sets a key a level refuses (the FlyAgent policy's ppo keys)."""
    for name in PROFILES:
        load_config(None, ["train.algo=planner", f"profile={name}"])


def test_the_fingerprint_reads_the_values_not_the_profiles_name(tmp_path):
    """A condition whose file names a profile is the same run as one whose file lists the profile's values."""
    by_name = _write(tmp_path, {"profile": "thesis", "train": {"algo": "planner"}}, "named.yaml")
    listed = {"train": {"algo": "planner"}}
    for dotted, value in PROFILES["thesis"].values.items():
        node = listed
        *sections, key = dotted.split(".")
        for s in sections:
            node = node.setdefault(s, {})
        node[key] = value
    by_values = _write(tmp_path, listed, "listed.yaml")
    assert to_dict(load_config(by_name)) == {**to_dict(load_config(by_values)), "profile": "thesis"}
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"name: demo\nseeds: 1\nconditions:\n  a: {{config: {by_name}}}\n  b: {{config: {by_values}}}\n")
    prints = load_spec(spec).fingerprints()
    assert prints["a/seed_0"] == prints["b/seed_0"]


def test_config_show_lists_the_profiles_and_their_values():
    text = show_keys("profile")
    for name, profile in PROFILES.items():
        assert f"{name}: {profile.summary}" in text
        assert all(k in text for k in profile.values)
    assert text in show_keys("")


def test_the_thesis_planner_setting_names_the_thesis_profile_and_states_its_departure():
    cfg = load_config(REPO / "configs" / "thesis" / "planner.yaml")
    assert cfg.profile == "thesis"
    assert (cfg.ignition.reseed, cfg.planner.time_limit, cfg.planner.meander) == (False, "thesis", "thesis")
    assert cfg.ppo.max_grad_norm == 0.5  # clipped: a departure the file states
