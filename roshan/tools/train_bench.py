"""``roshan bench train``: a fixed slice of each recipe family's training, timed the way a run spends it.

Each slice is a condition of an experiment spec (by default the thesis's), trained by the real :class:`Trainer`
for a warm-up update (kernel compilation, first allocations: not timed) and then ``updates`` timed ones, with
checkpoints and TensorBoard as a run writes them; then one periodic evaluation of the condition's size. Reported:
env-steps per second all told (planner: decisions), its split into collection, update and the rest (logging and
checkpoints), the evaluation's seconds (its second call: the first compiles) and its share of a run at the
condition's ``train.eval_every``, and the process's peak memory.

Every slice runs in a process of its own, started with the torch settings of its mode (they must be set before
torch loads, :mod:`roshan.reproducible`); ``--against DIR`` times the same slices with another checkout's code in
the same run, one after the other in each round, so that the ratios compare like with like. This file runs as a
script, roshan/tools/train_slice.py, inside those processes; it imports only what a checkout from before it also
has (the spec, the Trainer).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path

from roshan import reproducible
from roshan.tools import train_slice

# family -> (condition of the thesis spec, what one env step is called)
FAMILIES = {"E1": ("E1_ppo", "env-steps"), "E6": ("E6", "env-steps"), "TD3": ("E1_td3", "env-steps"),
            "planner": ("P3_h9600_i5", "decisions")}
# Settings a slice adds to its condition's: TD3 starts its updates once the buffer holds 30,000 transitions, eight
# iterations in; a slice would time collection alone. One iteration's worth (64 env steps x 64 drones) lets the
# warm-up iteration fill it, so that the timed ones update as a run does from then on.
SLICE_SETS = {"TD3": ("td3.min_memory_size=4096",)}
MODES = ("reproducible", "vendor")


def run_slice(checkout: Path, spec: str, condition: str, updates: int, mode: str, threads: int | None,
              sets: tuple[str, ...] = ()) -> dict:
    """One slice in a fresh process of ``checkout``'s code, with the torch settings of ``mode``."""
    env = {**reproducible.environ(mode == MODES[0]), "PYTHONPATH": str(checkout)}
    args = [sys.executable, train_slice.__file__, str(checkout / spec), condition, str(updates),
            str(threads or 0), *sets]
    done = subprocess.run(args, cwd=checkout, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"bench train: {condition} ({mode}, {checkout}) failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def bench_training(families: list[str], modes: list[str], updates: int, rounds: int = 1,
                   against: Path | None = None, spec: str = "configs/experiments/thesis.yaml",
                   threads: int | None = 1, on_row=None) -> dict:
    """Each family's slice in each mode (and with ``against``'s code), ``rounds`` times, interleaved."""
    here = Path(__file__).resolve().parents[2]
    checkouts = [("this", here)] + ([("against", Path(against).resolve())] if against is not None else [])
    rows = []
    for r in range(rounds):
        for family in families:
            condition, unit = FAMILIES[family]
            for mode in modes:
                for name, checkout in checkouts:
                    row = {"family": family, "unit": unit, "mode": mode, "code": name, "round": r,
                           **run_slice(checkout, spec, condition, updates, mode, threads,
                                       SLICE_SETS.get(family, ()))}
                    rows.append(row)
                    if on_row is not None:
                        on_row(row)
    return {"threads": threads, "updates": updates, "rounds": rounds, "spec": spec, "rows": rows,
            "against": str(against) if against is not None else None}


HEADER = (f"{'family':<8}{'mode':<13}{'code':<8}{'steps/s':>10}{'collect s':>11}{'update s':>10}{'other s':>9}"
          f"{'eval s':>8}{'eval %':>8}{'peak MB':>9}")


def format_row(r: dict) -> str:
    return (f"{r['family']:<8}{r['mode']:<13}{r['code']:<8}{r['steps_per_s']:>10,.0f}{r['collect_s']:>11.2f}"
            f"{r['update_s']:>10.2f}{r['other_s']:>9.2f}{r['eval_s']:>8.1f}{100 * r['eval_share']:>7.1f}%"
            f"{r['peak_rss_mb']:>9,.0f}")


def ratios(report: dict) -> list[str]:
    """Median steps/s of each family and variant, and each variant's ratio to this code's reproducible mode."""
    by: dict[tuple[str, str, str], list[float]] = {}
    for r in report["rows"]:
        by.setdefault((r["family"], r["mode"], r["code"]), []).append(r["steps_per_s"])
    lines = []
    for family in dict.fromkeys(r["family"] for r in report["rows"]):
        base = by.get((family, MODES[0], "this"))
        for (f, mode, code), values in by.items():
            if f != family:
                continue
            med = statistics.median(values)
            ratio = f"{med / statistics.median(base):.2f}x" if base else "-"
            lines.append(f"{family:<8}{mode:<13}{code:<8}{med:>10,.0f} steps/s (median of {len(values)}), "
                         f"{ratio} this code's reproducible mode")
    return lines
