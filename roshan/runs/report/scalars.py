"""TensorBoard scalars of a run folder, read back for learning-curve plots."""

import logging
import os
from pathlib import Path


def read_tensorboard_scalars(tb_dir: str | os.PathLike) -> dict[str, list[tuple[int, float]]]:
    """All scalar series in the event files directly inside ``tb_dir`` (every point, no reservoir sampling).

    Returns:
        tag -> [(step, value), ...] in the order written, tags sorted.
    """
    tb_dir = Path(tb_dir)
    if not tb_dir.is_dir():
        raise FileNotFoundError(f"read_tensorboard_scalars: no such folder {tb_dir}")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    # size_guidance 0 keeps every event; the default keeps a 10,000-point reservoir sample per tag. A resumed
    # run's newer file restarts at its checkpoint's step; the accumulator then drops the older file's points
    # after it (work the resume discarded) and warns about it, which is expected here, hence the quiet logger.
    acc = EventAccumulator(str(tb_dir), size_guidance={"scalars": 0})
    tb_logger = logging.getLogger("tensorboard")
    level = tb_logger.level
    tb_logger.setLevel(logging.ERROR)
    try:
        acc.Reload()
    finally:
        tb_logger.setLevel(level)
    return {tag: [(int(e.step), float(e.value)) for e in acc.Scalars(tag)] for tag in sorted(acc.Tags()["scalars"])}
