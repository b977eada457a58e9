"""Windowed replay: re-run the logged commands in the simulator from the measured states.

The log is cut into windows of ``window_s`` (default :data:`WINDOW_S`). Each window starts
the simulator afresh from the measured (smoothed) state at its first sample
(``set_state(pose, speed, steer, yaw_rate)``, see :mod:`simrunner.workflows.gap.logs`), then applies
each logged command until the next sample time (zero-order hold) and records the predicted
state at every sample. Before a window, the :data:`LEAD_S` seconds of commands that
precede it are replayed unrecorded and the car is then moved (``place``) to the measured
state at the window's start, so latency queues and lags carry the commands in flight. Restarting keeps open-loop drift from swamping the comparison; one
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
from simrunner.run.log import RunLog
from simrunner.workflows.gap.logs import Derived
from vehicle.description import CarDescription

WINDOW_S = 2.0
HOLDOUT_EVERY = 3  # every third window, counted back from the last, is held out
WORKFLOW_DT_S = 0.005  # physics step of the workflow (synthetic logs use 1 ms)
QUIET_SHIFT_S = 0.5  # window boundaries move by up to this to a quiet sample
QUIET_BEFORE_S = 0.25  # quiet = no command change in [t - before, t + after]
QUIET_AFTER_S = 0.1
NO_DRIVE_CMD_MPS = 0.05  # |speed_cmd| below this: no drive (as regimes.COAST_CMD_MPS)
MOVING_MPS = 0.1
LEAD_S = 0.3  # commands replayed before each window (not compared), see replay()

FIT_SIGNALS = ("along_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
REPORT_SIGNALS = ("position_m", "yaw_rad", "speed_mps", "yaw_rate_radps")

SimFactory = Callable[[CarDescription, float], object]


def default_sim_factory(car: CarDescription, dt_s: float):
    """A simulator applying ``car.effects`` (``simrunner.car.effects.make_sim``)."""
    from simrunner.car.effects import make_sim

    return make_sim(car, dt_s=dt_s)


@dataclass(frozen=True)
class Window:
    """Samples ``start <= i < stop`` of a log."""

    start: int
    stop: int


def make_windows(log: RunLog, window_s: float = WINDOW_S) -> list[Window]:
    """Consecutive windows of about ``window_s`` covering the log.

    Each boundary is moved (by up to :data:`QUIET_SHIFT_S`) to a quiet sample: the one with
    the least command change in ``[t - QUIET_BEFORE_S, t + QUIET_AFTER_S]`` (ties: nearest to
    the regular grid). A window that starts during a step or just after it would start
    from smoothed states that blur the step; quiet starts avoid that. A sample where the
    car rolls with the drive off (coasting, or ``speed_cmd`` ~ 0 while moving) in
    ``[t, t + QUIET_AFTER_S]`` is avoided above all: no speed loop would correct the
    noise in the start speed there, and the error would grow through the window. The last window is
    merged into its neighbour when shorter than half a window.
    """
    t = log.t_s
    steps = np.abs(np.diff(log.speed_cmd_mps)) / 1.0 + np.abs(np.diff(log.steer_cmd_rad)) / 0.1
    csum = np.concatenate([[0.0], np.cumsum(steps)])  # csum[i] = change before sample i
    # rolling with the drive off (coasting or braking to rest): no speed loop corrects the
    # start state there, so a noisy start speed would persist through the window
    free = (log.coasting() | (np.abs(log.speed_cmd_mps) < NO_DRIVE_CMD_MPS)) & (np.abs(log.speed_mps) >= MOVING_MPS)
    fsum = np.concatenate([[0], np.cumsum(free)])

    def activity(i: int) -> float:
        a = int(np.searchsorted(t, t[i] - QUIET_BEFORE_S))
        b = int(np.searchsorted(t, t[i] + QUIET_AFTER_S))
        b = min(b, len(t) - 1)
        return float(csum[b] - csum[a]) + (1e3 if fsum[b + 1] - fsum[i] else 0.0)

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
                  strata: Sequence[object] | None = None) -> tuple[list[Window], list[Window]]:
    """(fit, held_out), stratified: the windows are grouped by their ``strata`` label
    (default: one group) and, counting back from the group's last window, every
    ``every``-th window is held out (the last, the ``every + 1``-th from last, ...). So a
    rare manoeuvre (the report groups windows with coasting or braking to rest apart from
    the others) reaches the held-out set as soon as the log has two of them — the plan's
    last coast — while its first ones stay in the fit. A group of one window stays in the
    fit; if nothing is held out that way (a short log), the split ignores the strata."""
    labels = list(strata) if strata is not None else [None] * len(windows)
    size: dict[object, int] = {}
    for label in labels:
        size[label] = size.get(label, 0) + 1
    left = dict(size)
    fit, held = [], []
    for w, label in zip(windows, labels):
        left[label] -= 1  # windows of this group after this one
        (held if left[label] % every == 0 and size[label] > 1 else fit).append(w)
    if not held and strata is not None:  # a short log: hold out without strata
        return split_windows(windows, every)
    return fit, held


@dataclass(frozen=True)
class Prediction:
    """Predicted states at the log's samples, shape (N,), NaN outside replayed windows."""

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray


def replay(car: CarDescription, log: RunLog, derived: Derived, windows: Sequence[Window], *,
           dt_s: float = WORKFLOW_DT_S, sim_factory: SimFactory = default_sim_factory,
           lead_s: float | None = None) -> Prediction:
    """Replay ``windows`` of ``log`` with a simulator of ``car``; see the module docstring.

    Lead-in: a window starting at sample ``i0 > 0`` is preceded by the ``lead_s`` seconds
    of commands before it, replayed from the measured state at their first sample and not
    recorded; at ``i0`` the car is moved to the measured state with ``sim.place`` (the
    physical state only), so commands still in flight (latency, lags, rate limits) reach
    the window as they would on the car instead of starting settled. ``lead_s=None``:
    :data:`LEAD_S`; 0 starts every window settled."""
    lead_s = LEAD_S if lead_s is None else float(lead_s)
    n = len(log)
    out = np.full((5, n), np.nan)
    sim = sim_factory(car, dt_s)
    t = log.t_s
    coast = log.coasting()

    def state(i: int):
        return (Pose2(derived.x_m[i], derived.y_m[i], derived.yaw_rad[i]), float(derived.speed_mps[i]),
                float(derived.steer_rad[i]), float(derived.yaw_rate_radps[i]))

    def run(a: int, b: int, record: bool) -> None:
        """Apply the commands of samples a .. b-1 (zero-order hold) up to sample b (recorded
        at a .. b-1 when ``record``; the last command is applied only if b is past it)."""
        done = 0
        coast_now = bool(coast[a])
        for i in range(a, b):
            if record:
                p = sim.pose
                out[:, i] = (p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, sim.yaw_rate_radps)
            if i + 1 < n and (i + 1 < b or not record):
                if coast[i] != coast_now:
                    coast_now = bool(coast[i])
                    sim.set_coast(coast_now)
                sim.set_command(float(log.speed_cmd_mps[i]), float(log.steer_cmd_rad[i]))
                target = int(round((t[i + 1] - t[a]) / dt_s))
                if target > done:
                    sim.step(target - done)
                    done = target

    for w in windows:
        i0 = w.start
        j0 = int(np.searchsorted(t, t[i0] - lead_s - 1e-9)) if lead_s > 0.0 else i0
        sim.set_coast(bool(coast[j0]))
        sim.set_state(*state(j0))
        if j0 < i0:
            run(j0, i0, record=False)
            if bool(coast[i0 - 1]) != bool(coast[i0]):
                sim.set_coast(bool(coast[i0]))
            sim.place(*state(i0))
        run(i0, w.stop, record=True)
    return Prediction(*out)


def residuals(log: RunLog, derived: Derived, pred: Prediction) -> dict[str, np.ndarray]:
    """Predicted minus measured, per signal of :data:`FIT_SIGNALS` plus ``position_m``."""
    ex, ey = pred.x_m - log.x_m, pred.y_m - log.y_m
    c, s = np.cos(log.yaw_rad), np.sin(log.yaw_rad)
    along, cross = ex * c + ey * s, -ex * s + ey * c
    dyaw = (pred.yaw_rad - log.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
    return {"along_m": along, "cross_m": cross, "yaw_rad": dyaw,
            "speed_mps": pred.speed_mps - log.speed_mps,
            "yaw_rate_radps": pred.yaw_rate_radps - derived.yaw_rate_radps,
            "position_m": np.hypot(along, cross)}


def smoothed_log(log: RunLog, derived: Derived) -> RunLog:
    """``log`` with its states replaced by the smoothed ones (``derived``): residuals against
    it show the model error without most of the sensor noise."""
    return log.with_columns(x_m=derived.x_m, y_m=derived.y_m, yaw_rad=derived.yaw_rad,
                            speed_mps=derived.speed_mps)


def noise_rms(log: RunLog, derived: Derived) -> dict[str, float]:
    """Estimated sensor noise: RMS of measured minus smoothed states, per report signal
    (about 15 % below the true white-noise sigma: the smoother follows part of the noise)
    (``position_m`` is the distance; ``yaw_rate_radps`` is not measured: NaN)."""
    dyaw = (log.yaw_rad - derived.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
    ms = lambda v: float(np.sqrt(np.mean(v * v)))  # noqa: E731
    return {"position_m": ms(np.hypot(log.x_m - derived.x_m, log.y_m - derived.y_m)), "yaw_rad": ms(dyaw),
            "speed_mps": ms(log.speed_mps - derived.speed_mps), "yaw_rate_radps": float("nan")}


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
