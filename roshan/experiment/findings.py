"""The thesis's qualitative findings as checks on an experiment's figures, each with a verdict: confirmed,
contradicted, or untested (a condition it needs has no result yet). A finding whose failed checks are all ties
(both rows at 100 % success, say) is "contradicted, by ties only": the claimed order does not show, but no figure
goes the other way either, so these episodes cannot separate the rows.

A spec lists them under ``findings``::

    findings:
      - claim: interval 10 is the strongest planner at horizon 1200
        source: Table 5.11
        holds: [P2_i10.success > P2_i5.success, P2_i10.tte_median < P2_i5.tte_median]

Each check compares a condition's figure with another's or with a number. Figures: ``success``, ``collision``,
``boundary``, ``timeout``, ``burnout`` (mean over seeds, %), ``tte_median`` and ``tte_mean`` (over all evaluation
episodes of all seeds). A finding is judged once per set of weights (best, last, the training objective's), since
they can disagree; a scripted controller has one set of figures for all three.
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass

import numpy as np

FIGURES = ("success", "collision", "boundary", "timeout", "burnout", "tte_median", "tte_mean")
WEIGHTS = {"best": None, "last": "last", "objective": "objective"}  # label -> the result's key (None: the result)
_OPS = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}
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


def figure(results: list[dict], name: str, weights: str) -> float | None:
    """One condition's figure from its seeds' results with ``weights``; None if a seed lacks those weights."""
    key = WEIGHTS[weights]
    picked = [r if key is None or r.get("controller", "policy") != "policy" else r.get(key) for r in results]
    if not picked or any(p is None for p in picked):
        return None
    if name.startswith("tte_"):
        if any("tte_episodes" not in p for p in picked):
            return None
        tte = [t for p in picked for t in p["tte_episodes"]]
        if not tte:
            return None
        return float(np.median(tte) if name == "tte_median" else np.mean(tte))
    rates = [p["success_rate"] if name == "success" else p["failure_rates"].get(name, 0.0) for p in picked]
    return 100.0 * float(np.mean(rates))


def verdict(finding: Finding, by_condition: dict[str, list[dict]], weights: str) -> tuple[str, list[str]]:
    """``confirmed`` / ``contradicted`` / ``contradicted, by ties only`` / ``untested`` with ``weights``, and each
    check with its figures."""
    shown, outcomes, missing, reversed_ = [], [], [], False
    for c in finding.checks:
        lhs = figure(by_condition.get(c.condition, []), c.figure, weights)
        rhs = c.number if c.other is None else figure(by_condition.get(c.other, []), c.other_figure, weights)
        if lhs is None or rhs is None:
            outcomes.append(None)
            missing += [n for n, v in ((c.condition, lhs), (c.other, rhs)) if v is None and n not in missing]
            continue
        ok = _OPS[c.op](lhs, rhs)
        outcomes.append(ok)
        reversed_ |= not ok and lhs != rhs
        other = "" if c.other is None else f"{c.other}.{c.other_figure} "
        failed = " (fails)" if lhs != rhs else " (fails: equal)"
        shown.append(f"{c.condition}.{c.figure} {lhs:.1f} {c.op} {other}{rhs:.1f}" + ("" if ok else failed))
    if missing:
        shown.append(f"no figures yet for {', '.join(missing)}")
    if any(o is False for o in outcomes):
        return ("contradicted" if reversed_ else "contradicted, by ties only"), shown
    return ("untested" if missing else "confirmed"), shown


def findings_markdown(findings: tuple[Finding, ...], by_condition: dict[str, list[dict]],
                      seeds: dict[str, tuple[int, int]]) -> str:
    """A section of the report: each finding, its verdict with every set of weights, and the figures behind it;
    conditions still short of their planned seeds are named (a verdict on them may still change)."""
    if not findings:
        return ""
    out = ["", "## The thesis's findings", "",
           "Each finding's checks judged with the best, last and training-objective weights (a scripted controller "
           "has one set of figures). Rates are means over seeds in %, TTE in low-level steps over all episodes. "
           "*contradicted, by ties only*: every check that fails compares equal figures (both rows at 100 % "
           "success, say), so the claimed order does not show but none goes the other way either.", ""]
    for f in findings:
        names = sorted({c.condition for c in f.checks} | {c.other for c in f.checks if c.other})
        short = [f"{n} {seeds[n][0]}/{seeds[n][1]}" for n in names if seeds[n][0] < seeds[n][1]]
        out.append(f"- **{f.claim}** ({f.source})" + (f"; seeds short: {', '.join(short)}" if short else ""))
        judged: dict[tuple, list[str]] = {}  # weights that reach the same verdict on the same figures share a line
        for w in WEIGHTS:
            v, shown = verdict(f, by_condition, w)
            judged.setdefault((v, tuple(shown)), []).append(w)
        for (v, shown), weights in judged.items():
            out.append(f"  - {', '.join(weights)}: **{v}**: " + "; ".join(shown))
    return "\n".join(out) + "\n"
