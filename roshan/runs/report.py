"""Evaluation reporting (agents.md 15, learning.md 11-12): per-episode records -> summary statistics, tables, CSV,
JSON and plots. Pure numpy + matplotlib (an Agg canvas per figure, no pyplot state); no Taichi, no torch.
"""

import contextlib
import csv
import io
import json
import logging
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from statistics import NormalDist

import numpy as np

REASONS = ("none", "timeout", "boundary", "burnout", "collision")
# The reference's FailureReason names (agents.md 2): the CSV uses them so files compare with the original's.
CSV_REASON_NAMES = {"none": "None", "timeout": "Timeout", "boundary": "BoundaryExit", "burnout": "Burnout",
                    "collision": "Collision"}
_REASON_ALIASES = {**{r: r for r in REASONS}, **{name.lower(): r for r, name in CSV_REASON_NAMES.items()}}
_REQUIRED = ("reward", "time", "success", "reason")
_OPTIONAL = ("burned", "seed", "episode")
# Outcome categories in display order. "unspecified" is a failed episode whose reason is "none": the reference
# takes the reason of the last terminal agent, which can be None although another agent failed (agents.md 2).
_ALWAYS_REPORTED = ("collision", "boundary", "timeout")
_IF_PRESENT = ("burnout", "unspecified")
_LABELS = {"success": "Success", "collision": "Collision", "boundary": "Boundary", "timeout": "Timeout",
           "burnout": "Burnout", "unspecified": "Unspecified"}
_COLORS = {"success": "tab:green", "collision": "tab:red", "boundary": "tab:orange", "timeout": "tab:gray",
           "burnout": "tab:brown", "unspecified": "tab:purple"}


# ---------------------------------------------------------------------------------------------- validation

def validate_episodes(episodes: Mapping[str, Sequence]) -> dict[str, np.ndarray]:
    """Checks an episode set and returns it as typed numpy columns.

    Args:
        episodes: equal-length 1-D arrays or lists: ``reward`` (float), ``time`` (int steps, TTE), ``success``
            (0/1), ``reason`` (one of ``REASONS``; the reference names of ``CSV_REASON_NAMES`` are accepted too,
            any case), and optionally ``burned`` (fraction 0..1), ``seed`` and ``episode`` (int ids). Other keys
            are ignored.

    Returns:
        A new dict with those of the keys above that were given: float64 ``reward``/``burned``, int64
        ``time``/``success``/``seed``/``episode``, and ``reason`` as an array of the canonical names in ``REASONS``.

    Raises:
        ValueError: naming the key, for a missing key, an array that is not 1-D, arrays of different
            lengths, an empty set, a non-numeric or out-of-range value, an unknown reason, or a success with a
            failure reason.
    """
    if not isinstance(episodes, Mapping):
        raise ValueError(f"episodes must be a dict of arrays, got {type(episodes).__name__}")
    missing = [k for k in _REQUIRED if k not in episodes]
    if missing:
        raise ValueError(f"episodes: missing key(s) {missing}; expected {list(_REQUIRED)} and optionally "
                         f"{list(_OPTIONAL)}")
    # Other keys (an evaluator's extra columns such as env index or extinguished cells) are not ours to check.
    cols = {k: np.asarray(v) for k, v in episodes.items() if k in _REQUIRED or k in _OPTIONAL}
    for key, col in cols.items():
        if col.ndim != 1:
            raise ValueError(f"episodes[{key!r}] must be 1-D, got shape {col.shape}")
    lengths = {k: len(c) for k, c in cols.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"episodes: arrays have different lengths {lengths}")
    if lengths["reward"] == 0:
        raise ValueError("episodes: empty episode set (every array has length 0)")

    out = {"reward": _float_column(cols, "reward"), "time": _int_column(cols, "time", minimum=0)}
    out["success"] = _int_column(cols, "success", minimum=0, maximum=1)
    out["reason"] = _reason_column(cols["reason"], out["success"])
    if "burned" in cols:
        out["burned"] = _float_column(cols, "burned", minimum=0.0, maximum=1.0)
    for key in ("seed", "episode"):
        if key in cols:
            out[key] = _int_column(cols, key)
    return out


def _float_column(cols: dict, key: str, minimum: float = -math.inf, maximum: float = math.inf) -> np.ndarray:
    try:
        col = cols[key].astype(np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"episodes[{key!r}] must be numeric: {err}") from None
    bad = np.flatnonzero(~np.isfinite(col) | (col < minimum) | (col > maximum))
    if bad.size:
        raise ValueError(f"episodes[{key!r}] must be finite and within [{minimum}, {maximum}]; "
                         f"episode index {int(bad[0])} has {cols[key][bad[0]]!r}")
    return col


def _int_column(cols: dict, key: str, minimum: float = -math.inf, maximum: float = math.inf) -> np.ndarray:
    col = _float_column(cols, key, minimum, maximum)
    bad = np.flatnonzero(col != np.round(col))
    if bad.size:
        raise ValueError(f"episodes[{key!r}] must hold integers; episode index {int(bad[0])} has {col[bad[0]]!r}")
    return col.astype(np.int64)


def _reason_column(col: np.ndarray, success: np.ndarray) -> np.ndarray:
    names = [str(r).strip().lower() for r in col]
    unknown = sorted({n for n in names if n not in _REASON_ALIASES})
    if unknown:
        raise ValueError(f"episodes['reason'] has unknown value(s) {unknown}; expected one of {list(REASONS)}")
    reasons = np.array([_REASON_ALIASES[n] for n in names], dtype=object)
    bad = np.flatnonzero((success == 1) & (reasons != "none"))
    if bad.size:
        raise ValueError(f"episodes['reason'] must be 'none' for a success; episode index {int(bad[0])} succeeded "
                         f"with reason {reasons[bad[0]]!r}")
    return reasons


def _outcomes(ep: dict[str, np.ndarray]) -> np.ndarray:
    """Per-episode outcome category: "success", a failure reason, or "unspecified" (failed with reason none)."""
    outcome = ep["reason"].copy()
    outcome[ep["success"] == 1] = "success"
    outcome[(ep["success"] == 0) & (ep["reason"] == "none")] = "unspecified"
    return outcome


# ---------------------------------------------------------------------------------------------- statistics

def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927; Agresti & Coull 1998).

    Unlike the normal (Wald) interval it stays inside [0, 1] and does not collapse at 0 or n successes.

    Args:
        successes: number of successes k, 0 <= k <= n.
        n: number of trials, n >= 1.
        confidence: two-sided coverage, e.g. 0.95.

    Returns:
        (low, high) bounds of the interval for k / n.
    """
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"wilson_interval needs n >= 1 and 0 <= successes <= n, got successes={successes}, n={n}")
    z = NormalDist().inv_cdf(0.5 + confidence / 2)
    p = successes / n
    denom = 1 + z * z / n
    center = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # The interval always contains p; clamping keeps rounding (about 1e-17 at k = 0 or n) from moving it past p.
    return min(p, max(0.0, center - half)), max(p, min(1.0, center + half))


def _betacf(a: float, b: float, x: float) -> float:
    # Continued fraction of the incomplete beta function, modified Lentz (Numerical Recipes 3rd ed., 6.4).
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1 + num * d
            d = 1 / (d if abs(d) > tiny else tiny)
            c = 1 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    # The fraction converges fast only on this side of the mean; use the symmetry I_x(a,b) = 1 - I_{1-x}(b,a).
    if x < (a + 1) / (a + b + 2):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def _t_upper_tail(t: float, df: float) -> float:
    """P(T > t) for t >= 0 under Student's t with df degrees of freedom."""
    return 0.5 * _betainc(df / 2, 0.5, df / (df + t * t))


def t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t distribution without scipy: bisection on the tail from the incomplete beta function.

    Args:
        p: probability in (0, 1), e.g. 0.975 for a two-sided 95 % interval.
        df: degrees of freedom, > 0.

    Returns:
        t such that P(T <= t) = p; within 1e-8 of scipy's ``t.ppf`` for df <= 1e4 (1e-6 up to df = 1e7).
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f"t_quantile needs 0 < p < 1, got {p}")
    if not df > 0:
        raise ValueError(f"t_quantile needs df > 0, got {df}")
    if p == 0.5:
        return 0.0
    tail = 1.0 - p if p > 0.5 else p  # solve on the upper tail: precise for p near 1, symmetric for p < 0.5
    lo, hi = 0.0, 1.0
    while _t_upper_tail(hi, df) > tail and hi < 1e300:
        lo, hi = hi, hi * 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _t_upper_tail(mid, df) > tail:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    t = 0.5 * (lo + hi)
    return t if p > 0.5 else -t


def describe(values: Sequence[float], confidence: float = 0.95) -> dict:
    """Mean, sample std, median and t-interval of the mean.

    Args:
        values: 1-D numbers.
        confidence: two-sided coverage of the interval.

    Returns:
        ``{"mean", "std", "median", "ci": [lo, hi]}`` as Python floats. std uses ddof=1 and is 0 for one value,
        whose interval collapses to the value (a t-interval needs df >= 1). Every entry is None for no values.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        return {"mean": None, "std": None, "median": None, "ci": [None, None]}
    mean = float(x.mean())
    std = float(x.std(ddof=1)) if x.size > 1 else 0.0
    half = t_quantile(0.5 + confidence / 2, x.size - 1) * std / math.sqrt(x.size) if x.size > 1 else 0.0
    return {"mean": mean, "std": std, "median": float(np.median(x)), "ci": [mean - half, mean + half]}


def failure_counts(episodes: Mapping[str, Sequence]) -> dict[str, int]:
    """Failed episodes per reason: collision, boundary, timeout always; burnout and unspecified only if any."""
    return _failure_counts(validate_episodes(episodes))


def _failure_counts(ep: dict[str, np.ndarray]) -> dict[str, int]:
    outcome = _outcomes(ep)
    counts = {r: int(np.sum(outcome == r)) for r in _ALWAYS_REPORTED}
    counts.update({r: int(np.sum(outcome == r)) for r in _IF_PRESENT if np.any(outcome == r)})
    return counts


def summarize(episodes: Mapping[str, Sequence], confidence: float = 0.95) -> dict:
    """Aggregates of an evaluation (agents.md 15), JSON-able.

    Args:
        episodes: an episode set as described in :func:`validate_episodes`.
        confidence: coverage of the Wilson and t intervals.

    Returns:
        ``{"episodes": n, "success_rate", "success_ci": [lo, hi] (Wilson), "failure_rates": {"collision",
        "boundary", "timeout", and "burnout" / "unspecified" only if any}, "tte", "tte_success", "reward",
        ["burned"]}``; rates are fractions of all n episodes, and each statistics entry is :func:`describe`
        (``tte_success`` over successful episodes only).
    """
    ep = validate_episodes(episodes)
    n = len(ep["reward"])
    is_success = ep["success"] == 1
    k = int(is_success.sum())
    lo, hi = wilson_interval(k, n, confidence)
    summary = {
        "episodes": n,
        "success_rate": k / n,
        "success_ci": [lo, hi],
        "failure_rates": {r: c / n for r, c in _failure_counts(ep).items()},
        "tte": describe(ep["time"], confidence),
        "tte_success": describe(ep["time"][is_success], confidence),
        "reward": describe(ep["reward"], confidence),
    }
    if "burned" in ep:
        summary["burned"] = describe(ep["burned"], confidence)
    return summary


def evaluation_scalars(summary: dict) -> dict[str, float]:
    """The ``Evaluation/*`` TensorBoard scalars of learning.md 11 from a :func:`summarize` result."""
    scalars = {"Evaluation/Success_rate": summary["success_rate"],
               "Evaluation/Success_ci_low": summary["success_ci"][0],
               "Evaluation/Success_ci_high": summary["success_ci"][1], "Evaluation/Success_n": summary["episodes"]}
    for key, name in (("reward", "Reward"), ("tte", "Time"), ("burned", "Percent_Burned")):
        if key in summary:
            s = summary[key]
            scalars.update({f"Evaluation/{name}_mean": s["mean"], f"Evaluation/{name}_std": s["std"],
                            f"Evaluation/{name}_median": s["median"], f"Evaluation/{name}_ci_low": s["ci"][0],
                            f"Evaluation/{name}_ci_high": s["ci"][1]})
    return scalars


# ---------------------------------------------------------------------------------------------- tables

def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _mean_std_median(stats: dict, decimals: int, scale: float = 1.0, unit: str = "") -> str:
    if stats["mean"] is None:
        return "-"
    m, s, med = (scale * stats[k] for k in ("mean", "std", "median"))
    return f"{m:.{decimals}f} ± {s:.{decimals}f} ({med:.{decimals}f}){unit}"


def _row_values(summary: dict) -> dict[str, str]:
    """Row label -> formatted value, in display order."""
    lo, hi = summary["success_ci"]
    rows = {"Episodes": str(summary["episodes"]),
            "Success rate": f"{_pct(summary['success_rate'])} [{100 * lo:.1f}, {100 * hi:.1f}]"}
    for reason, rate in summary["failure_rates"].items():
        rows[f"{_LABELS[reason]} rate"] = _pct(rate)
    rows["TTE"] = _mean_std_median(summary["tte"], 1)
    rows["TTE (successes)"] = _mean_std_median(summary["tte_success"], 1)
    rows["Reward"] = _mean_std_median(summary["reward"], 2)
    if "burned" in summary:
        rows["Burned"] = _mean_std_median(summary["burned"], 1, scale=100.0, unit=" %")
    return rows


_ROW_ORDER = ("Episodes", "Success rate", *(f"{_LABELS[r]} rate" for r in _ALWAYS_REPORTED + _IF_PRESENT), "TTE",
              "TTE (successes)", "Reward", "Burned")


def _render(title: str, headers: list[str], columns: list[dict[str, str]]) -> str:
    labels = [label for label in _ROW_ORDER if any(label in col for col in columns)]
    cells = []
    for label in labels:
        # A failure reason seen in only some runs did not occur in the others: 0 %, not "missing".
        missing = _pct(0.0) if label.endswith(" rate") else "-"
        cells.append([col.get(label, missing) for col in columns])
    label_w = max(len("Metric"), *(len(label) for label in labels))
    widths = [max(len(h), *(len(row[i]) for row in cells)) for i, h in enumerate(headers)]
    header = "  ".join([f"{'Metric':<{label_w}}", *(f"{h:>{w}}" for h, w in zip(headers, widths, strict=True))])
    rule = "-" * len(header)
    body = ["  ".join([f"{label:<{label_w}}", *(f"{c:>{w}}" for c, w in zip(row, widths, strict=True))])
            for label, row in zip(labels, cells, strict=True)]
    return "\n".join([title, rule, header, rule, *body, rule])


def format_table(summary: dict, title: str = "Evaluation") -> str:
    """A thesis-style plain-text table of one :func:`summarize` result.

    Rates are percentages (the success rate with its Wilson interval in brackets); TTE, reward and burned fraction
    read "mean ± std (median)".
    """
    return _render(title, ["Value"], [_row_values(summary)])


def format_comparison(summaries: Mapping[str, dict], title: str = "Comparison") -> str:
    """Several :func:`summarize` results side by side, one column per name (e.g. ``{"policy": .., "greedy": ..}``).

    Rows as in :func:`format_table`; a row missing from one summary reads "0.0 %" for a failure rate (the reason
    did not occur) and "-" otherwise.
    """
    if not summaries:
        raise ValueError("format_comparison: no summaries given")
    return _render(title, [str(name) for name in summaries], [_row_values(s) for s in summaries.values()])


# ---------------------------------------------------------------------------------------------- files

def _write_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Writes a temp file in the target folder, then renames it over ``path``: readers never see a partial file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results should be as readable as any other output
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return path


def write_episodes_csv(episodes: Mapping[str, Sequence], path: str | os.PathLike) -> Path:
    """Writes ``evaluation_stats.csv`` (learning.md 12), atomically.

    Columns: ``Episode, Reward, Time, [Percent_Burned], Success, Failure_Reason, [Seed]``. Episode is the
    ``episode`` id if given, else 1..n; Failure_Reason uses the reference names (``CSV_REASON_NAMES``, "None" for
    successes). Floats are written with ``repr`` so that :func:`read_episodes_csv` gives them back exactly.
    """
    ep = validate_episodes(episodes)
    n = len(ep["reward"])
    ids = ep.get("episode", np.arange(1, n + 1))
    has_burned, has_seed = "burned" in ep, "seed" in ep
    header = ["Episode", "Reward", "Time", *(["Percent_Burned"] if has_burned else []), "Success", "Failure_Reason",
              *(["Seed"] if has_seed else [])]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for i in range(n):
        row = [int(ids[i]), repr(float(ep["reward"][i])), int(ep["time"][i])]
        if has_burned:
            row.append(repr(float(ep["burned"][i])))
        row += [int(ep["success"][i]), CSV_REASON_NAMES[ep["reason"][i]]]
        if has_seed:
            row.append(int(ep["seed"][i]))
        writer.writerow(row)
    return _write_atomic(path, buf.getvalue().encode())


_CSV_COLUMNS = {"Reward": "reward", "Time": "time", "Success": "success", "Failure_Reason": "reason",
                "Percent_Burned": "burned", "Seed": "seed", "Episode": "episode"}


def read_episodes_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Reads a file written by :func:`write_episodes_csv` (or the reference's) back into validated columns.

    Returns:
        As :func:`validate_episodes`; optional columns appear when the file has them, unknown columns are ignored.

    Raises:
        ValueError: naming the file and the missing column or bad value.
    """
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        header = reader.fieldnames or []
        rows = list(reader)
    missing = [c for c in ("Reward", "Time", "Success", "Failure_Reason") if c not in header]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}; found {header}")
    cols = {key: [row[col] for row in rows] for col, key in _CSV_COLUMNS.items() if col in header}
    # Python writers of the reference may spell the flag True/False.
    cols["success"] = [{"true": "1", "false": "0"}.get(s.strip().lower(), s) for s in cols["success"]]
    try:
        return validate_episodes(cols)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def write_summary_json(summary: dict, path: str | os.PathLike) -> Path:
    """Writes a :func:`summarize` result as indented JSON, atomically (NaN is refused: it is not JSON)."""
    return _write_atomic(path, (json.dumps(summary, indent=2, allow_nan=False) + "\n").encode())


# ---------------------------------------------------------------------------------------------- plots

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
    return _write_atomic(path, buf.getvalue())


def _ecdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points for ``ax.step(..., where="post")``; the leading 0 draws the jump at the smallest value."""
    x = np.sort(values)
    return np.concatenate([x[:1], x]), np.arange(x.size + 1) / x.size


def _categories(outcome_sets: Sequence[np.ndarray]) -> list[str]:
    """Success and the always-reported reasons, plus burnout / unspecified where any run has them."""
    present = set().union(*(set(o) for o in outcome_sets))
    return ["success", *_ALWAYS_REPORTED, *(r for r in _IF_PRESENT if r in present)]


def _plot_outcome_bar(ep: dict, path: Path) -> Path:
    outcome = _outcomes(ep)
    cats = _categories([outcome])
    counts = [int(np.sum(outcome == c)) for c in cats]
    fig = _new_figure()
    ax = fig.add_subplot()
    bars = ax.bar([_LABELS[c] for c in cats], counts, color=[_COLORS[c] for c in cats])
    ax.bar_label(bars)
    ax.set_ylabel("episodes")
    ax.set_title(f"Episode outcomes (n = {outcome.size})")
    return _save(fig, path)


def _plot_tte_hist(ep: dict, path: Path) -> Path:
    is_success = ep["success"] == 1
    bins = np.histogram_bin_edges(ep["time"], bins=min(30, max(5, int(np.sqrt(ep["time"].size)))))
    fig = _new_figure()
    ax = fig.add_subplot()
    ax.hist([ep["time"][is_success], ep["time"][~is_success]], bins=bins, stacked=True,
            color=[_COLORS["success"], _COLORS["collision"]], label=["Success", "Failure"])
    ax.set_xlabel("time to end (steps)")
    ax.set_ylabel("episodes")
    ax.legend()
    ax.set_title("Time to end")
    return _save(fig, path)


def _plot_tte_ecdf(ep: dict, path: Path) -> Path:
    is_success = ep["success"] == 1
    fig = _new_figure()
    ax = fig.add_subplot()
    for name, mask, color in (("all", np.ones_like(is_success), "black"), ("Success", is_success, _COLORS["success"]),
                              ("Failure", ~is_success, _COLORS["collision"])):
        if mask.any():
            ax.step(*_ecdf(ep["time"][mask]), where="post", color=color, label=f"{name} (n = {int(mask.sum())})")
    ax.set_xlabel("time to end (steps)")
    ax.set_ylabel("fraction of episodes")
    ax.set_ylim(0, 1.02)
    ax.legend()
    ax.set_title("Time to end, ECDF")
    return _save(fig, path)


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
    ax.set_xlabel("episode")
    ax.set_ylabel("episode reward")
    ax.legend()
    ax.set_title("Reward per episode")
    return _save(fig, path)


def _plot_success_bar(ep: dict, path: Path) -> Path:
    n, k = ep["success"].size, int(ep["success"].sum())
    lo, hi = wilson_interval(k, n)
    rate = k / n
    fig = _new_figure(3.2, 4.0)
    ax = fig.add_subplot()
    ax.bar(["Success"], [rate], yerr=[[rate - lo], [hi - rate]], capsize=8, color=_COLORS["success"])
    ax.set_ylim(0, 1)
    ax.set_ylabel("success rate (Wilson 95 % CI)")
    ax.set_title(f"{100 * rate:.1f} % of {n}")
    return _save(fig, path)


def _plot_reward_vs_time(ep: dict, path: Path) -> Path:
    outcome = _outcomes(ep)
    fig = _new_figure()
    ax = fig.add_subplot()
    for cat in _categories([outcome]):
        mask = outcome == cat
        if mask.any():
            ax.scatter(ep["time"][mask], ep["reward"][mask], s=12, color=_COLORS[cat], label=_LABELS[cat])
    ax.set_xlabel("time to end (steps)")
    ax.set_ylabel("episode reward")
    ax.legend()
    ax.set_title("Reward against time to end")
    return _save(fig, path)


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
    ax.set_ylim(0, 1)
    ax.set_xlabel("time to end (steps)")
    ax.set_ylabel("success rate in bin")
    ax.set_title("Success against time to end")
    return _save(fig, path)


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
    outcomes = {name: _outcomes(ep) for name, ep in eps.items()}
    cats = _categories(list(outcomes.values()))
    width = 0.8 / len(eps)
    fig = _new_figure(max(6.4, 0.6 * len(cats) * len(eps)), 4.0)
    ax = fig.add_subplot()
    for j, (name, outcome) in enumerate(outcomes.items()):
        ax.bar(np.arange(len(cats)) + (j - (len(eps) - 1) / 2) * width, [np.mean(outcome == c) for c in cats],
               width=width, label=name)
    ax.set_xticks(np.arange(len(cats)), [_LABELS[c] for c in cats])
    ax.set_ylabel("fraction of episodes")
    ax.set_ylim(0, 1)
    ax.legend()
    ax.set_title("Episode outcomes")
    return _save(fig, path)


def _plot_comparison_ecdf(eps: dict[str, dict], path: Path) -> Path:
    fig = _new_figure()
    ax = fig.add_subplot()
    for name, ep in eps.items():
        ax.step(*_ecdf(ep["time"]), where="post", label=f"{name} (n = {ep['time'].size})")
    ax.set_xlabel("time to end (steps)")
    ax.set_ylabel("fraction of episodes")
    ax.set_ylim(0, 1.02)
    ax.legend()
    ax.set_title("Time to end, ECDF")
    return _save(fig, path)


def _plot_comparison_success(eps: dict[str, dict], path: Path) -> Path:
    fig = _new_figure(max(3.2, 1.4 * len(eps)), 4.0)
    ax = fig.add_subplot()
    for j, ep in enumerate(eps.values()):
        n, k = ep["success"].size, int(ep["success"].sum())
        lo, hi = wilson_interval(k, n)
        ax.bar([j], [k / n], yerr=[[k / n - lo], [hi - k / n]], capsize=8, color=f"C{j}")
    ax.set_xticks(np.arange(len(eps)), list(eps))
    ax.set_ylim(0, 1)
    ax.set_ylabel("success rate (Wilson 95 % CI)")
    ax.set_title("Success rate")
    return _save(fig, path)


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


def read_tensorboard_scalars(tb_dir: str | os.PathLike) -> dict[str, list[tuple[int, float]]]:
    """All scalar series in the event files directly inside ``tb_dir`` (every point, no reservoir sampling).

    Returns:
        tag -> [(step, value), ...] in the order written, tags sorted.
    """
    tb_dir = Path(tb_dir)
    if not tb_dir.is_dir():
        raise FileNotFoundError(f"read_tensorboard_scalars: no such folder {tb_dir}")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    # size_guidance 0 keeps every event; the default keeps a 10,000-point reservoir sample per tag. A resumed
    # run's newer file restarts at its checkpoint's step; the accumulator then drops the older file's points
    # after it (work the resume discarded) and warns about it, which is expected here, hence the quiet logger.
    acc = EventAccumulator(str(tb_dir), size_guidance={"scalars": 0})
    tb_logger = logging.getLogger("tensorboard")
    level = tb_logger.level
    tb_logger.setLevel(logging.ERROR)
    try:
        acc.Reload()
    finally:
        tb_logger.setLevel(level)
    return {tag: [(int(e.step), float(e.value)) for e in acc.Scalars(tag)] for tag in sorted(acc.Tags()["scalars"])}
