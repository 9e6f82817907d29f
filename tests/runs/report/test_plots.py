"""What the evaluation plots show (issue 32, item 15), read from the figures themselves: the learning-rate panel
on a zero-based axis without an offset and the policy std in a panel of its own, no "running mean (1)", no legend
entry for an outcome no episode had, a success-vs-time plot that says when every episode succeeded and how many
episodes each bin holds, timeouts marked on the ECDFs, and whole-episode ticks on the histogram."""

import numpy as np
import pytest

from roshan.runs.report import plots


@pytest.fixture
def figures(monkeypatch):
    """file name -> the Figure each plot saved (the PNGs are written as usual)."""
    saved = {}
    real = plots._save

    def keep(fig, path):
        saved[path.name] = fig
        return real(fig, path)

    monkeypatch.setattr(plots, "_save", keep)
    return saved


def legend_texts(ax) -> list[str]:
    legend = ax.get_legend()
    return [t.get_text() for t in legend.get_texts()] if legend else []


def all_succeed(n=10):
    return {"reward": list(np.linspace(1.0, 2.0, n)), "time": list(range(10, 10 + 7 * n, 7)), "success": [1] * n,
            "reason": ["none"] * n}


def test_learning_rate_panel_is_flat_when_the_rate_barely_moves_and_std_has_its_own(tmp_path, figures):
    curves = {"Training/LR": [(0, 1e-3), (100, 0.9999977e-3)], "Training/log_std": [(0, 1.0), (100, 0.85)],
              "Training/actor_loss": [(0, 1.0), (100, 0.5)]}
    plots.plot_learning_curves(curves, tmp_path / "curves.png")
    axes = {ax.get_title(): ax for ax in figures["curves.png"].axes if ax.get_title()}
    assert "Learning rate and policy log std" not in axes
    lr, std = axes["Learning rate"], axes["Policy std (exp of log std)"]
    assert legend_texts(lr) == [] or legend_texts(lr) == ["learning rate"]
    assert [line.get_label() for line in std.get_lines()] == ["policy std"]
    low, high = lr.get_ylim()
    assert low == 0.0 and high >= 1e-3  # the line sits near the top of a zero-based axis: no steep fall
    formatter = lr.yaxis.get_major_formatter()
    assert formatter.offset == 0 and "+" not in formatter.get_offset()  # no "+9.99998e-4" offset, at most 1e-3 x
    assert std.get_ylim()[0] == 0.0


def test_one_episode_window_draws_no_running_mean_and_no_empty_outcome(tmp_path, figures):
    plots.plot_episodes(all_succeed(5), tmp_path)
    ax = figures["reward_vs_episode.png"].axes[0]
    assert legend_texts(ax) == ["Success"]  # no "Failure" (there was none), no "running mean (1)"
    assert all("Failure" not in t for t in legend_texts(figures["time_to_end_hist.png"].axes[0]))
    assert all("Failure" not in t for t in legend_texts(figures["time_to_end_ecdf.png"].axes[0]))
    plots.plot_episodes(all_succeed(30), tmp_path / "30")
    assert "running mean of 3 episodes" in legend_texts(figures["reward_vs_episode.png"].axes[0])


def test_success_vs_time_says_every_episode_succeeded_and_counts_each_bin(tmp_path, figures):
    plots.plot_episodes(all_succeed(9), tmp_path)
    ax = figures["success_vs_time.png"].axes[0]
    assert "every episode succeeded (9 of 9)" in ax.get_title()
    counts = [t.get_text() for t in ax.texts]
    assert counts and all(c.startswith("n=") for c in counts) and sum(int(c[2:]) for c in counts) == 9


def test_ecdfs_mark_the_timeouts_at_the_step_limit(tmp_path, figures):
    eps = {"time": [10, 20, 30, 100, 100], "success": [1, 1, 1, 0, 0], "reason": ["none"] * 3 + ["timeout"] * 2}
    plots.plot_episodes(eps, tmp_path)
    ax = figures["time_to_end_ecdf.png"].axes[0]
    assert "2 timeouts at the step limit (100)" in legend_texts(ax)
    assert any(tuple(line.get_xdata()) == (100, 100) for line in ax.get_lines())  # the dotted line at the limit
    plots.plot_comparison({"policy": eps, "greedy": all_succeed(5)}, tmp_path)
    texts = legend_texts(figures["comparison_time_to_end_ecdf.png"].axes[0])
    assert "policy: 2 timeouts at the step limit (100)" in texts and not any("greedy:" in t for t in texts)


def test_histogram_counts_whole_episodes(tmp_path, figures):
    plots.plot_episodes({"time": [10, 20, 30], "success": [1, 0, 1], "reason": ["none", "timeout", "none"]},
                        tmp_path)
    ax = figures["time_to_end_hist.png"].axes[0]
    ticks = ax.get_yticks()
    assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks)


def test_every_outcome_of_a_battery_run_has_its_bar_and_colour(tmp_path, figures):
    """Episodes that ended with every drone down (issue 33) get a "Drones lost" bar of their own."""
    ep = {"reward": [1.0, -1.0, -2.0], "time": [10, 20, 30], "success": [1, 0, 0], "reason": ["none", "lost", "lost"]}
    plots.plot_episodes(ep, tmp_path, reasons=("timeout", "burnout", "lost"))
    ax = figures["failure_reasons_bar.png"].axes[0]
    counts = {t.get_text(): int(b.get_height()) for t, b in zip(ax.get_xticklabels(), ax.patches, strict=True)}
    assert counts["Drones lost"] == 2 and counts["Success"] == 1
