"""Plots of evaluations (docs/model/learning.md §12) as PNGs: one run's outcomes, times to end and rewards, a policy
against its baselines, and learning curves. An Agg canvas per figure, no pyplot state.
"""

import io
import math
import os
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from roshan.io import write_atomic
from roshan.runs.report.episodes import ALWAYS_REPORTED, IF_PRESENT, LABELS, outcome_categories, validate_episodes
from roshan.runs.report.stats import wilson_interval

_TTE_LABEL = "time to end (steps)"
_COLORS = {"success": "tab:green", "collision": "tab:red", "boundary": "tab:orange", "timeout": "tab:gray",
           "burnout": "tab:brown", "lost": "tab:blue", "unspecified": "tab:purple"}


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


def _finish_ecdf(ax, path: Path, who: str | None = None) -> Path:
    """The finish of the time-to-end ECDFs, of one run and of a comparison alike."""
    return _finish(ax, path, _titled("time to end, ECDF", who), "fraction of episodes", xlabel=_TTE_LABEL,
                   ylim=(0, 1.02), legend=True)


def _ecdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points for ``ax.step(..., where="post")``; the leading 0 draws the jump at the smallest value."""
    x = np.sort(values)
    return np.concatenate([x[:1], x]), np.arange(x.size + 1) / x.size


def _categories(outcome_sets: Sequence[np.ndarray], reasons: Sequence[str] = ALWAYS_REPORTED) -> list[str]:
    """Success and the controller's failure reasons, plus burnout / unspecified where any run has them."""
    present = set().union(*(set(o) for o in outcome_sets))
    return ["success", *reasons, *(r for r in IF_PRESENT if r in present and r not in reasons)]


def _titled(title: str, who: str | None) -> str:
    """A plot title that says which controller it shows."""
    return f"{who}: {title}" if who else title[:1].upper() + title[1:]


def _plot_outcome_bar(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    outcome = outcome_categories(ep)
    cats = _categories([outcome], reasons)
    counts = [int(np.sum(outcome == c)) for c in cats]
    fig = _new_figure()
    ax = fig.add_subplot()
    bars = ax.bar([LABELS[c] for c in cats], counts, color=[_COLORS[c] for c in cats])
    ax.bar_label(bars)
    _integer_counts(ax)
    return _finish(ax, path, _titled(f"episode outcomes (n = {outcome.size})", who), "episodes")


def _integer_counts(ax) -> None:
    """Whole-number ticks on the y axis of a plot that counts episodes (no 0.5 episode)."""
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def _plot_tte_hist(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    is_success = ep["success"] == 1
    bins = np.histogram_bin_edges(ep["time"], bins=min(30, max(5, int(np.sqrt(ep["time"].size)))))
    fig = _new_figure()
    ax = fig.add_subplot()
    groups = [(ep["time"][m], c, f"{name} (n = {int(m.sum())})") for m, c, name in
              ((is_success, _COLORS["success"], "Success"), (~is_success, _COLORS["collision"], "Failure"))
              if m.any()]  # no legend entry for an outcome no episode had
    ax.hist([g[0] for g in groups], bins=bins, stacked=True, color=[g[1] for g in groups], label=[g[2] for g in groups])
    _integer_counts(ax)
    return _finish(ax, path, _titled("time to end", who), "episodes", xlabel=_TTE_LABEL, legend=True)


def _mark_timeouts(ax, ep: dict, color: str = _COLORS["timeout"], name: str = "") -> None:
    """Mark the episodes that timed out on an ECDF of times to end: they stop at the step limit, where the curve
    would otherwise rise as if they had ended there. A dotted line at the limit (a shaded span where the limits of
    the episodes differ), labelled with the count."""
    if "reason" not in ep:
        return
    times = ep["time"][ep["reason"] == "timeout"]
    if not times.size:
        return
    lo, hi = float(times.min()), float(times.max())
    label = f"{name + ': ' if name else ''}{times.size} timeout{'s' * (times.size != 1)} at the step limit"
    if lo == hi:
        ax.axvline(lo, color=color, linestyle=":", linewidth=1.5, label=f"{label} ({lo:g})")
    else:
        ax.axvspan(lo, hi, color=color, alpha=0.2, linewidth=0, label=f"{label} ({lo:g}-{hi:g})")


def _plot_tte_ecdf(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    is_success = ep["success"] == 1
    fig = _new_figure()
    ax = fig.add_subplot()
    for name, mask, color in (("all", np.ones_like(is_success), "black"), ("Success", is_success, _COLORS["success"]),
                              ("Failure", ~is_success, _COLORS["collision"])):
        if mask.any():
            ax.step(*_ecdf(ep["time"][mask]), where="post", color=color, label=f"{name} (n = {int(mask.sum())})")
    _mark_timeouts(ax, ep)
    return _finish_ecdf(ax, path, who)


def _plot_reward_vs_episode(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    n = ep["reward"].size
    x = ep.get("episode", np.arange(1, n + 1))
    is_success = ep["success"] == 1
    window = max(1, n // 10)
    fig = _new_figure()
    ax = fig.add_subplot()
    for mask, color, name in ((is_success, _COLORS["success"], "Success"), (~is_success, _COLORS["collision"],
                                                                              "Failure")):
        if mask.any():  # no legend entry for an outcome no episode had
            ax.scatter(x[mask], ep["reward"][mask], s=12, color=color, label=name)
    if window > 1:  # a running mean of 1 episode is the points themselves
        running = np.convolve(ep["reward"], np.ones(window) / window, mode="valid")
        ax.plot(x[window - 1:], running, color="black", label=f"running mean of {window} episodes")
    return _finish(ax, path, _titled("reward per episode", who), "episode return", xlabel="episode", legend=True)


def _plot_success_bar(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    n, k = ep["success"].size, int(ep["success"].sum())
    lo, hi = wilson_interval(k, n)
    rate = k / n
    fig = _new_figure(3.2, 4.0)
    ax = fig.add_subplot()
    ax.bar(["Success"], [rate], yerr=[[rate - lo], [hi - rate]], capsize=8, color=_COLORS["success"])
    return _finish(ax, path, _titled(f"{100 * rate:.1f} % of {n}", who), "success rate (Wilson 95 % CI)",
                   ylim=(0, 1))


def _plot_reward_vs_time(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    outcome = outcome_categories(ep)
    fig = _new_figure()
    ax = fig.add_subplot()
    for cat in _categories([outcome], reasons):
        mask = outcome == cat
        if mask.any():
            ax.scatter(ep["time"][mask], ep["reward"][mask], s=12, color=_COLORS[cat], label=LABELS[cat])
    return _finish(ax, path, _titled("reward against time to end", who), "episode return", xlabel=_TTE_LABEL,
                   legend=True)


def _plot_success_vs_time(ep: dict, path: Path, reasons: Sequence[str], who: str | None) -> Path:
    # Success rate per TTE bin: shows whether the policy succeeds early and fails late (timeouts) or otherwise.
    edges = np.histogram_bin_edges(ep["time"], bins=min(20, max(3, int(np.sqrt(ep["time"].size)))))
    which = np.clip(np.digitize(ep["time"], edges[1:-1]), 0, edges.size - 2)
    counts = np.bincount(which, minlength=edges.size - 1)
    wins = np.bincount(which, weights=ep["success"], minlength=edges.size - 1)
    rate = np.divide(wins, counts, out=np.zeros_like(wins), where=counts > 0)
    fig = _new_figure()
    ax = fig.add_subplot()
    bars = ax.bar(edges[:-1], rate, width=np.diff(edges), align="edge", color=_COLORS["success"], edgecolor="white")
    # each bin says how many episodes its rate stands for (an empty bin is "0", not a failed one)
    ax.bar_label(bars, labels=[f"n={c}" for c in counts.astype(int)], fontsize=7, padding=2)
    n, k = ep["success"].size, int(ep["success"].sum())
    title = "success against time to end"
    if k in (0, n):  # one outcome: the bars can only say 1 (or 0) everywhere; the title says so
        title += f"\n{'every' if k else 'no'} episode succeeded ({k} of {n})"
    return _finish(ax, path, _titled(title, who), "success rate in bin", xlabel=_TTE_LABEL, ylim=(0, 1.12))


_EPISODE_PLOTS = {"failure_reasons_bar.png": _plot_outcome_bar, "time_to_end_hist.png": _plot_tte_hist,
                  "time_to_end_ecdf.png": _plot_tte_ecdf, "reward_vs_episode.png": _plot_reward_vs_episode,
                  "overall_success_bar.png": _plot_success_bar, "reward_vs_time.png": _plot_reward_vs_time,
                  "success_vs_time.png": _plot_success_vs_time}
_REWARD_PLOTS = ("reward_vs_episode.png", "reward_vs_time.png")


def plot_episodes(episodes: Mapping[str, Sequence], out_dir: str | os.PathLike,
                  reasons: Sequence[str] = ALWAYS_REPORTED, who: str | None = None) -> list[Path]:
    """The single-run plots of docs/model/learning.md §12, as PNGs in ``out_dir``.

    Files: failure_reasons_bar.png (outcome counts, None shown as Success), time_to_end_hist.png,
    time_to_end_ecdf.png, reward_vs_episode.png, overall_success_bar.png (Wilson 95 % CI as error bar),
    reward_vs_time.png, success_vs_time.png. The reward plots only where the episodes have a reward.

    Args:
        episodes: an episode set (:func:`validate_episodes`).
        out_dir: folder for the PNGs.
        reasons: the failure reasons the controller's records can hold: a bar each in the outcome plot.
        who: the controller, named in every title (e.g. "planner", "greedy").

    Returns:
        The written paths, in that order.
    """
    ep = validate_episodes(episodes)
    out_dir = Path(out_dir)
    return [plot(ep, out_dir / name, reasons, who) for name, plot in _EPISODE_PLOTS.items()
            if "reward" in ep or name not in _REWARD_PLOTS]


def plot_comparison(runs: Mapping[str, Mapping[str, Sequence]], out_dir: str | os.PathLike,
                    reasons: Sequence[str] = ALWAYS_REPORTED) -> list[Path]:
    """Policy against baseline(s): one colour per run.

    Files: comparison_failure_reasons.png (grouped bars of outcome fractions), comparison_time_to_end_ecdf.png
    (TTE ECDFs overlaid), comparison_success_bar.png (success rates with Wilson 95 % CIs).

    Args:
        runs: run name -> episode set, e.g. ``{"policy": eps, "greedy": eps_greedy}``.
        out_dir: folder for the PNGs.
        reasons: the failure reasons the runs' records can hold: a group of bars each.

    Returns:
        The written paths, in that order.
    """
    if not runs:
        raise ValueError("plot_comparison: no runs given")
    eps = {str(name): validate_episodes(e) for name, e in runs.items()}
    out_dir = Path(out_dir)
    return [_plot_comparison_outcomes(eps, out_dir / "comparison_failure_reasons.png", reasons),
            _plot_comparison_ecdf(eps, out_dir / "comparison_time_to_end_ecdf.png"),
            _plot_comparison_success(eps, out_dir / "comparison_success_bar.png")]


def _plot_comparison_outcomes(eps: dict[str, dict], path: Path, reasons: Sequence[str]) -> Path:
    outcomes = {name: outcome_categories(ep) for name, ep in eps.items()}
    cats = _categories(list(outcomes.values()), reasons)
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
    for j, (name, ep) in enumerate(eps.items()):
        ax.step(*_ecdf(ep["time"]), where="post", color=f"C{j}", label=f"{name} (n = {ep['time'].size})")
        _mark_timeouts(ax, ep, color=f"C{j}", name=name)
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


# Learning-curve panels: (title, y label, y range, tag patterns). A tag goes to the first panel with a matching
# pattern; an interval's bounds (``*_ci_low`` / ``*_ci_high``) shade the band of their series instead of a
# panel of their own, and ``*_std`` / ``*_median`` / ``*_n`` are left out (the mean and its band say it).
_PANELS = (
    ("Training episodes: outcomes", "fraction of episodes", (0.0, 1.02),
     ("Episodes/success_rate", "Episodes/*_rate", "Training/Objective")),
    ("Evaluation: outcomes (95 % CI shaded)", "fraction of episodes", (0.0, 1.02),
     ("Evaluation/Success_rate", "Evaluation/*_rate")),
    ("Episode return", "return", None, ("Episodes/return", "Evaluation/Reward_mean")),
    ("Time to end", "steps", None, ("Sanitylogs/Episode_Steps", "Evaluation/Time_mean")),
    ("Evaluation: fire at the end", "fraction of the map's cells", None, ("Evaluation/Percent_Burned_mean",
                                                                          "Evaluation/Ever_Lit_mean")),
    ("Rewards and value targets (per step)", "value", None, ("Rewards/*",)),
    ("Losses", "loss", None, ("Training/*loss*", "*/*loss*")),
    ("PPO diagnostics", "value", None, ("Training/Approx_KL", "Training/Clip_Fraction",
                                        "Sanitylogs/Explained_Variance")),
    ("Learning rate", "learning rate", "from zero", ("Training/LR",)),
    # Training/log_std holds the policy's std (exp of its log std), as the trainer logs it
    ("Policy std (exp of log std)", "std of the action distribution", "from zero", ("Training/log_std",)),
    ("Speed", "env steps / s", None, ("Perf/*",)),
)
_DERIVED = ("_ci_low", "_ci_high", "_std", "_median", "_n")


def _band_tags(tag: str) -> tuple[str, str]:
    """The interval bounds of a series: ``X_mean`` -> ``X_ci_low/high``, ``Evaluation/Success_rate`` -> Success_ci."""
    base = tag.removesuffix("_mean").removesuffix("_rate")
    return f"{base}_ci_low", f"{base}_ci_high"


def _panel_of(tag: str) -> int | None:
    from fnmatch import fnmatchcase

    for i, (*_, patterns) in enumerate(_PANELS):
        if any(fnmatchcase(tag, p) for p in patterns):
            return i
    return None


def _pattern_rank(tag: str, panel: int | None) -> int:
    from fnmatch import fnmatchcase

    patterns = _PANELS[panel][3] if panel is not None else ()
    return next((i for i, p in enumerate(patterns) if fnmatchcase(tag, p)), len(patterns))


def _group_tags(tags) -> list[tuple[str, str, tuple | None, list[str]]]:
    """The non-empty panels in order, then "Other" (tags no panel claims), each with its series (in the order of
    the panel's patterns: success before the failure rates)."""
    groups: dict[int | None, list[str]] = {}
    named = {p for *_, patterns in _PANELS for p in patterns if "*" not in p}  # a series of its own, not derived
    for tag in tags:
        if tag.endswith(_DERIVED) and not tag.endswith("_rate") and tag not in named:  # Training/log_std is kept
            continue
        groups.setdefault(_panel_of(tag), []).append(tag)
    for panel, members in groups.items():
        members.sort(key=lambda t, p=panel: (_pattern_rank(t, p), t))
    out = [(*_PANELS[i][:3], groups[i]) for i in range(len(_PANELS)) if i in groups]
    if None in groups:
        out.append(("Other", "value", None, groups[None]))
    return out


def _series_label(tag: str) -> str:
    """``Evaluation/Reward_mean`` -> "eval: Reward", ``Episodes/success_rate`` -> "train: success_rate"."""
    group, _, name = tag.removesuffix("_mean").rpartition("/")
    special = {"Sanitylogs/Episode_Steps": "train: episode steps", "Evaluation/Percent_Burned_mean": "eval: burned out",
               "Evaluation/Ever_Lit_mean": "eval: ever lit", "Evaluation/Time_mean": "eval: time to end",
               "Training/LR": "learning rate", "Training/log_std": "policy std"}
    if tag in special:
        return special[tag]
    return {"Evaluation": f"eval: {name}", "Episodes": f"train: {name}"}.get(group, name or tag)


def plot_learning_curves(scalars: Mapping[str, Sequence[tuple[int, float]]], out_path: str | os.PathLike,
                         ncols: int = 4, title: str | None = None, note: str | None = None,
                         xlabel: str = "env steps") -> Path:
    """Learning curves as a few grouped panels (outcomes, return, time to end, fire, rewards, losses, PPO
    diagnostics, speed, other), each with labelled axes and a legend; confidence bounds are shaded bands.

    Args:
        scalars: tag -> [(step, value), ...] (e.g. from :func:`read_tensorboard_scalars`).
        out_path: the PNG to write.
        ncols: panels per row.
        title: the figure's title (say which run and controller).
        note: a line under the title, e.g. why training and evaluation differ by design.
        xlabel: what the step axis counts.

    Returns:
        ``out_path`` as a Path.
    """
    from matplotlib.ticker import EngFormatter, MaxNLocator

    if not scalars:
        raise ValueError("plot_learning_curves: no scalar tags given")
    panels = _group_tags(scalars)
    ncols = max(1, min(ncols, len(panels)))
    nrows = math.ceil(len(panels) / ncols)
    fig = _new_figure(4.4 * ncols, 3.0 * nrows + (0.5 if note else 0.0))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, (panel_title, ylabel, ylim, tags) in zip(axes, panels, strict=False):
        for j, tag in enumerate(tags):
            points = scalars[tag]
            if not len(points):
                continue
            steps, values = (np.asarray(v) for v in zip(*points, strict=True))
            color = f"C{j % 10}"
            ax.plot(steps, values, linewidth=1.2, color=color, label=_series_label(tag),
                    marker="." if len(points) < 30 else None)
            low, high = _band_tags(tag)
            if low in scalars and high in scalars and len(scalars[low]) == len(points) == len(scalars[high]):
                ax.fill_between(steps, [v for _, v in scalars[low]], [v for _, v in scalars[high]], color=color,
                                alpha=0.2, linewidth=0)
        ax.set_title(panel_title, fontsize=10)
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        if ylim == "from zero":  # a decay from 1e-3 to 0.999998e-3 is flat, not a steep fall
            top = max((max(v for _, v in scalars[t]) for t in tags if len(scalars[t])), default=1.0)
            ax.set_ylim(0.0, 1.15 * top if top > 0 else 1.0)
        elif ylim is not None:
            ax.set_ylim(*ylim)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=4))
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useOffset=False)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a panel whose only series is unlabelled needs no legend
            ax.legend(fontsize=6, loc="best")
    for ax in axes[len(panels):]:
        ax.set_axis_off()
    if title or note:
        lines = [title] if title else []
        lines += textwrap.wrap(note, width=int(15 * fig.get_figwidth())) if note else []
        fig.suptitle("\n".join(lines), fontsize=9)
    return _save(fig, Path(out_path))
