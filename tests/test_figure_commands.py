"""Every headline figure of the README names a command that gives it on a fresh clone: the command parses, names a
shipped model, and reads the settings the committed figure was made with (its provenance), and the figure quoted is
the committed one. The map-suite command runs as written, with one episode, up to where each map's evaluation
starts, and each map is evaluated with the committed figure's settings."""

import json
import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.cli import main
from roshan.config import apply_overrides
from roshan.runs import map_suite
from roshan.runs.report.stats import summarize

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
RESULTS = ROOT / "benchmarks" / "results"


def model_table() -> dict[str, tuple[str, str]]:
    """models/<name> -> (headline figure, command) from the README's table of shipped models."""
    table = README.split("## What to try next", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in table.splitlines():
        m = re.match(r"\| \[`(models/[\w-]+)`\]\([^)]*\) \| [^|]+ \| ([^|]+) \| `([^`]+)` \|$", line)
        if m:
            rows[m.group(1)] = (m.group(2).strip(), m.group(3))
    return rows


def eval_params(command: str) -> dict:
    """The options ``roshan eval ...`` parses ``command`` into (click's own parser: paths must exist)."""
    words = shlex.split(command)
    assert words[:2] == ["roshan", "eval"], command
    cmd = main.get_command(None, "eval")
    return cmd.make_context("eval", words[2:]).params


def same_settings(params: dict, provenance: dict) -> None:
    """The README command reads what the committed figure's provenance says it was made with."""
    assert params["seed"] == provenance["seed"] and params["episodes"] == provenance["episodes"]
    assert (params["baseline"] or None) == provenance["baseline"]
    assert params["which"] == provenance["checkpoint_choice"]
    assert list(params["sets"]) == provenance["overrides"]
    envs = params["envs"] or map_suite.run_config(params["target"], params["which"])[0].train.eval_envs
    assert envs == provenance["envs"]


def test_the_model_table_names_every_model_with_a_command():
    assert sorted(model_table()) == sorted(f"models/{p.name}" for p in (ROOT / "models").iterdir() if p.is_dir())


def test_fly_simple_figure():
    figure, command = model_table()["models/fly_simple"]
    params = eval_params(command)
    committed = (ROOT / "models/fly_simple/eval/table.txt").read_text()
    # the run's own evaluation: its title names the checkpoint, episodes and seed; the default checkpoint is that one
    assert "(best_objective, 200 episodes, seed 10000)" in committed
    assert params["seed"] == 10000 and params["episodes"] == 200 and not params["sets"]
    assert map_suite.run_config(params["target"], params["which"])[1].name == "best_objective.pt"
    assert "100.0 % [98.1, 100.0]" in committed and "100 % success [98.1, 100]" in figure


def test_fly_collision_figure():
    figure, command = model_table()["models/fly_collision"]
    params = eval_params(command)
    committed = json.loads((RESULTS / f"fly_collision_stable/seed_{params['seed']}.json").read_text())
    same_settings(params, committed["provenance"])  # made from the run folder the model was copied from
    assert f"{100 * committed['success_rate']:.1f} % success" in figure
    assert f"{100 * committed['failure_rates']['collision']:.1f} % collisions" in figure


def test_planner_figure():
    figure, command = model_table()["models/planner"]
    params = eval_params(command)
    committed = json.loads((RESULTS / "planner_ship/seed11_greedy_fixed.json").read_text())
    same_settings(params, committed["provenance"])
    assert f"median TTE {committed['policy']['tte']['median']}" in figure
    assert f"fixed greedy's {committed['greedy']['tte']['median']}" in figure
    assert committed["policy"]["success_rate"] == 1


def test_planner_endurance_16_figure():
    figure, command = model_table()["models/planner_endurance_16"]
    params = eval_params(command)
    committed = json.loads((RESULTS / "endurance/borkenberge_realistic_16_approach/eval.json").read_text())
    same_settings(params, committed["provenance"])
    assert committed["policy"]["drones_lost"] == 0 and "no drone lost" in figure


def test_planner_endurance_figure():
    """Its figure is over three training seeds, so its command is the experiment's: the rows it names exist and are
    the model's recipe (the distance prior and distinct goals) and the resource-aware greedy."""
    from roshan.experiment.spec import load_spec

    figure, command = model_table()["models/planner_endurance"]
    words = shlex.split(command)
    assert words[:3] == ["roshan", "experiment", "run"]
    spec = load_spec(ROOT / words[3])
    only = [words[i + 1] for i, w in enumerate(words) if w == "--only"]
    conditions = {c.name: c for c in spec.conditions}
    assert set(only) == {"planner_near_distinct", "greedy_resources"}
    planner = conditions["planner_near_distinct"]
    assert {"planner.distance_prior=10.0", "planner.distinct_goals=true"} <= set(planner.sets)
    assert len(planner.seeds) == 3 and (planner.eval_episodes, planner.eval_seed) == (100, 7)
    assert conditions["greedy_resources"].controller == "greedy"
    report = (RESULTS / "endurance/report.md").read_text()
    assert "| planner_near_distinct | 3/3 |" in report and "78.0 ± 0.8 (78.0)" in report
    assert "78.0 ± 0.8 %" in figure and "71 %" in figure


def map_suite_command() -> str:
    block = README.split("as a map suite:", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    return " ".join(block.replace("\\\n", " ").split())


def test_the_readme_map_suite_command_reads_the_settings_of_its_figure(tmp_path, monkeypatch):
    """The README's map-suite command, run as written with one episode on one env, evaluates each map with the
    settings that BENCHMARKS' unseen-maps figure records (it once left out the fire percentage and the battery,
    and both controllers then scored 0 % on borkenberge_heath against 44 % / 41 %). Each map's evaluation is
    replaced by one that records what it was asked to run: the full one takes minutes per map."""
    words = shlex.split(map_suite_command())
    assert words[:3] == ["roshan", "eval", "models/planner_endurance"]
    for option, value in (("--episodes", "1"), ("--envs", "1"), ("--out", str(tmp_path / "suite"))):
        words[words.index(option) + 1] = value
    asked = []

    def evaluate_run(target, **kw):
        trained, _ = map_suite.run_config(target, kw["which"])
        cfg = apply_overrides(trained, kw["overrides"])
        asked.append((str(target), kw, cfg))
        figures = summarize({"time": [1], "success": [0], "reason": ["timeout"]}, reasons=("timeout",), dt=0.1)
        return {**figures, "baseline": dict(figures), "baseline_name": "resource-aware greedy (fixed)",
                "provenance": {"command": "roshan eval " + str(target) + "".join(
                    f" --set {o}" for o in kw["overrides"]), "overrides": list(kw["overrides"])},
                "checkpoint": "models/planner_endurance/checkpoints/best_eval.pt", "out_dir": str(kw["out_dir"])}

    monkeypatch.setattr(map_suite, "evaluate_run", evaluate_run)
    res = CliRunner().invoke(main, [*words[1:], "--quiet"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    committed_dir = RESULTS / "endurance" / "maps_near"
    committed_rows = json.loads((committed_dir / "maps.json").read_text())["maps"]
    assert [a[2].map.name for a in asked] == [r["source"] for r in committed_rows]
    for (target, kw, cfg), row in zip(asked, committed_rows, strict=True):
        provenance = json.loads((committed_dir / row["folder"] / "summary.json").read_text())["provenance"]
        assert target == provenance["target"] and kw["seed"] == provenance["seed"]
        assert kw["baseline"] == provenance["baseline"] and kw["which"] == provenance["checkpoint_choice"]
        assert kw["overrides"] == provenance["overrides"]
        assert cfg.ignition.fire_percentage == 0.04 and cfg.drones.energy.values()["capacity"] == 45000
    # the figures the README quotes are the committed ones
    quoted = re.search(r"\(([\d / ]+) % against ([\d / ]+) %\)", README.split("as a map suite:", 1)[1])
    policy = " / ".join(f"{100 * r['policy']['success_rate']:.0f}" for r in committed_rows)
    greedy = " / ".join(f"{100 * r['baseline']['success_rate']:.0f}" for r in committed_rows)
    assert quoted.groups() == (policy, greedy)


@pytest.mark.parametrize("name", ["BENCHMARKS.md", "docs/endurance.md"])
def test_the_map_suite_command_is_the_same_everywhere(name):
    text = " ".join((ROOT / name).read_text(encoding="utf-8").replace("\\\n", " ").split())
    command = map_suite_command().replace(" --out out/maps_endurance", "")
    settings = ("--set ignition.fire_percentage=0.04", "--set drones.energy.capacity=45000", "models/planner_endurance")
    assert all(s in command for s in settings)
    at = text.find("--maps benchmarks/maps/borkenberge_heath.tif,benchmarks/maps/borkenberge_lake.tif")
    assert at > 0
    start = text.rfind("roshan eval", 0, at)
    assert all(s in text[start:at + 200] for s in settings)
