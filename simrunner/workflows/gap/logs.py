"""Measured logs: check a run log for the gap workflow and derive smoothed states from it.

A measured log is a :class:`simrunner.run.log.RunLog` (read with
``simrunner.run.log.read_log``; the one schema is docs/telemetry.md). The gap needs the
columns :data:`MEASURED_COLUMNS` and at least :data:`MIN_ROWS` rows over
:data:`MIN_DURATION_S`; :func:`check_measured` says so in one ``path:line:`` error:

    t_s            s     sample time, strictly increasing
    x_m, y_m       m     rear-axle midpoint in the world frame
    yaw_rad        rad   heading, counter-clockwise from +x (any wrapping)
    speed_mps      m/s   signed speed along the car's x axis
    speed_cmd_mps  m/s   commanded speed (physical units)
    steer_cmd_rad  rad   commanded bicycle-equivalent steering angle, positive = left

``coast`` (0/1: drive off, rear wheels rolling freely) is used when present (absent: never
coasting); other columns are ignored.

Commands are taken as held from their sample to the next one (zero-order hold), as
``simrunner.workflows.excite.run_plan`` logs them: the state at ``t_k`` and the command set at ``t_k``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simrunner.run.log import RunLog

MEASURED_COLUMNS = ("t_s", "x_m", "y_m", "yaw_rad", "speed_mps", "speed_cmd_mps", "steer_cmd_rad")
MIN_ROWS = 50
MIN_DURATION_S = 6.0  # three 2-s replay windows: two to fit, one to hold out
SMOOTH_S = 0.15  # Savitzky-Golay window for states and their derivatives
MIN_SPEED_FOR_STEER_MPS = 0.15  # below this the steer estimate falls back to the command


def check_measured(log: RunLog) -> RunLog:
    """``log`` if the gap workflow can use it, else :class:`simrunner.run.log.LogError`
    (``path:line: what was expected``): the columns :data:`MEASURED_COLUMNS`, at least
    :data:`MIN_ROWS` rows and :data:`MIN_DURATION_S` of data."""
    log.require(*MEASURED_COLUMNS, min_rows=MIN_ROWS, min_duration_s=MIN_DURATION_S)
    return log


@dataclass(frozen=True)
class Derived:
    """Smoothed states of a log (Savitzky-Golay, ``SMOOTH_S`` window), all shape (N,).

    ``yaw_rad`` is unwrapped; ``yaw_rate_radps`` and ``accel_mps2`` are derivatives of the
    smoothed yaw and speed; ``steer_rad`` is the bicycle-equivalent steer that explains the
    yaw rate, ``atan(L * r / v)``, or the command where ``|v|`` is small.
    """

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray
    accel_mps2: np.ndarray
    steer_rad: np.ndarray


def sample_dt_s(log: RunLog) -> float:
    """Median sample interval."""
    return float(np.median(np.diff(log.t_s)))


def derive(log: RunLog, wheelbase_m: float, steer_limit_rad: float = math.inf) -> Derived:
    """Smoothed states and derivatives; see :class:`Derived`."""
    from scipy.signal import savgol_filter  # here, not at import: `simrunner gap --help` stays quick
    dt = sample_dt_s(log)
    win = max(5, int(round(SMOOTH_S / dt)) | 1)
    n = len(log)
    win = min(win, n if n % 2 else n - 1)
    t = log.t_s
    # Savitzky-Golay assumes a uniform grid: resample, filter, and sample back.
    grid = np.linspace(t[0], t[-1], len(log))
    step = grid[1] - grid[0]

    def smooth(v: np.ndarray, deriv: int = 0) -> np.ndarray:
        g = np.interp(grid, t, v)
        s = savgol_filter(g, win, 2, deriv=deriv, delta=step, mode="interp")
        return np.interp(t, grid, s)

    yaw_u = np.unwrap(log.yaw_rad)
    speed = smooth(log.speed_mps)
    yaw_rate = smooth(yaw_u, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        steer = np.arctan(wheelbase_m * yaw_rate / speed)
    slow = np.abs(speed) < MIN_SPEED_FOR_STEER_MPS
    steer = np.where(slow, log.steer_cmd_rad, steer)
    steer = np.clip(steer, -steer_limit_rad, steer_limit_rad)
    return Derived(smooth(log.x_m), smooth(log.y_m), smooth(yaw_u), speed, yaw_rate,
                   smooth(log.speed_mps, 1), steer)
