"""What a frame shows (issue 15): the planner's explorers, the detected-fire map, cells put out by water, and the
caption and legend bands around the map."""

from pathlib import Path

import numpy as np
import pytest
import taichi as ti

from roshan.config import Config, DroneConfig, IgnitionConfig, MapConfig, PlannerConfig
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.kernels import annotate
from roshan.kernels.render import (
    EXPLORER_COLOUR,
    EXTINGUISHED_COLOUR,
    UNSEEN_FIRE_COLOUR,
    FrameRenderer,
    cell_colours,
    frame_legend,
)
from roshan.maps import BURNED, BURNING, CLASSES, SEALED
from tests.conftest import sim_with_fires

MODEL = str(Path(__file__).resolve().parents[2] / "models" / "fly_simple")
CFG = Config(map=MapConfig(name="15x15_Woods"), ignition=IgnitionConfig(fire_percentage=0.05),
             drones=DroneConfig(num_drones=2))
CELL_PX = 10


@pytest.fixture(scope="module")
def planner_env():
    """A greedy planner env in evaluation (its explorers fly), 10 decisions after a seeded reset."""
    pc = PlannerConfig(fly_model=MODEL, explorer_model=MODEL, num_explorers=3)
    env = PlannerVectorEnv(1, CFG, pc, evaluation=True, controller="greedy", seed=2)
    env.reset(seed=2)
    for _ in range(10):
        env.step(np.zeros((1, 2), np.int64))
    yield env
    env.close()


@pytest.mark.slow
def test_planner_frame_draws_every_explorer_where_it_flies(planner_env):
    env = planner_env
    frame = env._viewer.render()  # the map alone
    cell_px = frame.shape[0] // env.fire.rows
    px_per_m = cell_px / env.fire.cell_size
    drones = env.drones.pos.to_numpy()[0] * px_per_m
    explorers = env.explorers.pos.to_numpy()[0] * px_per_m
    assert len(explorers) == 3
    for y, x in explorers:
        if np.min(np.hypot(*(drones - (y, x)).T)) < cell_px:  # a planner drone's disc is drawn on top
            continue
        py, px = min(int(y), frame.shape[0] - 1), min(int(x), frame.shape[1] - 1)  # waypoints may lie on the edge
        assert tuple(frame[py, px]) == EXPLORER_COLOUR, f"no explorer drawn at pixel {(y, x)}"


def test_planner_frame_has_a_caption_above_and_a_legend_below_the_map(planner_env):
    env = planner_env
    bare = env._viewer.render()
    framed = env.render()
    assert framed.shape[1] == bare.shape[1] and framed.shape[0] > bare.shape[0]
    rows = [t for t in range(framed.shape[0] - bare.shape[0] + 1)
            if np.array_equal(framed[t:t + bare.shape[0]], bare)]
    assert len(rows) == 1, "the map must appear unchanged between the bands"
    top = rows[0]
    caption, legend = framed[:top], framed[top + bare.shape[0]:]
    assert top > 0 and legend.shape[0] > 0
    for band in (caption, legend):
        drawn = np.any(band != annotate.BAND_COLOUR, axis=-1)
        assert drawn.mean() > 0.02, "the band holds no text"
    labels = [item.label for item in env._viewer.legend()]
    assert {"drone 0", "drone 1", "explorer", "fire, seen", "fire, unseen", "put out", "groundstation"} <= set(labels)
    assert "greedy" in env.caption() and "episode 1" in env.caption() and "step 50" in env.caption()
    env.caption_name = "someone else"  # the caption band changes with the caption
    assert not np.array_equal(env.render()[:top], caption)
    env.caption_name = env.default_caption_name


@pytest.mark.slow
def test_fly_frame_legend_has_no_explorers_nor_unseen_fires():
    env = FlyVectorEnv(num_envs=1, config=CFG, seed=1)
    env.reset(seed=1)
    labels = [item.label for item in env._viewer.legend()]
    assert "explorer" not in labels and "fire, unseen" not in labels and "fire" in labels
    assert env.caption().startswith("FlyAgent | episode 1 | step 0 | t = 0.0 s | fires left ")
    env.close()


@pytest.fixture(scope="module")
def sim():
    """1 env of 35x36_Woods, no random fires; cells (5, 5) and (5, 6) burning for 10 s."""
    s = sim_with_fires("35x36_Woods", [(0, 5, slice(5, 7))])
    s.step(100)
    return s


def cell_pixel(frame, i, j):
    return tuple(int(v) for v in frame[i * CELL_PX + CELL_PX // 2, j * CELL_PX + CELL_PX // 2])


def test_extinguished_cells_keep_the_put_out_colour_after_the_flood(sim):
    land = sim.land.to_numpy().reshape(sim.rows, sim.cols)
    out = np.zeros((1, 1), np.int32)
    sim.flood(np.array([[5 * sim.cols + 5]], np.int32), out)
    assert out[0, 0] == 1
    sim.step(int(round(2 * sim.fire_cfg.flood_duration / sim.fire_cfg.dt)))  # the flood has drained
    assert sim.state(0)[5, 5] == land[5, 5]  # back to its class: only the colour tells it was put out
    frame = FrameRenderer(sim, cell_px=CELL_PX, particles=False, backend="raster", wind_arrow=False).render()
    assert cell_pixel(frame, 5, 5) == EXTINGUISHED_COLOUR
    assert cell_pixel(frame, 5, 6) == tuple(cell_colours()[BURNING, land[5, 6]])  # never flooded: still burning
    sim.reset()  # a new episode forgets the mark
    frame = FrameRenderer(sim, cell_px=CELL_PX, particles=False, backend="raster", wind_arrow=False).render()
    assert cell_pixel(frame, 5, 5) == tuple(cell_colours()[land[5, 5], land[5, 5]])


def test_fires_not_on_the_detected_map_are_dimmed():
    s = sim_with_fires("15x15_Woods", [(0, 3, slice(3, 5))])
    known = ti.field(ti.i8, (1, s.rows, s.cols))
    known[0, 3, 3] = 1  # only (3, 3) has been seen
    frame = FrameRenderer(s, cell_px=CELL_PX, particles=False, backend="raster", wind_arrow=False,
                          known_fires=known).render()
    assert cell_pixel(frame, 3, 3) == (255, 0, 0)
    assert cell_pixel(frame, 3, 4) == UNSEEN_FIRE_COLOUR


def test_single_env_renders_the_terminal_state_until_the_reset():
    import gymnasium

    env = gymnasium.make("roshan/FlyAgent-v0", config=CFG, render_mode="rgb_array")
    env.reset(seed=3)
    start = env.render()
    for _ in range(env.unwrapped.vector_env.t_max):
        _, _, terminated, truncated, _ = env.step(-np.ones((2, 2), np.float32))  # both drones fly off the map
        if terminated or truncated:
            break
    assert terminated or truncated
    end = env.render()
    env.reset()
    assert not np.array_equal(end, env.render()), "after the last step render() showed the next episode"
    assert not np.array_equal(end, start)
    env.close()


def test_caption_line_breaks_do_not_depend_on_the_numbers():
    frame = np.zeros((40, 300, 3), np.uint8)
    short = annotate.annotate(frame, "FlyAgent model x | episode 0 | step 0 | t = 0.0 s | fires left 3", [])
    long = annotate.annotate(frame, "FlyAgent model x | episode 12 | step 12345 | t = 1234.5 s | fires left 300", [])
    assert short.shape == long.shape  # every frame of a GIF has the same size


# ------------------------------------------------------------------------------- issue 32, items 11 and 16


def legend_band(framed: np.ndarray, bare: np.ndarray) -> np.ndarray:
    """The band below the map of an annotated frame (the map appears once, unchanged, between the bands)."""
    h = bare.shape[0]
    (top,) = [t for t in range(framed.shape[0] - h + 1) if np.array_equal(framed[t:t + h], bare)]
    return framed[top + h:]


def has_colour(img: np.ndarray, colour, at_least: int = 20) -> bool:
    return int((img == np.array(colour, np.uint8)).all(-1).sum()) >= at_least


def test_put_out_cells_are_one_colour_whatever_the_land_below():
    s = sim_with_fires("35x36_Woods", [(0, 1, slice(0, 2))])  # (1, 0) broadleaved, (1, 1) needle-leaved trees
    land = s.land.to_numpy().reshape(s.rows, s.cols)
    assert land[1, 0] != land[1, 1]
    out = np.zeros((1, 2), np.int32)
    s.flood(np.array([[s.cols, s.cols + 1]], np.int32), out)
    assert out.tolist() == [[1, 1]]
    s.step(int(round(2 * s.fire_cfg.flood_duration / s.fire_cfg.dt)))  # drained: both back to their classes
    frame = FrameRenderer(s, cell_px=CELL_PX, particles=False, backend="raster", wind_arrow=False).render()
    assert cell_pixel(frame, 1, 0) == cell_pixel(frame, 1, 1) == EXTINGUISHED_COLOUR  # one blue, as the legend
    assert [item.colour for item in frame_legend(2) if item.label == "put out"] == [EXTINGUISHED_COLOUR]
    assert EXTINGUISHED_COLOUR != CLASSES[10].colour  # not Water's blue


@pytest.mark.slow
def test_the_legend_names_the_land_cover_and_tells_sealed_from_burned_out():
    env = FlyVectorEnv(num_envs=1, config=Config(map=MapConfig(name="35x36_Woods"), drones=DroneConfig(num_drones=2)),
                       seed=1)
    env.reset(seed=1)
    items = {item.label: item.colour for item in env._viewer.legend()}
    assert {"Sealed", "Woody needle-leaved trees", "Permanent herbaceous", "burned out", "put out"} <= set(items)
    assert items["Sealed"] == CLASSES[SEALED].colour and items["burned out"] == tuple(cell_colours()[BURNED, 2])
    assert items["Sealed"] != items["burned out"]
    band = legend_band(env.render(), env._viewer.render())
    for label in ("Sealed", "burned out", "put out", "fire"):
        assert has_colour(band, items[label]), f"the legend band has no {label} swatch {items[label]}"
    env.close()


@pytest.mark.slow
def test_caption_episode_is_the_episodes_csv_number(tmp_path):
    from roshan.runs.baselines import baseline_fn
    from roshan.runs.evaluate import run_episodes
    from roshan.runs.report.files import read_episodes_csv, write_episodes_csv

    env = FlyVectorEnv(num_envs=2, config=CFG, seed=4)
    env.reset(seed=4)
    assert " | episode 1 | " in env.caption()  # the first episode
    eps = run_episodes(env, baseline_fn("greedy", 2, 2, 4), 3, 4)
    assert (eps["env"][0], eps["index"][0]) == (0, 0)  # the CSV's first row is env 0's first episode: the GIF's
    write_episodes_csv(eps, tmp_path / "episodes.csv")
    assert list(read_episodes_csv(tmp_path / "episodes.csv")["episode"][:1]) == [1]
    running = int(env.caption().split(" | episode ")[1].split(" | ")[0])
    assert running >= 3  # env 0 finished (at least) its quota of 2: its running episode is the 3rd or later
    env.close()


def test_a_trained_runs_caption_names_the_level_and_the_run_folder(tmp_path, monkeypatch):
    from roshan.runs.envs import caption_name

    monkeypatch.chdir(tmp_path)
    assert caption_name("planner", tmp_path / "models" / "planner") == "planner from models/planner"
    assert caption_name("FlyAgent", Path("/elsewhere/runs/fly")) == "FlyAgent from fly"


@pytest.mark.slow
def test_simulate_frames_have_a_caption_and_a_legend(tmp_path):
    from click.testing import CliRunner

    from roshan.cli import main
    from roshan.tools.simulate import fire_caption

    frames = tmp_path / "frames"
    r = CliRunner().invoke(main, ["simulate", "--map", "35x36_Woods", "--steps", "20", "--every", "10", "--frames",
                                  str(frames), "--quiet"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    img = np.asarray(__import__("PIL.Image").Image.open(sorted(frames.glob("*.png"))[-1]).convert("RGB"))
    assert img.shape[0] > 35 * 20 and img.shape[1] == 36 * 20  # bands above and below the 20 px cells
    assert (img[:8] == annotate.BAND_COLOUR).all(-1).mean() > 0.5  # the caption band
    bottom = img[-60:]
    for colour in (CLASSES[SEALED].colour, tuple(cell_colours()[BURNING, 0]), tuple(cell_colours()[BURNED, 2])):
        assert has_colour(bottom, colour), f"no legend swatch {colour}"
    rec = {"step": 20, "time_s": 2.0, "burning": [18], "burned": [0]}
    assert fire_caption(rec) == "fire alone | step 20 | t = 2.0 s | burning 18 | burned out 0"
