"""Excitation plan (issue 4): a command schedule a team drives on its real car.

The plan is a table at the camera frame rate (``RATE_HZ`` = 50 Hz) of ``t`` (s),
``speed_cmd`` (m/s), ``steer_cmd`` (rad, + = left), ``coast`` (0/1: drive off, wheels free),
``segment`` (``kind:detail``) and, on the rows of ``turn`` segments, the reference path
``ref_x, ref_y, ref_yaw`` (m, m, rad). It is built so that every effect of
:data:`simrunner.car.effects.EFFECTS` leaves a trace (``SEGMENT_KINDS`` says which kind
reveals which effect; docs/calibration.md has the table).

Staying in the hall area (issue 10 item 7). The experiments are open loop: their data is
what the gap fit needs. Between two experiments a ``turn`` (a Dubins path: arcs and a
straight run-in, at ``v_lo``) drives the car to the pose where the next experiment starts.
The planner (:meth:`_Builder.return_then`) places every experiment so that the paths of the
nominal car stay ``_PLAN_MARGIN_M`` inside the ``AREA_M`` x ``AREA_M`` area and those of the
whole *design envelope* (kinematic bicycles with a steering trim of up to
``DESIGN_TRIM_RAD``, a steering gain and a speed scale off by up to ``DESIGN_GAIN_ERROR`` and
``DESIGN_SPEED_ERROR``, in every combination, with room to turn afterwards) inside it. A
turn's rows hold what the nominal car does (``speed_cmd``, ``steer_cmd``) and where it is
(``ref_*``: its pose at the row). Two ways to play the turns:

* closed loop (recommended): the car follows the turn's reference path by pure pursuit
  (:func:`follow_path`) from its measured pose. A turn is *elastic*: once the car has
  arrived at the path's end the plan goes on with the row after the turn; while it has not,
  the turn's last row is repeated. Every experiment then starts about where it was planned
  whatever the car's errors: in the full simulator the cars of the design envelope stay
  inside the area grown by the margin (:func:`area_margin_m`: ``AREA_MARGIN_M`` for the
  default car, more for a car that turns wider; tests/test_excite.py).
* open loop: the turns' rows as they are. Errors then add up from one experiment to the
  next; a car with a 2 degree trim needs a much larger area (docs/calibration.md).

:func:`run_plan` plays a plan in the simulator (``make_sim``, so effects apply), open or
closed loop, and returns its :class:`~simrunner.telemetry.log.RunLog`, the record every workflow
uses (written with ``simrunner.telemetry.log.write_log``; schema: docs/telemetry.md).

The plan frame is the car's start pose: origin at the rear-axle midpoint, +x ahead, +y left,
yaw counter-clockwise (pieces/pose.py).
"""
from __future__ import annotations

import csv
import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pieces.pose import Pose2, wrap_angle
from simrunner.errors import SimError
from simrunner.telemetry.log import RunLog, log_from_columns
from trackgen.dubins import TURN_SIGN, WORDS, dubins_points, dubins_segments
from vehicle.description import CarDescription
from vehicle.userfiles import read_user_text, write_atomic

RATE_HZ = 50.0
MIN_DURATION_S = 90.0  # the core plan (every experiment once) of the default car lasts ~90 s
MAX_DURATION_S = 600.0
AREA_M = 6.0  # side of the square hall area a plan is meant for, at least (a larger car's: make_plan)
AREA_STEP_M = 0.5  # make_plan tries larger areas in these steps ...
AREA_MAX_M = 15.0  # ... up to this side
AREA_MARGIN_M = 0.6  # closed loop, a car of the design envelope stays inside the area grown by this
# (the default car's; a car that turns wider drifts further while it catches up: area_margin_m)
_PLAN_MARGIN_M = 0.3  # the planner keeps the nominal car's predicted path this far inside

# design envelope: the off-nominal cars the planner keeps inside the area (every combination)
DESIGN_TRIM_RAD = math.radians(2.0)  # steering offset, +-
DESIGN_GAIN_ERROR = 0.15  # steering gain 1 +- this
DESIGN_SPEED_ERROR = 0.15  # speed scale 1 +- this

# turns, closed loop (follow_path; docs/calibration.md has them in C)
RETURN_STEER_FRACTION = 0.9  # of steering.limit_rad: the most a planned turn steers
FOLLOW_STEER_FRACTION = 1.0  # of steering.limit_rad: the most the car steers to follow a turn
RETURN_LOOKAHEAD_M = 0.4  # pure pursuit: aim point this far away
RETURN_WINDOW_M = 0.5  # the nearest path point is looked for this far along the path
RETURN_PACE = 0.75  # the progress along the path keeps at least this fraction of the plan's ...
RETURN_LAG_S = 0.5  # ... pace, after this many seconds
RETURN_ARRIVED_M = 0.2  # arrived: past the path's end, at most this far off its end line
RETURN_TIMEOUT_S = 20.0  # a turn's last row is repeated at most this long
# turns, planned
_ARC_FRACTION = 0.85  # arcs at this fraction of the most a turn steers (the rest: room to correct)
_RUN_IN_M = 0.4  # a turn ends with this much straight on the experiment's start line

# kind -> effects it reveals (names of simrunner.car.effects.EFFECTS); "pause" and "turn" link
SEGMENT_KINDS: dict[str, tuple[str, ...]] = {
    "pause": (),
    "speed_ramp": ("throttle_deadband", "motor_lag", "speed_scale", "top_speed"),  # gentler than max accel
    "straight": ("steering_offset", "speed_scale", "top_speed"),
    "turn": ("steering_gain", "steering_rate_limit", "steering_offset", "steering_asymmetry",
             "steer_limit_scale", "inertia", "tyre_stiffness", "tyre_balance"),
    "step_steer": ("steering_offset", "steering_gain", "steering_lag", "command_latency",
                   "steering_rate_limit", "steering_asymmetry", "steering_play", "servo_rate_scale", "inertia",
                   "tyre_stiffness", "tyre_relaxation"),
    "circle": ("steering_gain", "tire_slip", "friction", "steering_offset", "steering_asymmetry",
               "steer_limit_scale", "inertia", "tyre_stiffness", "tyre_balance"),
    "speed_step": ("command_latency", "motor_lag", "lift_lag", "speed_scale", "accel_scale", "brake_scale", "mass_scale",
                   "top_speed", "front_drive"),
    "coast": ("rolling_resistance", "drag"),
    "brake": ("brake_scale", "mass_scale", "front_drive"),
    "chirp": ("steering_lag", "command_latency", "steering_rate_limit", "steering_play", "servo_rate_scale",
              "tyre_relaxation"),
    "reverse": ("esc_brake_reverse",),
    "random_steer": ("steering_lag", "command_latency", "steering_offset", "steering_play"),
}

HEADER = """\
nxpcup excitation plan (simrunner excite): one row per camera frame ({rate:g} Hz), {n} rows, {dur:.1f} s.
Columns: t (s from the start), speed_cmd (m/s, signed), steer_cmd (rad, bicycle-equivalent,
+ = left), coast (1 = drive off, wheels roll freely), segment (kind:detail); on turn rows
ref_x, ref_y (m), ref_yaw (rad): where the turn goes, in the plan frame (the start pose:
+x ahead, +y left).
Area: clear {area:g} x {area:g} m plus {margin:g} m on every side. Put the car at rest facing
+x (along the area's west-east side), {sx:.2f} m from the area's west edge and {sy:.2f} m from
its south edge (the nominal path spans {wx:.1f} x {wy:.1f} m).
Every frame k, at t_k: log t, x, y, yaw, speed and the commands you send; convert speed_cmd
with your speed normalisation (m/s -> motor command; coast = 1: motor driver off / ESC
neutral without drag brake) and steer_cmd with your servo normalisation (rad -> servo).
Turn rows: closed loop (recommended), steer to follow ref_x, ref_y with the pure-pursuit
code of docs/calibration.md from your measured pose, and go on with the row after the turn
once arrived (repeat the turn's last row until then); open loop, send them as they are.
Log format: docs/telemetry.md; see docs/calibration.md.
seed={seed}
area_centre_m={cx:.4f},{cy:.4f}
area_m={area:g}
margin_m={margin:g}"""

_COLUMNS = ("t", "speed_cmd", "steer_cmd", "coast", "segment", "ref_x", "ref_y", "ref_yaw")
_REF_COLUMNS = _COLUMNS[5:]
_DUTY_COLUMN = "duty_cmd"  # a duty-driven car's plan: the duty to send (speed_cmd: the speed it aims at)


class PlanError(SimError):
    """A plan CSV is malformed, or plan options are out of range."""


@dataclass(frozen=True, eq=False)
class ExcitationPlan:
    """A command schedule. Arrays are ``(N,)``: ``t_s`` from 0 at ``1 / rate_hz`` steps,
    ``speed_cmd_mps``, ``steer_cmd_rad``, ``coast`` (bool), ``segment`` (str), and the
    reference pose of the turns ``ref_x_m, ref_y_m, ref_yaw_rad`` (plan frame; NaN on other
    rows; ``None``: no turns to follow). ``area_centre_m`` is the middle of the square area
    of side ``area_m`` the plan was made for, in the plan frame (``None``: not known, e.g. a
    hand-made plan)."""

    t_s: np.ndarray
    speed_cmd_mps: np.ndarray
    steer_cmd_rad: np.ndarray
    coast: np.ndarray
    segment: tuple[str, ...]
    rate_hz: float = RATE_HZ
    seed: int = 0
    ref_x_m: np.ndarray | None = None
    ref_y_m: np.ndarray | None = None
    ref_yaw_rad: np.ndarray | None = None
    area_centre_m: tuple[float, float] | None = None
    area_m: float = AREA_M
    margin_m: float = AREA_MARGIN_M
    duty_cmd: np.ndarray | None = None  # a duty-driven car's plan: the duty of each row (duty_for_speed)

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def duration_s(self) -> float:
        return float(len(self.t_s)) / self.rate_hz

    def reference_rows(self) -> np.ndarray:
        """``(N,) bool``: the rows with a reference pose (the turns to follow closed loop)."""
        if self.ref_x_m is None:
            return np.zeros(len(self), dtype=bool)
        return np.isfinite(self.ref_x_m)

    def turns(self) -> list[tuple[int, int]]:
        """``[(first_row, end_row)]`` of every run of consecutive reference rows."""
        ref = self.reference_rows()
        edges = np.flatnonzero(np.diff(np.concatenate([[False], ref, [False]]).astype(int)))
        return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]

    def area_bounds_m(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of the area grown by ``margin_m``, plan frame."""
        if self.area_centre_m is None:
            raise PlanError("the plan does not say where its area is (no area_centre_m)")
        cx, cy = self.area_centre_m
        h = 0.5 * self.area_m + margin_m
        return cx - h, cx + h, cy - h, cy + h

    def outside_area_m(self, x_m: np.ndarray, y_m: np.ndarray) -> float:
        """How far the path ``(x_m, y_m)`` (``(N,)`` each, plan frame) gets outside the area
        (0.0: it stays inside)."""
        x0, x1, y0, y1 = self.area_bounds_m()
        return float(max(x0 - np.min(x_m), np.max(x_m) - x1, y0 - np.min(y_m), np.max(y_m) - y1, 0.0))

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
        :func:`predict_path` of the default car); it also places the area when the plan
        has no ``area_centre_m``."""
        path = Path(path)
        if extent is None:
            xy = predict_path(self, CarDescription())
            extent = (xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max())
        x0, x1, y0, y1 = extent
        cx, cy = self.area_centre_m if self.area_centre_m is not None else (0.5 * (x0 + x1), 0.5 * (y0 + y1))
        ref = self.reference_rows()
        head = HEADER.format(rate=self.rate_hz, n=len(self), dur=self.duration_s, area=self.area_m,
                             margin=self.margin_m, wx=x1 - x0, wy=y1 - y0, sx=0.5 * self.area_m - cx,
                             sy=0.5 * self.area_m - cy, seed=self.seed, cx=cx, cy=cy)
        lines = ["# " + ln for ln in head.splitlines()]
        duty = self.duty_cmd
        lines.append(",".join(_COLUMNS + ((_DUTY_COLUMN,) if duty is not None else ())))
        for k, (t, v, d, c, s) in enumerate(zip(self.t_s, self.speed_cmd_mps, self.steer_cmd_rad, self.coast,
                                                self.segment)):
            tail = f"{self.ref_x_m[k]:.4f},{self.ref_y_m[k]:.4f},{self.ref_yaw_rad[k]:.5f}" if ref[k] else ",,"
            lines.append(f"{t:.3f},{v:.6f},{d:.6f},{int(c)},{s},{tail}" + (f",{duty[k]:.6f}" if duty is not None else ""))
        try:
            write_atomic(path, "\n".join(lines) + "\n")
        except OSError as exc:
            raise PlanError(f"{path}: cannot write plan ({exc.strerror})") from None
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "ExcitationPlan":
        """Read a plan written by :meth:`to_csv` (``#`` lines are comments; ``coast``,
        ``segment`` and the three ``ref_*`` columns are optional; a row's reference is three
        numbers or three empty cells). Errors name the file and line."""
        path = Path(path)
        text = read_user_text(path, "plan", PlanError, "CSV")
        rows = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
        expect = f"expected t,speed_cmd,steer_cmd[,coast][,segment][,{','.join(_REF_COLUMNS)}]"
        if not rows:
            raise PlanError(f"{path}:1: empty plan, {expect}")
        hline, header = rows[0]
        cols = [c.strip() for c in next(csv.reader([header]))]
        for need in ("t", "speed_cmd", "steer_cmd"):
            if need not in cols:
                raise PlanError(f"{path}:{hline}: header lacks column '{need}' ({expect})")
        unknown = [c for c in cols if c not in _COLUMNS + (_DUTY_COLUMN,)]
        if unknown:
            raise PlanError(f"{path}:{hline}: unknown column '{unknown[0]}' ({expect})")
        has_ref = [c in cols for c in _REF_COLUMNS]
        if any(has_ref) and not all(has_ref):
            raise PlanError(f"{path}:{hline}: expected all of {','.join(_REF_COLUMNS)} or none")
        idx = {c: cols.index(c) for c in cols}
        t, v, d, co, seg, ref, du = [], [], [], [], [], [], []
        seed, centre, area, margin = 0, None, AREA_M, AREA_MARGIN_M
        for line_no, m in ((i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.startswith("#")):
            key, _, val = m[1:].strip().partition("=")
            if key in ("area_m", "margin_m"):
                try:
                    side = float(val)
                except ValueError:
                    side = math.nan
                if not (math.isfinite(side) and (side > 0.0 if key == "area_m" else side >= 0.0)):
                    raise PlanError(f"{path}:{line_no}: expected {key}= a {'positive' if key == 'area_m' else 'non-negative'} "
                                    f"number of metres (got {val.strip()!r})")
            try:
                if key == "seed":
                    seed = int(val)
                elif key == "area_centre_m":
                    cx, cy = (float(p) for p in val.split(","))
                    centre = (cx, cy) if math.isfinite(cx) and math.isfinite(cy) else None
                elif key == "area_m":
                    area = float(val)
                elif key == "margin_m":
                    margin = float(val)
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
            if _DUTY_COLUMN in idx:
                try:
                    duty = float(vals[idx[_DUTY_COLUMN]])
                except ValueError:
                    duty = math.nan
                if not -1.0 <= duty <= 1.0:
                    raise PlanError(f"{path}:{line_no}: expected a duty_cmd in -1..1")
                du.append(duty)
            t.append(tv), v.append(vv), d.append(dv), co.append(bool(cv))
            seg.append(vals[idx["segment"]].strip() if "segment" in idx else "")
            if all(has_ref):
                ref.append(_read_reference([vals[idx[c]].strip() for c in _REF_COLUMNS], f"{path}:{line_no}"))
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
        r = np.array(ref, dtype=float).reshape(-1, 3).T if ref else (None, None, None)
        return cls(np.arange(len(t)) / rate, np.array(v), np.array(d), np.array(co, dtype=bool), tuple(seg),
                   rate_hz=rate, seed=seed, ref_x_m=r[0], ref_y_m=r[1], ref_yaw_rad=r[2], area_centre_m=centre,
                   area_m=area, margin_m=margin, duty_cmd=np.array(du) if du else None)


def _read_reference(cells: list[str], where: str) -> tuple[float, float, float]:
    if not any(cells):
        return (math.nan, math.nan, math.nan)
    names = ",".join(_REF_COLUMNS)
    try:
        x, y, yaw = (float(c) for c in cells)
    except ValueError:
        raise PlanError(f"{where}: expected three numbers in {names} or three empty cells") from None
    if not all(math.isfinite(a) for a in (x, y, yaw)):
        raise PlanError(f"{where}: expected finite numbers in {names}")
    return x, y, yaw


def segment_kind(segment: str) -> str:
    """``"step_steer:+0.10"`` -> ``"step_steer"``."""
    return segment.split(":", 1)[0]


# -- steering by pure pursuit ------------------------------------------------------------
def pursuit_steer_rad(dx_m, dy_m, yaw_rad, *, wheelbase_m: float, steer_max_rad: float):
    """Pure pursuit from the rear-axle midpoint heading ``yaw_rad`` towards an aim point
    ``(dx_m, dy_m)`` away (world axes): ``atan(2 L sin(alpha) / RETURN_LOOKAHEAD_M)``
    (``alpha``: bearing of the aim point from the heading, ``L``: ``wheelbase_m``; the arc
    through a point ``RETURN_LOOKAHEAD_M`` away in that direction, so a far aim point is
    turned to as sharply as a near one), full ``steer_max_rad`` towards it when it is behind
    (``|alpha|`` > 90 degrees), clamped to ``+-steer_max_rad``. Floats or arrays."""
    alpha = (np.arctan2(dy_m, dx_m) - yaw_rad + math.pi) % (2.0 * math.pi) - math.pi
    steer = np.arctan(2.0 * wheelbase_m * np.sin(alpha) / RETURN_LOOKAHEAD_M)
    steer = np.where(np.abs(alpha) > 0.5 * math.pi, np.copysign(steer_max_rad, alpha), steer)
    return np.clip(steer, -steer_max_rad, steer_max_rad)


@dataclass(frozen=True)
class FollowStep:
    """One step of :func:`follow_path`: the steering to send, the progress to pass next
    time, and whether the car has arrived at the path's end (then the plan goes on with the
    row after the turn, in this frame)."""

    steer_cmd_rad: float
    progress: int
    arrived: bool


def follow_path(x_m: float, y_m: float, yaw_rad: float, path_xy: np.ndarray, end_yaw_rad: float, progress: int,
                min_progress: int, *, wheelbase_m: float, steer_max_rad: float) -> FollowStep:
    """Closed-loop turn: follow the reference path ``path_xy`` ``(M, 2)`` (a turn's
    ``ref_x, ref_y``, one point per row, same frame as the pose) from the measured pose
    ``(x_m, y_m, yaw_rad)`` (rear-axle midpoint). ``progress``: the index returned last
    time (0 at the turn's first row); ``min_progress``: ``RETURN_PACE`` x (frames since the
    turn began - ``RETURN_LAG_S`` x the frame rate).

    1. progress = the path point nearest the car among those from ``max(progress,
       min_progress)`` on up to ``RETURN_WINDOW_M`` further along the path. It only moves
       on along the path, so a car that ended its experiment elsewhere joins the path at
       its start and follows it in order; and at no less than ``RETURN_PACE`` of the plan's
       pace, so a car that cannot get onto the path where it is (it would circle round it)
       is led on along it;
    2. aim = the first path point from there, before the last, at least
       ``RETURN_LOOKAHEAD_M`` from the car; if there is none (the car is near the end), the
       point ``RETURN_LOOKAHEAD_M`` ahead of the car's projection on the end line (through
       the last point in the end heading ``end_yaw_rad``: the path ends on it); the car has
       arrived once it is level with or past the last point (along that heading), less than
       ``RETURN_ARRIVED_M`` off the end line, heading within 45 degrees of it (a car that
       comes to the end line late starts the experiment further on: better than a loop);
    3. steer by :func:`pursuit_steer_rad` towards the aim, at most ``steer_max_rad``.

    The same in C: docs/calibration.md."""
    last = len(path_xy) - 1
    progress = min(last, max(progress, min_progress))
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path_xy[progress:], axis=0).T))])
    win = path_xy[progress:progress + int(np.searchsorted(along, RETURN_WINDOW_M, side="right"))]
    progress += int(np.argmin(np.hypot(win[:, 0] - x_m, win[:, 1] - y_m)))
    ahead = np.hypot(path_xy[progress:last, 0] - x_m, path_xy[progress:last, 1] - y_m) >= RETURN_LOOKAHEAD_M
    c, s = math.cos(end_yaw_rad), math.sin(end_yaw_rad)
    if ahead.any():
        ax, ay = path_xy[progress + int(np.argmax(ahead))]
        arrived = False
    else:
        ex, ey = path_xy[last]
        past, cross = c * (x_m - ex) + s * (y_m - ey), -s * (x_m - ex) + c * (y_m - ey)
        ax, ay = ex + (past + RETURN_LOOKAHEAD_M) * c, ey + (past + RETURN_LOOKAHEAD_M) * s
        aligned = abs(wrap_angle(yaw_rad - end_yaw_rad)) < 0.25 * math.pi
        arrived = past >= 0.0 and abs(cross) < RETURN_ARRIVED_M and aligned
    steer = float(pursuit_steer_rad(ax - x_m, ay - y_m, yaw_rad, wheelbase_m=wheelbase_m, steer_max_rad=steer_max_rad))
    return FollowStep(steer, progress, bool(arrived))


# -- the planner's turns: Dubins paths (trackgen.dubins) -------------------------------------


# -- prediction ------------------------------------------------------------------------------
def design_envelope() -> np.ndarray:
    """``(27, 3)``: ``(steering_offset_rad, steering_gain, speed_scale)`` of the cars the
    planner keeps inside the area: every combination of -, 0, + each design error."""
    return np.array(list(itertools.product((-DESIGN_TRIM_RAD, 0.0, DESIGN_TRIM_RAD),
                                           (1.0 - DESIGN_GAIN_ERROR, 1.0, 1.0 + DESIGN_GAIN_ERROR),
                                           (1.0 - DESIGN_SPEED_ERROR, 1.0, 1.0 + DESIGN_SPEED_ERROR))))


_NOMINAL = np.array([[0.0, 1.0, 1.0]])


class _Kinematic:
    """Kinematic bicycle with the car's steering limit and rate and its accel and brake
    limits, for ``S`` cars at once (state arrays ``(S,)``); ``cars`` ``(S, 3)`` as
    :func:`design_envelope` (offset, gain and speed scale act like the effects of the same
    names; ``(1, 3)`` nominal: the plain car)."""

    def __init__(self, car: CarDescription, dt_s: float, cars: np.ndarray = _NOMINAL):
        self.dt = dt_s
        self.lim = car.steering.limit_rad
        self.ds = car.steering.rate_radps * dt_s
        self.acc, self.brk = car.drive.max_accel_mps2 * dt_s, car.drive.max_brake_mps2 * dt_s
        self.wb = car.chassis.wheelbase_m
        self.off, self.gain, self.vscale = (np.array(col, dtype=float) for col in np.asarray(cars, dtype=float).T)
        n = len(self.off)
        self.x, self.y, self.yaw, self.v, self.steer = (np.zeros(n) for _ in range(5))

    def step(self, speed, steer, coast: bool) -> None:
        """One frame of the commands ``speed`` (m/s), ``steer`` (rad): floats or ``(S,)``."""
        target = np.clip(self.gain * steer + self.off, -self.lim, self.lim)
        self.steer = self.steer + np.clip(target - self.steer, -self.ds, self.ds)
        if not coast:
            vt = self.vscale * speed
            a = np.where(np.abs(vt) > np.abs(self.v), self.acc, self.brk)
            self.v = self.v + np.clip(vt - self.v, -a, a)
        self.yaw = self.yaw + self.v * np.tan(self.steer) / self.wb * self.dt
        self.x = self.x + self.v * np.cos(self.yaw) * self.dt
        self.y = self.y + self.v * np.sin(self.yaw) * self.dt


# -- building ----------------------------------------------------------------------------
class _Builder:
    """Appends command rows while predicting them on ``cars`` (:class:`_Kinematic`); the
    plan's builder predicts the nominal car, probes predict the design envelope."""

    def __init__(self, car: CarDescription, rate_hz: float, cars: np.ndarray = _NOMINAL,
                 centre_xy: tuple[float, float] = (0.0, 0.0), area_m: float = AREA_M):
        self.car = car
        self.rate_hz = rate_hz
        self.dt = 1.0 / rate_hz
        self.kin = _Kinematic(car, self.dt, cars)
        self.cx, self.cy = centre_xy
        self.area_m = area_m
        self.out_m = 0.0  # the farthest the chosen turns and experiments' envelope get out of the area
        self.rows: list[tuple[float, float, bool, str, tuple[float, float, float] | None]] = []
        self.xy: list[tuple[np.ndarray, np.ndarray]] = [(self.kin.x, self.kin.y)]

    @property
    def steer_max(self) -> float:
        return RETURN_STEER_FRACTION * self.car.steering.limit_rad

    def emit(self, speed: float, steer: float, segment: str, coast: bool = False, ref: bool = False) -> None:
        """One row; ``ref``: record the (first) car's pose at the row as its reference."""
        pose = (float(self.kin.x[0]), float(self.kin.y[0]), float(wrap_angle(self.kin.yaw[0]))) if ref else None
        self.rows.append((float(speed), float(steer), bool(coast), segment, pose))
        self.kin.step(float(speed), float(steer), bool(coast))
        self.xy.append((self.kin.x, self.kin.y))

    def hold(self, seconds: float, speed: float, steer: float, segment: str, coast: bool = False) -> None:
        for _ in range(max(1, round(seconds / self.dt))):
            self.emit(speed, steer, segment, coast)

    def ramp(self, seconds: float, v0: float, v1: float, steer: float, segment: str) -> None:
        n = max(1, round(seconds / self.dt))
        for k in range(n):
            self.emit(v0 + (v1 - v0) * (k + 1) / n, steer, segment)

    def path(self) -> np.ndarray:
        """``(F, S, 2)``: every predicted point so far (F frames, S cars)."""
        return np.stack([np.array([p[0] for p in self.xy]), np.array([p[1] for p in self.xy])], 2)

    def probe(self, experiment, speed: float, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """``(nominal (F, 2), envelope (M, 2))``: the paths of ``experiment(builder)``
        started at the origin heading +x at ``speed`` (as commanded: each car at its own
        scale) of the nominal car and of the design envelope, every ``every``-th frame and
        the last; the envelope's with each car's room to turn afterwards: the arcs of a
        quarter turn left and right at ``steer_max`` from its last pose, on the radius of the
        envelope's widest-turning car (a dry run: nothing is emitted here)."""
        p = _Builder(self.car, self.rate_hz, design_envelope())
        p.kin.v = p.kin.vscale * speed
        experiment(p)
        path = p.path()
        steer = (1.0 - DESIGN_GAIN_ERROR) * self.steer_max - DESIGN_TRIM_RAD
        radius = self.car.chassis.wheelbase_m / math.tan(steer)
        th = np.radians(np.arange(15.0, 91.0, 15.0))
        fwd, side = radius * np.sin(th), radius * (1.0 - np.cos(th))
        c, s = np.cos(p.kin.yaw)[:, None], np.sin(p.kin.yaw)[:, None]
        arcs = [np.stack([p.kin.x[:, None] + c * fwd - s * sgn * side, p.kin.y[:, None] + s * fwd + c * sgn * side], 2)
                for sgn in (1.0, -1.0)]
        nominal = int(np.flatnonzero((design_envelope() == _NOMINAL).all(1))[0])
        keep = np.concatenate([path[::every], path[-1:]])
        return keep[:, nominal], np.concatenate([keep.reshape(-1, 2), *[a.reshape(-1, 2) for a in arcs]])

    def return_then(self, experiment, speed: float) -> None:
        """A ``turn`` at ``speed`` to the pose where ``experiment`` starts, then the
        experiment. Candidate start poses: 24 headings (15 degrees apart), each with the
        start point that centres the envelope's paths of the experiment (:meth:`probe`) in
        the area, moved -1.5 .. 1.5 m along the heading and -0.5 .. 0.5 m across. The turn to
        a candidate is a Dubins path (:func:`trackgen.dubins.dubins_segments`; arcs at ``_ARC_FRACTION`` of the turn
        steering) to ``_RUN_IN_M`` before the start, then straight to it. Chosen: the turn
        and start whose nominal path stays ``_PLAN_MARGIN_M`` inside the area, whose
        envelope reaches least far out of the area, then the shortest and most compact
        (costs in :data:`_COST`)."""
        nom, pts = self.probe(experiment, speed, every=3)
        psi = np.radians(15.0 * np.arange(24))
        c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
        rx, ry = c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]  # (24, M)
        sx = self.cx - 0.5 * (rx.min(1) + rx.max(1))
        sy = self.cy - 0.5 * (ry.min(1) + ry.max(1))
        da, dc = (a.ravel() for a in np.meshgrid(np.linspace(-1.5, 1.5, 7), np.linspace(-0.5, 0.5, 3)))
        tx = (sx[:, None] + da * c - dc * s).ravel()
        ty = (sy[:, None] + da * s + dc * c).ravel()
        tyaw = np.repeat(psi, len(da))
        ct, st = np.cos(tyaw)[:, None], np.sin(tyaw)[:, None]

        def reach_of(p):  # (C,): farthest Chebyshev distance of p (M, 2) started at the candidates
            wx = tx[:, None] + ct * p[:, 0] - st * p[:, 1] - self.cx
            wy = ty[:, None] + st * p[:, 0] + ct * p[:, 1] - self.cy
            return np.maximum(np.abs(wx), np.abs(wy)).max(1)

        k = self.kin
        x0, y0, yaw0 = float(k.x[0]), float(k.y[0]), float(k.yaw[0])
        radius = self.car.chassis.wheelbase_m / math.tan(_ARC_FRACTION * self.steer_max)
        segs = dubins_segments(x0, y0, yaw0, tx - _RUN_IN_M * ct[:, 0], ty - _RUN_IN_M * st[:, 0], tyaw, radius)
        length = radius * segs.sum(-1) + _RUN_IN_M  # (6, C)
        way = dubins_points(x0, y0, yaw0, np.nan_to_num(segs), radius)
        reach_turn = np.maximum(np.abs(way[..., 0] - self.cx), np.abs(way[..., 1] - self.cy)).max(-1)
        reach = np.maximum(reach_turn, reach_of(nom))  # (6, C) nominal
        over = np.maximum(np.maximum(reach, reach_of(pts)) - 0.5 * self.area_m, 0.0)
        inside = np.maximum(reach - (0.5 * self.area_m - _PLAN_MARGIN_M), 0.0)
        cost = (_COST["out_m"] * over + _COST["margin_m"] * inside + _COST["reach_m"] * reach
                + _COST["turn_s"] * length / speed)
        best_w, best_c = np.unravel_index(int(np.argmin(np.where(np.isfinite(length), cost, np.inf))), cost.shape)
        self.out_m = max(self.out_m, float(over[best_w, best_c]))
        bounds = np.cumsum(np.append(radius * segs[best_w, best_c], _RUN_IN_M))
        signs = [TURN_SIGN[ch] for ch in WORDS[best_w]] + [0.0]
        steer_arc = _ARC_FRACTION * self.steer_max
        done = 0.0  # distance driven: the steering follows the path's segments by distance
        for _ in range(round(60.0 / self.dt)):
            if done >= bounds[-1] - 1e-9:
                break
            j = int(np.searchsorted(bounds, done, side="right"))
            x_before, y_before = float(k.x[0]), float(k.y[0])
            self.emit(speed, signs[min(j, 3)] * steer_arc, "turn:return", ref=True)
            done += math.hypot(float(k.x[0]) - x_before, float(k.y[0]) - y_before)
        experiment(self)


# weights of the planner's choice of turns (_Builder.return_then): per metre the nominal car or
# the envelope (with room to turn afterwards) gets out of the area, per metre the nominal car
# comes closer than _PLAN_MARGIN_M to the edge, per metre of its farthest reach, per second of turn
_COST = {"out_m": 1000.0, "margin_m": 50.0, "reach_m": 0.1, "turn_s": 0.2}


def make_plan(car: CarDescription | None = None, *, seed: int = 0, rate_hz: float = RATE_HZ,
              duration_s: float | None = None, area_m: float | None = None) -> ExcitationPlan:
    """The excitation plan for ``car`` (about 90 s; docs/calibration.md lists the segments).

    Speeds and steering amplitudes follow the car's limits (``drive.max_speed_mps``,
    ``steering.limit_rad``, ``wheels.friction_mu``). ``seed`` drives only the
    ``random_steer`` steps (``numpy.random.default_rng(seed)``). ``duration_s`` (at least
    ``MIN_DURATION_S``) appends more random-steer blocks (each a turn, 3 to 4.5 s of steps
    and a stop) and a longer final pause until the plan lasts that long (a few seconds
    more if the last turn is long); ``None`` gives the core plan.

    ``area_m``: the side of the square area to plan for. The plan *fits* it when the turns
    and the design envelope of every experiment as planned (``_Builder.out_m``) and the
    nominal car's predicted path of the whole plan (:func:`predict_path`: the turns driven
    with the steering's rate limit) stay inside; the
    turns of a car with a wide turning circle (a 1:10 car's) do not fit the default
    ``AREA_M``. ``None``: the smallest side from ``AREA_M`` up, in ``AREA_STEP_M`` steps,
    that fits (``ExcitationPlan.area_m`` says which). A given side that does not fit is a
    :class:`PlanError` naming the smallest that does. The same arguments give the same plan.
    """
    car = car or CarDescription()
    if car.drive.command == "duty":  # planned as its speed-commanded twin, the speeds sent as duties
        import dataclasses as _dc

        twin = car.replace(drive=_dc.replace(car.drive, command="speed"))
        plan = make_plan(twin, seed=seed, rate_hz=rate_hz, duration_s=duration_s, area_m=area_m)
        return _dc.replace(plan, duty_cmd=duty_for_speed(car, plan.speed_cmd_mps))
    if not (5.0 <= rate_hz <= 1000.0):
        raise PlanError(f"rate_hz = {rate_hz!r}: expected 5 .. 1000")
    if duration_s is not None and not (MIN_DURATION_S <= duration_s <= MAX_DURATION_S):
        raise PlanError(f"duration = {duration_s!r} s: expected {MIN_DURATION_S:g} .. {MAX_DURATION_S:g} s "
                        f"(the core plan needs about {MIN_DURATION_S:g} s)")
    if area_m is not None and not (AREA_M <= area_m <= AREA_MAX_M):
        raise PlanError(f"area = {area_m:g} m: expected {AREA_M:g} .. {AREA_MAX_M:g} m")
    sides = [AREA_M + AREA_STEP_M * k for k in range(int(round((AREA_MAX_M - AREA_M) / AREA_STEP_M)) + 1)]
    first = area_m if area_m is not None else AREA_M
    plan, out_m = _plan_in(car, seed, rate_hz, duration_s, first)
    if out_m == 0.0:
        return plan
    for side in (x for x in sides if x > first + 1e-9):
        bigger, out_big = _plan_in(car, seed, rate_hz, duration_s, side)
        if out_big == 0.0:
            if area_m is None:
                return bigger
            raise PlanError(f"area = {area_m:g} m: this car's plan does not fit it (its turns or an experiment's "
                            f"off-nominal cars get up to {out_m:.2f} m out); the smallest area it fits: "
                            f"{side:g} x {side:g} m")
    raise PlanError(f"this car's plan fits no area up to {AREA_MAX_M:g} x {AREA_MAX_M:g} m (at "
                    f"{first:g} m its turns or an experiment's off-nominal cars get up to {out_m:.2f} m out): "
                    "check the car file's wheelbase and steering limit")


def duty_for_speed(car: CarDescription, speed_mps: np.ndarray) -> np.ndarray:
    """The duty that holds a duty-driven car at ``speed_mps``, in -1..1: the steady state of
    the motor model (docs/drive.md), ``2 (c1 d - c2 v) = F_rr + k v^2`` for a brake H-bridge,
    ``2 (c1 - c2 v) d = F_rr + k v^2`` for a coasting one (which needs the car file's rolling
    resistance or drag: without losses it reaches its top speed at any duty)."""
    from simrunner.workflows.calibration.duty import motor_of

    mo = motor_of(car)
    v = np.asarray(speed_mps, dtype=float)
    losses = mo.rolling_n * np.sign(v) + mo.drag * v * np.abs(v)
    if mo.brake:
        return np.clip((2.0 * mo.c2 * v + losses) / (2.0 * mo.c1), -1.0, 1.0)
    if mo.rolling_n <= 0.0 and mo.drag <= 0.0:
        raise PlanError("a coasting H-bridge (drive.hbridge = coast) with no rolling resistance or drag in the car "
                        "file reaches its top speed at any duty, so no duty holds a planned speed: measure them "
                        "(simrunner calibrate [duty], the coast-down) or plan for hbridge = brake")
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(np.abs(v) < mo.c1 / mo.c2, losses / (2.0 * (mo.c1 - mo.c2 * np.abs(v))), np.sign(v))
    return np.clip(d, -1.0, 1.0)


def turn_radius_m(car: CarDescription) -> float:
    """Radius of the planned turns' arcs: ``_ARC_FRACTION`` of the most a planned turn
    steers (``RETURN_STEER_FRACTION`` of the steering limit), kinematic."""
    return car.chassis.wheelbase_m / math.tan(_ARC_FRACTION * RETURN_STEER_FRACTION * car.steering.limit_rad)


def area_margin_m(car: CarDescription) -> float:
    """How far outside the area a car of the design envelope may get, closed loop:
    ``AREA_MARGIN_M`` (measured on the default car) scaled by the car's
    :func:`turn_radius_m` over the default car's, never less. An off-nominal car drifts off
    a turn's path in proportion to the arcs it cannot quite steer (docs/calibration.md:
    measured on two 1:10 cars, whose arcs are 1.8 times the default car's, 0.61 and 0.65 m)."""
    return round(AREA_MARGIN_M * max(1.0, turn_radius_m(car) / turn_radius_m(CarDescription())), 2)


def _plan_in(car: CarDescription, seed: int, rate_hz: float, duration_s: float | None,
             area_m: float) -> tuple[ExcitationPlan, float]:
    """The plan of :func:`make_plan` for an area of side ``area_m``, and how far its turns
    and the experiments' design envelope as planned, or the nominal car's predicted path,
    get out of that area (0.0: it fits)."""
    rng = np.random.default_rng(seed)
    lim, vmax = car.steering.limit_rad, car.drive.max_speed_mps
    wb, mu = car.chassis.wheelbase_m, car.wheels.friction_mu
    v_lo, v_mid = min(0.8, 0.5 * vmax), min(1.2, 0.6 * vmax)
    v_fast = min(2.0, 0.8 * vmax)

    # 1. from rest: slow ramp (deadband: when does it start to roll?), then straight (offset);
    #    the area's middle is the middle of this run's envelope
    def first_run(p):
        p.hold(1.0, 0.0, 0.0, "pause:start")
        p.ramp(2.5, 0.0, v_mid, 0.0, f"speed_ramp:0-{v_mid:.1f}")
        p.hold(1.0, v_mid, 0.0, f"straight:{v_mid:.1f}")

    _, probe = _Builder(car, rate_hz).probe(first_run, 0.0)
    b = _Builder(car, rate_hz, centre_xy=(0.5 * (probe[:, 0].min() + probe[:, 0].max()),
                                          0.5 * (probe[:, 1].min() + probe[:, 1].max())), area_m=area_m)
    first_run(b)

    # 2. step steers left and right, small and medium amplitude (offset, gain, lag, latency)
    def steps(frac):
        def run(p):
            a = frac * lim
            p.hold(0.4, v_mid, 0.0, f"straight:{v_mid:.1f}")
            for sign, secs in ((1, 0.5), (-1, 1.0), (1, 0.5)):
                p.hold(secs, v_mid, sign * a, f"step_steer:{sign * a:+.2f}")
            p.hold(0.4, v_mid, 0.0, f"straight:{v_mid:.1f}")
        return run

    b.return_then(steps(0.25), v_lo)
    b.return_then(steps(0.5), v_lo)

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

    b.return_then(circles(1), v_lo)
    b.return_then(circles(-1), v_lo)

    # 4. speed steps (latency, motor lag), then brake to rest
    v_step = min(1.6, 0.7 * vmax)

    def speed_steps(p):
        p.hold(0.3, v_lo, 0.0, "straight:settle")
        for v in (v_step, v_lo, v_step, 0.3):
            p.hold(0.7, v, 0.0, f"speed_step:{v:.1f}")
        p.hold(0.6, 0.0, 0.0, "brake:0")
        p.hold(0.5, 0.0, 0.0, "pause:rest")

    b.return_then(speed_steps, v_lo)

    # 5. coast-down from speed (rolling resistance, drag), then brake to rest
    def coast(p):
        p.hold(0.7, v_fast, 0.0, f"straight:{v_fast:.1f}")
        p.hold(1.0, 0.0, 0.0, f"coast:{v_fast:.1f}", coast=True)
        p.hold(0.8, 0.0, 0.0, "brake:0")
        p.hold(0.5, 0.0, 0.0, "pause:rest")

    b.return_then(coast, v_lo)

    # 6. steering chirp 0.3 -> 2.5 Hz (lag, latency, rate limit)
    f0, f1, amp, v_chirp = 0.3, 2.5, 0.3 * lim, min(0.6, v_lo)

    def chirp(p):
        p.hold(0.3, v_chirp, 0.0, "straight:settle")
        n, phase = round(5.0 * rate_hz), 0.0
        for k in range(n):
            phase += 2.0 * math.pi * (f0 + (f1 - f0) * k / n) / rate_hz
            p.emit(v_chirp, amp * math.sin(phase), f"chirp:{f0:g}-{f1:g}Hz")

    b.return_then(chirp, v_lo)

    # 7. slow circles at full lock, left then right (the steering limit: steer_limit_scale)
    v_lock = min(0.5, 0.4 * vmax)

    def full_lock(p):
        p.hold(0.3, v_lock, 0.0, "straight:settle")
        p.hold(2.5, v_lock, lim, f"circle:left@{v_lock:.1f}/lock")
        p.hold(2.5, v_lock, -lim, f"circle:right@{v_lock:.1f}/lock")

    b.return_then(full_lock, v_lo)

    # 8. reverse: rolling forward, a negative speed command (an ESC with brake brakes, waits
    #    at rest, then reverses), then forward again; twice (the gap workflow fits one and
    #    holds the other out to confirm it); brake to rest
    v_rev = min(0.6, 0.4 * vmax)

    def reverse(p):
        p.hold(0.5, v_lo, 0.0, f"straight:{v_lo:.1f}")
        for _ in range(2):
            p.hold(2.2, -v_rev, 0.0, f"reverse:-{v_rev:.1f}")
            p.hold(1.0, v_lo, 0.0, f"reverse:+{v_lo:.1f}")
        p.hold(0.6, 0.0, 0.0, "brake:0")
        p.hold(0.3, 0.0, 0.0, "pause:rest")

    b.return_then(reverse, v_lo)

    # 9. random steering steps (seeded): holds 0.15-0.5 s, amplitudes up to half the limit;
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

    block_s, overhead_s = 3.0, 5.5  # random steps; turn (~3.5 s), settle, coast, brake and pause
    while True:
        t_left = 0.0 if duration_s is None else duration_s - len(b.rows) * b.dt
        last = t_left < 2.0 * (block_s + overhead_s)
        seconds = min(max(t_left - overhead_s, block_s), 1.5 * block_s) if last and duration_s else block_s
        b.return_then(random_block(seconds, last), v_lo)
        if last:
            break
    if duration_s is not None and duration_s - len(b.rows) * b.dt > b.dt:  # the rest: a longer pause at the end
        b.hold(duration_s - len(b.rows) * b.dt, 0.0, 0.0, "pause:end")

    rows = b.rows
    ref = np.array([r[4] if r[4] is not None else (math.nan,) * 3 for r in rows], dtype=float)
    plan = ExcitationPlan(np.arange(len(rows)) / rate_hz, np.array([r[0] for r in rows]),
                          np.array([r[1] for r in rows]), np.array([r[2] for r in rows], dtype=bool),
                          tuple(r[3] for r in rows), rate_hz=float(rate_hz), seed=int(seed),
                          ref_x_m=ref[:, 0], ref_y_m=ref[:, 1], ref_yaw_rad=ref[:, 2],
                          area_centre_m=(float(b.cx), float(b.cy)), area_m=float(area_m),
                          margin_m=area_margin_m(car))
    xy = predict_path(plan, car)
    return plan, max(b.out_m, plan.outside_area_m(xy[:, 0], xy[:, 1]))


def predict_path(plan: ExcitationPlan, car: CarDescription) -> np.ndarray:
    """``(N + 1, 2)`` kinematic prediction of the open-loop path (nominal car, from the
    origin facing +x)."""
    b = _Builder(car, plan.rate_hz)
    for v, d, c in zip(plan.speed_cmd_mps, plan.steer_cmd_rad, plan.coast):
        b.emit(float(v), float(d), "", bool(c))
    return b.path()[:, 0]


# -- simulating ----------------------------------------------------------------------------
def run_plan(plan: ExcitationPlan, car: CarDescription, *, dt_s: float = 0.002, seed: int = 0,
             start: Pose2 = Pose2(), pose_noise_m: float = 0.0, closed_loop: bool = False,
             sim_factory: Callable[..., Any] | None = None,
             dead_reckoning: DeadReckoning | None = None) -> RunLog:
    """Play ``plan`` in the simulator (``simrunner.car.effects.make_sim``: effects apply).

    Each row's command is set at ``t_k`` and the state logged at ``t_k`` (before the
    frame's physics steps), like the telemetry of ``simrunner drive``. Returns a
    :class:`~simrunner.telemetry.log.RunLog` (source ``"<excite>"``) with ``frame`` (the frame
    index), ``t_s``, the pose ``x_m, y_m, yaw_rad``, the actual ``speed_mps, steer_rad,
    yaw_rate_radps``, the commands sent ``speed_cmd_mps, steer_cmd_rad``, the differential
    in force ``yaw_rate_cmd_radps``, and ``coast``; no ``lap`` or ``off_track`` (there is
    no track). ``pose_noise_m`` > 0 adds Gaussian noise of that std to x and y (std / 0.2 m
    per rad to yaw) from ``numpy.random.default_rng(seed)``, to mimic a real position log;
    0 gives the exact simulated pose (``seed`` then has no effect). ``start`` is where the
    plan frame's origin is in the world. ``sim_factory(car, dt_s=, start=)`` builds the
    simulator instead of ``make_sim`` (anything with the ``CarSim`` interface: a car with
    something the catalogue does not model, for the gap bench).

    Open loop (default) the log has one row per plan row, at the plan's times.
    ``closed_loop``: the car drives the turns as docs/calibration.md tells a team to: it
    steers to follow each turn's reference path (:func:`follow_path`) from the logged
    (noisy) pose, as a real car from its measured one; once it has arrived at the path's
    end the plan goes on with the row after the turn (skipping the turn's remaining rows),
    and until then the turn's last row is repeated (at most ``RETURN_TIMEOUT_S``). So the
    log's length differs from the plan's; it holds the commands sent. A plan without
    reference rows cannot be played closed loop (:class:`PlanError`).

    ``dead_reckoning`` (closed loop): the car steers from a pose it integrates itself from
    its wheel speed and gyro (:class:`DeadReckoning`: their errors), as a team without a
    camera or motion capture does; the log still holds the simulated (noisy) pose, where
    the car really went.
    """
    from simrunner.car.effects import make_sim

    duty = car.drive.command == "duty"
    if duty and plan.duty_cmd is None:
        raise PlanError("the car is driven by duty (drive.command = duty) and the plan has no duty_cmd column: "
                        "make the plan for this car (simrunner excite --car CAR.toml)")
    steps = plan_steps_per_row(plan, dt_s)
    n = len(plan)
    turns = plan.turns() if closed_loop else []
    if closed_loop and not turns:
        raise PlanError("the plan has no turns to follow closed loop (no ref_x, ref_y, ref_yaw rows)")
    turn_of = np.full(n, -1)  # per row: index into turns
    paths = []  # per turn: the reference path in the world, its end heading, its end row
    for i, (a, b) in enumerate(turns):
        turn_of[a:b] = i
        paths.append((start.apply(np.stack([plan.ref_x_m[a:b], plan.ref_y_m[a:b]], 1)),
                      float(plan.ref_yaw_rad[b - 1]) + start.yaw_rad, b))
    rng = np.random.default_rng(seed) if pose_noise_m > 0.0 else None
    noise_std = np.array([pose_noise_m, pose_noise_m, pose_noise_m / 0.2])
    noise = np.zeros((3, n))  # open loop: drawn in advance (x for all rows, then y, then yaw)
    if rng is not None and not turns:
        noise = np.stack([rng.normal(0.0, sd, n) for sd in noise_std])
    sim = (sim_factory or make_sim)(car, dt_s=dt_s, start=start)
    wb, steer_max = car.chassis.wheelbase_m, FOLLOW_STEER_FRACTION * car.steering.limit_rad
    max_extra = round(RETURN_TIMEOUT_S * plan.rate_hz)
    rows: list[tuple] = []  # row, x, y, yaw, speed, steer, yaw_rate, yaw_rate_cmd, speed_cmd, steer_cmd
    coast_now = False
    k, turn, progress, extra, turn_frames = 0, -1, 0, 0, 0
    row_s = 1.0 / plan.rate_hz
    dr = (start.x_m, start.y_m, start.yaw_rad)  # the dead-reckoned pose (world frame)
    while k < n:
        p = sim.pose
        e = rng.normal(0.0, noise_std) if turns and rng is not None else noise[:, min(k, n - 1)]
        x, y, yaw = p.x_m + e[0], p.y_m + e[1], p.yaw_rad
        if rng is not None:
            yaw = wrap_angle(yaw + e[2])
        logged = (x, y, yaw)
        if dead_reckoning is not None and turns:
            x, y, yaw = dr
        while k < n and turn_of[k] >= 0:  # a turn row: follow the turn's path, or skip the rest of it
            if turn_of[k] != turn:
                turn, progress, extra, turn_frames = int(turn_of[k]), 0, 0, 0
            path_xy, end_yaw, end = paths[turn]
            min_progress = int(RETURN_PACE * (turn_frames - RETURN_LAG_S * plan.rate_hz))
            step = follow_path(x, y, yaw, path_xy, end_yaw, progress, min_progress, wheelbase_m=wb,
                               steer_max_rad=steer_max)
            progress = step.progress
            if not step.arrived:
                break
            k = end
        if k == n:
            break
        v, d, c = float(plan.speed_cmd_mps[k]), float(plan.steer_cmd_rad[k]), bool(plan.coast[k])
        if turn_of[k] >= 0:
            d = step.steer_cmd_rad
            turn_frames += 1
        if c != coast_now:
            sim.set_coast(c)
            coast_now = c
        sim.set_command(float(plan.duty_cmd[k]) if duty else v, d)
        rows.append((k, *logged, sim.speed_mps, sim.steer_rad, sim.yaw_rate_radps, sim.yaw_rate_cmd_radps, v, d))
        sim.step(steps)
        if dead_reckoning is not None:  # this frame's wheel speed and gyro, as the car reads them after it
            dr = dead_reckoning.advance(dr, sim.speed_mps, sim.yaw_rate_radps, row_s)
        if turn_of[k] < 0:
            k += 1
        elif k + 1 == end and extra < max_extra:
            extra += 1
        else:
            k += 1
    state = np.array(rows, dtype=float)
    row = state[:, 0].astype(int)
    m = len(rows)
    return log_from_columns({"frame": np.arange(m), "t_s": np.arange(m) / plan.rate_hz if turns else plan.t_s,
                             "x_m": state[:, 1], "y_m": state[:, 2], "yaw_rad": state[:, 3],
                             "speed_mps": state[:, 4], "steer_rad": state[:, 5], "yaw_rate_radps": state[:, 6],
                             "speed_cmd_mps": state[:, 8], "steer_cmd_rad": state[:, 9],
                             "yaw_rate_cmd_radps": state[:, 7], "coast": plan.coast[row],
                             **({"duty_cmd": plan.duty_cmd[row]} if duty else {})}, "<excite>")


@dataclass(frozen=True)
class DeadReckoning:
    """A pose integrated on the car from its wheel speed and gyro, frame by frame (the
    closed-loop turns without a camera: docs/calibration.md): ``gyro_bias_radps`` (what
    is left of the gyro's bias after it was zeroed at rest) and ``odometry_scale`` (the
    wheel speed's scale error: a worn tyre, a wrong wheel radius)."""

    gyro_bias_radps: float = 0.0
    odometry_scale: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.gyro_bias_radps) and math.isfinite(self.odometry_scale)
                and self.odometry_scale > 0.0):
            raise PlanError(f"dead reckoning: gyro bias {self.gyro_bias_radps!r} rad/s, odometry scale "
                            f"{self.odometry_scale!r}: expected finite numbers, the scale above 0")

    def advance(self, pose: tuple[float, float, float], speed_mps: float, yaw_rate_radps: float,
                dt_s: float) -> tuple[float, float, float]:
        """``(x, y, yaw)`` after ``dt_s`` at the measured ``speed_mps`` and ``yaw_rate_radps``
        (midpoint heading)."""
        x, y, yaw = pose
        turn = (yaw_rate_radps + self.gyro_bias_radps) * dt_s
        v = speed_mps * self.odometry_scale
        mid = yaw + 0.5 * turn
        return x + v * math.cos(mid) * dt_s, y + v * math.sin(mid) * dt_s, yaw + turn


def plan_steps_per_row(plan: ExcitationPlan, dt_s: float) -> int:
    """Physics steps per plan row; the row period must be a whole number of steps."""
    steps = round(1.0 / (plan.rate_hz * dt_s))
    if steps < 1 or abs(steps * dt_s * plan.rate_hz - 1.0) > 1e-9:
        raise PlanError(f"dt_s = {dt_s!r}: expected a step that divides the plan's row period "
                        f"{1.0 / plan.rate_hz:g} s")
    return steps
