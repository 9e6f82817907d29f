"""No command overwrites an existing output file without --replace: simulate --json / --gif / --frames, watch's
GIF (its default out/watch.gif too) and --screenshot, eval --save-buffer and maps crop -o refuse it with one line
naming the file and --replace, before any work, so a refused command leaves every file as it was; with --replace
they write it."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from roshan.cli import main

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "fly_simple"
OLD = b"an earlier result"
SIMULATE = ("simulate", "--map", "21x21_Field", "--envs", 1, "--steps", 2, "--every", 1, "--quiet")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def refused(res, path: Path) -> None:
    assert res.exit_code == 1 and "Traceback" not in res.output
    (line,) = res.output.strip().splitlines()
    assert str(path) in line and "--replace" in line
    assert path.read_bytes() == OLD


@pytest.fixture
def no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


@pytest.mark.slow
@pytest.mark.parametrize("existing", ["json", "gif"])
def test_simulate_refuses_an_existing_json_or_gif(tmp_path, existing):
    paths = {"json": tmp_path / "run.json", "gif": tmp_path / "fire.gif"}
    paths[existing].write_bytes(OLD)
    args = (*SIMULATE, "--json", paths["json"], "--gif", paths["gif"])
    refused(cli(*args), paths[existing])
    assert sorted(p.name for p in tmp_path.iterdir()) == [paths[existing].name]  # the other file was not written
    res = cli(*args, "--replace")
    assert res.exit_code == 0, res.output
    assert paths["json"].read_bytes()[:1] == b"{" and paths["gif"].read_bytes()[:6] == b"GIF89a"


@pytest.mark.slow
def test_watch_refuses_an_existing_default_gif(tmp_path, monkeypatch, no_display):
    monkeypatch.chdir(tmp_path)
    gif = Path("out/watch.gif")
    gif.parent.mkdir()
    gif.write_bytes(OLD)
    refused(cli("watch", MODEL, "--steps", 1, "--set", "map.name=15x15_Woods"), gif)
    res = cli("watch", MODEL, "--steps", 1, "--set", "map.name=15x15_Woods", "--replace")
    assert res.exit_code == 0, res.output
    assert gif.read_bytes()[:6] == b"GIF89a"


@pytest.mark.slow
def test_eval_save_buffer_refuses_an_existing_file(tmp_path):
    buf = tmp_path / "buffer.pt"
    buf.write_bytes(OLD)
    refused(cli("eval", MODEL, "--save-buffer", 8, buf, "--envs", 2, "--quiet"), buf)
    res = cli("eval", MODEL, "--save-buffer", 8, buf, "--envs", 2, "--quiet", "--replace")
    assert res.exit_code == 0, res.output
    assert buf.read_bytes() != OLD


def test_maps_crop_refuses_an_existing_output(tmp_path):
    from roshan.maps import bundled_map_path, load_map

    src = load_map("Borkenberge")
    a, _, c, _, e, f = src.transform
    bounds = (c, f + 20 * e, c + 20 * a, f)  # the top-left 20 x 20 cells
    out = tmp_path / "crop.tif"
    out.write_bytes(OLD)
    args = ("maps", "crop", bundled_map_path("Borkenberge"), "--bounds", *bounds, "-o", out)
    refused(cli(*args), out)
    res = cli(*args, "--replace")
    assert res.exit_code == 0, res.output
    assert load_map(out).classes.shape == (20, 20)


@pytest.mark.slow
def test_simulate_refuses_a_frames_folder_that_holds_frames(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    old = frames / "frame_0000000_t000000.0s.png"
    old.write_bytes(OLD)
    res = cli(*SIMULATE, "--frames", frames)
    assert res.exit_code == 1 and "Traceback" not in res.output
    (line,) = res.output.strip().splitlines()
    assert str(frames) in line and "--replace" in line
    assert old.read_bytes() == OLD and [p.name for p in frames.iterdir()] == [old.name]
    res = cli(*SIMULATE, "--frames", frames, "--replace")
    assert res.exit_code == 0, res.output
    assert sorted(p.name[:13] for p in frames.iterdir()) == ["frame_0000000", "frame_0000001", "frame_0000002"]
    assert old.read_bytes()[:4] == b"\x89PNG"  # overwritten by this run's frame


def test_watch_refuses_an_existing_screenshot(tmp_path, no_display):
    shot = tmp_path / "shot.png"
    shot.write_bytes(OLD)
    refused(cli("watch", MODEL, "--steps", 1, "--gif", tmp_path / "w.gif", "--screenshot", shot), shot)
    assert not (tmp_path / "w.gif").exists()  # refused before any work
