"""Seeded random tracks built only from the official kit's pieces (``trackgen random --kit nxp``):
:func:`random_kit_layout`.

The kit is made to close on a grid (rules summary, section 1.2): a 45-degree curve has a
0.445 m centreline radius, so two make a 90-degree corner that turns the centreline through a
quarter circle between two points 0.445 m from the corner; and a straight plus an extender is
0.72 + 0.17 = 0.89 m, twice that radius. So a track that runs along the edges of a grid of
0.89 m cells, turning at the grid's points, is made of kit pieces exactly: a corner is two
curves, an edge k cells long is k - 1 (straight, extender) pairs between its corners, and the
loop closes by construction.

How a track is drawn (the same seed and options give the same text; randomness only from
``numpy.random.default_rng(seed)``):

1. a random *polyomino*: from two cells side by side, cells added one at a time, each a
   random free neighbour of the cells so far (uniform over those that keep the outline one
   simple loop: no hole, no two cells touching only at a corner), until the loop around it
   is as long as a target drawn uniformly in ``length_m`` (the last outline inside
   ``length_m`` is kept; a shape that overshoots it is drawn again);
2. the outline, counter-clockwise from its first edge at least 2 cells long (from the
   lowest-left corner on), becomes the layout: ``TURN_LEFT x2`` at a convex corner, ``TURN_RIGHT x2`` at a concave one, and
   ``STRAIGHT`` / ``EXTENDER`` pairs along the edges; the first straight is the
   ``START_FINISH`` piece.
Tracks have no crossings (a simple loop) and no chicanes; every one passes ``trackgen
validate`` for the car (the kit's curves are wider than the default car's turning circle).
"""
from __future__ import annotations

import math

import numpy as np
import shapely

from vehicle.description import CarDescription

from .errors import TrackError

CELL_M = 0.89            # kit STRAIGHT + EXTENDER = 2 x the kit curve's 0.445 m radius
KIT_TURN_RADIUS_M = 0.445
CORNER_M = 2 * KIT_TURN_RADIUS_M * math.pi / 4   # a corner's two curves, along the centreline
_NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1))


class RandomKitError(TrackError):
    """Bad options for :func:`random_kit_layout`, or no track within its attempts."""


def _outline(cells: set[tuple[int, int]]) -> list[tuple[int, int]] | None:
    """The counter-clockwise corner points (grid units) of the union of ``cells``, starting at
    the first edge at least 2 cells long from its lowest-left corner on; None when it is not
    one simple loop."""
    shape = shapely.union_all([shapely.box(x, y, x + 1, y + 1) for x, y in cells])
    if not isinstance(shape, shapely.Polygon) or shape.interiors or not shape.exterior.is_simple:
        return None
    ring = shapely.geometry.polygon.orient(shape, 1.0).exterior  # counter-clockwise
    pts = [(int(round(x)), int(round(y))) for x, y in ring.coords[:-1]]
    # keep the corners only (drop points where the outline goes straight on)
    corners = [p for i, p in enumerate(pts)
               if (pts[i - 1][0] - p[0]) * (pts[(i + 1) % len(pts)][1] - p[1])
               != (pts[i - 1][1] - p[1]) * (pts[(i + 1) % len(pts)][0] - p[0])]
    # a point where the outline touches itself (cells meeting at a corner only) repeats
    if len(set(corners)) != len(corners):
        return None
    # start at the first edge (from the lowest-left corner on) long enough for the START_FINISH
    n = len(corners)
    first = min(range(n), key=lambda i: (corners[i][1], corners[i][0]))
    for k in range(n):
        i = (first + k) % n
        a, b = corners[i], corners[(i + 1) % n]
        if abs(b[0] - a[0]) + abs(b[1] - a[1]) >= 2:
            return corners[i:] + corners[:i]
    return None


def _layout_lines(corners: list[tuple[int, int]]) -> tuple[list[str], float]:
    """The layout lines of the loop through ``corners`` and its centreline length (m)."""
    n = len(corners)
    lines, length = [], 0.0
    for i in range(n):
        a, b, c = corners[i], corners[(i + 1) % n], corners[(i + 2) % n]
        cells = abs(b[0] - a[0]) + abs(b[1] - a[1])
        pairs = ["STRAIGHT", "EXTENDER"] * (cells - 1)
        if i == 0:
            pairs[0] = "START_FINISH"
        lines += pairs
        cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
        lines.append("TURN_LEFT x2" if cross > 0 else "TURN_RIGHT x2")
        length += (cells - 1) * CELL_M + CORNER_M
    return lines, length


def random_kit_layout(seed: int, *, length_m: tuple[float, float] = (8.0, 40.0),
                      car: CarDescription | None = None, max_attempts: int = 2000) -> str:
    """Layout text of a random closed track of the official kit's pieces (module docstring),
    its lap in ``length_m``; valid for ``car`` (default: the built-in car)."""
    from .chain import chain
    from .layout import parse_layout
    from .validate import errors, validate_track

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RandomKitError(f"seed = {seed!r}: expected a whole number >= 0")
    lo, hi = (float(v) for v in length_m)
    if not 0.0 < lo <= hi:
        raise RandomKitError(f"length_m = {length_m!r}: expected 0 < min <= max (m)")
    smallest = 4 * CORNER_M + 2 * CELL_M  # a 2 x 1 rectangle: the shortest with a START_FINISH
    if hi < smallest:
        raise RandomKitError(f"length_m = {length_m!r}: the shortest kit loop with a START_FINISH is "
                             f"{smallest:.2f} m")
    car = car or CarDescription()
    rng = np.random.default_rng(int(seed))
    name = f"random_kit_{int(seed)}"
    cap = int(hi / CELL_M) + 8  # more cells than this have a longer outline than any lap asked for
    for attempt in range(1, int(max_attempts) + 1):
        target = float(rng.uniform(max(lo, smallest), hi))
        cells = {(0, 0), (1, 0)}
        best = None
        for _ in range(cap):
            corners = _outline(cells)
            lines, lap = _layout_lines(corners)
            if lap > hi:
                break
            if lap >= lo:
                best = (lines, lap)
            if lap >= target:
                break
            frontier = sorted({(x + dx, y + dy) for x, y in cells for dx, dy in _NEIGHBOURS} - cells)
            for j in rng.permutation(len(frontier)):  # a cell that keeps the outline one simple loop
                cell = frontier[int(j)]
                cells.add(cell)
                if _outline(cells) is not None:
                    break
                cells.remove(cell)
            else:
                break
        if best is None:
            continue
        lines, lap = best
        text = "\n".join([f"# Random track of the official kit's pieces: trackgen random --kit nxp --seed {int(seed)} "
                          f"(attempt {attempt})",
                          f"# lap {lap:.2f} m on a grid of {CELL_M} m cells (docs/random-tracks.md)",
                          f"@name = {name}", "@kit = nxp", "", *lines, ""])
        track = chain(parse_layout(text, path=f"<random kit seed {int(seed)}>", default_name=name))
        if not errors(validate_track(track, car.min_turn_radius_m)):
            return text
    raise RandomKitError(f"seed {int(seed)}: no valid kit track in {max_attempts} attempts (widen length_m)")


__all__ = ["random_kit_layout", "RandomKitError", "CELL_M"]
