"""CLI smoke tests: simulate (frames, GIF, JSON), maps list/show/crop, benches, and error messages."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from roshan.cli import main


def invoke(*args):
    result = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return result


@pytest.mark.slow
def test_simulate_writes_nonblank_frames_gif_and_json(tmp_path):
    frames, gif, out = tmp_path / "frames", tmp_path / "fire.gif", tmp_path / "run.json"
    r = invoke("simulate", "--map", "35x36_Woods", "--envs", "2", "--steps", "600", "--every", "200", "--seed", "4",
               "--fire-percentage", "0.1", "--frames", frames, "--gif", gif, "--json", out, "--quiet")
    assert r.exit_code == 0, r.output
    assert "env-steps/s" in r.output and "burning" in r.output
    pngs = sorted(frames.glob("*.png"))
    assert len(pngs) == 4 and "0000600" in pngs[-1].name
    img = np.asarray(Image.open(pngs[-1]).convert("RGB"))
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 5, "frame is blank"
    assert ((img[..., 0] > 200) & (img[..., 1] < 60)).sum() > 0, "burning cells should show red"
    assert Image.open(gif).n_frames >= 2
    data = json.loads(out.read_text())
    assert set(data) == {"config", "series", "timing"}
    assert [rec["step"] for rec in data["series"]] == [0, 200, 400, 600]
    assert len(data["series"][0]["burning"]) == 2
    assert data["config"]["ignition"]["fire_percentage"] == 0.1


@pytest.mark.slow
def test_simulate_json_is_a_function_of_the_seed(tmp_path):
    def series(seed, name):
        path = tmp_path / name
        r = invoke("simulate", "--map", "21x21_Field", "--envs", "3", "--steps", "1000", "--every", "250",
                   "--seed", seed, "--json", path, "--quiet")
        assert r.exit_code == 0, r.output
        data = json.loads(path.read_text())
        return data["config"], data["series"]

    first = series(1, "a.json")
    assert first == series(1, "b.json")
    assert first[1] != series(2, "c.json")[1]


def test_simulate_rejects_bad_input_with_clear_errors():
    r = CliRunner().invoke(main, ["simulate", "--set", "fire.dtt=0.1", "--steps", "1"])
    assert r.exit_code != 0 and "did you mean 'fire.dt'" in r.output
    r = CliRunner().invoke(main, ["simulate", "--fire-percentage", "2", "--steps", "1"])
    assert r.exit_code != 0 and "[0.0, 1.0]" in r.output
    r = CliRunner().invoke(main, ["simulate", "--map", "35x36_Wods", "--steps", "1"])
    assert r.exit_code != 0 and "35x36_Woods" in r.output


def test_maps_list_and_show():
    r = invoke("maps", "list")
    assert r.exit_code == 0 and "35x36_Woods" in r.output and "Borkenberge" in r.output
    r = invoke("maps", "show", "35x36_Woods")
    assert r.exit_code == 0 and "35" in r.output and "36" in r.output and "EPSG:3035" in r.output


def test_maps_crop_round_trips_a_window(tmp_path):
    from roshan.maps import bundled_map_path, load_map

    src = load_map("Borkenberge")
    a, _, c, _, e, f = src.transform
    west, north = c + 100 * a, f + 50 * e  # 100 columns east, 50 rows south of the corner
    bounds = (west, north + 30 * e, west + 40 * a, north)
    out = tmp_path / "crop.tif"
    r = invoke("maps", "crop", bundled_map_path("Borkenberge"), "--bounds", *bounds, "-o", out)
    assert r.exit_code == 0, r.output
    crop = load_map(out)
    np.testing.assert_array_equal(crop.classes, src.classes[50:80, 100:140])


@pytest.mark.slow
def test_bench_fire_and_fidelity_run_on_tiny_budgets(tmp_path):
    out = tmp_path / "fire.json"
    r = invoke("bench", "fire", "--envs", "1,2", "--steps", "50", "--warmup", "10", "--no-big", "--json", out)
    assert r.exit_code == 0, r.output
    runs = json.loads(out.read_text())["runs"]
    assert len(runs) == 4 and all(run["env_steps_per_s"] > 0 for run in runs)
    r = invoke("bench", "fidelity", "--seeds", "2", "--condition", "field21_p005", "--plot", tmp_path / "f.png")
    assert r.exit_code == 0, r.output
    assert "field21_p005" in r.output and "burning" in r.output
    assert (tmp_path / "f.png").stat().st_size > 10_000


@pytest.mark.slow
def test_bench_env_runs_on_a_tiny_budget(tmp_path):
    out = tmp_path / "env.json"
    r = invoke("bench", "env", "--envs", "2", "--drones", "2", "--fire", "0.05", "--policies",
               "random,simple,fly_collision", "--min-env-steps", "40", "--json", out)
    assert r.exit_code == 0, r.output
    runs = json.loads(out.read_text())["runs"]
    assert [run["policy"] for run in runs] == ["random", "simple", "fly_collision"]
    # each row is printed (stderr) as its run finishes, not only in the table at the end
    assert "timing 3 runs" in r.stderr and len([line for line in r.stderr.splitlines() if "%" in line]) == 3
    assert all(run["env_steps_per_s"] > 0 and run["agent_steps_per_s"] == 2 * run["env_steps_per_s"] for run in runs)


@pytest.mark.parametrize("args, message", [
    (("bench", "fire", "--envs", "0", "--steps", "10"), "Invalid value for --envs: expected comma-separated int "
                                                         "values from 1, got '0'"),
    (("bench", "fire", "--envs", "2,x", "--steps", "10"), "got '2,x'"),
    (("bench", "env", "--envs", "1", "--fire", "1.5"), "Invalid value for --fire: expected comma-separated float "
                                                        "values from 0.0 to 1.0, got '1.5'"),
    (("simulate", "--steps", "1", "--gif", "out.png"), "'out.png' does not end in .gif"),
])
def test_bad_lists_and_gif_names_are_usage_errors_before_any_work(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, list(args))
    assert r.exit_code == 2 and message in r.output and "Traceback" not in r.output
    assert not list(tmp_path.iterdir())  # nothing written
