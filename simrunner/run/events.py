"""The NXP Cup's disciplines as runs (``--event NAME``): each sets up its track, laps, time
limit and off-track rule as the rules describe it, watches what the judge does not (the stop
after the finish, the speed in a zone, an obstacle placed during the run) and scores it.
Numbers from the rules summary (``../shared/reference/nxp-cup-rules.md``): the race section 3,
the other disciplines section 4; "ours" marks what the rules leave open.

| event | track (unless ``--track``) | the run | passed when |
| --- | --- | --- | --- |
| ``race`` | the given track (default: the bundled one) | 1 lap, 120 s, 3 wheels off fail | the lap is done; +1 s when the car does not stop within 2 m after the line |
| ``figure8`` | the kit's M figure 8 | laps until 60 s (``--time-limit 90``: the 2018/19 rules) | the whole time driven without a wheel off; score: laps |
| ``speed_limit`` | the kit's M oval with the zone | from just past the 3-stripe piece to 1.5 m past it again | the zone's speed at most 0.6 x the approach, back to 0.8 x after it |

The other disciplines void an attempt when any part of any wheel leaves the track (section 4,
"Common void-attempt conditions"): their runs end at the first wheel off.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simrunner.run.result import Outcome
from simrunner.run.rules import (EVENT_NAMES, RACE_LAPS, RACE_TIME_LIMIT_S, RULES_OFF_TRACK_WHEELS, STOPPED_MPS,
                                 Penalty, StopCheck)

EVENT_TRACKS = Path(__file__).resolve().parent.parent / "data" / "events"
SPEED_LIMIT_SLOW = 0.6       # ours: "about half" the approach speed (section 4.3: not specified)
SPEED_LIMIT_BACK = 0.8       # ours: back to this share of the approach speed after the zone ...
SPEED_LIMIT_AFTER_M = 1.5    # ... within this far past the 3-stripe piece
SPEED_LIMIT_SETTLE_M = 0.5   # ours: the zone's first 0.5 m are for braking (not judged)
APPROACH_M = 1.0             # the approach speed: the mean over the last metre before the zone
SUCCESS_POINTS = 150         # section 4.2-4.4: 150 for success, 0 otherwise


@dataclass(frozen=True)
class EventRules:
    """One discipline: ``layout`` (a file of simrunner/data/events, None: the run's track),
    the judge's ``laps``, ``time_limit_s``, ``off_track_wheels`` and the ``points`` for
    success (None: by rank among the teams, not known from one run); ``rules``: the rules
    summary's section."""

    name: str
    layout: str | None
    laps: int
    time_limit_s: float
    off_track_wheels: int
    points: int | None
    rules: str


EVENTS: dict[str, EventRules] = {
    "race": EventRules("race", None, RACE_LAPS, RACE_TIME_LIMIT_S, RULES_OFF_TRACK_WHEELS, None, "section 3"),
    # 60 s in 2019/20 (R20), 90 s in 2018/19 (R19): section 4.1
    "figure8": EventRules("figure8", "kit_M.txt", 10**6, 60.0, 1, None, "section 4.1"),
    "speed_limit": EventRules("speed_limit", "kit_speed_limit.txt", 10**6, 90.0, 1, SUCCESS_POINTS, "section 4.3"),
}


assert tuple(EVENTS) == EVENT_NAMES


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

    def frame(self, t: float, pose, speed: float) -> tuple[Outcome, str] | None:
        return None

    def at_laps(self, t: float, speed: float, off: bool) -> tuple[Outcome, str] | None:
        self.verdict.passed = True
        self.verdict.points = self.rules.points
        return Outcome.FINISHED, f"{self.run.judge.laps_completed} lap(s) completed"

    def at_time_limit(self, t: float) -> tuple[Outcome, str]:
        return Outcome.TIMEOUT, f"time limit of {self.rules.time_limit_s:g} s simulated time reached"

    def failed(self, outcome: Outcome) -> None:
        """The run ended otherwise (off track, off course, a fault): not passed."""
        self.verdict.passed = False
        self.verdict.points = 0 if self.rules.points is not None else None


class RaceMonitor(EventMonitor):
    """The race: after the lap, the stop within 2 m of the line (:class:`StopCheck`)."""

    stop: StopCheck | None = None

    def at_laps(self, t, speed, off):
        judge = self.run.judge
        if self.stop is None:
            self.stop = StopCheck(judge.finish_t_s, judge.finish_distance_m)
        verdict = self.stop.update(t, judge.distance_m, speed, int(off),
                                   time_up=t >= self.run.time_limit_s - 1e-9)
        if verdict is None:
            return None
        text, penalty = verdict
        if penalty is not None:
            self.verdict.penalties.append(penalty)
            text += f" (+{penalty.seconds:g} s)"
        self.verdict.passed = True
        return Outcome.FINISHED, f"{judge.laps_completed} lap(s) completed; {text}"


class Figure8Monitor(EventMonitor):
    """As many complete laps as the time allows; the attempt counts when the whole time was
    driven cleanly (section 4.1)."""

    def at_time_limit(self, t):
        n = self.run.judge.laps_completed
        self.verdict.passed = n >= 1
        self.verdict.details["laps"] = n
        return Outcome.FINISHED, f"{n} complete lap(s) in {self.rules.time_limit_s:g} s"


class SpeedLimitMonitor(EventMonitor):
    """The speed-limit zone (section 4.3; the rules give no measure, ours is stated in the
    module docstring): the approach speed is the mean over the metre before the 4-stripe piece,
    the zone's speed the highest from 0.5 m into it to its end, and after the 3-stripe piece
    the car must be back to 0.8 x the approach within 1.5 m."""

    def __init__(self, rules, run):
        super().__init__(rules, run)
        from simrunner.track.progress import CentrelineProgress

        course = run.track.course
        starts = [s for s in course.sections if s.kind == "SPEED_LIMIT_START"]
        ends = [s for s in course.sections if s.kind == "SPEED_LIMIT_END"]
        if not starts or not ends:
            raise ValueError("the speed_limit event needs a track with SPEED_LIMIT_START and SPEED_LIMIT_END "
                             "pieces (e.g. simrunner/data/events/kit_speed_limit.txt)")
        self.zone = (starts[0].s_start_m, next((e.s_end_m for e in ends if e.s_end_m > starts[0].s_start_m),
                                               ends[0].s_end_m + course.length_m))
        self.length = course.length_m
        self.follow = CentrelineProgress(course.centreline)
        self.s_m: float | None = None
        self.samples: list[tuple[float, float]] = []  # (s along the course since the start, speed)

    def frame(self, t, pose, speed):
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
        if self.s_m < b + SPEED_LIMIT_AFTER_M:
            return None
        s = np.array([p[0] for p in self.samples])
        v = np.array([p[1] for p in self.samples])
        approach = v[(s >= a - APPROACH_M) & (s < a)]
        zone = v[(s >= a + SPEED_LIMIT_SETTLE_M) & (s <= b)]
        after = v[(s > b) & (s <= b + SPEED_LIMIT_AFTER_M)]
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


MONITORS = {"race": RaceMonitor, "figure8": Figure8Monitor, "speed_limit": SpeedLimitMonitor}


def make_monitor(name: str, run) -> EventMonitor:
    return MONITORS.get(name, EventMonitor)(EVENTS[name], run)


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


__all__ = ["EVENTS", "EventRules", "EventMonitor", "Verdict", "event_track", "make_monitor", "start_past"]
