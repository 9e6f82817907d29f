"""The planner's clairvoyant reference (``roshan eval RUN --baseline clairvoyant``): the assignment of drones to fires
with the least summed flight time each decision, the battery's reserve kept, on every burning cell from the start."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from roshan.cli import main
from roshan.runs.baselines import _assign, baseline_fn, clairvoyant_fn

ROOT = Path(__file__).resolve().parents[2]


def scene(drones, fires, water=None, energy=None) -> dict:
    """One env's planner observation: candidate 0 the groundstation at (-1, -1), then the fires."""
    n = len(drones)
    cand = np.array([(-1.0, -1.0), *fires], dtype=np.float32)
    obs = {"drones": torch.tensor([drones], dtype=torch.float32), "fires": torch.from_numpy(cand[None]),
           "fires_mask": torch.ones(1, len(cand)), "water": torch.ones(1, n, 1) if water is None
           else torch.tensor(water, dtype=torch.float32).view(1, n, 1)}
    if energy is not None:
        obs["energy"] = torch.tensor(energy, dtype=torch.float32).view(1, 2 * n)
    return obs


def test_the_least_summed_flight_time_beats_each_drone_taking_its_nearest_fire():
    """Drone 0 at 0 and drone 1 at 0.5 on one line, fires at 0.3 and -0.4: each taking its nearest in turn flies
    0.3 + 0.9 = 1.2; the assignment flies 0.4 + 0.2 = 0.6 (drone 0 to -0.4, drone 1 to 0.3)."""
    goals = clairvoyant_fn(0.25)(scene([(0.0, 0.0), (0.5, 0.0)], [(0.3, 0.0), (-0.4, 0.0)]))
    assert goals.tolist() == [[2, 1]]


def test_the_flight_time_is_the_longer_axis():
    """Drones fly at v_max per axis: (0.5, 0.5) away takes as long as (0.5, 0): the Chebyshev distance."""
    drones = np.array([(0.0, 0.0)], dtype=np.float32)
    fires = np.array([(-1.0, -1.0), (0.5, 0.5), (0.0, 0.6)], dtype=np.float32)
    assert _assign(drones, fires, np.ones(3, bool), np.zeros(1, bool)).tolist() == [1]  # 0.5 < 0.6


def test_drones_left_over_take_their_nearest_fire_and_padding_is_never_chosen():
    obs = scene([(0.0, 0.0), (0.1, 0.0), (0.9, 0.0)], [(0.05, 0.0), (5.0, 5.0)])
    obs["fires_mask"][0, 2] = 0  # the far candidate is padding
    assert clairvoyant_fn(0.25)(obs).tolist() == [[1, 1, 1]]


def test_an_empty_tank_or_the_batterys_reserve_sends_a_drone_home_and_it_waits_there_for_a_full_one():
    fires = [(0.0, 0.0)]
    drones = [(0.1, 0.0)] * 4
    # (charge, charge the flight home needs) per drone: plenty; at the reserve (0.25 x 1.25 = 0.3125 >= 0.3);
    # landed and not full; landed and full
    energy = [1.0, 0.2, 0.3, 0.25, 0.5, 0.0, 1.0, 0.0]
    goals = clairvoyant_fn(0.25)(scene(drones, fires, energy=energy))
    assert goals.tolist() == [[1, 0, 0, 1]]
    goals = clairvoyant_fn(0.25)(scene(drones[:2], fires, water=[0.0, 0.5]))
    assert goals.tolist() == [[0, 1]]


def test_a_flyagent_has_no_clairvoyant_baseline():
    with pytest.raises(ValueError, match="clairvoyant plays the planner's level"):
        baseline_fn("clairvoyant", 2, 2, 0)


@pytest.mark.slow
def test_the_planner_is_evaluated_beside_the_clairvoyant_reference(tmp_path):
    res = CliRunner().invoke(main, ["eval", str(ROOT / "models/planner"), "--baseline", "clairvoyant", "--episodes",
                                    "2", "--envs", "2", "--quiet", "--out", str(tmp_path / "e"), "--json",
                                    str(tmp_path / "e.json"), "--set", "ignition.fire_percentage=0.02"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    payload = json.loads((tmp_path / "e.json").read_text())
    assert set(payload) >= {"policy", "clairvoyant"}
    assert 0.0 <= payload["clairvoyant"]["success_rate"] <= 1.0
    assert "clairvoyant reference" in res.output


def test_with_two_bases_a_drone_sent_home_takes_its_nearest_base():
    """Candidates 0 and 1 are bases at (-1, -1) and (1, 1): the drone with an empty tank near (1, 1) goes to base 1,
    the one near (-1, -1) to base 0, and the fires after the bases are assigned among the others."""
    drones = np.array([(0.8, 0.9), (-0.7, -0.9), (0.0, 0.0)], dtype=np.float32)
    fires = np.array([(-1.0, -1.0), (1.0, 1.0), (0.1, 0.0), (0.5, -0.5)], dtype=np.float32)
    home = np.array([True, True, False])
    assert _assign(drones, fires, np.ones(4, bool), home, bases=2).tolist() == [1, 0, 2]
    assert _assign(drones, fires, np.ones(4, bool), home).tolist()[:2] == [0, 0]  # one base: the groundstation
