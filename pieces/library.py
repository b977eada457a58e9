"""Piece constructors: pure functions of their keyword-only parameters (metres, radians).

Every constructor validates its inputs first and raises :class:`PieceError` naming the
parameter, its value and the expected range; then it builds exact 2D footprints (meshes are
made lazily by :class:`Piece`).
"""
from __future__ import annotations

import math
import re
from typing import Callable, Mapping

import numpy as np
import shapely
import shapely.affinity

from .geometry import arc_samples, arc_segments, rect, road_bands
from .piece import Piece
from .pose import Pose2
from .spec import PARAMS, PieceError, PieceType, TrackSettings, check_range

DEFAULT_SETTINGS = TrackSettings()


def _check_settings(settings: TrackSettings) -> TrackSettings:
    if not isinstance(settings, TrackSettings):
        raise PieceError(f"settings={settings!r}: expected a pieces.TrackSettings")
    return settings


def _check_direction(direction: int) -> int:
    if direction not in (1, -1):
        raise PieceError(f"direction={direction!r}: expected +1 (left) or -1 (right)")
    return int(direction)


def _straight_edges(length_m: float, s: TrackSettings) -> shapely.MultiPolygon:
    h, e = s.lane_width_m / 2.0, s.edge_width_m
    return shapely.MultiPolygon([rect(0.0, -h - e, length_m, -h), rect(0.0, h, length_m, h + e)])


def _straight(kind: PieceType, length_m: float, settings: TrackSettings) -> Piece:
    s = _check_settings(settings)
    length_m = check_range("length_m", length_m, 0.0)
    h = s.lane_width_m / 2.0
    return Piece(
        kind=kind, settings=s, params={"length_m": length_m},
        lane=rect(0.0, -h, length_m, h), edges=_straight_edges(length_m, s), marking=None,
        centreline=[[0.0, 0.0], [length_m, 0.0]],
        ports={"entry": Pose2(), "exit": Pose2(length_m, 0.0, 0.0)},
        length_m=length_m,
    )


def straight(*, length_m: float = 1.0, settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """STRAIGHT: ``length_m`` long, exit at ``Pose2(length_m, 0, 0)``."""
    return _straight(PieceType.STRAIGHT, length_m, settings)


def straight_short(*, length_m: float = 0.5, settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """STRAIGHT_SHORT: a straight whose default length is 0.5 m."""
    return _straight(PieceType.STRAIGHT_SHORT, length_m, settings)


def start_finish(*, length_m: float = 1.0, mark_length_m: float = 0.05, mark_gap_m: float = 0.0,
                 mark_inset_m: float = 0.0, mark_offset_m: float = 0.0,
                 settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """START_FINISH: a straight with a black bar ``mark_length_m`` long (along travel) across
    the lane, its centre ``mark_offset_m`` after mid-piece (negative: before). ``mark_gap_m``
    leaves a white gap that wide in the lane's centre (two bars, as the rules' mark) and
    ``mark_inset_m`` that much white between each bar and its edge line; by default one bar
    across the full lane at mid-piece. The bars are cut out of the lane, so lane, edges and
    marking footprints are disjoint. Extra port ``"finish"``: the centre of the mark."""
    s = _check_settings(settings)
    length_m = check_range("length_m", length_m, 0.0)
    mark_length_m = check_range("mark_length_m", mark_length_m, 0.0, length_m, hi_open=True,
                                why="shorter than the piece")
    reach = (length_m - mark_length_m) / 2.0
    mark_offset_m = check_range("mark_offset_m", mark_offset_m, -reach, reach, lo_open=False,
                                why="the mark on the piece")
    h = s.lane_width_m / 2.0
    mark_gap_m = check_range("mark_gap_m", mark_gap_m, 0.0, s.lane_width_m, lo_open=False, hi_open=True,
                             why="narrower than the lane")
    mark_inset_m = check_range("mark_inset_m", mark_inset_m, 0.0, h - mark_gap_m / 2.0, lo_open=False,
                               hi_open=True, why="the bars wider than nothing: mark_gap / 2 + mark_inset < lane / 2")
    c = length_m / 2.0 + mark_offset_m
    x0, x1 = c - mark_length_m / 2.0, c + mark_length_m / 2.0
    params = {"length_m": length_m, "mark_length_m": mark_length_m}
    if (mark_gap_m, mark_inset_m, mark_offset_m) == (0.0, 0.0, 0.0):  # one bar across the lane
        lane = shapely.MultiPolygon([rect(0.0, -h, x0, h), rect(x1, -h, length_m, h)])
        marking = rect(x0, -h, x1, h)
    else:
        params.update(mark_gap_m=mark_gap_m, mark_inset_m=mark_inset_m, mark_offset_m=mark_offset_m)
        g, a = mark_gap_m / 2.0, h - mark_inset_m
        bars = [rect(x0, -a, x1, -g), rect(x0, g, x1, a)] if g > 0.0 else [rect(x0, -a, x1, a)]
        marking = shapely.MultiPolygon(bars) if len(bars) > 1 else bars[0]
        lane = shapely.difference(rect(0.0, -h, length_m, h), marking)
    return Piece(
        kind=PieceType.START_FINISH, settings=s, params=params,
        lane=lane, edges=_straight_edges(length_m, s), marking=marking,
        centreline=[[0.0, 0.0], [length_m, 0.0]],
        ports={"entry": Pose2(), "exit": Pose2(length_m, 0.0, 0.0),
               "finish": Pose2(c, 0.0, 0.0)},
        length_m=length_m,
    )


def turn(*, angle_rad: float = math.pi / 4, radius_m: float = 0.8, direction: int = 1,
         settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """TURN_LEFT (``direction=+1``) or TURN_RIGHT (``-1``): a circular arc of centreline
    radius ``radius_m`` (> half the road width) through ``angle_rad`` in (0, pi].
    Exit at ``Pose2(R sin a, +-R (1 - cos a), +-a)``."""
    s = _check_settings(settings)
    direction = _check_direction(direction)
    angle_rad = check_range("angle_rad", angle_rad, 0.0, math.pi, unit="rad")
    half_road = s.road_width_m / 2.0
    radius_m = check_range("radius_m", radius_m, half_road, why="more than half the road width")
    n = arc_segments(angle_rad, radius_m + half_road, s.arc_tolerance_m)
    pts, yaw = arc_samples(radius_m, angle_rad, direction, n)
    lane, edges = road_bands(pts, yaw, s.lane_width_m, s.edge_width_m)
    exit_pose = Pose2(radius_m * math.sin(angle_rad),
                      direction * radius_m * (1.0 - math.cos(angle_rad)), direction * angle_rad)
    return Piece(
        kind=PieceType.TURN_LEFT if direction > 0 else PieceType.TURN_RIGHT, settings=s,
        params={"radius_m": radius_m, "angle_rad": angle_rad},
        lane=lane, edges=edges, marking=None, centreline=pts,
        ports={"entry": Pose2(), "exit": exit_pose},
        length_m=radius_m * angle_rad, min_radius_m=radius_m,
    )


def turn_left(*, angle_rad: float = math.pi / 4, radius_m: float = 0.8,
              settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """TURN_LEFT; see :func:`turn`."""
    return turn(angle_rad=angle_rad, radius_m=radius_m, direction=1, settings=settings)


def turn_right(*, angle_rad: float = math.pi / 4, radius_m: float = 0.8,
               settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """TURN_RIGHT; see :func:`turn`."""
    return turn(angle_rad=angle_rad, radius_m=radius_m, direction=-1, settings=settings)


def chicane_geometry(length_m: float, offset_m: float) -> tuple[float, float]:
    """Arc angle ``theta = 2 atan(offset / length)`` (rad) and radius
    ``R = length / (2 sin theta)`` (m) of the two opposite arcs of a chicane."""
    theta = 2.0 * math.atan2(offset_m, length_m)
    return theta, length_m / (2.0 * math.sin(theta))


def chicane(*, length_m: float = 1.0, offset_m: float = 0.20, direction: int = 1,
            settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """CHICANE_LEFT (``direction=+1``, shifts to +y) or CHICANE_RIGHT (``-1``): an S-bend of
    two opposite circular arcs (see :func:`chicane_geometry`) that moves the lane sideways
    by ``offset_m`` over ``length_m`` and keeps the heading. Exit at
    ``Pose2(length_m, +-offset_m, 0)``. The arc radius must exceed half the road width."""
    s = _check_settings(settings)
    direction = _check_direction(direction)
    length_m = check_range("length_m", length_m, 0.0)
    offset_m = check_range("offset_m", offset_m, 0.0)
    theta, radius_m = chicane_geometry(length_m, offset_m)
    half_road = s.road_width_m / 2.0
    if not radius_m > half_road:
        raise PieceError(
            f"offset_m={offset_m:g} with length_m={length_m:g}: arc radius {radius_m:.4g} m must "
            f"exceed half the road width {half_road:g} m (use a smaller offset or a longer piece)")
    n = arc_segments(theta, radius_m + half_road, s.arc_tolerance_m)
    p1, y1 = arc_samples(radius_m, theta, direction, n)
    p2, y2 = arc_samples(radius_m, theta, -direction, n, start_xy=tuple(p1[-1]),
                         start_yaw_rad=float(y1[-1]))
    pts, yaw = np.vstack([p1, p2[1:]]), np.concatenate([y1, y2[1:]])
    pts[-1] = (length_m, direction * offset_m)  # exact exit edge (rounding ~1e-16 otherwise)
    yaw[-1] = 0.0
    lane, edges = road_bands(pts, yaw, s.lane_width_m, s.edge_width_m)
    return Piece(
        kind=PieceType.CHICANE_LEFT if direction > 0 else PieceType.CHICANE_RIGHT, settings=s,
        params={"length_m": length_m, "offset_m": offset_m},
        lane=lane, edges=edges, marking=None, centreline=pts,
        ports={"entry": Pose2(), "exit": Pose2(length_m, direction * offset_m, 0.0)},
        length_m=2.0 * radius_m * theta, min_radius_m=radius_m,
    )


def chicane_left(*, length_m: float = 1.0, offset_m: float = 0.20,
                 settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """CHICANE_LEFT; see :func:`chicane`."""
    return chicane(length_m=length_m, offset_m=offset_m, direction=1, settings=settings)


def chicane_right(*, length_m: float = 1.0, offset_m: float = 0.20,
                  settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """CHICANE_RIGHT; see :func:`chicane`."""
    return chicane(length_m=length_m, offset_m=offset_m, direction=-1, settings=settings)


def crossroads(*, length_m: float | None = None, angle_rad: float = math.pi / 2,
               settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """CROSSROADS: two roads, each ``length_m`` long, crossing at their middles, ``(C, 0)``
    with ``C = length_m / 2``; the side road at ``angle_rad`` to the main road (pi/2, the
    default: perpendicular; the rules allow 45-degree crossings too, rules summary section 7).
    White = union of both lanes; the edge lines are broken where the other road passes.
    Ports: entry, exit = ``Pose2(length_m, 0, 0)``, side_in = ``Pose2(C - C cos a, -C sin a,
    a)``, side_out = ``Pose2(C + C cos a, C sin a, a)`` (side road travelled away from -y).

    ``length_m`` (default 0.6 m at 90 degrees, else the smallest that fits) is at least
    ``road_width (1 + cos a) / sin a``: at 90 degrees the road width (a square), at 45
    degrees 2.41 road widths: then the side road's ends clear the main road and the piece
    stays between its entry and exit lines, as every piece does."""
    s = _check_settings(settings)
    angle_rad = check_range("angle_rad", angle_rad, math.radians(30.0), math.radians(150.0),
                            lo_open=False, why="30 to 150 degrees")
    perpendicular = angle_rad == math.pi / 2
    need = s.road_width_m if perpendicular else (
        s.road_width_m * (1.0 + abs(math.cos(angle_rad))) / math.sin(angle_rad))
    if length_m is None:
        length_m = 0.6 if perpendicular else need
    length_m = check_range("length_m", length_m, need, lo_open=False,
                           why="at least the road width" if perpendicular else
                           f"at least {need:.3f} m for a {math.degrees(angle_rad):g}-degree crossing")
    h, e, c = s.lane_width_m / 2.0, s.edge_width_m, length_m / 2.0
    if perpendicular:  # (the square of the thesis's figure 8, built as it always was)
        lane = shapely.union(rect(0.0, -h, length_m, h), rect(c - h, -c, c + h, c))
        corners = []
        for sx in (-1.0, 1.0):          # left / right of the side road
            for sy in (-1.0, 1.0):      # below / above the main road
                # L-shape: a main-road edge stub from the piece's end to the side lane, and a
                # side-road edge stub from the main lane to the piece's side; they share the corner.
                (x0, x1), (y0, y1) = sorted((c + sx * c, c + sx * h)), sorted((sy * h, sy * (h + e)))
                stub_x = rect(x0, y0, x1, y1)
                (x0, x1), (y0, y1) = sorted((c + sx * h, c + sx * (h + e))), sorted((sy * h, sy * c))
                corners.append(shapely.union(stub_x, rect(x0, y0, x1, y1)))
        edges = shapely.union_all(corners)
        side = [[c, -c], [c, c]]
        side_in, side_out = Pose2(c, -c, math.pi / 2), Pose2(c, c, math.pi / 2)
        params = {"length_m": length_m}
    else:
        def side_road(half_width: float):
            band = rect(-c, -half_width, c, half_width)
            return shapely.affinity.translate(shapely.affinity.rotate(band, angle_rad, origin=(0, 0),
                                                                      use_radians=True), c, 0.0)

        lane = shapely.union(rect(0.0, -h, length_m, h), side_road(h))
        road = shapely.union(rect(0.0, -h - e, length_m, h + e), side_road(h + e))
        edges = road.difference(lane)
        ca, sa = c * math.cos(angle_rad), c * math.sin(angle_rad)
        side = [[c - ca, -sa], [c + ca, sa]]
        side_in, side_out = Pose2(c - ca, -sa, angle_rad), Pose2(c + ca, sa, angle_rad)
        params = {"length_m": length_m, "angle_rad": angle_rad}
    return Piece(
        kind=PieceType.CROSSROADS, settings=s, params=params,
        lane=lane, edges=edges, marking=None,
        centreline=[[0.0, 0.0], [length_m, 0.0]],
        side_centreline=side,
        ports={"entry": Pose2(), "exit": Pose2(length_m, 0.0, 0.0),
               "side_in": side_in, "side_out": side_out},
        length_m=length_m,
    )


TUNNEL_CLEARANCE_M = 0.30   # ours: the roof's underside above the track (a car with its camera mast)
TUNNEL_WALL_M = 0.05        # ours: the walls stand this far outside the road, this thick


def tunnel(*, length_m: float = 1.0, transmission: float = 0.15,
           settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """TUNNEL: a straight ``length_m`` long under a roof that lets ``transmission`` (0 .. 1)
    of the light reach its floor (the track's lighting gets a shade over it:
    ``trackgen.chain.Track.lighting``); its roof and walls are drawn in the Gazebo world
    (``TUNNEL_CLEARANCE_M`` high, ``TUNNEL_WALL_M`` outside the road)."""
    transmission = check_range("transmission", transmission, 0.0, 1.0, unit="", lo_open=False)
    piece = _straight(PieceType.TUNNEL, length_m, settings)
    return Piece(kind=piece.kind, settings=piece.settings,
                 params={"length_m": piece.length_m, "transmission": transmission},
                 lane=piece.lane, edges=piece.edges, marking=None, centreline=piece.centreline,
                 ports=piece.ports, length_m=piece.length_m)


def hill(*, length_m: float = 1.44, height_m: float = 0.10,
         settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """HILL: a straight ``length_m`` long (on the floor) lifted by a raised-cosine hill
    ``height_m`` high at its middle (:class:`worlds.terrain.Hill`: up, crest, down, zero slope at
    both ends). Its 2D footprint is a straight's; its meshes, the physics and the cameras follow
    the hill. At most 45 degrees steep here (``height_m <= length_m / pi``); the car's own
    limits are :mod:`trackgen.validate`'s."""
    piece = _straight(PieceType.HILL, length_m, settings)
    height_m = check_range("height_m", height_m, 0.0, piece.length_m / math.pi,
                           why="a hill at most 45 degrees steep (height <= length / pi)")
    return Piece(kind=piece.kind, settings=piece.settings,
                 params={"length_m": piece.length_m, "height_m": height_m},
                 lane=piece.lane, edges=piece.edges, marking=None, centreline=piece.centreline,
                 ports=piece.ports, length_m=piece.length_m)


def extender(*, length_m: float = 0.17, settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """EXTENDER: the official kit's short straight (0.17 m: a 45-degree kit turn's centreline
    radius, 0.445 m, is half a kit crossing, 0.275 m, plus one extender)."""
    return _straight(PieceType.EXTENDER, length_m, settings)


def _speed_limit(kind: PieceType, stripes: int, length_m: float, stripe_length_m: float,
                 stripe_width_m: float, settings: TrackSettings) -> Piece:
    s = _check_settings(settings)
    length_m = check_range("length_m", length_m, 0.0)
    stripe_length_m = check_range("stripe_length_m", stripe_length_m, 0.0, length_m, hi_open=True,
                                  why="shorter than the piece")
    h = s.lane_width_m / 2.0
    across = (2 * stripes - 1) * stripe_width_m  # stripes and the gaps between them (gap = stripe width)
    check_range("stripe_width_m", stripe_width_m, 0.0, s.lane_width_m / (2 * stripes - 1), hi_open=True,
                why=f"{stripes} stripes and their gaps inside the lane")
    x0 = (length_m - stripe_length_m) / 2.0
    marks = [rect(x0, -across / 2 + 2 * i * stripe_width_m, x0 + stripe_length_m,
                  -across / 2 + (2 * i + 1) * stripe_width_m) for i in range(stripes)]
    marking = shapely.MultiPolygon(marks)
    return Piece(
        kind=kind, settings=s,
        params={"length_m": length_m, "stripe_length_m": stripe_length_m, "stripe_width_m": stripe_width_m},
        lane=shapely.difference(rect(0.0, -h, length_m, h), marking), edges=_straight_edges(length_m, s),
        marking=marking, centreline=[[0.0, 0.0], [length_m, 0.0]],
        ports={"entry": Pose2(), "exit": Pose2(length_m, 0.0, 0.0)},
        length_m=length_m,
    )


def speed_limit_start(*, length_m: float = 0.72, stripe_length_m: float = 0.30, stripe_width_m: float = 0.05,
                      settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """SPEED_LIMIT_START: a straight with the rules' 4 black stripes along the lane (each
    ``stripe_length_m`` x ``stripe_width_m``, gaps as wide as a stripe, centred on the piece):
    the speed-limit zone begins (../shared/reference/nxp-cup-rules.md, section 1.2)."""
    return _speed_limit(PieceType.SPEED_LIMIT_START, 4, length_m, stripe_length_m, stripe_width_m, settings)


def speed_limit_end(*, length_m: float = 0.72, stripe_length_m: float = 0.30, stripe_width_m: float = 0.05,
                    settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """SPEED_LIMIT_END: as :func:`speed_limit_start` with 3 stripes: the zone ends."""
    return _speed_limit(PieceType.SPEED_LIMIT_END, 3, length_m, stripe_length_m, stripe_width_m, settings)


def wave_geometry(period_m: float, swing_m: float) -> tuple[float, float]:
    """Arc angle ``theta = 2 atan(2 swing / period)`` (rad) and radius ``R = period / (4 sin
    theta)`` (m) of the four arcs (left, right, right, left, each ``theta``) of one wave of
    ``period_m`` that swings ``swing_m`` side to side and ends where it started across."""
    theta = 2.0 * math.atan2(2.0 * swing_m, period_m)
    return theta, period_m / (4.0 * math.sin(theta))


def wave(*, length_m: float = 1.44, swing_m: float = 0.08557, settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """WAVE: the rules' chicane (../shared/reference/nxp-cup-rules.md, section 1.2): two waves
    over ``length_m``, each four circular arcs of equal radius (left, right, right, left;
    :func:`wave_geometry`), the lane swinging ``swing_m`` to the left and back; exit at
    ``Pose2(length_m, 0, 0)``. The kit's: 1.44 m, swing 85.57 mm, arcs of R0.400 (its edge
    lines are drawn as R400 arcs; here the centreline is, the lines follow it at the lane's
    half width). ``min_radius_m`` is not the arcs' (tighter than the default car turns) but
    that of the smoothest path a point can take through the lane, which swings
    ``max(0, swing - lane width)``: infinite (straight) for the kit's wave."""
    s = _check_settings(settings)
    length_m = check_range("length_m", length_m, 0.0)
    swing_m = check_range("swing_m", swing_m, 0.0)
    theta, radius_m = wave_geometry(length_m / 2.0, swing_m)
    half_road = s.road_width_m / 2.0
    if not radius_m > half_road:
        raise PieceError(f"swing_m={swing_m:g} with length_m={length_m:g}: arc radius {radius_m:.4g} m must "
                         f"exceed half the road width {half_road:g} m (use a smaller swing or a longer piece)")
    n = arc_segments(theta, radius_m + half_road, s.arc_tolerance_m)
    pts, yaw = np.zeros((1, 2)), np.zeros(1)
    for turn in (1, -1, -1, 1, 1, -1, -1, 1):
        p, y = arc_samples(radius_m, theta, turn, n, start_xy=tuple(pts[-1]), start_yaw_rad=float(yaw[-1]))
        pts, yaw = np.vstack([pts, p[1:]]), np.concatenate([yaw, y[1:]])
    pts[-1], yaw[-1] = (length_m, 0.0), 0.0  # exact exit edge (rounding ~1e-16 otherwise)
    lane, edges = road_bands(pts, yaw, s.lane_width_m, s.edge_width_m)
    slack = max(0.0, swing_m - s.lane_width_m)
    smooth = math.inf if slack == 0.0 else wave_geometry(length_m / 2.0, slack)[1]
    return Piece(
        kind=PieceType.WAVE, settings=s, params={"length_m": length_m, "swing_m": swing_m},
        lane=lane, edges=edges, marking=None, centreline=pts,
        ports={"entry": Pose2(), "exit": Pose2(length_m, 0.0, 0.0)},
        length_m=8.0 * radius_m * theta, min_radius_m=smooth,
    )


_BUILDERS: Mapping[PieceType, Callable[..., Piece]] = {
    PieceType.STRAIGHT: straight,
    PieceType.STRAIGHT_SHORT: straight_short,
    PieceType.CROSSROADS: crossroads,
    PieceType.TUNNEL: tunnel,
    PieceType.HILL: hill,
    PieceType.TURN_LEFT: turn_left,
    PieceType.TURN_RIGHT: turn_right,
    PieceType.CHICANE_LEFT: chicane_left,
    PieceType.CHICANE_RIGHT: chicane_right,
    PieceType.START_FINISH: start_finish,
    PieceType.EXTENDER: extender,
    PieceType.SPEED_LIMIT_START: speed_limit_start,
    PieceType.SPEED_LIMIT_END: speed_limit_end,
    PieceType.WAVE: wave,
}


def make_piece(kind: PieceType, settings: TrackSettings = DEFAULT_SETTINGS, **params: float) -> Piece:
    """Build a piece of ``kind`` from internal-unit keywords (``length_m``, ``radius_m``,
    ``angle_rad``, ``offset_m``, ``mark_length_m``; see ``PARAMS[kind][..].internal``).
    Unknown keywords raise :class:`PieceError`."""
    if not isinstance(kind, PieceType):
        raise PieceError(f"kind={kind!r}: expected a pieces.PieceType")
    allowed = {spec.internal for spec in PARAMS[kind].values()}
    for name in params:
        if name not in allowed:
            raise PieceError(f"{kind.name} has no parameter {name!r}: expected one of "
                             f"{', '.join(sorted(allowed))}")
    return _BUILDERS[kind](settings=settings, **params)


def piece_from_layout(kind: PieceType, params: Mapping[str, float],
                      settings: TrackSettings = DEFAULT_SETTINGS) -> Piece:
    """Build a piece from layout-file names and units (``angle=90`` is degrees,
    lengths in metres); each value is range-checked against ``PARAMS[kind]`` first."""
    if not isinstance(kind, PieceType):
        raise PieceError(f"kind={kind!r}: expected a pieces.PieceType")
    specs = PARAMS[kind]
    internal = {}
    for name, value in params.items():
        if name not in specs:
            known = ", ".join(specs) or "none"
            raise PieceError(f"{kind.name} has no parameter {name!r}: expected one of {known}")
        internal[specs[name].internal] = specs[name].check(value)
    try:
        return make_piece(kind, settings, **internal)
    except PieceError as err:  # limits that depend on settings: speak in layout names
        message = str(err)
        for spec in specs.values():
            message = re.sub(rf"\b{spec.internal}=", f"{spec.name}=", message)
        raise PieceError(message) from None
