"""Driving regimes of a log and residual statistics per signal and regime.

Regimes (boolean masks, shape (N,); a sample can be in one longitudinal and one lateral
regime; samples with ``|speed| < settings.moving_mps`` are in neither):

    accelerating   smoothed acceleration > settings.accel_mps2
    braking        acceleration < -settings.accel_mps2 while drive is commanded (|speed_cmd| >= settings.coast_cmd_mps)
    coasting       drive off (the log's ``coast`` column) or no drive commanded
                   (|speed_cmd| < settings.coast_cmd_mps), while moving
    steady         moving, none of the three above
    straight       |steer_cmd| < settings.straight_rad
    left, right    steer_cmd >= settings.straight_rad / <= -settings.straight_rad
    cornering      left or right
    reversing      smoothed speed < -settings.moving_mps
    high_lat_accel |v * yaw_rate| above settings.high_lateral_fraction of the grip limit mu * g
                   (mu: the car's ``wheels.friction_mu``): the tyres work in their
                   non-linear range, where slip and friction effects show

A regime is empty where the log cannot tell (no yaw rate: never ``high_lat_accel``).
Lateral regimes follow the *command*: a car that curves while told to go straight shows up
as a cross-track bias in "straight", which is what a steering offset looks like.
"""
from __future__ import annotations

import numpy as np

from simrunner.telemetry.log import RunLog
from simrunner.workflows.gap.logs import Derived, sample_dt_s
from simrunner.workflows.gap.settings import GRAVITY_MPS2, SETTINGS, GapSettings
from vehicle.description import CarDescription


REGIMES = ("all", "accelerating", "braking", "coasting", "steady", "straight", "cornering", "left", "right",
           "reversing", "high_lat_accel")


def segment(log: RunLog, derived: Derived, car: CarDescription | None = None, *,
            settings: GapSettings = SETTINGS) -> dict[str, np.ndarray]:
    """Boolean masks (N,) for every name in :data:`REGIMES` (see the module docstring);
    ``car`` gives the grip limit (default: the default car)."""
    mu = (car or CarDescription()).wheels.friction_mu
    speed = np.where(np.isfinite(derived.speed_mps), derived.speed_mps, 0.0)
    moving = np.abs(speed) >= settings.moving_mps
    a = derived.accel_mps2 * np.sign(np.where(speed == 0.0, 1.0, speed))
    coasting = moving & (log.coasting() | (np.abs(log.speed_cmd_mps) < settings.coast_cmd_mps))
    accelerating = moving & ~coasting & (a > settings.accel_mps2)
    braking = moving & ~coasting & (a < -settings.accel_mps2)
    steady = moving & ~coasting & ~accelerating & ~braking
    left = moving & (log.steer_cmd_rad >= settings.straight_rad)
    right = moving & (log.steer_cmd_rad <= -settings.straight_rad)
    straight = moving & ~left & ~right
    with np.errstate(invalid="ignore"):
        lateral = (np.abs(derived.speed_mps * derived.yaw_rate_radps)
                   > settings.high_lateral_fraction * mu * GRAVITY_MPS2)
    return {"all": moving, "accelerating": accelerating, "braking": braking, "coasting": coasting,
            "steady": steady, "straight": straight, "cornering": left | right, "left": left, "right": right,
            "reversing": speed < -settings.moving_mps, "high_lat_accel": moving & lateral}


def brake_to_reverse(log: RunLog, derived: Derived, max_brake_mps2: float | None = None, *,
                     settings: GapSettings = SETTINGS) -> np.ndarray:
    """``(N,) bool``: a reverse command (``speed_cmd_mps`` below ``-settings.coast_cmd_mps``) while the
    car still rolls forward, faster than ``settings.moving_mps`` and than it sheds in one sample
    interval braking at ``max_brake_mps2`` (the car file's; None: ``settings.moving_mps`` only). An
    ESC that brakes before it reverses shows only there; slower, the car is at rest by the
    next sample and the log cannot show how it braked (DS2's reverse command from rest at a
    smoothed 0.11 m/s is no such event)."""
    speed = np.where(np.isfinite(derived.speed_mps), derived.speed_mps, 0.0)
    rolling_mps = (settings.moving_mps if max_brake_mps2 is None
                   else max(settings.moving_mps, max_brake_mps2 * sample_dt_s(log)))
    return (np.asarray(log.speed_cmd_mps, float) < -settings.coast_cmd_mps) & (speed > rolling_mps)


def reversal_onsets(log: RunLog, derived: Derived, windows, max_brake_mps2: float | None = None, *,
                    settings: GapSettings = SETTINGS) -> list[bool]:
    """One flag per window (anything with ``start``/``stop`` sample indices): does it hold
    a :func:`brake_to_reverse` sample? The one test behind the fit/held-out split, the
    screening subset and the cannot-reveal check."""
    onset = brake_to_reverse(log, derived, max_brake_mps2, settings=settings)
    return [bool(onset[w.start:w.stop].any()) for w in windows]


def residual_stats(residuals: dict[str, np.ndarray | None], masks: dict[str, np.ndarray]) -> list[dict]:
    """RMSE, bias (mean) and count of every residual signal in every regime.

    ``residuals``: signal name -> (N,) array, NaN where not compared (outside windows); a
    signal the log does not support may be left out or given as None (no rows). Returns
    rows ``{"signal", "regime", "count", "rmse", "bias"}`` in signal-then-regime order;
    ``rmse``/``bias`` are NaN when ``count`` is 0.
    """
    rows = []
    for signal, r in residuals.items():
        if r is None:
            continue
        for regime, m in masks.items():
            v = r[m & np.isfinite(r)]
            n = int(v.size)
            rows.append({"signal": signal, "regime": regime, "count": n,
                         "rmse": float(np.sqrt(np.mean(v * v))) if n else float("nan"),
                         "bias": float(np.mean(v)) if n else float("nan")})
    return rows


def format_stats(rows: list[dict], units: dict[str, str] | None = None) -> str:
    """A fixed-width text table of :func:`residual_stats` rows (signals as row blocks; ``-``
    where a value is NaN)."""
    units = units or {}

    def num(x: float) -> str:
        return f"{x:>11.4g}" if np.isfinite(x) else f"{'-':>11}"

    lines = [f"{'signal':<16}{'regime':<16}{'count':>7}{'rmse':>11}{'bias':>11}"]
    for r in rows:
        u = units.get(r["signal"], "")
        lines.append(f"{r['signal'] + (' ' + u if u else ''):<16}{r['regime']:<16}{r['count']:>7}"
                     f"{num(r['rmse'])}{num(r['bias'])}")
    return "\n".join(lines)
