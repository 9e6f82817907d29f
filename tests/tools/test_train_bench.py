"""roshan bench train: what a slice times and how the summary compares variants (no timing is asserted)."""

from pathlib import Path

import pytest

from roshan.tools import train_bench as tb
from roshan.tools.train_slice import time_slice

SPEC = str(Path(__file__).resolve().parents[2] / "configs" / "experiments" / "thesis.yaml")


@pytest.mark.slow
def test_a_td3_slice_times_updates_not_only_the_warm_up():
    """TD3 starts updating at 30,000 stored transitions, eight iterations in: the slice's setting lets the warm-up
    iteration fill the buffer, so that the timed iteration (64 env steps of 16 envs) holds updates."""
    row = time_slice(SPEC, "E1_td3", 1, sets=tb.SLICE_SETS["TD3"], evaluate=False)
    assert row["env_steps"] == 64 * 16
    assert row["update_s"] > 0 and row["collect_s"] > 0 and row["other_s"] >= 0
    assert row["update_s"] + row["collect_s"] + row["other_s"] == pytest.approx(row["seconds"])
    assert row["steps_per_s"] == pytest.approx(row["env_steps"] / row["seconds"])
    assert row["eval_s"] == 0 and row["peak_rss_mb"] > 100


def test_the_summary_gives_medians_and_ratios_to_the_reproducible_mode():
    def row(family, mode, code, rate):
        return {"family": family, "mode": mode, "code": code, "steps_per_s": rate}

    report = {"rows": [row("E6", "reproducible", "this", 600.0), row("E6", "vendor", "this", 1200.0),
                       row("E6", "reproducible", "this", 700.0), row("E6", "vendor", "this", 1500.0),
                       row("E6", "reproducible", "against", 325.0), row("E6", "reproducible", "against", 325.0)]}
    lines = tb.ratios(report)
    assert lines == [
        "E6      reproducible this           650 steps/s (median of 2), 1.00x this code's reproducible mode",
        "E6      vendor       this         1,350 steps/s (median of 2), 2.08x this code's reproducible mode",
        "E6      reproducible against        325 steps/s (median of 2), 0.50x this code's reproducible mode"]


def test_unknown_families_and_modes_are_refused_by_name():
    from click.testing import CliRunner

    from roshan.cli import main

    out = CliRunner().invoke(main, ["bench", "train", "--families", "E6,E9", "--modes", "fast"])
    assert out.exit_code == 1 and "unknown ['E9', 'fast']" in out.output


def test_a_relative_spec_is_each_checkouts_own_and_an_absolute_one_is_shared(tmp_path, monkeypatch):
    """Each code times its own spec unless one spec file is named for both: a spec's settings and models change
    with the code (a new low level, another step limit), so only a shared spec compares code on one workload."""
    read = []
    monkeypatch.setattr(tb, "run_slice", lambda checkout, spec, *a: read.append(checkout / spec) or
                        {"steps_per_s": 1.0})
    other = tmp_path / "old"
    tb.bench_training(["planner"], ["vendor"], 1, against=other)
    here = Path(tb.__file__).resolve().parents[2]
    assert read == [here / "configs/experiments/thesis.yaml", other.resolve() / "configs/experiments/thesis.yaml"]
    read.clear()
    tb.bench_training(["planner"], ["vendor"], 1, against=other, spec=SPEC)
    assert read == [Path(SPEC), Path(SPEC)]


def test_a_shared_spec_that_does_not_exist_is_refused_by_name(tmp_path):
    from click.testing import CliRunner

    from roshan.cli import main

    missing = tmp_path / "nope.yaml"
    out = CliRunner().invoke(main, ["bench", "train", "--families", "planner", "--spec", str(missing)])
    assert out.exit_code == 1 and f"--spec {missing}: no such file" in out.output
