"""What a run did: :class:`Outcome` and :class:`RunResult` (the ``--summary`` JSON)."""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

from simrunner.errors import ControllerError
from simrunner.telemetry.log import RunLog, empty_log


class Outcome(enum.StrEnum):
    """How a run ended (the summary's ``outcome``; a ``str``, so ``== "finished"`` works)."""

    FINISHED = "finished"                        # the laps were completed
    OFF_TRACK = "off_track"                      # too many wheels left the road
    OFF_COURSE = "off_course"                    # turned at a crossing, cut across, drove back
    TOUCHED = "touched"                          # the car touched an object on the track
    TIMEOUT = "timeout"                          # the simulated time limit passed
    CONTROLLER_ERROR = "controller_error"        # main raised (or sent a bad command)
    CONTROLLER_RETURNED = "controller_returned"  # main returned
    STALLED = "stalled"                          # no simulated time passed for the wall limit
    INTERRUPTED = "interrupted"                  # Ctrl-C

    @property
    def ok(self) -> bool:
        """The run succeeded (exit code 0)."""
        return self in (Outcome.FINISHED, Outcome.CONTROLLER_RETURNED)


@dataclass
class RunResult:
    """What a run did; times in seconds. ``log`` is the run log (one row per camera frame)."""

    outcome: Outcome
    laps: int
    laps_completed: int
    lap_times_s: list[float]
    sim_time_s: float
    wall_time_s: float
    track: str
    seed: int
    message: str = ""
    cpu_time_s: float = 0.0  # process CPU time of the run loop (load-independent speed)
    error: ControllerError | None = None
    log: RunLog = field(default_factory=empty_log, repr=False)
    outputs: dict[str, str] = field(default_factory=dict)
    unused_params: tuple[str, ...] = ()  # --param names the controller never read
    params_read: tuple[str, ...] = ()  # names the controller (and its kit library) asked for
    # rows the run recorded (``log`` holds them all up to log.KEEP_ROWS, then every k-th)
    frames: int | None = None
    warnings: list[str] = field(default_factory=list)  # noticed, did not stop the run
    stray_threads: int = 0  # non-daemon threads the controller left running
    signal: int | None = None  # the signal that interrupted the run (None: Ctrl-C or none)
    event: str | None = None  # None: practice; else the discipline (simrunner.run.events)
    verdict: Any = None       # the discipline's simrunner.run.events.Verdict (None: practice)
    lap_distances_m: list[float] = field(default_factory=list)  # path driven in each counted lap
    lap_courses_m: list[float] = field(default_factory=list)  # course followed in each counted lap
    course_from_start_m: float | None = None  # where the run ended along the course, from its start
    course_length_m: float | None = None

    @property
    def penalties(self) -> list:
        """The discipline's time penalties (:class:`simrunner.run.rules.Penalty`), in order."""
        return [] if self.verdict is None else list(self.verdict.penalties)

    @property
    def penalty_s(self) -> float:
        return float(sum(p.seconds for p in self.penalties))

    @property
    def passed(self) -> bool:
        """The attempt counts: the discipline's verdict; in practice, the laps were completed."""
        if self.verdict is not None:
            return bool(self.verdict.passed)
        return Outcome(self.outcome) == Outcome.FINISHED

    @property
    def points(self) -> int | None:
        """The rules' points for this attempt (None: practice, or ranked among teams)."""
        return None if self.verdict is None else self.verdict.points

    @property
    def time_s(self) -> float | None:
        """The race's result: the first lap's time plus the penalties (None without a lap, or
        when the attempt failed)."""
        if self.event != "race" or not self.lap_times_s or not self.passed:
            return None
        return self.lap_times_s[0] + self.penalty_s

    @property
    def ok(self) -> bool:
        return Outcome(self.outcome).ok

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def summary(self) -> dict[str, Any]:
        """The ``--summary`` JSON object."""
        return {"outcome": str(self.outcome), "message": self.message, "laps": self.laps,
                "laps_completed": self.laps_completed,
                "lap_times_s": [round(t, 6) for t in self.lap_times_s],
                "lap_distances_m": [round(d, 4) for d in self.lap_distances_m],
                "lap_courses_m": [round(d, 4) for d in self.lap_courses_m],
                "sim_time_s": round(self.sim_time_s, 6), "wall_time_s": round(self.wall_time_s, 3),
                "real_time_factor": round(self.real_time_factor, 2),
                "cpu_time_s": round(self.cpu_time_s, 3), "track": self.track,
                "seed": self.seed, "frames": len(self.log) if self.frames is None else self.frames,
                "warnings": list(self.warnings), "outputs": self.outputs,
                "event": self.event, "passed": self.passed,
                "penalties": [{"seconds": p.seconds, "reason": p.reason} for p in self.penalties],
                "penalty_s": self.penalty_s,
                "time_s": None if self.time_s is None else round(self.time_s, 6),
                "points": self.points,
                "details": {} if self.verdict is None else dict(self.verdict.details)}
