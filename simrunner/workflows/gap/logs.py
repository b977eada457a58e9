"""Measured logs: check a run log for the gap workflow and derive smoothed states from it.

A measured log is a :class:`simrunner.telemetry.log.RunLog` (read with
``simrunner.telemetry.log.read_log``; the one schema is docs/telemetry.md). The gap needs

    t_s            s     sample time, strictly increasing (irregular stamps are fine)
    speed_cmd_mps  m/s   commanded speed (physical units)
    steer_cmd_rad  rad   commanded bicycle-equivalent steering angle, positive = left

and at least one way to see the car move: the pose (``x_m, y_m`` of the rear-axle midpoint
in the world frame, ``yaw_rad`` counter-clockwise from +x, any wrapping) or a speed sensor
(``speed_mps``, signed, along the car's x: an encoder). A gyro (``yaw_rate_radps``) is used
when present. :func:`check_measured` also asks for at least ``settings.min_rows`` rows over
``settings.min_duration_s`` and a median sample rate of at least ``settings.min_rate_hz``, and says
what is missing in one ``path:line:`` error.

Which residual signals a log supports follows from its columns
(:func:`simrunner.workflows.gap.replay.signals_of`): the pose gives position and heading,
and speed and yaw rate when there is no speed sensor or gyro.

``coast`` (0/1: drive off, rear wheels rolling freely) is used when present (absent: never
coasting); other columns are ignored.

Commands are taken as held from their sample to the next one (zero-order hold), as
``simrunner.workflows.excite.run_plan`` logs them: the state at ``t_k`` and the command set at ``t_k``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from simrunner.telemetry.log import LogError, RunLog
from simrunner.workflows.gap.glitches import has_pose, time_gaps
from simrunner.workflows.gap.settings import SETTINGS, GapSettings

REQUIRED_COLUMNS = ("t_s", "speed_cmd_mps", "steer_cmd_rad")
POSE_COLUMNS = ("x_m", "y_m", "yaw_rad")
# every state column a measured log may carry (a synthetic log has these and ``coast``)
MEASURED_COLUMNS = ("t_s", "x_m", "y_m", "yaw_rad", "speed_mps", "speed_cmd_mps", "steer_cmd_rad")
def is_duty_log(log: RunLog) -> bool:
    """The log's motor command is a PWM duty: ``duty_cmd``, or ``duty_left`` and ``duty_right``."""
    return log.duty_cmd is not None or (log.duty_left is not None and log.duty_right is not None)


def duty_commands(log: RunLog) -> RunLog:
    """A duty log with its duty as the command the replay sends (``speed_cmd_mps``: a
    duty-driven car takes it as the duty of both motors, as ``set_speed`` does; where
    ``duty_cmd`` is nan or absent, the mean of ``duty_left`` and ``duty_right``, which the
    replay then sets each). Duties outside -1..1 are a :class:`LogError` naming the row."""
    for name in ("duty_cmd", "duty_left", "duty_right"):
        a = getattr(log, name)
        if a is None:
            continue
        bad = np.flatnonzero(np.abs(a) > 1.0 + 1e-9)
        if bad.size:
            raise LogError(log.source, int(bad[0]) + 2, f"column {name!r}: expected a duty in -1..1 (got "
                                                        f"{a[bad[0]]:g}); a duty in percent: --column "
                                                        f"'{name}=YOUR_COLUMN / 100'")
    if log.duty_left is not None and log.duty_right is not None:
        mean = 0.5 * (log.duty_left + log.duty_right)
        cmd = mean if log.duty_cmd is None else np.where(np.isfinite(log.duty_cmd), log.duty_cmd, mean)
    else:
        cmd = log.duty_cmd
        if not np.all(np.isfinite(cmd)):
            i = int(np.flatnonzero(~np.isfinite(cmd))[0])
            raise LogError(log.source, i + 2, "column 'duty_cmd': expected a duty (nan only with duty_left "
                                              "and duty_right, the motors' own)")
    return dataclasses.replace(log, speed_cmd_mps=np.asarray(cmd, dtype=float))


def check_measured(log: RunLog, pooled: bool = False, *, settings: GapSettings = SETTINGS) -> RunLog:
    """``log`` if the gap workflow can use it (see the module docstring), else
    :class:`simrunner.telemetry.log.LogError` (``path:line: what was expected``); a duty log
    (:func:`is_duty_log`) comes back with its duty as the command (:func:`duty_commands`). ``pooled``: one
    of several runs of a data set, which may be as short as one replay window
    (``settings.min_run_rows``, ``min_run_s``; the data set as a whole needs three windows)."""
    if is_duty_log(log):
        log = duty_commands(log)
    log.require(*REQUIRED_COLUMNS)
    if log.speed_mps is None and not has_pose(log):
        missing = [c for c in POSE_COLUMNS if getattr(log, c) is None]
        raise LogError(log.source, 1, f"expected a pose ({', '.join(POSE_COLUMNS)}) or a speed sensor (speed_mps) "
                                      f"(missing: {', '.join(missing)}, speed_mps)")
    if pooled:
        log.require(*REQUIRED_COLUMNS, min_rows=settings.min_run_rows, min_duration_s=settings.min_run_s)
    else:
        log.require(*REQUIRED_COLUMNS, min_rows=settings.min_rows, min_duration_s=settings.min_duration_s)
    step = float(np.median(np.diff(log.t_s)))
    rate = 1.0 / step
    if rate < settings.min_rate_hz * (1.0 - 1e-6):
        raise LogError(log.source, 0, f"expected a median sample rate of at least {settings.min_rate_hz:g} Hz "
                                      f"(got {rate:.3g} Hz){_stamp_unit_hint(step, settings=settings)}")
    return log


def _stamp_unit_hint(step: float, *, settings: GapSettings = SETTINGS) -> str:
    """For a median time step that would be a plausible logging rate (10-1000 Hz) in ms, us
    or ns: the mapping that reads such stamps (docs/telemetry.md), else ''."""
    for unit, factor in (("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)):
        if settings.min_rate_hz <= 1.0 / (step * factor) <= 1000.0:
            return (f"; a median step of {step:.6g} looks like stamps in {unit}: read them with "
                    f"--column 't_s={{column = \"YOUR_TIME_COLUMN\", unit = \"{unit}\"}}'")
    return ""


@dataclass(frozen=True)
class Derived:
    """Smoothed states of a log (Savitzky-Golay, ``settings.smooth_s`` window), all shape (N,), NaN
    where the log cannot give them (no pose: ``x_m``, ``y_m``, ``yaw_rad``; no pose and no
    gyro: ``yaw_rate_radps``) and at excluded samples.

    ``yaw_rad`` is unwrapped within each piece; ``speed_mps`` is the smoothed speed sensor,
    else the pose's velocity along the heading; ``yaw_rate_radps`` the smoothed gyro, else the
    derivative of the smoothed yaw; ``accel_mps2`` the derivative of the smoothed speed;
    ``steer_rad`` the bicycle-equivalent steer that explains the yaw rate,
    ``atan(L * r / v)``, or the command where ``|v|`` is small or the yaw rate unknown;
    ``at_rest`` (bool) where the car stands still (:func:`at_rest`): a replay starting there
    starts the car at rest, not at the smoothed noise's speed (a car whose drive is off, a
    deadband's, would roll on at it).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray
    accel_mps2: np.ndarray
    steer_rad: np.ndarray
    at_rest: np.ndarray


def sample_dt_s(log: RunLog) -> float:
    """Median sample interval."""
    return float(np.median(np.diff(log.t_s)))


def pieces(log: RunLog, exclude: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Sample ranges ``[a, b)`` of kept samples (not ``exclude``) without a time gap inside
    (:func:`simrunner.workflows.gap.glitches.time_gaps`), in order."""
    n = len(log)
    keep = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    cut = np.zeros(n + 1, dtype=bool)  # cut[k]: a piece boundary before sample k
    cut[1:n] = time_gaps(log.t_s)
    out, a = [], None
    for k in range(n):
        if a is not None and (not keep[k] or cut[k]):
            out.append((a, k))
            a = None
        if keep[k] and a is None:
            a = k
    if a is not None:
        out.append((a, n))
    return out


def speed_estimate(log: RunLog) -> np.ndarray:
    """``(N,)`` unsmoothed signed speed: the speed sensor, else the pose's velocity along the
    heading (central differences within each piece; zero for a single-sample piece)."""
    if log.speed_mps is not None:
        return log.speed_mps
    out = np.zeros(len(log))
    t = log.t_s
    for a, b in pieces(log):
        if b - a < 2:
            continue
        vx, vy = np.gradient(log.x_m[a:b], t[a:b]), np.gradient(log.y_m[a:b], t[a:b])
        out[a:b] = vx * np.cos(log.yaw_rad[a:b]) + vy * np.sin(log.yaw_rad[a:b])
    return out


def derive(log: RunLog, wheelbase_m: float, steer_limit_rad: float = math.inf, *,
           exclude: np.ndarray | None = None, settings: GapSettings = SETTINGS) -> Derived:
    """Smoothed states and derivatives; see :class:`Derived`.

    The log is smoothed piece by piece (:func:`pieces`): nothing is smoothed across a time
    gap or an ``exclude``-d sample (``(N,) bool``, e.g.
    :func:`simrunner.workflows.gap.glitches.glitch_mask`), which stay NaN. Within a piece,
    the irregular stamps are resampled to a uniform grid, filtered and sampled back."""
    n = len(log)
    out = {k: np.full(n, np.nan) for k in ("x_m", "y_m", "yaw_rad", "speed_mps", "yaw_rate_radps", "accel_mps2")}
    for a, b in pieces(log, exclude):
        for k, v in _derive_piece(log, a, b, settings).items():
            out[k][a:b] = v
    speed, yaw_rate = out["speed_mps"], out["yaw_rate_radps"]
    with np.errstate(divide="ignore", invalid="ignore"):
        steer = np.arctan(wheelbase_m * yaw_rate / speed)
    fallback = ~(np.abs(speed) >= settings.min_speed_for_steer_mps) | ~np.isfinite(steer)
    steer = np.where(fallback, log.steer_cmd_rad, steer)
    steer = np.clip(steer, -steer_limit_rad, steer_limit_rad)
    if exclude is not None:
        steer = np.where(np.asarray(exclude, dtype=bool), np.nan, steer)
    return Derived(out["x_m"], out["y_m"], out["yaw_rad"], speed, yaw_rate, out["accel_mps2"], steer,
                   at_rest(log, out, exclude, settings=settings))


def rms_finite(v: np.ndarray) -> float:
    """RMS of the finite values of ``v`` (NaN for none)."""
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v * v))) if v.size else math.nan


def at_rest(log: RunLog, smoothed: dict[str, np.ndarray], exclude: np.ndarray | None = None, *,
            settings: GapSettings = SETTINGS) -> np.ndarray:
    """``(N,) bool``: the car stands still at the sample. Over ``settings.smooth_s`` either side
    (within the sample's piece, :func:`pieces`; at least 3 readings), the speed readings'
    mean (a speed sensor; without one, the slope of a straight line through each of the
    pose's x and y against time) lies within ``settings.at_rest_z`` of its standard errors of
    zero: the readings cannot tell the car from one standing still. The noise sigma is the
    RMS of the readings about ``smoothed`` (:func:`derive`'s states: a little below the true
    sigma, the smoother follows part of the noise)."""
    n = len(log)
    out = np.zeros(n, dtype=bool)
    t = log.t_s
    if log.speed_mps is not None:
        sigma = rms_finite(log.speed_mps - smoothed["speed_mps"])
    elif has_pose(log):
        sigma = rms_finite(np.hypot(log.x_m - smoothed["x_m"], log.y_m - smoothed["y_m"])) / math.sqrt(2.0)
    else:  # pragma: no cover - check_measured asks for a pose or a speed sensor
        return out
    if not sigma > 0.0:
        return out
    for a, b in pieces(log, exclude):
        tt = t[a:b]
        lo = np.searchsorted(tt, tt - settings.smooth_s - 1e-9, side="left")
        hi = np.searchsorted(tt, tt + settings.smooth_s + 1e-9, side="right")
        m = hi - lo
        if log.speed_mps is not None:  # the finite readings' mean
            v = log.speed_mps[a:b]
            finite = np.isfinite(v)
            c = np.concatenate([[0.0], np.cumsum(np.where(finite, v, 0.0))])
            k = np.concatenate([[0], np.cumsum(finite)])
            m = k[hi] - k[lo]
            mean = (c[hi] - c[lo]) / np.maximum(m, 1)
            out[a:b] = (m >= 3) & (np.abs(mean) <= settings.at_rest_z * sigma / np.sqrt(np.maximum(m, 1)))
            continue
        xs, ys = log.x_m[a:b], log.y_m[a:b]
        for i in np.flatnonzero(m >= 3):
            dt = tt[lo[i]:hi[i]] - tt[i]
            sxx = float(np.sum((dt - dt.mean()) ** 2))
            if sxx <= 0.0:
                continue
            limit = settings.at_rest_z * sigma / math.sqrt(sxx)  # the slope's standard error times settings.at_rest_z
            out[a + i] = all(abs(float(np.dot(dt - dt.mean(), p[lo[i]:hi[i]]))) / sxx <= limit for p in (xs, ys))
    return out


def _derive_piece(log: RunLog, a: int, b: int, settings: GapSettings) -> dict[str, np.ndarray]:
    """Smoothed states of samples a .. b - 1 (one piece: no gap, nothing excluded)."""
    m = b - a
    t = log.t_s[a:b]
    if m < 3:  # too short to smooth or differentiate: the raw values, no derivatives
        raw = {}
        if has_pose(log):
            raw.update(x_m=log.x_m[a:b], y_m=log.y_m[a:b], yaw_rad=log.yaw_rad[a:b])
        if log.speed_mps is not None:
            raw["speed_mps"] = log.speed_mps[a:b]
        if log.yaw_rate_radps is not None:
            raw["yaw_rate_radps"] = log.yaw_rate_radps[a:b]
        return raw
    sg = _Smoother(t, settings=settings)
    on_grid, back = sg.on_grid, sg.back
    out: dict[str, np.ndarray] = {}
    if has_pose(log):
        pose = _pose_states(sg, log.x_m[a:b], log.y_m[a:b], log.yaw_rad[a:b])
        out.update(x_m=pose["x_m"], y_m=pose["y_m"], yaw_rad=pose["yaw_rad"])
    if log.speed_mps is not None:
        out["speed_mps"] = back(on_grid(log.speed_mps[a:b]))
        out["accel_mps2"] = back(on_grid(log.speed_mps[a:b], 1))
    elif has_pose(log):  # the pose's velocity along the heading
        out["speed_mps"] = back(pose["v_grid"])
        out["accel_mps2"] = back(sg.filter(pose["v_grid"], 1))
    if log.yaw_rate_radps is not None:  # the gyro, when there is one
        out["yaw_rate_radps"] = back(on_grid(log.yaw_rate_radps[a:b]))
    elif has_pose(log):
        out["yaw_rate_radps"] = pose["yaw_rate_radps"]
    return out


class _Smoother:
    """The Savitzky-Golay smoothing of one piece with stamps ``t`` (at least 3): it assumes a
    uniform grid, so values are resampled to one, filtered, and sampled back."""

    def __init__(self, t: np.ndarray, win: int | None = None, *, settings: GapSettings = SETTINGS):
        m = len(t)
        self.t = t
        self.grid = np.linspace(t[0], t[-1], m)
        self.step = self.grid[1] - self.grid[0]
        if win is None:
            win = smoothing_window(t, settings=settings)
        self.win = min(win, m if m % 2 else m - 1)
        self.order = min(2, self.win - 1)

    def on_grid(self, v: np.ndarray, deriv: int = 0) -> np.ndarray:
        """``v`` (at the stamps) resampled to the grid and filtered."""
        return self.filter(np.interp(self.grid, self.t, v), deriv)

    def filter(self, g: np.ndarray, deriv: int = 0) -> np.ndarray:
        """``g`` (on the grid) filtered, or its ``deriv``-th derivative."""
        from scipy.signal import savgol_filter  # here, not at import: `simrunner gap --help` stays quick

        return savgol_filter(g, self.win, self.order, deriv=deriv, delta=self.step, mode="interp")

    def back(self, g: np.ndarray) -> np.ndarray:
        return np.interp(self.t, self.grid, g)


def smoothing_window(t_s: np.ndarray, *, settings: GapSettings = SETTINGS) -> int:
    """Samples in the smoothing window of :func:`derive` for one piece with stamps ``t_s``
    (odd, at least 5; about ``settings.smooth_s`` at the piece's mean rate; at most the piece)."""
    m = len(t_s)
    step = (t_s[-1] - t_s[0]) / (m - 1)
    win = max(5, int(round(settings.smooth_s / step)) | 1)
    return min(win, m if m % 2 else m - 1)


def _pose_speeds(sg: _Smoother, x_m: np.ndarray, y_m: np.ndarray, yaw_rad: np.ndarray):
    """``(yaw on the grid, speed on the grid, yaw rate)`` the pose gives (smoothed)."""
    yaw_u = np.unwrap(yaw_rad)
    yaw_grid = sg.on_grid(yaw_u)
    v_grid = sg.on_grid(x_m, 1) * np.cos(yaw_grid) + sg.on_grid(y_m, 1) * np.sin(yaw_grid)
    return yaw_grid, v_grid, sg.back(sg.on_grid(yaw_u, 1))


def _pose_states(sg: _Smoother, x_m: np.ndarray, y_m: np.ndarray, yaw_rad: np.ndarray) -> dict[str, np.ndarray]:
    """Smoothed pose, and the speed (on the grid: ``v_grid``) and yaw rate the pose gives."""
    yaw_grid, v_grid, yaw_rate = _pose_speeds(sg, x_m, y_m, yaw_rad)
    return {"x_m": sg.back(sg.on_grid(x_m)), "y_m": sg.back(sg.on_grid(y_m)), "yaw_rad": sg.back(yaw_grid),
            "v_grid": v_grid, "yaw_rate_radps": yaw_rate}


def pose_rates(t_s: np.ndarray, x_m: np.ndarray, y_m: np.ndarray, yaw_rad: np.ndarray,
               window: int | None = None, *, settings: GapSettings = SETTINGS) -> tuple[np.ndarray, np.ndarray]:
    """``(speed_mps, yaw_rate_radps)`` that :func:`derive` takes from a pose ``x_m, y_m,
    yaw_rad`` at stamps ``t_s`` (one piece, no gap): the same smoothing and derivatives. The
    replay puts its predicted pose through this where the log's speed or yaw rate comes from
    its pose, so that the prediction is compared with what the pose shows (the smoothing
    rounds a step in yaw rate over ``settings.smooth_s``; compared unsmoothed, that rounding looks
    like a slower servo or a latency). ``window``: samples in the smoothing window (that of
    the log piece the samples come from, :func:`smoothing_window`; default: from ``t_s``).
    Fewer than 3 samples: NaN."""
    t_s = np.asarray(t_s, dtype=float)
    if len(t_s) < 3:
        nan = np.full(len(t_s), np.nan)
        return nan, nan.copy()
    sg = _Smoother(t_s, window, settings=settings)  # (the smoothed pose itself is not needed here)
    _, v_grid, yaw_rate = _pose_speeds(sg, np.asarray(x_m, float), np.asarray(y_m, float), np.asarray(yaw_rad, float))
    return sg.back(v_grid), yaw_rate


__all__ = ["Derived", "at_rest", "check_measured", "derive", "pieces", "pose_rates", "rms_finite", "smoothing_window",
           "speed_estimate", "sample_dt_s", "MEASURED_COLUMNS", "REQUIRED_COLUMNS", "POSE_COLUMNS",]
