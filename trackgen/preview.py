"""Top-down PNG preview of a track, drawn with Pillow (no matplotlib: ~0.6 s of import and
drawing that dominated ``trackgen build``; Pillow draws this in ~50 ms).

What it shows: the dark floor; the white lane, black edge lines and finish bar (drawn at
SUPERSAMPLE x the size and reduced, so edges are smooth); a grid in metres every
:func:`grid_step_m` with the coordinates written along the left and bottom edges (world
frame: the layout starts at (0, 0) heading +x, y up); a scale bar; a red arrow at the car's
start pose; each physical piece labelled ``piece#:line`` in grey (at most MAX_LABELS, every
k-th on long layouts); and a legend of all of these in a band above the map (over the
map it hid labels and grid numbers).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import shapely

from .chain import Track
from .export import TrackGeometry

FLOOR_RGB = (43, 43, 43)
GRID_RGB = (75, 75, 75)
LABEL_RGB = (128, 128, 128)
ARROW_RGB = (214, 39, 40)
TEXT_RGB = (230, 230, 230)
PREVIEW_WIDTH_PX = 1200
"""Width of the longer side of the image; the other side follows the track's aspect."""
MIN_SIDE_PX = 400
"""The shorter side is at least this (room for the legend); the track is centred."""
LEGEND_BAND_PX = 124
"""Height of the band above the map that holds the legend."""
MARGIN_M = 0.3
MAX_LABELS = 150
"""At most this many piece labels (every k-th piece on long layouts)."""
SUPERSAMPLE = 2
_NICE = (1.0, 2.0, 2.5, 5.0)


def grid_step_m(span_m: float, lines: int = 8) -> float:
    """A round grid spacing (1, 2, 2.5 or 5 times a power of ten) giving about ``lines``
    grid lines over ``span_m``."""
    raw = max(span_m, 1e-9) / lines
    power = 10.0 ** math.floor(math.log10(raw))
    return next((n * power for n in _NICE if n * power >= raw), 10.0 * power)


def _font(size_px: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=max(6, int(size_px)))
    except TypeError:  # Pillow < 10.1 or no FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _mask(geom, to_px, size: tuple[int, int]):
    """An 8-bit mask (255 inside) of a (Multi)Polygon, holes kept."""
    from PIL import Image, ImageDraw

    mask = Image.new("L", size, 0)
    if geom is None or geom.is_empty:
        return mask
    draw = ImageDraw.Draw(mask)
    polys = [p for p in shapely.get_parts(geom) if p.geom_type == "Polygon" and not p.is_empty]
    # Larger outlines first: an island inside another polygon's hole is drawn after the hole.
    polys.sort(key=lambda p: -shapely.Polygon(p.exterior).area)
    for poly in polys:
        draw.polygon(to_px(np.asarray(poly.exterior.coords)), fill=255)
        for ring in poly.interiors:
            draw.polygon(to_px(np.asarray(ring.coords)), fill=0)
    return mask


def _lit(image, lighting, x0: float, y1: float, px_per_m: float, surface_z_m: float):
    """``image`` as the track's light shows it: each pixel times its illuminance over the
    default hall's (``worlds.lighting.DEFAULT_AMBIENT_LUX``), clipped at white; the lamps marked
    with their position (a yellow ring)."""
    from PIL import Image, ImageDraw

    from worlds.lighting import DEFAULT_AMBIENT_LUX

    w, h = image.size
    xs = x0 + (np.arange(w) + 0.5) / px_per_m
    ys = y1 - (np.arange(h) + 0.5) / px_per_m
    lux = lighting.illuminance_grid(xs, ys, surface_z_m)
    shade = np.asarray(image, dtype=np.float64) * (lux / DEFAULT_AMBIENT_LUX)[:, :, None]
    out = Image.fromarray(np.clip(np.rint(shade), 0, 255).astype(np.uint8), "RGB")
    draw = ImageDraw.Draw(out)
    for lamp in lighting.lights:
        px, py = (lamp.x_m - x0) * px_per_m, (y1 - lamp.y_m) * px_per_m
        draw.ellipse((px - 6, py - 6, px + 6, py + 6), outline=(230, 190, 0), width=2)
    return out


def render_preview(track: Track, geometry: TrackGeometry, path: str | Path) -> tuple[int, int]:
    """Write the PNG to ``path``; return its ``(width_px, height_px)`` (the longer side
    PREVIEW_WIDTH_PX, the legend's band included)."""
    from PIL import Image, ImageDraw

    x0, y0, x1, y1 = geometry.road.bounds
    x0, y0, x1, y1 = x0 - MARGIN_M, y0 - MARGIN_M, x1 + MARGIN_M, y1 + MARGIN_M
    w_m, h_m = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
    px_per_m = min(PREVIEW_WIDTH_PX / w_m, (PREVIEW_WIDTH_PX - LEGEND_BAND_PX) / h_m)
    width = max(MIN_SIDE_PX, int(round(w_m * px_per_m)))
    height = max(MIN_SIDE_PX - LEGEND_BAND_PX, int(round(h_m * px_per_m)))  # the map's
    # centre the track in the image
    x0 -= (width / px_per_m - w_m) / 2
    y1 += (height / px_per_m - h_m) / 2

    def to_px(xy: np.ndarray, k: float = 1.0) -> list[tuple[float, float]]:
        xy = np.asarray(xy, dtype=float)[:, :2]
        return [tuple(p) for p in np.column_stack([(xy[:, 0] - x0) * px_per_m * k,
                                                   (y1 - xy[:, 1]) * px_per_m * k])]

    big = (width * SUPERSAMPLE, height * SUPERSAMPLE)
    image = Image.new("RGB", big, FLOOR_RGB)

    def k_px(xy):
        return to_px(xy, SUPERSAMPLE)

    step = grid_step_m(max(w_m, h_m))
    grid = ImageDraw.Draw(image)
    gx = np.arange(math.ceil(x0 / step), math.floor((x0 + width / px_per_m) / step) + 1) * step
    gy = np.arange(math.ceil((y1 - height / px_per_m) / step), math.floor(y1 / step) + 1) * step
    for x in gx:
        grid.line(k_px([[x, y1], [x, y1 - height / px_per_m]]), fill=GRID_RGB, width=SUPERSAMPLE)
    for y in gy:
        grid.line(k_px([[x0, y], [x0 + width / px_per_m, y]]), fill=GRID_RGB, width=SUPERSAMPLE)
    # edge lines and the finish bar are black: the whole road black, then the lane white
    for geom, colour in ((geometry.road, (0, 0, 0)), (geometry.lane, (255, 255, 255))):
        image.paste(colour, (0, 0), _mask(geom, k_px, big))
    for code in track.layout.barcodes:  # printed barcodes (worlds.marks): card, then bars
        image.paste((255, 255, 255), (0, 0), _mask(code.card(), k_px, big))
        for bar in code.bars():
            image.paste((0, 0, 0), (0, 0), _mask(bar, k_px, big))
    for box in track.layout.boxes:  # objects standing on the track (worlds.solids): their footprint,
        shade = int(round(255 * box.reflectance * 0.5))  # in the grey of their sides
        image.paste((shade, shade, min(255, shade + 60)), (0, 0), _mask(shapely.Polygon(box.corners_xy()), k_px, big))
    image = image.reduce(SUPERSAMPLE)  # box filter: smooth edges
    lighting = track.lighting()
    if not lighting.is_default():
        image = _lit(image, lighting, x0, y1, px_per_m, track.layout.settings.thickness_m)
    draw = ImageDraw.Draw(image)
    _arrow(track, draw, to_px)
    _labels(track, draw, to_px, px_per_m)  # over the arrow, on a white halo: a label it covers stays readable
    font = _font(13)
    for x in gx:
        px, _ = to_px([[x, 0.0]])[0]
        draw.text((px + 2, height - 16), f"{x:g}", fill=TEXT_RGB, font=font)
    for y in gy:
        _, py = to_px([[0.0, y]])[0]
        draw.text((3, py - 15), f"{y:g}", fill=TEXT_RGB, font=font)
    _scale_bar(draw, step, px_per_m, width, height, font)
    framed = Image.new("RGB", (width, height + LEGEND_BAND_PX), FLOOR_RGB)
    framed.paste(image, (0, LEGEND_BAND_PX))
    _legend(ImageDraw.Draw(framed), step, font)
    framed.save(str(path), format="PNG", compress_level=3)
    return framed.size


def _labels(track: Track, draw, to_px, px_per_m: float) -> None:
    physical = track.physical
    step = max(1, -(-len(physical) // MAX_LABELS))
    font = _font(min(13, max(8, 0.12 * px_per_m)))
    for p in physical[::step]:
        (cx, cy), = to_px(p.centreline_world().mean(axis=0, keepdims=True))
        draw.text((cx, cy), f"{p.index + 1}:{p.line}", fill=LABEL_RGB, font=font, anchor="mm",
                  stroke_width=2, stroke_fill=(255, 255, 255))


def _arrow(track: Track, draw, to_px, length_m: float = 0.25) -> None:
    start = track.car_start_pose()
    c, s = math.cos(start.yaw_rad), math.sin(start.yaw_rad)
    tail = np.array([start.x_m, start.y_m])
    tip = tail + length_m * np.array([c, s])
    back = tip - 0.4 * length_m * np.array([c, s])
    side = 0.22 * length_m * np.array([-s, c])
    draw.line(to_px([tail, back]), fill=ARROW_RGB, width=4)
    draw.polygon(to_px([tip, back + side, back - side]), fill=ARROW_RGB)


def _scale_bar(draw, step: float, px_per_m: float, width: int, height: int, font) -> None:
    bar = step * px_per_m
    right, y = width - 20, height - 34
    draw.rectangle([right - bar - 6, y - 20, right + 6, y + 8], fill=FLOOR_RGB)
    draw.line([(right - bar, y), (right, y)], fill=TEXT_RGB, width=3)
    for x in (right - bar, right):
        draw.line([(x, y - 6), (x, y + 6)], fill=TEXT_RGB, width=2)
    draw.text((right - bar / 2, y - 4), f"{step:g} m", fill=TEXT_RGB, font=font, anchor="mb")


def _legend(draw, step: float, font) -> None:
    rows = [("lane", "swatch", (255, 255, 255)),
            ("edge line, finish bar", "swatch", (0, 0, 0)),
            ("car start and heading", "arrow", ARROW_RGB),
            ("12:7  piece 12, layout line 7", "text", LABEL_RGB),
            (f"grid {step:g} m, x and y in m", "grid", GRID_RGB)]
    left, top, row_h = 8, 8, 20
    draw.rectangle([left, top, left + 250, top + 8 + row_h * len(rows)], fill=(20, 20, 20),
                   outline=(100, 100, 100))
    for i, (text, kind, colour) in enumerate(rows):
        y = top + 6 + i * row_h
        if kind == "swatch":
            draw.rectangle([left + 8, y + 3, left + 30, y + 14], fill=colour, outline=(140, 140, 140))
        elif kind == "arrow":
            draw.line([(left + 8, y + 9), (left + 22, y + 9)], fill=colour, width=4)
            draw.polygon([(left + 31, y + 9), (left + 21, y + 3), (left + 21, y + 15)], fill=colour)
        elif kind == "grid":
            draw.line([(left + 8, y + 9), (left + 30, y + 9)], fill=(110, 110, 110), width=2)
        if kind == "text":
            draw.text((left + 8, y + 2), text, fill=colour, font=font)
        else:
            draw.text((left + 38, y + 2), text, fill=TEXT_RGB, font=font)
