"""``simrunner calibrate``: the thesis's chapter-5 calibration procedures, run in the simulator
against numbers measured on the real car (file format: :mod:`simrunner.workflows.calibration.measured`,
docs/calibration.md).

Each procedure turns measurements into car-description values, then runs the same test in
the simulator before and after the change (:mod:`simrunner.workflows.calibration.simtests`) so the
team sees measured vs simulated:

=============  ===============  ==========================================================
section        thesis           result
=============  ===============  ==========================================================
mass           5.5              ``chassis.mass_kg = weight * scale^3``
traction       5.4              ``wheels.friction_mu = tan(slip angle) / effects.friction_scale``;
                                checked by the simulated tilt test (holds below, slides above)
steering       5.3.1            ``steering.limit_rad = atan(L / R)`` (R of the rear-axle centre),
                                then refined by simulation (brentq) to the measured radius
speed          5.2.1            fit of distance vs command (scipy ``curve_fit``) -> the speed
                                normalisation to use; ``drive.max_speed_mps`` from ``full_command``
acceleration   5.2.2            ``drive.max_accel_mps2`` by brentq on the simulated distance
braking        5.2.3            ``drive.max_brake_mps2`` by brentq on the simulated distance
duty           motor model      ``drive.command = "duty"`` and the motor model's c1, c2, rolling
                                resistance and drag, fitted to steady speeds, 0 -> duty and a
                                coast-down (:mod:`.duty`)
camera         Fig. 5.2         ``camera.default_row``: the row that sees the ground ``distance_m``
                                ahead of the front bumper
=============  ===============  ==========================================================

Procedures run in that order, each on the car the previous ones produced. Library code
returns a :class:`CalibrationResult`; :meth:`CalibrationResult.report` is the text the CLI
prints.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import OptimizeWarning, brentq, curve_fit

from simrunner.workflows.calibration import camera_procedures as cp
from simrunner.workflows.calibration import simtests as st
from simrunner.workflows.calibration.duty import calibrate_duty
from simrunner.workflows.calibration.measured import (ORDER, SOURCES, CalibrationError, Measurements,
                                            load_measurements)
from simrunner.workflows.calibration.procedure import Check, ProcedureResult, range_checked
from vehicle.description import CarDescription, CarDescriptionError

__all__ = ["calibrate", "CalibrationResult", "ProcedureResult", "Check", "CalibrationError",
           "load_measurements"]


@dataclass(frozen=True)
class CalibrationResult:
    car_before: CarDescription
    car_after: CarDescription
    procedures: tuple[ProcedureResult, ...]

    def procedure(self, section: str) -> ProcedureResult:
        return next(p for p in self.procedures if p.section == section)

    def sources(self) -> dict[str, str]:
        """``"section.field"`` -> the procedure that set it (the written car file's source
        comments, :meth:`vehicle.description.CarDescription.to_toml`)."""
        return {key: f"simrunner calibrate [{p.section}], {SOURCES[p.section]}: {p.title}"
                for p in self.procedures for key in p.changes}

    def report(self) -> str:
        """Human-readable text: per procedure the notes, changes and a measured / before /
        after table."""
        out: list[str] = []
        for p in self.procedures:
            out.append(f"[{p.section}] {SOURCES[p.section]}: {p.title}")
            out += [f"  {n}" for n in p.notes]
            for key, (old, new) in p.changes.items():
                out.append(f"  {key}: {_num(old)} -> {_num(new)}")
            if p.checks:
                head = "simulated vs measured"
                w = max([len(c.label) + len(c.unit) + 3 for c in p.checks] + [len(head)])
                out.append(f"  {head.ljust(w)}  {'measured':>9}  {'before':>9}  {'after':>9}")
                for c in p.checks:
                    label = f"{c.label} ({c.unit})"
                    out.append(f"  {label.ljust(w)}  {_num(c.measured):>9}  {_num(c.before):>9}  {_num(c.after):>9}")
            out.append("")
        return "\n".join(out).rstrip() + "\n"


def _num(x: float | str) -> str:
    if isinstance(x, (int, str)):
        return str(x)
    if not math.isfinite(x):
        return str(x)
    return f"{x:.4g}" if abs(x) < 1e4 else f"{x:.0f}"


def _set(car: CarDescription, dotted: str, value: float) -> CarDescription:
    section, name = dotted.split(".")
    return car.replace(**{section: dataclasses.replace(getattr(car, section), **{name: value})})


def _solve(f: Callable[[float], float], guess: float, lo: float, hi: float, where: str, what: str) -> float:
    """Root of increasing-or-decreasing ``f`` in [lo, hi], bracketing around ``guess``
    first (few simulations), then the whole range."""
    guess = min(max(guess, lo), hi)
    a, b = max(lo, guess / 1.5), min(hi, guess * 1.5)
    fa, fb = f(a), f(b)
    if fa * fb > 0:
        a, b = lo, hi
        fa, fb = f(a), f(b)
        if fa * fb > 0:
            raise CalibrationError(f"{where}: the simulated car cannot reproduce it with {what} in "
                                   f"[{lo:g}, {hi:g}]; expected a measurement inside that range")
    return float(brentq(f, a, b, xtol=1e-5, rtol=1e-6))


# -- procedures ------------------------------------------------------------------------------
def _mass(car, m, v, dt_s):
    weight, scale = v["weight_kg"], v["scale"]
    mass = weight * scale ** 3
    new = range_checked(_set(car, "chassis.mass_kg", mass), m, "mass")
    try:
        before, after = st.built_mass_kg(car), st.built_mass_kg(new)
    except CarDescriptionError as exc:
        raise CalibrationError(f"{m.where('mass', 'weight_kg')}: {str(exc).split(': ', 1)[-1]}") from None
    return new, ProcedureResult(
        "mass", "mass from the scale (m = w s^3)", {"chassis.mass_kg": (car.chassis.mass_kg, mass)},
        (Check("mass of the simulated car", "kg", mass, before, after),),
        (f"m = {weight:g} kg x {scale:g}^3 = {mass:.4g} kg",), {"mass_kg": mass})


def _traction(car, m, v, dt_s):
    theta = math.radians(v["slip_angle_deg"])
    orient = v["orientation"]
    mu_eff = math.tan(theta)
    scale = car.effects.friction_scale
    mu = mu_eff / scale
    new = range_checked(_set(car, "wheels.friction_mu", mu), m, "traction")
    before = math.degrees(st.slip_angle_rad(car, orient, dt_s))
    after = math.degrees(st.slip_angle_rad(new, orient, dt_s))
    margin = math.radians(2.0)
    holds = not st.slides(new, max(theta - margin, 0.0), orient, dt_s)
    slides = st.slides(new, min(theta + margin, math.radians(st.MAX_SLOPE_DEG)), orient, dt_s)
    notes = [f"mu = tan({v['slip_angle_deg']:g} deg) = {mu_eff:.4g}"
             + (f"; wheels.friction_mu = mu / effects.friction_scale ({scale:g})" if scale != 1.0 else ""),
             f"tilted-track test ({orient}, wheels locked): "
             f"{'holds' if holds else 'SLIDES'} at {math.degrees(theta - margin):.1f} deg, "
             f"{'slides' if slides else 'HOLDS'} at {math.degrees(theta + margin):.1f} deg"]
    if orient == "sideways":
        notes.append("dart has one friction coefficient per tyre: the sideways value is used for both directions")
    return new, ProcedureResult(
        "traction", "tyre friction from the tilt test (mu = tan theta)",
        {"wheels.friction_mu": (car.wheels.friction_mu, mu)},
        (Check("slip angle", "deg", v["slip_angle_deg"], before, after),), tuple(notes),
        {"mu": mu_eff, "holds_below": holds, "slides_above": slides})


def _steering(car, m, v, dt_s):
    L, half_t = car.chassis.wheelbase_m, 0.5 * car.chassis.track_m
    r, at = v["radius_m"], v["measured_at"]
    if at == "inner_rear_wheel":
        rc = r + half_t
    elif at == "rear_axle_centre":
        rc = r
    else:
        if r <= L + half_t:
            raise CalibrationError(f"{m.where('steering', 'radius_m')}: expected an outer-front-wheel radius "
                                   f"above wheelbase + track/2 = {L + half_t:.3f} m")
        rc = math.sqrt(r * r - L * L) - half_t
    limit0 = math.atan(L / rc)
    if not (0.01 <= limit0 <= 1.2):
        raise CalibrationError(f"{m.where('steering', 'radius_m')}: gives a steering limit of {limit0:.3f} rad, "
                               f"expected 0.01 .. 1.2 rad")
    speed = v["speed_mps"]

    def radius_error(limit):
        return st.turn_radius_m(_set(car, "steering.limit_rad", limit), speed, dt_s) - rc
    try:
        limit = _solve(radius_error, limit0, max(0.01, 0.8 * limit0), min(1.2, 1.25 * limit0),
                       m.where("steering", "radius_m"), "steering.limit_rad")
    except CalibrationError:
        limit = limit0  # the simulated radius does not bracket: keep eq. 5.1
    new = range_checked(_set(car, "steering.limit_rad", limit), m, "steering")
    before, after = st.turn_radius_m(car, speed, dt_s), st.turn_radius_m(new, speed, dt_s)
    notes = [f"thesis eq. 5.1 with the measured radius: atan(L / R) = atan({L:g} / {r:g}) = "
             f"{math.atan(L / r):.4f} rad ({math.degrees(math.atan(L / r)):.2f} deg)",
             f"bicycle-equivalent limit from the rear-axle-centre radius {rc:.4f} m: {limit0:.4f} rad; "
             f"refined by simulation: {limit:.4f} rad ({math.degrees(limit):.2f} deg)"]
    return new, ProcedureResult(
        "steering", "steering limit from the turning radius (eq. 5.1)",
        {"steering.limit_rad": (car.steering.limit_rad, limit)},
        (Check(f"full-lock radius, rear-axle centre, {speed:g} m/s", "m", rc, before, after),), tuple(notes),
        {"limit_rad": limit, "limit_eq51_rad": limit0})


_SPEED_MODELS = {
    "linear": (lambda c, a, b: a * c + b, 2),
    "proportional": (lambda c, a: a * c, 1),
    "quadratic": (lambda c, a, b, e: a * c * c + b * c + e, 3),
}


def _speed(car, m, v, dt_s):
    cmds, dists = np.array(v["commands"]), np.array(v["distances_m"])
    window, settle = v["window_s"], v["settle_s"]
    fn, n_par = _SPEED_MODELS[v["model"]]
    with warnings.catch_warnings():  # exactly determined fits have no covariance: fine here
        warnings.simplefilter("ignore", OptimizeWarning)
        params, _ = curve_fit(fn, cmds, dists, p0=np.ones(n_par))
    pred = fn(cmds, *params)
    ss_res, ss_tot = float(np.sum((dists - pred) ** 2)), float(np.sum((dists - dists.mean()) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0
    k = params / window  # speed (m/s) = fn(command, *k)

    def speed_of(command: float) -> float:
        return float(fn(np.float64(command), *k))

    def term(x: float) -> str:
        return f"{'-' if x < 0 else '+'} {abs(x):.6g}"

    if v["model"] == "linear":
        formula = f"{k[0]:.6g} * speed {term(k[1])}"
    elif v["model"] == "proportional":
        formula = f"{k[0]:.6g} * speed"
    else:
        formula = f"{k[0]:.6g} * speed**2 {term(k[1])} * speed {term(k[2])}"
    norm = formula
    if v["model"] == "linear" and k[0] > 0 and k[1] < 0:
        # a deadband: below it the line would ask for a negative speed (the car backing up);
        # the norm holds 0 there and mirrors it for reverse commands
        norm = f"(1 if speed >= 0 else -1) * max(0.0, {k[0]:.6g} * abs(speed) {term(k[1])})"
    notes = [f"fit ({v['model']}, scipy curve_fit, R^2 = {r2:.5f}): speed_mps = {formula.replace('speed', 'command')}",
             f"speed normalisation for the controller: spinner.configure(speed_norm=lambda speed, angle: {norm})"]
    if v["model"] == "linear" and k[0] != 0 and k[1] < 0:
        notes.append(f"the car starts to roll above command {-k[1] / k[0]:.4g} (deadband of the motor driver): "
                     "the normalisation gives 0 below it (and mirrors it for reverse commands)")
    speeds = [speed_of(c) for c in cmds]
    vmax_old = car.drive.max_speed_mps
    changes: dict[str, tuple[float, float]] = {}
    new = car
    if v["full_command"] is not None:
        vmax = speed_of(v["full_command"])
        changes["drive.max_speed_mps"] = (vmax_old, vmax)
        new = range_checked(_set(car, "drive.max_speed_mps", vmax), m, "speed")
    elif max(speeds) > vmax_old:
        vmax = max(speeds)
        changes["drive.max_speed_mps"] = (vmax_old, vmax)
        notes.append("the measured speeds exceed drive.max_speed_mps: raised to the fastest measured speed "
                     "(give full_command for the real top speed)")
        new = range_checked(_set(car, "drive.max_speed_mps", vmax), m, "speed")
    norm = v["sim_norm"]
    checks = tuple(
        Check(f"distance in {window:g} s after {settle:g} s, command {c:g}", "m", d,
              st.window_distance_m(car, norm * c, settle, window, dt_s),
              st.window_distance_m(new, s, settle, window, dt_s))
        for c, d, s in zip(cmds, dists, speeds))
    notes.append(f"'before' commands the simulator with speed = {norm:g} x command (sim_norm), "
                 f"'after' with the fitted normalisation")
    return new, ProcedureResult("speed", "speed normalisation (distance over a fixed window)", changes, checks,
                                tuple(notes), {"params": tuple(float(p) for p in k), "r2": r2, "speed_of": speed_of})


def _command_speed(section, m, v, speed_result):
    if v["speed_mps"] is not None:
        return v["speed_mps"], f"{v['speed_mps']:g} m/s"
    if speed_result is None:
        raise CalibrationError(f"{m.where(section, 'command')}: expected a [speed] section to convert "
                               f"the command to m/s (or give speed_mps)")
    speed = speed_result.values["speed_of"](v["command"])
    if speed <= 0:
        raise CalibrationError(f"{m.where(section, 'command')}: the [speed] fit gives {speed:.3g} m/s for it, "
                               f"expected a command that moves the car")
    return speed, f"command {v['command']:g} ({speed:.3g} m/s)"


def _acceleration(car, m, v, dt_s, speed_result=None):
    speed, label = _command_speed("acceleration", m, v, speed_result)
    T, D = v["time_s"], v["distance_m"]
    if D >= speed * T:
        raise CalibrationError(f"{m.where('acceleration', 'distance_m')}: {D:g} m in {T:g} s at {speed:.3g} m/s "
                               f"is at least an instant start ({speed * T:.3g} m); expected less")
    guess = 2 * D / T ** 2 if D < 0.5 * speed * T else speed ** 2 / (2 * (speed * T - D))

    def err(a):
        return st.accel_distance_m(_set(car, "drive.max_accel_mps2", a), speed, T, dt_s) - D
    a = _solve(err, guess, 0.1, 50.0, m.where("acceleration", "distance_m"), "drive.max_accel_mps2")
    new = range_checked(_set(car, "drive.max_accel_mps2", a), m, "acceleration")
    return new, ProcedureResult(
        "acceleration", "acceleration limit from the distance covered from standstill",
        {"drive.max_accel_mps2": (car.drive.max_accel_mps2, a)},
        (Check(f"distance in {T:g} s from rest, {label}", "m", D, st.accel_distance_m(car, speed, T, dt_s),
               st.accel_distance_m(new, speed, T, dt_s)),),
        (f"simulated on high-traction ground (mu {st.HIGH_MU:g}), as in the thesis",), {"max_accel_mps2": a})


def _braking(car, m, v, dt_s, speed_result=None):
    speed, label = _command_speed("braking", m, v, speed_result)
    D = v["distance_m"]

    def err(b):
        return st.brake_distance_m(_set(car, "drive.max_brake_mps2", b), speed, dt_s) - D
    b = _solve(err, speed ** 2 / (2 * D), 0.1, 50.0, m.where("braking", "distance_m"), "drive.max_brake_mps2")
    new = range_checked(_set(car, "drive.max_brake_mps2", b), m, "braking")
    return new, ProcedureResult(
        "braking", "braking limit from the braking distance",
        {"drive.max_brake_mps2": (car.drive.max_brake_mps2, b)},
        (Check(f"braking distance from {label}", "m", D, st.brake_distance_m(car, speed, dt_s),
               st.brake_distance_m(new, speed, dt_s)),),
        (f"simulated on high-traction ground (mu {st.HIGH_MU:g}), as in the thesis",), {"max_brake_mps2": b})


def _camera(car, m, v, dt_s):
    d = v["distance_m"]
    dist = st.row_ground_distances_m(car)
    finite = dist[np.isfinite(dist)]
    if finite.size == 0 or not (finite.min() - 0.02 <= d <= finite.max() + 0.02):
        seen = f"{finite.min():.3f} .. {finite.max():.3f} m" if finite.size else "no ground"
        raise CalibrationError(f"{m.where('camera', 'distance_m')}: expected a distance the camera sees "
                               f"(its rows cover {seen} ahead of the front bumper)")
    row = st.row_for_distance(car, d)
    old = car.camera.default_row
    new = range_checked(_set(car, "camera.default_row", row), m, "camera")
    rows = st.rows_seeing_line(car, d)
    seen = f"rows {rows[0]}..{rows[-1]}" if rows else "no row"
    return new, ProcedureResult(
        "camera", "line-camera row from the distance ahead of the front bumper",
        {"camera.default_row": (old, row)},
        (Check("ground distance ahead of the bumper seen by the line row", "m", d, float(dist[old]),
               float(dist[row])),),
        (f"row {row} looks {dist[row]:.3f} m ahead of the front bumper",
         f"rendered test (Fig. 5.2): a line {d:g} m ahead of the bumper is seen in {seen}"),
        {"row": row, "rows_seeing_line": rows})


_PROCEDURES = {"mass": _mass, "traction": _traction, "steering": _steering, "speed": _speed,
               "acceleration": _acceleration, "braking": _braking, "duty": calibrate_duty, "camera": _camera,
               "camera_dark": cp.camera_dark, "camera_flat": cp.camera_flat, "camera_sweep": cp.camera_sweep}


def calibrate(measurements: Measurements, car: CarDescription | None = None, *,
              dt_s: float = 0.002) -> CalibrationResult:
    """Run every procedure whose section is in ``measurements`` (order: ``ORDER``)."""
    car0 = car or CarDescription()
    car = car0
    results: list[ProcedureResult] = []
    speed_result = None
    for section in ORDER:
        if section not in measurements:
            continue
        fn = _PROCEDURES[section]
        extra = {"speed_result": speed_result} if section in ("acceleration", "braking") else {}
        car, res = fn(car, measurements, measurements[section], dt_s, **extra)
        if section == "speed":
            speed_result = res
        results.append(res)
    return CalibrationResult(car0, car, tuple(results))
