"""``roshan simulate --drones``: the straight-to-goal controller, drone frames, the JSON keys and bad input.

Each new FlyVectorEnv configuration compiles its kernels (10-15 s on a cold cache), so the tests use two:
one simple-policy drone (controller, overlay) and three complex-policy drones on 35x36_Woods (CLI).
"""

import json

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from PIL import Image

from roshan.cli import main
from roshan.config import Config, DroneConfig, EnergyConfig, FlyConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.heuristics import random_actions, straight_to_goal
from roshan.kernels.battery import BATTERY_COLOUR
from roshan.kernels.drones import TANK_COLOUR
from roshan.kernels.render import FrameRenderer, drone_colours, drone_overlay
from roshan.tools.simulate import DRONE_SERIES_KEYS, SERIES_KEYS

CELLS_PER_STEP = 0.1  # v_max * dt / cell size with the default drone physics (10 m/s, 0.1 s, 10 m)


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def test_straight_to_goal_commands_point_at_the_goal_and_stop_there():
    obs = torch.zeros(2, 3, 3, 9)
    obs[0, :, 0, 3:5] = torch.tensor([[1.0, 0.5], [0.02, -0.01], [0.0, 0.0]])  # far, near, at the goal
    obs[1, :, 1, 3:5] = 1.0  # an older frame: must be ignored
    a = straight_to_goal(obs)
    assert a.shape == (2, 3, 2) and bool((a.abs() <= 1).all())
    assert torch.allclose(a[0, 0], torch.tensor([1.0, 0.5]))  # full speed on the long axis, direction kept
    assert torch.allclose(a[0, 1], torch.tensor([0.2, -0.1]))  # slows down near the goal
    assert bool((a[0, 2] == 0).all()) and bool((a[1] == 0).all())
    g = torch.Generator().manual_seed(3)
    r = random_actions(4, 2, g)
    assert r.shape == (4, 2, 2) and bool((r.abs() <= 1).all())
    assert torch.equal(r, random_actions(4, 2, torch.Generator().manual_seed(3)))


@pytest.fixture(scope="module")
def simple_env():
    """4 envs with one simple-policy drone: the episode succeeds when the drone reaches its goal."""
    return FlyVectorEnv(num_envs=4, config=Config(drones=DroneConfig(num_drones=1)),
                        fly=FlyConfig(policy="simple", fire_goal_percentage=0.5), seed=5)


@pytest.mark.slow
def test_straight_to_goal_reaches_the_goal_in_about_the_straight_line_time(simple_env):
    env = simple_env
    obs, _ = env.reset(seed=5)
    gap = np.abs(env.drones.goal.to_numpy() - env.drones.pos.to_numpy() / env.fire.cell_size).max(-1)[:, 0]
    # Full speed on the longer axis until 0.5 cells away: a few steps over the straight-line time to the
    # 0.25-cell tolerance (the goal-delta feature is clipped per axis beyond 5 cells, which bends the path).
    bound = np.ceil((gap - 0.25) / CELLS_PER_STEP) + 10
    assert gap.min() > 1.0, "the goals should not start under the drones"
    steps = np.zeros(env.num_envs)
    success = np.zeros(env.num_envs)
    for t in range(1, int(bound.max()) + 1):
        obs, _, _, _, info = env.step(straight_to_goal(obs["agent"]))
        first = info["_episode_stats"].numpy() & (steps == 0)
        steps[first] = t
        success[first] = info["episode_stats"]["success"].numpy()[first]
        if (steps > 0).all():
            break
    assert (steps > 0).all(), f"episodes still running after {int(bound.max())} steps: {steps}"
    assert (success == 1).all()
    assert (steps <= bound).all(), (steps, bound)


def test_drone_overlay_draws_north_up_where_the_drone_and_its_goal_are(simple_env):
    env = simple_env
    env.reset(seed=5)
    env.drones.set_state(np.tile([35.0, 202.5], (4, 1, 1)), np.zeros((4, 1, 2)))  # row 3.5, column 20.25 cells
    env.drones.set_goals(np.tile([10.5, 5.5], (4, 1, 1)))
    renderer = FrameRenderer(env.fire, env=2, cell_px=10, backend="raster", particles=False, wind_arrow=False)
    img = renderer.render(overlay=drone_overlay(env.drones, env=2))
    colour = drone_colours(1)[0]
    assert (img[35, 202] == colour).all(), "the disc sits at (x1, x2) / cell_size * cell_px"
    assert not (img[202 % img.shape[0], 35] == colour).all()
    assert (img[105, 55] == colour).all(), "the goal cross is centred on the goal (grid units * cell_px)"
    gs_row, gs_col = env.drones.bases.to_numpy()[:, 0][2] * 10
    assert (img[gs_row, gs_col:gs_col + 10] == 255).all(), "the groundstation cell has a white outline"


@pytest.fixture(scope="module")
def greedy_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("drones")
    frames, out = tmp / "frames", tmp / "run.json"
    r = invoke("simulate", "--map", "35x36_Woods", "--drones", 3, "--policy", "greedy", "--steps", 400,
               "--every", 200, "--frames", frames, "--json", out, "--quiet")
    assert r.exit_code == 0, r.output
    return r, sorted(frames.glob("*.png")), json.loads(out.read_text())


@pytest.mark.slow
def test_simulate_with_greedy_drones_draws_them_in_their_colours(greedy_run):
    r, pngs, _ = greedy_run
    assert "success rate" in r.output and "episodes finished" in r.output
    assert [p.name[:13] for p in pngs] == ["frame_0000000", "frame_0000200", "frame_0000400"]
    assert all("_ep" in p.name for p in pngs)
    for png in (pngs[0], pngs[-1]):
        img = np.asarray(Image.open(png).convert("RGB"))
        for d, colour in enumerate(drone_colours(3)):
            assert (img == colour).all(-1).sum() >= 20, f"{png.name}: drone {d}'s colour {colour} is missing"
        assert (img == 255).all(-1).sum() > 0, "the groundstation's white outline is missing"


def test_simulate_with_drones_json_keeps_the_schema_and_adds_episode_keys(greedy_run):
    _, _, data = greedy_run
    assert {"config", "series", "timing"} <= set(data)
    assert data["config"]["drones"]["num_drones"] == 3
    assert [rec["step"] for rec in data["series"]] == [0, 200, 400]
    for rec in data["series"]:
        assert set(SERIES_KEYS) | set(DRONE_SERIES_KEYS) <= set(rec)
        assert all(len(rec[k]) == 1 for k in SERIES_KEYS + DRONE_SERIES_KEYS)
    last = data["series"][-1]
    assert last["successes"][0] <= last["episodes"][0]
    assert last["extinguished_total"][0] >= last["extinguished"][0]
    assert last["extinguished_total"][0] > 0, "greedy drones should have put out some fire in 40 s"
    summary = data["drones"]
    assert summary["drones"] == 3 and summary["policy"] == "greedy" and summary["episodes"] == last["episodes"][0]


def test_simulate_with_random_drones_runs(tmp_path):
    out = tmp_path / "random.json"
    r = invoke("simulate", "--map", "35x36_Woods", "--drones", 3, "--policy", "random", "--steps", 50, "--every",
               25, "--json", out, "--quiet")
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["drones"]["policy"] == "random" and len(data["series"]) == 3


def test_simulate_rejects_bad_drone_options():
    for bad in ("0", "-1"):
        r = CliRunner().invoke(main, ["simulate", "--drones", bad, "--steps", "1"])
        assert r.exit_code != 0 and "--drones: expected a positive number" in r.output, r.output
    r = CliRunner().invoke(main, ["simulate", "--policy", "random", "--steps", "1"])
    assert r.exit_code != 0 and "--policy needs --drones" in r.output
    r = CliRunner().invoke(main, ["simulate", "--drones", "2", "--policy", "smart", "--steps", "1"])
    assert r.exit_code != 0 and "'smart' is not one of" in r.output


def test_with_a_battery_and_a_tank_each_drone_carries_its_charge_and_fill_as_bars():
    cfg = Config(drones=DroneConfig(num_drones=1, use_water_limit=True, energy=EnergyConfig(preset="scenario")))
    env = FlyVectorEnv(1, cfg, seed=2)
    env.reset(seed=2)
    env.drones.set_state(np.array([[[95.0, 152.5]]]), np.zeros((1, 1, 2)))
    battery = cfg.drones.energy.values()["capacity"]
    env.drones.battery.charge.from_numpy(np.full((1, 1), battery / 2, np.float32))  # half charged
    env.drones.water.from_numpy(np.full((1, 1), cfg.drones.water_capacity / 4, np.float32))  # a quarter full
    renderer = FrameRenderer(env.fire, cell_px=10, backend="raster", particles=False, wind_arrow=False)
    img = renderer.render(overlay=drone_overlay(env.drones))
    rows = {}
    for name, colour in (("battery", BATTERY_COLOUR), ("tank", TANK_COLOUR)):
        hit = (img == np.asarray(colour, np.uint8)).all(-1)
        ys, xs = hit.nonzero()
        assert ys.size and 95 < ys.min() and np.ptp(xs) < 12, f"the {name} bar sits under the disc"
        rows[name] = ys.min(), hit[ys.min()].sum()
    assert rows["tank"][0] > rows["battery"][0]  # the tank's bar below the battery's
    assert abs(rows["battery"][1] - 2 * rows["tank"][1]) <= 1  # half a bar against a quarter of one
    env.close()


def test_drones_on_one_spot_are_all_visible_as_nested_rings():
    """Drones without collisions can sit on one spot (in `roshan watch models/fly_simple` drone 0 vanished under
    drone 2 while the legend listed it): a disc drawn on an earlier drone's is smaller, so every drone shows."""
    env = FlyVectorEnv(num_envs=1, config=Config(drones=DroneConfig(num_drones=3)), fly=FlyConfig(policy="simple"),
                       seed=5)
    env.reset(seed=5)
    env.drones.set_state(np.tile([[35.0, 202.5]], (1, 3, 1)), np.zeros((1, 3, 2)))  # all three on one point
    env.drones.set_goals(np.tile([[10.5, 5.5]], (1, 3, 1)))
    renderer = FrameRenderer(env.fire, env=0, cell_px=10, backend="raster", particles=False, wind_arrow=False)
    img = renderer.render(overlay=drone_overlay(env.drones))
    disc = img[20:51, 187:218]  # around the spot: the view squares' outlines lie outside it
    counts = [int((disc == colour).all(-1).sum()) for colour in drone_colours(3)]
    assert all(n >= 4 for n in counts), f"pixels of drones 0, 1, 2 at their shared spot: {counts}"
    assert (img[35, 202] == drone_colours(3)[2]).all(), "the last drone is drawn on top, in the middle"
    env.close()
