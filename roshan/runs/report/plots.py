"""Plots of evaluations (learning.md 12) as PNGs: one run's outcomes, times to end and rewards, a policy against
its baselines, and learning curves. An Agg canvas per figure, no pyplot state.
"""

import io
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from roshan.io import write_atomic
from roshan.runs.report.episodes import ALWAYS_REPORTED, IF_PRESENT, LABELS, outcome_categories, validate_episodes
from roshan.runs.report.stats import wilson_interval

_TTE_LABEL = "time to end (steps)"
_COLORS = {"success": "tab:green", "collision": "tab:red", "boundary": "tab:orange", "timeout": "tab:gray",
           "burnout": "tab:brown", "unspecified": "tab:purple"}


def _new_figure(width: float = 6.4, height: float = 4.0):
    # A Figure on its own Agg canvas: no pyplot, so no global backend switch and no figure registry to leak into.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return write_atomic(path, buf.getvalue())


def _finish(ax, path: Path, title: str, ylabel: str, xlabel: str | None = None, ylim: tuple | None = None,
            legend: bool = False) -> Path:
    """What every plot ends with: axis labels, y range, legend and title, then the PNG of the axes' figure."""
    if xlabel is not None:
        ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if ylim is not None:
        ax.set_ylim(*ylim)
    if legend:
        ax.legend()
    ax.set_title(title)
    return _save(ax.figure, path)


def _finish_ecdf(ax, path: Path) -> Path:
    """The finish of the time-to-end ECDFs, of one run and of a comparison alike."""
    return _finish(ax, path, "Time to end, ECDF", "fraction of episodes", xlabel=_TTE_LABEL, ylim=(0, 1.02),
                   legend=True)


def _ecdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points for ``ax.step(..., where="post")``; the leading 0 draws the jump at the smallest value."""
    x = np.sort(values)
    return np.concatenate([x[:1], x]), np.arange(x.size + 1) / x.size


def _categories(outcome_sets: Sequence[np.ndarray]) -> list[str]:
    """Success and the always-reported reasons, plus burnout / unspecified where any run has them."""
    present = set().union(*(set(o) for o in outcome_sets))
    return ["success", *ALWAYS_REPORTED, *(r for r in IF_PRESENT if r in present)]


def _plot_outcome_bar(ep: dict, path: Path) -> Path:
    outcome = outcome_categories(ep)
    cats = _categories([outcome])
    counts = [int(np.sum(outcome == c)) for c in cats]
    fig = _new_figure()
    ax = fig.add_subplot()
    bars = ax.bar([LABELS[c] for c in cats], counts, color=[_COLORS[c] for c in cats])
    ax.bar_label(bars)
    return _finish(ax, path, f"Episode outcomes (n = {outcome.size})", "episodes")


def _plot_tte_hist(ep: dict, path: Path) -> Path:
    is_success = ep["success"] == 1
    bins = np.histogram_bin_edges(ep["time"], bins=min(30, max(5, int(np.sqrt(ep["time"].size)))))
    fig = _new_figure()
    ax = fig.add_subplot()
    ax.hist([ep["time"][is_success], ep["time"][~is_success]], bins=bins, stacked=True,
            color=[_COLORS["success"], _COLORS["collision"]], label=["Success", "Failure"])
    return _finish(ax, path, "Time to end", "episodes", xlabel=_TTE_LABEL, legend=True)


def _plot_tte_ecdf(ep: dict, path: Path) -> Path:
    is_success = ep["success"] == 1
    fig = _new_figure()
    ax = fig.add_subplot()
    for name, mask, color in (("all", np.ones_like(is_success), "black"), ("Success", is_success, _COLORS["success"]),
                              ("Failure", ~is_success, _COLORS["collision"])):
        if mask.any():
            ax.step(*_ecdf(ep["time"][mask]), where="post", color=color, label=f"{name} (n = {int(mask.sum())})")
    return _finish_ecdf(ax, path)


def _plot_reward_vs_episode(ep: dict, path: Path) -> Path:
    n = ep["reward"].size
    x = ep.get("episode", np.arange(1, n + 1))
    is_success = ep["success"] == 1
    window = max(1, n // 10)
    running = np.convolve(ep["reward"], np.ones(window) / window, mode="valid")
    fig = _new_figure()
    ax = fig.add_subplot()
    ax.scatter(x[is_success], ep["reward"][is_success], s=12, color=_COLORS["success"], label="Success")
    ax.scatter(x[~is_success], ep["reward"][~is_success], s=12, color=_COLORS["collision"], label="Failure")
    ax.plot(x[window - 1:], running, color="black", label=f"running mean ({window})")
    return _finish(ax, path, "Reward per episode", "episode reward", xlabel="episode", legend=True)


def _plot_success_bar(ep: dict, path: Path) -> Path:
    n, k = ep["success"].size, int(ep["success"].sum())
    lo, hi = wilson_interval(k, n)
    rate = k / n
    fig = _new_figure(3.2, 4.0)
    ax = fig.add_subplot()
    ax.bar(["Success"], [rate], yerr=[[rate - lo], [hi - rate]], capsize=8, color=_COLORS["success"])
    return _finish(ax, path, f"{100 * rate:.1f} % of {n}", "success rate (Wilson 95 % CI)", ylim=(0, 1))


def _plot_reward_vs_time(ep: dict, path: Path) -> Path:
    outcome = outcome_categories(ep)
    fig = _new_figure()
    ax = fig.add_subplot()
    for cat in _categories([outcome]):
        mask = outcome == cat
        if mask.any():
            ax.scatter(ep["time"][mask], ep["reward"][mask], s=12, color=_COLORS[cat], label=LABELS[cat])
    return _finish(ax, path, "Reward against time to end", "episode reward", xlabel=_TTE_LABEL, legend=True)


def _plot_success_vs_time(ep: dict, path: Path) -> Path:
    # Success rate per TTE bin: shows whether the policy succeeds early and fails late (timeouts) or otherwise.
    edges = np.histogram_bin_edges(ep["time"], bins=min(20, max(3, int(np.sqrt(ep["time"].size)))))
    which = np.clip(np.digitize(ep["time"], edges[1:-1]), 0, edges.size - 2)
    counts = np.bincount(which, minlength=edges.size - 1)
    wins = np.bincount(which, weights=ep["success"], minlength=edges.size - 1)
    rate = np.divide(wins, counts, out=np.zeros_like(wins), where=counts > 0)
    fig = _new_figure()
    ax = fig.add_subplot()
    ax.bar(edges[:-1], rate, width=np.diff(edges), align="edge", color=_COLORS["success"], edgecolor="white")
    return _finish(ax, path, "Success against time to end", "success rate in bin", xlabel=_TTE_LABEL,
                   ylim=(0, 1))


_EPISODE_PLOTS = {"failure_reasons_bar.png": _plot_outcome_bar, "time_to_end_hist.png": _plot_tte_hist,
                  "time_to_end_ecdf.png": _plot_tte_ecdf, "reward_vs_episode.png": _plot_reward_vs_episode,
                  "overall_success_bar.png": _plot_success_bar, "reward_vs_time.png": _plot_reward_vs_time,
                  "success_vs_time.png": _plot_success_vs_time}


def plot_episodes(episodes: Mapping[str, Sequence], out_dir: str | os.PathLike) -> list[Path]:
    """The single-run plots of learning.md 12, as PNGs in ``out_dir``.

    Files: failure_reasons_bar.png (outcome counts, None shown as Success), time_to_end_hist.png,
    time_to_end_ecdf.png, reward_vs_episode.png, overall_success_bar.png (Wilson 95 % CI as error bar),
    reward_vs_time.png, success_vs_time.png.

    Returns:
        The written paths, in that order.
    """
    ep = validate_episodes(episodes)
    out_dir = Path(out_dir)
    return [plot(ep, out_dir / name) for name, plot in _EPISODE_PLOTS.items()]


def plot_comparison(runs: Mapping[str, Mapping[str, Sequence]], out_dir: str | os.PathLike) -> list[Path]:
    """Policy against baseline(s): one colour per run.

    Files: comparison_failure_reasons.png (grouped bars of outcome fractions), comparison_time_to_end_ecdf.png
    (TTE ECDFs overlaid), comparison_success_bar.png (success rates with Wilson 95 % CIs).

    Args:
        runs: run name -> episode set, e.g. ``{"policy": eps, "greedy": eps_greedy}``.
        out_dir: folder for the PNGs.

    Returns:
        The written paths, in that order.
    """
    if not runs:
        raise ValueError("plot_comparison: no runs given")
    eps = {str(name): validate_episodes(e) for name, e in runs.items()}
    out_dir = Path(out_dir)
    return [_plot_comparison_outcomes(eps, out_dir / "comparison_failure_reasons.png"),
            _plot_comparison_ecdf(eps, out_dir / "comparison_time_to_end_ecdf.png"),
            _plot_comparison_success(eps, out_dir / "comparison_success_bar.png")]


def _plot_comparison_outcomes(eps: dict[str, dict], path: Path) -> Path:
    outcomes = {name: outcome_categories(ep) for name, ep in eps.items()}
    cats = _categories(list(outcomes.values()))
    width = 0.8 / len(eps)
    fig = _new_figure(max(6.4, 0.6 * len(cats) * len(eps)), 4.0)
    ax = fig.add_subplot()
    for j, (name, outcome) in enumerate(outcomes.items()):
        ax.bar(np.arange(len(cats)) + (j - (len(eps) - 1) / 2) * width, [np.mean(outcome == c) for c in cats],
               width=width, label=name)
    ax.set_xticks(np.arange(len(cats)), [LABELS[c] for c in cats])
    return _finish(ax, path, "Episode outcomes", "fraction of episodes", ylim=(0, 1), legend=True)


def _plot_comparison_ecdf(eps: dict[str, dict], path: Path) -> Path:
    fig = _new_figure()
    ax = fig.add_subplot()
    for name, ep in eps.items():
        ax.step(*_ecdf(ep["time"]), where="post", label=f"{name} (n = {ep['time'].size})")
    return _finish_ecdf(ax, path)


def _plot_comparison_success(eps: dict[str, dict], path: Path) -> Path:
    fig = _new_figure(max(3.2, 1.4 * len(eps)), 4.0)
    ax = fig.add_subplot()
    for j, ep in enumerate(eps.values()):
        n, k = ep["success"].size, int(ep["success"].sum())
        lo, hi = wilson_interval(k, n)
        ax.bar([j], [k / n], yerr=[[k / n - lo], [hi - k / n]], capsize=8, color=f"C{j}")
    ax.set_xticks(np.arange(len(eps)), list(eps))
    return _finish(ax, path, "Success rate", "success rate (Wilson 95 % CI)", ylim=(0, 1))


def plot_learning_curves(scalars: Mapping[str, Sequence[tuple[int, float]]], out_path: str | os.PathLike,
                         ncols: int = 3) -> Path:
    """A grid of small line plots, one per tag (e.g. from :func:`read_tensorboard_scalars`).

    Args:
        scalars: tag -> [(step, value), ...].
        out_path: the PNG to write.
        ncols: panels per row.

    Returns:
        ``out_path`` as a Path.
    """
    if not scalars:
        raise ValueError("plot_learning_curves: no scalar tags given")
    ncols = max(1, min(ncols, len(scalars)))
    nrows = math.ceil(len(scalars) / ncols)
    fig = _new_figure(3.2 * ncols, 2.4 * nrows)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, (tag, points) in zip(axes, scalars.items(), strict=False):
        if len(points):
            steps, values = zip(*points, strict=True)
            ax.plot(steps, values, linewidth=1, marker="." if len(points) < 30 else None)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(tag, fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[len(scalars):]:
        ax.set_axis_off()
    return _save(fig, Path(out_path))
