"""`roshan eval` never clobbers: each setting gets its own named folder under RUN/eval, an output that already holds
results is refused unless --replace, and every summary JSON says how it was made."""

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ("--episodes", 2, "--envs", 2, "--quiet")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def model(tmp_path) -> Path:
    """A copy of the shipped fly_simple run folder, committed evaluation included (tests never write in models/)."""
    run = tmp_path / "fly_simple"
    shutil.copytree(ROOT / "models/fly_simple", run)
    return run


def committed_files(run: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in (run / "eval").iterdir() if p.is_file()}


@pytest.mark.slow
def test_two_evaluations_with_different_settings_keep_both_and_the_committed_one(model):
    committed = committed_files(model)
    res = cli("eval", model, *TINY)
    assert res.exit_code == 0, res.output
    first = model / "eval" / "0-2"
    assert (first / "episodes.csv").is_file() and f"files: {first}" in res.output
    first_csv = (first / "episodes.csv").read_bytes()

    res = cli("eval", model, *TINY, "--set", "drones.num_drones=3")
    assert res.exit_code == 0, res.output
    (second,) = [p for p in (model / "eval").iterdir() if p.is_dir() and p != first]
    assert second.name.startswith("0-2-") and len(second.name) == len("0-2-") + 8
    assert (first / "episodes.csv").read_bytes() == first_csv  # the first evaluation is still there, unchanged
    assert committed_files(model) == committed  # and so is the shipped 200-episode one
    prov = json.loads((second / "summary.json").read_text())["provenance"]
    assert prov["overrides"] == ["drones.num_drones=3"] and "--set drones.num_drones=3" in prov["command"]
    assert prov["checkpoint"].endswith("checkpoints/best_objective.pt") and prov["checkpoint_choice"] == "best"
    assert prov["code"]["version"] and (prov["code"]["commit"] is None or len(prov["code"]["commit"]) == 40)
    assert json.loads((first / "summary.json").read_text())["provenance"]["overrides"] == []

    # the same setting again: refused, naming the folder and both ways out, before any episode ran
    res = cli("eval", model, *TINY)
    assert res.exit_code != 0
    assert str(first) in res.output and "--replace" in res.output and "--out DIR" in res.output
    assert (first / "episodes.csv").read_bytes() == first_csv
    # the same setting with another checkpoint or seed is another folder; --replace rewrites the first
    assert cli("eval", model, *TINY, "--checkpoint", "latest").exit_code == 0
    assert cli("eval", model, *TINY, "--seed", 1).exit_code == 0
    assert (model / "eval" / "1-2").is_dir() and len([p for p in (model / "eval").iterdir() if p.is_dir()]) == 4
    res = cli("eval", model, *TINY, "--replace")
    assert res.exit_code == 0, res.output
    assert (first / "episodes.csv").read_bytes() == first_csv  # same seed, same episodes


@pytest.mark.slow
def test_explicit_out_and_json_follow_the_same_rule(model, tmp_path):
    out, js = tmp_path / "out", tmp_path / "e.json"
    res = cli("eval", model, *TINY, "--out", out, "--json", js)
    assert res.exit_code == 0, res.output
    payload = json.loads(js.read_text())
    assert set(payload) == {"episodes", "success_rate", "failure_rates", "tte", "provenance"}
    assert payload["provenance"]["episodes"] == 2 and payload["provenance"]["envs"] == 2
    # the simple policy reaches goals and puts out no fire: its table says so beside "Extinguished"
    note = "fly.policy = simple: an episode succeeds when the drones reach their goals; they put out no fire"
    assert note in res.output and note in (out / "table.txt").read_text()
    before = js.read_bytes(), (out / "summary.json").read_bytes()

    res = cli("eval", model, *TINY, "--out", out, "--set", "fire.dt=0.2")
    assert res.exit_code != 0 and str(out) in res.output and "--replace" in res.output
    res = cli("eval", model, *TINY, "--out", tmp_path / "other", "--json", js, "--set", "fire.dt=0.2")
    assert res.exit_code != 0 and str(js) in res.output and "--replace" in res.output
    assert not (tmp_path / "other" / "episodes.csv").exists()
    assert (js.read_bytes(), (out / "summary.json").read_bytes()) == before

    res = cli("eval", model, *TINY, "--out", out, "--json", js, "--set", "fire.dt=0.2", "--replace")
    assert res.exit_code == 0, res.output
    assert json.loads(js.read_text())["provenance"]["overrides"] == ["fire.dt=0.2"]
    assert json.loads((out / "summary.json").read_text())["provenance"]["overrides"] == ["fire.dt=0.2"]
    assert not (model / "eval" / "0-2").exists()  # --out replaces the default folder
