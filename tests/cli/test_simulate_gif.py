"""`roshan simulate --gif` without `--frames` leaves the GIF and nothing else (its frames are scratch files)."""

import pytest
from click.testing import CliRunner

from roshan.cli import main


@pytest.mark.slow
def test_gif_alone_leaves_no_frames_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may appear in the working directory either (imgui.ini, frames/)
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["simulate", "--map", "35x36_Woods", "--envs", "1", "--steps", "20", "--every",
                                    "10", "--fire-percentage", "0.1", "--gif", str(out / "fire.gif"), "--quiet"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert (out / "fire.gif").read_bytes()[:6] == b"GIF89a"
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == ["out", "out/fire.gif"]
