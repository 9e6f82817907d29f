"""`roshan eval RUN --maps A,B,C`: one evaluation per map, each as `--set map.name=MAP` makes it, in its own folder,
and a summary with one row per map; maps that cannot be evaluated and single-evaluation options are refused before
anything is written."""

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.cli import main
from roshan.config import load_config
from roshan.runs.map_suite import map_row, write_suite_summary
from roshan.runs.report.notes import controller_notes, reach_note
from roshan.runs.report.stats import summarize
from roshan.runs.report.tables import format_comparison

ROOT = Path(__file__).resolve().parents[2]
PLANNER = ROOT / "models/planner"
MAPS = ("15x15_Woods", "21x21_Field")
TINY = ("--episodes", 2, "--envs", 2, "--quiet", "--set", "ignition.fire_percentage=0.02")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.mark.slow
def test_a_suite_writes_one_evaluation_per_map_and_a_summary_of_them(tmp_path):
    out = tmp_path / "suite"
    res = cli("eval", PLANNER, "--maps", ",".join(MAPS), "--baseline", "greedy", "--out", out, *TINY)
    assert res.exit_code == 0, res.output

    rows = json.loads((out / "maps.json").read_text())["maps"]
    assert [r["map"] for r in rows] == list(MAPS)
    for name, row in zip(MAPS, rows, strict=True):
        folder = out / name
        assert (folder / "episodes.csv").is_file() and (folder / "greedy" / "episodes.csv").is_file()
        policy = json.loads((folder / "summary.json").read_text())
        greedy = json.loads((folder / "greedy" / "summary.json").read_text())
        # the map's evaluation is the single one with --set map.name=MAP added after the user's --set
        assert policy["provenance"]["overrides"] == ["ignition.fire_percentage=0.02", f"map.name={name}"]
        assert row["policy"]["success_rate"] == policy["success_rate"]
        assert row["policy"]["tte_median"] == policy["tte"]["median"]
        assert row["baseline"]["success_rate"] == greedy["success_rate"]
        assert row["baseline"]["tte_median"] == greedy["tte"]["median"]
        if policy["success_rate"] > 0 and greedy["success_rate"] > 0:
            assert row["tte_median_ratio"] == pytest.approx(policy["tte"]["median"] / greedy["tte"]["median"])
        else:  # a median of time limits: no ratio
            assert row["tte_median_ratio"] is None and row["tte_median_ratio_note"] == "n/a: no episode succeeded"
        assert row["cells"] == {"15x15_Woods": 225, "21x21_Field": 441}[name]
        assert f"models/planner on {name} (best_eval, seed 0)" in res.output  # each map's own table
        assert f"| {name} | {row['cells']}" in (out / "maps.md").read_text()
    assert res.output.count("Success rate") == len(MAPS)
    assert (out / "maps.md").read_text().strip() in res.output  # the summary table is printed at the end
    provenance = json.loads((out / "maps.json").read_text())["provenance"]
    assert "--maps 15x15_Woods,21x21_Field" in provenance["command"] and "map.name" not in provenance["command"]

    # the same suite again: refused before any episode runs, naming the folder and both ways out
    before = (out / "maps.json").read_bytes()
    res = cli("eval", PLANNER, "--maps", ",".join(MAPS), "--baseline", "greedy", "--out", out, *TINY)
    assert res.exit_code != 0 and str(out) in res.output and "--replace" in res.output
    assert (out / "maps.json").read_bytes() == before


def test_a_map_that_cannot_load_is_refused_before_anything_is_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default folder would go under ./out
    res = cli("eval", PLANNER, "--maps", "15x15_Woods,Nowhere_Woods", *TINY)
    assert res.exit_code == 1
    assert "'Nowhere_Woods' cannot be evaluated" in res.output and "bundled maps: 15x15_Woods" in res.output
    (tmp_path / "bad.tif").write_text("not a raster")
    res = cli("eval", PLANNER, "--maps", f"21x21_Field,{tmp_path / 'bad.tif'}", "--out", tmp_path / "suite", *TINY)
    assert res.exit_code == 1 and "bad.tif' cannot be evaluated" in res.output and "not a readable raster" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.tif"]


def test_maps_with_single_evaluation_outputs_is_a_usage_error(tmp_path):
    res = cli("eval", PLANNER, "--maps", ",".join(MAPS), "--gif", tmp_path / "a.gif", *TINY)
    assert res.exit_code == 2 and "--maps cannot be combined with --gif" in res.output
    assert not (tmp_path / "a.gif").exists()


def test_the_summary_has_drones_lost_columns_with_a_battery(tmp_path):
    from roshan.maps import load_map

    def summary(times, lost):
        n = len(times)
        return summarize({"time": times, "success": [1] * n, "reason": ["none"] * n, "drones_lost": lost,
                          "battery_swaps": [0] * n, "energy_used": [1.0] * n, "base_time": [0.0] * n}, dt=0.1)

    planner = summary([100, 300, 200], [0, 1, 2]) | {"baseline_name": "greedy (fixed)"}
    planner["baseline"] = summary([400, 400, 100], [3, 3, 0])
    row = map_row("15x15_Woods", load_map("15x15_Woods"), planner)
    assert row["policy"]["drones_lost"] == 1.0 and row["baseline"]["drones_lost"] == 2.0
    assert row["tte_median_ratio"] == 0.5
    table = write_suite_summary([row], tmp_path, "suite", {"command": "roshan eval"})
    assert "policy drones lost (mean)" in table and "greedy (fixed) drones lost (mean)" in table
    assert "| 15x15_Woods | 225 (15 x 15) | 100.0 % | 200.0 | 100.0 % | 400.0 | 1.00 | 2.00 | 0.50 |" in table
    assert (tmp_path / "maps.md").read_text() == table + "\n"
    assert json.loads((tmp_path / "maps.json").read_text())["maps"] == [row]


def test_a_tte_ratio_without_successes_reads_n_a(tmp_path):
    """Where a controller succeeded in no episode its median TTE is the time limit, so the suite prints no ratio
    of two time limits (it printed 1.00 when every episode of both timed out)."""
    from roshan.maps import load_map

    def summary(success):
        n = len(success)
        reasons = ["none" if s else "timeout" for s in success]
        return summarize({"time": [9680] * n, "success": success, "reason": reasons}, reasons=("timeout",), dt=0.1)

    for policy_success, greedy_success in (([0, 0], [0, 0]), ([1, 0], [0, 0]), ([0, 0], [1, 1])):
        evaluation = summary(policy_success) | {"baseline_name": "resource-aware greedy (fixed)"}
        evaluation["baseline"] = summary(greedy_success)
        row = map_row("15x15_Woods", load_map("15x15_Woods"), evaluation)
        assert row["tte_median_ratio"] is None and row["tte_median_ratio_note"] == "n/a: no episode succeeded"
        table = write_suite_summary([row], tmp_path, "suite", {"command": "roshan eval"})
        assert table.splitlines()[-1].endswith("| n/a: no episode succeeded |")
        assert "1.00" not in table.splitlines()[-1]


def test_results_that_cannot_mean_anything_say_so(tmp_path):
    # issue 52: borkenberge_heath with the default battery: both controllers flew home 141 times and put out no
    # cell, and the row read 0 % against 0 % with a TTE ratio of 1.00
    from roshan.maps import load_map

    def summary(success, extinguished, swaps, energy):
        n = len(success)
        reasons = ["none" if s else "timeout" for s in success]
        return summarize({"time": [9680] * n, "success": success, "reason": reasons,
                          "extinguished": extinguished, "drones_lost": [0] * n, "battery_swaps": swaps,
                          "energy_used": energy, "base_time": [0.0] * n}, reasons=("timeout",), dt=0.1)

    failed = summary([0, 0], [0, 0], [70, 71], [9e5, 9e5])
    failed["notes"] = controller_notes(failed, "planner policy")
    failed |= {"baseline_name": "greedy (fixed)", "baseline": summary([0, 0], [0, 0], [0, 0], [0.0, 0.0])}
    failed["baseline"]["notes"] = controller_notes(failed["baseline"], "greedy")
    assert failed["notes"] == ["planner policy put out no cell in any of its 2 episodes (its drones flew home 141 "
                               "times): its rates say nothing about how it fights fire"]
    assert "greedy never left the base: its drones drew 0 J in every episode" in failed["baseline"]["notes"]
    row = map_row("15x15_Woods", load_map("15x15_Woods"), failed)
    assert row["tte_median_ratio"] is None
    table = write_suite_summary([row], tmp_path, "suite", {"command": "roshan eval"})
    assert table.endswith("| n/a: no episode succeeded |" + "".join(f"\n{line}" for line in [
        "", "Notes:", f"- 15x15_Woods: {failed['notes'][0]}",
        *(f"- 15x15_Woods: {n}" for n in failed["baseline"]["notes"])]))
    assert "note: planner policy put out no cell" in format_comparison({"policy": failed,
                                                                        "greedy": failed["baseline"]})


def test_fires_out_of_the_battery_s_range_are_named():
    reach = load_config(None, ["drones.energy.preset=scenario"]).drones.battery_reach()
    assert reach == pytest.approx(15000 / 170 * 10 * 2**0.5 / 2)  # the README's 88 s at full speed, out and back
    assert reach_note(reach, 10.0 * math.hypot(34, 33)) is None  # scenario is scaled to 35x36_Woods: all in reach
    note = reach_note(reach, 1458.0)
    assert note.startswith("fires out of the battery's range: a full battery takes a drone at most 624 m out and "
                           "back, and the farthest cell is 1458 m from its nearest base")
    assert load_config().drones.battery_reach() is None and reach_note(None, 1458.0) is None
