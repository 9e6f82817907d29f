"""The thesis's qualitative findings as checks on an experiment's figures, each judged with 95 % confidence
intervals (intervals.py): a check *holds* or *fails* only when the interval of its difference excludes equality;
otherwise it is *not resolved*, because the two figures tie within the noise or both rates sit at 100 % (or 0 %),
where these episodes cannot separate them. A finding is *confirmed* when every check holds, *contradicted* when a
check fails, *not resolved* otherwise, or *untested* while a condition it needs has no result.

A spec lists them under ``findings``::

    findings:
      - claim: interval 10 is the strongest planner at horizon 1200
        source: Table 5.11
        holds: [P2_i10.success > P2_i5.success, P2_i10.tte_median < P2_i5.tte_median]

Each check compares a condition's figure with another's or with a number. Figures: ``success``, ``collision``,
``boundary``, ``timeout``, ``burnout`` (mean over seeds, %), ``tte_median`` and ``tte_mean`` (over all evaluation
episodes of all seeds). ``>`` and ``>=`` are judged alike (as are ``<`` and ``<=``): a tie confirms neither. A
finding is judged once per set of weights (best, last, the training objective's), since they can disagree; a
scripted controller has one set of figures for all three.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from roshan.experiment.intervals import (
    Interval,
    MeanPart,
    bootstrap_medians,
    newcombe_interval,
    over_episodes,
    over_seeds,
    percentile_interval,
    t_interval,
    welch_interval,
)
from roshan.runs.report.stats import wilson_interval

FIGURES = ("success", "collision", "boundary", "timeout", "burnout", "tte_median", "tte_mean")
WEIGHTS = {"best": None, "last": "last", "objective": "objective"}  # label -> the result's key (None: the result)
TIE, SATURATED = "a tie within noise", "saturated"
_PLURAL = {"holds": "hold", "fails": "fail", "not resolved": "not resolved"}
_CHECK = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9_.-]*)\.(\w+)\s*(<=|>=|<|>)\s*(?:([A-Za-z0-9][A-Za-z0-9_.-]*)\.(\w+)"
                    r"|([-+]?\d+(?:\.\d+)?))\s*$")


@dataclass(frozen=True)
class Check:
    condition: str
    figure: str
    op: str
    other: str | None  # a condition, or None when comparing with ``number``
    other_figure: str | None
    number: float | None

    def __str__(self) -> str:
        rhs = f"{self.other}.{self.other_figure}" if self.other else f"{self.number:g}"
        return f"{self.condition}.{self.figure} {self.op} {rhs}"


@dataclass(frozen=True)
class Finding:
    claim: str
    source: str
    checks: tuple[Check, ...]


def parse_findings(raw, conditions: set[str], where: str) -> tuple[Finding, ...]:
    """The spec's ``findings`` list, each check naming known conditions and figures (else a SpecError-worthy
    ValueError naming the entry)."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise ValueError(f"{where}: findings: expected a list of {{claim, source, holds}}, got {raw!r}")
    out = []
    for i, item in enumerate(raw):
        at = f"{where}: findings[{i}]"
        if not isinstance(item, dict) or set(item) - {"claim", "source", "holds"} or "claim" not in item:
            raise ValueError(f"{at}: expected a mapping with claim, source and holds, got {item!r}")
        holds = item.get("holds") or []
        if not isinstance(holds, list) or not holds:
            raise ValueError(f"{at}.holds: expected a non-empty list of checks such as 'A.success > B.success'")
        out.append(Finding(str(item["claim"]), str(item.get("source", "")),
                           tuple(_check(h, conditions, f"{at}.holds") for h in holds)))
    return tuple(out)


def _check(text, conditions: set[str], at: str) -> Check:
    m = _CHECK.match(str(text))
    if not m:
        raise ValueError(f"{at}: {text!r} is not a check; expected 'CONDITION.FIGURE OP CONDITION.FIGURE' or "
                         "'CONDITION.FIGURE OP NUMBER' (OP one of <, <=, >, >=)")
    cond, fig, op, other, other_fig, number = m.groups()
    for c, f in ((cond, fig), (other, other_fig)):
        if c is None:
            continue
        if c not in conditions:
            raise ValueError(f"{at}: {text!r}: no condition {c!r} in this spec")
        if f not in FIGURES:
            raise ValueError(f"{at}: {text!r}: unknown figure {f!r}; expected one of {', '.join(FIGURES)}")
    return Check(cond, fig, op, other, other_fig, None if number is None else float(number))



def sample(results: list[dict], name: str, weights: str) -> list[np.ndarray] | None:
    """One condition's figure ``name`` with ``weights``, seed by seed: each seed's per-episode values (100 or 0 per
    episode for a rate, the TTE in steps); None if a seed lacks those weights or there is no episode."""
    key = WEIGHTS[weights]
    out = []
    for r in results:
        p = r if key is None or r.get("controller", "policy") != "policy" else r.get(key)
        if p is None:
            return None
        if name.startswith("tte_"):
            if "tte_episodes" not in p:
                return None
            if p["tte_episodes"]:
                out.append(np.asarray(p["tte_episodes"], dtype=float))
            continue
        n = int(r["episodes"])  # the other weights play the same episodes
        share = p["success_rate"] if name == "success" else p["failure_rates"].get(name, 0.0)
        k = int(round(share * n))
        out.append(np.r_[np.full(k, 100.0), np.zeros(n - k)])
    return out or None


def _counts(seeds: list[np.ndarray]) -> tuple[int, int]:
    x = np.concatenate(seeds)
    return int(np.count_nonzero(x)), x.size


def value(seeds: list[np.ndarray], name: str) -> float:
    """The figure: a rate's mean over seeds, the TTE's median or mean over all episodes of all seeds."""
    if name == "tte_median":
        return float(np.median(np.concatenate(seeds)))
    return float(np.mean(np.concatenate(seeds))) if name == "tte_mean" else float(np.mean([s.mean() for s in seeds]))


def estimate(seeds: list[np.ndarray], name: str) -> Interval:
    """The figure with its 95 % interval: the wider of the one over episodes (a rate's Wilson interval on the
    pooled episodes, a mean TTE's t interval) and the t interval over seeds (two seeds or more); a median TTE's
    two-level bootstrap."""
    v = value(seeds, name)
    if name == "tte_median":
        return percentile_interval(bootstrap_medians(seeds), v)
    if name == "tte_mean":
        out = Interval(v, *t_interval(over_episodes(seeds)))
    else:
        k, n = _counts(seeds)
        lo, hi = wilson_interval(k, n)
        out = Interval(v, 100 * lo, 100 * hi)
    if len(seeds) > 1:
        out = out.envelope(Interval(v, *t_interval(over_seeds(seeds))))
    return out if name == "tte_mean" else Interval(v, max(out.lo, 0.0), min(out.hi, 100.0))  # a rate stays a rate


def difference(a: list[np.ndarray], b: list[np.ndarray], name: str) -> Interval:
    """a's figure minus b's with its 95 % interval: the wider of the one over episodes (Newcombe's for rates,
    Welch's t for mean TTEs) and Welch's t over seeds (when a side has two seeds or more; a side with one seed
    enters with its spread over episodes); for median TTEs the two-level bootstrap of the difference."""
    d = value(a, name) - value(b, name)
    if name == "tte_median":
        return percentile_interval(bootstrap_medians(a, seed=0) - bootstrap_medians(b, seed=1), d)
    if name == "tte_mean":
        out = Interval(d, *welch_interval(over_episodes(a), over_episodes(b)))
    else:
        lo, hi = newcombe_interval(*_counts(a), *_counts(b))
        out = Interval(d, 100 * lo, 100 * hi)
    if len(a) > 1 or len(b) > 1:
        out = out.envelope(Interval(d, *welch_interval(over_seeds(a), over_seeds(b))))
    if name != "tte_mean":  # a difference of rates stays within what two rates can differ by
        out = Interval(d, max(out.lo, -100.0), min(out.hi, 100.0))
    return out


def _fmt(x: float, name: str, sign: str = "") -> str:
    return f"{x:{sign}.0f}" if name.startswith("tte_") else f"{x:{sign}.1f}"


@dataclass(frozen=True)
class Judged:
    """One check with its figures, the difference (left minus right) and the outcome: holds, fails or not
    resolved (``reason``: a tie within noise, or both rates at 100 % / 0 %)."""

    check: Check
    lhs: Interval
    rhs: Interval | None  # None: the check compares with a number
    diff: Interval
    outcome: str
    saturated_at: float | None = None  # not resolved with both rates at this bound (0 or 100 %); else a tie

    @property
    def reason(self) -> str:
        if self.outcome != "not resolved":
            return ""
        return TIE if self.saturated_at is None else f"{SATURATED}, both at {self.saturated_at:g} %"

    @property
    def statistic(self) -> str:
        name, d = self.check.figure, self.diff
        unit = "steps" if name.startswith("tte_") else "points"
        return (f"difference {_fmt(d.value, name, '+')} {unit}, 95 % CI [{_fmt(d.lo, name, '+')}, "
                f"{_fmt(d.hi, name, '+')}]")

    @property
    def margin(self) -> float:
        """How far the interval clears 0 on the claimed side, in its widths (negative: it does not)."""
        near = self.diff.lo if self.check.op.startswith(">") else -self.diff.hi
        return near / max(self.diff.hi - self.diff.lo, 1e-12)

    def __str__(self) -> str:
        c = self.check

        def fig(x: Interval, name: str) -> str:
            return f"{_fmt(x.value, name)} [{_fmt(x.lo, name)}, {_fmt(x.hi, name)}]"

        rhs = f"{c.number:g}" if self.rhs is None else f"{c.other}.{c.other_figure} {fig(self.rhs, c.other_figure)}"
        return (f"{c.condition}.{c.figure} {fig(self.lhs, c.figure)} {c.op} {rhs}: {self.statistic}: {self.outcome}"
                + (f", {self.reason}" if self.reason else ""))


def judge(check: Check, lhs: list[np.ndarray], rhs: list[np.ndarray] | None) -> Judged:
    """A check on its samples (``rhs`` None: against ``check.number``)."""
    a = estimate(lhs, check.figure)
    if rhs is None:
        b, diff = None, Interval(a.value - check.number, a.lo - check.number, a.hi - check.number)
    else:
        b, diff = estimate(rhs, check.other_figure), difference(lhs, rhs, check.figure)
    wants_more = check.op.startswith(">")
    if diff.lo > 0 or diff.hi < 0:
        return Judged(check, a, b, diff, "holds" if (diff.lo > 0) == wants_more else "fails")
    return Judged(check, a, b, diff, "not resolved", _saturation(check, lhs, rhs))


def _saturation(check: Check, lhs: list[np.ndarray], rhs: list[np.ndarray] | None) -> float | None:
    """100 (or 0) where both sides are rates pinned at that bound, else None."""
    if check.figure.startswith("tte_") or (check.other_figure or "").startswith("tte_"):
        return None
    sides = [100.0 * _counts(lhs)[0] / _counts(lhs)[1],
             check.number if rhs is None else 100.0 * _counts(rhs)[0] / _counts(rhs)[1]]
    for bound in (0.0, 100.0):
        if all(s == bound for s in sides):
            return bound
    return None


@dataclass(frozen=True)
class Verdict:
    """A finding judged with one set of weights."""

    label: str  # confirmed, contradicted, not resolved or untested
    why: str  # the check that decides it with its statistic and the count of checks by outcome, or what is missing
    checks: tuple[str, ...]  # every check with its figures
    reasons: str = ""  # not resolved: a tie within noise, saturated or both

    def __str__(self) -> str:
        return f"**{self.label}**" + (f" ({self.reasons})" if self.reasons else "") + f": {self.why}"


def verdict(finding: Finding, by_condition: dict[str, list[dict]], weights: str) -> Verdict:
    """``confirmed`` / ``contradicted`` / ``not resolved`` / ``untested`` with ``weights``, with the check that
    decides it: the first that fails, else the first tie within noise (else the first saturated one), else, for a
    confirmed finding, the check nearest to not holding."""
    judged, missing = [], []
    for c in finding.checks:
        lhs = sample(by_condition.get(c.condition, []), c.figure, weights)
        rhs = None if c.other is None else sample(by_condition.get(c.other, []), c.other_figure, weights)
        if lhs is None or (c.other is not None and rhs is None):
            missing += [n for n, v in ((c.condition, lhs), (c.other, rhs)) if n and v is None and n not in missing]
            continue
        judged.append(judge(c, lhs, rhs))
    shown = tuple(str(j) for j in judged)
    by = {o: [j for j in judged if j.outcome == o] for o in ("holds", "fails", "not resolved")}
    reasons = ""
    if by["fails"]:
        lead, label = by["fails"][0], "contradicted"
    elif missing:
        return Verdict("untested", f"no figures yet for {', '.join(missing)}", shown)
    elif by["not resolved"]:
        ties = [j for j in by["not resolved"] if j.reason == TIE]
        lead, label = (ties or by["not resolved"])[0], "not resolved"
        bounds = sorted({j.saturated_at for j in by["not resolved"] if j.saturated_at is not None}, reverse=True)
        saturated = f"{SATURATED}, both at {' % or '.join(f'{b:g}' for b in bounds)} %"
        reasons = "; ".join(([TIE] if ties else []) + ([saturated] if bounds else []))
    else:
        lead, label = min(judged, key=lambda j: j.margin), "confirmed"
    counts = ", ".join(f"{len(v)} {_PLURAL[o] if len(v) > 1 else o}" for o, v in by.items() if v)
    counts = f"1 check: {lead.outcome}" if len(judged) == 1 else f"{len(judged)} checks: {counts}"
    return Verdict(label, f"{lead.check}, {lead.statistic} ({counts})", shown, reasons)


def setting_line(name: str, results: list[dict], thesis: dict) -> str:
    """How hard our episodes are against the thesis's, read from a scripted controller (the same heuristic on
    both sides): its success and TTE beside the thesis's row, each difference with its 95 % interval (the thesis's
    row taken over as many episodes as ours)."""
    success, tte = sample(results, "success", "best"), sample(results, "tte_mean", "best")
    if success is None or tte is None:
        return ""
    k, n = _counts(success)
    s = estimate(success, "success")
    pooled = np.concatenate(tte)
    parts = [f"{name} succeeds in {s.value:.1f} % of {n} episodes (95 % CI [{s.lo:.1f}, {s.hi:.1f}])"]
    easier = []  # +1: ours easier on that figure, -1: harder, 0: within noise
    if "success" in thesis:
        ref = thesis["success"].mean
        lo, hi = newcombe_interval(k, n, int(round(ref * n / 100)), n)
        parts[-1] += (f" against the thesis's {ref:g} %: {s.value - ref:+.1f} points, 95 % CI "
                      f"[{100 * lo:+.1f}, {100 * hi:+.1f}]")
        easier.append(int(lo > 0) - int(hi < 0))
    parts.append(f"its TTE is {pooled.mean():.0f} ± {pooled.std():.0f} ({np.median(pooled):.0f}) steps")
    ref = thesis.get("tte")
    if ref is not None and ref.std is not None:
        ours = over_episodes(tte)
        lo, hi = welch_interval(ours, MeanPart(ref.mean, ref.std ** 2 / n, n - 1))
        parts[-1] += (f" against the thesis's {ref}: mean {ours.mean - ref.mean:+.0f} steps, 95 % CI "
                      f"[{lo:+.0f}, {hi:+.0f}]")
        easier.append(int(hi < 0) - int(lo > 0))
    if easier and all(e == 1 for e in easier):
        parts.append(f"our episodes are easier for {name} than the thesis's")
    elif easier and all(e == -1 for e in easier):
        parts.append(f"our episodes are harder for {name} than the thesis's")
    return "Our setting against the thesis's: " + "; ".join(parts) + "."


LEGEND = (
    "Each finding's checks judged with the best, last and training-objective weights (a scripted controller has one "
    "set of figures). Rates in % (mean over seeds), TTE in low-level steps over all episodes of all seeds, each "
    "figure with its 95 % confidence interval in brackets; each check gives the difference, left minus right, with "
    "its 95 % interval. A check *holds* or *fails* only when that interval excludes 0; otherwise it is *not "
    "resolved*: *a tie within noise*, or *saturated* where both rates sit at 100 % (or 0 %) and these episodes "
    "cannot separate them. `>` and `>=` are judged alike (a tie confirms neither), as are `<` and `<=`. A finding is "
    "*confirmed* when every check holds, *contradicted* when a check fails, *not resolved* otherwise; its line "
    "names the check that decides it (the first that fails, else the first tie, else for a confirmed finding the "
    "one nearest to not holding). Intervals are the wider of two: over episodes (a rate: Wilson's score interval on "
    "the pooled episodes, a difference of rates Newcombe's hybrid score interval; a mean TTE: Student's or Welch's "
    "t over the pooled episodes) and over seeds (Student's or Welch's t over the seeds' figures, Welch-Satterthwaite "
    "degrees of freedom; a condition with one seed, such as greedy, has no seed spread and enters with its spread "
    "over episodes). A median TTE and a difference of medians: a percentile bootstrap over seeds and, within each "
    "drawn seed, over its episodes (4,000 resamples, a fixed generator seed). Each check is judged at 95 % on its "
    "own, with no correction for the number of checks.")


def findings_markdown(findings: tuple[Finding, ...], by_condition: dict[str, list[dict]],
                      seeds: dict[str, tuple[int, int]], baselines: dict[str, dict] | None = None) -> str:
    """A section of the report: how hard our setting is against the thesis's (``baselines``: scripted conditions
    -> their thesis figures), then each finding, its verdict with every set of weights, the check that decides it
    with its statistic, and every check below; conditions still short of their planned seeds are named (a verdict
    on them may still change)."""
    if not findings:
        return ""
    out = ["", "## The thesis's findings", "", LEGEND, ""]
    lines = [setting_line(n, by_condition.get(n, []), ref) for n, ref in (baselines or {}).items()]
    out += [ln for ln in lines if ln] + ([""] if any(lines) else [])
    for f in findings:
        names = sorted({c.condition for c in f.checks} | {c.other for c in f.checks if c.other})
        short = [f"{n} {seeds[n][0]}/{seeds[n][1]}" for n in names if seeds[n][0] < seeds[n][1]]
        out.append(f"- **{f.claim}** ({f.source})" + (f"; seeds short: {', '.join(short)}" if short else ""))
        judged: dict[tuple, list[str]] = {}  # weights that reach the same verdict on the same figures share a line
        for w in WEIGHTS:
            judged.setdefault(verdict(f, by_condition, w), []).append(w)
        for v, weights in judged.items():
            out.append(f"  - {', '.join(weights)}: {v}")
            out += [f"    - {line}" for line in v.checks]
    return "\n".join(out) + "\n"
