"""The settings of an ``NXPCup-v0`` environment, validated once: :class:`EnvSettings`.

Every field can be given to ``gymnasium.make("NXPCup-v0", name=value, ...)``.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

from simrunner.errors import SimError
from simrunner.run.settings import MAX_DT_S


class EnvSettingsError(SimError):
    """An environment setting is out of range (the message names it and the range)."""


@dataclass(frozen=True)
class EnvSettings:
    """How an episode runs (docs/gym.md).

    ``dt_s``: physics step (s), as ``simrunner drive``'s ``--dt`` (default the same 2 ms).
    ``time_limit_s``: simulated time after which an episode is truncated (s).
    ``laps``: an episode terminates when this many laps are completed (None: never; the
    time limit ends it). ``speed_min_mps`` / ``speed_max_mps``: the speeds the speed action
    -1 and +1 ask for (None: the car's ``drive.max_speed_mps``). ``off_track_penalty``:
    subtracted from the reward of the step that leaves the track (metres of progress).
    ``camera_noise``: add the car's camera noise (``camera.noise_std``) to the line row.
    ``line_row``: the image row observed (None: the car's ``camera.default_row``).
    ``random_start``: start each episode at rest at a point of the track's centreline drawn
    uniformly along it (from the reset generator), heading in the driving direction; False:
    at the track's start pose.
    """

    dt_s: float = 0.002
    time_limit_s: float = 30.0
    laps: int | None = None
    speed_min_mps: float = 0.0
    speed_max_mps: float | None = None
    off_track_penalty: float = 2.0
    camera_noise: bool = True
    line_row: int | None = None
    random_start: bool = False

    def __post_init__(self) -> None:
        for name, lo, hi, allow_zero in (("dt_s", 0.0, MAX_DT_S, False), ("time_limit_s", 0.0, 1e6, False),
                                         ("speed_min_mps", -10.0, 10.0, True),
                                         ("speed_max_mps", -10.0, 10.0, True),
                                         ("off_track_penalty", 0.0, 1e6, True)):
            v = getattr(self, name)
            if v is None and name == "speed_max_mps":
                continue
            if (isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v)
                    or not (lo <= v <= hi if allow_zero else lo < v <= hi)):
                raise EnvSettingsError(f"{name} = {v!r}: expected a number in "
                                       f"{'[' if allow_zero else '('}{lo:g}, {hi:g}]")
            object.__setattr__(self, name, float(v))
        for name, lo in (("laps", 1), ("line_row", 0)):
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, bool) or not hasattr(v, "__index__") or int(v) < lo:
                raise EnvSettingsError(f"{name} = {v!r}: expected a whole number >= {lo} (or None)")
            object.__setattr__(self, name, int(v))
        for name in ("camera_noise", "random_start"):
            if not isinstance(getattr(self, name), bool):
                raise EnvSettingsError(f"{name} = {getattr(self, name)!r}: expected True or False")
        if self.speed_max_mps is not None and self.speed_max_mps <= self.speed_min_mps:
            raise EnvSettingsError(f"speed_max_mps = {self.speed_max_mps:g}: expected more than "
                                   f"speed_min_mps = {self.speed_min_mps:g}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))
