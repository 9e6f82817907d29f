"""An evaluation's files (docs/model/learning.md §12): the per-episode CSV (``evaluation_stats.csv``, in the reference's
column and reason names) read and written, and the summary as JSON; written atomically.
"""

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from roshan.episode import EXTRA_COLUMNS
from roshan.io import write_atomic
from roshan.runs.report.episodes import CSV_REASON_NAMES, validate_episodes

# Value columns: CSV name -> episode key, in file order (all but Time optional). Percent_Burned is the
# reference's name for the burned-out fraction (0..1, not a percentage); the other fire columns follow it, then
# the record's extra columns under their headers.
_VALUE_COLUMNS = (("Reward", "reward"), ("Time", "time"), ("Percent_Burned", "burned"),
                 ("Burning_Fraction", "burning"), ("Lit_Fraction", "lit"), ("Extinguished", "extinguished"),
                 *((c.header, c.name) for c in EXTRA_COLUMNS))


def write_episodes_csv(episodes: Mapping[str, Sequence], path: str | os.PathLike) -> Path:
    """Writes ``evaluation_stats.csv`` (docs/model/learning.md §12), atomically.

    Columns: ``Episode, [Reward], Time, [Percent_Burned, Burning_Fraction, Lit_Fraction, Extinguished],
    [the extra columns' headers], Success, Failure_Reason, [Seed]``, bracketed ones where the episodes have them
    (no Reward for a controller that earns none; the record's extra columns, :data:`roshan.episode.EXTRA_COLUMNS`,
    where the drones counted them).
    Episode is the ``episode`` id if given, else 1..n; Failure_Reason uses the reference names
    (``CSV_REASON_NAMES``, "None" for successes). Floats are written with ``repr`` so that
    :func:`read_episodes_csv` gives them back exactly.
    """
    ep = validate_episodes(episodes)
    n = len(ep["time"])
    ids = ep.get("episode", np.arange(1, n + 1))
    cols = [(name, key) for name, key in _VALUE_COLUMNS if key in ep]
    has_seed = "seed" in ep
    header = ["Episode", *(name for name, _ in cols), "Success", "Failure_Reason", *(["Seed"] if has_seed else [])]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for i in range(n):
        row = [int(ids[i])]
        for _, key in cols:
            v = ep[key][i]
            row.append(int(v) if ep[key].dtype.kind == "i" else repr(float(v)))
        row += [int(ep["success"][i]), CSV_REASON_NAMES[ep["reason"][i]]]
        if has_seed:
            row.append(int(ep["seed"][i]))
        writer.writerow(row)
    return write_atomic(path, buf.getvalue().encode())


_CSV_COLUMNS = {**dict(_VALUE_COLUMNS), "Success": "success", "Failure_Reason": "reason", "Seed": "seed",
                "Episode": "episode"}


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
    missing = [c for c in ("Time", "Success", "Failure_Reason") if c not in header]
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
    return write_atomic(path, (json.dumps(summary, indent=2, allow_nan=False) + "\n").encode())
