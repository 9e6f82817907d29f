"""The training episodes of a run: the success window behind the training objective (the checkpoint rule of
docs/model/learning.md §9) and the episodes that ended since the last TensorBoard write."""

import collections
from dataclasses import dataclass, field

import numpy as np

from roshan.episode import EPISODE_FIELDS, FAILURES, REASONS


@dataclass
class EpisodeLog:
    """Training episodes: the success window behind the objective, and what ended since the last write."""

    window: int = 100
    episodes: int = 0
    recent: collections.deque = field(default_factory=collections.deque)
    pending: list = field(default_factory=list)  # rows of EPISODE_FIELDS since the last write

    def add(self, rows: np.ndarray) -> None:
        for row in rows:
            self.recent.append(float(row[0]))
            if len(self.recent) > self.window:
                self.recent.popleft()
        self.episodes += len(rows)
        self.pending.extend(rows.tolist())

    @property
    def objective(self) -> float:
        """Success rate over the last ``window`` training episodes; 0 until that many exist
        (docs/model/learning.md §9)."""
        return float(np.mean(self.recent)) if len(self.recent) >= self.window else 0.0

    @property
    def success_so_far(self) -> float:
        return float(np.mean(self.recent)) if self.recent else float("nan")

    def drain(self) -> dict[str, float]:
        """Means over the episodes since the last call (empty dict if none ended)."""
        if not self.pending:
            return {}
        rows = np.asarray(self.pending)
        self.pending = []
        reasons = rows[:, EPISODE_FIELDS.index("reason")].astype(int)
        out = {"success": rows[:, 0].mean(), "steps": rows[:, EPISODE_FIELDS.index("steps")].mean(),
               "return": rows[:, EPISODE_FIELDS.index("return")].mean(), "count": float(len(rows))}
        for name in FAILURES:
            out[f"{name}_rate"] = float((reasons == REASONS.index(name)).mean())
        return out

    def state_dict(self) -> dict:
        return {"window": self.window, "episodes": self.episodes, "recent": list(self.recent)}

    def load_state_dict(self, s: dict) -> None:
        self.window, self.episodes, self.recent = s["window"], s["episodes"], collections.deque(s["recent"])
