"""Windowed replay: re-run the logged commands in the simulator from the measured states.

The log is cut into windows of ``window_s`` (default ``settings.window_s``), never across a time
gap or an excluded (glitch) sample. Each window starts the simulator afresh from the
measured (smoothed) state at its first sample (``set_state(pose, speed, steer, yaw_rate)``,
see :mod:`simrunner.workflows.gap.logs`), then applies each logged command until the next
sample time (zero-order hold; a merged log's command messages between two samples,
``RunLog.command_steps``, at their own stamps) and records the predicted state at every sample. Before a
window, the ``settings.lead_s`` seconds of commands that precede it (within the same piece of
the log) are replayed unrecorded and the car is then moved (``place``) to the measured
state at the window's start, so latency queues and lags carry the commands in flight
(a steering play, whose state no measurement gives, also gets the ``settings.play_history_s``
seconds of steering commands before that).
A window far from the log's origin (a map frame, a motion-capture hall's corner) is replayed
with its poses shifted by a whole number of ``settings.origin_step_m`` towards the simulator's
origin, and shifted back when recorded: the ground is flat and the same everywhere, but
finite (``physics.GROUND_SIZE_M``), and a car placed past its edge falls. A log within
half a step of its origin is replayed where it is.
Restarting keeps open-loop drift from swamping the comparison; one simulator object serves
all windows of a replay, so a whole replay is one pass. A log without pose starts every
window at the origin with the measured speed and yaw rate, heading the yaw rate integrated
from the log's start (:func:`dead_reckoned_yaw`; only pose-free signals are compared, but
the simulator's tyre friction is a pyramid aligned with the world axes, so grip depends a
little on heading, and a car that always starts at heading 0 would hide it).

Residual signals (predicted minus measured, shape (N,), NaN outside the replayed windows),
those the log supports (:func:`signals_of`):

    along_m         position error along the measured heading           (pose)
    cross_m         position error to the left of the measured heading   (pose)
    yaw_rad         heading error, wrapped to [-pi, pi)                  (pose)
    speed_mps       speed error (measured: the speed sensor, else the pose's speed)
    yaw_rate_radps  yaw-rate error (measured: the gyro, else the derivative of the smoothed yaw)

A speed or yaw rate that the log takes from its pose is compared with the predicted pose's,
derived the same way (:class:`Prediction`): the smoothing rounds the steps of the measured
one, and a raw prediction against it would ask for a slower servo or a latency.

``position_m`` (the distance, for reports) is ``hypot(along, cross)`` (pose only).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from pieces.pose import Pose2
from simrunner.telemetry.log import RunLog
from simrunner.workflows.gap.glitches import has_pose, time_gaps
from simrunner.workflows.gap.logs import (Derived, pieces, pose_rates, rms_finite, smoothing_window,
                                          speed_estimate)
from simrunner.workflows.gap.settings import SETTINGS, GapSettings
from vehicle.description import CarDescription

FIT_SIGNALS = ("along_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
REPORT_SIGNALS = ("position_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
POSE_SIGNALS = ("along_m", "cross_m", "yaw_rad")


def signals_of(log: RunLog) -> tuple[str, ...]:
    """The residual signals ``log`` supports, in :data:`FIT_SIGNALS` order: the pose gives
    ``along_m``, ``cross_m``, ``yaw_rad`` (and speed and yaw rate); a speed sensor
    ``speed_mps``; a gyro ``yaw_rate_radps``."""
    pose = has_pose(log)
    have = set(POSE_SIGNALS) if pose else set()
    if pose or log.speed_mps is not None:
        have.add("speed_mps")
    if pose or log.yaw_rate_radps is not None:
        have.add("yaw_rate_radps")
    return tuple(sig for sig in FIT_SIGNALS if sig in have)

SimFactory = Callable[[CarDescription, float], object]


def default_sim_factory(car: CarDescription, dt_s: float):
    """A simulator applying ``car.effects`` (``simrunner.car.effects.make_sim``)."""
    from simrunner.car.effects import make_sim

    return make_sim(car, dt_s=dt_s)


@dataclass(frozen=True)
class Window:
    """Samples ``start <= i < stop`` of a log; ``slot``: the window's place on the grid of
    ``window_s`` fixed in the log's time (``m * window_s`` from ``t = 0``) that
    :func:`make_windows` lays the windows on: the window starting near ``m * window_s`` has
    slot ``m`` (the first window of a piece: the slot before its end's)."""

    start: int
    stop: int
    slot: int = 0


def make_windows(log: RunLog, window_s: float | None = None, exclude: np.ndarray | None = None, *,
                 settings: GapSettings = SETTINGS) -> list[Window]:
    """Consecutive windows of about ``window_s`` (default: ``settings.window_s``) covering the
    usable parts of the log.

    The log is first cut into pieces (:func:`simrunner.workflows.gap.logs.pieces`) at every
    time gap and around every ``exclude``-d sample (``(N,) bool``, e.g.
    :func:`simrunner.workflows.gap.glitches.glitch_mask`; samples within
    half ``settings.smooth_s`` of one are left out too, as the smoothing reaches that far);
    pieces shorter than half a window are dropped. So no window spans a gap or holds an
    excluded sample, and a log with gaps gives fewer windows; a log that passed
    ``check_measured`` never makes this raise (it may give no window at all).

    Within a piece, the boundaries aim at a grid fixed in the log's time, ``m * window_s``
    from ``t = 0`` (the first at least half a window after the piece's start), not at one
    window after the boundary before: so a glitch or a gap changes only the windows it
    touches, and every window away from it is the same with and without it (laid one after
    the other, the windows after a dropped second started up to a window earlier, and a
    hidden effect living in two windows 55 s later moved the answer; bench/results/gap-history.md). Each
    boundary is moved (by up to ``settings.quiet_shift_s``, at most a quarter window) from its
    grid time to a quiet sample: the one with the least command change in
    ``[t - settings.quiet_before_s, t + settings.quiet_after_s]`` (ties: nearest to the regular grid). A window
    that starts during a step or just after it would start from smoothed states that blur
    the step; quiet starts avoid that. A sample where the car rolls with the drive off
    (coasting, or ``speed_cmd`` ~ 0 while moving) in ``[t, t + settings.quiet_after_s]`` is avoided
    above all: no speed loop would correct the noise in the start speed there, and the error
    would grow through the window. So is a sample between a reverse command given while the
    car rolls forward and the car's reversing (:func:`_esc_reversals`): an ESC that brakes
    before it reverses is then braking or waiting at rest, a state no measurement gives, and
    a window cut there sees half of it (a 1:10 car's reverse delay of 0.60 s: the fit window
    held the braking only, flat in the delay, and the chain refitted 0.19 s; whole, 0.601 s).
    The last window of a piece is merged into its neighbour
    when shorter than half a window.
    """
    window_s = settings.window_s if window_s is None else window_s
    t = log.t_s
    n = len(log)
    if n < 2:
        return []
    shift = min(settings.quiet_shift_s, 0.25 * window_s)
    steps = np.abs(np.diff(log.speed_cmd_mps)) / 1.0 + np.abs(np.diff(log.steer_cmd_rad)) / 0.1
    csum = np.concatenate([[0.0], np.cumsum(steps)])  # csum[i] = change before sample i
    # rolling with the drive off (coasting or braking to rest): no speed loop corrects the
    # start state there, so a noisy start speed would persist through the window
    drive_off = log.coasting() | (np.abs(log.speed_cmd_mps) < settings.coast_cmd_mps)
    speed = speed_estimate(log)
    free = ((drive_off & (np.abs(speed) >= settings.moving_mps))
            | _esc_reversals(log.speed_cmd_mps, speed, settings=settings))
    fsum = np.concatenate([[0], np.cumsum(free)])

    def activity(i: int, *, settings: GapSettings = SETTINGS) -> float:
        a = int(np.searchsorted(t, t[i] - settings.quiet_before_s))
        b = int(np.searchsorted(t, t[i] + settings.quiet_after_s))
        b = min(b, n - 1)
        return float(csum[b] - csum[a]) + (1e3 if fsum[b + 1] - fsum[i] else 0.0)

    windows: list[Window] = []
    for a, b in pieces(log, _widen(t, exclude, 0.5 * settings.smooth_s)):
        if t[b - 1] - t[a] < 0.5 * window_s:
            continue
        edges, slots = [a], [math.ceil((t[a] + 0.5 * window_s) / window_s) - 1]
        m = slots[0]
        while True:
            m += 1  # the next boundary's grid slot
            goal = m * window_s
            if goal >= t[b - 1] - 0.5 * window_s:
                break
            if goal <= t[edges[-1]]:  # passed already (a sparse stretch): the next slot
                continue
            lo = int(np.searchsorted(t, goal - shift))
            hi = int(np.searchsorted(t, goal + shift))
            cands = range(max(lo, edges[-1] + 1), min(hi, b - 1))
            if len(cands):
                edges.append(min(cands, key=lambda i: (round(activity(i, settings=settings), 9), abs(t[i] - goal))))
            else:
                k = max(int(np.searchsorted(t, goal)), edges[-1] + 1)  # no sample near the goal: the next one
                if k >= b - 1:
                    break
                edges.append(k)
            slots.append(m)
        edges.append(b)
        windows += [Window(x, y, m) for x, y, m in zip(edges[:-1], edges[1:], slots)]
    return windows


def _esc_reversals(speed_cmd_mps: np.ndarray, speed_mps: np.ndarray, *, settings: GapSettings = SETTINGS) -> np.ndarray:
    """``(N,) bool``: the samples from a reverse command (``speed_cmd <= -settings.coast_cmd_mps``)
    given while the car rolls forward (``speed >= settings.moving_mps``) until the car reverses
    (``speed <= -settings.moving_mps``) or the command is no longer a reverse one."""
    reverse = speed_cmd_mps <= -settings.coast_cmd_mps
    out = np.zeros(reverse.size, dtype=bool)
    starts = np.flatnonzero(reverse & ~np.concatenate([[False], reverse[:-1]]) & (speed_mps >= settings.moving_mps))
    for k in starts:
        j = k
        while j < reverse.size and reverse[j] and speed_mps[j] > -settings.moving_mps:
            j += 1
        out[k:j] = True
    return out


def _widen(t: np.ndarray, exclude: np.ndarray | None, margin_s: float) -> np.ndarray | None:
    """``exclude`` grown to every sample within ``margin_s`` of an excluded one."""
    if exclude is None:
        return None
    ex = np.asarray(exclude, dtype=bool)
    if not ex.any() or margin_s <= 0.0:
        return ex
    te = t[ex]
    k = np.searchsorted(te, t)
    before = np.abs(t - te[np.clip(k - 1, 0, te.size - 1)])
    after = np.abs(te[np.clip(k, 0, te.size - 1)] - t)
    return ex | (np.minimum(before, after) <= margin_s)


def split_windows(windows: Sequence[Window], every: int | None = None,
                  strata: Sequence[object] | None = None, *,
                  settings: GapSettings = SETTINGS) -> tuple[list[Window], list[Window]]:
    """(fit, held_out), stratified: the windows are grouped by their ``strata`` label
    (default: one group). In the largest group (the first of equal ones), a window is held
    out when its grid slot (:attr:`Window.slot`) is ``every - 1`` modulo ``every``: the
    choice is the window's own, so a glitch or a gap that removes a window leaves every
    other window where it was (counted from the group's last window, the windows before a
    dropped second of a log all moved between the sets). In each other group, counting
    back from its last window, every ``every``-th window is held out (the last, the ``every
    + 1``-th from last, ...), so a rare manoeuvre (the report groups windows with coasting
    or braking to rest apart) reaches the held-out set as soon as the log has two of them -
    the plan's last coast - while its first ones stay in the fit; a group of one window
    stays in the fit. If nothing is held out that way (a short log), the split ignores the
    strata, and if still nothing, the last window is held out. ``every`` default:
    ``settings.holdout_every``."""
    every = settings.holdout_every if every is None else every
    labels = list(strata) if strata is not None else [None] * len(windows)
    size: dict[object, int] = {}
    for label in labels:
        size[label] = size.get(label, 0) + 1
    main = max(size, key=lambda label: size[label]) if size else None  # max keeps the first of equals
    left = dict(size)
    fit, held = [], []
    for w, label in zip(windows, labels):
        left[label] -= 1  # windows of this group after this one
        if label == main:
            out = w.slot % every == every - 1
        else:
            out = left[label] % every == 0 and size[label] > 1
        (held if out else fit).append(w)
    if not held and strata is not None:  # a short log: hold out without strata
        return split_windows(windows, every, settings=settings)
    if not held and len(windows) > 1:
        return list(windows[:-1]), [windows[-1]]
    return fit, held


@dataclass(frozen=True)
class Prediction:
    """Predicted states at the log's samples, shape (N,), NaN outside replayed windows.

    ``speed_mps`` and ``yaw_rate_radps`` are what the log's sensors would show: where the log
    takes them from its pose (no speed sensor, no gyro), the predicted pose of each window
    put through the same smoothing and derivative (:func:`simrunner.workflows.gap.logs.pose_rates`)."""

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray


def replay(car: CarDescription, log: RunLog, derived: Derived, windows: Sequence[Window], *,
           dt_s: float = SETTINGS.workflow_dt_s, sim_factory: SimFactory = default_sim_factory,
           lead_s: float | None = None, settings: GapSettings = SETTINGS) -> Prediction:
    """Replay ``windows`` of ``log`` with a simulator of ``car``; see the module docstring.

    Lead-in: a window starting at sample ``i0 > 0`` is preceded by the ``lead_s`` seconds
    of commands before it, replayed from the measured state at their first sample and not
    recorded; at ``i0`` the car is moved to the measured state with ``sim.place`` (the
    physical state only), so commands still in flight (latency, lags, rate limits) reach
    the window as they would on the car instead of starting settled. ``lead_s=None``:
    ``settings.lead_s``; 0 starts every window settled. A car with a steering play first gets
    the ``settings.play_history_s`` seconds of steering commands before the lead-in
    (``prime_steering``): which side of its band the play rests on is in no measured state."""
    lead_s = settings.lead_s if lead_s is None else float(lead_s)
    n = len(log)
    out = np.full((5, n), np.nan)
    sim = sim_factory(car, dt_s)
    t = log.t_s
    coast = log.coasting()
    pose = has_pose(log)
    wheelbase = car.chassis.wheelbase_m
    prime = car.effects.steering_play_rad > 0.0  # the only history-dependent command state
    after_gap = np.concatenate([[0], np.flatnonzero(time_gaps(t)) + 1])  # first sample of each piece

    heading = None if pose else dead_reckoned_yaw(log, derived, wheelbase)
    seen_through_pose = pose and (log.speed_mps is None or log.yaw_rate_radps is None)
    if seen_through_pose:  # the pieces the log was smoothed in (derive leaves NaN between them)
        smooth_pieces = pieces(log, ~np.isfinite(derived.x_m))
        smooth_starts = np.array([lo for lo, _ in smooth_pieces])

    shift = [0.0, 0.0]  # the current window's poses minus the simulator's (settings.origin_step_m)

    def state(i: int):
        v, steer, r = float(derived.speed_mps[i]), float(derived.steer_rad[i]), float(derived.yaw_rate_radps[i])
        if derived.at_rest[i]:  # standing: not rolling at the smoothed noise's speed
            v, r = 0.0, 0.0
        if not math.isfinite(r):  # no gyro and no pose: the kinematic yaw rate of the steer
            r = v * math.tan(steer) / wheelbase
        p = (Pose2(derived.x_m[i] - shift[0], derived.y_m[i] - shift[1], derived.yaw_rad[i]) if pose
             else Pose2(0.0, 0.0, float(heading[i])))
        return p, v, steer, r

    def usable(i: int) -> bool:
        p, v, steer, r = state(i)
        return all(math.isfinite(x) for x in (p.x_m, p.y_m, p.yaw_rad, v, steer, r))

    steps = log.command_steps  # a merged log's commands at their own stamps (None: the rows')
    if steps is not None:
        step_coast = steps.coast if steps.coast is not None else np.zeros(len(steps), dtype=bool)
        # the command messages strictly between each row and the next
        first_step = np.searchsorted(steps.t_s, t, side="right")
        last_step = np.append(np.searchsorted(steps.t_s, t[1:], side="left"), first_step[-1])
        # as Python values once per replay (the same floats; numpy scalars are slow one at a time)
        step_t, step_coast_l = steps.t_s.tolist(), step_coast.astype(bool).tolist()
        step_speed, step_steer = steps.speed_cmd_mps.tolist(), steps.steer_cmd_rad.tolist()
        first_l, last_l = first_step.tolist(), last_step.tolist()

    motors = (log.duty_left, log.duty_right) if log.duty_left is not None and log.duty_right is not None else None
    # the per-sample columns the loop below reads, as Python values (same floats, bools)
    t_l, coast_l = t.tolist(), coast.astype(bool).tolist()
    speed_cmd, steer_cmd = log.speed_cmd_mps.tolist(), log.steer_cmd_rad.tolist()
    if motors is not None:  # the motors' own duties where the log gives no one duty command
        own_duties = ~np.isfinite(log.duty_cmd) if log.duty_cmd is not None else np.ones(n, dtype=bool)
        own_duties_l, duty_l, duty_r = own_duties.tolist(), motors[0].tolist(), motors[1].tolist()

    def run(a: int, b: int, record: bool) -> None:
        """Apply the commands of samples a .. b-1 (zero-order hold) up to sample b (recorded
        at a .. b-1 when ``record``; the last command is applied only if b is past it); a
        merged log's command messages between two samples take effect at their own stamps."""
        done = 0
        coast_now = coast_l[a]
        t_a = t_l[a]
        rows = []

        def advance(to_s: float) -> None:  # step the simulator up to the time to_s
            nonlocal done
            target = int(round((to_s - t_a) / dt_s))
            if target > done:
                sim.step(target - done)
                done = target

        for i in range(a, b):
            if record:
                p = sim.pose
                rows.append((p.x_m + shift[0], p.y_m + shift[1], p.yaw_rad, sim.speed_mps, sim.yaw_rate_radps))
            if i + 1 < n and (i + 1 < b or not record):
                if coast_l[i] != coast_now:
                    coast_now = coast_l[i]
                    sim.set_coast(coast_now)
                sim.set_command(speed_cmd[i], steer_cmd[i])
                if motors is not None and own_duties_l[i]:
                    sim.set_motors(duty_l[i], duty_r[i])  # the motors' own duties
                if steps is not None:
                    for k in range(first_l[i], last_l[i]):
                        advance(step_t[k])
                        if step_coast_l[k] != coast_now:
                            coast_now = step_coast_l[k]
                            sim.set_coast(coast_now)
                        sim.set_command(step_speed[k], step_steer[k])
                advance(t_l[i + 1])
        if rows:  # recorded at once: one array write instead of one per sample
            out[:, a:a + len(rows)] = np.array(rows).T

    for w in windows:
        i0 = next((i for i in range(w.start, w.stop) if usable(i)), None)
        if i0 is None:
            continue
        piece_start = int(after_gap[np.searchsorted(after_gap, i0, side="right") - 1])
        j0 = int(np.searchsorted(t, t[i0] - lead_s - 1e-9)) if lead_s > 0.0 else i0
        j0 = max(j0, piece_start)  # the lead-in stays on this side of a time gap
        j0 = next(j for j in range(j0, i0 + 1) if usable(j))
        if pose:
            shift[:] = [settings.origin_step_m * round(float(derived.x_m[j0]) / settings.origin_step_m),
                        settings.origin_step_m * round(float(derived.y_m[j0]) / settings.origin_step_m)]
        sim.set_coast(bool(coast[j0]))
        sim.set_state(*state(j0))
        if prime and lead_s > 0.0:
            h = int(np.searchsorted(t, t[j0] - settings.play_history_s - 1e-9))  # time gaps: commands held
            if h < j0 and steps is None:
                sim.prime_steering(t[h:j0 + 1], log.steer_cmd_rad[h:j0])
            elif h < j0:  # a merged log: the command messages between the rows too
                a, b = first_step[h], int(np.searchsorted(steps.t_s, t[j0], side="left"))
                sim.prime_steering(np.concatenate([[t[h]], steps.t_s[a:b], [t[j0]]]),
                                   np.concatenate([[log.steer_cmd_rad[h]], steps.steer_cmd_rad[a:b]]))
        if j0 < i0:
            run(j0, i0, record=False)
            if bool(coast[i0 - 1]) != bool(coast[i0]):
                sim.set_coast(bool(coast[i0]))
            sim.place(*state(i0))
        if not seen_through_pose:
            run(i0, w.stop, record=True)
            continue
        # the rates the pose gives at a sample depend on the samples around it: the log's own
        # pose before the window (the car's history), and the prediction run on past its end
        k = int(np.searchsorted(smooth_starts, i0, side="right")) - 1
        lo, hi = smooth_pieces[k]
        win = smoothing_window(t[lo:hi], settings=settings)
        a, stop2 = max(lo, i0 - win // 2), min(hi, w.stop + win // 2)
        kept = out[:, w.stop:stop2].copy()
        run(i0, stop2, record=True)
        xs = np.concatenate([log.x_m[a:i0], out[0, i0:stop2]])
        ys = np.concatenate([log.y_m[a:i0], out[1, i0:stop2]])
        yaws = np.concatenate([log.yaw_rad[a:i0], out[2, i0:stop2]])  # pose_rates unwraps
        speed, rate = pose_rates(t[a:stop2], xs, ys, yaws, window=win, settings=settings)
        out[:, w.stop:stop2] = kept
        if log.speed_mps is None:
            out[3, i0:w.stop] = speed[i0 - a:w.stop - a]
        if log.yaw_rate_radps is None:
            out[4, i0:w.stop] = rate[i0 - a:w.stop - a]
    return Prediction(*out)




def dead_reckoned_yaw(log: RunLog, derived: Derived, wheelbase_m: float) -> np.ndarray:
    """``(N,)`` heading (rad) of a log without pose: the smoothed yaw rate (the kinematic
    ``v tan(steer) / L`` where it is unknown) integrated by the trapezoid rule from 0 at the
    first sample, across gaps too (the heading after a gap is a guess either way)."""
    r = np.asarray(derived.yaw_rate_radps, dtype=float)
    kin = derived.speed_mps * np.tan(derived.steer_rad) / wheelbase_m
    r = np.where(np.isfinite(r), r, np.where(np.isfinite(kin), kin, 0.0))
    inc = 0.5 * (r[1:] + r[:-1]) * np.diff(log.t_s)
    return np.concatenate([[0.0], np.cumsum(inc)])


def residuals(log: RunLog, derived: Derived, pred: Prediction) -> dict[str, np.ndarray]:
    """Predicted minus measured, per signal of :func:`signals_of` (``log``), plus
    ``position_m`` when the log has a pose."""
    out: dict[str, np.ndarray] = {}
    have = signals_of(log)
    if "along_m" in have:
        ex, ey = pred.x_m - log.x_m, pred.y_m - log.y_m
        c, s = np.cos(log.yaw_rad), np.sin(log.yaw_rad)
        out["along_m"], out["cross_m"] = ex * c + ey * s, -ex * s + ey * c
        out["yaw_rad"] = (pred.yaw_rad - log.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
    if "speed_mps" in have:
        out["speed_mps"] = pred.speed_mps - (log.speed_mps if log.speed_mps is not None else derived.speed_mps)
    if "yaw_rate_radps" in have:
        measured = log.yaw_rate_radps if log.yaw_rate_radps is not None else derived.yaw_rate_radps
        out["yaw_rate_radps"] = pred.yaw_rate_radps - measured
    if "along_m" in have:
        out["position_m"] = np.hypot(out["along_m"], out["cross_m"])
    return out


def smoothed_log(log: RunLog, derived: Derived) -> RunLog:
    """``log`` with its measured states replaced by the smoothed ones (``derived``; the
    measured value stays where there is no smoothed one): residuals against it show the
    model error without most of the sensor noise."""
    cols = {}
    for name in ("x_m", "y_m", "yaw_rad", "speed_mps", "yaw_rate_radps"):
        measured = getattr(log, name)
        if measured is not None:
            smooth = getattr(derived, name)
            cols[name] = np.where(np.isfinite(smooth), smooth, measured)
    return log.with_columns(**cols)


def noise_rms(log: RunLog, derived: Derived) -> dict[str, float]:
    """Estimated sensor noise: RMS of measured minus smoothed states, per report signal
    (about 15 % below the true white-noise sigma: the smoother follows part of the noise);
    NaN for a signal the log does not measure directly (``position_m`` and ``yaw_rad``
    without a pose, ``speed_mps`` without a speed sensor or pose, ``yaw_rate_radps``
    without a gyro)."""
    nan = float("nan")
    out = {"position_m": nan, "yaw_rad": nan, "speed_mps": nan, "yaw_rate_radps": nan}
    if has_pose(log):
        out["position_m"] = rms_finite(np.hypot(log.x_m - derived.x_m, log.y_m - derived.y_m))
        out["yaw_rad"] = rms_finite((log.yaw_rad - derived.yaw_rad + math.pi) % (2.0 * math.pi) - math.pi)
    if log.speed_mps is not None:
        out["speed_mps"] = rms_finite(log.speed_mps - derived.speed_mps)
    if log.yaw_rate_radps is not None:
        out["yaw_rate_radps"] = rms_finite(log.yaw_rate_radps - derived.yaw_rate_radps)
    return out


def window_mask(n: int, windows: Sequence[Window]) -> np.ndarray:
    """Boolean (n,) mask of the samples inside ``windows``."""
    m = np.zeros(n, dtype=bool)
    for w in windows:
        m[w.start:w.stop] = True
    return m


def rmse(res: dict[str, np.ndarray], mask: np.ndarray, signals: Sequence[str] = REPORT_SIGNALS) -> dict[str, float]:
    """RMS of each residual signal over the finite samples in ``mask`` (NaN for a signal
    that ``res`` lacks or has no finite sample of in ``mask``)."""
    out = {}
    for s in signals:
        r = res.get(s)
        v = r[mask & np.isfinite(r)] if r is not None else np.zeros(0)
        out[s] = float(np.sqrt(np.mean(v * v))) if v.size else float("nan")
    return out
