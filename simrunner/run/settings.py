"""The settings of one run, validated once: :class:`RunSettings`."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Mapping

from simrunner.errors import SimError
from simrunner.run.params import ParamValue, frozen_params

MAX_DT_S = 0.02


class SettingsError(SimError):
    """A run setting is out of range (the message names it and the range)."""


@dataclass(frozen=True)
class RunSettings:
    """How to run a controller (every other part trusts these values).

    ``laps``: laps to complete (>= 1). ``time_limit_s``: simulated-time limit (s).
    ``seed``: seed of the camera-noise generator (>= 0). ``dt_s``: physics step (s, at most
    0.02). ``wall_limit_s``: wall time a controller may spend without letting simulated time
    pass before it is stopped (s). ``params``: controller parameters, a read-only mapping
    name -> int | float | str, read with ``spinner.param(name, default)``
    (:mod:`simrunner.run.params`).
    """

    laps: int = 1
    time_limit_s: float = 60.0
    seed: int = 0
    dt_s: float = 0.002
    wall_limit_s: float = 10.0
    params: Mapping[str, ParamValue] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        for name, lo in (("laps", 1), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not hasattr(v, "__index__") or int(v) < lo:
                raise SettingsError(f"{name} = {v!r}: expected a whole number >= {lo}")
            object.__setattr__(self, name, int(v))
        for name, hi in (("time_limit_s", 1e6), ("dt_s", MAX_DT_S), ("wall_limit_s", 1e6)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or not 0.0 < v <= hi:
                raise SettingsError(f"{name} = {v!r}: expected a number in (0, {hi:g}]")
            object.__setattr__(self, name, float(v))
        object.__setattr__(self, "params", frozen_params(self.params))
