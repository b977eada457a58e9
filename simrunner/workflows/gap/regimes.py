"""Driving regimes of a log and residual statistics per signal and regime.

Regimes (boolean masks, shape (N,); a sample can be in one longitudinal and one lateral
regime; samples with ``|speed| < MOVING_MPS`` are in neither):

    accelerating   smoothed acceleration > ACCEL_MPS2
    braking        acceleration < -ACCEL_MPS2 while drive is commanded (|speed_cmd| >= COAST_CMD_MPS)
    coasting       drive off (the log's ``coast`` column) or no drive commanded
                   (|speed_cmd| < COAST_CMD_MPS), while moving
    steady         moving, none of the three above
    straight       |steer_cmd| < STRAIGHT_RAD
    left, right    steer_cmd >= STRAIGHT_RAD / <= -STRAIGHT_RAD
    cornering      left or right

Lateral regimes follow the *command*: a car that curves while told to go straight shows up
as a cross-track bias in "straight", which is what a steering offset looks like.
"""
from __future__ import annotations

import numpy as np

from simrunner.run.log import RunLog
from simrunner.workflows.gap.logs import Derived

MOVING_MPS = 0.1
ACCEL_MPS2 = 0.3
COAST_CMD_MPS = 0.05
STRAIGHT_RAD = 0.03

REGIMES = ("all", "accelerating", "braking", "coasting", "steady", "straight", "cornering", "left", "right")


def segment(log: RunLog, derived: Derived) -> dict[str, np.ndarray]:
    """Boolean masks (N,) for every name in :data:`REGIMES` (see the module docstring)."""
    moving = np.abs(derived.speed_mps) >= MOVING_MPS
    a = derived.accel_mps2 * np.sign(np.where(derived.speed_mps == 0.0, 1.0, derived.speed_mps))
    coasting = moving & (log.coasting() | (np.abs(log.speed_cmd_mps) < COAST_CMD_MPS))
    accelerating = moving & ~coasting & (a > ACCEL_MPS2)
    braking = moving & ~coasting & (a < -ACCEL_MPS2)
    steady = moving & ~coasting & ~accelerating & ~braking
    left = moving & (log.steer_cmd_rad >= STRAIGHT_RAD)
    right = moving & (log.steer_cmd_rad <= -STRAIGHT_RAD)
    straight = moving & ~left & ~right
    return {"all": moving, "accelerating": accelerating, "braking": braking, "coasting": coasting,
            "steady": steady, "straight": straight, "cornering": left | right, "left": left, "right": right}


def residual_stats(residuals: dict[str, np.ndarray], masks: dict[str, np.ndarray]) -> list[dict]:
    """RMSE, bias (mean) and count of every residual signal in every regime.

    ``residuals``: signal name -> (N,) array, NaN where not compared (outside windows).
    Returns rows ``{"signal", "regime", "count", "rmse", "bias"}`` in signal-then-regime
    order; ``rmse``/``bias`` are NaN when ``count`` is 0.
    """
    rows = []
    for signal, r in residuals.items():
        for regime, m in masks.items():
            v = r[m & np.isfinite(r)]
            n = int(v.size)
            rows.append({"signal": signal, "regime": regime, "count": n,
                         "rmse": float(np.sqrt(np.mean(v * v))) if n else float("nan"),
                         "bias": float(np.mean(v)) if n else float("nan")})
    return rows


def format_stats(rows: list[dict], units: dict[str, str] | None = None) -> str:
    """A fixed-width text table of :func:`residual_stats` rows (signals as row blocks)."""
    units = units or {}
    lines = [f"{'signal':<16}{'regime':<14}{'count':>7}{'rmse':>11}{'bias':>11}"]
    for r in rows:
        u = units.get(r["signal"], "")
        lines.append(f"{r['signal'] + (' ' + u if u else ''):<16}{r['regime']:<14}{r['count']:>7}"
                     f"{r['rmse']:>11.4g}{r['bias']:>11.4g}")
    return "\n".join(lines)
