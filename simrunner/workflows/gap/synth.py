"""Synthetic "measured" logs with a hidden effect, for tests, the bench and calibration.

``make_measured_log(effect, rng=...)`` plays the excitation plan
(``simrunner.workflows.excite.make_plan``) in the simulator with

* the hidden effect (or none) at a random magnitude drawn log-uniformly from
  :data:`RANGES` (sign random where both signs make sense);
* nuisance changes the workflow does not model: mass and tyre friction each scaled by a
  factor uniform in ``1 +- NUISANCE_FRACTION``;
* a different physics step than the workflow: :data:`SYNTH_DT_S` = 1 ms
  (the workflow uses ``SETTINGS.workflow_dt_s`` = 5 ms);
* Gaussian noise on the logged states: position :data:`NOISE_POS_M` (5 mm per axis), yaw
  :data:`NOISE_YAW_RAD` (0.005 rad), speed :data:`NOISE_SPEED_MPS` (0.02 m/s), gyro
  :data:`NOISE_GYRO_RADPS`. Commands are exact (they are what the controller sent).

Several effects can be hidden at once (``effect`` a sequence of names). ``sensors`` picks
what the "car" logged: ``"pose"`` (overhead camera: x, y, yaw), ``"speed_gyro"`` (encoder +
gyro: speed and yaw rate, no pose) or ``"both"``; the default is the pose and the speed, as
before.

All randomness comes from the ``rng`` argument (plan seed, magnitudes, nuisance, noise).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from simrunner.telemetry.log import RunLog, log_from_columns
from simrunner.workflows.gap import GapError
from vehicle.description import CarDescription

SYNTH_DT_S = 0.001
NOISE_POS_M = 0.005
NOISE_YAW_RAD = 0.005
NOISE_SPEED_MPS = 0.02
NOISE_GYRO_RADPS = 0.02
SENSORS = {"pose_speed": ("x_m", "y_m", "yaw_rad", "speed_mps"), "pose": ("x_m", "y_m", "yaw_rad"),
           "speed_gyro": ("speed_mps", "yaw_rate_radps"),
           "both": ("x_m", "y_m", "yaw_rad", "speed_mps", "yaw_rate_radps")}
NUISANCE_FRACTION = 0.03

# effect -> (field, low, high, both signs): |value - neutral| for offset and gain, else the
# value, is log-uniform in [low, high] (sign random where both make sense). The ranges run
# from barely visible (SNR ~ 1) to strong, so the bench sees accuracy against SNR.
RANGES: dict[str, tuple[str, float, float, bool]] = {
    "steering_offset": ("steering_offset_rad", 0.002, 0.05, True),
    "steering_gain": ("steering_gain", 0.02, 0.35, True),  # gain = 1 +- that
    "steering_lag": ("steering_lag_s", 0.01, 0.2, False),
    "steering_rate_limit": ("steering_rate_limit_radps", 0.8, 5.0, False),
    "command_latency": ("command_latency_s", 0.01, 0.15, False),
    "motor_lag": ("motor_lag_s", 0.02, 0.6, False),
    "throttle_deadband": ("throttle_deadband_mps", 0.03, 0.4, False),
    "rolling_resistance": ("rolling_resistance_coeff", 0.005, 0.08, False),
    "drag": ("drag_coeff_kgpm", 0.02, 0.4, False),
    "tire_slip": ("tire_slip_understeer_radps2pm", 0.003, 0.08, False),
    "friction": ("friction_scale", 0.45, 0.95, False),  # the value; log-uniform
    "speed_scale": ("speed_scale", 0.02, 0.25, True),  # scale = 1 +- that
    "steering_asymmetry": ("steering_asymmetry", 0.02, 0.25, True),
    "steering_play": ("steering_play_rad", 0.003, 0.04, False),
    "esc_brake_reverse": ("esc_reverse_delay_s", 0.05, 0.8, False),
    "accel_scale": ("accel_scale", 0.1, 0.6, False),  # scale = 1 - that
    "brake_scale": ("brake_scale", 0.1, 0.6, False),  # scale = 1 - that
    "servo_rate_scale": ("servo_rate_scale", 0.1, 0.7, False),  # scale = 1 - that
    "steer_limit_scale": ("steer_limit_scale", 0.05, 0.3, False),  # scale = 1 - that
    "mass_scale": ("mass_scale", 0.1, 0.6, True),  # scale = 1 +- that
    "top_speed": ("top_speed_mps", 1.2, 2.6, False),  # the cap; the plan reaches ~3 m/s
    "lift_lag": ("lift_lag_s", 0.05, 1.0, False),
    # a four-wheel-drive car with a rear-drive file; shows only where the drive and brake limits
    # reach the tyres' grip (not on the default car: its 3.1 m/s^2 stay well inside it)
    "front_drive": ("front_share_shift", 0.15, 0.5, False),
    # the chassis's inertia: shows only where the tyres slide (as front_drive, not on the default car)
    "inertia": ("inertia_scale", 0.3, 0.6, True),  # scale = 1 +- that
    # the slip tyres' numbers: only for a car with wheels.tyre_model = "slip"
    "tyre_stiffness": ("tyre_stiffness_scale", 0.15, 0.6, True),  # scale = 1 +- that
    "tyre_balance": ("tyre_balance", 0.05, 0.35, True),
    "tyre_relaxation": ("tyre_relaxation_scale", 0.3, 1.5, True),  # scale = 1 + that or 1 / (1 + that)
}
_RELATIVE_TO_ONE = {"steering_gain", "speed_scale", "mass_scale", "inertia", "tyre_stiffness", "tyre_relaxation"}
_BELOW_ONE = {"accel_scale", "brake_scale", "servo_rate_scale", "steer_limit_scale"}


@dataclass(frozen=True)
class Truth:
    """What :func:`make_measured_log` hid: the first ``effect`` (or None), its ``field`` and
    ``value``; every hidden effect in ``effects`` / ``values`` (field -> value); the nuisance
    factors, the plan seed, and the car the log was simulated with."""

    effect: str | None
    field: str | None
    value: float | None
    mass_factor: float
    friction_factor: float
    plan_seed: int
    car: CarDescription
    effects: tuple[str, ...] = ()
    values: dict = dataclasses.field(default_factory=dict)


def draw_value(effect: str, rng: np.random.Generator) -> float:
    """A random magnitude for ``effect`` from :data:`RANGES`."""
    _, lo, hi, signed = RANGES[effect]
    mag = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    sign = float(rng.choice([-1.0, 1.0])) if signed else 1.0
    if effect in _BELOW_ONE:
        return 1.0 - mag
    if effect == "tyre_relaxation":  # a factor: 1 + that or 1 / (1 + that)
        return 1.0 + mag if sign > 0 else 1.0 / (1.0 + mag)
    return 1.0 + sign * mag if effect in _RELATIVE_TO_ONE else sign * mag


def make_measured_log(effect: str | Sequence[str] | None, *, rng: np.random.Generator,
                      car: CarDescription | None = None, value: float | Sequence[float] | None = None,
                      start_s: float = 0.0, duration_s: float | None = None, noise: bool = True,
                      sensors: str = "pose_speed", sim_factory=None,
                      hbridge: str | None = None) -> tuple[RunLog, Truth]:
    """A synthetic measured log with ``effect`` hidden (see the module docstring).

    ``effect``: a catalogue name, several names, or None. ``value`` fixes the magnitude(s)
    instead of drawing them; ``start_s``/``duration_s`` play only that part of the plan
    (from rest at the origin; tests use ~20 s parts); ``noise=False`` gives exact states
    (for the signal-to-noise computation of the bench); ``sensors`` one of :data:`SENSORS`;
    ``sim_factory`` plays the plan in another simulator (``excite.run_plan``'s: something the
    catalogue does not model, on top of the car and its effects); ``hbridge``: a duty-driven
    car's H-bridge mode in truth (the plan is made for ``car``'s). A duty-driven car's log holds
    the duty it was given (``duty_cmd``).
    Returns ``(log, truth)``; the log holds the commands, ``coast`` and the sensors' columns
    (source ``"<synthetic EFFECT+EFFECT>"``).
    """
    from simrunner.car.effects import with_effects
    from simrunner.workflows.excite import make_plan, run_plan

    car = car or CarDescription()
    names = [] if effect is None else [effect] if isinstance(effect, str) else list(effect)
    unknown = [n for n in names if n not in RANGES]
    if unknown or len(set(names)) != len(names):
        raise GapError(f"unknown or repeated effect(s) {names!r} (expected some of {', '.join(RANGES)} or None)")
    if sensors not in SENSORS:
        raise GapError(f"sensors {sensors!r}: expected one of {', '.join(SENSORS)}")
    values_in = [None] * len(names) if value is None else (
        [value] if isinstance(value, (int, float)) else list(value))
    if len(values_in) != len(names):
        raise GapError(f"expected {len(names)} value(s) for {names!r} (got {len(values_in)})")
    plan_seed = int(rng.integers(0, 2**31 - 1))
    values = {}
    for n, v in zip(names, values_in):
        values[RANGES[n][0]] = float(v) if v is not None else draw_value(n, rng)
    m_f = 1.0 + float(rng.uniform(-NUISANCE_FRACTION, NUISANCE_FRACTION))
    mu_f = 1.0 + float(rng.uniform(-NUISANCE_FRACTION, NUISANCE_FRACTION))
    truth_car = car.replace(chassis=dataclasses.replace(car.chassis, mass_kg=car.chassis.mass_kg * m_f),
                            wheels=dataclasses.replace(car.wheels, friction_mu=car.wheels.friction_mu * mu_f))
    if values:
        truth_car = with_effects(truth_car, **values)
    if hbridge is not None:
        truth_car = truth_car.replace(drive=dataclasses.replace(truth_car.drive, hbridge=hbridge))
    plan = make_plan(car, seed=plan_seed)
    if start_s > 0.0 or duration_s is not None:
        a = int(round(start_s * plan.rate_hz))
        b = len(plan) if duration_s is None else min(len(plan), a + int(round(duration_s * plan.rate_hz)))
        n_rows = len(plan)
        rows = {f.name: getattr(plan, f.name)[a:b] for f in dataclasses.fields(plan)
                if isinstance(getattr(plan, f.name), np.ndarray) and len(getattr(plan, f.name)) == n_rows}
        rows["t_s"] = rows["t_s"] - plan.t_s[a]
        plan = dataclasses.replace(plan, **rows)
    out = run_plan(plan, truth_car, dt_s=SYNTH_DT_S, sim_factory=sim_factory)
    n = len(out)
    keep = ("t_s", "speed_cmd_mps", "steer_cmd_rad", "coast") + SENSORS[sensors]
    if car.drive.command == "duty":
        keep += ("duty_cmd",)
    cols = {k: out.column(k) for k in keep}
    if noise:
        if "x_m" in cols:
            cols["x_m"] = cols["x_m"] + rng.normal(0.0, NOISE_POS_M, n)
            cols["y_m"] = cols["y_m"] + rng.normal(0.0, NOISE_POS_M, n)
            yaw = cols["yaw_rad"] + rng.normal(0.0, NOISE_YAW_RAD, n)
            cols["yaw_rad"] = (yaw + math.pi) % (2.0 * math.pi) - math.pi
        if "speed_mps" in cols:
            cols["speed_mps"] = cols["speed_mps"] + rng.normal(0.0, NOISE_SPEED_MPS, n)
        if "yaw_rate_radps" in cols:
            cols["yaw_rate_radps"] = cols["yaw_rate_radps"] + rng.normal(0.0, NOISE_GYRO_RADPS, n)
    name = f"<synthetic {'+'.join(names) or 'none'}>"
    first = names[0] if names else None
    truth = Truth(first, RANGES[first][0] if first else None, values.get(RANGES[first][0]) if first else None,
                  m_f, mu_f, plan_seed, truth_car, tuple(names), values)
    return log_from_columns(cols, name), truth
