"""The planner level end to end: `roshan train` on a planner config, resume, and `roshan eval --baseline greedy`
with the thesis-style comparison and the {"policy", "greedy"} JSON."""

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.checkpoints import checkpoint_path, load_checkpoint
from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "fly_simple"
# The small bundled field keeps episodes short (T_max 1784 low-level steps at 5 %).
TINY = ["--set", "map.name=21x21_Field", "--set", "ignition.fire_percentage=0.05",
        "--set", f"planner.fly_model={MODEL}", "--set", f"planner.explorer_model={MODEL}",
        "--set", "planner.num_explorers=2", "--set", "sim.envs=4", "--set", "ppo.horizon=32",
        "--set", "ppo.batch_size=16", "--set", "train.max_minutes=0", "--set", "train.eval_every=0"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.mark.slow
def test_planner_trains_resumes_and_evaluates_against_greedy_on_the_same_episodes(tmp_path):
    res = cli("train", ROOT / "configs/planner.yaml", "--root", tmp_path, "--name", "p", "--no-eval", "--quiet",
              *TINY, "--set", "train.max_updates=2")
    assert res.exit_code == 0, res.output
    run = tmp_path / "p"
    progress = load_checkpoint(checkpoint_path(run, "latest"))["progress"]
    assert (progress["updates"], progress["env_steps"]) == (2, 64)  # decisions: 8 per env and update
    res = cli("train", "--resume", run, "--no-eval", "--quiet", *TINY,
              "--set", "train.max_updates=3")
    assert res.exit_code == 0, res.output
    assert load_checkpoint(checkpoint_path(run, "latest"))["progress"]["updates"] == 3

    out = tmp_path / "eval.json"
    gif = tmp_path / "gif" / "episode.gif"
    res = cli("eval", run, "--episodes", 4, "--envs", 4, "--seed", 5, "--baseline", "greedy", "--json", out,
              "--gif", gif, "--quiet")
    assert res.exit_code == 0, res.output
    assert "greedy" in res.output and "TTE" in res.output
    # the column and a note say which greedy heuristic played (issue 32, item 12)
    # (the default since issue 32: the fixed heuristic; the thesis configs set original)
    assert "greedy (fixed)" in res.output and "planner.greedy_home = fixed" in res.output
    payload = json.loads(out.read_text())
    assert payload["greedy"].pop("greedy_home") == "fixed"
    assert set(payload) == {"policy", "greedy", "provenance"}
    assert payload.pop("provenance")["baseline"] == "greedy"
    for part in payload.values():
        assert part["episodes"] == 4 and 0.0 <= part["success_rate"] <= 1.0
        # only the failures a planner or its greedy can have: collisions and boundary exits never end their episodes
        assert set(part["failure_rates"]) == {"timeout", "burnout"}
        assert part["tte"]["mean"] > 0 and part["tte"]["median"] > 0
    (folder,) = (run / "eval").glob("5-4-*")  # the baseline is a setting of its own: a hashed folder name
    assert (folder / "episodes.csv").is_file() and (folder / "greedy" / "episodes.csv").is_file()
    # tables show what each controller measured: the heuristic earns no reward; neither can collide or exit
    greedy, planner = (folder / "greedy" / "table.txt").read_text(), (folder / "table.txt").read_text()
    assert "Reward" not in greedy and "Reward (episode return)" in planner
    for table in (greedy, planner):
        assert "Collision rate" not in table and "Boundary rate" not in table and "Burnout rate" in table
        assert "TTE (s)" in table and "Ever lit (% of cells)" in table
    assert not (folder / "greedy" / "reward_vs_episode.png").exists()
    assert gif.read_bytes()[:6] == b"GIF89a"
    assert [p.name for p in gif.parent.iterdir()] == ["episode.gif"]  # the GIF's frames were scratch files


def test_the_planner_greedy_baseline_is_named_by_its_groundstation_rule():
    from roshan.config import Config, PlannerConfig, TrainConfig
    from roshan.runs.levels import kit_of

    def baseline_name(name, cfg):
        return kit_of(cfg).baseline_name(name, cfg)

    for home in ("original", "fixed"):
        cfg = Config(train=TrainConfig(algo="planner"), planner=PlannerConfig(greedy_home=home))
        name, note, extras = baseline_name("greedy", cfg)
        assert name == f"greedy ({home})" and f"planner.greedy_home = {home}" in note
        assert extras == {"greedy_home": home}
    original = Config(train=TrainConfig(algo="planner"), planner=PlannerConfig(greedy_home="original"))
    assert "never put out" in baseline_name("greedy", original)[1]
    assert baseline_name("greedy", Config()) == ("greedy", "", {})  # the FlyAgent's straight-to-goal


def test_the_resource_aware_greedy_is_named_so():
    """With a battery the greedy watches it (planner.greedy_resources, on by default), and its column says so, as
    the README does: the endurance evaluation called it plain "greedy (fixed)"."""
    from roshan.config import Config, DroneConfig, PlannerConfig, TrainConfig
    from roshan.config.sim import EnergyConfig
    from roshan.runs.baselines import planner_baseline_name as baseline_name

    planner = TrainConfig(algo="planner")
    battery = DroneConfig(energy=EnergyConfig(preset="scenario"))
    name, note, _ = baseline_name("greedy", Config(train=planner, drones=battery))
    assert name == "resource-aware greedy (fixed)" and "planner.greedy_resources" in note
    blind = Config(train=planner, drones=battery, planner=PlannerConfig(greedy_resources=False))
    assert baseline_name("greedy", blind)[0] == "greedy (fixed)"
    assert baseline_name("greedy", Config(train=planner))[0] == "greedy (fixed)"  # no battery to watch


def test_the_learning_curves_note_reads_the_training_episodes_from_the_log():
    """The note under a planner's learning curves said "time out: success 0 by design" under a training success
    curve at 1.0 for all 99 points (models/planner); it now says what the log holds."""
    from roshan.config import FLY_AGENT, PLANNER
    from roshan.runs.evaluate import training_note
    from roshan.runs.report.scalars import read_tensorboard_scalars

    scalars = read_tensorboard_scalars(ROOT / "models" / "planner" / "tb")
    note = training_note(PLANNER, scalars)
    assert "success 0" not in note and "time out" not in note
    assert "Training success 1.00 at the first point, 1.00 at the last." in note
    assert training_note(PLANNER, {}) is not None and training_note(FLY_AGENT, scalars) is None


@pytest.mark.slow
def test_a_fleet_planner_trains_on_each_fleet_in_turn_and_flies_another(tmp_path):
    """planner.fleet_sizes: an env per fleet, each taking an update in turn with the one network; the model then
    flies a fleet it never trained with."""
    from roshan.config import load_config
    from roshan.runs.train import Trainer

    sets = [a for a in TINY if a != "--set"]
    cfg = load_config(ROOT / "configs/planner.yaml", [*sets, "planner.network=fleet", "planner.fleet_sizes=2,3",
                                                      "train.max_updates=3"])
    trainer = Trainer(cfg, tmp_path / "fleet", progress_bar=False)
    trainer.run()
    assert [env.num_drones for env, _ in trainer.turns] == [2, 3]
    assert trainer.env.num_drones == 2  # updates 1 and 3 flew two drones, update 2 three
    assert trainer.progress.env_steps == 3 * 32  # every update: ppo.horizon decisions, whatever the fleet
    res = cli("eval", tmp_path / "fleet", "--episodes", 2, "--envs", 2, "--quiet", "--set", "drones.num_drones=5",
              "--out", tmp_path / "e5")
    assert res.exit_code == 0, res.output
    refused = cli("train", ROOT / "configs/planner.yaml", "--root", tmp_path, "--name", "r", *TINY,
                  "--set", "planner.fleet_sizes=2,3")
    assert refused.exit_code != 0 and "needs a network that flies any fleet" in refused.output


def test_base_counts_take_their_turns_with_each_fleet():
    """planner.base_counts: each fleet of planner.fleet_sizes with each count of bases, fleet by fleet; either key
    alone varies only its own setting, and neither leaves the run's one setting."""
    from roshan.config import ConfigError, load_config
    from roshan.runs.learners import fleet_configs

    base = [a for a in TINY if a != "--set"] + ["planner.network=fleet"]
    cfg = load_config(ROOT / "configs/planner.yaml", [*base, "planner.fleet_sizes=2,3", "planner.base_counts=1,2"])
    assert [(c.drones.num_drones, c.drones.bases) for c in fleet_configs(cfg)] == [(2, 1), (2, 2), (3, 1), (3, 2)]
    only = load_config(ROOT / "configs/planner.yaml", [*base, "planner.base_counts=2,1"])
    n = only.drones.num_drones
    assert [(c.drones.num_drones, c.drones.bases) for c in fleet_configs(only)] == [(n, 2), (n, 1)]
    one = load_config(ROOT / "configs/planner.yaml", [*base, "drones.num_drones=3", "planner.fleet_sizes='5'"])
    assert [c.drones.num_drones for c in fleet_configs(one)] == [5]
    plain = load_config(ROOT / "configs/planner.yaml", base)
    assert fleet_configs(plain) == [plain]
    with pytest.raises(ConfigError, match=r"planner.base_counts = '1,5': expected base counts from 1 to 4"):
        load_config(ROOT / "configs/planner.yaml", [*base, "planner.base_counts=1,5"])
