"""Sign and unit conventions of a measured log, checked between its own signals.

A log whose columns follow other conventions than the run log's (docs/telemetry.md) reads
without an error, and the chain would then fit nonsense to it: a gyro that counts
clockwise as positive, a steering command that is positive to the right (the thesis's car),
a speed in km/h read as m/s, a heading in degrees. Each of these leaves an unmistakable trace
between the log's own signals, so :func:`check_conventions` compares them where the log has
two views of one quantity and refuses the log (:class:`~simrunner.telemetry.log.LogError`, the
column named, what was found, what was expected and how to map it) when one is reversed or
off by a unit's factor:

========================  ==========================================================  =========================
check                     compares (moving samples, glitches left out)                refused when
========================  ==========================================================  =========================
heading                   ``yaw_rad`` with the direction of the path's chords         negated or in degrees it fits
                                                                                      better; or under half the
                                                                                      chords within 37 deg (chords:
                                                                                      0.5 s, at least 0.3 m)
gyro                      ``yaw_rate_radps`` with the pose's yaw rate                 slope -1 (sign) or ~57 (deg/s)
speed sensor              ``speed_mps`` with the pose's speed along its heading        slope -1 (sign) or ~3.6, 100,
                                                                                      1000 (km/h, cm/s, mm/s)
speed command             ``speed_cmd_mps`` with the measured speed                    opposite signs (slope < 0),
                                                                                      or the speed 2.5x the command
steering command range    ``steer_cmd_rad`` itself                                     1 % of it beyond both 1.2 rad
                                                                                      and 3x the car's limit
steering command sign     the measured yaw rate with ``v tan(steer_cmd) / L``           opposite signs (slope < 0);
                                                                                      a gyro without a pose: slope
                                                                                      57 +- 60 % (deg/s)
========================  ==========================================================  =========================

"slope": the least-squares slope through the origin of the first signal on the second over
the samples where the second is clearly non-zero (``settings.conventions_min_rate_radps``,
``settings.conventions_min_speed_mps``), with their correlation
beyond +-``settings.conventions_min_correlation``; a check
needs ``settings.conventions_min_samples`` such samples (else it is skipped: the log does not show it). The
bands are wide (a real car's odometry and pose disagree by up to ~20 %, a gain or a lag
moves a slope, never its sign) and a unit factor is named only near its value, so a log in
the right conventions is never refused for a car effect.
"""
from __future__ import annotations

import math

import numpy as np

from simrunner.telemetry.log import LogError, RunLog
from simrunner.workflows.gap.glitches import has_pose
from simrunner.workflows.gap.logs import Derived, derive, is_duty_log
from simrunner.workflows.gap.settings import SETTINGS, GapSettings

_DOC = "(docs/telemetry.md, \"Logs with other columns or units\")"
_REVERSED = "sign is reversed? map it negated, e.g. --column '{col}=-COLUMN'"


def _fit(y: np.ndarray, x: np.ndarray, ok: np.ndarray, *,
         settings: GapSettings = SETTINGS) -> tuple[float, float] | None:
    """(slope through the origin of y on x, correlation) over ``ok``; None when too few."""
    ok = ok & np.isfinite(x) & np.isfinite(y)
    if np.count_nonzero(ok) < settings.conventions_min_samples:
        return None
    x, y = x[ok], y[ok]
    sxx, syy = float(np.dot(x, x)), float(np.dot(y, y))
    if sxx <= 0.0 or syy <= 0.0:
        return None
    sxy = float(np.dot(x, y))
    return sxy / sxx, sxy / math.sqrt(sxx * syy)


def _unit(slope: float, factors: dict[str, float], band: float | None = None, *,
          settings: GapSettings = SETTINGS) -> str | None:
    band = settings.unit_band if band is None else band
    for unit, f in factors.items():
        if abs(slope / f - 1.0) <= band:
            return unit
    return None


def _refuse(log: RunLog, column: str, text: str) -> LogError:
    return LogError(log.source, 1, f"{column}: {text}")


def _heading(log: RunLog, exclude: np.ndarray, *, settings: GapSettings = SETTINGS) -> bool:
    """The heading points along the motion (forward or reversing): the direction of each
    chord of the path over ``settings.chord_s`` that travels at least ``settings.chord_m`` (so a
    standing car's localisation jitter, centimetres in any direction, never counts) against
    the mean heading at its ends."""
    t, x, y = log.t_s, log.x_m, log.y_m
    j = np.searchsorted(t, t + settings.chord_s)
    i = np.flatnonzero(j < len(t))
    j = j[i]
    bad = np.concatenate([[0], np.cumsum(exclude.astype(np.int64))])  # excluded samples in [i, j]
    ok = (bad[j + 1] - bad[i] == 0) & (t[j] - t[i] <= 2.0 * settings.chord_s)  # no glitch, no time gap inside
    dx, dy = x[j] - x[i], y[j] - y[i]
    ok &= np.hypot(dx, dy) >= settings.chord_m
    if np.count_nonzero(ok) < settings.conventions_min_samples:
        return False
    course = np.arctan2(dy[ok], dx[ok])
    i, j = i[ok], j[ok]

    def share(heading: np.ndarray, *, settings: GapSettings = SETTINGS) -> float:
        """Share of the chords within ~37 deg of ``heading`` (the whole column's, any
        wrapping) averaged over the chord's ends."""
        h = np.unwrap(heading)
        return float(np.mean(np.abs(np.cos(course - 0.5 * (h[i] + h[j]))) >= settings.aligned_cos))

    yaw = np.asarray(log.yaw_rad, dtype=float)
    own = share(yaw, settings=settings)
    if own >= settings.aligned_share:
        return True
    found = f"points along the motion in {own:.0%} of the path's chords"
    # the path turns enough to tell conventions apart
    if share(np.zeros_like(yaw), settings=settings) < settings.aligned_share:
        for alt, what, fix in ((-yaw, "negated", f"expected counter-clockwise from +x; its "
                                                 f"{_REVERSED.format(col='yaw_rad')}"),
                               (np.radians(yaw), "read as degrees",
                                f"expected radians; map it with unit = \"deg\" {_DOC}")):
            if (share(alt, settings=settings) >= settings.aligned_share_other
                    and share(alt, settings=settings) > own + 0.1):
                raise _refuse(log, "yaw_rad", f"{found}, {what} in {share(alt, settings=settings):.0%}: {fix}")
    if own < settings.min_aligned_share:
        raise _refuse(log, "yaw_rad", f"{found}: expected the heading of the car (radians, counter-clockwise "
                                      f"from +x) with x_m, y_m in one world frame; check its unit, sign and frame")
    return True


def _against_pose(log: RunLog, column: str, sensor: np.ndarray, from_pose: np.ndarray, min_value: float,
                  what: str, positive: str, unit: str, units: dict[str, float], *,
                  settings: GapSettings = SETTINGS) -> bool:
    """A sensor against the same quantity from the pose: reversed, or in one of ``units``;
    False when the log shows too little of it to tell."""
    fit = _fit(sensor, from_pose, np.abs(from_pose) > min_value, settings=settings)
    if fit is None or abs(fit[1]) <= settings.conventions_min_correlation:  # too little, or too scattered to tell
        return False
    slope, corr = fit
    found = f"is {slope:.3g}x {what} (correlation {corr:.2f})"
    if slope < 0.0 and corr < -settings.conventions_min_correlation:
        raise _refuse(log, column, f"{found}: expected + = {positive}; its {_REVERSED.format(col=column)}")
    other = _unit(slope, units, settings=settings) if corr > settings.conventions_min_correlation else None
    if other:
        raise _refuse(log, column, f"{found}: expected {unit}; in {other}? map it with unit = \"{other}\" {_DOC}")
    return True


def check_conventions(log: RunLog, wheelbase_m: float, steer_limit_rad: float,
                      exclude: np.ndarray | None = None, measured: Derived | None = None, *,
                      settings: GapSettings = SETTINGS) -> tuple[str, ...]:
    """Raise :class:`LogError` (``path:1: column: what was found, what was expected``) when a
    column of ``log`` is reversed or in another unit (module docstring); ``exclude``: samples
    to leave out (glitches); ``measured``: ``derive(log, wheelbase_m, exclude=exclude)`` if
    the caller has it already. Returns what could not be checked (a check the log shows too
    little of, or, without a pose, a sensor's unit that nothing else measures), one phrase
    each, for the report to say: a short log or one without turns passes them unseen."""
    unchecked: list[str] = []
    steer = np.asarray(log.steer_cmd_rad, dtype=float)
    keep_out = np.zeros(len(log), dtype=bool) if exclude is None else np.asarray(exclude, dtype=bool)
    keep = ~keep_out
    far = np.abs(steer[keep]) > max(settings.steer_range_rad, settings.steer_range_limits * steer_limit_rad)
    if far.size and far.mean() > 0.01:
        top = float(np.max(np.abs(steer[keep])))
        raise _refuse(log, "steer_cmd_rad", f"reaches {top:.4g} rad, beyond any steering (this car's limit: "
                                            f"{steer_limit_rad:.3g} rad): expected radians, bicycle-equivalent; "
                                            f"degrees or the car's own units? map it {_DOC}")
    pose = None
    if has_pose(log):
        bare = log.with_columns(speed_mps=None, yaw_rate_radps=None)
        pose = derive(bare, wheelbase_m, exclude=exclude, settings=settings)
        if not _heading(log, keep_out, settings=settings):
            unchecked.append("yaw_rad's sign and unit (too little travel)")
    if measured is None:  # the sensors where present, else the pose
        measured = derive(log, wheelbase_m, exclude=exclude, settings=settings)
    if pose is not None:
        if log.yaw_rate_radps is not None and not _against_pose(
                log, "yaw_rate_radps", measured.yaw_rate_radps, pose.yaw_rate_radps,
                settings.conventions_min_rate_radps, "the yaw rate of the pose", "counter-clockwise", "rad/s",
                {"deg/s": 180.0 / math.pi}, settings=settings):
            unchecked.append("yaw_rate_radps's sign and unit (too little turning, or too scattered to tell)")
        if log.speed_mps is not None and not _against_pose(
                log, "speed_mps", measured.speed_mps, pose.speed_mps, settings.conventions_min_speed_mps,
                "the speed of the pose along its heading", "forward", "m/s",
                {"km/h": 3.6, "cm/s": 100.0, "mm/s": 1000.0}, settings=settings):
            unchecked.append("speed_mps's sign and unit (too little driving, or too scattered to tell)")
    elif log.speed_mps is not None:
        unchecked.append("speed_mps's unit (no pose to compare it with; only its sign, against the command)")
    # the measured speed and yaw rate are now right where a pose confirmed them (or gave them);
    # without a pose, a reversal below may be the sensor's as well as the command's
    v, rate = measured.speed_mps, measured.yaw_rate_radps
    cmd = np.asarray(log.speed_cmd_mps, dtype=float)
    duty = is_duty_log(log)  # the command is a duty (-1..1, checked on reading): its sign only
    name = "the duty" if duty else "speed_cmd_mps"
    fit = _fit(v, cmd, (np.abs(cmd) > (settings.conventions_min_duty if duty else settings.conventions_min_speed_mps))
                       & (np.abs(v) > settings.conventions_min_speed_mps), settings=settings)
    if fit is None or abs(fit[1]) <= settings.conventions_min_correlation:
        unchecked.append(f"{name}'s sign{'' if duty else ' and unit'} (too little driving)" if fit is None else
                         f"{name}'s sign{'' if duty else ' and unit'} (the measured speed follows it too loosely: "
                         f"correlation {fit[1]:.2f})")
    col = ("duty_cmd" if log.duty_cmd is not None else "duty_left and duty_right") if duty else "speed_cmd_mps"
    if fit is not None and fit[0] < 0.0 and fit[1] < -settings.conventions_min_correlation:
        found = f"the measured speed is {fit[0]:.3g}x the {'duty' if duty else 'command'} (correlation {fit[1]:.2f})"
        if pose is not None:  # the measured speed is the pose's or was checked against it
            raise _refuse(log, col, f"{found}: expected + = forward; its {_REVERSED.format(col=col)}")
        raise _refuse(log, f"{col} or speed_mps", f"{found}: expected + = forward for both; one "
                                                  f"{_REVERSED.format(col=col)} (or speed_mps)")
    if (not duty and fit is not None and fit[0] > settings.max_speed_per_command
            and fit[1] > settings.conventions_min_correlation):
        raise _refuse(log, "speed_mps or speed_cmd_mps", f"the measured speed is {fit[0]:.3g}x the command "
                                                         f"(correlation {fit[1]:.2f}): expected both in m/s; "
                                                         f"is one in km/h, cm/s or the car's own units? map it "
                                                         f"{_DOC}")
    with np.errstate(invalid="ignore"):
        kinematic = v * np.tan(np.clip(steer, -1.5, 1.5)) / wheelbase_m
    fit = _fit(rate, kinematic, (np.abs(kinematic) > settings.conventions_min_rate_radps)
                                & (np.abs(v) > settings.conventions_min_speed_mps), settings=settings)
    if fit is None or abs(fit[1]) <= settings.conventions_min_correlation:
        unchecked.append(("steer_cmd_rad's sign (too little turning)" if fit is None else
                          f"steer_cmd_rad's sign (the measured yaw rate follows it too loosely: correlation "
                          f"{fit[1]:.2f})")
                         + (" and yaw_rate_radps's unit" if pose is None and log.yaw_rate_radps is not None else ""))
    if (pose is None and fit is not None and fit[1] > settings.conventions_min_correlation
            and _unit(fit[0], {"deg/s": 180.0 / math.pi}, band=0.6, settings=settings)):
        raise _refuse(log, "yaw_rate_radps", f"is {fit[0]:.3g}x the yaw rate the steering command and the speed "
                                             f"give (correlation {fit[1]:.2f}): expected rad/s; in deg/s? map it "
                                             f"with unit = \"deg/s\" {_DOC}")
    if fit is not None and fit[0] < 0.0 and fit[1] < -settings.conventions_min_correlation:
        found = (f"the car turns against the command (measured yaw rate {fit[0]:.3g}x what it gives, "
                 f"correlation {fit[1]:.2f})")
        if pose is not None:
            raise _refuse(log, "steer_cmd_rad", f"{found}: expected + = left; its "
                                                f"{_REVERSED.format(col='steer_cmd_rad')}")
        raise _refuse(log, "steer_cmd_rad or yaw_rate_radps", f"{found}: expected + = left (steering) and + = "
                                                              f"counter-clockwise (gyro); one "
                                                              f"{_REVERSED.format(col='steer_cmd_rad')} (or "
                                                              f"yaw_rate_radps)")
    return tuple(unchecked)


__all__ = ["check_conventions"]
