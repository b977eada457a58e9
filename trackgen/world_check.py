"""``trackgen validate`` of an imported Gazebo world (no track.json, e.g. NXP's ``nxp_raceway``).

A world has no layout to re-check, so this measures what the car needs from the road
itself, with shapely only (no simulator import):

1. the world is read as ``simrunner drive`` reads it (``worlds.sdf_read.read_world`` and
   ``worlds.mesh_read.scene_triangles``: the same limits, the same one-line errors);
2. the road footprint is the union of every visual's upward faces, closed by
   :data:`CRACK_M` (meshes from other tools leave sub-millimetre cracks between their
   triangles that a camera never sees);
3. the start is the car's pose in the world, else the world origin heading +x (as the
   simulator chooses it); it must be on the road (within :data:`START_TOL_M`, one raster
   pixel);
4. the centreline is traced from the start: every :data:`STEP_M` the point moves to the
   middle of the road measured across the current heading, then on along it; where the
   road across is over 1.5 times its usual width (a crossing, a junction) it goes straight
   on. The trace ends when it is back at the start (a loop) or leaves the road;
5. checks against the car: the road width (median and narrowest across the traced
   centreline, road = lane + edge lines) against the car's chassis width, and the tightest
   centreline radius (circle through points :data:`RADIUS_SPAN_M` apart along the trace:
   a turn shorter than that reads wider than it is) against the car's minimum turning
   radius ``wheelbase / tan(steering limit)``, with :data:`RADIUS_TOL` relative slack for
   the tracing's noise. Tighter than that is a warning when the car can still take the turn
   by moving towards the outside of the turn (radius + half the road width - half the car's width reaches the
   minimum radius: the centreline is only estimated, and NXP's own ``nxp_raceway`` has
   such a hairpin, about 0.36 m against the default car's 0.414 m), an error otherwise.

Problems are :class:`trackgen.validate.Problem` with ``line=None`` (a world is not a layout)
and checks ``road_width``, ``turn_radius``, ``start``, ``trace`` (a trace that does not
come back is a warning: the other checks then cover the part traced).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from pieces.pose import Pose2
from vehicle.description import CarDescription

from .errors import TrackError
from .validate import Problem

CRACK_M = 0.003  # cracks narrower than 2 x this are closed
STEP_M = 0.02  # trace step along the road
HEADING_SPAN_STEPS = 10  # heading = direction of the last 10 steps (0.2 m) of the trace
SEARCH_M = 3.0  # how far across the road its edges are looked for
RADIUS_SPAN_M = 0.25  # chord half-length of the curvature estimate
RADIUS_TOL = 0.05  # relative slack on the minimum turning radius
START_TOL_M = 0.005  # start within this of the road counts as on it (one raster pixel)
MAX_TRACE_M = 2000.0  # a trace longer than this stops (the world is at most 50 m x 50 m)


@dataclass(frozen=True, eq=False)
class Trace:
    """A traced centreline: ``points (N, 2)`` metres in driving order, ``widths (N,)`` road
    width across each point (nan where it was not measured: crossings), ``closed`` when it
    came back to the start, ``end`` the last point."""

    points: np.ndarray
    widths: np.ndarray
    closed: bool

    @property
    def length_m(self) -> float:
        d = np.diff(self.points, axis=0)
        return float(np.hypot(d[:, 0], d[:, 1]).sum())


@dataclass(frozen=True, eq=False)
class WorldRoad:
    """A world read as the simulator reads it: its ``scene``, the road footprint ``road``
    (shapely), the ``start`` pose and where it comes from (``origin``, the simulator's words)."""

    scene: object
    road: object
    start: Pose2
    origin: str

    def start_problems(self) -> list[Problem]:
        """The start off the road (the simulator refuses to drive then)."""
        s = self.start
        if self.road.distance(shapely.Point(s.x_m, s.y_m)) <= START_TOL_M:
            return []
        return [Problem(str(self.scene.source), None, (
            f"the start pose ({s.x_m:.3f}, {s.y_m:.3f}) m ({self.origin}) is not on the track"),
            "start")]


def read_world_road(path: str | Path) -> WorldRoad:
    """Read a world in the simulator's order and with its errors (``read_world``, then
    track.json's fields, then every mesh within the limits): ``worlds.WorldError``, or
    :class:`TrackError` for a world with nothing to drive on."""
    from worlds.mesh_read import scene_triangles, upward
    from worlds.sdf_read import read_world
    from worlds.track_json import read_track_json

    scene = read_world(path)
    meta = read_track_json(scene.track_json) if scene.track_json is not None else {}
    tris = scene_triangles(scene)
    tops = [upward(t)[:, :, :2] for t in tris.visuals]
    tops = [t for t in tops if len(t)]
    if not tops:
        raise TrackError(f"{scene.source}: the world has no mesh visuals with upward faces "
                         "(nothing to drive on)")
    if scene.car_pose is not None:  # the simulator's rule (simrunner.track.load)
        start, origin = scene.car_pose, "the car's pose in the world"
    elif "start_pose" in meta:
        start, origin = meta["start_pose"], "track.json's start_pose"
    else:
        start, origin = Pose2(), "no car in the world and no track.json: the world origin"
    return WorldRoad(scene, road_footprint(np.concatenate(tops)), start, origin)


def validate_world(path: str | Path, car: CarDescription | None = None, *,
                   sdf_checker: bool = True) -> list[Problem]:
    """Problems of an imported world or model folder/file (module docstring). Raises
    ``worlds.WorldError`` for a world the simulator refuses too, :class:`TrackError` for one
    with nothing to drive on."""
    from worlds.check import check_world

    car = car or CarDescription()
    world = read_world_road(path)
    where = str(world.scene.source)
    problems = [Problem(where, None, msg, "world")
                for msg in check_world(world.scene.source, use_ign=sdf_checker)]
    start = world.start_problems()
    if start:
        return problems + start
    trace = trace_centreline(world.road, world.start)
    problems += _width_problems(where, trace, car)
    problems += _radius_problems(where, trace, car)
    if not trace.closed:
        x, y = trace.points[-1]
        problems.append(Problem(where, None, (
            f"the road could not be followed around a loop from the start: the trace ends at "
            f"({x:.2f}, {y:.2f}) m after {trace.length_m:.2f} m; width and curvature were "
            "checked on that part only"), "trace", warning=True))
    return problems


def road_footprint(triangles_xy: np.ndarray):
    """Union of ``(T, 3, 2)`` triangles, cracks narrower than ``2 * CRACK_M`` closed."""
    tri = shapely.polygons(np.concatenate([triangles_xy, triangles_xy[:, :1]], axis=1))
    tri = tri[shapely.area(tri) > 0]
    road = shapely.union_all(tri, grid_size=1e-6)
    road = road.buffer(CRACK_M, join_style="mitre").buffer(-CRACK_M, join_style="mitre")
    shapely.prepare(road)
    return road


def _edges(road) -> tuple[np.ndarray, np.ndarray]:
    """Boundary segments of a (Multi)Polygon: start points ``(M, 2)`` and end points ``(M, 2)``."""
    a, b = [], []
    for ring in shapely.get_rings(shapely.get_parts(road)):
        c = np.asarray(ring.coords)
        a.append(c[:-1])
        b.append(c[1:])
    return np.concatenate(a), np.concatenate(b)


def _across(p: np.ndarray, n: np.ndarray, a: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """Offsets along ``n`` from ``p`` to the nearest boundary crossing on each side
    (``-SEARCH_M``, ``SEARCH_M`` when none): segments ``a + s d``, ``s`` in [0, 1]."""
    denom = n[0] * d[:, 1] - n[1] * d[:, 0]
    ok = np.abs(denom) > 1e-15
    w = a[ok] - p
    t = (w[:, 0] * d[ok, 1] - w[:, 1] * d[ok, 0]) / denom[ok]
    s = (w[:, 0] * n[1] - w[:, 1] * n[0]) / denom[ok]
    t = t[(s >= 0.0) & (s <= 1.0) & (np.abs(t) <= SEARCH_M)]
    neg, pos = t[t <= 0.0], t[t > 0.0]
    return (float(neg.max()) if len(neg) else -SEARCH_M), (float(pos.min()) if len(pos) else SEARCH_M)


def trace_centreline(road, start: Pose2) -> Trace:
    """Follow the middle of ``road`` from ``start`` (module docstring, step 4)."""
    a, b = _edges(road)
    d = b - a
    p = np.array([start.x_m, start.y_m], dtype=float)
    heading = start.yaw_rad
    pts: list[np.ndarray] = []
    widths: list[float] = []
    measured: list[float] = []
    closed = False
    for _ in range(int(MAX_TRACE_M / STEP_M)):
        if not shapely.contains_xy(road, p[0], p[1]) and road.distance(shapely.Point(p)) > START_TOL_M:
            break
        n = np.array([-math.sin(heading), math.cos(heading)])
        lo, hi = _across(p, n, a, d)
        width = hi - lo
        usual = float(np.median(measured[-100:])) if len(measured) >= 5 else None
        if usual is None or width < 1.5 * usual:
            p = p + n * (lo + hi) / 2.0
            measured.append(width)
            widths.append(width)
        else:
            widths.append(math.nan)  # a crossing: straight on
        pts.append(p)
        if len(pts) > HEADING_SPAN_STEPS:
            step = pts[-1] - pts[-1 - HEADING_SPAN_STEPS]
            heading = math.atan2(step[1], step[0])
        p = p + STEP_M * np.array([math.cos(heading), math.sin(heading)])
        if len(pts) * STEP_M > 1.0 and np.hypot(*(p - pts[0])) < 1.5 * STEP_M:
            closed = True
            break
    points = np.asarray(pts, dtype=float).reshape(-1, 2)
    return Trace(points, np.asarray(widths, dtype=float), closed)


def tightest_radius(points: np.ndarray, closed: bool) -> tuple[float, np.ndarray] | None:
    """Smallest radius of the circles through points ``RADIUS_SPAN_M`` before and after each
    point of a polyline sampled every ``STEP_M``, and where; None when it is too short."""
    k = max(1, int(round(RADIUS_SPAN_M / STEP_M)))
    pts = np.concatenate([points[-k:], points, points[:k]]) if closed else points
    if len(pts) < 2 * k + 1:
        return None
    p0, p1, p2 = pts[:-2 * k], pts[k:-k], pts[2 * k:]
    ab, bc, ca = (np.linalg.norm(p1 - p0, axis=1), np.linalg.norm(p2 - p1, axis=1),
                  np.linalg.norm(p0 - p2, axis=1))
    cross = np.abs((p1 - p0)[:, 0] * (p2 - p0)[:, 1] - (p1 - p0)[:, 1] * (p2 - p0)[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(cross > 1e-12, ab * bc * ca / (2.0 * cross), math.inf)
    i = int(np.argmin(radius))
    return float(radius[i]), p1[i]


def _width_problems(where: str, trace: Trace, car: CarDescription) -> list[Problem]:
    widths = trace.widths[np.isfinite(trace.widths)]
    if len(widths) == 0:
        return []
    need = car.chassis.width_m
    i = int(np.nanargmin(trace.widths))
    x, y = trace.points[i]
    if widths.min() < need:
        return [Problem(where, None, (
            f"the road is {widths.min():.3f} m wide at ({x:.2f}, {y:.2f}) m (median "
            f"{np.median(widths):.3f} m): narrower than the car (chassis width {need:.3f} m)"),
            "road_width")]
    return []


def _radius_problems(where: str, trace: Trace, car: CarDescription) -> list[Problem]:
    found = tightest_radius(trace.points, trace.closed)
    if found is None:
        return []
    radius, xy = found
    need = car.min_turn_radius_m
    if radius >= need * (1.0 - RADIUS_TOL):
        return []
    near = np.hypot(*(trace.points - xy).T) <= RADIUS_SPAN_M
    widths = trace.widths[near & np.isfinite(trace.widths)]
    width = float(widths.min()) if len(widths) else float(np.nanmedian(trace.widths))
    outside = radius + (width - car.chassis.width_m) / 2.0  # the widest path inside the road
    text = (f"the centreline's radius is about {radius:.3f} m at ({xy[0]:.2f}, {xy[1]:.2f}) m: "
            f"tighter than the car's minimum turning radius {need:.3f} m (wheelbase / "
            f"tan(steering limit), thesis eq. 5.1)")
    if outside >= need:
        return [Problem(where, None, f"{text}; the car can take it only off the centreline, "
                        f"towards the outside of the turn", "turn_radius", warning=True)]
    return [Problem(where, None, f"{text}, even along the outside of the {width:.3f} m road",
                    "turn_radius")]
