"""``train.auto_train``: k independent runs of one config (seeds seed .. seed+k-1), each trained and evaluated,
their success rates summarised; and the console lines about a finished run."""

import json
from pathlib import Path

import numpy as np

from roshan.config import Config, apply_overrides
from roshan.runs.report.tables import format_table
from roshan.runs.resume import start_run
from roshan.runs.train import train


def train_auto(cfg: Config, root: str | Path = "runs", name: str | None = None, progress_bar: bool = True,
               evaluate_at_end: bool = True) -> list[dict]:
    """``train.auto_train`` = k independent runs (seeds seed .. seed+k-1) in sequence, each evaluated; one
    run goes straight to ``root/name``, several to ``root/name/seed_<s>``."""

    k = cfg.train.auto_train
    if k == 1:
        return [train(cfg, start_run(cfg, root, name), progress_bar=progress_bar, evaluate_at_end=evaluate_at_end)]
    parent = start_run(cfg, root, name)
    results = []
    for i in range(k):
        seed_cfg = apply_overrides(cfg, [f"sim.seed={cfg.sim.seed + i}", "train.auto_train=1"])
        run_dir = start_run(seed_cfg, parent, f"seed_{seed_cfg.sim.seed}")
        results.append(train(seed_cfg, run_dir, progress_bar=progress_bar, evaluate_at_end=evaluate_at_end))
    if evaluate_at_end:
        _write_auto_summary(parent, results)
    return results


def _write_auto_summary(parent: Path, results: list[dict]) -> None:
    """Per-seed success rates and their mean ± std (median), the way the thesis reports FlyAgent experiments."""

    rates = np.array([r["eval"]["success_rate"] for r in results])
    summary = {"runs": [r["run_dir"] for r in results], "success_rates": rates.tolist(),
               "success_mean": float(rates.mean()), "success_std": float(rates.std(ddof=1)) if len(rates) > 1 else 0.0,
               "success_median": float(np.median(rates))}
    (Path(parent) / "auto_train.json").write_text(json.dumps(summary, indent=2) + "\n")


def result_lines(res: dict) -> str:
    """A few lines about a finished run for the console."""

    mins = res["seconds"] / 60.0
    head = (f"{res['run_dir']}: {res['updates']} updates, {res['env_steps']:,} env steps, {mins:.1f} min "
            f"({res['env_steps'] / max(res['seconds'], 1e-9):,.0f} env-steps/s), {res['train_episodes']} episodes")
    if res.get("stopped_by"):
        head += f"; stopped: {res['stopped_by']}"
    if "eval" not in res:
        return head
    return head + "\n" + format_table(res["eval"], f"evaluation of {Path(res['run_dir']).name}")
