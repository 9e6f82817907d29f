"""Frames of one FireSim env as north-up RGB images, drawn by Taichi kernels (docs/model/fire.md §13).

A frame is built in one ``u8`` image field, ``image[py, px]``, with pixel row 0 = grid row 0 (the northern
edge) and pixel column = grid column, ``cell_px`` pixels per cell:

1. ``_paint_cells``: every pixel takes its cell's colour from a (state, original class) table. Class ids
   show their class colour, BURNING is (255, 0, 0), BURNED blends (42, 42, 42) with the original class colour
   20:1 and FLOODED blends (77, 187, 230) with it 40:1. No texture noise. Cells that water put out this
   episode show one pale blue once their flood has drained (``EXTINGUISHED_COLOUR``); with a detected-fire map
   (``known_fires``) burning cells that no drone has seen are dimmed (``UNSEEN_FIRE_COLOUR``).
2. ``_splat_particles`` (``particles=True``): each live particle of the env is alpha-blended into its own
   bounding box of pixels, in pool order (serial loop, so overlapping particles always blend the same way).
   Radius grows linearly with intensity Y from ``r0 = cell_px / 6`` (Y = 0) to ``3 r0`` (Y = 1), never below
   ``MIN_RADIUS_PX`` so that every particle covers at least one pixel on small frames. Colour is the "fire"
   palette (``fire_colour``: dark red -> red for Y <= 0.3, red -> yellow above, green clamped at 255), alpha
   ``0.6 + 0.4 rel``. **Convection** particles are filled discs; **radiation** particles are rings (a third
   of the radius thick, at least one pixel) in the palette lightened halfway to white, drawn after the
   convection discs so they stay visible on top of them.
3. ``overlay`` (optional argument of :meth:`FrameRenderer.render`): a callable ``overlay(image, cell_px)``
   that may draw into the same field, e.g. drones. ``image`` is the ``ti.Vector.field(3, ti.u8, (H, W))``
   above (north-up, ``[py, px]``); a point at ``(x1, x2)`` metres lies at pixel
   ``(x1 / cell_size * cell_px, x2 / cell_size * cell_px)``. :func:`drone_overlay` is such a callable: the
   drones of one env of a :class:`~roshan.kernels.drones.DroneSim` as discs, view squares and goal crosses in
   one colour per drone id, and the groundstation cell as a white outline (:class:`DroneOverlay` also draws a
   second group, the planner's explorers, as white diamonds).
4. ``_draw_wind_arrow``: a white arrow on a dark disc in the top-right corner points where the wind blows
   (wind component 1 = south = down the image, component 2 = east = right). A calm wind shows a dot.

Backends only differ in how the finished field leaves Taichi:

- ``raster``: ``image.to_numpy()``, PNGs written with PIL. No Vulkan needed.
- ``ggui``: the field is copied, flipped, into a ``(W, H)`` field (GGUI indexes images as ``(x, y)`` with
  ``(0, 0)`` at the bottom-left) and set as the canvas image of an offscreen ``ti.ui.Window``; frames are
  read back with ``get_image_buffer_as_numpy``. The ``u8`` field reaches GGUI's 8-bit target unchanged, so both
  backends give identical pixels. PNGs are written with PIL from the rendered array on both backends (RGB, and
  faster than GGUI's RGBA ``window.save_image``).
- ``auto``: ``ggui`` if an offscreen window opens, else ``raster`` with one warning.

:class:`EnvZeroFrames` (the envs' ``render()``) adds a caption band above the map and a legend band below it
(:mod:`roshan.kernels.annotate`, PIL on the host).

The offscreen GGUI window is the process's one shared window of :mod:`roshan.ggui`: renderers of the same size
share it, and a renderer of another size replaces it.
"""

import math
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import taichi as ti
from PIL import Image

from roshan import runtime
from roshan.ggui import acquire_window, release_window
from roshan.kernels.annotate import LegendItem, annotate
from roshan.kernels.particles import P_X1, P_X2, P_Y, R_Y, radiation_position
from roshan.maps import BURNED, BURNING, CLASSES, FLOODED, class_histogram

BACKENDS = ("auto", "ggui", "raster")
TARGET_LONG_SIDE_PX = 720  # default frame size: the longer side of the map is about this many pixels
MIN_CELL_PX, MAX_CELL_PX = 2, 24
MIN_RADIUS_PX = 0.75  # > sqrt(2)/2: some pixel centre always lies inside the particle's disc
BURNED_WEIGHT, FLOODED_WEIGHT = 20, 40  # state colour : original class colour (docs/model/fire.md §13)
ARROW_BACKDROP = (21, 19, 51)  # the reference's background colour, behind the wind arrow
ARROW_BACKDROP_ALPHA = 0.65
# Burning cells that no drone has seen yet (frames with a detected-fire map): a dim, greyed red, so the fires the
# planner knows of (bright red) stand out from those it cannot know of.
UNSEEN_FIRE_COLOUR = (150, 75, 75)
# Cells that water put out show this pale blue for the rest of the episode (a flood returns them to their class
# colour, which would hide where the drones worked): one colour whatever the land below, as the legend shows it
# (a tint over the class colour gave a different blue on each class), lighter than Water (50, 90, 255).
EXTINGUISHED_COLOUR = (150, 165, 255)
NO_GGUI_HINT = ("GGUI/Vulkan is unavailable, so frames are rendered with the raster fallback (numpy/PIL). "
                "For GGUI install a Vulkan driver, e.g. `apt-get install -y mesa-vulkan-drivers` (Debian).")

Overlay = Callable[[object, int], None]
# No `from __future__ import annotations` here: Taichi reads the ti.f32 / ti.template() annotations at runtime.


def default_cell_px(rows: int, cols: int) -> int:
    """Pixels per cell so the longer side is about ``TARGET_LONG_SIDE_PX`` (between 2 and 24 px per cell)."""
    return int(min(MAX_CELL_PX, max(MIN_CELL_PX, round(TARGET_LONG_SIDE_PX / max(rows, cols)))))


def cell_colours() -> np.ndarray:
    """(K, K, 3) uint8 table, K = len(CLASSES): the colour of a cell in state ``s`` whose original class is ``k``.

    Plain states show their own colour; BURNED and FLOODED blend theirs with the original class colour.
    """
    base = np.array([c.colour for c in CLASSES], np.float64)
    table = np.repeat(base[:, None, :], len(CLASSES), axis=1)
    table[BURNED] = (BURNED_WEIGHT * base[BURNED] + base) / (BURNED_WEIGHT + 1)
    table[FLOODED] = (FLOODED_WEIGHT * base[FLOODED] + base) / (FLOODED_WEIGHT + 1)
    return np.rint(table).astype(np.uint8)


@ti.func
def fire_colour(y: ti.f32):
    """The "fire" palette of docs/model/fire.md §13 as (r, g, b, alpha), r/g/b in 0..255, alpha in 0.6..1.

    Y <= 0.3: dark red (128, 0, 0) -> (255, 100, 0); Y > 0.3: red -> yellow, green from 128 up to at most 255
    (the reference overflows its 8-bit green channel here; we clamp instead).
    """
    rgba = ti.Vector([0.0, 0.0, 0.0, 0.0])
    if y <= 0.3:
        rel = y / 0.3
        rgba = ti.Vector([128.0 + 127.0 * rel, 100.0 * rel, 0.0, 0.6 + 0.4 * rel])
    else:
        rel = ti.min((y - 0.3) / 0.7, 1.0)
        rgba = ti.Vector([255.0, ti.min(255.0, 128.0 + 127.0 * rel), 0.0, 0.6 + 0.4 * rel])
    return rgba


@ti.func
def blend(old, colour, alpha: ti.f32):
    """``alpha * colour + (1 - alpha) * old`` for a u8 pixel, rounded to nearest."""
    mixed = ti.cast(old, ti.f32) + alpha * (colour - ti.cast(old, ti.f32))
    return ti.cast(ti.min(ti.max(mixed + 0.5, 0.0), 255.0), ti.u8)


@ti.data_oriented
class FrameRenderer:
    """Renders env ``env`` of a :class:`~roshan.kernels.fire.FireSim` into north-up RGB frames.

    Args:
        sim: the simulator (read only; any object with FireSim's ``cells, land, counts, conv, rad`` fields,
            ``rows, cols, cell_size, num_envs`` and ``wind_vectors()``).
        env: which env to draw; may be changed between frames (``renderer.env = 3``).
        cell_px: pixels per cell; default :func:`default_cell_px`.
        particles: draw convection discs and radiation rings.
        backend: ``"auto"``, ``"ggui"`` or ``"raster"`` (see the module docstring). The GGUI window is opened
            at the first frame, or when :attr:`backend` is read.
        wind_arrow: draw the wind arrow in the top-right corner.
        known_fires: optional (E, rows, cols) field of the cells some drone has seen burning (nonzero), e.g.
            :attr:`roshan.kernels.explore.ExploreMaps.fire_map`: burning cells not on it are drawn dimmed
            (:data:`UNSEEN_FIRE_COLOUR`).
    """

    def __init__(self, sim, env: int = 0, cell_px: int | None = None, particles: bool = True,
                 backend: str = "auto", wind_arrow: bool = True, known_fires=None):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        self.sim = sim
        self.env = env
        self.cell_px = int(cell_px) if cell_px is not None else default_cell_px(sim.rows, sim.cols)
        if self.cell_px < 1:
            raise ValueError(f"cell_px must be >= 1, got {cell_px}")
        self.particles = particles
        self.wind_arrow = wind_arrow
        self.known_fires = known_fires
        self.has_known_fires = known_fires is not None  # (Taichi scope cannot test `is not None`)
        self._backend = backend
        self._window = None
        self.height, self.width = sim.rows * self.cell_px, sim.cols * self.cell_px
        self.px_per_m = self.cell_px / float(sim.cell_size)
        self.r0 = self.cell_px / 6.0
        self._arrow = _arrow_geometry(self.height, self.width)

        colours = cell_colours()
        self.colours = ti.Vector.field(3, ti.u8, colours.shape[:2])
        self.colours.from_numpy(colours)
        self.image = ti.Vector.field(3, ti.u8, (self.height, self.width))
        # GGUI's (x, y)-indexed copy; a 1x1 stub for raster renderers so every field exists from __init__ on.
        display_shape = (1, 1) if backend == "raster" else (self.width, self.height)
        self._display = ti.Vector.field(3, ti.u8, display_shape)

    # ------------------------------------------------------------------------------------------ public API

    @property
    def env(self) -> int:
        return self._env

    @env.setter
    def env(self, env: int) -> None:
        self._env = _env_index(env, self.sim.num_envs)

    @property
    def backend(self) -> str:
        """``"ggui"`` or ``"raster"``: the backend in use (resolving ``"auto"`` opens the window)."""
        if self._backend == "auto":
            self._resolve_auto()
        return self._backend

    @property
    def window(self):
        """The offscreen ``ti.ui.Window`` this renderer draws into, or ``None`` on the raster backend."""
        if self.backend == "ggui":
            try:
                self._window = acquire_window((self.width, self.height), self._window)
            except Exception as err:  # say what to do instead of Taichi's bare "Vulkan must be available"
                raise RuntimeError(f"backend='ggui': GGUI/Vulkan is unavailable ({err}). Install a Vulkan "
                                   "driver (`apt-get install -y mesa-vulkan-drivers` on Debian) or use "
                                   "backend='raster'.") from err
        return self._window

    def draw(self, overlay: Overlay | None = None) -> None:
        """Build the frame in :attr:`image` (cells, particles, ``overlay(image, cell_px)``, wind arrow)."""
        self._paint_cells(self.env)
        if self.particles:
            self._splat_particles(self.env)
        if overlay is not None:
            overlay(self.image, self.cell_px)
        if self.wind_arrow and self._arrow is not None:
            w1, w2 = (float(v) for v in self.sim.wind_vectors()[self.env])
            speed = math.hypot(w1, w2)
            d1, d2 = (w1 / speed, w2 / speed) if speed > 1e-6 else (0.0, 0.0)
            self._draw_wind_arrow(*self._arrow, d1, d2)

    def render(self, overlay: Overlay | None = None) -> np.ndarray:
        """The current frame as an (H, W, 3) uint8 array, north up (row 0 = grid row 0)."""
        if self.backend == "raster":
            self.draw(overlay)
            return self.image.to_numpy()
        buf = self.present(overlay).get_image_buffer_as_numpy()  # (W, H, 4) floats in 0..1, y = 0 at the bottom
        return np.ascontiguousarray(np.rint(buf[:, ::-1, :3] * 255.0).astype(np.uint8).transpose(1, 0, 2))

    def save_png(self, path, overlay: Overlay | None = None) -> Path:
        """Render a frame and write it as an RGB PNG (with PIL on both backends); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(self.render(overlay)).save(path)
        return path

    def present(self, overlay: Overlay | None = None):
        """GGUI only: draw the frame onto the window's canvas and return the window.

        The next ``window.get_image_buffer_as_numpy()`` or ``window.save_image(path)`` consumes the frame (a
        second read without a new ``present`` comes back black).
        """
        if self.backend != "ggui":
            raise RuntimeError("present() needs the ggui backend; this renderer uses raster")
        self.draw(overlay)
        self._flip_to_display()
        window = self.window
        window.get_canvas().set_image(self._display)
        return window

    def close(self) -> None:
        """Give up this renderer's claim on the shared GGUI window (destroyed once no renderer uses it)."""
        if self._window is not None:
            release_window()
            self._window = None

    # ------------------------------------------------------------------------------------------ backends

    def _resolve_auto(self) -> None:
        try:
            self._window = acquire_window((self.width, self.height), None)
            self._backend = "ggui"
        except Exception:  # any failure to open an offscreen window means no usable GGUI here
            self._backend = "raster"
            if runtime.warn_once("no ggui"):
                warnings.warn(NO_GGUI_HINT, RuntimeWarning, stacklevel=_user_stacklevel())

    # ------------------------------------------------------------------------------------------ kernels

    @ti.kernel
    def _paint_cells(self, env: ti.i32):
        cp = self.cell_px
        ext = ti.Vector(EXTINGUISHED_COLOUR, ti.u8)
        for py, px in self.image:
            c = (py // cp) * self.sim.cols + px // cp
            state = self.sim.cell_state(env, c)
            colour = self.colours[state, self.sim.land[c]]
            if ti.static(self.has_known_fires):
                if state == BURNING and self.known_fires[env, py // cp, px // cp] == 0:
                    colour = ti.Vector(UNSEEN_FIRE_COLOUR, ti.u8)
            if state != BURNING and state != FLOODED and self.sim.was_extinguished(env, c) != 0:
                colour = ext
            self.image[py, px] = colour

    @ti.kernel
    def _splat_particles(self, env: ti.i32):
        # Serial loops: overlapping particles read-modify-write the same pixels, so a parallel loop would race
        # and make frames depend on thread timing.
        ti.loop_config(serialize=True)
        for k in range(self.sim.convection_count(env)):
            p = self.sim.conv[env, k]
            self._splat(p[P_X1], p[P_X2], p[P_Y], False)
        ti.loop_config(serialize=True)
        for k in range(self.sim.radiation_count(env)):
            p = self.sim.rad[env, k]
            x = radiation_position(p)
            self._splat(x[0], x[1], p[R_Y], True)

    @ti.func
    def _splat(self, x1: ti.f32, x2: ti.f32, y: ti.f32, ring: ti.template()):
        """Blend one particle (a disc, or a ring if ``ring``) into the pixels of its bounding box."""
        cy, cx = x1 * self.px_per_m, x2 * self.px_per_m
        y = ti.min(ti.max(y, 0.0), 1.0)
        r = ti.max(self.r0 * (1.0 + 2.0 * y), MIN_RADIUS_PX)
        rgba = fire_colour(y)
        colour = ti.Vector([rgba[0], rgba[1], rgba[2]])
        inner = 0.0
        if ti.static(ring):
            colour = 0.5 * (colour + 255.0)
            inner = ti.max(r - ti.max(1.0, r / 3.0), 0.0)
        row0 = ti.max(0, ti.cast(ti.floor(cy - r), ti.i32))
        row1 = ti.min(self.height, ti.cast(ti.ceil(cy + r), ti.i32))
        col0 = ti.max(0, ti.cast(ti.floor(cx - r), ti.i32))
        col1 = ti.min(self.width, ti.cast(ti.ceil(cx + r), ti.i32))
        for py, px in ti.ndrange((row0, row1), (col0, col1)):
            d2 = (py + 0.5 - cy) ** 2 + (px + 0.5 - cx) ** 2
            if inner * inner <= d2 <= r * r:
                self.image[py, px] = blend(self.image[py, px], colour, rgba[3])

    @ti.kernel
    def _draw_wind_arrow(self, cy: ti.f32, cx: ti.f32, radius: ti.f32, d1: ti.f32, d2: ti.f32):
        """Dark disc of ``radius`` px at (cy, cx) with a white arrow along (d1, d2), or a dot if (d1, d2) = 0."""
        half = 0.75 * radius  # arrow from -half to +half along the wind
        head = 0.5 * radius
        head_w = 0.45 * radius
        shaft_w = ti.max(1.0, radius / 8.0)
        backdrop = ti.Vector(ARROW_BACKDROP, ti.f32)
        white = ti.Vector([255, 255, 255], ti.u8)
        calm = d1 == 0.0 and d2 == 0.0
        for py, px in ti.ndrange((ti.cast(cy - radius, ti.i32), ti.cast(cy + radius, ti.i32) + 1),
                                 (ti.cast(cx - radius, ti.i32), ti.cast(cx + radius, ti.i32) + 1)):
            v1, v2 = py + 0.5 - cy, px + 0.5 - cx
            if v1 * v1 + v2 * v2 <= radius * radius:
                self.image[py, px] = blend(self.image[py, px], backdrop, ARROW_BACKDROP_ALPHA)
                along = v1 * d1 + v2 * d2
                across = ti.abs(v2 * d1 - v1 * d2)
                in_shaft = -half <= along <= half - head and across <= shaft_w
                in_head = half - head <= along <= half and across <= head_w * (half - along) / head
                if calm:
                    in_shaft = v1 * v1 + v2 * v2 <= (shaft_w + 1.0) ** 2
                if in_shaft or in_head:
                    self.image[py, px] = white

    @ti.kernel
    def _flip_to_display(self):
        for py, px in self.image:
            self._display[px, self.height - 1 - py] = self.image[py, px]


# ---------------------------------------------------------------------------------------------- drones

# Drone colours by id: four far-apart hues first (magenta, sky blue, navy, violet; planner runs have four drones),
# none of them a land-cover class colour nor in the fire palette (reds, oranges, yellows), nor white (the
# groundstation and the explorers).
DRONE_PALETTE = ((255, 0, 255), (0, 191, 255), (0, 0, 160), (148, 0, 211), (0, 128, 128), (255, 105, 180),
                 (65, 105, 225), (186, 85, 211))
DRONE_RIM = (0, 0, 0)  # one-pixel dark rim so discs, crosses and explorers stand out on any land colour
GROUNDSTATION_COLOUR = (255, 255, 255)
# A disc drawn on another drone's shrinks by NESTED_STEP of the radius per drone under it, to NESTED_MIN at least
NESTED_STEP, NESTED_MIN = 0.3, 0.25
EXPLORER_COLOUR = (255, 255, 255)  # explorers: white diamonds with a dark rim (planner drones are discs)
MIN_DRONE_RADIUS_PX = 3.0


def drone_colours(n: int) -> np.ndarray:
    """(n, 3) uint8 colours of drones 0..n-1: :data:`DRONE_PALETTE`, then golden-ratio hues of lighter shades."""
    import colorsys

    out = [DRONE_PALETTE[i] for i in range(min(n, len(DRONE_PALETTE)))]
    for i in range(len(out), n):
        # Beyond the fixed palette keep going round the colour wheel; the golden-ratio step spreads any count.
        hue = (0.55 + 0.618034 * (i - len(DRONE_PALETTE))) % 1.0
        out.append(tuple(round(255 * c) for c in colorsys.hsv_to_rgb(hue, 0.55 + 0.4 * (i % 2), 1.0)))
    return np.asarray(out, np.uint8).reshape(n, 3)


def mark_sizes(cell_px: int) -> dict[str, float]:
    """Pixel sizes of the drone marks at ``cell_px``: view-square line, goal-cross half thickness and arm,
    explorer diamond radius (shared by the kernels and the legend)."""
    line = max(2, cell_px // 8)
    return {"line": line, "cross_half": line, "arm": max(5.0, 0.45 * cell_px),
            "explorer": max(4.0, 0.4 * cell_px)}


@ti.func
def _fill_rect(image: ti.template(), r0, r1, c0, c1, colour):
    """Set the pixels of rows [r0, r1) x columns [c0, c1), clipped to the image."""
    for py, px in ti.ndrange((ti.max(r0, 0), ti.min(r1, image.shape[0])), (ti.max(c0, 0), ti.min(c1, image.shape[1]))):
        image[py, px] = colour


@ti.func
def _pixels_around(image: ti.template(), c, r):
    """The image's pixel rows y0..y1 and columns x0..x1 (half-open) of the square of half-side r around c."""
    return ti.Vector([ti.max(0, ti.floor(c[0] - r, ti.i32)), ti.min(image.shape[0], ti.ceil(c[0] + r, ti.i32)),
                      ti.max(0, ti.floor(c[1] - r, ti.i32)), ti.min(image.shape[1], ti.ceil(c[1] + r, ti.i32))])


@ti.func
def _outline(image: ti.template(), r0, r1, c0, c1, t, colour):
    """A ``t``-pixel outline just inside rows [r0, r1) x columns [c0, c1)."""
    _fill_rect(image, r0, ti.min(r0 + t, r1), c0, c1, colour)
    _fill_rect(image, ti.max(r1 - t, r0), r1, c0, c1, colour)
    _fill_rect(image, r0, r1, c0, ti.min(c0 + t, c1), colour)
    _fill_rect(image, r0, r1, ti.max(c1 - t, c0), c1, colour)


@ti.func
def _cross(image: ti.template(), gy, gx, h, lo, hi, colour):
    """A plus sign centred on pixel (gy, gx): bars ``2 h`` pixels thick from ``lo`` to ``hi`` (exclusive)."""
    _fill_rect(image, gy - h, gy + h, gx + lo, gx + hi, colour)
    _fill_rect(image, gy + lo, gy + hi, gx - h, gx + h, colour)


@ti.data_oriented
class DroneOverlay:
    """An ``overlay(image, cell_px)`` for :meth:`FrameRenderer.render` drawing the drones of env ``env``.

    Per drone, in its colour (:func:`drone_colours`, by id): the view square (a 2+ pixel outline, ``view_range``
    cells wide, centred on the drone), the goal (a cross with a dark rim) and the drone (a filled disc with a
    dark rim, radius ``max(3 px, drone_size / cell_size * cell_px, 0.3 cell_px)``); the groundstation cell gets
    a white outline. With ``explorers`` (a second DroneSim of the same envs, e.g. the planner's ExploreAgents)
    each explorer is a white diamond with a dark rim. Layers go groundstation, explorers, view squares, goals,
    discs, so drones are never hidden; within a layer drones are drawn in id order by a serial loop, so
    overlapping marks always come out the same, and a disc whose centre lies on an earlier drone's disc is drawn
    smaller (by :data:`NESTED_STEP` of the radius per drone under it), so that drones on one spot show as rings.
    Under each disc, one bar per gauge of the drone group (``DroneSim.gauges``, in their order), as wide as the
    disc, fills with the gauge's fraction in its colour. Positions are read
    from the DroneSims' fields at each call (north up like the cells: metres along rows go down the image). Sizes
    come from :func:`mark_sizes`.
    """

    def __init__(self, drones, env: int = 0, explorers=None):
        self.drones = drones
        self.explorers = explorers
        self.has_explorers = explorers is not None
        self.env = env
        self.palette = ti.Vector.field(3, ti.u8, drones.num_drones)
        self.palette.from_numpy(drone_colours(drones.num_drones))

    @property
    def env(self) -> int:
        return self._env

    @env.setter
    def env(self, env: int) -> None:
        self._env = _env_index(env, self.drones.num_envs)

    def __call__(self, image, cell_px: int) -> None:
        if tuple(image.shape) != (self.drones.rows * cell_px, self.drones.cols * cell_px):
            raise ValueError(f"image {tuple(image.shape)} does not match the drones' map at {cell_px} px per cell")
        size = mark_sizes(int(cell_px))
        self._draw(image, self.env, int(cell_px), int(size["line"]), int(size["cross_half"]), float(size["arm"]),
                   float(size["explorer"]))

    @ti.kernel
    def _draw(self, image: ti.template(), env: ti.i32, cell_px: ti.i32, line: ti.i32, h: ti.i32, arm: ti.f32,
              diamond: ti.f32):
        dr = self.drones
        px_per_m = ti.cast(cell_px, ti.f32) / dr.cell
        thick = ti.max(2, cell_px // 8)
        half_view = dr.half_view * cell_px
        radius = ti.max(MIN_DRONE_RADIUS_PX, dr.cfg.drone_size * px_per_m, 0.3 * cell_px)
        rim = ti.Vector(DRONE_RIM, ti.u8)
        for b in ti.static(range(dr.num_bases)):
            gs = dr.bases[env, b] * cell_px
            _outline(image, gs[0], gs[0] + cell_px, gs[1], gs[1] + cell_px, thick,
                     ti.Vector(GROUNDSTATION_COLOUR, ti.u8))
        if ti.static(self.has_explorers):
            ex = self.explorers
            white = ti.Vector(EXPLORER_COLOUR, ti.u8)
            ti.loop_config(serialize=True)
            for x in range(ex.num_drones):
                c = ex.pos[env, x] * px_per_m
                outer = diamond + 1.5
                b = _pixels_around(image, c, outer)
                for py, px in ti.ndrange((b[0], b[1]), (b[2], b[3])):
                    d1 = ti.abs(py + 0.5 - c[0]) + ti.abs(px + 0.5 - c[1])  # L1 distance: a diamond
                    if d1 <= diamond:
                        image[py, px] = white
                    elif d1 <= outer:
                        image[py, px] = rim
        ti.loop_config(serialize=True)
        for d in range(dr.num_drones):
            c = dr.pos[env, d] * px_per_m
            _outline(image, ti.round(c[0] - half_view, ti.i32), ti.round(c[0] + half_view, ti.i32),
                     ti.round(c[1] - half_view, ti.i32), ti.round(c[1] + half_view, ti.i32), line, self.palette[d])
        ti.loop_config(serialize=True)
        for d in range(dr.num_drones):
            g = dr.goal[env, d] * cell_px  # grid units -> pixels
            gy, gx = ti.floor(g[0], ti.i32), ti.floor(g[1], ti.i32)
            lo, hi = ti.floor(-arm, ti.i32), ti.ceil(arm, ti.i32) + 1
            _cross(image, gy, gx, h + 1, lo - 1, hi + 1, rim)
            _cross(image, gy, gx, h, lo, hi, self.palette[d])
        ti.loop_config(serialize=True)
        for d in range(dr.num_drones):
            c = dr.pos[env, d] * px_per_m
            # A drone whose centre lies on the disc of a drone drawn before it is drawn smaller, so the one under
            # it stays visible as a ring (drones without collisions can sit on one spot)
            under = 0
            for e in range(d):
                if (dr.pos[env, e] * px_per_m - c).norm() < radius:
                    under += 1
            r = radius * ti.max(NESTED_MIN, 1.0 - NESTED_STEP * under)
            outer = r + 1.0 if under == 0 else r  # a nested disc has no rim: it would cover the ring under it
            b = _pixels_around(image, c, outer)
            for py, px in ti.ndrange((b[0], b[1]), (b[2], b[3])):
                d2 = (py + 0.5 - c[0]) ** 2 + (px + 0.5 - c[1]) ** 2
                if d2 <= r * r:
                    image[py, px] = self.palette[d]
                elif d2 <= outer * outer:
                    image[py, px] = rim
        if ti.static(len(dr.gauges) > 0):
            self._draw_bars(image, env, px_per_m, radius, ti.max(2, cell_px // 10))

    @ti.func
    def _draw_bars(self, image: ti.template(), env, px_per_m, radius, height):
        """Per drone, rows under its disc, one per gauge of the drone group in its order: the gauge's fraction of
        a bar as wide as the disc, in its colour on a dark background."""
        dr = self.drones
        rim = ti.Vector(DRONE_RIM, ti.u8)
        ti.loop_config(serialize=True)
        for d in range(dr.num_drones):
            c = dr.pos[env, d] * px_per_m
            width = ti.cast(2.0 * radius + 2.0, ti.i32)
            c0 = ti.floor(c[1] - radius - 1.0, ti.i32)
            row = ti.floor(c[0] + radius + 2.0, ti.i32)
            for gauge in ti.static(dr.gauges):
                fill = gauge.fraction(env, d)
                _fill_rect(image, row, row + height, c0, c0 + width, rim)
                _fill_rect(image, row, row + height, c0, c0 + ti.round(fill * width, ti.i32),
                           ti.Vector(gauge.colour, ti.u8))
                row += height + 1


def drone_overlay(drones, env: int = 0) -> DroneOverlay:
    """The overlay drawing env ``env`` of ``drones`` (a :class:`~roshan.kernels.drones.DroneSim`); pass it as
    ``FrameRenderer(drones.fire).render(overlay=drone_overlay(drones))``. Build it once and reuse it: it holds
    a small Taichi field (the palette) and its kernel compiles on first use."""
    return DroneOverlay(drones, env)


def _env_index(env: int, num_envs: int) -> int:
    """``env`` as an int, checked to be one of the ``num_envs`` envs that a renderer or overlay may draw."""
    if not 0 <= env < num_envs:
        raise ValueError(f"env must be in 0..{num_envs - 1}, got {env}")
    return int(env)


class EnvZeroFrames:
    """``render()`` of the vector envs: env 0's land cover, fire and drones through the raster backend, built on
    the first call (rendering is optional, and the renderer compiles kernels).

    Args:
        drones: the drone group whose drones, view squares and goals are drawn (its FireSim is the map).
        explorers: the planner's explorer group, drawn as white diamonds (or None).
        known_fires: the detected-fire map (``ExploreMaps.fire_map``): burning cells no drone has seen are
            dimmed (or None: every burning cell is bright).
    """

    def __init__(self, drones, explorers=None, known_fires=None):
        self.drones = drones
        self.explorers = explorers
        self.known_fires = known_fires
        self._renderer: FrameRenderer | None = None
        self._overlay: DroneOverlay | None = None
        self._classes: tuple[int, ...] | None = None  # the map's land-cover classes, for the legend

    def render(self, caption: str | None = None) -> np.ndarray:
        """Env 0's map (H, W, 3) uint8; with ``caption``, a caption band above it and the legend below."""
        if self._renderer is None:
            self._renderer = FrameRenderer(self.drones.fire, backend="raster", known_fires=self.known_fires)
            self._overlay = DroneOverlay(self.drones, 0, explorers=self.explorers)
        frame = self._renderer.render(overlay=self._overlay)
        if caption is None:
            return frame
        return annotate(frame, caption, self.legend())

    def legend(self) -> list[LegendItem]:
        """What the marks and colours of this env's frames mean (:func:`frame_legend`)."""
        if self._classes is None:
            self._classes = tuple(class_histogram(self.drones.fire.land_map))
        return frame_legend(self.drones.num_drones, explorers=self.explorers is not None,
                            known_fires=self.known_fires is not None, classes=self._classes,
                            gauges=self.drones.gauges)

    def close(self) -> None:
        """Release the window claim but keep the renderer: its fields and kernels are reused when the env's
        simulators are (roshan.kernels.pool), instead of allocating new ones at every env's first render."""
        if self._renderer is not None:
            self._renderer.close()


BURNED_LABEL = "burned out"


def frame_legend(num_drones: int = 0, explorers: bool = False, known_fires: bool = False,
                 classes: tuple[int, ...] | list[int] = (), gauges: tuple = ()) -> list[LegendItem]:
    """The legend of a frame: the drones (``num_drones``, 0 for the fire alone; with their view, goal, the
    groundstation and the bar of each of their ``gauges``, ``DroneSim.gauges``), the planner's ``explorers``, the
    fire (seen and unseen with a ``known_fires`` map), the states water and fire leave (put out, flooded, burned
    out), fire particles, and each land-cover class of ``classes`` (the map's class ids) in its colour under its
    CLC+ name, so that a grey Sealed cell is not read as burned out."""
    colours = [tuple(int(v) for v in c) for c in drone_colours(num_drones)]
    items = [LegendItem("disc", c, f"drone {d}") for d, c in enumerate(colours[:8])]
    if len(colours) > 8:
        items.append(LegendItem("disc", colours[8], f"drones 8-{len(colours) - 1}"))
    if colours:
        items += [LegendItem("square", colours[0], "its view"), LegendItem("cross", colours[0], "its goal")]
    if explorers:
        items.append(LegendItem("diamond", EXPLORER_COLOUR, "explorer"))
    if colours:
        items.append(LegendItem("square", GROUNDSTATION_COLOUR, "groundstation"))
    if colours:
        items += [LegendItem("cell", gauge.colour, gauge.label) for gauge in gauges]
    table = cell_colours()
    burning = tuple(int(v) for v in table[BURNING, 0])
    if known_fires:
        items += [LegendItem("cell", burning, "fire, seen"), LegendItem("cell", UNSEEN_FIRE_COLOUR, "fire, unseen")]
    else:
        items.append(LegendItem("cell", burning, "fire"))
    if colours:  # water: only drones drop it
        items += [LegendItem("cell", EXTINGUISHED_COLOUR, "put out"),
                  LegendItem("cell", tuple(int(v) for v in table[FLOODED, 2]), "flooded")]
    items += [LegendItem("cell", tuple(int(v) for v in table[BURNED, 2]), BURNED_LABEL),
              LegendItem("particle", (255, 200, 0), "fire particle")]
    items += [LegendItem("cell", tuple(int(v) for v in table[c, c]), CLASSES[c].name) for c in classes]
    return items


def _arrow_geometry(height: int, width: int) -> tuple[float, float, float] | None:
    """(centre row, centre column, radius) of the wind arrow's disc in the top-right corner; None if too small."""
    radius = min(28.0, max(6.0, 0.05 * min(height, width)))
    margin = max(2.0, radius / 3.0)
    if 2.0 * (radius + margin) > min(height, width):
        return None
    return margin + radius, width - margin - radius, radius


def _user_stacklevel() -> int:
    """``warnings.warn`` stacklevel of the first caller outside this module and Taichi's method wrappers."""
    frame, level = sys._getframe(1), 1
    while frame is not None and (frame.f_code.co_filename == __file__ or "taichi" in frame.f_code.co_filename):
        frame, level = frame.f_back, level + 1
    return level

