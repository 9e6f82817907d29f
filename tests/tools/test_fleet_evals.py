"""benchmarks/scripts/fleet_evals.py: the fleet planner's evaluation matrix. What it runs (the settings and the
eval command) and how its table judges the planner against greedy, on summaries written by hand."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("fleet_evals", ROOT / "benchmarks/scripts/fleet_evals.py")
fleet_evals = importlib.util.module_from_spec(spec)
spec.loader.exec_module(fleet_evals)


def summary(success: float, tte: float, lost: float) -> dict:
    return {"success_rate": success, "tte": {"median": tte}, "drones_lost": {"mean": lost}}


def test_the_matrix_covers_three_fleets_two_base_counts_and_the_crops():
    names = fleet_evals.settings()
    assert len(names) == 3 * 2 + 3 * 2
    assert names["endurance_n16_b2"] == ("drones.num_drones=16", "drones.bases=2")
    assert names["lake_n4_b1"][0] == "map.name=benchmarks/maps/borkenberge_lake.tif"
    assert all((ROOT / crop).is_file() for crop in fleet_evals.CROPS)
    cmd = fleet_evals.eval_command(Path("runs/x"), names["endurance_n8_b1"], Path("out/y"), 100, baseline=True)
    assert cmd[2:] == ["roshan.cli", "eval", "runs/x", "--episodes", "100", "--envs", "100", "--seed", "7", "--quiet",
                       "--out", "out/y", "--baseline", "greedy", "--set", "drones.num_drones=8",
                       "--set", "drones.bases=1"]


def test_the_table_takes_the_seeds_mean_and_holds_it_to_greedy(tmp_path):
    seeds = ["seed_0", "seed_1", "seed_2"]
    plans = {"wins": [(0.8, 2700, 0.0), (0.9, 2600, 0.0), (0.7, 2800, 0.0)],  # 80 %, 2700 against 75 %, 2750
             "slower": [(0.8, 2800, 0.0), (0.9, 2760, 0.0), (0.7, 2800, 0.0)]}  # a higher median TTE than greedy's
    for name, figures in plans.items():
        for s, f in zip(seeds, figures, strict=True):
            (tmp_path / name / s).mkdir(parents=True)
            (tmp_path / name / s / "summary.json").write_text(json.dumps(summary(*f)))
        (tmp_path / name / "seed_0" / "greedy").mkdir()
        (tmp_path / name / "seed_0" / "greedy" / "summary.json").write_text(json.dumps(summary(0.75, 2750, 0.0)))
    (tmp_path / "unfinished" / "seed_0").mkdir(parents=True)  # no summaries yet: no row
    rows = fleet_evals.read_rows(tmp_path, ["wins", "slower", "unfinished"], seeds)
    assert [r["setting"] for r in rows] == ["wins", "slower"]
    assert rows[0]["mean"] == {"success": 80.0, "tte_median": 2700.0, "lost": 0.0} and rows[0]["meets"]
    assert not rows[1]["meets"]
    table = fleet_evals.format_table(rows)
    assert "| wins | 80.0 (80, 90, 70) | 75 | 2700 (2700, 2600, 2800) | 2750 | 0.00, 0.00 | yes |" in table
    assert "| slower |" in table and table.rstrip().endswith("**no** |")
