"""Lap counting and off-track detection from the car's poses (no physics, no rendering).

Laps. The gate is the segment through ``track.gate`` across its heading, ``+-
track.gate_half_width_m`` long on each side. A lap is counted when the rear-axle midpoint
(the car pose's origin) crosses that segment in the gate's heading direction after travelling
at least ``min_lap_fraction * track.lap_length_m`` since the previous counted crossing.
Crossings are found between consecutive updates on the straight line joining the two
positions; the crossing time (and distance) is interpolated linearly.
- Lap 1 starts at the first update if the car stands on the gate line then (within
  ``on_gate_tol_m`` along the gate heading, inside the segment): NXP's worlds start the car
  on the gate, so timing starts at t = 0.
- Otherwise lap 1 starts at the first forward crossing (trackgen's START_FINISH tracks start
  the car 0.3 m behind the gate): that crossing needs no minimum distance.
- Crossing backwards emits a ``"gate_backward"`` event and never counts; a forward crossing
  too soon after the last one (less than the minimum distance) is ignored.
- A lap follows the course (``track.course``, :mod:`simrunner.track.course`: the layout's
  pieces in order, crossings straight on; a world's traced centreline). The rear-axle
  midpoint is followed along the course's centreline (projected onto the part near where it
  was, never onto the other branch of a crossing). The car leaves the course when it is
  farther than half the road (``track.gate_half_width_m``) + ``OFF_COURSE_MARGIN_M`` from
  that part (it turned at a crossing, or cut across to another part of the track), or when
  it has driven ``BACKWARD_LIMIT_M`` back along the course: an ``"off_course"`` event names
  the place (``turned at CROSSROADS (piece 38, line 41)``; on a traced course the distance
  from the finish line) and the lap in progress cannot count. A forward crossing counts as a
  lap only when the car followed the course since the lap started, at least its length less
  ``COURSE_SLACK_M``; otherwise a ``"lap_short"`` event says why (timing restarts). After
  leaving the course the car is found again on the nearest part of the course once it is
  back on it (a run that keeps driving).
- Without a course (a world whose road could not be traced around a loop) shortcuts are
  caught by coverage: the road is divided into square cells of ``COVERAGE_CELL_M``; a cell
  is visited when the rear-axle midpoint passes within ``COVERAGE_REACH_CELLS`` cells of it.
  A forward crossing counts as a lap only if at least ``min_coverage`` (default 0.8) of the
  road's cells were visited since the lap started; otherwise a ``"lap_short"`` event says
  how much of the track was skipped.
- After ``laps`` laps the judge is ``finished`` and counts no more (nor follows the course).

Off track. A wheel is off the road when every sample of its contact patch lies outside
``track.road_mask``; the patch is modelled as a segment across the tyre (along the car's
lateral axis, the front wheels' steering ignored), ``tyre_width_m`` long, centred on the
wheel's contact point, sampled at ``PATCH_SAMPLES`` points. Edge lines and markings belong to
the road, so a wheel on the black edge line is on the road; a wheel overhanging the edge is on
the road while any part of its tyre touches it. ``wheel_off="any_part"`` is the stricter rule
of the rules' other disciplines (rules summary section 4: "no part of any wheel may leave the
track"): a wheel is off as soon as any sample of its contact patch lies outside the road.
``off_track`` is True while any wheel is off; ``"off_track"`` / ``"on_track"`` events mark the
changes.

Events: ``Event(t_s, kind, text)`` with ``kind`` an :class:`EventKind` (a ``str``):
``lap_start``, ``lap``, ``lap_short``, ``finished``, ``gate_backward``, ``off_track``,
``on_track``, ``off_course``.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.track.progress import CentrelineProgress

WHEEL_NAMES = ("FL", "FR", "RL", "RR")
PATCH_SAMPLES = 5
WHEEL_OFF_RULES = ("whole", "any_part")  # a wheel is off when its whole tyre / any part of it is off the road
COVERAGE_CELL_M = 0.25
COVERAGE_REACH_CELLS = 2      # cells within 2 cells (0.5-0.75 m) of the car count as visited
COVERAGE_ROAD_FRACTION = 0.25  # a cell is road when at least this share of it is road
# The course: with fewer than 3 wheels off (the rules' limit, rules summary section 3) the
# rear-axle midpoint stays within half a car width of the road's edge; 0.15 m covers the
# widest 1:10 car (track 0.25 m) with margin, and is less than half a crossing's arm, so a
# car turning at a crossing is caught on the crossing road's first piece.
OFF_COURSE_MARGIN_M = 0.15
BACKWARD_LIMIT_M = 1.0   # driving back along the course this far leaves it (a U-turn)
COURSE_SLACK_M = 0.5     # a lap follows at least the course's length less this


class EventKind(enum.StrEnum):
    """What happened (see the module docstring)."""

    LAP_START = "lap_start"
    LAP = "lap"
    LAP_SHORT = "lap_short"          # gate crossed after a shortcut: not counted
    FINISHED = "finished"
    GATE_BACKWARD = "gate_backward"
    OFF_TRACK = "off_track"
    ON_TRACK = "on_track"
    OFF_COURSE = "off_course"        # turned at a crossing, cut across, drove back


@dataclass(frozen=True)
class Event:
    t_s: float
    kind: EventKind
    text: str


class Judge:
    """Referee of one run on ``track`` (a ``SimTrack``) for ``laps`` laps."""

    def __init__(self, track, *, laps: int, min_lap_fraction: float = 0.5,
                 min_coverage: float = 0.8, tyre_width_m: float = 0.025,
                 on_gate_tol_m: float = 0.02, wheel_off: str = "whole") -> None:
        if int(laps) < 1:
            raise SimError(f"Judge: laps must be >= 1, got {laps!r}")
        if not 0.0 <= float(min_lap_fraction) <= 1.0:
            raise SimError(f"Judge: min_lap_fraction must be in [0, 1], got {min_lap_fraction!r}")
        self.track = track
        self.laps = int(laps)
        self.min_lap_distance_m = float(min_lap_fraction) * float(track.lap_length_m)
        self.on_gate_tol_m = float(on_gate_tol_m)
        self._patch = np.linspace(-tyre_width_m / 2.0, tyre_width_m / 2.0, PATCH_SAMPLES)
        if wheel_off not in WHEEL_OFF_RULES:
            raise SimError(f"Judge: wheel_off must be one of {', '.join(WHEEL_OFF_RULES)}, got {wheel_off!r}")
        self.any_part = wheel_off == "any_part"
        self._half_tyre_m = 0.5 * float(tyre_width_m)
        g = track.gate
        self._gate_x, self._gate_y = float(g.x_m), float(g.y_m)
        self._gate_dx, self._gate_dy = math.cos(g.yaw_rad), math.sin(g.yaw_rad)
        self._half = float(track.gate_half_width_m)
        self._prev: tuple[float, float, float, float] | None = None  # t, s, l, distance
        self._prev_xy: np.ndarray | None = None
        self._distance_m = 0.0
        self._lap_start: tuple[float, float] | None = None  # t, distance
        self._lap_times: list[float] = []
        self._lap_distances: list[float] = []
        self._lap_courses: list[float] = []
        self._off_wheels: tuple[str, ...] = ()
        self.min_coverage = float(min_coverage)
        self._init_coverage(track.raster)
        self._init_fast_lookup(track.raster)
        self.course = getattr(track, "course", None)
        self._follow = None if self.course is None else CentrelineProgress(self.course.centreline)
        self._course_tol_m = float(track.gate_half_width_m) + OFF_COURSE_MARGIN_M
        self._lap_progress_m = 0.0   # along the course since the lap started
        self._best_progress_m = 0.0  # its largest value (driving back is measured from it)
        self._lap_left_course = ""   # why the lap in progress cannot count ("" : it can)
        self._lost = False           # off the course, not yet back on it
        self._off_course = ""        # the last off-course text
        self._course_s0: float | None = None  # where the car started along the course
        self.finish_t_s: float | None = None         # when the last lap was completed
        self.finish_distance_m: float | None = None  # distance_m then

    def _init_coverage(self, raster) -> None:
        mask = np.asarray(raster.road_mask, dtype=bool)
        k = max(1, int(round(COVERAGE_CELL_M / raster.m_per_px)))
        h, w = mask.shape
        hc, wc = -(-h // k), -(-w // k)
        padded = np.zeros((hc * k, wc * k), dtype=np.float32)
        padded[:h, :w] = mask
        share = padded.reshape(hc, k, wc, k).mean(axis=(1, 3))
        self._cov_road = share >= COVERAGE_ROAD_FRACTION
        self._cov_visited = np.zeros_like(self._cov_road)
        self._cov_k_px = k
        self._cov_last: tuple[int, int] | None = None  # last cell visited (same cell: no work)

    def _init_fast_lookup(self, raster) -> None:
        self._mask = np.asarray(raster.road_mask, dtype=bool)
        self._mask_h, self._mask_w = self._mask.shape
        self._mask_bytes = self._mask.tobytes()  # row-major, 1 = road: indexing bytes is cheap
        self._ox, self._oy = (float(v) for v in raster.origin_xy_m)
        self._inv_m = 1.0 / float(raster.m_per_px)

    def _px(self, x: float, y: float) -> tuple[int, int]:
        """Nearest pixel (col, row) of a world point (same rule as ``TrackRaster.on_road``)."""
        return round((x - self._ox) * self._inv_m), round((self._oy - y) * self._inv_m)

    def _on_road(self, x: float, y: float) -> bool:
        c, r = self._px(x, y)
        return 0 <= c < self._mask_w and 0 <= r < self._mask_h and bool(self._mask_bytes[r * self._mask_w + c])

    def _visit(self, x: float, y: float) -> None:
        c, r = self._px(x, y)
        k = self._cov_k_px
        cell = (c // k, r // k)
        if cell != self._cov_last:  # else already marked since the last reset
            self._mark_cell(cell)

    def _mark_cell(self, cell: tuple[int, int]) -> None:
        """Mark the coverage cells within reach of ``cell`` (column, row) as visited."""
        ci, ri = cell
        n = COVERAGE_REACH_CELLS
        self._cov_last = cell
        self._cov_visited[max(ri - n, 0):max(ri + n + 1, 0), max(ci - n, 0):max(ci + n + 1, 0)] = True

    @property
    def coverage(self) -> float:
        """Share of the road's cells visited since the current lap started."""
        road = int(self._cov_road.sum())
        return 1.0 if road == 0 else float((self._cov_visited & self._cov_road).sum()) / road

    # -- state ---------------------------------------------------------------------
    @property
    def laps_completed(self) -> int:
        return len(self._lap_times)

    @property
    def lap_times_s(self) -> list[float]:
        return list(self._lap_times)

    @property
    def lap_distances_m(self) -> list[float]:
        """Path length of the rear-axle midpoint in each counted lap (m)."""
        return list(self._lap_distances)

    @property
    def lap_courses_m(self) -> list[float]:
        """Distance followed along the course's centreline in each counted lap (m; empty
        without a course). A counted lap is the course: about its length, whatever line the
        car took (an inside line drives less than the centreline, ``lap_distances_m``)."""
        return list(self._lap_courses)

    @property
    def finished(self) -> bool:
        return self.laps_completed >= self.laps

    @property
    def lap_started_s(self) -> float | None:
        """Start time of the lap being driven (None before lap 1 starts)."""
        return None if self._lap_start is None else self._lap_start[0]

    @property
    def off_track(self) -> bool:
        return bool(self._off_wheels)

    @property
    def off_wheels(self) -> tuple[str, ...]:
        """Names (FL, FR, RL, RR) of the wheels now off the road."""
        return self._off_wheels

    @property
    def off_course(self) -> str:
        """Where the car last left the course (``turned at CROSSROADS (piece 38, line 41)``),
        "" when it never did."""
        return self._off_course

    @property
    def course_s_m(self) -> float | None:
        """Where the car is along the course's centreline (arc length, m; None: no course)."""
        return None if self._follow is None else self._follow.s_m

    @property
    def course_from_start_m(self) -> float | None:
        """Where the car is along the course, measured from where it started (m, in [0, L);
        None: no course)."""
        if self._follow is None or self._course_s0 is None:
            return None
        return (self._follow.s_m - self._course_s0) % self._follow.length_m

    @property
    def course_progress_m(self) -> float:
        """Distance followed along the course since the lap in progress started (m)."""
        return self._lap_progress_m

    @property
    def distance_m(self) -> float:
        """Path length of the rear-axle midpoint so far."""
        return self._distance_m

    # -- update --------------------------------------------------------------------
    def update(self, t_s: float, pose: Pose2, wheel_xy: np.ndarray) -> list[Event]:
        """Feed the state at time ``t_s``: car ``pose`` and wheel contact points ``wheel_xy``
        ``(4, 2)`` world metres (FL, FR, RL, RR). Returns the events since the last update."""
        # (runs every camera frame: plain float arithmetic, the rare cases in other methods)
        t_s = float(t_s)
        x, y = pose.x_m, pose.y_m
        rx, ry = x - self._gate_x, y - self._gate_y
        dx, dy = self._gate_dx, self._gate_dy
        s, lat = rx * dx + ry * dy, -rx * dy + ry * dx
        ox, oy, inv = self._ox, self._oy, self._inv_m
        k = self._cov_k_px  # coverage cell of the nearest pixel (_visit, inlined)
        cell = (round((x - ox) * inv) // k, round((oy - y) * inv) // k)
        if cell != self._cov_last:
            self._mark_cell(cell)
        prev = self._prev
        events: list[Event] = []
        if self._follow is not None and not self.finished:
            events += self._follow_course(t_s, x, y, prev is None)
        if prev is None:
            if abs(s) <= self.on_gate_tol_m and abs(lat) <= self._half:
                self._lap_start = (t_s, 0.0)
                events.append(Event(t_s, EventKind.LAP_START, "lap 1 started (car starts on the gate)"))
        else:
            px, py = self._prev_xy
            self._distance_m += math.hypot(x - px, y - py)
            if (prev[1] < 0.0) != (s < 0.0):  # the gate line was crossed (forwards or backwards)
                events += self._gate_events(t_s, s, lat)
        self._prev = (t_s, s, lat, self._distance_m)
        self._prev_xy = (x, y)
        # fast path: a wheel whose contact point (any_part: both ends of its patch) is on the
        # road is on the road; only the others get the full contact-patch test (_wheel_events)
        w, h, mask = self._mask_w, self._mask_h, self._mask_bytes
        points = wheel_xy.tolist() if isinstance(wheel_xy, np.ndarray) else wheel_xy
        if self.any_part:
            yaw = pose.yaw_rad
            ex, ey = -math.sin(yaw) * self._half_tyre_m, math.cos(yaw) * self._half_tyre_m
            points = [(cx + sx * ex, cy + sx * ey) for cx, cy in points for sx in (-1.0, 1.0)]
        for cx, cy in points:
            c, r = round((cx - ox) * inv), round((oy - cy) * inv)
            if not (0 <= c < w and 0 <= r < h and mask[r * w + c]):
                return events + self._wheel_events(t_s, pose, wheel_xy)
        if self._off_wheels:
            self._off_wheels = ()
            events.append(Event(t_s, EventKind.ON_TRACK, "all wheels back on the track"))
        return events

    def _gate_events(self, t_s: float, s: float, lat: float) -> list[Event]:
        t0, s0, lat0, d0 = self._prev  # (the caller saw a sign change of s)
        forward = s0 < 0.0 <= s
        backward = s < 0.0 <= s0
        if not (forward or backward) or self.finished:
            return []
        f = s0 / (s0 - s)
        if abs(lat0 + f * (lat - lat0)) > self._half:
            return []
        tc = t0 + f * (t_s - t0)
        dc = d0 + f * (self._distance_m - d0)
        if backward:
            return [Event(tc, EventKind.GATE_BACKWARD, "crossed the finish gate backwards (not counted)")]
        if self._lap_start is None:
            self._start_lap(tc, dc)
            return [Event(tc, EventKind.LAP_START, "lap 1 started (first gate crossing)")]
        start_t, start_d = self._lap_start
        if dc - start_d < self.min_lap_distance_m:
            return []
        if self._follow is not None:
            short = self._course_shortfall()
            if short:
                self._start_lap(tc, dc)
                return [Event(tc, EventKind.LAP_SHORT, f"crossed the finish gate {short}: lap not "
                              "counted, timing restarts")]
        elif (coverage := self.coverage) < self.min_coverage:
            self._start_lap(tc, dc)
            return [Event(tc, EventKind.LAP_SHORT, f"crossed the finish gate after driving only "
                          f"{100 * coverage:.0f} % of the track (needs {100 * self.min_coverage:.0f} %):"
                          " lap not counted, timing restarts")]
        self._lap_times.append(tc - start_t)
        self._lap_distances.append(dc - start_d)
        if self._follow is not None:
            self._lap_courses.append(self._lap_progress_m)
        n = self.laps_completed
        events = [Event(tc, EventKind.LAP, f"lap {n} in {tc - start_t:.3f} s")]
        if self.finished:
            self.finish_t_s, self.finish_distance_m = tc, dc
            events.append(Event(tc, EventKind.FINISHED, f"{n} lap{'s' if n > 1 else ''} done in "
                                f"{sum(self._lap_times):.3f} s"))
            self._lap_start = None
        else:
            self._start_lap(tc, dc)
            events.append(Event(tc, EventKind.LAP_START, f"lap {n + 1} started"))
        return events

    def _follow_course(self, t_s: float, x: float, y: float, first: bool) -> list[Event]:
        """Follow the car along the course; an ``off_course`` event when it leaves it."""
        follow = self._follow
        if first or self._lost:
            follow.reset(x, y)
            if first:
                self._course_s0 = follow.s_m
            if self._lost and abs(follow.lateral_m) <= self._course_tol_m:
                self._lost = False  # back on the course (the lap in progress stays void)
                self._best_progress_m = self._lap_progress_m
            return []
        progress = self._lap_progress_m + follow.advance(x, y)
        self._lap_progress_m = progress
        if progress > self._best_progress_m:
            self._best_progress_m = progress
        if abs(follow.lateral_m) > self._course_tol_m:
            section = self.course.section_at(follow.s_m)
            where = self.course.describe(follow.s_m)
            text = (f"turned at {where}" if section is not None and section.kind == "CROSSROADS"
                    else f"left the course at {where}")
        elif progress < self._best_progress_m - BACKWARD_LIMIT_M:
            text = f"drove backwards at {self.course.describe(follow.s_m)}"
        else:
            return []
        self._off_course = text
        self._lap_left_course = self._lap_left_course or text
        self._lost = True
        return [Event(t_s, EventKind.OFF_COURSE, f"{text} at ({x:.2f}, {y:.2f}) m")]

    def _course_shortfall(self) -> str:
        """Why the lap in progress does not count ("" when it does)."""
        if self._lap_left_course:
            return f"after the car {self._lap_left_course}"
        need = self.course.length_m - COURSE_SLACK_M
        if self._lap_progress_m < need:
            return (f"after following only {self._lap_progress_m:.2f} m of the course's "
                    f"{self.course.length_m:.2f} m")
        return ""

    def _start_lap(self, t_s: float, distance_m: float) -> None:
        self._lap_progress_m = self._best_progress_m = 0.0
        self._lap_left_course = self._off_course if self._lost else ""
        self._lap_start = (t_s, distance_m)
        self._cov_visited[:] = False
        self._cov_last = None
        if self._prev_xy is not None:
            self._visit(*self._prev_xy)

    def wheels_on_road(self, pose: Pose2, wheel_xy: np.ndarray) -> np.ndarray:
        """``(4,) bool``: is each wheel on the road: its contact patch touches the road
        anywhere (``wheel_off="any_part"``: everywhere)."""
        wheels = np.asarray(wheel_xy, dtype=float).reshape(4, 2)
        left = np.array([-math.sin(pose.yaw_rad), math.cos(pose.yaw_rad)])
        pts = wheels[:, None, :] + self._patch[None, :, None] * left  # (4, P, 2)
        on = self.track.raster.on_road(pts.reshape(-1, 2)).reshape(4, -1)
        return on.all(axis=1) if self.any_part else on.any(axis=1)

    def _wheel_events(self, t_s: float, pose: Pose2, wheel_xy: np.ndarray) -> list[Event]:
        """Off/on-track events when some wheel's contact point is off the road (the full
        contact-patch test decides)."""
        on = self.wheels_on_road(pose, wheel_xy)
        off = tuple(name for name, ok in zip(WHEEL_NAMES, on) if not ok)
        events = []
        if off and not self._off_wheels:
            events.append(Event(t_s, EventKind.OFF_TRACK, f"wheel{'s' if len(off) > 1 else ''} "
                                f"{', '.join(off)} {'partly ' if self.any_part else ''}off the track at "
                                f"({pose.x_m:.2f}, {pose.y_m:.2f}) m"))
        elif self._off_wheels and not off:
            events.append(Event(t_s, EventKind.ON_TRACK, "all wheels back on the track"))
        self._off_wheels = off
        return events
