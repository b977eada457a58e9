"""Windowed replay: re-run the logged commands in the simulator from the measured states.

The log is cut into windows of ``window_s`` (default :data:`WINDOW_S`). Each window starts
the simulator afresh from the measured (smoothed) state at its first sample
(``set_state(pose, speed, steer, yaw_rate)``, see :mod:`simrunner.gap.logs`), then applies
each logged command until the next sample time (zero-order hold) and records the predicted
state at every sample. Restarting keeps open-loop drift from swamping the comparison; one
simulator object serves all windows of a replay, so a whole replay is one pass.

Residual signals (predicted minus measured, shape (N,), NaN outside the replayed windows):

    along_m         position error along the measured heading
    cross_m         position error to the left of the measured heading
    yaw_rad         heading error, wrapped to [-pi, pi)
    speed_mps       speed error
    yaw_rate_radps  yaw-rate error (measured: derivative of the smoothed yaw)

``position_m`` (the distance, for reports) is ``hypot(along, cross)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from pieces.pose import Pose2
from simrunner.gap.logs import Derived, MeasuredLog
from worlds.car import CarDescription

WINDOW_S = 2.0
HOLDOUT_EVERY = 3  # every third window (index 2, 5, 8, ...) is held out from the fit
WORKFLOW_DT_S = 0.005  # physics step of the workflow (synthetic logs use 1 ms)
QUIET_SHIFT_S = 0.5  # window boundaries move by up to this to a quiet sample
QUIET_BEFORE_S = 0.25  # quiet = no command change in [t - before, t + after]
QUIET_AFTER_S = 0.1

FIT_SIGNALS = ("along_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
REPORT_SIGNALS = ("position_m", "yaw_rad", "speed_mps", "yaw_rate_radps")

SimFactory = Callable[[CarDescription, float], object]


def default_sim_factory(car: CarDescription, dt_s: float):
    """A simulator applying ``car.effects`` (``simrunner.effects.make_sim``)."""
    from simrunner.effects import make_sim

    return make_sim(car, dt_s=dt_s)


@dataclass(frozen=True)
class Window:
    """Samples ``start <= i < stop`` of a log."""

    start: int
    stop: int


def make_windows(log: MeasuredLog, window_s: float = WINDOW_S) -> list[Window]:
    """Consecutive windows of about ``window_s`` covering the log.

    Each boundary is moved (by up to :data:`QUIET_SHIFT_S`) to a quiet sample: the one with
    the least command change in ``[t - QUIET_BEFORE_S, t + QUIET_AFTER_S]`` (ties: nearest to
    the regular grid). A window that starts during a step or just after it would start
    from smoothed states that blur the step; quiet starts avoid that. The last window is
    merged into its neighbour when shorter than half a window.
    """
    t = log.t_s
    steps = np.abs(np.diff(log.speed_cmd_mps)) / 1.0 + np.abs(np.diff(log.steer_cmd_rad)) / 0.1
    csum = np.concatenate([[0.0], np.cumsum(steps)])  # csum[i] = change before sample i

    def activity(i: int) -> float:
        a = int(np.searchsorted(t, t[i] - QUIET_BEFORE_S))
        b = int(np.searchsorted(t, t[i] + QUIET_AFTER_S))
        return float(csum[min(b, len(t) - 1)] - csum[a])

    edges = [0]
    while True:
        goal = t[edges[-1]] + window_s
        if goal >= t[-1] - 0.5 * window_s:
            break
        lo = int(np.searchsorted(t, goal - QUIET_SHIFT_S))
        hi = int(np.searchsorted(t, goal + QUIET_SHIFT_S))
        cands = range(max(lo, edges[-1] + 1), min(hi, len(t) - 1))
        edges.append(min(cands, key=lambda i: (round(activity(i), 9), abs(t[i] - goal))))
    edges.append(len(t))
    return [Window(a, b) for a, b in zip(edges[:-1], edges[1:])]


def split_windows(windows: Sequence[Window], every: int = HOLDOUT_EVERY,
                  must_fit: Sequence[bool] | None = None) -> tuple[list[Window], list[Window]]:
    """(fit, held_out): window ``k`` is held out when ``k % every == every - 1``, except that
    a window flagged in ``must_fit`` (rare manoeuvres: the plan has one short coast) stays
    in the fit set and the next unflagged window is held out in its place."""
    flags = list(must_fit) if must_fit is not None else [False] * len(windows)
    held_idx: set[int] = set()
    pending = False
    for k in range(len(windows)):
        pending = pending or k % every == every - 1
        if pending and not flags[k]:
            held_idx.add(k)
            pending = False
    fit = [w for k, w in enumerate(windows) if k not in held_idx]
    held = [w for k, w in enumerate(windows) if k in held_idx]
    return fit, held


@dataclass(frozen=True)
class Prediction:
    """Predicted states at the log's samples, shape (N,), NaN outside replayed windows."""

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray


def replay(car: CarDescription, log: MeasuredLog, derived: Derived, windows: Sequence[Window], *,
           dt_s: float = WORKFLOW_DT_S, sim_factory: SimFactory = default_sim_factory) -> Prediction:
    """Replay ``windows`` of ``log`` with a simulator of ``car``; see the module docstring."""
    n = len(log)
    out = np.full((5, n), np.nan)
    sim = sim_factory(car, dt_s)
    t = log.t_s
    coast = log.coasting()
    for w in windows:
        i0 = w.start
        coast_now = bool(coast[i0])
        sim.set_coast(coast_now)
        sim.set_state(Pose2(derived.x_m[i0], derived.y_m[i0], derived.yaw_rad[i0]),
                      float(derived.speed_mps[i0]), float(derived.steer_rad[i0]),
                      float(derived.yaw_rate_radps[i0]))
        done = 0
        for i in range(i0, w.stop):
            p = sim.pose
            out[:, i] = (p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, sim.yaw_rate_radps)
            if i + 1 < w.stop:
                if coast[i] != coast_now:
                    coast_now = bool(coast[i])
                    sim.set_coast(coast_now)
                sim.set_command(float(log.speed_cmd_mps[i]), float(log.steer_cmd_rad[i]))
                target = int(round((t[i + 1] - t[i0]) / dt_s))
                if target > done:
                    sim.step(target - done)
                    done = target
    return Prediction(*out)


def residuals(log: MeasuredLog, derived: Derived, pred: Prediction) -> dict[str, np.ndarray]:
    """Predicted minus measured, per signal of :data:`FIT_SIGNALS` plus ``position_m``."""
    ex, ey = pred.x_m - log.x_m, pred.y_m - log.y_m
    c, s = np.cos(log.yaw_rad), np.sin(log.yaw_rad)
    along, cross = ex * c + ey * s, -ex * s + ey * c
    dyaw = (pred.yaw_rad - log.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
    return {"along_m": along, "cross_m": cross, "yaw_rad": dyaw,
            "speed_mps": pred.speed_mps - log.speed_mps,
            "yaw_rate_radps": pred.yaw_rate_radps - derived.yaw_rate_radps,
            "position_m": np.hypot(along, cross)}


def window_mask(n: int, windows: Sequence[Window]) -> np.ndarray:
    """Boolean (n,) mask of the samples inside ``windows``."""
    m = np.zeros(n, dtype=bool)
    for w in windows:
        m[w.start:w.stop] = True
    return m


def rmse(res: dict[str, np.ndarray], mask: np.ndarray, signals: Sequence[str] = REPORT_SIGNALS) -> dict[str, float]:
    """RMS of each residual signal over the finite samples in ``mask``."""
    out = {}
    for s in signals:
        v = res[s][mask & np.isfinite(res[s])]
        out[s] = float(np.sqrt(np.mean(v * v))) if v.size else float("nan")
    return out
