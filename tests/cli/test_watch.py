"""`roshan watch RUN`: the shipped FlyAgent flies in a shown GGUI window on a virtual display (Xvfb, started here),
and writes a GIF with a message where no display exists."""

import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from roshan.cli import main

MODEL = Path(__file__).resolve().parents[2] / "models" / "fly_simple"
SMALL = ["--set", "map.name=15x15_Woods", "--set", "ignition.fire_percentage=0.05"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def virtual_display(monkeypatch):
    """An Xvfb server on a free display number, named in DISPLAY for the test."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt-get install -y xvfb)")
    number = next(n for n in range(90, 200) if not Path(f"/tmp/.X{n}-lock").exists()
                  and not Path(f"/tmp/.X11-unix/X{n}").exists())
    server = subprocess.Popen(["Xvfb", f":{number}", "-screen", "0", "1024x900x24", "-nolisten", "tcp"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(100):
            if Path(f"/tmp/.X11-unix/X{number}").exists():
                break
            time.sleep(0.05)
        else:
            pytest.skip("Xvfb did not start")
        monkeypatch.setenv("DISPLAY", f":{number}")
        yield f":{number}"
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_watch_shows_the_run_in_a_window_on_a_display(virtual_display, tmp_path):
    shot = tmp_path / "watch.png"
    res = cli("watch", MODEL, "--steps", 3, "--fps", 100, "--screenshot", shot, "--gif", tmp_path / "no.gif", *SMALL)
    if "no window could open" in res.output:
        pytest.skip(f"GGUI cannot open a window on Xvfb here: {res.output.strip()}")
    assert res.exit_code == 0, res.output
    assert "showed 4 frames of fly_simple" in res.output  # the reset and 3 steps
    assert not (tmp_path / "no.gif").exists()
    image = np.asarray(Image.open(shot).convert("RGB"))
    assert image.shape[1] == 15 * 24 and image.shape[0] > 15 * 24  # the map with its caption and legend bands
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10, "the window showed a blank image"


@pytest.mark.slow
def test_watch_without_a_display_writes_a_gif_and_says_so(monkeypatch, tmp_path):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    gif = tmp_path / "out" / "watch.gif"
    res = cli("watch", MODEL, "--steps", 3, "--gif", gif, *SMALL)
    assert res.exit_code == 0, res.output
    assert "no display" in res.output and str(gif) in res.output
    with Image.open(gif) as g:
        assert g.n_frames == 4
    assert os.environ.get("DISPLAY") is None
