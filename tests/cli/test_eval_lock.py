"""Two `roshan eval` into one --out folder at the same time: the second is refused, naming who writes there, and
changes nothing (not even with --replace), instead of both exiting 0 and the folder keeping one result."""

import fcntl
import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "fly_simple"
TINY = ("--episodes", 2, "--envs", 2, "--quiet")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def hold(folder: Path) -> int:
    """Lock ``folder`` the way a running evaluation does (flock of ``folder/.lock``); returns the fd to close."""
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.pwrite(fd, b"pid 4242 on elsewhere: roshan eval first\n", 0)
    return fd


@pytest.mark.slow
def test_a_second_evaluation_into_a_busy_folder_is_refused_and_writes_nothing(tmp_path):
    out, replaced = tmp_path / "out", tmp_path / "replaced"
    fd = hold(out)
    try:
        res = cli("eval", MODEL, *TINY, "--out", out)
        assert res.exit_code == 1 and "Traceback" not in res.output
        assert "pid 4242 on elsewhere" in res.output and str(out) in res.output
        assert sorted(p.name for p in out.iterdir()) == [".lock"]
    finally:
        os.close(fd)
    fd = hold(replaced)
    (replaced / "episodes.csv").write_text("the first evaluation's\n")
    try:  # --replace does not clear what the running evaluation writes
        res = cli("eval", MODEL, *TINY, "--out", replaced, "--replace")
        assert res.exit_code == 1 and "pid 4242 on elsewhere" in res.output
        assert (replaced / "episodes.csv").read_text() == "the first evaluation's\n"
        assert sorted(p.name for p in replaced.iterdir()) == [".lock", "episodes.csv"]
    finally:
        os.close(fd)
    res = cli("eval", MODEL, *TINY, "--out", out)  # the lock went with its holder
    assert res.exit_code == 0, res.output
    assert (out / "episodes.csv").is_file()
