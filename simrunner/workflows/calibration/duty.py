"""``simrunner calibrate`` ``[duty]``: the motor model of a duty-driven car from the tests a team
can do with a tape, a stopwatch and its encoder (docs/calibration.md, docs/drive.md "Duty drive").

The model (docs/drive.md; Liniger et al. 2015): each rear motor pushes its wheel with
``f(v, d) = c1 d - c2 v`` (H-bridge ``brake``) or ``(c1 - c2 v) d`` (``coast``), and the car obeys
``m_eff dv/dt = 2 f(v, d) - F_rr - k v^2``. Three tests reveal its four numbers:

=================  =========================================  =============================
test               measured                                   reveals
=================  =========================================  =============================
steady speeds      the steady speed at a few duties           c2 (with c1: the top speed c1 / c2);
                                                              F_rr too with 2+ duties
0 -> duty          distance from rest when a timer ends       c1
coast-down         from a speed, H-bridge off: distance to    F_rr (and k with the time)
                   standstill (and the time)
=================  =========================================  =============================

The numbers are fitted together (scipy ``least_squares``, relative errors) on the model's
one-dimensional equation (``solve_ivp``; closed forms for the steady speed and the coast-down),
which the simulated car follows within 0.3 % (bench/bench_duty.py); what no test reveals keeps
the car file's value. The checks then run each test on the simulated car before and after.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, least_squares

from pieces.pose import Pose2
from simrunner.car.effects import make_sim
from simrunner.car.physics import CarSim
from simrunner.workflows.calibration.measured import CalibrationError
from simrunner.workflows.calibration.procedure import Check, ProcedureResult, range_checked
from simrunner.workflows.calibration.simtests import _high_traction
from vehicle.description import CarDescription

PARAMS = ("motor_force_n", "motor_back_emf_nspm", "rolling_resistance_n", "drag_nspm2")
BOUNDS = ((1e-3, 1000.0), (1e-3, 1000.0), (0.0, 100.0), (0.0, 10.0))  # the car file's ranges
STOPPED_MPS = 1e-3  # the simulated coast-down has ended below this speed
MAX_COAST_S = 120.0


@dataclasses.dataclass(frozen=True)
class Motor:
    """The model's numbers: per motor c1 (N), c2 (N s/m); the car's F_rr (N), k (N s^2/m^2), m_eff (kg)."""

    c1: float
    c2: float
    rolling_n: float
    drag: float
    m_eff_kg: float
    brake: bool

    def force_n(self, v: float, duty: float) -> float:
        """Both motors' force at speed ``v`` and duty ``duty`` (``duty`` None: H-bridge off)."""
        if duty is None:
            return 0.0
        return 2.0 * (self.c1 * duty - self.c2 * v * (1.0 if self.brake else abs(duty)))

    def steady_speed_mps(self, duty: float) -> float:
        """The speed where the motors' force meets rolling resistance and drag (0 when they cannot start)."""
        def net(v):
            return self.force_n(v, duty) - self.rolling_n - self.drag * v * v
        if net(0.0) <= 0.0:
            return 0.0
        hi = self.c1 / self.c2 * (1.0 + 1e-6) + 1e-9
        return float(brentq(net, 0.0, hi, xtol=1e-12, rtol=1e-12))

    def accel_distance_m(self, duty: float, time_s: float) -> float:
        """Distance from rest after ``time_s`` at ``duty``."""
        if self.force_n(0.0, duty) <= self.rolling_n:
            return 0.0

        def rhs(_t, y):
            v = y[1]
            return (v, (self.force_n(v, duty) - self.rolling_n - self.drag * v * abs(v)) / self.m_eff_kg)
        sol = solve_ivp(rhs, (0.0, time_s), (0.0, 0.0), rtol=1e-9, atol=1e-12)
        return float(sol.y[0, -1])

    def coast_down(self, speed_mps: float) -> tuple[float, float]:
        """(distance m, time s) to standstill from ``speed_mps`` with the H-bridge off (closed forms)."""
        m, f, k, v0 = self.m_eff_kg, self.rolling_n, self.drag, speed_mps
        if f <= 0.0:
            return math.inf, math.inf
        if k <= 0.0:
            return m * v0 * v0 / (2.0 * f), m * v0 / f
        return m / (2.0 * k) * math.log1p(k * v0 * v0 / f), m / math.sqrt(f * k) * math.atan(v0 * math.sqrt(k / f))


def motor_of(car: CarDescription) -> Motor:
    """The model's numbers of ``car`` (c1, c2 derived from its limits where the file leaves them 0)."""
    dr = car.drive
    m_eff = CarSim(car).effective_mass_kg
    c1 = dr.motor_force_n or 0.5 * m_eff * dr.max_accel_mps2
    c2 = dr.motor_back_emf_nspm or c1 / dr.max_speed_mps
    return Motor(c1, c2, dr.rolling_resistance_n, dr.drag_nspm2, m_eff, dr.hbridge == "brake")


# -- the tests on the simulated car ---------------------------------------------------------------
def sim_steady_speed_mps(car: CarDescription, duty: float, dt_s: float = 0.002) -> float:
    """From rest at ``duty``, the speed after ten of the model's time constants (at most 60 s)."""
    mo = motor_of(car)
    tau = mo.m_eff_kg / (2.0 * mo.c2 * (1.0 if mo.brake else duty))
    sim = make_sim(car, dt_s=dt_s)
    sim.set_motors(duty, duty)
    sim.step(round(min(60.0, 10.0 * tau) / sim.dt_s))
    return sim.speed_mps


def sim_accel_distance_m(car: CarDescription, duty: float, time_s: float, dt_s: float = 0.002) -> float:
    """From rest at ``duty``, the distance after ``time_s`` (high traction, as the thesis's 5.2.2)."""
    sim = make_sim(_high_traction(car), dt_s=dt_s)
    sim.set_motors(duty, duty)
    sim.step(round(time_s / sim.dt_s))
    return math.hypot(sim.pose.x_m, sim.pose.y_m)


def sim_coast_down(car: CarDescription, speed_mps: float, dt_s: float = 0.002) -> tuple[float, float]:
    """(distance m, time s) from ``speed_mps`` to standstill with the H-bridge off (the motors
    float); ``inf`` when the car still rolls after ``MAX_COAST_S``."""
    sim = make_sim(car, dt_s=dt_s)
    sim.set_state(Pose2(), speed_mps)
    sim.set_coast(True)
    t0, chunk = sim.time_s, max(1, round(0.01 / sim.dt_s))
    while abs(sim.speed_mps) >= STOPPED_MPS:
        if sim.time_s - t0 > MAX_COAST_S:
            return math.inf, math.inf
        sim.step(chunk)
    return math.hypot(sim.pose.x_m, sim.pose.y_m), sim.time_s - t0


# -- the procedure -----------------------------------------------------------------------------
def _free(v: dict) -> list[bool]:
    """Which of PARAMS the given tests reveal (the module docstring's table)."""
    speeds, coast = v["duties"] is not None, v["coast_speed_mps"] is not None
    return [v["accel_time_s"] is not None, speeds,
            coast or (speeds and len(set(v["duties"])) >= 2),
            coast and v["coast_time_s"] is not None]


def _residuals(mo: Motor, v: dict) -> list[float]:
    """Relative errors of the model against each measured number."""
    out = []
    if v["duties"] is not None:
        out += [(mo.steady_speed_mps(d) - s) / s for d, s in zip(v["duties"], v["speeds_mps"])]
    if v["accel_time_s"] is not None:
        out.append((mo.accel_distance_m(v["accel_duty"], v["accel_time_s"]) - v["accel_distance_m"])
                   / v["accel_distance_m"])
    if v["coast_speed_mps"] is not None:
        dist, time_s = mo.coast_down(v["coast_speed_mps"])
        out.append(min((dist - v["coast_distance_m"]) / v["coast_distance_m"], 1e3))
        if v["coast_time_s"] is not None:
            out.append(min((time_s - v["coast_time_s"]) / v["coast_time_s"], 1e3))
    return out


def _checks(before: CarDescription, after: CarDescription, v: dict, dt_s: float) -> tuple[Check, ...]:
    checks = []
    if v["duties"] is not None:
        checks += [Check(f"steady speed at duty {d:g}", "m/s", s, sim_steady_speed_mps(before, d, dt_s),
                         sim_steady_speed_mps(after, d, dt_s)) for d, s in zip(v["duties"], v["speeds_mps"])]
    if v["accel_time_s"] is not None:
        d, t = v["accel_duty"], v["accel_time_s"]
        checks.append(Check(f"distance in {t:g} s from rest at duty {d:g}", "m", v["accel_distance_m"],
                            sim_accel_distance_m(before, d, t, dt_s), sim_accel_distance_m(after, d, t, dt_s)))
    if v["coast_speed_mps"] is not None:
        s = v["coast_speed_mps"]
        b, a = sim_coast_down(before, s, dt_s), sim_coast_down(after, s, dt_s)
        checks.append(Check(f"coast-down distance from {s:g} m/s", "m", v["coast_distance_m"], b[0], a[0]))
        if v["coast_time_s"] is not None:
            checks.append(Check(f"coast-down time from {s:g} m/s", "s", v["coast_time_s"], b[1], a[1]))
    return tuple(checks)


def calibrate_duty(car: CarDescription, m, v: dict, dt_s: float):
    """The ``[duty]`` procedure: (the calibrated car, its :class:`ProcedureResult`)."""
    drive0 = car.drive
    hbridge = v["hbridge"] or drive0.hbridge
    before = car.replace(drive=dataclasses.replace(drive0, command="duty", hbridge=hbridge, front_share=0.0))
    mo = motor_of(before)
    x0 = np.array([mo.c1, mo.c2, mo.rolling_n, mo.drag])
    free = _free(v)
    if v["coast_speed_mps"] is not None and x0[2] <= 0.0:  # a start the coast-down can move from
        x0[2] = mo.m_eff_kg * v["coast_speed_mps"] ** 2 / (2.0 * v["coast_distance_m"])
    if free[3] and x0[3] <= 0.0:
        x0[3] = 1e-3
    idx = [i for i, f in enumerate(free) if f]
    lo = np.array([BOUNDS[i][0] for i in idx])
    hi = np.array([BOUNDS[i][1] for i in idx])

    def model(x_free) -> Motor:
        x = x0.copy()
        x[idx] = x_free
        return dataclasses.replace(mo, c1=x[0], c2=x[1], rolling_n=x[2], drag=x[3])

    start = np.clip(x0[idx], lo + 1e-9, hi - 1e-9)
    fit = least_squares(lambda xf: _residuals(model(xf), v), start, bounds=(lo, hi), x_scale=np.maximum(start, 1e-3),
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    fitted = model(fit.x)
    rms = float(np.sqrt(np.mean(np.square(fit.fun))))
    values = dict(zip(PARAMS, (fitted.c1, fitted.c2, fitted.rolling_n, fitted.drag)))
    after = range_checked(car.replace(drive=dataclasses.replace(before.drive, **values)), m, "duty")
    changes: dict[str, tuple] = {}
    if drive0.command != "duty":
        changes["drive.command"] = (drive0.command, "duty")
    if hbridge != drive0.hbridge:
        changes["drive.hbridge"] = (drive0.hbridge, hbridge)
    for name, i in zip(PARAMS, range(4)):
        if free[i] or getattr(drive0, name) == 0.0 and i < 2:  # derived c1, c2 are written out
            changes[f"drive.{name}"] = (getattr(drive0, name), values[name])
    kept = [name for name, f in zip(PARAMS, free) if not f]
    notes = [f"model (docs/drive.md, H-bridge {hbridge}): m_eff dv/dt = 2 f(v, d) - F_rr - k v^2, "
             f"m_eff = {mo.m_eff_kg:.4g} kg; fitted {', '.join(p for p, f in zip(PARAMS, free) if f)} "
             f"(scipy least_squares, relative RMS error {100 * rms:.2g} %)",
             f"full duty's top speed c1 / c2 = {fitted.c1 / fitted.c2:.4g} m/s"
             + (f", less rolling resistance and drag: {fitted.steady_speed_mps(1.0):.4g} m/s"
                if fitted.rolling_n or fitted.drag else "")]
    if kept:
        notes.append(f"kept from the car file (no test here reveals them): {', '.join(kept)}")
    if rms > 0.05:
        notes.append(f"the model misses the measurements by {100 * rms:.2g} % (RMS): check the numbers, "
                     f"the H-bridge mode ({hbridge}) and the speeds being steady")
    if not fit.success or not all(np.isfinite(fit.fun)):
        raise CalibrationError(f"{m.where('duty')}: the motor model cannot reproduce these measurements "
                               f"({fit.message}); expected numbers of one car and H-bridge mode")
    return after, ProcedureResult("duty", "motor model from steady speeds, 0 -> duty and a coast-down", changes,
                                  _checks(before, after, v, dt_s), tuple(notes),
                                  {**values, "rms": rms, "free": tuple(free)})
