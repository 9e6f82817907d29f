"""The level a run trains, chosen once from ``train.algo`` (roshan/config/levels.py), and the builders that read it."""

import pytest

from roshan.checkpoints import config_differences, model_keys, optimiser_keys
from roshan.config import FLY_AGENT, PLANNER, Config, ConfigError, level_of, load_config
from roshan.runs.collect import DroneRows, EnvRows, level_rows


@pytest.mark.parametrize("algo, level", [("ppo", FLY_AGENT), ("td3", FLY_AGENT), ("iql", FLY_AGENT),
                                         ("planner", PLANNER)])
def test_each_algo_trains_one_level(algo, level):
    cfg = load_config(None, [f"train.algo={algo}"])
    assert cfg.train.level is level_of(algo) is level
    assert level.flies == (algo != "planner")


def test_an_unknown_algo_is_refused_by_name():
    with pytest.raises(ValueError, match="train.algo: unknown algo 'sac'; expected one of ppo, td3, iql, planner"):
        level_of("sac")
    with pytest.raises(ConfigError, match="train.algo"):
        load_config(None, ["train.algo=sac"])


def test_model_keys_follow_the_level_and_the_algos_section():
    assert model_keys(load_config(None, ["train.algo=td3"])) == ("train.algo", "fly.collision", "fly.frames",
                                                                   "td3.share_encoder")
    assert model_keys(Config()) == ("train.algo", "fly.collision", "fly.frames", "ppo.share_encoder")
    planner = load_config(None, ["train.algo=planner"])
    assert model_keys(planner) == ("train.algo", "planner.network", "drones.num_drones", "drones.energy.enabled",
                                   "planner.distance_prior")
    # a planner trained without a battery cannot serve one: its observation has no energy part
    battery = load_config(None, ["train.algo=planner", "drones.energy.preset=scenario"])
    assert config_differences(battery, planner, model_keys(planner)) == [
        "drones.energy.enabled = True here but False in the checkpoint"]
    # one trained with a battery serves another preset: the observation is the same, in fractions of a battery
    realistic = load_config(None, ["train.algo=planner", "drones.energy.preset=realistic"])
    assert config_differences(realistic, battery, model_keys(planner)) == []
    # the distance prior adds a parameter: a net trained with one is a different net
    prior = load_config(None, ["train.algo=planner", "planner.distance_prior=10"])
    assert config_differences(prior, planner, model_keys(planner)) == [
        "planner.distance_prior = 10.0 here but 0.0 in the checkpoint"]


def test_the_planner_is_trained_by_the_one_ppo():
    planner = load_config(None, ["train.algo=planner"])
    assert planner.train.section == "ppo"
    assert optimiser_keys(planner) == optimiser_keys(Config()) == ("ppo.optim.name", "ppo.separate_optimizers")
    assert optimiser_keys(load_config(None, ["train.algo=iql"])) == ("iql.optim.name",)


def test_rows_are_drones_for_flyagents_and_envs_for_the_planner():
    fly = level_rows(load_config(None, ["drones.num_drones=3"]))
    assert isinstance(fly, DroneRows) and fly.per_env == 3
    assert isinstance(level_rows(load_config(None, ["train.algo=planner", "drones.num_drones=3"])), EnvRows)


def test_no_module_guesses_the_level_from_the_algos_name():
    """``train.algo`` is mapped to a level in one place (roshan/config/levels.py); elsewhere an algo is a key of a
    table (agents, learners), never compared with a name."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "roshan"
    compare = re.compile(r"""algo"?\]?\)?\s*(==|!=|\bin\b\s*\()\s*["'(]""")
    found = [f"{p.relative_to(root)}:{n}: {line.strip()}" for p in sorted(root.rglob("*.py"))
             if p.name != "levels.py" for n, line in enumerate(p.read_text().splitlines(), 1) if compare.search(line)]
    assert not found, found
