"""One slice of ``roshan bench train`` (:mod:`roshan.tools.train_bench`), run as a script in a process of its own:
``python train_slice.py SPEC CONDITION UPDATES THREADS [KEY=VALUE ...]`` prints one JSON line. It imports only what
the checkout it runs against has had for long (the experiment spec, the Trainer, the runtime), so that an older
checkout's code can be timed with it (``PYTHONPATH`` names that checkout).
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import torch

from roshan.experiment.spec import load_spec
from roshan.runs.train import Trainer
from roshan.runtime import init_taichi


class Stopwatch:
    """Seconds spent inside a wrapped method, counted from :meth:`start`."""

    def __init__(self, owner, name: str):
        self.seconds, self.on = 0.0, False
        inner = getattr(owner, name)

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                if self.on:
                    self.seconds += time.perf_counter() - t0

        setattr(owner, name, timed)

    def start(self) -> None:
        self.seconds, self.on = 0.0, True


def time_slice(spec_path: str, condition: str, updates: int, seed: int = 0, sets: tuple[str, ...] = (),
               evaluate: bool = True) -> dict:
    """Train ``condition`` of the spec (plus ``sets``) for 1 + ``updates`` updates in a scratch folder and time the
    last ``updates`` of them, then (``evaluate``) one periodic evaluation."""
    cond = load_spec(spec_path).condition(condition)
    budget = (f"train.max_updates={updates + 1}", "train.max_minutes=0", "train.total_steps=0", "train.eval_every=0")
    cfg = cond.run_config(seed, (*sets, *budget))
    marks: list[tuple[float, int]] = []
    with tempfile.TemporaryDirectory() as folder:
        trainer = Trainer(cfg, Path(folder), progress_bar=False,
                          on_update=lambda m: marks.append((time.perf_counter(), m["env_steps"])))
        learner = trainer.learner
        update = Stopwatch(trainer.agent, "update")
        collector = getattr(learner, "collector", None)
        collect = None
        if collector is not None:
            collect = Stopwatch(collector, "collect" if hasattr(collector, "collect") else "step")

        def after_warmup(m, first=trainer.on_update):
            first(m)
            if len(marks) == 1:
                update.start()
                if collect is not None:
                    collect.start()

        trainer.on_update = after_warmup
        trainer.run()
        (t0, s0), (t1, s1) = marks[0], marks[-1]
        seconds = t1 - t0
        eval_seconds = 0.0
        if evaluate:
            trainer._periodic_eval()  # builds and compiles the evaluation env
            t = time.perf_counter()
            trainer._periodic_eval()
            eval_seconds = time.perf_counter() - t
    collect_s = collect.seconds if collect is not None else 0.0
    every = cond.run_config(seed).train.eval_every
    per_update = seconds / updates
    return {"condition": condition, "updates": updates, "env_steps": s1 - s0, "seconds": seconds,
            "steps_per_s": (s1 - s0) / seconds, "collect_s": collect_s, "update_s": update.seconds,
            "other_s": seconds - collect_s - update.seconds, "eval_s": eval_seconds,
            "eval_share": eval_seconds / (eval_seconds + every * per_update) if every else 0.0,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def _main(argv: list[str]) -> None:
    spec, condition, updates, threads, sets = argv[0], argv[1], int(argv[2]), int(argv[3]), tuple(argv[4:])
    if threads:
        torch.set_num_threads(threads)
    init_taichi("cpu", threads or None)
    row = time_slice(spec, condition, updates, sets=sets)
    row["isa"] = str(torch.backends.cpu.get_cpu_capability())
    print(json.dumps(row))


if __name__ == "__main__":
    _main(sys.argv[1:])
