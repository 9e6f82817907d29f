"""Evaluation reporting: intervals against hand-worked values, summaries, tables, CSV/JSON round trips, plots."""

import json
import math
import re

import numpy as np
import pytest

from roshan.runs import report

T_9 = 2.262157  # t_{0.975, 9} from a printed t table


def ten_episodes(**extra):
    """7 successes, then one collision, one boundary exit and one timeout."""
    eps = {
        "reward": [1.0] * 7 + [-1.0] * 3,
        "time": [10, 20, 30, 40, 50, 60, 70, 15, 25, 100],
        "success": [1] * 7 + [0] * 3,
        "reason": ["none"] * 7 + ["collision", "boundary", "timeout"],
    }
    eps.update(extra)
    return eps


# ---------------------------------------------------------------------------------------------- intervals

def test_wilson_interval_hand_worked():
    # p = 0.7, z = 1.96: centre (0.7 + z^2/20) / (1 + z^2/10) = 0.6445, half-width 0.2477.
    lo, hi = report.wilson_interval(7, 10)
    assert lo == pytest.approx(0.3968, abs=1e-4)
    assert hi == pytest.approx(0.8922, abs=1e-4)
    # k = 0: [0, z^2 / (n + z^2)]; k = n mirrors it.
    z2 = 1.959963984540054**2
    assert report.wilson_interval(0, 10) == pytest.approx((0.0, z2 / (10 + z2)))
    assert report.wilson_interval(10, 10) == pytest.approx((10 / (10 + z2), 1.0))
    for n in range(1, 60):  # exact bounds at the ends: a plot's error bar must not come out negative
        assert report.wilson_interval(0, n)[0] == 0.0
        assert report.wilson_interval(n, n)[1] == 1.0


@pytest.mark.parametrize("k, n", [(0, 0), (-1, 5), (6, 5)])
def test_wilson_interval_rejects_bad_counts(k, n):
    with pytest.raises(ValueError, match="wilson_interval"):
        report.wilson_interval(k, n)


@pytest.mark.parametrize("df, expected", [(1, 12.7062), (2, 4.3027), (5, 2.5706), (9, 2.2622), (30, 2.0423),
                                          (1000, 1.9623)])
def test_t_quantile_matches_the_table(df, expected):
    assert report.t_quantile(0.975, df) == pytest.approx(expected, abs=1e-4)


@pytest.mark.parametrize("p", [0.6, 0.9, 0.975, 0.995, 0.9999])
def test_t_quantile_closed_forms(p):
    # df = 1 is the Cauchy distribution; df = 2 has t = (2p - 1) / sqrt(2 p (1 - p)).
    assert report.t_quantile(p, 1) == pytest.approx(math.tan(math.pi * (p - 0.5)), rel=1e-9)
    assert report.t_quantile(p, 2) == pytest.approx((2 * p - 1) / math.sqrt(2 * p * (1 - p)), rel=1e-9)
    assert report.t_quantile(1 - p, 7) == pytest.approx(-report.t_quantile(p, 7), rel=1e-9)
    assert report.t_quantile(0.5, 3) == 0.0


def test_t_quantile_matches_scipy():
    from scipy import stats  # a dev dependency: this check must run, not skip
    for df in (1, 3, 4.5, 9, 29, 200, 10_000):
        for p in (0.01, 0.55, 0.9, 0.95, 0.975, 0.995):
            assert report.t_quantile(p, df) == pytest.approx(stats.t.ppf(p, df), abs=1e-8)


def test_t_quantile_rejects_bad_arguments():
    with pytest.raises(ValueError, match="0 < p < 1"):
        report.t_quantile(1.0, 5)
    with pytest.raises(ValueError, match="df > 0"):
        report.t_quantile(0.975, 0)


def test_describe_small_samples():
    assert report.describe([3.0]) == {"mean": 3.0, "std": 0.0, "median": 3.0, "ci": [3.0, 3.0]}
    assert report.describe([]) == {"mean": None, "std": None, "median": None, "ci": [None, None]}


# ---------------------------------------------------------------------------------------------- summary

def test_summary_of_a_constructed_set():
    s = report.summarize(ten_episodes())
    assert s["episodes"] == 10
    assert s["success_rate"] == pytest.approx(0.7)
    assert s["success_ci"] == pytest.approx([0.3968, 0.8922], abs=1e-4)
    assert s["failure_rates"] == pytest.approx({"collision": 0.1, "boundary": 0.1, "timeout": 0.1})
    assert list(s["failure_rates"]) == ["collision", "boundary", "timeout"]  # no burnout key when none occurred
    # TTE: sum 420 -> mean 42; sorted middle pair (30, 40) -> median 35; squared deviations sum to 7210.
    std = math.sqrt(7210 / 9)
    assert s["tte"]["mean"] == pytest.approx(42.0)
    assert s["tte"]["median"] == pytest.approx(35.0)
    assert s["tte"]["std"] == pytest.approx(std)
    assert s["tte"]["ci"] == pytest.approx([42 - T_9 * std / math.sqrt(10), 42 + T_9 * std / math.sqrt(10)], abs=1e-4)
    # Successes only: 10..70 -> mean 40, std sqrt(2800 / 6).
    assert s["tte_success"]["mean"] == pytest.approx(40.0)
    assert s["tte_success"]["std"] == pytest.approx(math.sqrt(2800 / 6))
    # Reward: mean 0.4, deviations 0.6 (x7) and -1.4 (x3) -> variance 8.4 / 9.
    assert s["reward"]["mean"] == pytest.approx(0.4)
    assert s["reward"]["median"] == pytest.approx(1.0)
    assert s["reward"]["std"] == pytest.approx(math.sqrt(8.4 / 9))
    assert "burned" not in s
    json.dumps(s, allow_nan=False)  # JSON-able as it stands


def test_summary_with_burned_burnout_and_unspecified_failures():
    eps = ten_episodes(burned=[0.1, 0.2, 0.3, 0.1, 0.2, 0.3, 0.1, 0.2, 0.3, 0.4])
    eps["reason"] = ["none"] * 7 + ["Burnout", "BoundaryExit", "none"]  # reference names accepted, any case
    s = report.summarize(eps)
    assert s["failure_rates"] == pytest.approx({"collision": 0.0, "boundary": 0.1, "timeout": 0.0, "burnout": 0.1,
                                                "unspecified": 0.1})
    assert s["burned"]["mean"] == pytest.approx(0.22)
    assert s["burned"]["median"] == pytest.approx(0.2)


def test_evaluation_scalars_use_the_tensorboard_tags():
    s = report.summarize(ten_episodes(burned=[0.5] * 10))
    scalars = report.evaluation_scalars(s)
    assert scalars["Evaluation/Success_rate"] == pytest.approx(0.7)
    assert scalars["Evaluation/Success_ci_low"] == pytest.approx(0.3968, abs=1e-4)
    assert scalars["Evaluation/Success_n"] == 10
    assert scalars["Evaluation/Time_mean"] == pytest.approx(42.0)
    assert scalars["Evaluation/Time_median"] == pytest.approx(35.0)
    assert scalars["Evaluation/Reward_std"] == pytest.approx(math.sqrt(8.4 / 9))
    assert scalars["Evaluation/Percent_Burned_ci_high"] == pytest.approx(0.5)
    assert scalars["Evaluation/Collision_rate"] == pytest.approx(0.1)
    assert len(scalars) == 4 + 3 + 3 * 5  # success, the three failure rates, reward / time / burned statistics



def test_with_a_battery_the_evaluation_scalars_carry_its_figures():
    eps = ten_episodes(burned=[0.5] * 10)
    eps.update(drones_lost=[0, 1, 0, 0, 2, 0, 0, 0, 0, 1], battery_swaps=[3] * 10, energy_used=[9000.0] * 10,
               base_time=[12.5] * 10)
    scalars = report.evaluation_scalars(report.summarize(eps))
    assert scalars["Evaluation/Drones_Lost_mean"] == pytest.approx(0.4)
    assert scalars["Evaluation/Battery_Swaps_median"] == 3.0 and scalars["Evaluation/Energy_Used_mean"] == 9000.0
    assert scalars["Evaluation/Base_Time_mean"] == pytest.approx(12.5)
    assert len(scalars) == 4 + 3 + 7 * 5  # and the battery's four statistics

# ---------------------------------------------------------------------------------------------- tables

def table_rows(table: str) -> dict[str, str]:
    """Row label -> value of a one-column table (label and value are separated by two or more spaces)."""
    lines = [line for line in table.splitlines()[1:] if line and not line.startswith("-")]
    return dict(re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in lines)


def test_format_table_numbers():
    eps = ten_episodes(burned=[0.1] * 10, burning=[0.02] * 10, lit=[0.3] * 10, extinguished=[4] * 10)
    table = report.format_table(report.summarize(eps, dt=0.1), title="FlyAgent")
    assert table.splitlines()[0] == "FlyAgent"
    rows = table_rows(table)
    assert rows["Episodes"] == "10"
    assert rows["Success rate"] == "70.0 % [39.7, 89.2]"
    assert rows["Collision rate"] == rows["Boundary rate"] == rows["Timeout rate"] == "10.0 %"
    assert rows["TTE (steps)"] == "42.0 ± 28.3 (35.0)"
    assert rows["TTE (s)"] == "4.2 ± 2.8 (3.5)"  # steps * dt
    assert rows["TTE of successes (steps)"] == "40.0 ± 21.6 (40.0)"
    assert rows["Reward (episode return)"] == "0.40 ± 0.97 (1.00)"
    assert rows["Burned out (% of cells)"] == "10.0 ± 0.0 (10.0) %"
    assert rows["Burning at end (% of cells)"] == "2.0 ± 0.0 (2.0) %"
    assert rows["Ever lit (% of cells)"] == "30.0 ± 0.0 (30.0) %"
    assert rows["Extinguished (cells)"] == "4.0 ± 0.0 (4.0)"
    assert "Burnout rate" not in rows


def test_tables_show_only_what_the_controller_measures():
    # The greedy heuristic earns no reward: no reward column, so no reward row (not "0.00 ± 0.00").
    greedy = ten_episodes()
    del greedy["reward"]
    greedy["reason"] = ["none"] * 7 + ["timeout", "burnout", "timeout"]
    summary = report.summarize(greedy, reasons=("timeout", "burnout"))
    assert "reward" not in summary
    rows = table_rows(report.format_table(summary))
    assert not any(label.startswith("Reward") for label in rows)
    # The planner's records end by timeout or burnout only: no collision or boundary rows; burnout always.
    assert [label for label in rows if label.endswith(" rate")] == ["Success rate", "Timeout rate", "Burnout rate"]
    no_burnout = report.summarize({**greedy, "reason": ["none"] * 7 + ["timeout"] * 3}, reasons=("timeout", "burnout"))
    assert no_burnout["failure_rates"] == {"timeout": 0.3, "burnout": 0.0}
    # Side by side with a policy that has a reward: the greedy column reads "-" there.
    policy = report.summarize({**greedy, "reward": [1.0] * 10}, reasons=("timeout", "burnout"))
    row = {line.split("  ")[0].strip(): line for line in report.format_comparison(
        {"planner": policy, "greedy": summary}).splitlines()}
    assert row["Reward (episode return)"].split()[-1] == "-"
    assert "Collision rate" not in row


def test_tables_show_the_drones_lost_per_episode_beside_the_rate_of_episodes_that_lost_all():
    # issue 52: 64 drones, 50 of them lost in every episode, read "Drones lost rate 0.0 %" beside 100 % success
    eps = {"time": [400] * 4, "success": [1] * 4, "reason": ["none"] * 4, "drones_lost": [50, 50, 48, 52]}
    rows = table_rows(report.format_table(report.summarize(eps, reasons=("timeout", "burnout", "lost"))))
    assert rows["All drones lost rate"] == "0.0 %"
    assert rows["Drones lost (per episode)"] == "50.00 ± 1.63 (50.00)"  # sample std
    assert "Drones lost rate" not in rows


def test_outcome_plots_show_every_reason_the_controller_can_have(tmp_path):
    from roshan.runs.report.plots import _categories

    outcome = np.array(["success", "timeout"])
    assert _categories([outcome], ("timeout", "burnout")) == ["success", "timeout", "burnout"]
    greedy = ten_episodes()
    del greedy["reward"]
    names = [p.name for p in report.plot_episodes(greedy, tmp_path, reasons=("timeout", "burnout"), who="greedy")]
    assert "reward_vs_episode.png" not in names and "reward_vs_time.png" not in names


def test_format_comparison_side_by_side():
    greedy = ten_episodes()
    greedy["reason"] = ["none"] * 7 + ["burnout", "burnout", "timeout"]
    table = report.format_comparison({"policy": report.summarize(ten_episodes()),
                                      "greedy": report.summarize(greedy)})
    header = next(line for line in table.splitlines() if line.startswith("Metric"))
    assert header.split() == ["Metric", "policy", "greedy"]
    row = {line.split("  ")[0].strip(): line for line in table.splitlines()}
    # Burnout happened only under greedy: the policy column reads 0.0 %, not a gap.
    assert row["Burnout rate"].split() == ["Burnout", "rate", "0.0", "%", "20.0", "%"]
    assert row["Collision rate"].split() == ["Collision", "rate", "10.0", "%", "0.0", "%"]
    assert row["Success rate"].count("70.0 % [39.7, 89.2]") == 2
    with pytest.raises(ValueError, match="no summaries"):
        report.format_comparison({})


# ---------------------------------------------------------------------------------------------- files

def test_csv_round_trip(tmp_path):
    eps = ten_episodes(burned=np.linspace(0.0, 0.3, 10), seed=list(range(100, 110)))
    eps["reward"] = [0.1 + 0.2, -1 / 3, *eps["reward"][2:]]  # floats that need every digit
    path = report.write_episodes_csv(eps, tmp_path / "logs" / "evaluation_stats.csv")
    assert [p.name for p in path.parent.iterdir()] == ["evaluation_stats.csv"]  # the temp file was renamed away
    lines = path.read_text().splitlines()
    assert lines[0] == "Episode,Reward,Time,Percent_Burned,Success,Failure_Reason,Seed"
    assert lines[1].endswith(",1,None,100")
    assert lines[9].split(",")[-2] == "BoundaryExit"
    back = report.read_episodes_csv(path)
    np.testing.assert_array_equal(back["reward"], np.asarray(eps["reward"]))
    np.testing.assert_array_equal(back["burned"], eps["burned"])
    np.testing.assert_array_equal(back["time"], eps["time"])
    np.testing.assert_array_equal(back["success"], eps["success"])
    np.testing.assert_array_equal(back["seed"], eps["seed"])
    np.testing.assert_array_equal(back["episode"], np.arange(1, 11))


def test_csv_of_a_controller_without_reward_and_with_the_fire_columns(tmp_path):
    eps = ten_episodes(burned=[0.1] * 10, burning=[0.05] * 10, lit=[0.25] * 10, extinguished=list(range(10)))
    del eps["reward"]
    path = report.write_episodes_csv(eps, tmp_path / "e.csv")
    assert path.read_text().splitlines()[0] == ("Episode,Time,Percent_Burned,Burning_Fraction,Lit_Fraction,"
                                                "Extinguished,Success,Failure_Reason")
    back = report.read_episodes_csv(path)
    assert "reward" not in back
    np.testing.assert_array_equal(back["extinguished"], np.arange(10))
    np.testing.assert_array_equal(back["lit"], eps["lit"])
    assert list(back["reason"]) == eps["reason"]
    assert report.summarize(back) == report.summarize(eps)


def test_csv_with_the_battery_columns_keeps_their_headers_and_types(tmp_path):
    # the record's extra columns (roshan.episode.EXTRA_COLUMNS) under the headers users' files have
    eps = ten_episodes(drones_lost=[0, 1] * 5, battery_swaps=[3] * 10, energy_used=[0.1 + 0.2] * 10,
                       base_time=[12.5] * 10)
    lines = report.write_episodes_csv(eps, tmp_path / "e.csv").read_text().splitlines()
    assert lines[0] == ("Episode,Reward,Time,Drones_Lost,Battery_Swaps,Energy_Used,Base_Time,Success,"
                        "Failure_Reason")
    assert lines[2] == "2,1.0,20,1,3,0.30000000000000004,12.5,1,None"
    back = report.read_episodes_csv(tmp_path / "e.csv")
    assert back["drones_lost"].dtype == np.int64 and back["energy_used"].dtype == np.float64
    assert report.summarize(back) == report.summarize(eps)
    with pytest.raises(ValueError, match=r"episodes\['battery_swaps'\] must hold integers"):
        report.validate_episodes(ten_episodes(battery_swaps=[0.5] * 10))
    with pytest.raises(ValueError, match=r"episodes\['base_time'\] must be finite and within \[0.0, inf\]"):
        report.validate_episodes(ten_episodes(base_time=[-1.0] * 10))


def test_csv_reader_names_the_missing_column_and_bad_value(tmp_path):
    path = tmp_path / "stats.csv"
    path.write_text("Episode,Reward,Time,Success\n1,0.5,10,1\n")
    with pytest.raises(ValueError, match="missing column.*Failure_Reason"):
        report.read_episodes_csv(path)
    path.write_text("Episode,Reward,Time,Success,Failure_Reason\n1,0.5,10,False,Stuckish\n")
    with pytest.raises(ValueError, match=r"stats\.csv.*'reason'.*stuckish"):
        report.read_episodes_csv(path)


def test_summary_json(tmp_path):
    s = report.summarize(ten_episodes())
    path = report.write_summary_json(s, tmp_path / "summary.json")
    assert json.loads(path.read_text()) == s
    with pytest.raises(ValueError):
        report.write_summary_json({"x": float("nan")}, tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]


# ---------------------------------------------------------------------------------------------- plots

def assert_png(path, min_bytes=2000):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > min_bytes


def test_plot_episodes(tmp_path):
    paths = report.plot_episodes(ten_episodes(), tmp_path / "logs")
    assert [p.name for p in paths] == ["failure_reasons_bar.png", "time_to_end_hist.png", "time_to_end_ecdf.png",
                                       "reward_vs_episode.png", "overall_success_bar.png", "reward_vs_time.png",
                                       "success_vs_time.png"]
    for p in paths:
        assert_png(p)


def test_plot_episodes_all_failed_or_single(tmp_path):
    timeouts = {"reward": np.zeros(5), "time": np.full(5, 7), "success": np.zeros(5, bool), "reason": ["Timeout"] * 5}
    one = {"reward": [0.5], "time": [3], "success": [1], "reason": ["none"]}
    for name, eps in (("timeouts", timeouts), ("one", one)):
        for p in report.plot_episodes(eps, tmp_path / name):
            assert_png(p)


def test_plot_comparison_and_learning_curves(tmp_path):
    greedy = ten_episodes()
    greedy["reason"] = ["none"] * 7 + ["burnout", "burnout", "timeout"]
    paths = report.plot_comparison({"policy": ten_episodes(), "greedy": greedy}, tmp_path)
    assert [p.name for p in paths] == ["comparison_failure_reasons.png", "comparison_time_to_end_ecdf.png",
                                       "comparison_success_bar.png"]
    for p in paths:
        assert_png(p)
    curves = {"Training/actor_loss": [(0, 1.0), (1, 0.5), (2, 0.25)], "Training/LR": [(0, 3e-4), (2, 1e-4)],
              "Training/Objective": [], "Rewards/Returns": [(5, -2.0)]}
    assert_png(report.plot_learning_curves(curves, tmp_path / "curves.png"))
    with pytest.raises(ValueError, match="no scalar tags"):
        report.plot_learning_curves({}, tmp_path / "none.png")


def test_read_tensorboard_scalars(tmp_path):
    from tensorboard.compat.proto.event_pb2 import Event
    from tensorboard.compat.proto.summary_pb2 import Summary
    from tensorboard.summary.writer.event_file_writer import EventFileWriter

    # The same records torch's SummaryWriter.add_scalar writes (simple_value summaries).
    writer = EventFileWriter(str(tmp_path))
    for step, (loss, lr) in enumerate([(1.0, 0.5), (0.5, 0.25), (0.25, 0.125)]):
        for tag, value in (("Training/actor_loss", loss), ("Training/LR", lr)):
            writer.add_event(Event(step=step, wall_time=1.0 + step,
                                   summary=Summary(value=[Summary.Value(tag=tag, simple_value=value)])))
    writer.close()
    scalars = report.read_tensorboard_scalars(tmp_path)
    assert scalars == {"Training/LR": [(0, 0.5), (1, 0.25), (2, 0.125)],
                       "Training/actor_loss": [(0, 1.0), (1, 0.5), (2, 0.25)]}
    with pytest.raises(FileNotFoundError):
        report.read_tensorboard_scalars(tmp_path / "missing")


# ---------------------------------------------------------------------------------------------- errors

@pytest.mark.parametrize("change, message", [
    (lambda e: e.pop("reason"), r"missing key\(s\) \['reason'\]"),
    (lambda e: e.update(time=[1, 2, 3]), r"different lengths.*'time': 3"),
    (lambda e: e.update(reason=["none"] * 7 + ["explode", "boundary", "timeout"]), r"'reason'.*\['explode'\]"),
    (lambda e: e.update(reason=["timeout"] * 10), r"'reason'.*'none' for a success; episode index 0"),
    (lambda e: e.update(success=[2] * 10), r"episodes\['success'\]"),
    (lambda e: e.update(time=[1.5] * 10), r"episodes\['time'\] must hold integers"),
    (lambda e: e.update(reward=[float("nan")] * 10), r"episodes\['reward'\] must be finite"),
    (lambda e: e.update(burned=[1.5] * 10), r"episodes\['burned'\]"),
    (lambda e: e.update(reward=np.zeros((10, 1))), r"episodes\['reward'\] must be 1-D"),
])
def test_bad_input_names_the_key(change, message):
    eps = ten_episodes()
    change(eps)
    with pytest.raises(ValueError, match=message):
        report.summarize(eps)


def test_extra_columns_are_ignored():
    eps = ten_episodes(env=np.arange(10), index=[3] * 10)
    checked = report.validate_episodes(eps)
    assert sorted(checked) == ["reason", "reward", "success", "time"]
    assert report.summarize(eps) == report.summarize(ten_episodes())


def test_empty_episode_set():
    with pytest.raises(ValueError, match="empty episode set"):
        report.summarize({"reward": [], "time": [], "success": [], "reason": []})
    with pytest.raises(ValueError, match="no runs"):
        report.plot_comparison({}, "unused")
