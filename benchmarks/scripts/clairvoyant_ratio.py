"""Median TTEs as ratios to the clairvoyant reference's, on the same episodes (BENCHMARKS.md, "How far from a
clairvoyant reference").

    roshan eval models/planner_endurance --baseline clairvoyant --episodes 100 --envs 100 --seed 7 --out out/clair
    roshan eval models/planner_endurance --baseline greedy --episodes 100 --envs 100 --seed 7 --out out/greedy
    python benchmarks/scripts/clairvoyant_ratio.py out/clair out/greedy

Each controller plays the same episodes (the same env seed and episode order), so the interval is a paired
bootstrap over episodes: the same drawn episodes for the controller and the reference, 10,000 draws, seeded.
"""

import csv
import sys
from pathlib import Path

import numpy as np


def column(path: Path, name: str = "Time") -> np.ndarray:
    with open(path) as fh:
        return np.array([float(row[name]) for row in csv.DictReader(fh)])


def ratio(tte: np.ndarray, reference: np.ndarray, reps: int = 10_000, seed: int = 0) -> tuple[float, float, float]:
    """median(tte) / median(reference) with its 95 % paired-bootstrap interval."""
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, tte.size, size=(reps, tte.size))
    boot = np.median(tte[draws], axis=1) / np.median(reference[draws], axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return float(np.median(tte) / np.median(reference)), float(lo), float(hi)


def main(clair_dir: str, greedy_dir: str) -> None:
    reference = column(Path(clair_dir) / "clairvoyant" / "episodes.csv")
    rows = {"planner": column(Path(clair_dir) / "episodes.csv"),
            "greedy": column(Path(greedy_dir) / "greedy" / "episodes.csv")}
    print(f"clairvoyant reference: median TTE {np.median(reference):.1f} steps over {reference.size} episodes")
    for name, tte in rows.items():
        assert tte.size == reference.size, f"{name}: {tte.size} episodes against the reference's {reference.size}"
        value, lo, hi = ratio(tte, reference)
        print(f"{name}: median TTE {np.median(tte):.1f} steps, ratio to the reference {value:.3f} [{lo:.3f}, {hi:.3f}]")


if __name__ == "__main__":
    main(*sys.argv[1:3])
