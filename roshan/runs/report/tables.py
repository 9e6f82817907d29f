"""Thesis-style plain-text tables of evaluation summaries: one run, or several side by side."""

from collections.abc import Mapping

from roshan.runs.report.episodes import ALWAYS_REPORTED, IF_PRESENT, LABELS


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
        rows[f"{LABELS[reason]} rate"] = _pct(rate)
    rows["TTE"] = _mean_std_median(summary["tte"], 1)
    rows["TTE (successes)"] = _mean_std_median(summary["tte_success"], 1)
    rows["Reward"] = _mean_std_median(summary["reward"], 2)
    if "burned" in summary:
        rows["Burned"] = _mean_std_median(summary["burned"], 1, scale=100.0, unit=" %")
    return rows


_ROW_ORDER = ("Episodes", "Success rate", *(f"{LABELS[r]} rate" for r in ALWAYS_REPORTED + IF_PRESENT), "TTE",
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
