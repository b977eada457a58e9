"""The NXP Cup's disciplines as runs (``--event NAME``): each sets up its track, laps, time
limit and off-track rule as the rules describe it, watches what the judge does not (the stop
after the finish, the speed in a zone, an obstacle placed during the run) and scores it.
Numbers from the rules summary (``../shared/reference/nxp-cup-rules.md``): the race section 3,
the other disciplines section 4; "ours" marks what the rules leave open.

| event | track (unless ``--track``) | the run | passed when |
| --- | --- | --- | --- |
| ``race`` | the given track (default: the bundled one) | 1 lap, 120 s, 3 wheels off fail | the lap is done; +1 s when the car does not stop within 2 m after the line |
| ``figure8`` | the kit's M figure 8 | laps until 60 s (``--time-limit 90``: the 2018/19 rules) | the whole time driven without a wheel off; score: laps |
| ``speed_limit`` | the kit's M oval with the zone | from just past the 3-stripe piece to 1.5 m past it again | the zone's speed at most 0.6 x the approach, back to 0.8 x from the 3-stripe piece on |
| ``obstacle`` | the kit's S oval | lap 1 clear, then a white 20 cm cube on a straight ahead (seeded), off the lane's middle | lap 2 done without touching it |
| ``emergency_brake`` | the kit's S oval without marks | 2 laps, then a black 20 x 60 x 20 cm block across a straight ahead (seeded) | the car stops without touching it |

The other disciplines void an attempt when any part of any wheel leaves the track (section 4,
"Common void-attempt conditions"): their runs end when a wheel is first partly off the road
(the judge's ``wheel_off="any_part"``; the race's rule is a wheel wholly off, 3 of them).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simrunner.run.result import Outcome
from simrunner.run.settings import SettingsError
from simrunner.run.rules import EVENTS, STOPPED_MPS, EventRules, Penalty, StopCheck

EVENT_TRACKS = Path(__file__).resolve().parent.parent / "data" / "events"
SPEED_LIMIT_SLOW = 0.6       # ours: "about half" the approach speed (section 4.3: not specified)
SPEED_LIMIT_BACK = 0.8       # ours: back to this share of the approach speed after the zone ...
SPEED_LIMIT_AFTER_M = 1.5    # ... within this far past the 3-stripe piece
SPEED_LIMIT_SETTLE_M = 0.5   # ours: the zone's first 0.5 m are for braking (not judged)
APPROACH_M = 1.0             # the approach speed: the mean over the last metre before the zone




def event_track(name: str) -> Path | None:
    """The layout the discipline is run on by default (None: the run's own track)."""
    layout = EVENTS[name].layout
    return None if layout is None else EVENT_TRACKS / layout


@dataclass
class Verdict:
    """How the discipline went: ``passed``, the ``points`` (None: rank-based), ``penalties``
    and ``details`` (measured numbers, for the summary)."""

    passed: bool = False
    points: int | None = None
    penalties: list[Penalty] = field(default_factory=list)
    details: dict = field(default_factory=dict)


class EventMonitor:
    """Watches one run of a discipline; the frame loop (:class:`simrunner.run.runner.FrameWork`)
    calls :meth:`frame` every camera frame, :meth:`at_laps` once the judge has counted its laps
    and :meth:`at_time_limit` at the limit; each returns ``(outcome, message)`` to end the run
    or None. ``verdict`` is the result."""

    def __init__(self, rules: EventRules, run):
        self.rules = rules
        self.run = run  # the run's parts (track, sim, judge, objects)
        self.verdict = Verdict(points=None)

    def frame(self, t_s: float, pose, speed_mps: float) -> tuple[Outcome, str] | None:
        return None

    def at_laps(self, t_s: float, speed_mps: float, off: bool) -> tuple[Outcome, str] | None:
        self.verdict.passed = True
        self.verdict.points = self.rules.points
        return Outcome.FINISHED, f"{self.run.judge.laps_completed} lap(s) completed"

    def at_time_limit(self, t_s: float) -> tuple[Outcome, str]:
        return Outcome.TIMEOUT, f"time limit of {self.run.time_limit_s:g} s simulated time reached"

    def failed(self, outcome: Outcome) -> None:
        """The run ended otherwise (off track, off course, a touch, a fault): not passed."""
        self.verdict.passed = False
        self.verdict.points = 0 if self.rules.points is not None else None


class RaceMonitor(EventMonitor):
    """The race: after the lap, the stop within 2 m of the line (:class:`StopCheck`)."""

    stop: StopCheck | None = None

    def at_laps(self, t_s, speed_mps, off):
        judge = self.run.judge
        if self.stop is None:
            self.stop = StopCheck(judge.finish_t_s, judge.finish_distance_m)
        verdict = self.stop.update(t_s, judge.distance_m, speed_mps, int(off),
                                   time_up=t_s >= self.run.time_limit_s - 1e-9)
        if verdict is None:
            return None
        return Outcome.FINISHED, f"{judge.laps_completed} lap(s) completed; {self._stop_verdict(verdict)}"

    def _stop_verdict(self, verdict) -> str:
        text, penalty = verdict
        if penalty is not None:
            self.verdict.penalties.append(penalty)
            text += f" (+{penalty.seconds:g} s)"
        self.verdict.passed = True
        return text

    def failed(self, outcome: Outcome) -> None:
        """After the lap the attempt counts whatever ends the run; the stop is judged on the
        state it ended in (main returned while rolling: +1 s)."""
        judge = self.run.judge
        if not judge.finished or self.verdict.passed:
            super().failed(outcome)
            return
        if self.stop is None:
            self.stop = StopCheck(judge.finish_t_s, judge.finish_distance_m)
        sim = self.run.sim
        verdict = self.stop.update(sim.time_s, judge.distance_m, sim.speed_mps,
                                   int(len(judge.off_wheels) >= self.run.settings.off_track_wheels), time_up=True)
        self.verdict.details["stop"] = self._stop_verdict(verdict)


class Figure8Monitor(EventMonitor):
    """As many complete laps as the time allows; the attempt counts when the whole time was
    driven cleanly (section 4.1)."""

    def at_time_limit(self, t_s):
        n = self.run.judge.laps_completed
        self.verdict.passed = n >= 1
        self.verdict.details["laps"] = n
        return Outcome.FINISHED, f"{n} complete lap(s) in {self.run.time_limit_s:g} s"


class SpeedLimitMonitor(EventMonitor):
    """The speed-limit zone (section 4.3: slow at the 4-stripe pattern, back to speed at the
    3-stripe pattern; the rules give no measure, ours): the approach speed is the mean over the
    metre before the 4-stripe piece, the zone's speed the highest from 0.5 m into it to the
    3-stripe piece, and from the 3-stripe piece to 1.5 m past it the car must be back to 0.8 x
    the approach."""

    def __init__(self, rules, run):
        super().__init__(rules, run)
        from simrunner.track.progress import CentrelineProgress

        course = run.track.course
        starts = [s for s in course.sections if s.kind == "SPEED_LIMIT_START"] if course else []
        ends = [s for s in course.sections if s.kind == "SPEED_LIMIT_END"] if course else []
        if not starts or not ends:
            raise SettingsError(f"{run.track.name}: the speed_limit event needs a layout with SPEED_LIMIT_START "
                                "and SPEED_LIMIT_END pieces (e.g. simrunner/data/events/kit_speed_limit.txt)")
        end = next((e for e in ends if e.s_start_m > starts[0].s_start_m), ends[0])
        end_start = end.s_start_m if end.s_start_m > starts[0].s_start_m else end.s_start_m + course.length_m
        # the zone: from the 4-stripe piece to the 3-stripe piece, where the car speeds up again
        self.zone = (starts[0].s_start_m, end_start)
        self.end_length = end.s_end_m - end.s_start_m
        self.length = course.length_m
        self.follow = CentrelineProgress(course.centreline)
        self.s_m: float | None = None
        self.samples: list[tuple[float, float]] = []  # (s along the course since the start, speed)

    def frame(self, t_s, pose, speed_mps):
        speed = speed_mps
        if self.s_m is None:
            self.follow.reset(pose.x_m, pose.y_m)
            self.s_m = self.follow.s_m
            self.s0 = self.follow.s_m
        else:
            self.s_m += self.follow.advance(pose.x_m, pose.y_m)
        # the zone's arc lengths, unwrapped to lie ahead of the start
        a, b = self.zone
        while a < self.s0:
            a, b = a + self.length, b + self.length
        self.samples.append((self.s_m, speed))
        if self.s_m < b + self.end_length + SPEED_LIMIT_AFTER_M:
            return None
        s = np.array([p[0] for p in self.samples])
        v = np.array([p[1] for p in self.samples])
        approach = v[(s >= a - APPROACH_M) & (s < a)]
        zone = v[(s >= a + SPEED_LIMIT_SETTLE_M) & (s <= b)]
        after = v[(s > b) & (s <= b + self.end_length + SPEED_LIMIT_AFTER_M)]
        if not len(approach) or not len(zone) or not len(after):
            return None
        v_in, v_zone, v_out = float(approach.mean()), float(zone.max()), float(after.max())
        slow = v_zone <= SPEED_LIMIT_SLOW * v_in
        back = v_out >= SPEED_LIMIT_BACK * v_in
        self.verdict.details.update(approach_mps=round(v_in, 4), zone_max_mps=round(v_zone, 4),
                                    after_max_mps=round(v_out, 4))
        self.verdict.passed = slow and back and v_in > STOPPED_MPS
        self.verdict.points = self.rules.points if self.verdict.passed else 0
        text = (f"approach {v_in:.2f} m/s, zone at most {v_zone:.2f} m/s "
                f"({'<=' if slow else '>'} {SPEED_LIMIT_SLOW:g} x), after it up to {v_out:.2f} m/s "
                f"({'>=' if back else '<'} {SPEED_LIMIT_BACK:g} x)")
        return Outcome.FINISHED, ("passed: " if self.verdict.passed else "failed: ") + text


STRAIGHT_KINDS = ("STRAIGHT", "STRAIGHT_SHORT", "START_FINISH", "SPEED_LIMIT_START", "SPEED_LIMIT_END")
OBJECT_AHEAD_M = 1.5            # ours: an object goes on a straight at least this far ahead of the car
CUBE_OFF_CENTRE_M = (0.05, 0.155)  # ours: the cube's centre this far off the lane's middle (a seeded
#                                  side; wholly on the lane, and a 20 cm wide car passes on the road)
BLOCK_AFTER_START_M = 0.3       # ours: the block at least this far along its straight (a car sees it)
STOPPED_FOR_S = 0.5             # ours: standing still this long is a stop


class _ObjectMonitor(EventMonitor):
    """Shared by the disciplines that put an object on the track during the run."""

    def __init__(self, rules, run):
        super().__init__(rules, run)
        course = run.track.course
        if course is None or not any(s.kind in STRAIGHT_KINDS and s.s_end_m - s.s_start_m >= 0.5
                                     for s in course.sections):
            raise SettingsError(f"{run.track.name}: the {rules.name} event needs a layout with straight "
                                "pieces (STRAIGHT, START_FINISH, ...) to put its object on")
        self.rng = np.random.default_rng([int(run.settings.seed), sum(map(ord, rules.name))])
        self.solid = None

    def _ahead(self, s_m: float) -> float:
        """Arc length from the car to ``s_m`` along the course, in [0, L)."""
        return (s_m - self.run.judge.course_s_m) % self.run.track.course.length_m

    def _straight_ahead(self, from_start_m: float) -> float:
        """A seeded arc length on a straight piece at least OBJECT_AHEAD_M ahead of the car, at
        least ``from_start_m`` after the piece's start and 0.1 m before its end."""
        course = self.run.track.course
        straights = [s for s in course.sections if s.kind in STRAIGHT_KINDS
                     and self._ahead(s.s_start_m) >= OBJECT_AHEAD_M
                     and self._ahead(s.s_end_m) > self._ahead(s.s_start_m)
                     and s.s_end_m - s.s_start_m >= from_start_m + 0.1]
        if not straights:  # (the check at the start found one: any is ahead within a lap)
            straights = [s for s in course.sections if s.kind in STRAIGHT_KINDS
                         and s.s_end_m - s.s_start_m >= from_start_m + 0.1]
        sec = straights[int(self.rng.integers(len(straights)))]
        return float(self.rng.uniform(sec.s_start_m + from_start_m, sec.s_end_m - 0.1))

    def _place(self, solid, along_m: float, across_m: float) -> None:
        self.solid = solid
        self.run.place_solid(solid)
        self.verdict.details.update(object=solid.name, x_m=round(solid.x_m, 4), y_m=round(solid.y_m, 4),
                                    along_m=round(along_m, 4), across_m=round(across_m, 4))



class ObstacleMonitor(_ObjectMonitor):
    """Lap 1 clear; then the white 20 cm cube on a straight at least 1.5 m ahead, anywhere
    along it (section 4.2: "anywhere along that straight"), 5 to 15.5 cm off the lane's middle
    on a seeded side (the rules: not specified; ours, so that a car passes on the road); lap 2
    without touching it (and no wheel off)."""

    def frame(self, t_s, pose, speed_mps):
        if self.solid is None and self.run.judge.laps_completed >= 1:
            from worlds.solids import obstacle_cube

            along = self._straight_ahead(0.1)
            across = float(self.rng.uniform(*CUBE_OFF_CENTRE_M)) * (1.0 if self.rng.random() < 0.5 else -1.0)
            x, y, yaw = _course_point(self.run.track.course, along, across)
            self._place(obstacle_cube("cube", x, y, yaw), along, across)
        return None


class EmergencyBrakeMonitor(_ObjectMonitor):
    """Two laps; then the black block across a straight at least 1.5 m ahead, at least 0.3 m
    after its start (seeded; section 4.4: when and where are not said, the drawing shows a bar
    across a straight); passed when the car stands still (below 0.02 m/s for 0.5 s) without
    touching it."""

    still_since: float | None = None

    def frame(self, t_s, pose, speed_mps):
        if self.solid is None:
            if self.run.judge.laps_completed >= 2:
                from worlds.solids import braking_block

                along = self._straight_ahead(BLOCK_AFTER_START_M)
                x, y, yaw = _course_point(self.run.track.course, along, 0.0)
                self._place(braking_block("block", x, y, yaw), along, 0.0)
                self.verdict.details["placed_ahead_m"] = round(self._ahead(along), 4)
            return None
        if abs(speed_mps) >= STOPPED_MPS:
            self.still_since = None
            return None
        if self.still_since is None:
            self.still_since = t_s
        if t_s - self.still_since < STOPPED_FOR_S:
            return None
        chassis = self.run.car.chassis  # the front bumper to the block's near face
        gap = self._ahead(self.verdict.details["along_m"]) - 0.1 - (chassis.length_m - chassis.rear_overhang_m)
        self.verdict.passed, self.verdict.points = True, self.rules.points
        self.verdict.details["stopped_before_m"] = round(gap, 4)
        return Outcome.FINISHED, f"stopped with its front {gap:.2f} m before the block"

    def at_time_limit(self, t_s):
        self.failed(Outcome.TIMEOUT)
        what = "did not stop before the block" if self.solid is not None else "the block was never placed"
        return Outcome.TIMEOUT, f"time limit of {self.run.time_limit_s:g} s: {what}"


def _course_point(course, along_m: float, across_m: float) -> tuple[float, float, float]:
    """World ``(x, y, heading)`` ``across_m`` to the left of the course at arc length ``along_m``."""
    from simrunner.track.progress import CentrelineProgress

    x, y, yaw = CentrelineProgress(course.centreline).point_at(along_m)
    return x - math.sin(yaw) * across_m, y + math.cos(yaw) * across_m, yaw


MONITORS = {"race": RaceMonitor, "figure8": Figure8Monitor, "speed_limit": SpeedLimitMonitor,
            "obstacle": ObstacleMonitor, "emergency_brake": EmergencyBrakeMonitor}


def make_monitor(name: str, run) -> EventMonitor:
    return MONITORS.get(name, EventMonitor)(EVENTS[name], run)


def event_start(settings, track):
    """``settings`` with the discipline's own start (``EventRules.start_after``) when the run
    gives none: the car just past the first piece of that kind."""
    import dataclasses

    rules = EVENTS.get(settings.event) if settings.event is not None else None
    if (rules is None or rules.start_after is None or settings.start is not None
            or settings.start_before_finish_m is not None or track.course is None):
        return settings
    past = start_past(track.course, rules.start_after, 0.05)
    if past is None:
        return settings
    return dataclasses.replace(settings, start=(past.x_m, past.y_m, past.yaw_rad))


def start_past(course, kind: str, past_m: float = 0.05):
    """The pose on the course ``past_m`` after the first piece of ``kind`` (rear axle),
    heading along it; None when the course has no such piece."""
    from pieces.pose import Pose2
    from simrunner.track.progress import CentrelineProgress

    sec = next((s for s in course.sections if s.kind == kind), None)
    if sec is None:
        return None
    x, y, yaw = CentrelineProgress(course.centreline).point_at(sec.s_end_m + past_m)
    return Pose2(x, y, yaw)


__all__ = ["EVENTS", "EventRules", "EventMonitor", "Verdict", "event_start", "event_track", "make_monitor",
           "start_past"]
