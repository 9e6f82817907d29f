"""The fleet planner's evaluation matrix: every training seed of ``configs/experiments/fleet.yaml``'s
``planner_fleet`` against the resource-aware greedy on the same episodes, at 4, 8 and 16 drones with one and two
bases on the endurance scenario, and at 4 drones with one and two bases on the unseen Borkenberge crops (the
"Unseen maps" setting of BENCHMARKS.md: 4 % ignition, a 45 kJ battery).

    python benchmarks/scripts/fleet_evals.py RUN_ROOT --out benchmarks/results/fleet/evals
    python benchmarks/scripts/fleet_evals.py RUN_ROOT --out benchmarks/results/fleet/evals --table-only

RUN_ROOT holds the experiment's runs (``roshan experiment run ... --root RUN_ROOT``: RUN_ROOT/fleet/planner_fleet/
seed_K). Each evaluation is one ``roshan eval`` command, written to OUT/<setting>/seed_K (an existing folder is
kept, so a killed matrix resumes); greedy plays only beside seed 0 (it is deterministic given the episodes). The
table (OUT/table.md) gives, per setting, the planner's mean over seeds with each seed's figure and greedy's, and
whether the planner meets the bar: at least greedy's success, a lower median TTE, no more drones lost.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

CROPS = ("benchmarks/maps/borkenberge_heath.tif", "benchmarks/maps/borkenberge_lake.tif",
         "benchmarks/maps/borkenberge_village.tif")
MAP_SETS = ("ignition.fire_percentage=0.04", "drones.energy.capacity=45000")


def settings() -> dict[str, tuple[str, ...]]:
    """Setting name -> the ``--set`` overrides of its evaluation."""
    out = {f"endurance_n{n}_b{b}": (f"drones.num_drones={n}", f"drones.bases={b}") for n in (4, 8, 16) for b in (1, 2)}
    for crop in CROPS:
        name = Path(crop).stem.removeprefix("borkenberge_")
        for b in (1, 2):
            out[f"{name}_n4_b{b}"] = (f"map.name={crop}", *MAP_SETS, "drones.num_drones=4", f"drones.bases={b}")
    return out


def eval_command(run: Path, sets: tuple[str, ...], out: Path, episodes: int, baseline: bool) -> list[str]:
    cmd = [sys.executable, "-m", "roshan.cli", "eval", str(run), "--episodes", str(episodes), "--envs",
           str(episodes), "--seed", "7", "--quiet", "--out", str(out)]
    if baseline:
        cmd += ["--baseline", "greedy"]
    for s in sets:
        cmd += ["--set", s]
    return cmd


def figures(summary: dict) -> dict[str, float]:
    """Success (%), median TTE (steps) and drones lost per episode of one evaluation's summary.json."""
    return {"success": 100.0 * summary["success_rate"], "tte_median": summary["tte"]["median"],
            "lost": summary["drones_lost"]["mean"]}


def row(setting: str, seeds: list[dict[str, float]], greedy: dict[str, float]) -> dict:
    """The table row of one setting: each figure's mean over the planner's seeds, the seeds' own, greedy's, and
    whether the planner's mean meets the bar against greedy."""
    mean = {k: statistics.fmean(s[k] for s in seeds) for k in ("success", "tte_median", "lost")}
    meets = mean["success"] >= greedy["success"] and mean["tte_median"] < greedy["tte_median"] \
        and mean["lost"] <= greedy["lost"]
    return {"setting": setting, "seeds": seeds, "mean": mean, "greedy": greedy, "meets": meets}


def format_table(rows: list[dict]) -> str:
    lines = ["| setting | planner success % (seeds) | greedy | planner median TTE (seeds) | greedy | "
             "lost / ep (planner, greedy) | meets the bar |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        s, m, g = r["seeds"], r["mean"], r["greedy"]
        success = ", ".join(f"{x['success']:.0f}" for x in s)
        tte = ", ".join(f"{x['tte_median']:.0f}" for x in s)
        verdict = "yes" if r["meets"] else "**no**"
        lines.append(f"| {r['setting']} | {m['success']:.1f} ({success}) | {g['success']:.0f} | "
                     f"{m['tte_median']:.0f} ({tte}) | {g['tte_median']:.0f} | {m['lost']:.2f}, {g['lost']:.2f} | "
                     f"{verdict} |")
    return "\n".join(lines) + "\n"


def read_rows(out: Path, names: list[str], seeds: list[str]) -> list[dict]:
    rows = []
    for name in names:
        folder = out / name
        done = [folder / s / "summary.json" for s in seeds if (folder / s / "summary.json").is_file()]
        greedy = folder / seeds[0] / "greedy" / "summary.json"
        if len(done) == len(seeds) and greedy.is_file():
            rows.append(row(name, [figures(json.loads(p.read_text())) for p in done],
                            figures(json.loads(greedy.read_text()))))
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_root", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--only", default=None, help="comma-separated setting names")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    runs = sorted((args.run_root / "fleet" / "planner_fleet").glob("seed_*"))
    if not runs:
        raise SystemExit(f"{args.run_root}: no fleet/planner_fleet/seed_* runs")
    names = [n for n in settings() if args.only is None or n in args.only.split(",")]
    if not args.table_only:
        for name in names:
            for i, run in enumerate(runs):
                out = args.out / name / run.name
                if (out / "summary.json").is_file():
                    continue
                cmd = eval_command(run, settings()[name], out, args.episodes, baseline=i == 0)
                print(" ".join(cmd), flush=True)
                subprocess.run(cmd, check=True)
    table = format_table(read_rows(args.out, names, [r.name for r in runs]))
    (args.out / "table.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
