"""The level a run trains, chosen once from ``train.algo`` (roshan/config/levels.py), and the builders that read it."""

import re
from pathlib import Path

import pytest

from roshan.checkpoints import config_differences, model_keys, optimiser_keys
from roshan.config import FLY_AGENT, PLANNER, Config, ConfigError, check_model_level, level_of, load_config
from roshan.runs.collect import DroneRows, EnvRows
from roshan.runs.levels import KITS, kit_of


@pytest.mark.parametrize("algo, level", [("ppo", FLY_AGENT), ("td3", FLY_AGENT), ("iql", FLY_AGENT),
                                         ("planner", PLANNER)])
def test_each_algo_trains_one_level(algo, level):
    cfg = load_config(None, [f"train.algo={algo}"])
    assert cfg.train.level is level_of(algo) is level


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
    fly = load_config(None, ["drones.num_drones=3"])
    rows = kit_of(fly).rows(fly)
    assert isinstance(rows, DroneRows) and rows.per_env == 3
    planner = load_config(None, ["train.algo=planner", "drones.num_drones=3"])
    assert isinstance(kit_of(planner).rows(planner), EnvRows)


def test_every_level_has_a_kit_and_its_facts():
    assert set(KITS) == {FLY_AGENT.name, PLANNER.name}
    assert FLY_AGENT.fights_fire(load_config(None, ["fly.policy=complex"]))
    assert not FLY_AGENT.fights_fire(load_config(None, ["fly.policy=simple"]))
    assert PLANNER.fights_fire(load_config(None, ["train.algo=planner"]))
    assert PLANNER.training_note and not FLY_AGENT.training_note
    assert FLY_AGENT.refused_keys == () and "ppo.log_std" in PLANNER.refused_keys


def test_a_model_of_another_level_is_refused_by_name():
    with pytest.raises(ValueError, match="x.pt is a planner checkpoint; planner.fly_model needs a FlyAgent run"):
        check_model_level("planner.fly_model", PLANNER, "x.pt")
    check_model_level("buffer.model", FLY_AGENT, "y.pt")  # the level it needs: no error


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


# Asking which level a run trains, in any spelling: its facts' old flag, an identity or name comparison with a level,
# or a lookup of an algo's level compared with one.
LEVEL_BRANCH = re.compile(r"\.flies\b|\bis (not )?(PLANNER|FLY_AGENT)\b|[!=]= *(PLANNER|FLY_AGENT)\b"
                          r"|level\.name *[!=]=|level *(is|==|!=) *(level_of|ALGO_LEVELS|PLANNER|FLY_AGENT)"
                          r"|ALGO_LEVELS\.get\([^)]*\) *(is|==)")
# The one other place: the upgrade of configs and checkpoints written when the planner had its own PPO.
LEVEL_BRANCH_ALLOWED = {"config/upgrade.py"}


def test_no_module_branches_on_the_level():
    """The level's facts and its kit (roshan/runs/levels.py) answer what differs between levels; a module that
    asks which level it is has missed one of them. config/levels.py may ask, and the upgrade of the old planner
    PPO's files."""
    root = Path(__file__).resolve().parents[2] / "roshan"
    found = {str(p.relative_to(root)): [n for n, line in enumerate(p.read_text().splitlines(), 1)
                                        if LEVEL_BRANCH.search(line)]
             for p in sorted(root.rglob("*.py")) if p.name != "levels.py"}
    found = {k: v for k, v in found.items() if v}
    assert set(found) <= LEVEL_BRANCH_ALLOWED, found
    assert len(found) <= 2


@pytest.mark.parametrize("line", ["if cfg.train.level.flies:", "if level is PLANNER:", "x = lv == FLY_AGENT",
                                  "if cfg.train.level.name == 'planner':",
                                  "if ALGO_LEVELS.get(algo) is PLANNER:", "if level is not FLY_AGENT:"])
def test_the_level_branch_guard_catches_every_spelling(line):
    assert LEVEL_BRANCH.search(line)
