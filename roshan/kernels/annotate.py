"""A caption band above a finished frame and a legend band below it, drawn on the host with PIL.

Frames are pictures for people, made when a frame is saved, never in the training loop; the map itself is drawn
by the kernels of :mod:`roshan.kernels.render` and is left untouched here (the bands are added around it).
"""

import re
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw, ImageFont

BAND_COLOUR = (21, 19, 51)  # the reference's background colour, as behind the wind arrow
TEXT_COLOUR = (255, 255, 255)
RIM = (0, 0, 0)
FONT_PX = 14
PAD = 6  # pixels around the text and between rows
SWATCH = 16  # legend symbols are SWATCH x SWATCH pixels
GAP = 14  # between legend items
KINDS = ("cell", "disc", "diamond", "square", "cross", "particle")


@dataclass(frozen=True)
class LegendItem:
    """One legend entry: a symbol of ``kind`` (:data:`KINDS`) in ``colour``, and its label."""

    kind: str
    colour: tuple[int, int, int]
    label: str


def font(size: int = FONT_PX):
    """Pillow's bundled scalable font at ``size`` px (its fixed bitmap font where FreeType is missing)."""
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, ImportError, OSError):  # Pillow < 10.1, or no FreeType
        return ImageFont.load_default()


def annotate(frame: np.ndarray, caption: str, legend: list[LegendItem]) -> np.ndarray:
    """``frame`` (H, W, 3) uint8 with a caption band on top and a legend band below; returns a new array.

    The caption's `` | ``-separated parts wrap onto further lines when the frame is too narrow; legend items
    flow left to right and wrap likewise. The map keeps its pixels: ``out[top:top + H] == frame``.
    """
    f = font()
    width = frame.shape[1]
    line_h = _text_height(f) + PAD
    caption_lines = _wrap(caption.split(" | "), " | ", f, width - 2 * PAD)
    rows = _legend_rows(legend, f, width - 2 * PAD)
    top = len(caption_lines) * line_h + PAD
    bottom = len(rows) * (max(SWATCH, _text_height(f)) + PAD) + PAD if rows else 0
    out = Image.new("RGB", (width, top + frame.shape[0] + bottom), BAND_COLOUR)
    out.paste(Image.fromarray(frame), (0, top))
    draw = ImageDraw.Draw(out)
    for i, text in enumerate(caption_lines):
        draw.text((PAD, PAD + i * line_h), text, fill=TEXT_COLOUR, font=f)
    y = top + frame.shape[0] + PAD
    row_h = max(SWATCH, _text_height(f)) + PAD
    for row in rows:
        x = PAD
        for item in row:
            _symbol(draw, item, x, y + (row_h - PAD - SWATCH) // 2)
            draw.text((x + SWATCH + 4, y), item.label, fill=TEXT_COLOUR, font=f)
            x += _item_width(item, f) + GAP
        y += row_h
    return np.asarray(out)


def _text_height(f) -> int:
    box = f.getbbox("Ag|(")
    return int(box[3])


def _text_width(f, text: str) -> int:
    return int(np.ceil(f.getlength(text)))


def _wrap(parts: list[str], sep: str, f, width: int) -> list[str]:
    """Join ``parts`` with ``sep`` into lines no wider than ``width`` px (a part too wide alone stays whole).

    Widths are measured with every number widened to at least six digits, so the line breaks (and the frame's
    height) stay the same while the numbers of a caption grow: every frame of a GIF has one size.
    """
    lines: list[list[str]] = []
    for part in parts:
        if lines and _text_width(f, _widest(sep.join([*lines[-1], part]))) <= width:
            lines[-1].append(part)
        else:
            lines.append([part])
    return [sep.join(line) for line in lines] or [""]


def _widest(text: str) -> str:
    return re.sub(r"\d+", lambda m: "8" * max(6, len(m.group())), text)


def _item_width(item: LegendItem, f) -> int:
    return SWATCH + 4 + _text_width(f, item.label)


def _legend_rows(items: list[LegendItem], f, width: int) -> list[list[LegendItem]]:
    rows: list[list[LegendItem]] = []
    used = 0
    for item in items:
        if item.kind not in KINDS:
            raise ValueError(f"legend item {item.label!r}: kind must be one of {', '.join(KINDS)}, got {item.kind!r}")
        w = _item_width(item, f)
        if rows and used + GAP + w <= width:
            rows[-1].append(item)
            used += GAP + w
        else:
            rows.append([item])
            used = w
    return rows


def _symbol(draw: ImageDraw.ImageDraw, item: LegendItem, x: int, y: int) -> None:
    """The legend symbol of ``item`` in the SWATCH x SWATCH box at (x, y)."""
    s, c = SWATCH, tuple(item.colour)
    if item.kind == "cell":
        draw.rectangle((x, y, x + s - 1, y + s - 1), fill=c, outline=(90, 90, 90))
    elif item.kind == "disc":
        draw.ellipse((x + 1, y + 1, x + s - 2, y + s - 2), fill=c, outline=RIM)
    elif item.kind == "particle":
        draw.ellipse((x + 4, y + 4, x + s - 5, y + s - 5), fill=c)
    elif item.kind == "diamond":
        m = s // 2
        draw.polygon([(x + m, y), (x + s - 1, y + m), (x + m, y + s - 1), (x, y + m)], fill=c, outline=RIM)
    elif item.kind == "square":
        draw.rectangle((x + 1, y + 1, x + s - 2, y + s - 2), outline=c, width=2)
    elif item.kind == "cross":
        m = s // 2
        draw.rectangle((x, y + m - 3, x + s - 1, y + m + 2), fill=RIM)
        draw.rectangle((x + m - 3, y, x + m + 2, y + s - 1), fill=RIM)
        draw.rectangle((x + 1, y + m - 2, x + s - 2, y + m + 1), fill=c)
        draw.rectangle((x + m - 2, y + 1, x + m + 1, y + s - 2), fill=c)
