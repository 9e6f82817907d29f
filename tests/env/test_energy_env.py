"""Batteries at the env level (issue 33): a FlyAgent drone whose battery runs empty ends its episode as "lost";
a planner episode fails as "lost" once every drone came down; the records and the evaluation carry the batteries."""

from pathlib import Path

import numpy as np
import pytest
import torch

from roshan.config import (
    Config,
    DroneConfig,
    EnergyConfig,
    IgnitionConfig,
    PlannerConfig,
    PlannerRewardConfig,
    WindConfig,
    load_config,
)
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.episode import LOST, REASONS
from roshan.runs.evaluate import flyagent_json, run_episodes
from roshan.runs.report import summarize

ROOT = Path(__file__).resolve().parents[2]
MODEL = str(ROOT / "models" / "fly_simple")
FIRES = IgnitionConfig(fire_percentage=0.05, clusters=2)
# 30 J at 100 W (+ 20 W payload, + the speed term): every drone that leaves the groundstation is down within 3 steps
TINY = EnergyConfig(preset="scenario", capacity=30.0)


def test_a_fly_agent_drone_with_an_empty_battery_ends_the_episode_as_lost():
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=2, groundstation_start_percentage=0.0, energy=TINY),
                 wind=WindConfig(speed=0.0))
    env = FlyVectorEnv(2, cfg, seed=1)
    assert env.failure_reasons == ("collision", "boundary", "timeout", "lost")
    env.reset(seed=1)
    actions = torch.zeros((2, 2, 2))
    for step in range(1, 4):
        _, _, terms, truncs, info = env.step(actions)
        if step < 3:
            assert not bool(info["_episode_stats"].any())
    assert bool(terms.all()) and not bool(truncs.any())  # a crash is no time-out: terminated, not truncated
    stats, batteries = info["episode_stats"], info["episode_energy"]
    assert stats["reason"].tolist() == [LOST, LOST] and stats["success"].tolist() == [0.0, 0.0]
    assert batteries["drones_lost"].tolist() == [2.0, 2.0]
    np.testing.assert_allclose(batteries["energy_used"].numpy(), [60.0, 60.0], rtol=1e-5)  # both batteries, whole
    env.close()


def test_without_a_battery_the_records_hold_no_battery_figures():
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=2, groundstation_start_percentage=0.0),
                 wind=WindConfig(speed=0.0))
    env = FlyVectorEnv(2, cfg, seed=1)
    assert "lost" not in env.failure_reasons
    env.reset(seed=1)
    for _ in range(3):
        _, _, _, _, info = env.step(torch.zeros((2, 2, 2)))
    assert not bool(info["_episode_stats"].any())
    assert all(float(v.abs().sum()) == 0.0 for v in info["episode_energy"].values())
    env.close()


def greedy_env(energy: EnergyConfig, resources: bool = True) -> PlannerVectorEnv:
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=3, energy=energy), wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, greedy_home="fixed",
                       greedy_resources=resources)
    return PlannerVectorEnv(2, cfg, pc, evaluation=True, controller="greedy", seed=3)


def test_a_planner_episode_fails_as_lost_once_every_drone_came_down():
    env = greedy_env(TINY, resources=False)
    assert env.failure_reasons == ("timeout", "burnout", "lost")
    out = run_episodes(env, lambda obs: torch.zeros((2, 3), dtype=torch.long), 2, seed=3)
    assert list(out["reason"]) == ["lost", "lost"] and out["success"].tolist() == [0, 0]
    assert out["drones_lost"].tolist() == [3, 3] and out["battery_swaps"].tolist() == [0, 0]
    np.testing.assert_allclose(out["energy_used"], [90.0, 90.0], rtol=1e-5)
    assert REASONS[LOST] == "lost"
    env.close()


def test_the_plain_greedy_blind_to_its_batteries_loses_every_drone():
    env = greedy_env(EnergyConfig(preset="scenario", capacity=4000.0), resources=False)
    out = run_episodes(env, lambda obs: torch.zeros((2, 3), dtype=torch.long), 2, seed=3)
    assert list(out["reason"]) == ["lost", "lost"]
    assert out["drones_lost"].tolist() == [3, 3] and out["battery_swaps"].tolist() == [0, 0]
    np.testing.assert_allclose(out["energy_used"], [12000.0, 12000.0], rtol=1e-5)  # three whole batteries each
    js = flyagent_json(summarize(out, reasons=env.failure_reasons), env.failure_reasons)  # eval --json's shape
    assert js["failure_rates"]["lost"] == 1.0 and js["drones_lost"] == 3.0 and js["battery_swaps"] == 0.0
    env.close()


def test_the_resource_aware_greedy_swaps_batteries_and_loses_no_drone():
    env = greedy_env(EnergyConfig(preset="scenario"))
    out = run_episodes(env, lambda obs: torch.zeros((2, 3), dtype=torch.long), 4, seed=3)
    assert out["drones_lost"].tolist() == [0, 0, 0, 0]  # a base is always reachable on this map: none may be lost
    assert out["success"].tolist() == [1, 1, 1, 1]
    assert out["battery_swaps"].sum() >= 3  # the long episodes needed returns (every drone swaps at once here)
    env.close()


@pytest.mark.slow
def test_the_resource_aware_greedy_loses_no_drone_in_the_endurance_setting():
    """configs/endurance.yaml (4 drones flown by the collision FlyAgent, the scenario battery, whose full charge
    flies home from any cell) with the 4-drop tank it had then (the drones run dry and go home together), 4 envs for
    200 s of their 357 s episodes. Before the greedy landed the drones that wait at the groundstation (issue 33) they
    jostled each other off its cell, never stayed the swap's 3 s there and came down beside it: 4 of these 16 drones
    (1.7 per episode over 32 whole episodes)."""
    cfg = load_config(ROOT / "configs" / "endurance.yaml", ["drones.water_capacity=4"])  # the tank it was seen with
    env = PlannerVectorEnv(4, cfg, evaluation=True, controller="greedy", seed=7)
    env.reset(seed=7)
    actions = torch.zeros((4, 4), dtype=torch.long)
    for _ in range(400):  # a decision every 5 low-level steps of 0.1 s
        _, _, terms, truncs, info = env.step(actions)
        ended = terms | truncs
        assert float(info["episode_energy"]["drones_lost"][ended].sum()) == 0.0
    battery = env.drones.battery
    assert int(battery.lost.to_numpy().sum()) == 0
    assert int(battery.swaps.to_numpy().min(axis=1).min()) >= 1  # every env swapped batteries: the rule was used
    env.close()


def planner_env(energy: EnergyConfig, resources: bool = False, queue: str = "all", **rewards) -> PlannerVectorEnv:
    """A planner-controlled env in training mode (explorers parked), 3 drones, a decision every low-level step;
    ``resources``: planner.planner_resources; ``queue``: planner.return_queue; ``rewards`` replace the whole
    reward (every other term 0)."""
    zero = {k: 0.0 for k in ("goal", "burned", "ground", "timeout", "same", "extinguish", "fast", "lost")}
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=3, energy=energy), wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, planner_resources=resources,
                       return_queue=queue, rewards=PlannerRewardConfig(**{**zero, **rewards}))
    return PlannerVectorEnv(2, cfg, pc, controller="planner", seed=4)


def home_fraction(env: PlannerVectorEnv, battery: float) -> np.ndarray:
    """(E, N) energy of each drone's quickest flight home over a full battery, computed here from the positions
    (kernels/battery.py Battery.energy_home, with the scenario's powers and a full tank)."""
    dr, values = env.drones, env.config.drones.energy.values()
    centre = (dr.bases.to_numpy()[:, 0][:, None, :] + 0.5) * dr.cell
    gap = np.abs(centre - dr.pos.to_numpy())
    long_axis, short_axis = gap.max(-1), gap.min(-1)
    v = env.config.drones.max_speed
    speed_sq = v * v * (1.0 + (short_axis / np.maximum(long_axis, 1e-6)) ** 2)
    power = values["hover_power"] + values["speed_power"] * speed_sq + values["payload_power"]
    return np.clip(power * long_axis / v / battery, 0.0, 1.0)


def test_the_planner_observes_each_drones_charge_and_the_charge_its_flight_home_needs():
    env = planner_env(EnergyConfig(preset="scenario"))
    assert env.single_observation_space["energy"].shape == (3, 2)
    obs, _ = env.reset(seed=4)
    assert obs["energy"].shape == (2, 3, 2) and bool((obs["energy"][..., 0] == 1.0).all())  # full at the start
    for _ in range(12):  # every drone flies to the first listed fire
        obs, *_ = env.step(torch.ones((2, 3), dtype=torch.long))
    battery = env.config.drones.energy.values()["capacity"]
    charge = env.drones.battery.charge.to_numpy() / battery
    assert float(charge.max()) < 1.0  # they flew: the batteries drained
    np.testing.assert_allclose(obs["energy"][..., 0].numpy(), charge, rtol=1e-6)
    home = home_fraction(env, battery)
    assert float(home.max()) > 0.0
    np.testing.assert_allclose(obs["energy"][..., 1].numpy(), home, rtol=1e-4, atol=1e-6)
    env.close()


def test_without_a_battery_the_planner_observation_has_no_energy_part():
    env = planner_env(EnergyConfig())
    assert "energy" not in env.single_observation_space.spaces
    obs, _ = env.reset(seed=4)
    assert "energy" not in obs
    env.close()


def test_drone_lost_pays_its_penalty_once_for_each_drone_that_came_down():
    env = planner_env(TINY, lost=-2.0)
    env.reset(seed=4)
    total, lost, running = torch.zeros(2), torch.zeros(2), torch.ones(2, dtype=torch.bool)
    for _ in range(30):  # 30 J: each drone is down within 3 steps of leaving the groundstation
        _, rewards, terms, truncs, info = env.step(torch.ones((2, 3), dtype=torch.long))
        total += rewards * running  # the first episode of each env
        ended = (terms | truncs) & running
        lost[ended] = info["episode_energy"]["drones_lost"][ended]
        running &= ~ended
        if not bool(running.any()):
            break
    assert not bool(running.any()) and lost.tolist() == [3.0, 3.0]
    torch.testing.assert_close(total, torch.full((2,), -6.0))  # the only term: 3 drones x -2, each once
    env.close()


def test_planner_drones_sent_home_together_land_there_and_get_their_swap():
    """The planner sends all three drones home at once: each lands on the groundstation cell (its position no longer
    changes while its goal is home, whatever the FlyAgent would do there) and gets its battery swapped. Hovering
    instead, the FlyAgent moved them about the cell, and several at once jostled each other off it (issue 33)."""
    env = planner_env(EnergyConfig(preset="scenario"))
    env.reset(seed=4)
    for _ in range(12):  # out to the first listed fire: the batteries drain
        env.step(torch.ones((2, 3), dtype=torch.long))
    dr = env.drones
    gs = dr.bases.to_numpy()[:, 0][:, None, :]
    landed_at = {}
    for _ in range(150):
        env.step(torch.zeros((2, 3), dtype=torch.long))  # candidate 0: the groundstation
        pos = dr.pos.to_numpy()
        on_base = (np.floor(pos / dr.cell).astype(int) == gs).all(-1)  # pos and the cell: (row, column)
        for e, d in zip(*np.nonzero(on_base), strict=True):
            landed_at.setdefault((e, d), pos[e, d].copy())
            np.testing.assert_array_equal(pos[e, d], landed_at[(e, d)])  # landed: it stays where it came down
    assert len(landed_at) == 6  # every drone of both envs reached the cell
    assert int(dr.battery.lost.to_numpy().sum()) == 0 and int(dr.battery.swaps.to_numpy().min()) >= 1
    env.close()


def test_planner_drones_with_the_resource_rule_go_home_by_themselves_and_stay_until_stocked():
    """planner.planner_resources: a planner that only ever names the first listed fire loses no drone (with 4 kJ
    batteries and no rule, all three drones of both envs come down within 400 steps), every drone that flies home
    or waits there keeps the groundstation as its goal whatever the planner says, and choosing the groundstation for
    a drained drone sends it home until it is stocked again."""
    env = planner_env(EnergyConfig(preset="scenario", capacity=4000.0), resources=True)
    env.reset(seed=4)
    fire, home = torch.ones((2, 3), dtype=torch.long), torch.zeros((2, 3), dtype=torch.long)
    dr = env.drones
    for _ in range(12):  # out to the first listed fire: the batteries drain
        env.step(fire)
    env.step(home)
    assert dr.refilling.to_numpy().all()  # drained: sent home until stocked
    centre = dr.bases.to_numpy()[:, 0][:, None, :] + 0.5
    lost = 0.0
    for _ in range(400):
        _, _, terms, truncs, info = env.step(fire)
        ended = terms | truncs
        lost += float(info["episode_energy"]["drones_lost"][ended].sum())
        waiting = dr.refilling.to_numpy() != 0
        np.testing.assert_array_equal(dr.goal.to_numpy()[waiting], np.broadcast_to(centre, (2, 3, 2))[waiting])
    assert lost == 0.0 and int(dr.battery.lost.to_numpy().sum()) == 0
    assert int(dr.battery.swaps.to_numpy().min()) >= 1  # every drone went home and got a swap
    env.close()


def test_the_waiting_queue_reserve_counts_only_the_drones_restocking_now():
    """planner.return_queue: with `all` a drone keeps every other drone's turn at the base in reserve, with `waiting`
    only the turns of the drones flying home or waiting there now, with `none` nothing (landed drones swap side by
    side), so out at the fires with nobody restocking it turns home later, and still loses no drone."""
    fire = torch.ones((2, 3), dtype=torch.long)
    first_return = {}
    for queue in ("all", "waiting", "none"):
        env = planner_env(EnergyConfig(preset="scenario", capacity=4000.0), resources=True, queue=queue)
        env.reset(seed=4)
        dr, lost = env.drones, 0.0
        for step in range(400):
            _, _, terms, truncs, info = env.step(fire)
            lost += float(info["episode_energy"]["drones_lost"][terms | truncs].sum())
            if queue not in first_return and dr.refilling.to_numpy().any():
                first_return[queue] = step
        assert lost == 0.0 and int(dr.battery.lost.to_numpy().sum()) == 0, queue
        assert int(dr.battery.swaps.to_numpy().min()) >= 1, queue
        env.close()
    assert first_return["none"] >= first_return["waiting"] > first_return["all"]


@pytest.mark.slow
def test_drones_landed_at_the_groundstation_do_not_keep_another_off_it():
    """configs/endurance.yaml's collision FlyAgent: the planner keeps drones 0-2 at the groundstation and sends drone 3
    to the first listed fire. Drone 3 comes back on the return rule and gets its swap. Before landed drones left the
    others' neighbour lists, it circled 8-13 m off the crowded cell until its battery ran out (every env, decisions
    231-249)."""
    cfg = load_config(ROOT / "configs" / "endurance.yaml")
    env = PlannerVectorEnv(2, cfg, controller="planner", seed=7)
    env.reset(seed=7)
    actions = torch.zeros((2, 4), dtype=torch.long)
    actions[:, 3] = 1
    for _ in range(300):
        _, _, terms, truncs, info = env.step(actions)
        ended = terms | truncs
        assert float(info["episode_energy"]["drones_lost"][ended].sum()) == 0.0
    assert int(env.drones.battery.lost.to_numpy().sum()) == 0
    assert int(env.drones.battery.swaps.to_numpy()[:, 3].min()) >= 1  # drone 3 came back and swapped in both envs
    env.close()


def test_drones_restocking_under_the_return_rule_share_no_goal():
    """SameGoalPenalty counts drones with one goal; with planner.planner_resources, drones that fly home to restock
    (sent by the planner or by the rule) have no fire to share: three drones sent home together cost nothing, where
    the thesis's count (no rule) charges two duplicates for every decision of it."""
    for resources, per_decision in ((True, 0.0), (False, -2.0)):
        env = planner_env(EnergyConfig(preset="scenario"), resources=resources, same=-1.0)
        env.reset(seed=4)
        for _ in range(12):  # out to the first listed fire: the batteries drain
            env.step(torch.ones((2, 3), dtype=torch.long))
        for _ in range(5):
            _, rewards, *_ = env.step(torch.zeros((2, 3), dtype=torch.long))
            torch.testing.assert_close(rewards, torch.full((2,), per_decision))
        env.close()


def test_options_that_do_nothing_without_a_battery_say_so_once():
    # issue 52: planner.planner_resources and drones.energy.approach with the battery off, and
    # planner.max_candidates=1, changed nothing and said nothing
    cfg = Config(ignition=FIRES, drones=DroneConfig(num_drones=3, energy=EnergyConfig(approach=1.5)),
                 wind=WindConfig(speed=0.0))
    pc = PlannerConfig(interval=1, fly_model=MODEL, explorer_model=MODEL, num_explorers=2, planner_resources=True,
                       max_candidates=1)
    with pytest.warns(UserWarning) as caught:
        env = PlannerVectorEnv(2, cfg, pc, evaluation=True, controller="greedy", seed=3)
    env.close()
    said = [str(w.message) for w in caught]
    for words in ("drones.energy.approach = 1.5 does nothing while drones.energy.preset is off",
                  "planner.planner_resources = true does nothing while drones.energy.preset is off",
                  "planner.max_candidates = 1 lists the groundstation alone"):
        assert sum(words in line for line in said) == 1, said
    assert DroneConfig(energy=EnergyConfig(preset="scenario", approach=2.0)).inert() == []
    assert PlannerConfig(planner_resources=True).inert(DroneConfig(energy=EnergyConfig(preset="scenario"))) == []
