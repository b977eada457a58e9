"""Top-down PNG preview of a track (matplotlib's Agg canvas; no pyplot, no global state).

White lane, black edge lines and markings, dark floor, an arrow at the car's start pose and
the gate (if any), each physical piece (at most MAX_LABELS) labelled ``piece#:line`` in small grey text.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from .chain import Track
from .export import TrackGeometry

FLOOR_RGB = "#2b2b2b"
PREVIEW_WIDTH_PX = 1200
"""Width of the longer side of the image; the other side follows the track's aspect."""
MARGIN_M = 0.3
MAX_LABELS = 150
"""At most this many piece labels (every k-th piece on long layouts)."""


def _path(geom):
    from matplotlib.path import Path as MPath

    verts, codes = [], []
    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon" or poly.is_empty:
            continue
        poly = orient(poly, 1.0)  # exterior CCW, holes CW: non-zero fill keeps holes
        for ring in (poly.exterior, *poly.interiors):
            xy = np.asarray(ring.coords)[:, :2]
            verts.append(xy)
            codes += [MPath.MOVETO] + [MPath.LINETO] * (len(xy) - 2) + [MPath.CLOSEPOLY]
    if not verts:
        return None
    return MPath(np.vstack(verts), codes)


def render_preview(track: Track, geometry: TrackGeometry, path: str | Path) -> tuple[int, int]:
    """Write the PNG to ``path``; return its ``(width_px, height_px)``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import FancyArrow, PathPatch

    x0, y0, x1, y1 = geometry.road.bounds
    x0, y0, x1, y1 = x0 - MARGIN_M, y0 - MARGIN_M, x1 + MARGIN_M, y1 + MARGIN_M
    w_m, h_m = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
    dpi = 100
    scale = PREVIEW_WIDTH_PX / max(w_m, h_m)
    fig = Figure(figsize=(max(w_m * scale, 64) / dpi, max(h_m * scale, 64) / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_facecolor(FLOOR_RGB)
    fig.patch.set_facecolor(FLOOR_RGB)
    for geom, colour in ((geometry.edges, "black"), (geometry.lane, "white"),
                         (geometry.markings, "black")):
        mpath = _path(geom) if geom is not None else None
        if mpath is not None:
            ax.add_patch(PathPatch(mpath, facecolor=colour, edgecolor="none", lw=0))
    font = max(4.0, min(8.0, 0.08 * scale * 72 / dpi))
    physical = track.physical
    step = max(1, -(-len(physical) // MAX_LABELS))
    for p in physical[::step]:
        cx, cy = p.centreline_world().mean(axis=0)
        ax.text(cx, cy, f"{p.index + 1}:{p.line}", fontsize=font, color="#808080",
                ha="center", va="center")
    start = track.car_start_pose()
    arrow_m = 0.25
    ax.add_patch(FancyArrow(start.x_m, start.y_m, arrow_m * np.cos(start.yaw_rad),
                            arrow_m * np.sin(start.yaw_rad), width=0.04, head_width=0.12,
                            head_length=0.1, length_includes_head=True, color="#d62728"))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.savefig(str(path), dpi=dpi, facecolor=FLOOR_RGB, format="png")
    width, height = fig.canvas.get_width_height()
    return int(width), int(height)
