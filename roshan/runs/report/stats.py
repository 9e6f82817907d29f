"""Statistics of an evaluation (docs/model/agents.md §15, docs/model/learning.md §11): Wilson and t intervals (no
scipy), per-episode descriptions, the summary of an episode set and its ``Evaluation/*`` TensorBoard scalars.
"""

import math
from collections.abc import Mapping, Sequence
from statistics import NormalDist

import numpy as np

from roshan.episode import EXTRA_COLUMNS, EXTRA_FIELDS
from roshan.runs.report.episodes import ALWAYS_REPORTED, IF_PRESENT, outcome_categories, validate_episodes


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


def failure_counts(episodes: Mapping[str, Sequence], reasons: Sequence[str] = ALWAYS_REPORTED) -> dict[str, int]:
    """Failed episodes per reason: every one of ``reasons`` (those the controller's records can hold), plus
    burnout and unspecified if any."""
    return _failure_counts(validate_episodes(episodes), reasons)


def _failure_counts(ep: dict[str, np.ndarray], reasons: Sequence[str] = ALWAYS_REPORTED) -> dict[str, int]:
    outcome = outcome_categories(ep)
    counts = {r: int(np.sum(outcome == r)) for r in reasons}
    counts.update({r: int(np.sum(outcome == r)) for r in IF_PRESENT if r not in counts and np.any(outcome == r)})
    return counts


def summarize(episodes: Mapping[str, Sequence], confidence: float = 0.95, reasons: Sequence[str] = ALWAYS_REPORTED,
              dt: float | None = None) -> dict:
    """Aggregates of an evaluation (docs/model/agents.md §15), JSON-able.

    Args:
        episodes: an episode set as described in :func:`validate_episodes`.
        confidence: coverage of the Wilson and t intervals.
        reasons: the failure reasons the controller's records can hold (an env's ``failure_reasons``); each gets
            a rate, 0 or not. Burnout and unspecified are added where they occur.
        dt: seconds per step, to give the TTE in seconds too.

    Returns:
        ``{"episodes": n, "success_rate", "success_ci": [lo, hi] (Wilson), "failure_rates": {reason: rate},
        "tte", "tte_success", ["tte_seconds"], ["reward"], ["burned", "burning", "lit", "extinguished"],
        [the record's extra columns, by name: where the episodes have them]}``;
        rates are fractions of all n episodes, each statistics entry is :func:`describe` (``tte_success`` over
        successful episodes only), fire fractions are fractions of the map's cells, extinguished a cell count.
        A column the episodes lack (the greedy heuristic's reward) has no entry.
    """
    ep = validate_episodes(episodes)
    n = len(ep["time"])
    is_success = ep["success"] == 1
    k = int(is_success.sum())
    lo, hi = wilson_interval(k, n, confidence)
    summary = {
        "episodes": n,
        "success_rate": k / n,
        "success_ci": [lo, hi],
        "failure_rates": {r: c / n for r, c in _failure_counts(ep, reasons).items()},
        "tte": describe(ep["time"], confidence),
        "tte_success": describe(ep["time"][is_success], confidence),
    }
    if dt is not None:
        summary["step_seconds"] = float(dt)
        summary["tte_seconds"] = describe(ep["time"] * float(dt), confidence)
    for key in ("reward", "burned", "burning", "lit", "extinguished", *EXTRA_FIELDS):
        if key in ep:
            summary[key] = describe(ep[key], confidence)
    return summary


def evaluation_scalars(summary: dict) -> dict[str, float]:
    """The ``Evaluation/*`` TensorBoard scalars of docs/model/learning.md §11 from a :func:`summarize` result, plus the
    rate of each failure reason (``Evaluation/<Reason>_rate``) and the record's extra columns the summary has
    (tagged by their ``header``, :data:`roshan.episode.EXTRA_COLUMNS`)."""
    scalars = {"Evaluation/Success_rate": summary["success_rate"],
               "Evaluation/Success_ci_low": summary["success_ci"][0],
               "Evaluation/Success_ci_high": summary["success_ci"][1], "Evaluation/Success_n": summary["episodes"]}
    for reason, rate in summary["failure_rates"].items():
        scalars[f"Evaluation/{reason.capitalize()}_rate"] = rate
    for key, name in (("reward", "Reward"), ("tte", "Time"), ("burned", "Percent_Burned"), ("lit", "Ever_Lit"),
                      *((c.name, c.header) for c in EXTRA_COLUMNS)):
        if key in summary:
            s = summary[key]
            scalars.update({f"Evaluation/{name}_mean": s["mean"], f"Evaluation/{name}_std": s["std"],
                            f"Evaluation/{name}_median": s["median"], f"Evaluation/{name}_ci_low": s["ci"][0],
                            f"Evaluation/{name}_ci_high": s["ci"][1]})
    return scalars
