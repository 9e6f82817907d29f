"""Evaluation reporting (docs/model/agents.md §15, docs/model/learning.md §11-12): per-episode records -> summary
statistics, tables, CSV, JSON and plots. Pure numpy + matplotlib (an Agg canvas per figure, no pyplot state); no
Taichi, no torch.

One module per trade: ``episodes`` (columns and validation), ``stats`` (intervals and summaries), ``tables``,
``files`` (CSV and JSON), ``plots`` and ``scalars`` (TensorBoard reading). This package re-exports their public
functions so ``from roshan.runs import report; report.summarize(...)`` keeps working; code inside roshan imports
from the trade modules.
"""

from roshan.runs.report.episodes import CSV_REASON_NAMES, REASONS, validate_episodes
from roshan.runs.report.files import read_episodes_csv, write_episodes_csv, write_summary_json
from roshan.runs.report.plots import plot_comparison, plot_episodes, plot_learning_curves
from roshan.runs.report.scalars import read_tensorboard_scalars
from roshan.runs.report.stats import (
    describe,
    evaluation_scalars,
    failure_counts,
    summarize,
    t_quantile,
    wilson_interval,
)
from roshan.runs.report.tables import format_comparison, format_table

__all__ = ["CSV_REASON_NAMES", "REASONS", "describe", "evaluation_scalars", "failure_counts", "format_comparison",
           "format_table", "plot_comparison", "plot_episodes", "plot_learning_curves", "read_episodes_csv",
           "read_tensorboard_scalars", "summarize", "t_quantile", "validate_episodes", "wilson_interval",
           "write_episodes_csv", "write_summary_json"]
