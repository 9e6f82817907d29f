"""Thesis-style plain-text tables of evaluation summaries: one run, or several side by side.

A table shows what was measured for its controller and nothing else: a failure row for each reason its records
can hold (the summary's ``failure_rates``), a reward row only where the controller earns a reward, and units
in every label (TTE in steps and seconds, the fire in % of the map's cells, extinguished cells as a count).
"""

from collections.abc import Mapping

from roshan.episode import EXTRA_COLUMNS
from roshan.runs.report.episodes import LABELS

# Fire rows: summary key -> (label, scale, unit, decimals).
FIRE_ROWS = {"burned": ("Burned out (% of cells)", 100.0, " %", 1),
             "burning": ("Burning at end (% of cells)", 100.0, " %", 1),
             "lit": ("Ever lit (% of cells)", 100.0, " %", 1),
             "extinguished": ("Extinguished (cells)", 1.0, "", 1)}


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _mean_std_median(stats: dict, decimals: int, scale: float = 1.0, unit: str = "") -> str:
    if stats["mean"] is None:
        return "-"
    m, s, med = (scale * stats[k] for k in ("mean", "std", "median"))
    return f"{m:.{decimals}f} ± {s:.{decimals}f} ({med:.{decimals}f}){unit}"


def _rate_label(reason: str) -> str:
    if reason == "lost":  # an episode fails as lost once every drone is down; the drones lost per episode are a row
        return "All drones lost rate"
    return f"{LABELS[reason]} rate"


def _row_values(summary: dict) -> dict[str, str]:
    """Row label -> formatted value, in display order."""
    lo, hi = summary["success_ci"]
    rows = {"Episodes": str(summary["episodes"]),
            "Success rate": f"{_pct(summary['success_rate'])} [{100 * lo:.1f}, {100 * hi:.1f}]"}
    for reason, rate in summary["failure_rates"].items():
        rows[_rate_label(reason)] = _pct(rate)
    for c in EXTRA_COLUMNS:  # the extra columns with a row, where counted
        if c.label and c.name in summary:
            rows[f"{c.label} (per episode)"] = _mean_std_median(summary[c.name], 2)
    rows["TTE (steps)"] = _mean_std_median(summary["tte"], 1)
    if "tte_seconds" in summary:
        rows["TTE (s)"] = _mean_std_median(summary["tte_seconds"], 1)
    rows["TTE of successes (steps)"] = _mean_std_median(summary["tte_success"], 1)
    if "reward" in summary:
        rows["Reward (episode return)"] = _mean_std_median(summary["reward"], 2)
    for key, (label, scale, unit, decimals) in FIRE_ROWS.items():
        if key in summary:
            rows[label] = _mean_std_median(summary[key], decimals, scale=scale, unit=unit)
    return rows


def _render(title: str, headers: list[str], columns: list[dict[str, str]]) -> str:
    labels: list[str] = []
    for col in columns:  # the first column's order, then rows only later columns have, after their predecessor
        for i, label in enumerate(col):
            if label not in labels:
                before = list(col)[i - 1] if i else None
                labels.insert(labels.index(before) + 1 if before in labels else len(labels), label)
    cells = [[col.get(label, "-") for col in columns] for label in labels]  # "-": not measured for that column
    label_w = max(len("Metric"), *(len(label) for label in labels))
    widths = [max(len(h), *(len(row[i]) for row in cells)) for i, h in enumerate(headers)]
    header = "  ".join([f"{'Metric':<{label_w}}", *(f"{h:>{w}}" for h, w in zip(headers, widths, strict=True))])
    rule = "-" * len(header)
    body = ["  ".join([f"{label:<{label_w}}", *(f"{c:>{w}}" for c, w in zip(row, widths, strict=True))])
            for label, row in zip(labels, cells, strict=True)]
    return "\n".join([title, rule, header, rule, *body, rule])


def format_table(summary: dict, title: str = "Evaluation") -> str:
    """A thesis-style plain-text table of one :func:`summarize` result.

    Rates are percentages (the success rate with its Wilson interval in brackets); TTE, reward and the fire read
    "mean ± std (median)".
    """
    return _render(title, ["Value"], [_row_values(summary)]) + _notes([summary])


def format_comparison(summaries: Mapping[str, dict], title: str = "Comparison") -> str:
    """Several :func:`summarize` results side by side, one column per name (e.g. ``{"policy": .., "greedy": ..}``).

    Rows as in :func:`format_table`. A failure reason one run's records can hold and another's cannot reads "-"
    in the other, as does a quantity not measured there (the greedy heuristic's reward); "Unspecified" and
    "Burnout" appear only where they occurred, so their absence in a column reads "0.0 %".
    """
    if not summaries:
        raise ValueError("format_comparison: no summaries given")
    columns = [_row_values(s) for s in summaries.values()]
    for col in columns:
        for reason in ("unspecified", "burnout"):
            if any(_rate_label(reason) in other for other in columns):
                col.setdefault(_rate_label(reason), _pct(0.0))
    return _render(title, [str(name) for name in summaries], columns) + _notes(summaries.values())


def _notes(summaries) -> str:
    """The summaries' notes (:mod:`roshan.runs.report.notes`), each once, as lines under the table."""
    notes = list(dict.fromkeys(n for s in summaries for n in s.get("notes", ())))
    return "".join(f"\nnote: {n}" for n in notes)
