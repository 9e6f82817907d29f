"""Files the project writes whole: atomic writes (a reader never sees half a file) and GIFs of frames."""

import contextlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from PIL import Image


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, mode: int | None = None) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through: a temp file in the target folder, fsynced and renamed over
    ``path`` when the block ends, removed if it raises, so readers (and a killed run) never see half a file.
    ``mode`` sets its permissions (mkstemp creates 0600)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_file`), readable like any other output."""
    with atomic_file(path, mode=0o644) as f:
        f.write(data)
    return Path(path)


def write_gif(frames: Sequence[Path | str | np.ndarray], out: Path | str, fps: int = 10) -> Path:
    """Write frames (PNG paths or (H, W, 3) uint8 arrays) as a GIF that loops forever; returns ``out``."""
    if not frames:
        raise ValueError("write_gif needs at least one frame")
    if fps < 1:
        raise ValueError(f"fps must be >= 1, got {fps}")
    images = []
    for f in frames:
        if isinstance(f, np.ndarray):
            images.append(Image.fromarray(np.asarray(f, np.uint8)).convert("RGB"))
        else:
            with Image.open(f) as im:
                images.append(im.convert("RGB"))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # Pillow merges identical consecutive frames into one longer frame; the GIF's total duration is kept.
    images[0].save(out, save_all=True, append_images=images[1:], duration=max(1, round(1000 / fps)), loop=0)
    return out
