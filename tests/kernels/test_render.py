"""Tests for roshan.kernels.render: colours, orientation, particles, wind arrow, backends agreeing, GIFs."""

import warnings

import numpy as np
import pytest
import taichi as ti
from PIL import Image

from roshan import runtime
from roshan.ggui import ggui_available
from roshan.io import write_gif
from roshan.kernels import particles as pt
from roshan.kernels import render
from roshan.kernels.fire import N_CONV, N_RAD
from roshan.kernels.render import FrameRenderer, cell_colours, default_cell_px
from roshan.maps import BURNED, BURNING, CLASSES, FLOODED
from roshan.runtime import init_taichi
from tests.conftest import sim_with_fires

RED = (255, 0, 0)
CELL_PX = 10  # small frames keep the tests fast
TOP_LEFT = (slice(1, 4), slice(2, 6))  # env 0: burning cells, rows 1-3 x columns 2-5 (asymmetric on purpose)
CENTRE = (slice(10, 26), slice(8, 24))  # env 1: a large fire, so that it emits particles
# Raster vs GGUI: the u8 image reaches GGUI's 8-bit RGBA target unchanged (a 0..255 ramp round-trips exactly on
# Mesa lavapipe, and this test measured a difference of 0). One level is allowed for drivers that round the
# unorm <-> float conversion differently; anything larger would be a real difference (orientation, blending).
GGUI_TOLERANCE = 1


@pytest.fixture(scope="module")
def sim():
    """2 envs of 35x36_Woods with no random fires: env 0 burns TOP_LEFT, env 1 burns CENTRE for 60 s."""
    s = sim_with_fires("35x36_Woods", [(0, *TOP_LEFT), (1, *CENTRE)], num_envs=2)
    s.step(600)  # 60 s: every burning cell has emitted a convection particle, none has burned out
    assert (s.state(0) == BURNING).sum() == 3 * 4  # every TOP_LEFT cell
    assert s.stats()["convection"][1] > 0
    return s


@pytest.fixture
def ggui():
    init_taichi("cpu")
    if not ggui_available():
        pytest.skip("GGUI cannot open an offscreen window here (no Vulkan driver: apt-get install mesa-vulkan-drivers)")


def _backend(request, name: str) -> str:
    if name == "ggui":
        request.getfixturevalue("ggui")
    return name


def test_default_cell_px_targets_720_px():
    assert default_cell_px(35, 36) == 20
    assert default_cell_px(481, 758) == 2  # Borkenberge: clamped at 2 px per cell
    assert default_cell_px(15, 15) == 24  # small maps: clamped at 24


def test_cell_colour_table_blends_burned_and_flooded_with_the_original_class():
    table = cell_colours()
    needle = np.array(CLASSES[2].colour, float)
    assert tuple(table[2, 2]) == CLASSES[2].colour
    assert tuple(table[BURNING, 2]) == RED
    np.testing.assert_array_equal(table[BURNED, 2], np.rint((20 * np.array([42, 42, 42]) + needle) / 21))
    np.testing.assert_array_equal(table[FLOODED, 2], np.rint((40 * np.array([77, 187, 230]) + needle) / 41))


def test_fire_palette_is_red_to_yellow_without_overflow():
    init_taichi("cpu")
    ys = np.array([0.0, 0.15, 0.3, 0.65, 1.0, 1.5], np.float32)
    out = ti.Vector.field(4, ti.f32, len(ys))

    @ti.kernel
    def palette(y: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for k in range(y.shape[0]):
            out[k] = render.fire_colour(y[k])

    palette(ys)
    rgba = out.to_numpy()
    np.testing.assert_allclose(rgba[0], [128, 0, 0, 0.6], atol=1e-4)
    np.testing.assert_allclose(rgba[1], [191.5, 50, 0, 0.8], atol=1e-4)
    np.testing.assert_allclose(rgba[2], [255, 100, 0, 1.0], atol=1e-4)
    np.testing.assert_allclose(rgba[3], [255, 191.5, 0, 0.8], atol=1e-4)
    np.testing.assert_allclose(rgba[4], [255, 255, 0, 1.0], atol=1e-4)
    assert rgba[5, 1] == 255  # clamped, where the reference's 8-bit green channel wraps around


def test_frame_is_not_blank_and_shows_fire_and_particles(sim):
    r = FrameRenderer(sim, env=1, cell_px=CELL_PX, backend="raster")
    frame = r.render()
    assert frame.shape == (sim.rows * CELL_PX, sim.cols * CELL_PX, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5
    assert np.all(frame == RED, axis=-1).sum() > 0
    r.particles = False
    assert np.any(r.render() != frame), "particles drew nothing"
    r.close()


@pytest.mark.parametrize("backend", ["raster", "ggui"])
def test_png_is_north_up(sim, backend, request, tmp_path):
    r = FrameRenderer(sim, env=0, cell_px=CELL_PX, particles=False, backend=_backend(request, backend))
    assert r.backend == backend
    path = r.save_png(tmp_path / "frame.png")
    png = np.asarray(Image.open(path).convert("RGB"))
    rows, cols = np.nonzero(np.all(png == RED, axis=-1))
    assert rows.size > 0
    # The red pixels are exactly the burning cells' pixels: no flip, no transpose, no offset.
    assert (rows.min(), rows.max() + 1) == (TOP_LEFT[0].start * CELL_PX, TOP_LEFT[0].stop * CELL_PX)
    assert (cols.min(), cols.max() + 1) == (TOP_LEFT[1].start * CELL_PX, TOP_LEFT[1].stop * CELL_PX)
    np.testing.assert_array_equal(png, r.render())
    if backend == "ggui":  # GGUI's own screenshot of its canvas is north-up too
        r.present().save_image(str(tmp_path / "window.png"))
        np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "window.png").convert("RGB")), png)
    r.close()


def test_raster_and_ggui_agree(sim, ggui):
    raster = FrameRenderer(sim, env=1, cell_px=CELL_PX, backend="raster").render()
    g = FrameRenderer(sim, env=1, cell_px=CELL_PX, backend="ggui")
    frame = g.render()
    g.close()
    assert frame.shape == raster.shape
    assert np.abs(frame.astype(int) - raster.astype(int)).max() <= GGUI_TOLERANCE


def test_particles_are_discs_and_radiation_rings(sim):
    """One convection and one radiation particle of intensity 1 at known cell centres of env 0."""
    saved = sim.counts.to_numpy(), sim.conv.to_numpy(), sim.rad.to_numpy()
    try:
        counts, conv, rad = (a.copy() for a in saved)
        counts[0, N_CONV], counts[0, N_RAD] = 1, 1
        conv[0, 0, [pt.P_X1, pt.P_X2, pt.P_Y]] = 205.0, 105.0, 1.0  # centre of cell (20, 10)
        rad[0, 0] = 0.0
        rad[0, 0, [pt.R_O1, pt.R_O2, pt.R_C, pt.R_Y]] = 255.0, 305.0, 1.0, 1.0  # centre of cell (25, 30), r = 0
        sim.counts.from_numpy(counts)
        sim.conv.from_numpy(conv)
        sim.rad.from_numpy(rad)
        frame = FrameRenderer(sim, env=0, cell_px=24, backend="raster", wind_arrow=False).render()
    finally:
        sim.counts.from_numpy(saved[0])
        sim.conv.from_numpy(saved[1])
        sim.rad.from_numpy(saved[2])
    r = 3 * 24 / 6  # radius at Y = 1: 3 r0
    disc_centre = frame[20 * 24 + 12, 10 * 24 + 12]
    assert tuple(disc_centre) == (255, 255, 0)  # yellow, opaque at Y = 1
    ring_centre = frame[25 * 24 + 12, 30 * 24 + 12]
    land_colour = cell_colours()[sim.state(0)[25, 30], sim.state(0)[25, 30]]
    np.testing.assert_array_equal(ring_centre, land_colour)  # hollow
    ring_edge = frame[25 * 24 + 12, 30 * 24 + 12 + int(r) - 1]
    assert tuple(ring_edge) == (255, 255, 128)  # the palette lightened halfway to white


@pytest.mark.parametrize(("wind", "direction"), [((10.0, 0.0), (1, 0)), ((0.0, -10.0), (0, -1)),
                                                 ((-6.0, 8.0), (-6, 8))])
def test_wind_arrow_points_downwind(sim, wind, direction):
    saved = sim.wind.to_numpy()
    try:
        w = saved.copy()
        w[0] = wind
        sim.wind.from_numpy(w)
        r = FrameRenderer(sim, env=0, cell_px=CELL_PX, particles=False, backend="raster")
        frame = r.render()
    finally:
        sim.wind.from_numpy(saved)
    cy, cx, radius = r._arrow
    rows, cols = np.nonzero(np.all(frame == 255, axis=-1))
    assert rows.size > 0 and np.all(np.hypot(rows + 0.5 - cy, cols + 0.5 - cx) <= radius)
    # Only the arrow head is wider than the shaft, and it must lie downwind of the disc centre.
    d = np.array(direction) / np.hypot(*direction)
    v1, v2 = rows + 0.5 - cy, cols + 0.5 - cx
    along, across = v1 * d[0] + v2 * d[1], np.abs(v2 * d[0] - v1 * d[1])
    wide = across > 2 * max(1.0, radius / 8)
    assert wide.sum() > 5 and np.all(along[wide] > 0)
    assert along.max() > 0.6 * radius and along.min() < -0.6 * radius  # a long shaft, centred


def test_calm_wind_shows_a_dot(sim):
    saved = sim.wind.to_numpy()
    try:
        sim.wind.from_numpy(np.zeros_like(saved))
        r = FrameRenderer(sim, env=0, cell_px=CELL_PX, particles=False, backend="raster")
        frame = r.render()
    finally:
        sim.wind.from_numpy(saved)
    cy, cx, radius = r._arrow
    rows, cols = np.nonzero(np.all(frame == 255, axis=-1))
    assert rows.size > 0 and np.all(np.hypot(rows + 0.5 - cy, cols + 0.5 - cx) <= max(1.0, radius / 8) + 1)


def test_overlay_draws_after_particles(sim):
    calls = []

    @ti.kernel
    def mark(img: ti.template()):
        img[5, 7] = ti.Vector([255, 0, 255], ti.u8)

    def overlay(img, cell_px):
        calls.append(cell_px)
        mark(img)

    r = FrameRenderer(sim, env=0, cell_px=CELL_PX, backend="raster")
    frame = r.render(overlay=overlay)
    assert calls == [CELL_PX]
    assert tuple(frame[5, 7]) == (255, 0, 255)


def test_auto_falls_back_to_raster_with_one_warning(sim, monkeypatch):
    def no_vulkan(*args):
        raise RuntimeError("Vulkan must be available for GGUI")

    monkeypatch.setattr(render, "acquire_window", no_vulkan)
    monkeypatch.setitem(runtime._per_process, "warned", set())  # warned once per process: as if none was given
    first = FrameRenderer(sim, env=0, cell_px=CELL_PX, particles=False, backend="auto")
    with pytest.warns(RuntimeWarning, match="mesa-vulkan-drivers"):
        frame = first.render()
    assert first.backend == "raster" and np.all(frame == RED, axis=-1).any()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        FrameRenderer(sim, env=0, cell_px=CELL_PX, particles=False, backend="auto").render()


def test_bad_arguments_are_rejected(sim):
    with pytest.raises(ValueError, match="backend"):
        FrameRenderer(sim, backend="opengl")
    with pytest.raises(ValueError, match="env"):
        FrameRenderer(sim, env=2, backend="raster")


def test_write_gif_keeps_every_frame(tmp_path):
    frames = [np.full((12, 16, 3), 40 * k, np.uint8) for k in range(3)]
    Image.fromarray(np.full((12, 16, 3), 200, np.uint8)).save(tmp_path / "last.png")
    out = write_gif([*frames, tmp_path / "last.png"], tmp_path / "anim" / "fire.gif", fps=5)
    with Image.open(out) as gif:
        assert gif.n_frames == 4
        assert gif.info["loop"] == 0
        assert gif.info["duration"] == 200


def test_ggui_frames_leave_no_imgui_ini_in_the_working_directory(sim, ggui, tmp_path, monkeypatch):
    """Dear ImGui saves ./imgui.ini when GGUI's window is destroyed; the user's folder must stay clean."""
    monkeypatch.chdir(tmp_path)
    r = FrameRenderer(sim, env=0, cell_px=CELL_PX, backend="ggui")
    r.render()
    r.present()
    r.close()  # the last user: the shared window is destroyed here
    assert not (tmp_path / "imgui.ini").exists()
    assert list(tmp_path.iterdir()) == []
