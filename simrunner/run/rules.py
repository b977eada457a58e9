"""The NXP Cup's rules a run applies: the timed race (``--event race``) and when leaving the
track ends an attempt. Numbers from the rules summary (``../shared/reference/nxp-cup-rules.md``,
section 3, the timed race: identical in the 2018/19 and 2019/20 rules, R19 §5, §8, §9 and
R20 §7, §10, §11); where the rules are silent the simulator's choice is marked "ours".

The disciplines' table (:data:`EVENTS`) lives here too (the settings check against it);
:mod:`simrunner.run.events` runs them.

The race: one lap per attempt, timed when the car crosses the start/finish line and crosses
it again (the judge times the rear-axle midpoint's crossings: the same interval as "the
first part of the car" for a car that keeps its shape); the attempt fails after 120 s or
when 3 or more wheels leave the track; +1 s when the car does not stop within 2 m of the
finish line or leaves the track after crossing it (:class:`StopCheck`).
"""
from __future__ import annotations

from dataclasses import dataclass

RACE_LAPS = 1                # section 3, "Laps": one lap per attempt
RACE_TIME_LIMIT_S = 120.0    # section 3, "Time limit"
RULES_OFF_TRACK_WHEELS = 3   # section 3, "Leaving the track": 3 or more wheels off fails
STOP_WITHIN_M = 2.0          # section 3, "Stop after finish": 2 m (6 ft) ...
STOP_PENALTY_S = 1.0         # ... or +1 s
STOPPED_MPS = 0.02           # ours: a car slower than this has stopped
STOP_WAIT_S = 10.0           # ours: a car still rolling this long after the finish has not stopped


SUCCESS_POINTS = 150         # section 4.2-4.4: 150 for success, 0 otherwise


@dataclass(frozen=True)
class EventRules:
    """One discipline of ``--event`` (:mod:`simrunner.run.events` runs it): ``layout`` (a file
    of simrunner/data/events, None: the run's track), the judge's ``laps`` (None: as many as
    the time allows), ``time_limit_s``, ``off_track_wheels`` (each wheel judged by
    ``wheel_off``: ``"whole"``, off when no part of its tyre touches the road, or ``"any_part"``,
    off when any part of it leaves the road, as in section 4) and the ``points`` for success
    (None: by rank among the teams, not known from one run); ``rules``: the rules summary's
    section; ``start_after``: the car starts just past the first piece of that kind (None:
    the track's start)."""

    name: str
    layout: str | None
    laps: int | None
    time_limit_s: float
    off_track_wheels: int
    points: int | None
    rules: str
    start_after: str | None = None
    wheel_off: str = "any_part"  # section 4, "Common void-attempt conditions"


EVENTS: dict[str, EventRules] = {
    "race": EventRules("race", None, RACE_LAPS, RACE_TIME_LIMIT_S, RULES_OFF_TRACK_WHEELS, None, "section 3",
                       wheel_off="whole"),  # section 3: "wheels leave the racing surface"
    # 60 s in 2019/20 (R20), 90 s in 2018/19 (R19): section 4.1
    "figure8": EventRules("figure8", "kit_M.txt", None, 60.0, 1, None, "section 4.1"),
    # R20: the car starts just past the 3-stripe pattern
    "speed_limit": EventRules("speed_limit", "kit_speed_limit.txt", None, 90.0, 1, SUCCESS_POINTS, "section 4.3",
                              start_after="SPEED_LIMIT_END"),
    "obstacle": EventRules("obstacle", "kit_S.txt", 2, 90.0, 1, SUCCESS_POINTS, "section 4.2"),
    "emergency_brake": EventRules("emergency_brake", "kit_S_plain.txt", None, 90.0, 1, SUCCESS_POINTS,
                                  "section 4.4"),
}
EVENT_NAMES = tuple(EVENTS)


@dataclass(frozen=True)
class Penalty:
    """A time penalty: ``seconds`` added to the result, ``reason`` in the rules' words."""

    seconds: float
    reason: str


class StopCheck:
    """After the finish line: does the car stop within :data:`STOP_WITHIN_M` of it (path
    length of the rear-axle midpoint from its crossing) without leaving the track?
    :meth:`update` returns None while undecided, then the verdict ``(text, penalty or None)``."""

    def __init__(self, t_finish_s: float, distance_at_finish_m: float):
        self.t_finish_s = float(t_finish_s)
        self.d_finish_m = float(distance_at_finish_m)

    def update(self, t_s: float, distance_m: float, speed_mps: float, wheels_off: int,
               time_up: bool = False) -> tuple[str, Penalty | None] | None:
        past = max(0.0, distance_m - self.d_finish_m)
        if wheels_off:
            return "left the track after the finish line", Penalty(
                STOP_PENALTY_S, "left the track after crossing the finish line")
        if past > STOP_WITHIN_M:
            return f"did not stop within {STOP_WITHIN_M:g} m of the finish line", Penalty(
                STOP_PENALTY_S, f"did not stop within {STOP_WITHIN_M:g} m of the finish line")
        if abs(speed_mps) < STOPPED_MPS:
            return f"stopped {past:.2f} m after the finish line", None
        if time_up or t_s - self.t_finish_s >= STOP_WAIT_S:
            return f"still rolling {t_s - self.t_finish_s:.1f} s after the finish line", Penalty(
                STOP_PENALTY_S, f"did not stop within {STOP_WITHIN_M:g} m of the finish line")
        return None
