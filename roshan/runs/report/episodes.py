"""Episode sets of an evaluation (docs/model/agents.md §15): the columns, their validation into typed numpy arrays, and
each episode's outcome category (success or a failure reason).
"""

import math
from collections.abc import Mapping, Sequence

import numpy as np

from roshan.episode import EXTRA_COLUMNS, EXTRA_FIELDS, REASONS

# The reference's FailureReason names (docs/model/agents.md §2): the CSV uses them so files compare with the original's.
# "lost" is this project's (roshan.episode.REASONS): the original has no such failure.
CSV_REASON_NAMES = {"none": "None", "timeout": "Timeout", "boundary": "BoundaryExit", "burnout": "Burnout",
                    "collision": "Collision", "lost": "DronesLost"}
_REASON_ALIASES = {**{r: r for r in REASONS}, **{name.lower(): r for r, name in CSV_REASON_NAMES.items()}}
_REQUIRED = ("time", "success", "reason")
# reward is optional: a controller that earns none (the greedy heuristic) has no reward column, so no table row
# or plot pretends it scored 0. The fire at the end, as fractions of the map's cells: burned (burned out),
# burning (still burning) and lit (ever lit: burning, burned out or extinguished); extinguished is a cell count.
_OPTIONAL = ("reward", "burned", "burning", "lit", "extinguished", "seed", "episode", *EXTRA_FIELDS)
FRACTIONS = ("burned", "burning", "lit")
# Outcome categories in display order. "unspecified" is a failed episode whose reason is "none": the reference
# takes the reason of the last terminal agent, which can be None although another agent failed
# (docs/model/agents.md §2).
ALWAYS_REPORTED = ("collision", "boundary", "timeout")
IF_PRESENT = ("burnout", "lost", "unspecified")
LABELS = {"success": "Success", "collision": "Collision", "boundary": "Boundary", "timeout": "Timeout",
          "burnout": "Burnout", "lost": "Drones lost", "unspecified": "Unspecified"}


def validate_episodes(episodes: Mapping[str, Sequence]) -> dict[str, np.ndarray]:
    """Checks an episode set and returns it as typed numpy columns.

    Args:
        episodes: equal-length 1-D arrays or lists: ``time`` (int steps, TTE), ``success`` (0/1), ``reason`` (one
            of ``REASONS``; the reference names of ``CSV_REASON_NAMES`` are accepted too, any case), and
            optionally ``reward`` (float; absent for a controller that earns none), the fire at the end as
            fractions 0..1 of the map's cells ``burned`` (burned out), ``burning`` and ``lit`` (ever lit),
            ``extinguished`` (int cells), ``seed`` and ``episode`` (int ids), and the record's extra columns
            (:data:`roshan.episode.EXTRA_COLUMNS`: counts or floats >= 0). Other keys are ignored.

    Returns:
        A new dict with those of the keys above that were given: float64 ``reward`` and fractions, int64
        ``time``/``success``/``extinguished``/``seed``/``episode`` and counts, and ``reason`` as an array of the
        canonical names in ``REASONS``.

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
    if lengths["time"] == 0:
        raise ValueError("episodes: empty episode set (every array has length 0)")

    out = {"time": _int_column(cols, "time", minimum=0)}
    out["success"] = _int_column(cols, "success", minimum=0, maximum=1)
    out["reason"] = _reason_column(cols["reason"], out["success"])
    readers = {"reward": _float_column, **dict.fromkeys(FRACTIONS, _fraction_column),
               "extinguished": _count_column, "seed": _int_column, "episode": _int_column,
               **{c.name: _count_column if c.is_count else _nonnegative_column for c in EXTRA_COLUMNS}}
    out.update({key: read(cols, key) for key, read in readers.items() if key in cols})
    return out


def _fraction_column(cols: dict, key: str) -> np.ndarray:
    return _float_column(cols, key, minimum=0.0, maximum=1.0)


def _nonnegative_column(cols: dict, key: str) -> np.ndarray:
    return _float_column(cols, key, minimum=0.0)


def _count_column(cols: dict, key: str) -> np.ndarray:
    return _int_column(cols, key, minimum=0)


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


def outcome_categories(ep: dict[str, np.ndarray]) -> np.ndarray:
    """Per-episode outcome category: "success", a failure reason, or "unspecified" (failed with reason none)."""
    outcome = ep["reason"].copy()
    outcome[ep["success"] == 1] = "success"
    outcome[(ep["success"] == 0) & (ep["reason"] == "none")] = "unspecified"
    return outcome
