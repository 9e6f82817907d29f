"""Files the project writes whole: atomic writes (a reader never sees half a file), GIFs of frames, and the
one error a command gives when it cannot write its output (:class:`OutputError`)."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

if TYPE_CHECKING:
    import numpy as np


class OutputError(ValueError):
    """A file or folder a command must write cannot be written: "cannot write <what> to <path>: <reason>".
    A ValueError, so that every command reports it as one line, like a bad option."""

    def __init__(self, what: str, path: str | os.PathLike, reason: OSError | str):
        self.what, self.path = what, Path(path)
        self.reason = reason if isinstance(reason, str) else (reason.strerror or str(reason))
        super().__init__(f"cannot write {what} to {path}: {self.reason}")


@contextlib.contextmanager
def writing(what: str, path: str | os.PathLike) -> Iterator[None]:
    """Turn an OSError of the block (full disk, read-only folder, permission...) into an :class:`OutputError`
    that names ``what`` was being written and where."""
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(what, path, exc) from exc


def refuse_overwrite(path: str | os.PathLike | None, what: str, replace: bool) -> None:
    """Refuse (:class:`OutputError`) to overwrite the existing file ``path`` unless ``replace`` (a command's
    ``--replace``). Commands call it before any work, so that a refused command touches nothing."""
    if path is not None and not replace and Path(path).is_file():
        raise OutputError(what, path, "the file exists; give --replace to overwrite it, or name a new file")


def inside(root: str | os.PathLike, name: str, what: str, option: str = "--name") -> Path:
    """``root/name`` for a ``name`` a user gave (``--name``): one folder name, so that the folder stays inside
    ``root`` (``--name ../../escape`` used to write a whole run outside it). Raises :class:`OutputError`."""
    parts = Path(name).parts
    if not name or len(parts) != 1 or parts[0] in (".", "..") or "\0" in name or os.sep in name or "/" in name:
        raise OutputError(what, Path(root) / name, f"{option} {name!r} must be one folder name inside {root} (no "
                                                  "'/', '.' or '..')")
    return Path(root) / name


def prepare_output(path: str | os.PathLike, what: str, is_dir: bool = True) -> Path:
    """Make sure ``path`` (a folder, or with ``is_dir=False`` a file) can be written before the work that fills
    it starts: missing folders are created and a probe file is created and removed in the folder (permission
    bits say nothing to root and nothing about a read-only mount or a full disk). Raises :class:`OutputError`."""
    path = Path(path)
    folder = path if is_dir else path.parent
    if not is_dir and path.is_dir():
        raise OutputError(what, path, "it is a folder")
    if folder.exists() and not folder.is_dir():
        raise OutputError(what, path, f"{folder} is a file, not a folder")
    with writing(what, path):
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".roshan-probe-")
        os.close(fd)
        os.unlink(probe)
    return path


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
    import numpy as np  # here: the config layer imports this module, and `roshan --help` needs neither
    from PIL import Image

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


# ------------------------------------------------------------------------------------------------ progress


class LineStream:
    """A progress bar's output for a pipe or a log file: each refresh a line of its own. tqdm rewrites its one line
    with carriage returns, which a terminal shows as a moving bar and a log as a single line that grows for the whole
    run."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        line = text.replace("\r", "").replace("\x1b[A", "").rstrip("\n")
        if line.strip():
            self.stream.write(line + "\n")

    def flush(self) -> None:
        self.stream.flush()


LOG_INTERVAL_S = 30.0  # seconds between a bar's lines in a log: a line per refresh would flood it


def progress_bar(**kwargs):
    """A tqdm bar (keyword arguments as tqdm's) on standard error: a moving bar on a terminal; elsewhere a line
    every :data:`LOG_INTERVAL_S` seconds (and at the end), of a fixed width, so that a log stays readable."""
    from tqdm import tqdm

    if not sys.stderr.isatty():
        kwargs.update(file=LineStream(sys.stderr), dynamic_ncols=False, ncols=kwargs.get("ncols", 100),
                      position=None, mininterval=max(kwargs.get("mininterval", 0.0), LOG_INTERVAL_S))
    return tqdm(**kwargs)
