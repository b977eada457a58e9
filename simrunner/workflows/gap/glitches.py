"""Glitches of a measured log: samples the gap workflow must keep out of its windows.

Real logs are not what a simulator writes: the localisation jumps, a topic stops for a
while, a row is logged twice, a sensor repeats its last value. :func:`find_glitches`
finds five kinds (:class:`GlitchKind`); :func:`glitch_mask` turns them into the samples to
keep out. Every threshold is relative to the log itself - its time steps, the
noise of its own signals, its own speed - so that one rule serves a 20-Hz particle
filter and a 100-Hz motion-capture log alike:

``time_gap``
    ``dt > GAP_FACTOR * quantile(dt, GAP_QUANTILE)`` (:func:`simrunner.telemetry.sparse.gap_limit_s`:
    5 times the log's own long interval, its median step when the stamps are regular):
    samples were dropped (or the logger paused). Nothing is known in between, so windows and
    smoothing are cut there (:func:`time_gaps`). A log with irregular stamps (a controller
    logging when it acts, a sensor with jitter) has long intervals as part of its rhythm;
    they are not gaps.
``duplicate``
    a time step below ``settings.duplicate_dt_fraction * median(dt)`` (the same sample stamped
    twice), or a row whose every sensor column (pose, speed, gyro) equals the previous
    row's while the car moves (a repeated row with a new stamp; at rest identical rows
    are normal), or a row the reader left out for repeating the previous row's stamp
    (``RunLog.repeats``, ``read_log(repeated_stamps=True)``): a copy of the row kept leaves
    its data whole and keeps nothing out; a row with other values makes the kept one
    doubtful too, which is kept out.
``localisation_jump``
    a position step that the speed and the time step cannot explain. Each step's
    residual, along and across the heading, is ``step - v * dt * (cos, sin)(heading)``
    with ``v`` the mean of the logged speeds at its two ends (without a speed column: the
    median of the neighbouring steps' speeds). Its noise depends on speed (time-stamp
    jitter grows with speed), so the steps are grouped by speed (quantiles, up to
    ``settings.speed_groups``) and each group's median and robust scale (1.4826 MAD) give a
    z-score (steps where the pose stood still at rest carry no noise and are left out of
    the statistics); a step with ``z > settings.jump_z`` whose residual also exceeds
    ``settings.jump_motion_fraction`` of the step the speed gives (more than a sideslip or a
    speed-sensor error could explain: a noise-free log of a sliding car has outlying but
    real residuals) is a jump. The scale is floored at
    ``settings.scale_floor_fraction`` of the median moving step (noise-free logs) and at the
    CSV resolution.
    The heading can jump alone (a particle filter's flip, a camera marker read the wrong way
    round, a quaternion's sign): each heading step's residual is ``wrap(dyaw - turn)``, the
    turn from the gyro (trapezoid) or, without one, the median turn rate of the
    neighbouring steps; a step is a jump when its robust z-score exceeds ``settings.jump_z`` **and**
    the step is more than the car can turn in it (``|v| dt / R``, ``R`` the car's smallest
    turning radius, ``CarDescription.min_turn_radius_m``) plus ``settings.jump_z`` noise scales
    **and** its residual exceeds ``settings.jump_motion_fraction`` of that most the car can turn
    (a noise-free log's tiny residuals at full lock are no jump). A jump out followed by
    the next one back (their residuals cancel within ``settings.jump_z`` scales) keeps out the
    samples between them too: a heading displaced for a while and restored, whose windows
    would start from a wrong heading. The position test then uses the heading with the
    jumps taken out.
    A car file on slip tyres (``wheels.tyre_model = "slip"``) says the car slides: its pose
    then moves off its heading and turns faster than its steering turns it (power oversteer,
    a drift). For it each position step is compared with the velocity of its neighbouring
    steps, and a jump must exceed what the tyres change that velocity in the time
    (:func:`slip_limits`: ``settings.slip_margin`` x ``mu g``); a heading step with the same
    z-score must leave the gyro's (or the neighbours') turn by more than the tyres change the
    yaw rate. A slide is continuous in velocity and yaw rate; a localisation jump is not.
``frozen_sensor``
    a channel (position, yaw, speed, gyro) repeating its exact value for a run of ``L``
    samples while the car moves (evidence from the other channels: the speed column, a
    frozen speed's own non-zero value, or the pose's displacement when it is well above
    the pose noise and no jump is near), when such a run is
    improbable for this channel: with ``p`` the chance that one sample repeats the last -
    the larger of the fraction of repeats in the log's moving samples and the chance that
    the channel's noise (robust, from second differences) stays within its quantisation
    step - ``n_moving * p ** (L - 1) < settings.frozen_alpha``. That test takes the repeats as
    independent. A heading, speed or yaw rate without noise (a simulator's, written with 6
    decimals) holds its value through every steady stretch instead, one run after the other:
    where the channel has no noise (``p = 1``), or holds a value for ``settings.frozen_min_samples`` or
    more ``settings.frozen_common_runs`` other times while moving (DS2's ESC speed does 13 times, a
    simulator's speed a hundred), a run is frozen only where the channel then catches up by
    more than the shortest frozen run would at its fast rate of change (twice the 99th
    percentile of its one-sample changes while moving): it held while the value moved on. A
    position holds no value while the car moves.

``sensor_spike``
    a speed or gyro reading that steps out and back by more than the car can change it: a
    step ``|dy| > A dt + settings.jump_z sqrt(2) sigma`` is impossible for the car, with ``A`` the
    most that signal's rate of change can be - ``settings.spike_agility`` times the car file's
    (speed: its acceleration or brake limit; yaw rate: ``A_speed tan(limit) / L + |v| rate /
    (L cos^2(limit))``, with the steering limit, the servo rate and the faster end's speed) -
    and ``sigma`` one sample's noise (robust, from each sample's distance to the line through
    its neighbours). An impossible step followed by the next impossible one back (opposite
    sign, at most ``settings.spike_max_samples`` readings later, and the readings either side of
    the pair differ by what the car can do in the time) keeps the readings between out: an
    encoder that missed ticks, a gyro that saturated for a few samples. Longer excursions
    are left in: a wheel that locks under hard braking and spins up again reads like that
    for a second (DS2's brake to reverse at 113.9 s, encoder at 30 Hz), and is the car's
    [shaped by the shared logs].
    One impossible step alone (a level that changes and stays) is no spike: its two sides
    cannot tell which is wrong. Samples already kept out (jumps, frozen runs, duplicates)
    and steps across time gaps are not judged.

A glitch keeps out the samples in ``(t_start_s, t_end_s]``: the sample after a jump, a
duplicate, a frozen sensor's repeats, a spike. A time gap has no samples inside; windows and
smoothing are cut at gaps anyway.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

import numpy as np

from simrunner.telemetry.log import RunLog
from simrunner.telemetry.sparse import GAP_FACTOR, GAP_QUANTILE, gap_limit_s
from simrunner.workflows.gap.settings import GRAVITY_MPS2, SETTINGS, GapSettings
from vehicle.description import CarDescription

POSE = ("x_m", "y_m", "yaw_rad")
SENSOR_COLUMNS = ("x_m", "y_m", "yaw_rad", "speed_mps", "yaw_rate_radps")


class GlitchKind(StrEnum):
    TIME_GAP = "time_gap"
    DUPLICATE = "duplicate"
    JUMP = "localisation_jump"
    FROZEN = "frozen_sensor"
    SPIKE = "sensor_spike"


@dataclass(frozen=True)
class Glitch:
    """One glitch: its kind, the time span ``[t_start_s, t_end_s]`` (samples in
    ``(t_start_s, t_end_s]`` are kept out), the column(s) concerned (comma-separated) and a
    one-line description with the numbers that made it a glitch."""

    kind: GlitchKind
    t_start_s: float
    t_end_s: float
    column: str
    detail: str


def has_pose(log: RunLog) -> bool:
    return all(getattr(log, c) is not None for c in POSE)


def median_dt_s(t: np.ndarray) -> float:
    """Median time step of ``t`` (inf for fewer than two samples)."""
    return float(np.median(np.diff(t))) if t.size > 1 else math.inf


def time_gaps(t: np.ndarray) -> np.ndarray:
    """``(N - 1,) bool``: the step from sample k to k + 1 is a time gap (see the module
    docstring)."""
    dt = np.diff(t)
    return dt > gap_limit_s(dt) if dt.size else np.zeros(0, dtype=bool)


def find_glitches(log: RunLog, car: CarDescription | None = None, *, settings: GapSettings = SETTINGS) -> list[Glitch]:
    """The glitches of ``log`` (see the module docstring), sorted by start time. ``car``: the
    car file (None: the default car), whose smallest turning radius bounds a real heading
    step and whose limits bound a real change of speed and yaw rate."""
    if len(log) < 3:
        return []
    if car is None:
        car = CarDescription()
    found = _gaps(log) + _duplicates(log, settings=settings)
    jumps = np.zeros(len(log) - 1, dtype=bool)
    pose_scale = math.nan
    if has_pose(log):
        more, jumps, pose_scale = _jumps(log, car.min_turn_radius_m, slip_limits(car, settings), settings=settings)
        found += more
    found += _frozen(log, jumps, pose_scale, settings=settings)
    found += _spikes(log, car, glitch_mask(log, found), settings=settings)
    return sorted(found, key=lambda g: (g.t_start_s, g.t_end_s, g.kind))


def glitch_mask(log: RunLog, glitches: list[Glitch] | tuple[Glitch, ...]) -> np.ndarray:
    """``(N,) bool``: True for the samples to keep out (``(t_start_s, t_end_s]`` of every
    glitch but time gaps, which hold no sample)."""
    t = log.t_s
    out = np.zeros(len(log), dtype=bool)
    for g in glitches:
        if g.kind is GlitchKind.TIME_GAP:
            continue
        a = int(np.searchsorted(t, g.t_start_s, side="right"))
        b = int(np.searchsorted(t, g.t_end_s, side="right"))
        out[a:b] = True
    return out


# -- the rules --------------------------------------------------------------------------------
def _gaps(log: RunLog) -> list[Glitch]:
    t = log.t_s
    med, limit = median_dt_s(t), gap_limit_s(np.diff(t))
    out = []
    for k in np.flatnonzero(time_gaps(t)):
        text = (f"no sample for {t[k + 1] - t[k]:.3g} s ({(t[k + 1] - t[k]) / med:.0f} median time steps; "
                f"this log's gaps are longer than {limit:.3g} s)")
        if has_pose(log):
            text += (f"; the pose moved {math.hypot(log.x_m[k + 1] - log.x_m[k], log.y_m[k + 1] - log.y_m[k]):.3g} m "
                     f"and turned {_wrap(np.array(log.yaw_rad[k + 1] - log.yaw_rad[k])):+.2f} rad across it")
        out.append(Glitch(GlitchKind.TIME_GAP, float(t[k]), float(t[k + 1]), "t_s", text))
    return out


def _sensor_columns(log: RunLog) -> tuple[str, ...]:
    return tuple(c for c in SENSOR_COLUMNS if getattr(log, c) is not None
                 and (c not in POSE or has_pose(log)))


def moving(log: RunLog, *, settings: GapSettings = SETTINGS) -> np.ndarray:
    """``(N,) bool``: the car moves at each sample: ``|speed| >= settings.moving_mps`` from the speed
    column, else from the pose's displacement over ``settings.moving_baseline_s`` (all True when
    the log has neither)."""
    if log.speed_mps is not None:
        return np.abs(log.speed_mps) >= settings.moving_mps
    if has_pose(log):
        return _pose_speed(log, settings.moving_baseline_s) >= settings.moving_mps
    return np.ones(len(log), dtype=bool)


def _pose_speed(log: RunLog, baseline_s: float) -> np.ndarray:
    """``(N,)`` speed from the pose's displacement over ``baseline_s`` centred on each sample."""
    t = log.t_s
    a = np.searchsorted(t, t - 0.5 * baseline_s)
    b = np.minimum(np.searchsorted(t, t + 0.5 * baseline_s, side="right") - 1, len(t) - 1)
    span = t[b] - t[a]
    d = np.hypot(log.x_m[b] - log.x_m[a], log.y_m[b] - log.y_m[a])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(span > 0.0, d / np.where(span > 0.0, span, 1.0), 0.0)


def _repeats(log: RunLog) -> list[Glitch]:
    """The rows left out at reading for repeating the stamp before them (module docstring)."""
    rep = log.repeats
    if rep is None:
        return []
    t = log.t_s
    out = []
    for ts, line, differ in zip(rep.t_s, rep.lines, rep.differ):
        ts = float(ts)
        if not differ:
            out.append(Glitch(GlitchKind.DUPLICATE, ts, ts, "t_s",
                              f"line {line} repeats the row before it (same stamp, same values): left out"))
            continue
        k = int(np.searchsorted(t, ts, side="left"))  # the row kept at that stamp
        before = float(t[k - 1]) if k > 0 else math.nextafter(ts, -math.inf)
        out.append(Glitch(GlitchKind.DUPLICATE, before, ts, differ,
                          f"line {line} has the stamp of the row before it with other values ({differ}): "
                          f"left out, and the row kept is kept out of the windows"))
    return out


def _duplicates(log: RunLog, *, settings: GapSettings = SETTINGS) -> list[Glitch]:
    t = log.t_s
    dt = np.diff(t)
    med = median_dt_s(t)
    out = _repeats(log) + [Glitch(GlitchKind.DUPLICATE, float(t[k]), float(t[k + 1]), "t_s",
                  f"stamped {dt[k] * 1e3:.3g} ms after the previous sample (median time step {med * 1e3:.3g} ms)")
           for k in np.flatnonzero(dt < settings.duplicate_dt_fraction * med)]
    cols = _sensor_columns(log)
    if not cols:
        return out
    same = np.ones(len(log) - 1, dtype=bool)
    for c in cols:
        same &= np.diff(getattr(log, c)) == 0.0
    mov = moving(log, settings=settings)
    same &= mov[:-1] | mov[1:]
    same &= dt >= settings.duplicate_dt_fraction * med  # already reported
    for a, b in _runs(same):
        out.append(Glitch(GlitchKind.DUPLICATE, float(t[a]), float(t[b]), ",".join(cols),
                          f"{b - a} row(s) repeating every sensor column of the previous one while moving"))
    return out


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs of True steps in ``flags`` (``(N - 1,)``, step k from sample k to k + 1)
    as sample ranges ``(first, last)``: steps first .. last - 1 are True."""
    f = np.concatenate([[False], np.asarray(flags, dtype=bool), [False]])
    d = np.diff(f.astype(np.int8))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops)]


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _robust(v: np.ndarray) -> tuple[float, float]:
    """(median, 1.4826 MAD) of ``v``."""
    m = float(np.median(v))
    return m, 1.4826 * float(np.median(np.abs(v - m)))


def _neighbour_median(rate: np.ndarray, valid: np.ndarray, *, settings: GapSettings = SETTINGS) -> np.ndarray:
    """Per step, the median of ``rate`` over the ``settings.neighbour_steps`` valid steps each side
    (the step itself left out; 0 where there are none)."""
    rate = np.where(valid, rate, np.nan)
    k = settings.neighbour_steps
    padded = np.concatenate([np.full(k, np.nan), rate, np.full(k, np.nan)])
    near = np.stack([padded[j:j + rate.size] for j in range(2 * k + 1) if j != k])
    with np.errstate(all="ignore"):
        v = np.nanmedian(np.where(np.isnan(near).all(axis=0), 0.0, near), axis=0) \
            if near.size else np.zeros_like(rate)
    return np.where(np.isfinite(v), v, 0.0)


class SlipLimits(NamedTuple):
    """What a car on slip tyres can do (:func:`slip_limits`)."""

    accel_mps2: float  # the most it changes its velocity
    yaw_accel_radps2: float  # the most it changes its yaw rate
    gyration_m: float  # its radius of gyration about the vertical: a spin turns at most |v| / this


def slip_limits(car: CarDescription, settings: GapSettings = SETTINGS) -> SlipLimits | None:
    """What a car on slip tyres (``wheels.tyre_model = "slip"``, docs/tyres.md) can do, with
    ``settings.slip_margin`` on what its tyres give: its velocity changes by at most ``mu g`` (the
    friction circle), its yaw rate by at most ``mu g L / (2 k^2)`` (the axles' peak forces
    ``mu m g b / L`` and ``mu m g a / L`` turning it the most at ``a = b = L / 2``; ``k`` the chassis
    box's radius of gyration), and a spin that turns all its motion into rotation turns at
    ``|v| / k``. None for rigid tyres (the kinematic bounds apply)."""
    if car.wheels.tyre_model != "slip":
        return None
    ch = car.chassis
    mu_g = car.wheels.friction_mu * car.effects.friction_scale * GRAVITY_MPS2
    k2 = (ch.length_m ** 2 + ch.width_m ** 2) / 12.0 * car.effects.inertia_scale
    m = settings.slip_margin
    return SlipLimits(m * mu_g, m * mu_g * ch.wheelbase_m / (2.0 * k2), math.sqrt(k2) / m)


def _jumps(log: RunLog, min_turn_radius_m: float, slip: SlipLimits | None = None, *,
           settings: GapSettings = SETTINGS) -> tuple[list[Glitch], np.ndarray, float]:
    """Localisation jumps, of the heading (:func:`_heading_jumps`) and of the position; also
    the ``(N - 1,)`` jump steps and the pose's step noise at low speed (the slowest group's
    cross-heading scale, m). ``slip``: :func:`slip_limits` of a car on slip tyres, which slides:
    each step is then compared with the velocity of its neighbours (the median of
    ``settings.neighbour_steps`` valid steps each side, the step itself left out), not with the
    speed along the heading, and a jump must exceed what its ``accel_mps2`` changes over their mean
    distance (``(neighbour_steps + 1) / 2`` steps)."""
    t = log.t_s
    dt = np.diff(t)
    med = median_dt_s(t)
    valid = ~time_gaps(t) & (dt >= settings.duplicate_dt_fraction * med)
    safe_dt = np.where(dt > 0, dt, 1.0)
    dx, dy = np.diff(log.x_m), np.diff(log.y_m)
    if log.speed_mps is not None:
        v = 0.5 * (log.speed_mps[:-1] + log.speed_mps[1:])
    else:  # the neighbouring steps' speed along the heading, this step left out
        yaw0 = log.yaw_rad[:-1] + 0.5 * _wrap(np.diff(log.yaw_rad))
        v = _neighbour_median((dx * np.cos(yaw0) + dy * np.sin(yaw0)) / safe_dt, valid, settings=settings)
    out, turned, yaw = _heading_jumps(log, dt, valid, v, min_turn_radius_m, slip, settings=settings)
    heading = yaw[:-1] + 0.5 * _wrap(np.diff(yaw))
    c, s = np.cos(heading), np.sin(heading)
    along, cross = dx * c + dy * s, -dx * s + dy * c
    ra, rc = along - v * dt, cross
    if slip is not None:  # a sliding car moves off its heading: the neighbours' velocity predicts the step
        vx = _neighbour_median(dx / safe_dt, valid & ~turned, settings=settings)
        vy = _neighbour_median(dy / safe_dt, valid & ~turned, settings=settings)
        ex, ey = dx - vx * dt, dy - vy * dt
        ra, rc = ex * c + ey * s, -ex * s + ey * c
    jump = np.zeros(dt.size, dtype=bool)
    z = np.zeros(dt.size)
    idx = np.flatnonzero(valid)
    if idx.size < 10:
        return out, jump | turned, math.nan
    step = np.hypot(dx, dy)
    moving_steps = idx[np.abs(v[idx]) >= settings.moving_mps]
    floor = max(settings.resolution,
                settings.scale_floor_fraction * (float(np.median(step[moving_steps])) if moving_steps.size else 0.0))
    still = (dx == 0.0) & (dy == 0.0) & (v == 0.0)  # a pose that did not move at rest: no noise to learn
    stats = idx[~still[idx]]
    if stats.size < 10:
        return out, jump | turned, math.nan
    order = stats[np.argsort(np.abs(v[stats]), kind="stable")]
    groups = np.array_split(order, max(1, min(settings.speed_groups, order.size // settings.group_min_steps)))
    slow_scale = math.nan
    for g in groups:
        ma, sa = _robust(ra[g])
        mc, sc = _robust(rc[g])
        sa, sc = max(sa, floor), max(sc, floor)
        z[g] = np.hypot((ra[g] - ma) / sa, (rc[g] - mc) / sc)
        if math.isnan(slow_scale):
            slow_scale = sc
    residual = np.hypot(ra, rc)
    if slip is None:  # more than a sideslip or a speed error explains
        bound = settings.jump_motion_fraction * np.abs(v) * dt
    else:  # more than the tyres change the velocity over the neighbours
        bound = slip.accel_mps2 * 0.5 * (settings.neighbour_steps + 1) * dt * dt
    jump[idx] = (z[idx] > settings.jump_z) & (residual[idx] > bound[idx])
    for a, b in _runs(jump):
        k = int(np.argmax(z[a:b])) + a
        if slip is None:
            why = f"where speed {v[k]:+.3g} m/s moves {abs(v[k]) * dt[k]:.3g} m"
        else:
            why = (f"{residual[k]:.3g} m off the neighbouring steps' velocity, where the tyres change it by "
                   f"{bound[k]:.3g} m at most")
        out.append(Glitch(GlitchKind.JUMP, float(t[a]), float(t[b]), "x_m,y_m",
                          f"position step {step[k]:.3g} m in {dt[k]:.3g} s {why} (z = {z[k]:.0f})"))
    return out, jump | turned, slow_scale


def _heading_jumps(log: RunLog, dt: np.ndarray, valid: np.ndarray, v: np.ndarray,
                   min_turn_radius_m: float, slip: SlipLimits | None = None, *,
                   settings: GapSettings = SETTINGS) -> tuple[list[Glitch], np.ndarray, np.ndarray]:
    """Heading jumps (see the module docstring): the glitches, the ``(N - 1,)`` jump steps and
    the yaw with each jump taken out of its samples (for the position test). ``slip``
    (:func:`slip_limits`): a sliding car turns faster than its steering turns it, so its step
    must instead leave the predicted turn by more than its ``yaw_accel_radps2`` changes the yaw
    rate over the prediction's reach (the gyro's step, or the neighbours' mean distance), or turn
    more than a spin can (``|v| / gyration_m``) beyond the steering."""
    yaw = np.asarray(log.yaw_rad, float)
    dyaw = _wrap(np.diff(yaw))
    if log.yaw_rate_radps is not None:
        pred = 0.5 * (log.yaw_rate_radps[:-1] + log.yaw_rate_radps[1:]) * dt
        source = "the gyro turns"
    else:
        pred = _neighbour_median(dyaw / np.where(dt > 0, dt, 1.0), valid, settings=settings) * dt
        source = "the neighbouring steps turn"
    res = _wrap(dyaw - pred)
    jump = np.zeros(dt.size, dtype=bool)
    idx = np.flatnonzero(valid & ~((dyaw == 0.0) & (pred == 0.0)))
    if idx.size < 10:
        return [], jump, yaw
    m, scale = _robust(res[idx])
    scale = max(scale, settings.resolution)
    z = np.abs(res - m) / scale
    turn = np.abs(v) * dt / min_turn_radius_m  # the most the car turns in the step (at its steering limit)
    reach = 1.0 if log.yaw_rate_radps is not None else 0.5 * (settings.neighbour_steps + 1)
    if slip is None:
        jump[idx] = ((z[idx] > settings.jump_z) & (np.abs(dyaw[idx]) > turn[idx] + settings.jump_z * scale)
                     & (np.abs(res[idx]) > settings.jump_motion_fraction * turn[idx]))
    else:
        ground = np.hypot(np.diff(log.x_m), np.diff(log.y_m)) / np.where(dt > 0, dt, 1.0)
        moving = np.maximum(np.abs(v), _neighbour_median(ground, valid, settings=settings))  # sliding: not |v|
        spin = turn + moving * dt / slip.gyration_m
        jump[idx] = (z[idx] > settings.jump_z) & (
            (np.abs(res[idx]) > slip.yaw_accel_radps2 * reach * dt[idx] ** 2)
            | (np.abs(dyaw[idx]) > spin[idx] + settings.jump_z * scale))
    runs = _runs(jump)
    spans: list[tuple[int, int, str]] = []
    i = 0
    while i < len(runs):
        a, b = runs[i]
        k = int(np.argmax(z[a:b])) + a
        most = turn[k] if slip is None else float(np.abs(pred[k]) + slip.yaw_accel_radps2 * reach * dt[k] ** 2)
        text = (f"heading step {dyaw[k]:+.3g} rad in {dt[k]:.3g} s where {source} {pred[k]:+.3g} rad and the car "
                f"turns {most:.3g} rad at most (z = {z[k]:.0f})")
        if i + 1 < len(runs):  # out and back: the samples between are displaced too
            a2, b2 = runs[i + 1]
            if abs(float(_wrap(np.array(res[a:b].sum() + res[a2:b2].sum())))) < settings.jump_z * scale:
                text = (f"heading displaced by {float(res[a:b].sum()):+.3g} rad for {log.t_s[a2] - log.t_s[a]:.3g} s "
                        f"and back ({text})")
                b, i = b2, i + 1
        spans.append((a, b, text))
        i += 1
    held = yaw.copy()  # each span's samples less the jumps so far in it
    out = []
    for a, b, text in spans:
        held[a + 1:b + 1] = yaw[a + 1:b + 1] - np.cumsum(np.where(jump[a:b], res[a:b], 0.0))
        jump[a:b] = True
        out.append(Glitch(GlitchKind.JUMP, float(log.t_s[a]), float(log.t_s[b]), "yaw_rad", text))
    return out, jump, held


def _channels(log: RunLog) -> list[tuple[str, tuple[str, ...]]]:
    out = []
    if has_pose(log):
        out += [("position", ("x_m", "y_m")), ("yaw", ("yaw_rad",))]
    for c in ("speed_mps", "yaw_rate_radps"):
        if getattr(log, c) is not None:
            out.append((c, (c,)))
    return out


def _repeat_chance(values: np.ndarray, mov_pairs: np.ndarray, *, settings: GapSettings = SETTINGS) -> float:
    """Chance that the channel's noise leaves one column unchanged between two samples:
    ``erf(q / (4 sigma))`` with ``q`` its smallest change and ``sigma`` its noise (robust,
    from second differences over moving samples); 1 for a noise-free column."""
    d = np.diff(values)
    nz = np.abs(d[d != 0.0])
    if nz.size == 0:
        return 1.0
    q = max(float(nz.min()), settings.resolution)
    d2 = np.diff(values, 2)
    m2 = mov_pairs[:-1] & mov_pairs[1:]
    if not m2.any():
        return 1.0
    sigma = 1.4826 * float(np.median(np.abs(d2[m2]))) / math.sqrt(6.0)
    return 1.0 if sigma <= 0.0 else math.erf(q / (4.0 * sigma))


def _catches_up(v: np.ndarray, b: int, mov_pairs: np.ndarray, *, settings: GapSettings = SETTINGS) -> bool:
    """Whether ``v`` moves from sample ``b`` to the next by more than ``settings.frozen_min_samples - 1``
    times the 99th percentile of its one-sample changes while moving: what the shortest frozen
    run catches up where the signal moves on that fast (a steady stretch's first change after
    a step command is one such change: a simulator's speed and gyro, without noise)."""
    d = np.abs(np.diff(v))
    changes = d[mov_pairs & (d > 0.0)]
    return (b + 1 < len(v) and bool(mov_pairs[b]) and changes.size > 0
            and d[b] > (settings.frozen_min_samples - 1) * np.quantile(changes, 0.99))


def _frozen(log: RunLog, jumps: np.ndarray, pose_scale: float, *, settings: GapSettings = SETTINGS) -> list[Glitch]:
    t = log.t_s
    n = len(log)
    out = []
    gaps = time_gaps(t)
    for name, cols in _channels(log):
        values = [np.unwrap(log.yaw_rad) if c == "yaw_rad" else getattr(log, c) for c in cols]
        same = np.ones(n - 1, dtype=bool)
        for v in values:
            same &= np.diff(v) == 0.0
        mov = _moving_without(log, name, settings=settings)
        mov_pairs = (mov[:-1] & mov[1:]) & ~gaps
        n_mov = int(mov_pairs.sum())
        if n_mov < 2:
            continue
        p_emp = max(float((same & mov_pairs).sum()) / n_mov, 1.0 / n_mov)
        p_noise = math.prod(_repeat_chance(v, mov_pairs, settings=settings) for v in values)
        p = max(p_emp, p_noise)
        # the channel's runs of repeats while the car moves (a heading or rate that holds its
        # value through steady driving has many)
        n_runs = sum(b - a + 1 >= settings.frozen_min_samples for a, b in _runs(same & mov_pairs))
        for a, b in _runs(same):
            length = b - a + 1
            if length < settings.frozen_min_samples:
                continue
            others = n_runs - int(bool(mov_pairs[a:b].all()))  # but this one
            if name != "position" and (p >= 1.0 or others >= settings.frozen_common_runs):
                if not _catches_up(values[0], b, mov_pairs, settings=settings):
                    continue
                why = (f"then jumps by {abs(values[0][b + 1] - values[0][b]):.3g}: it held while the value moved on "
                       f"(the channel holds a value for {settings.frozen_min_samples} samples or more {others} other "
                       "times while moving)")
            elif p >= 1.0 or n_mov * p ** (length - 1) >= settings.frozen_alpha:
                continue
            else:
                why = f"its noise repeats a value with p = {p:.2g} per sample"
            if not _moves_during(log, name, a, b, jumps, pose_scale, settings=settings):
                continue
            out.append(Glitch(GlitchKind.FROZEN, float(t[a]), float(t[b]), ",".join(cols),
                              f"{name} holds {', '.join(f'{getattr(log, c)[a]:.6g}' for c in cols)} for {length} "
                              f"samples ({t[b] - t[a]:.3g} s) while moving; {why}"))
    return out


def _spikes(log: RunLog, car: CarDescription, kept_out: np.ndarray, *,
            settings: GapSettings = SETTINGS) -> list[Glitch]:
    """Speed and gyro spikes (module docstring); ``kept_out``: the samples other glitches
    keep out already (neither judged nor used as neighbours)."""
    t = log.t_s
    dt_all = np.diff(t)
    cut = np.concatenate([[0], np.cumsum(time_gaps(t) | (dt_all < settings.duplicate_dt_fraction * median_dt_s(t)))])
    if log.speed_mps is not None:
        speed = np.abs(log.speed_mps)
    elif has_pose(log):
        speed = _pose_speed(log, settings.moving_baseline_s)
    else:
        speed = np.zeros(len(log))
    accel = settings.spike_agility * max(car.drive.max_accel_mps2, car.drive.max_brake_mps2)
    wheelbase, limit = car.chassis.wheelbase_m, car.steering.limit_rad
    steer_rate = settings.spike_agility * car.steering.rate_radps
    idx = np.flatnonzero(~np.asarray(kept_out, dtype=bool))
    if idx.size < 10:
        return []
    ti, dt = t[idx], np.diff(t[idx])
    ok = (cut[idx[1:]] - cut[idx[:-1]]) == 0  # the step between two judged samples crosses no gap
    fast = np.maximum(speed[idx[:-1]], speed[idx[1:]])
    out = []
    for c in ("speed_mps", "yaw_rate_radps"):
        y = getattr(log, c)
        if y is None:
            continue
        yi = y[idx]
        most = np.full(dt.size, accel) if c == "speed_mps" else \
            accel * math.tan(limit) / wheelbase + fast * steer_rate / (wheelbase * math.cos(limit) ** 2)
        sigma = _sample_noise(ti, yi, ok, settings=settings)
        d = np.diff(yi)
        noise = settings.jump_z * math.sqrt(2.0) * sigma  # of a step: two samples' noise
        big = np.flatnonzero(ok & (np.abs(d) > most * dt + noise))
        i = 0
        while i + 1 < big.size:
            a, b = int(big[i]), int(big[i + 1])
            net = yi[b + 1] - yi[a]
            if (b - a <= settings.spike_max_samples and ok[a:b + 1].all() and np.sign(d[a]) == -np.sign(d[b])
                    and abs(net) <= float(most[a:b + 1].max()) * (ti[b + 1] - ti[a]) + noise):
                values = ", ".join(f"{v:+.3g}" for v in yi[a + 1:b + 1][:4]) + (" ..." if b - a > 4 else "")
                out.append(Glitch(GlitchKind.SPIKE, float(ti[a]), float(ti[b]), c,
                                  f"{c} steps {d[a]:+.3g} and back {d[b]:+.3g} in {ti[b + 1] - ti[a]:.3g} s "
                                  f"({b - a} sample(s): {values}); the car changes it by at most "
                                  f"{float(most[a]) * dt[a] + noise:.3g} in a step (noise included)"))
                i += 2
            else:
                i += 1
    return out


def _sample_noise(t: np.ndarray, y: np.ndarray, ok: np.ndarray, *, settings: GapSettings = SETTINGS) -> float:
    """One sample's noise in ``y`` (robust), from each sample's distance to the line through
    its neighbours (whose variance is 1.5 sigma^2 at regular stamps); floored at the CSV
    resolution."""
    both = ok[:-1] & ok[1:]
    d1, d2 = np.diff(t)[:-1], np.diff(t)[1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = y[1:-1] - (y[:-2] * d2 + y[2:] * d1) / (d1 + d2)
    r = r[both & np.isfinite(r)]
    if r.size < 10:
        return settings.resolution
    return max(_robust(r)[1] / math.sqrt(1.5), settings.resolution)


def _moving_without(log: RunLog, channel: str, *, settings: GapSettings = SETTINGS) -> np.ndarray:
    """Per-sample moving evidence that does not come from ``channel`` (all True if none)."""
    if channel != "speed_mps" and log.speed_mps is not None:
        return np.abs(log.speed_mps) >= settings.moving_mps
    if channel not in ("position", "yaw") and has_pose(log):
        return _pose_speed(log, settings.moving_baseline_s) >= settings.moving_mps
    if channel == "speed_mps":
        return np.abs(log.speed_mps) >= settings.moving_mps
    return np.ones(len(log), dtype=bool)


def _moves_during(log: RunLog, channel: str, a: int, b: int, jumps: np.ndarray, pose_scale: float, *,
                  settings: GapSettings = SETTINGS) -> bool:
    """Whether the car moves over samples a .. b by evidence other than ``channel`` itself:
    the speed column; a frozen speed's own non-zero value (it says the car moves); the pose's
    displacement, when it exceeds ``settings.moving_mps`` times the duration plus ``settings.jump_z`` times the
    pose's step noise and no jump lies within ``settings.moving_baseline_s / 2`` of the run."""
    if channel != "speed_mps" and log.speed_mps is not None:
        return float(np.median(np.abs(log.speed_mps[a:b + 1]))) >= settings.moving_mps
    if channel == "speed_mps" and abs(float(log.speed_mps[a])) >= settings.moving_mps:
        return True
    if channel not in ("position", "yaw") and has_pose(log):
        t = log.t_s
        near = slice(int(np.searchsorted(t, t[a] - 0.5 * settings.moving_baseline_s)),
                     int(np.searchsorted(t, t[b] + 0.5 * settings.moving_baseline_s)))
        if jumps[near].any() or not math.isfinite(pose_scale):
            return False  # a jumping pose is no evidence of motion
        d = math.hypot(float(log.x_m[b] - log.x_m[a]), float(log.y_m[b] - log.y_m[a]))
        return d >= settings.moving_mps * float(t[b] - t[a]) + settings.jump_z * pose_scale
    return False


__all__ = ["Glitch", "GlitchKind", "find_glitches", "glitch_mask", "time_gaps", "median_dt_s", "moving",
           "has_pose", "GAP_FACTOR", "GAP_QUANTILE",]
