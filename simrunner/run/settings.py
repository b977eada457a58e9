"""The settings of one run, validated once: :class:`RunSettings`."""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Mapping

from simrunner.errors import SimError
from simrunner.run.params import ParamValue, frozen_params
from simrunner.run.rules import EVENTS, RULES_OFF_TRACK_WHEELS

MAX_DT_S = 0.02


class SettingsError(SimError):
    """A run setting is out of range (the message names it and the range)."""


@dataclass(frozen=True)
class RunSettings:
    """How to run a controller (every other part trusts these values).

    ``laps``: laps to complete (>= 1). ``time_limit_s``: simulated-time limit (s); None (the
    default) grows with the laps: ``max(60, laps x lap length / 0.5 m/s)``
    (:func:`default_time_limit_s`; 60 s on a free floor). ``seed``: seed of the camera-noise
    generator (>= 0). ``dt_s``: physics step (s, at most 0.02). ``wall_limit_s``: wall time
    a controller may spend without letting simulated time pass before it is stopped (s).

    Start pose (at most one of the two; default: the track's start,
    :mod:`simrunner.run.start`): ``start`` a pose ``(x_m, y_m, yaw_rad)`` (or a ``Pose2``) of
    the car frame (rear-axle midpoint) in the world; ``start_before_finish_m`` the car on
    the track's centre, heading along it, its front bumper this far (m, along the track)
    before the finish line.

    Judging: ``off_track_wheels``: how many wheels off the road end the run (1-4; None, the
    default: 3, the rules' race, "3 or more wheels", :mod:`simrunner.run.rules`, or the
    event's; 1 is the stricter rule that any wheel off ends it, the other disciplines'); fewer
    wheels off are recorded (the ``off_track`` column, a warning). Leaving the course
    (:mod:`simrunner.run.judge`) ends the run too. ``keep_driving``: neither ends the run
    (both are still recorded). ``event``: None (practice: ``laps`` laps) or a discipline of
    :data:`simrunner.run.events.EVENTS` (``"race"``: the rules' timed race, one lap, 120 s,
    +1 s when the car does not stop within 2 m after the finish line; ``"figure8"``, ...): its
    laps, time limit (unless ``time_limit_s`` is given) and off-track rule. ``params``: controller
    parameters, a read-only mapping name -> int | float | str, read with
    ``spinner.param(name, default)`` (:mod:`simrunner.run.params`).

    The controller's own time (:mod:`simrunner.run.mcu`): ``mcu_time`` None (the default: the
    controller's code runs in no simulated time), ``"measured"`` (its CPU time between Spinner
    calls, times ``mcu_scale``) or a number of seconds each call costs (deterministic).
    """

    laps: int = 1
    time_limit_s: float | None = None
    seed: int = 0
    dt_s: float = 0.002
    wall_limit_s: float = 10.0
    params: Mapping[str, ParamValue] = field(default_factory=dict, hash=False)
    start: tuple[float, float, float] | None = None
    start_before_finish_m: float | None = None
    keep_driving: bool = False
    off_track_wheels: int | None = None
    event: str | None = None
    mcu_time: str | float | None = None
    mcu_scale: float = 1.0

    def __post_init__(self) -> None:
        for name, lo in (("laps", 1), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not hasattr(v, "__index__") or int(v) < lo:
                raise SettingsError(f"{name} = {v!r}: expected a whole number >= {lo}")
            object.__setattr__(self, name, int(v))
        if self.event is not None and self.event not in EVENTS:
            raise SettingsError(f"event = {self.event!r}: expected one of {', '.join(EVENTS)} (or none: practice)")
        if self.event is not None and self.keep_driving:
            raise SettingsError("keep_driving: not with an event (leaving the track or the course voids "
                                "an attempt; keep driving in practice)")
        if self.event is not None and self.laps != 1:
            rules = EVENTS[self.event]
            raise SettingsError(f"laps = {self.laps!r}: the {self.event} event sets its own laps (rules "
                                f"summary, {rules.rules}); several laps are practice (no event)")
        if self.off_track_wheels is None:
            object.__setattr__(self, "off_track_wheels", RULES_OFF_TRACK_WHEELS if self.event is None
                               else EVENTS[self.event].off_track_wheels)
        v = self.off_track_wheels
        if isinstance(v, bool) or not hasattr(v, "__index__") or not 1 <= int(v) <= 4:
            raise SettingsError(f"off_track_wheels = {v!r}: expected 1, 2, 3 or 4 (wheels off the road "
                                "that end the run)")
        object.__setattr__(self, "off_track_wheels", int(v))
        for name, hi in (("time_limit_s", 1e6), ("dt_s", MAX_DT_S), ("wall_limit_s", 1e6)):
            v = getattr(self, name)
            if v is None and name == "time_limit_s":
                continue
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or not 0.0 < v <= hi:
                raise SettingsError(f"{name} = {v!r}: expected a number in (0, {hi:g}]")
            object.__setattr__(self, name, float(v))
        object.__setattr__(self, "params", frozen_params(self.params))
        if self.start is not None and self.start_before_finish_m is not None:
            raise SettingsError("start and start_before_finish_m: give one of them, not both")
        if self.start is not None:
            v = self.start
            values = (v.x_m, v.y_m, v.yaw_rad) if hasattr(v, "yaw_rad") else v
            try:
                values = tuple(float(x) for x in values)
            except (TypeError, ValueError):
                values = ()
            if len(values) != 3 or not all(math.isfinite(x) for x in values):
                raise SettingsError(f"start = {v!r}: expected (x_m, y_m, yaw_rad), three finite numbers")
            object.__setattr__(self, "start", values)
        v = self.start_before_finish_m
        if v is not None:
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or not 0.0 <= v <= 1e4:
                raise SettingsError(f"start_before_finish_m = {v!r}: expected a distance in [0, 10000] m")
            object.__setattr__(self, "start_before_finish_m", float(v))
        if not isinstance(self.keep_driving, bool):
            raise SettingsError(f"keep_driving = {self.keep_driving!r}: expected True or False")
        v = self.mcu_time
        if isinstance(v, str) and v != "measured":
            try:
                v = float(v)
            except ValueError:
                v = None
                raise SettingsError(f"mcu_time = {self.mcu_time!r}: expected \"measured\" or seconds per "
                                    "call (e.g. 0.002)") from None
        if v is not None and v != "measured":
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or not 0.0 <= v <= 10.0:
                raise SettingsError(f"mcu_time = {self.mcu_time!r}: expected \"measured\" or seconds per call "
                                    "in [0, 10]")
            v = float(v)
        object.__setattr__(self, "mcu_time", v)
        v = self.mcu_scale
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or not 0.0 < v <= 1e4:
            raise SettingsError(f"mcu_scale = {v!r}: expected a factor in (0, 10000] (how many times slower "
                                "the MCU runs the code)")
        object.__setattr__(self, "mcu_scale", float(v))

    def for_track(self, track) -> "RunSettings":
        """These settings with ``time_limit_s`` filled in for ``track`` (a ``SimTrack``)."""
        if self.time_limit_s is not None:
            return self
        if self.event is not None:
            return dataclasses.replace(self, time_limit_s=EVENTS[self.event].time_limit_s)
        return dataclasses.replace(self, time_limit_s=default_time_limit_s(self.laps, track))


DEFAULT_TIME_LIMIT_S = 60.0
SLOW_LAP_SPEED_MPS = 0.5  # a slow first controller still finishes its laps in time


def default_time_limit_s(laps: int, track) -> float:
    """``max(60, laps x lap length / 0.5 m/s)``; 60 s on a track without laps (a floor)."""
    if not getattr(track, "judged", True):
        return DEFAULT_TIME_LIMIT_S
    return min(1e6, max(DEFAULT_TIME_LIMIT_S, laps * float(track.lap_length_m) / SLOW_LAP_SPEED_MPS))
