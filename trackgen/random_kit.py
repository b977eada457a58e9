"""Seeded random tracks built only from the official kit's pieces (``trackgen random --kit nxp``):
:func:`random_kit_layout`.

The kit is made to close on a grid (rules summary, section 1.2): a 45-degree curve has a
0.445 m centreline radius, so two make a 90-degree corner that turns the centreline through a
quarter circle between two points 0.445 m from the corner; and a straight plus an extender is
0.72 + 0.17 = 0.89 m, twice that radius. So a track that runs along the edges of a grid of
0.89 m cells, turning at the grid's points, is made of kit pieces exactly. Seen from the grid
points, each point is a 0.89 m square *tile* holding one piece, entered and left at the
middles of its sides: a corner (two curves, the quarter circle centred on a corner of the
tile), a straight (``STRAIGHT`` + ``EXTENDER``), or the intersection, crossed twice straight
on (``EXTENDER`` + the 0.55 m ``CROSSROADS`` square + ``EXTENDER``: the kit intersection's
stubs; 0.17 + 0.55 + 0.17 = 0.89 m). Two straight tiles in a row can hold the chicane
instead (``EXTENDER`` + the 1.44 m ``WAVE`` + ``EXTENDER`` = 2 x 0.89 m). Every piece stays
inside its tiles (the road is 0.55 m wide, a WAVE's swing 0.64 m), so a path that uses each
tile once (a crossing twice) has no overlapping pieces, and the loop closes by construction.

How a track is drawn (the same seed and options give the same text; randomness only from
``numpy.random.default_rng(seed)``):

1. a random *polyomino*: from two cells side by side, cells added one at a time, each a
   random free neighbour of the cells so far (uniform over those that keep the outline one
   simple loop: no hole, no two cells touching only at a corner), until the loop around it
   is as long as a target drawn uniformly in ``length_m`` (the last outline inside
   ``length_m`` is kept; a shape that overshoots it is drawn again);
2. with ``crossings`` k > 0 (uniform in its range): the lap's target is shared among k + 1
   such loops (a Dirichlet(2) share of what exceeds their smallest sizes). The first grows
   from the two cells to at least the loop around a 2 x 2 square (6.36 m); each further
   loop grows from a 2 x 2 square in the corner diagonally opposite a corner of the track
   so far (drawn uniformly among the corners whose tiles on both sides are plain
   straights), using no tile of the track but that corner, whose two arms stay straight
   for at least one tile. Both corners become the
   intersection: the track now crosses itself there, straight on both times (a figure 8 when
   the new loop lies outside, a curl when inside). More crossings than fit in the longest
   lap are not drawn; a lap outside ``length_m``, or a loop that finds no room, is drawn again;
3. the loop, counter-clockwise from its first corner (the first edge at least 2 cells long
   from the lowest-left corner on), becomes the layout from the first straight tile after a
   corner, which is the ``START_FINISH`` piece: ``TURN_LEFT x2`` / ``TURN_RIGHT x2`` at a
   corner, ``STRAIGHT`` + ``EXTENDER`` on a straight tile, the intersection as above;
4. with a ``chicane`` weight in ``mix``: along each run of plain straight tiles (not the
   start), at each tile with a plain straight after it, a ``WAVE`` with probability
   chicane / (straight + chicane), filling both tiles.
Without crossings or chicanes (the defaults) steps 1 and 3 make the track, as before these
options existed. Every track passes ``trackgen validate`` for the car (the kit's curves are
wider than the default car's turning circle).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np
import shapely

from vehicle.description import CarDescription

from .errors import TrackError

CELL_M = 0.89            # kit STRAIGHT + EXTENDER = 2 x the kit curve's 0.445 m radius
KIT_TURN_RADIUS_M = 0.445
CORNER_M = 2 * KIT_TURN_RADIUS_M * math.pi / 4   # a corner's two curves, along the centreline
SQUARE_LOOP_M = 4 * CORNER_M + 4 * CELL_M          # the loop around a 2 x 2 square of cells
CROSSING_GAIN_M = 2 * (CELL_M - CORNER_M)          # two corners become two straight passes
MAX_CROSSINGS = 8
_NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1))
_STRAIGHT, _CROSSING = ["STRAIGHT", "EXTENDER"], ["EXTENDER", "CROSSROADS", "EXTENDER"]
_WAVE = ["EXTENDER", "WAVE", "EXTENDER"]

Point = tuple[int, int]


class RandomKitError(TrackError):
    """Bad options for :func:`random_kit_layout`, or no track within its attempts."""


def _ring(cells: set[Point]) -> list[Point] | None:
    """The counter-clockwise corner points (grid units) of the union of ``cells`` from the
    lowest-left one; None when it is not one simple loop."""
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
    first = min(range(len(corners)), key=lambda i: (corners[i][1], corners[i][0]))
    return corners[first:] + corners[:first]


def _outline(cells: set[Point]) -> list[Point] | None:
    """:func:`_ring` from its first edge at least 2 cells long (room for the START_FINISH);
    None when it is not one simple loop or has no such edge."""
    corners = _ring(cells)
    if corners is None:
        return None
    n = len(corners)
    for i in range(n):
        a, b = corners[i], corners[(i + 1) % n]
        if abs(b[0] - a[0]) + abs(b[1] - a[1]) >= 2:
            return corners[i:] + corners[:i]
    return None


def _tiles(corners: list[Point]) -> list[Point]:
    """Every grid point the loop through ``corners`` passes, in order from ``corners[0]``."""
    out = []
    for a, b in zip(corners, corners[1:] + corners[:1]):
        n = abs(b[0] - a[0]) + abs(b[1] - a[1])
        out += [(a[0] + (b[0] - a[0]) * k // n, a[1] + (b[1] - a[1]) * k // n) for k in range(n)]
    return out


def _loop_m(corners: list[Point]) -> float:
    """Centreline length of the loop through ``corners`` (m)."""
    length = 0.0
    for a, b in zip(corners, corners[1:] + corners[:1]):
        length += (abs(b[0] - a[0]) + abs(b[1] - a[1]) - 1) * CELL_M + CORNER_M
    return length


def _turn(path: list[Point], i: int) -> int:
    """+1 (left), -1 (right) or 0 (straight on) at ``path[i]`` of the closed ``path``."""
    a, b, c = path[i - 1], path[i], path[(i + 1) % len(path)]
    cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
    return (cross > 0) - (cross < 0)


def _grow(rng: np.random.Generator, cells: set[Point], target_m: float, cap: int, ok) -> list[Point] | None:
    """Add random neighbouring cells to ``cells`` (in place) while ``ok(ring)`` holds for the new
    outline, until its loop is at least ``target_m`` long: that ring, or None when stuck."""
    for _ in range(cap):
        corners = _ring(cells)
        if _loop_m(corners) >= target_m:
            return corners
        frontier = sorted({(x + dx, y + dy) for x, y in cells for dx, dy in _NEIGHBOURS} - cells)
        for j in rng.permutation(len(frontier)):
            cell = frontier[int(j)]
            cells.add(cell)
            ring = _ring(cells)
            if ring is not None and ok(ring):
                break
            cells.remove(cell)
        else:
            return None
    return None


def _crossing_path(rng: np.random.Generator, k: int, target_m: float, cap: int) -> list[Point] | None:
    """A closed path of grid points crossing itself (straight on) at ``k`` points (module
    docstring, step 2), at least ``target_m`` long; None when a loop cannot be placed."""
    share = rng.dirichlet(np.full(k + 1, 2.0)) * (target_m - SQUARE_LOOP_M - k * (SQUARE_LOOP_M + CROSSING_GAIN_M))
    cells = {(0, 0), (1, 0)}
    if _grow(rng, cells, SQUARE_LOOP_M + float(share[0]), cap, lambda ring: True) is None:
        return None
    corners = _outline(cells)
    if corners is None:
        return None
    path = _tiles(corners)
    crossings: set[Point] = set()
    for loop in range(1, k + 1):
        n = len(path)
        sites = [i for i in range(n) if _turn(path, i) and path[i] not in crossings
                 and all(not _turn(path, j % n) and path[j % n] not in crossings for j in (i - 1, i + 1))]
        if not sites:
            return None
        i = sites[int(rng.integers(len(sites)))]
        x = path[i]
        d_in = (x[0] - path[i - 1][0], x[1] - path[i - 1][1])
        d_out = (path[(i + 1) % n][0] - x[0], path[(i + 1) % n][1] - x[1])
        # the new loop's corner at x is diagonally opposite the track's: its square lies on
        # the side of the incoming and outgoing-reversed directions, (sx, sy) from x
        sx, sy = d_in[0] - d_out[0], d_in[1] - d_out[1]
        square = {(x[0] + (sx - 1) // 2 + a * sx, x[1] + (sy - 1) // 2 + b * sy) for a in (0, 1) for b in (0, 1)}
        used = set(path) - {x}
        around = {(x[0] + a, x[1] + b) for a in (-1, 0) for b in (-1, 0)} - square

        def fits(ring: list[Point], x=x, used=used) -> bool:
            if x not in ring:
                return False
            j = ring.index(x)
            arms = (ring[j - 1], ring[(j + 1) % len(ring)])
            return all(abs(a[0] - x[0]) + abs(a[1] - x[1]) >= 2 for a in arms) and used.isdisjoint(_tiles(ring))

        new = set(square)
        if not fits(_ring(new)):
            return None
        ring = _grow(rng, new, SQUARE_LOOP_M + float(share[loop]), cap,
                     lambda r: fits(r) and around.isdisjoint(new))
        if ring is None:
            return None
        loop_tiles = _tiles(ring)
        j = loop_tiles.index(x)
        loop_tiles = loop_tiles[j:] + loop_tiles[:j]       # from x
        ahead = (x[0] + d_in[0], x[1] + d_in[1])           # straight on from the track's entry
        if loop_tiles[1] != ahead:
            loop_tiles = [x] + loop_tiles[1:][::-1]
        path = path[:i + 1] + loop_tiles[1:] + path[i:]    # x, the new loop, x again
        crossings.add(x)
    return path


def _layout_lines(path: list[Point], waves: float, rng: np.random.Generator) -> tuple[list[str], int, int]:
    """The layout lines of the closed ``path`` from its first straight tile after a corner
    (the START_FINISH), WAVEs at probability ``waves`` (module docstring, step 4); and the
    numbers of crossings and waves."""
    n = len(path)
    twice = {p for p in path if path.count(p) > 1}
    start = next(i for i in range(n) if not _turn(path, i) and path[i] not in twice and _turn(path, i - 1))
    order = path[start:] + path[:start]
    lines: list[str] = ["START_FINISH", "EXTENDER"]
    passed: set[Point] = set()
    wave_count, i = 0, 1
    while i < n:
        p, turn = order[i], _turn(order, i)
        if turn:
            lines.append("TURN_LEFT x2" if turn > 0 else "TURN_RIGHT x2")
        elif p in twice:
            lines += _CROSSING if p not in passed else ["EXTENDER", "CROSSROADS          # second pass", "EXTENDER"]
            passed.add(p)
        elif (waves > 0.0 and i + 1 < n and not _turn(order, i + 1) and order[i + 1] not in twice
              and rng.random() < waves):
            lines += _WAVE
            wave_count += 1
            i += 1
        else:
            lines += _STRAIGHT
        i += 1
    return lines, len(twice), wave_count


def _options(length_m, crossings, mix) -> tuple[float, float, int, int, float]:
    lo, hi = (float(v) for v in length_m)
    if not 0.0 < lo <= hi:
        raise RandomKitError(f"length_m = {length_m!r}: expected 0 < min <= max (m)")
    given = crossings
    if isinstance(crossings, (int, np.integer)) and not isinstance(crossings, bool):
        crossings = (crossings, crossings)
    try:
        k_lo, k_hi = (int(v) for v in crossings)
    except (TypeError, ValueError):
        raise RandomKitError(f"crossings = {given!r}: expected N or (min, max)") from None
    if not 0 <= k_lo <= k_hi <= MAX_CROSSINGS:
        raise RandomKitError(f"crossings = {given!r}: expected 0 <= min <= max <= {MAX_CROSSINGS}")
    mix = dict(mix or {})
    if "turn" in mix:
        raise RandomKitError("mix: 'turn' is not for kit tracks (their corners come from the loop's "
                             "shape); expected straight, chicane")
    unknown = sorted(set(mix) - {"straight", "chicane"})
    if unknown:
        raise RandomKitError(f"mix: unknown kind {unknown[0]!r} (expected straight, chicane)")
    straight, chicane = float(mix.get("straight", 1.0)), float(mix.get("chicane", 0.0))
    if any(not math.isfinite(w) or w < 0 for w in (straight, chicane)) or straight + chicane <= 0:
        raise RandomKitError(f"mix = {mix!r}: expected weights >= 0, not all 0")
    return lo, hi, k_lo, k_hi, chicane / (straight + chicane)


def random_kit_layout(seed: int, *, length_m: tuple[float, float] = (8.0, 40.0),
                      crossings: int | tuple[int, int] = 0, mix: Mapping[str, float] | None = None,
                      car: CarDescription | None = None, max_attempts: int = 2000) -> str:
    """Layout text of a random closed track of the official kit's pieces (module docstring),
    its lap in ``length_m``; valid for ``car`` (default: the built-in car).

    ``crossings``: N or (min, max), the intersections crossed twice (0 .. 8; default none).
    ``mix``: weights ``straight`` (default 1) and ``chicane`` (default 0): a WAVE's chance
    on each pair of plain straight tiles is chicane / (straight + chicane).
    """
    from .chain import chain
    from .layout import parse_layout
    from .validate import errors, validate_track

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RandomKitError(f"seed = {seed!r}: expected a whole number >= 0")
    lo, hi, k_lo, k_hi, waves = _options(length_m, crossings, mix)
    smallest = 4 * CORNER_M + 2 * CELL_M  # a 2 x 1 rectangle: the shortest with a START_FINISH
    if k_lo:
        smallest = SQUARE_LOOP_M + k_lo * (SQUARE_LOOP_M + CROSSING_GAIN_M)
    if hi < smallest:
        what = f"with {k_lo} crossing(s)" if k_lo else "with a START_FINISH"
        raise RandomKitError(f"length_m = {length_m!r}: the shortest kit loop {what} is {smallest:.2f} m")
    while k_hi > k_lo and SQUARE_LOOP_M + k_hi * (SQUARE_LOOP_M + CROSSING_GAIN_M) > hi:
        k_hi -= 1  # more crossings than fit in the longest lap are never drawn
    car = car or CarDescription()
    rng = np.random.default_rng(int(seed))
    name = f"random_kit_{int(seed)}"
    cap = int(hi / CELL_M) + 8  # more cells than this have a longer outline than any lap asked for
    for attempt in range(1, int(max_attempts) + 1):
        k = int(rng.integers(k_lo, k_hi + 1)) if k_hi else 0
        least = smallest if not k else SQUARE_LOOP_M + k * (SQUARE_LOOP_M + CROSSING_GAIN_M)
        target = float(rng.uniform(max(lo, least), hi))
        if k:
            path = _crossing_path(rng, k, target, cap)
        else:
            path = _simple_path(rng, target, lo, hi, cap)
        if path is None:
            continue
        lines, k_made, wave_count = _layout_lines(path, waves, rng)
        lap = _loop_m([p for i, p in enumerate(path) if _turn(path, i)])
        if not lo <= lap <= hi + 1e-9:
            continue
        extra = ([f"# {k_made} intersection(s) crossed twice, straight on; {wave_count} WAVE(s)"]
                 if k_made or wave_count else [])
        body = [f"@name = {name}", "@kit = nxp", "", *lines, ""]
        track = chain(parse_layout("\n".join(body), path=f"<random kit seed {int(seed)}>", default_name=name))
        if wave_count:  # a WAVE's centreline swings: longer than its 1.44 m
            lap = track.length_m
            if lap > hi:
                continue
        if not errors(validate_track(track, car.min_turn_radius_m)):
            return "\n".join([f"# Random track of the official kit's pieces: trackgen random --kit nxp "
                              f"--seed {int(seed)} (attempt {attempt})",
                              f"# lap {lap:.2f} m on a grid of {CELL_M} m cells (docs/random-tracks.md)",
                              *extra, *body])
    raise RandomKitError(f"seed {int(seed)}: no valid kit track in {max_attempts} attempts (widen length_m)")


def _simple_path(rng: np.random.Generator, target_m: float, lo: float, hi: float, cap: int) -> list[Point] | None:
    """A simple loop (module docstring, step 1): the last outline in [lo, hi] on the way to
    ``target_m``, or None."""
    cells = {(0, 0), (1, 0)}
    best = None
    for _ in range(cap):
        corners = _outline(cells)
        lap = _loop_m(corners)
        if lap > hi:
            break
        if lap >= lo:
            best = corners
        if lap >= target_m:
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
    return None if best is None else _tiles(best)


__all__ = ["random_kit_layout", "RandomKitError", "CELL_M"]
