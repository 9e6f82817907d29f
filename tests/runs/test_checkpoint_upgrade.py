"""Checkpoints and run configs of the two-PPO era (a ``planner_ppo`` section, the planner's single optimiser)
load into the one PPO: the first shipped planner (tests/data/planner_v1) keeps its weights and hyperparameters, and
resumes."""

from pathlib import Path

import pytest
import torch
import yaml

from roshan.algos.agent import Agent
from roshan.algos.agents import make_agent
from roshan.algos.frozen import load_agent, policy_fn
from roshan.checkpoints import config_of_checkpoint, load_checkpoint, resolve_checkpoint
from roshan.config import Config, ConfigError, TrainConfig, all_keys, apply_overrides, load_config, to_dict

ROOT = Path(__file__).resolve().parents[2]
PLANNER = ROOT / "tests" / "data" / "planner_v1"  # the first shipped planner, of the two-PPO era


def raw_checkpoint(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=False)


def same_tree(a, b) -> bool:
    """Equal nested dicts / lists with tensors compared exactly."""
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        return isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor) and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same_tree(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same_tree(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def test_the_first_shipped_planner_checkpoint_loads_with_its_weights_and_hyperparameters():
    path = resolve_checkpoint(PLANNER)
    raw = raw_checkpoint(path)
    assert "planner_ppo" in raw["config"] and "optimizer" in raw["agent"]  # the old layout
    state = load_checkpoint(path)
    cfg = config_of_checkpoint(state, str(path))
    old = raw["config"]["planner_ppo"]
    assert cfg.planner.network == old["network"]
    assert {k: v for k, v in to_dict(cfg.ppo).items() if k in old} == {k: v for k, v in old.items() if k != "network"}
    assert same_tree(state["agent"]["optimizers"], [raw["agent"]["optimizer"]])
    assert same_tree(state["agent"]["schedulers"], [raw["agent"]["scheduler"]])
    agent = make_agent(cfg)
    agent.load_state_dict(state["agent"])  # everything, as a resume does
    assert same_tree(agent.net.state_dict(), raw["agent"]["net"])
    assert same_tree(agent.optimizers[0].state_dict(), raw["agent"]["optimizer"])
    assert agent.updates == raw["agent"]["updates"] and agent.scaler.count == raw["agent"]["scaler"]["count"]


def test_an_old_run_folder_config_upgrades_on_load(tmp_path):
    old = yaml.safe_load((PLANNER / "config.yaml").read_text())
    assert "planner_ppo" in old
    partial = {"train": {"algo": "planner"}, "planner_ppo": {"network": "pointer", "lr": 1e-3}}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(partial))
    cfg = load_config(tmp_path / "config.yaml")
    # keys the old section left out meant the old planner defaults, not the FlyAgent's
    assert (cfg.planner.network, cfg.ppo.lr, cfg.ppo.horizon, cfg.ppo.gamma, cfg.ppo.value_loss_coef) == (
        "pointer", 1e-3, 4800, 0.99, 0.001)
    shipped = load_config(PLANNER / "config.yaml")
    assert shipped.ppo.lr == old["planner_ppo"]["lr"] and shipped.ppo.horizon == old["planner_ppo"]["horizon"]


def test_flyagent_only_ppo_keys_are_refused_for_the_planner():
    with pytest.raises(ConfigError, match="ppo.use_tanh_dist"):
        load_config(ROOT / "configs" / "planner.yaml", ["ppo.use_tanh_dist=true"])
    with pytest.raises(ConfigError, match="ppo.minibatch"):
        load_config(ROOT / "configs" / "planner.yaml", ["ppo.minibatch=sequences"])
    load_config(ROOT / "configs" / "fly_collision.yaml", ["ppo.minibatch=sequences"])  # fine for FlyAgents


@pytest.mark.parametrize("algo", ["ppo", "planner", "td3", "iql"])
def test_every_agent_follows_the_protocol(algo):
    agent = make_agent(Config(train=TrainConfig(algo=algo)))
    assert isinstance(agent, Agent)
    assert policy_fn(agent) == agent.act_deterministic


def test_shipped_flyagents_act_deterministically_through_the_protocol():
    for name in ("fly_simple", "fly_collision"):
        cfg, agent, _ = load_agent(ROOT / "models" / name)
        obs = {"agent": torch.randn(5, cfg.fly.frames, 9), "neighbors": torch.randn(5, cfg.fly.frames, 4, 4),
               "neighbors_mask": torch.ones(5, cfg.fly.frames, 4)}
        with torch.no_grad():
            mean = agent.net(obs)[0]
        torch.testing.assert_close(agent.act_deterministic(obs), agent.policy.dist_class.mode_of(mean),
                                   rtol=0, atol=0)


def test_training_reads_the_one_batch_and_seed_keys_and_old_ones_move_there(tmp_path):
    """train.num_envs / train.seed (read by training while sim.envs / sim.seed were silently ignored) are now
    sim.envs / sim.seed everywhere: in old files, old checkpoints and --set."""
    assert not {"train.num_envs", "train.seed"} & set(all_keys())
    old = tmp_path / "old.yaml"
    old.write_text("train:\n  num_envs: 12\n  seed: 9\n  algo: ppo\nsim:\n  envs: 3\n")
    cfg = load_config(old)
    assert (cfg.sim.envs, cfg.sim.seed) == (12, 9)  # the old run trained with train.*
    assert load_config(None, ["train.num_envs=5"]).sim.envs == 5
    assert apply_overrides(Config(), ["train.seed=4"]).sim.seed == 4
    shipped = config_of_checkpoint(load_checkpoint(resolve_checkpoint(ROOT / "models" / "fly_simple")), "fly_simple")
    saved = yaml.safe_load((ROOT / "models" / "fly_simple" / "config.yaml").read_text())["train"]
    assert (shipped.sim.envs, shipped.sim.seed) == (saved["num_envs"], saved["seed"])
