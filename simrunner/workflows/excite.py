"""Excitation plan (issue 4): a command schedule a team drives open loop on its real car.

The plan is a table at the camera frame rate (``RATE_HZ`` = 50 Hz) of
``t`` (s), ``speed_cmd`` (m/s), ``steer_cmd`` (rad, + = left), ``coast`` (0/1: drive off,
wheels free) and ``segment`` (``kind:detail``). It is built so that every effect of
:data:`simrunner.car.effects.EFFECTS` leaves a trace (``SEGMENT_KINDS`` says which kind
reveals which effect; docs/calibration.md has the table) and the car stays in a hall-floor
area of about 6 x 6 m: between experiments a ``turn`` segment (alternating left and right
when either would do) points the car back through the middle of the area, using a
kinematic bicycle prediction of the nominal car.

:func:`run_plan` plays a plan in the simulator (``make_sim``, so effects apply) and
returns its :class:`~simrunner.run.log.RunLog`, the record every workflow uses (written with
``simrunner.run.log.write_log``; schema: docs/telemetry.md).
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pieces.pose import Pose2, wrap_angle
from simrunner.errors import SimError
from simrunner.run.log import RunLog, log_from_columns
from vehicle.description import CarDescription
from vehicle.userfiles import read_user_text

RATE_HZ = 50.0
MIN_DURATION_S = 67.0  # the core plan (every experiment once) of the default car lasts ~67 s
MAX_DURATION_S = 600.0
AREA_M = 6.0  # side of the square hall area the plan is meant for
_MARGIN_M = 0.8  # the turn planner keeps the predicted path this far inside the area

# kind -> effects it reveals (names of simrunner.car.effects.EFFECTS); "pause" and "turn" link
SEGMENT_KINDS: dict[str, tuple[str, ...]] = {
    "pause": (),
    "speed_ramp": ("throttle_deadband", "motor_lag"),
    "straight": ("steering_offset",),
    "turn": ("steering_gain", "steering_rate_limit", "steering_offset"),
    "step_steer": ("steering_offset", "steering_gain", "steering_lag", "command_latency",
                   "steering_rate_limit"),
    "circle": ("steering_gain", "tire_slip", "friction", "steering_offset"),
    "speed_step": ("command_latency", "motor_lag"),
    "coast": ("rolling_resistance", "drag"),
    "brake": (),
    "chirp": ("steering_lag", "command_latency", "steering_rate_limit"),
    "random_steer": ("steering_lag", "command_latency", "steering_offset"),
}

HEADER = """\
nxpcup excitation plan (simrunner excite): one row per camera frame ({rate:g} Hz), {n} rows, {dur:.1f} s.
Columns: t (s from the start), speed_cmd (m/s, signed), steer_cmd (rad, bicycle-equivalent,
+ = left), coast (1 = drive off, wheels roll freely), segment (kind:detail).
Play-back on the real car: put it at rest in a free area of at least {area:g} x {area:g} m,
facing along +x (the predicted path spans {wx:.1f} x {wy:.1f} m; start {sx:.1f} m from the
area's west edge and {sy:.1f} m from its south edge). Every frame k, at t_k: convert speed_cmd
with your speed normalisation (m/s -> your motor command) and steer_cmd with your servo
normalisation (rad -> your servo command), send both (coast = 1: motor driver off / ESC
neutral without drag brake), and log t, x, y, yaw, speed (and your actual commands) to a
CSV in the telemetry schema (docs/telemetry.md). See docs/calibration.md.
seed={seed}"""


class PlanError(SimError):
    """A plan CSV is malformed, or plan options are out of range."""


@dataclass(frozen=True, eq=False)
class ExcitationPlan:
    """A command schedule. Arrays are ``(N,)``: ``t_s`` from 0 at ``1 / rate_hz`` steps,
    ``speed_cmd_mps``, ``steer_cmd_rad``, ``coast`` (bool), ``segment`` (str)."""

    t_s: np.ndarray
    speed_cmd_mps: np.ndarray
    steer_cmd_rad: np.ndarray
    coast: np.ndarray
    segment: tuple[str, ...]
    rate_hz: float = RATE_HZ
    seed: int = 0

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def duration_s(self) -> float:
        return float(len(self.t_s)) / self.rate_hz

    def segments(self) -> list[tuple[str, float, float]]:
        """``[(segment, t_start_s, t_end_s)]`` of consecutive runs of equal segment names."""
        out: list[tuple[str, float, float]] = []
        start = 0
        for i in range(1, len(self.segment) + 1):
            if i == len(self.segment) or self.segment[i] != self.segment[start]:
                out.append((self.segment[start], float(self.t_s[start]), float(self.t_s[i - 1]) + 1.0 / self.rate_hz))
                start = i
        return out

    def kind_mask(self, kind: str) -> np.ndarray:
        """``(N,) bool``: rows whose segment is of ``kind`` (see :data:`SEGMENT_KINDS`)."""
        return np.array([segment_kind(s) == kind for s in self.segment], dtype=bool)

    # -- files -------------------------------------------------------------------------
    def to_csv(self, path: str | Path, *, extent: tuple[float, float, float, float] | None = None) -> Path:
        """Write the plan (atomically) with the play-back header as ``#`` comments.
        ``extent`` = predicted ``(x_min, x_max, y_min, y_max)`` of the path (default:
        :func:`predict_path` of the default car)."""
        path = Path(path)
        if extent is None:
            xy = predict_path(self, CarDescription())
            extent = (xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max())
        x0, x1, y0, y1 = extent
        wx, wy = x1 - x0, y1 - y0
        head = HEADER.format(rate=self.rate_hz, n=len(self), dur=self.duration_s, area=AREA_M,
                             wx=wx, wy=wy, sx=0.5 * (AREA_M - wx) - x0, sy=0.5 * (AREA_M - wy) - y0,
                             seed=self.seed)
        lines = ["# " + ln for ln in head.splitlines()]
        lines.append("t,speed_cmd,steer_cmd,coast,segment")
        for t, v, d, c, s in zip(self.t_s, self.speed_cmd_mps, self.steer_cmd_rad, self.coast, self.segment):
            lines.append(f"{t:.3f},{v:.6f},{d:.6f},{int(c)},{s}")
        tmp = path.with_name(path.name + ".tmp")
        try:
            tmp.write_text("\n".join(lines) + "\n")
            os.replace(tmp, path)
        except OSError as exc:
            raise PlanError(f"{path}: cannot write plan ({exc.strerror})") from None
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "ExcitationPlan":
        """Read a plan written by :meth:`to_csv` (``#`` lines are comments; ``coast`` and
        ``segment`` columns are optional). Errors name the file and line."""
        path = Path(path)
        text = read_user_text(path, "plan", PlanError, "CSV")
        rows = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
        if not rows:
            raise PlanError(f"{path}:1: empty plan, expected the header t,speed_cmd,steer_cmd[,coast][,segment]")
        hline, header = rows[0]
        cols = [c.strip() for c in next(csv.reader([header]))]
        for need in ("t", "speed_cmd", "steer_cmd"):
            if need not in cols:
                raise PlanError(f"{path}:{hline}: header lacks column '{need}' (expected t,speed_cmd,steer_cmd[,coast][,segment])")
        unknown = [c for c in cols if c not in ("t", "speed_cmd", "steer_cmd", "coast", "segment")]
        if unknown:
            raise PlanError(f"{path}:{hline}: unknown column '{unknown[0]}' (expected t,speed_cmd,steer_cmd[,coast][,segment])")
        idx = {c: cols.index(c) for c in cols}
        t, v, d, co, seg = [], [], [], [], []
        seed = 0
        for m in (ln for ln in text.splitlines() if ln.startswith("# seed=")):
            try:
                seed = int(m.split("=", 1)[1])
            except ValueError:
                pass
        for line_no, ln in rows[1:]:
            vals = next(csv.reader([ln]))
            if len(vals) != len(cols):
                raise PlanError(f"{path}:{line_no}: expected {len(cols)} values, got {len(vals)}")
            try:
                tv, vv, dv = (float(vals[idx[c]]) for c in ("t", "speed_cmd", "steer_cmd"))
                cv = int(vals[idx["coast"]]) if "coast" in idx else 0
            except ValueError:
                raise PlanError(f"{path}:{line_no}: expected numbers in t,speed_cmd,steer_cmd and 0/1 in coast") from None
            if not all(math.isfinite(x) for x in (tv, vv, dv)) or cv not in (0, 1):
                raise PlanError(f"{path}:{line_no}: expected finite numbers and coast 0 or 1")
            t.append(tv), v.append(vv), d.append(dv), co.append(bool(cv))
            seg.append(vals[idx["segment"]].strip() if "segment" in idx else "")
        if len(t) < 2:
            raise PlanError(f"{path}: expected at least 2 rows")
        ta = np.array(t)
        dt = np.diff(ta)
        period = float(dt[0])
        if period <= 0 or np.any(np.abs(dt - period) > 1e-3 * period + 5e-4) or abs(ta[0]) > 1e-9:
            bad = int(np.argmax(np.abs(dt - period) > 1e-3 * period + 5e-4)) if period > 0 else 0
            raise PlanError(f"{path}:{rows[bad + 2][0]}: expected t to start at 0 and rise in equal steps "
                            f"(one row per camera frame)")
        rate = round(1.0 / period, 6)
        return cls(np.arange(len(t)) / rate, np.array(v), np.array(d), np.array(co, dtype=bool), tuple(seg),
                   rate_hz=rate, seed=seed)


def segment_kind(segment: str) -> str:
    """``"step_steer:+0.10"`` -> ``"step_steer"``."""
    return segment.split(":", 1)[0]


# -- building ----------------------------------------------------------------------------
class _Builder:
    """Appends command rows and predicts the nominal car (kinematic bicycle with the speed
    and steering limits) so turns can aim the car back through the area's middle."""

    def __init__(self, car: CarDescription, rate_hz: float, middle_xy: tuple[float, float] = (0.0, 0.0)):
        self.car = car
        self.mx, self.my = middle_xy
        self.dt = 1.0 / rate_hz
        self.rows: list[tuple[float, float, bool, str]] = []
        self.x = self.y = self.yaw = self.v = self.steer = 0.0
        self.turn_sign = -1.0  # direction of the last turn: the next tie goes the other way
        self._probe_cache: np.ndarray | None = None
        self.xy: list[tuple[float, float]] = [(0.0, 0.0)]

    def emit(self, speed: float, steer: float, segment: str, coast: bool = False) -> None:
        car, dt = self.car, self.dt
        lim = car.steering.limit_rad
        self.rows.append((float(speed), float(steer), bool(coast), segment))
        # predict one frame
        target = min(max(steer, -lim), lim)
        ds = car.steering.rate_radps * dt
        self.steer += min(max(target - self.steer, -ds), ds)
        if not coast:
            a = car.drive.max_accel_mps2 if abs(speed) > abs(self.v) else car.drive.max_brake_mps2
            self.v += min(max(speed - self.v, -a * dt), a * dt)
        self.yaw += self.v * math.tan(self.steer) / car.chassis.wheelbase_m * dt
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        self.xy.append((self.x, self.y))

    def hold(self, seconds: float, speed: float, steer: float, segment: str, coast: bool = False) -> None:
        for _ in range(max(1, round(seconds / self.dt))):
            self.emit(speed, steer, segment, coast)

    def ramp(self, seconds: float, v0: float, v1: float, steer: float, segment: str) -> None:
        n = max(1, round(seconds / self.dt))
        for k in range(n):
            self.emit(v0 + (v1 - v0) * (k + 1) / n, steer, segment)

    def probe(self, experiment) -> np.ndarray:
        """``(M, 2)`` path of ``experiment(builder)`` from this speed and steering, started at
        the origin heading +x (a dry run: nothing is emitted here)."""
        p = _Builder(self.car, 1.0 / self.dt)
        p.v, p.steer = self.v, self.steer
        experiment(p)
        return np.array(p.xy)

    def turn_then(self, experiment, speed: float, steer_frac: float = 0.8) -> None:
        """Turn at ``steer_frac`` of the limit, then run ``experiment(builder)``. The turn
        (direction, and angle in 5 degree steps) minimises the largest distance of the
        experiment's predicted path from the middle of the area (plus a small price per
        degree); ties go against the last turn's direction, so turns alternate."""
        wb = self.car.chassis.wheelbase_m
        steer = steer_frac * self.car.steering.limit_rad
        radius = wb / math.tan(steer)
        best = None
        for sign in (-self.turn_sign, self.turn_sign):
            cx, cy = self.x - sign * radius * math.sin(self.yaw), self.y + sign * radius * math.cos(self.yaw)
            for k in range(72):
                phi = math.radians(5.0 * k)
                yaw = self.yaw + sign * phi
                px, py = cx + sign * radius * math.sin(yaw), cy - sign * radius * math.cos(yaw)
                path = self._probe_cache if k or sign != -self.turn_sign else None
                if path is None:
                    path = self._probe_cache = self.probe(experiment)
                c, s_ = math.cos(yaw), math.sin(yaw)
                wx = px + c * path[:, 0] - s_ * path[:, 1] - self.mx
                wy = py + s_ * path[:, 0] + c * path[:, 1] - self.my
                cost = float(np.sqrt(wx * wx + wy * wy).max()) + 0.05 * phi
                cost += 0.0 if sign == -self.turn_sign else 0.05
                if best is None or cost < best[0] - 1e-9:
                    best = (cost, sign, phi)
        _, sign, phi = best
        self.turn_sign = sign
        label = f"turn:{'left' if sign > 0 else 'right'}"
        yaw0 = self.yaw
        for _ in range(int(10.0 / self.dt)):
            if sign * (self.yaw - yaw0) >= phi - 0.5 * abs(self.v) * math.tan(steer) / wb * self.dt:
                break
            self.emit(speed, sign * steer, label)
        experiment(self)


def make_plan(car: CarDescription | None = None, *, seed: int = 0, rate_hz: float = RATE_HZ,
              duration_s: float | None = None) -> ExcitationPlan:
    """The excitation plan for ``car`` (about 65 s; docs/calibration.md lists the segments).

    Speeds and steering amplitudes follow the car's limits (``drive.max_speed_mps``,
    ``steering.limit_rad``, ``wheels.friction_mu``). ``seed`` drives only the
    ``random_steer`` steps (``numpy.random.default_rng(seed)``). ``duration_s`` (at least
    ``MIN_DURATION_S``) appends more random-steer blocks until the plan lasts about that
    long (each block a turn, 3 s of steps and a stop: +-4 s); ``None`` gives the core plan.
    """
    car = car or CarDescription()
    if not (5.0 <= rate_hz <= 1000.0):
        raise PlanError(f"rate_hz = {rate_hz!r}: expected 5 .. 1000")
    if duration_s is not None and not (MIN_DURATION_S <= duration_s <= MAX_DURATION_S):
        raise PlanError(f"duration = {duration_s!r} s: expected {MIN_DURATION_S:g} .. {MAX_DURATION_S:g} s "
                        f"(the core plan needs about {MIN_DURATION_S:g} s)")
    rng = np.random.default_rng(seed)
    lim, vmax = car.steering.limit_rad, car.drive.max_speed_mps
    wb, mu = car.chassis.wheelbase_m, car.wheels.friction_mu
    v_lo, v_mid = min(0.8, 0.5 * vmax), min(1.2, 0.6 * vmax)
    v_fast = min(2.0, 0.8 * vmax)
    # the first run (ramp + straight) goes ~2.7 m east: the middle of the area is half-way
    b = _Builder(car, rate_hz, middle_xy=(0.5 * (0.5 * 2.5 + 1.0) * v_mid, 0.0))
    b.hold(1.0, 0.0, 0.0, "pause:start")
    # 1. slow ramp from rest (deadband: when does it start to roll?), then straight (offset)
    b.ramp(2.5, 0.0, v_mid, 0.0, f"speed_ramp:0-{v_mid:.1f}")
    b.hold(1.0, v_mid, 0.0, f"straight:{v_mid:.1f}")

    # 2. step steers left and right, small and medium amplitude (offset, gain, lag, latency)
    def steps(frac):
        def run(p):
            a = frac * lim
            p.hold(0.4, v_mid, 0.0, f"straight:{v_mid:.1f}")
            for sign, secs in ((1, 0.5), (-1, 1.0), (1, 0.5)):
                p.hold(secs, v_mid, sign * a, f"step_steer:{sign * a:+.2f}")
            p.hold(0.4, v_mid, 0.0, f"straight:{v_mid:.1f}")
        return run

    b.turn_then(steps(0.25), v_lo)
    b.turn_then(steps(0.5), v_lo)

    # 3. circles at rising speed, left then right (gain, understeer, grip limit)
    steer_c = 0.7 * lim
    radius = wb / math.tan(steer_c)
    v_top = min(math.sqrt(0.85 * mu * 9.81 * radius), 0.85 * vmax)

    def circles(sign):
        side = "left" if sign > 0 else "right"

        def run(p):
            p.hold(0.3, v_lo, 0.0, "straight:settle")
            for k, v in enumerate(np.linspace(v_lo, v_top, 4)):
                p.hold(0.75 * 2.0 * math.pi * radius / v if k == 0 else 1.5, v, sign * steer_c, f"circle:{side}@{v:.1f}")
            p.hold(0.8, v_lo, sign * steer_c, f"circle:{side}@{v_lo:.1f}")
        return run

    b.turn_then(circles(1), v_lo)
    b.turn_then(circles(-1), v_lo)

    # 4. speed steps (latency, motor lag), then brake to rest
    def speed_steps(p):
        p.hold(0.3, v_lo, 0.0, "straight:settle")
        for v in (v_step, v_lo, v_step, 0.3):
            p.hold(0.8, v, 0.0, f"speed_step:{v:.1f}")
        p.hold(0.6, 0.0, 0.0, "brake:0")
        p.hold(0.5, 0.0, 0.0, "pause:rest")

    v_step = min(1.6, 0.7 * vmax)
    b.turn_then(speed_steps, v_lo)

    # 5. coast-down from speed (rolling resistance, drag), then brake to rest
    def coast(p):
        p.hold(0.9, v_fast, 0.0, f"straight:{v_fast:.1f}")
        p.hold(1.0, 0.0, 0.0, f"coast:{v_fast:.1f}", coast=True)
        p.hold(0.8, 0.0, 0.0, "brake:0")
        p.hold(0.5, 0.0, 0.0, "pause:rest")

    b.turn_then(coast, v_lo)

    # 6. steering chirp 0.3 -> 2.5 Hz (lag, latency, rate limit)
    f0, f1, amp, v_chirp = 0.3, 2.5, 0.3 * lim, min(0.6, v_lo)

    def chirp(p):
        p.hold(0.3, v_chirp, 0.0, "straight:settle")
        n, phase = round(5.0 * rate_hz), 0.0
        for k in range(n):
            phase += 2.0 * math.pi * (f0 + (f1 - f0) * k / n) / rate_hz
            p.emit(v_chirp, amp * math.sin(phase), f"chirp:{f0:g}-{f1:g}Hz")

    b.turn_then(chirp, v_lo)

    # 7. random steering steps (seeded): holds 0.15-0.5 s, amplitudes up to half the limit;
    #    repeated (new draws) until the plan lasts duration_s
    def random_block(seconds, last):
        holds, t_left = [], seconds
        while t_left > 1e-9:
            secs = min(float(rng.uniform(0.15, 0.5)), t_left)
            holds.append((secs, float(rng.uniform(-0.5, 0.5)) * lim))
            t_left -= secs

        def run(p):
            p.hold(0.3, v_lo, 0.0, "straight:settle")
            for secs, steer in holds:
                p.hold(secs, v_lo, steer, "random_steer:seed")
            p.hold(0.6, 0.0, 0.0, f"coast:{v_lo:.1f}", coast=True)
            p.hold(0.8, 0.0, 0.0, "brake:0")
            p.hold(1.0 if last else 0.4, 0.0, 0.0, "pause:end" if last else "pause:rest")
        return run

    block_s, overhead_s = 3.0, 4.5  # random steps; turn (~2 s), settle, brake and pause
    while True:
        t_now = len(b.rows) * b.dt
        last = duration_s is None or t_now + 2 * (block_s + overhead_s) > duration_s
        seconds = block_s if duration_s is None or not last else max(block_s, duration_s - t_now - overhead_s)
        b.turn_then(random_block(seconds, last), v_lo)
        if last:
            break

    rows = b.rows
    return ExcitationPlan(np.arange(len(rows)) / rate_hz, np.array([r[0] for r in rows]),
                          np.array([r[1] for r in rows]), np.array([r[2] for r in rows], dtype=bool),
                          tuple(r[3] for r in rows), rate_hz=float(rate_hz), seed=int(seed))


def predict_path(plan: ExcitationPlan, car: CarDescription) -> np.ndarray:
    """``(N + 1, 2)`` kinematic prediction of the path (nominal car, from the origin facing +x)."""
    b = _Builder(car, plan.rate_hz)
    for v, d, c in zip(plan.speed_cmd_mps, plan.steer_cmd_rad, plan.coast):
        b.emit(float(v), float(d), "", bool(c))
    return np.array(b.xy)


# -- simulating ----------------------------------------------------------------------------
def run_plan(plan: ExcitationPlan, car: CarDescription, *, dt_s: float = 0.002, seed: int = 0,
             start: Pose2 = Pose2(), pose_noise_m: float = 0.0) -> RunLog:
    """Play ``plan`` in the simulator (``simrunner.car.effects.make_sim``: effects apply).

    Each row's command is set at ``t_k`` and the state logged at ``t_k`` (before the
    frame's physics steps), like the telemetry of ``simrunner drive``. Returns a
    :class:`~simrunner.run.log.RunLog` (source ``"<excite>"``) with ``frame`` (the row
    index), ``t_s``, the pose ``x_m, y_m, yaw_rad``, the actual ``speed_mps, steer_rad,
    yaw_rate_radps``, the commands ``speed_cmd_mps, steer_cmd_rad`` and the differential
    in force ``yaw_rate_cmd_radps``, and ``coast``; no ``lap`` or ``off_track`` (there is
    no track). ``pose_noise_m`` > 0 adds Gaussian noise of that std to x and y (std / 0.2 m
    per rad to yaw) from ``numpy.random.default_rng(seed)``, to mimic a real position log;
    0 gives the exact simulated pose (``seed`` then has no effect).
    """
    from simrunner.car.effects import make_sim

    steps = plan_steps_per_row(plan, dt_s)
    sim = make_sim(car, dt_s=dt_s, start=start)
    n = len(plan)
    state = np.empty((n, 7))  # x, y, yaw, speed, steer, yaw_rate, yaw_rate_cmd
    coast_now = False
    for k in range(n):
        v, d, c = float(plan.speed_cmd_mps[k]), float(plan.steer_cmd_rad[k]), bool(plan.coast[k])
        if c != coast_now:
            sim.set_coast(c)
            coast_now = c
        sim.set_command(v, d)
        p = sim.pose
        state[k] = (p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, sim.steer_rad, sim.yaw_rate_radps,
                    sim.yaw_rate_cmd_radps)
        sim.step(steps)
    x, y, yaw = state[:, 0], state[:, 1], state[:, 2]
    if pose_noise_m > 0.0:
        rng = np.random.default_rng(seed)
        x = x + rng.normal(0.0, pose_noise_m, n)
        y = y + rng.normal(0.0, pose_noise_m, n)
        yaw = np.array([wrap_angle(a) for a in yaw + rng.normal(0.0, pose_noise_m / 0.2, n)])
    return log_from_columns({"frame": np.arange(n), "t_s": plan.t_s, "x_m": x, "y_m": y, "yaw_rad": yaw,
                             "speed_mps": state[:, 3], "steer_rad": state[:, 4], "yaw_rate_radps": state[:, 5],
                             "speed_cmd_mps": plan.speed_cmd_mps, "steer_cmd_rad": plan.steer_cmd_rad,
                             "yaw_rate_cmd_radps": state[:, 6], "coast": plan.coast}, "<excite>")


def plan_steps_per_row(plan: ExcitationPlan, dt_s: float) -> int:
    """Physics steps per plan row; the row period must be a whole number of steps."""
    steps = round(1.0 / (plan.rate_hz * dt_s))
    if steps < 1 or abs(steps * dt_s * plan.rate_hz - 1.0) > 1e-9:
        raise PlanError(f"dt_s = {dt_s!r}: expected a step that divides the plan's row period "
                        f"{1.0 / plan.rate_hz:g} s")
    return steps
