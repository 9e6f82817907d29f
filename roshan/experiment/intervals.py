"""Confidence intervals for the findings' figures and for the difference between two conditions' figures.

A condition's figure varies with its evaluation episodes and with its seeds (training runs); each interval here
covers one source, and the findings take the wider of the two (``Interval.envelope``). Methods: Wilson's score
interval for a rate over pooled episodes and Newcombe's hybrid score interval (his method 10) for the difference
of two rates; Student's t over seeds, or over episodes for a mean TTE, and Welch's t with the Welch-Satterthwaite
degrees of freedom for a difference of means; a two-level percentile bootstrap (seeds, then episodes within each
drawn seed) for a median and a difference of medians. A condition with one seed (a scripted controller) has no seed
spread: its spread over episodes stands in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from roshan.runs.report.stats import t_quantile, wilson_interval

CONFIDENCE = 0.95
BOOTSTRAP_REPS = 4000


@dataclass(frozen=True)
class Interval:
    """A figure (or a difference) with its confidence bounds."""

    value: float
    lo: float
    hi: float

    def envelope(self, other: Interval) -> Interval:
        """The smallest interval holding both (the value stays this one's)."""
        return Interval(self.value, min(self.lo, other.lo), max(self.hi, other.hi))


@dataclass(frozen=True)
class MeanPart:
    """A mean, the variance of that mean, and the degrees of freedom of that variance's estimate."""

    mean: float
    var: float
    df: float


def newcombe_interval(k1: int, n1: int, k2: int, n2: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Newcombe's hybrid score interval for p1 - p2 from two independent binomial samples (Newcombe 1998, Statistics
    in Medicine 17, method 10): the Wilson intervals of both rates combined by the square-and-add rule.

    Args:
        k1, n1: successes and trials of the first sample; k2, n2: of the second.

    Returns:
        (low, high) for k1 / n1 - k2 / n2, as fractions.
    """
    p1, p2 = k1 / n1, k2 / n2
    l1, u1 = wilson_interval(k1, n1, confidence)
    l2, u2 = wilson_interval(k2, n2, confidence)
    d = p1 - p2
    return d - math.hypot(p1 - l1, u2 - p2), d + math.hypot(u1 - p1, p2 - l2)


def welch_interval(a: MeanPart, b: MeanPart, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Welch's t interval for a.mean - b.mean, each mean with its own variance, degrees of freedom by
    Welch-Satterthwaite. A part with df < 1 (one value) adds its variance if it has one, and no degrees of freedom;
    two exact means (variance 0) give the point."""
    d = a.mean - b.mean
    var = a.var + b.var
    if var <= 0:
        return d, d
    parts = [p for p in (a, b) if p.df >= 1 and p.var > 0]
    df = var * var / sum(p.var * p.var / p.df for p in parts) if parts else 1.0
    half = t_quantile(0.5 + confidence / 2, df) * math.sqrt(var)
    return d - half, d + half


def t_interval(part: MeanPart, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Student's t interval of one mean (the point when its variance is 0 or unknown)."""
    if part.var <= 0 or part.df < 1:
        return part.mean, part.mean
    half = t_quantile(0.5 + confidence / 2, part.df) * math.sqrt(part.var)
    return part.mean - half, part.mean + half


def over_episodes(seeds: list[np.ndarray]) -> MeanPart:
    """The pooled episodes' mean with its variance (sample variance / episodes)."""
    x = np.concatenate(seeds)
    return MeanPart(float(x.mean()), float(x.var(ddof=1)) / x.size if x.size > 1 else 0.0, x.size - 1)


def over_seeds(seeds: list[np.ndarray]) -> MeanPart:
    """The mean of the seeds' means with its variance over seeds; one seed has no seed spread, so its spread over
    episodes stands in."""
    if len(seeds) < 2:
        return over_episodes(seeds)
    means = np.array([s.mean() for s in seeds])
    return MeanPart(float(means.mean()), float(means.var(ddof=1)) / means.size, means.size - 1)


def bootstrap_medians(seeds: list[np.ndarray], reps: int = BOOTSTRAP_REPS, seed: int = 0) -> np.ndarray:
    """Medians of ``reps`` two-level resamples: as many seeds as there are drawn with replacement, then each drawn
    seed's episodes drawn with replacement, all pooled. One seed: a bootstrap over its episodes. The generator is
    seeded, so the same data give the same medians on any machine.

    Args:
        seeds: each seed's per-episode values.

    Returns:
        (reps,) medians.
    """
    rng = np.random.default_rng(seed)
    lens = np.array([s.size for s in seeds])
    data = np.full((len(seeds), lens.max()), np.nan)
    for i, s in enumerate(seeds):
        data[i, :s.size] = s
    chosen = rng.integers(0, len(seeds), size=(reps, len(seeds)))
    n = lens[chosen][..., None]  # (reps, seeds, 1): the drawn seed's episode count
    idx = np.minimum((rng.random((reps, len(seeds), lens.max())) * n).astype(int), n - 1)
    values = data[chosen[..., None], idx]
    values[np.arange(lens.max()) >= n] = np.nan  # a drawn seed with fewer episodes than the longest fills less
    values = values.reshape(reps, -1)
    return np.median(values, axis=1) if (lens == lens[0]).all() else np.nanmedian(values, axis=1)


def percentile_interval(draws: np.ndarray, value: float, confidence: float = CONFIDENCE) -> Interval:
    lo, hi = np.percentile(draws, [50 * (1 - confidence), 50 * (1 + confidence)])
    return Interval(value, float(min(lo, value)), float(max(hi, value)))
