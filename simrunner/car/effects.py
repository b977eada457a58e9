"""Effects catalogue (issue 4): what the nominal car model leaves out, as switchable parts.

Every effect has parameters in ``car.effects`` (``vehicle.description.Effects``) whose neutral
values give back the nominal model exactly. :data:`EFFECTS` describes them;
:func:`make_sim` builds the simulator for a car: a plain :class:`~simrunner.car.physics.CarSim`
when every effect is neutral (zero extra cost, bit-identical), else an :class:`EffectSim`.

Where each effect acts (docs/effects.md has the physics):

* build (:func:`built_car`): errors in the car file's own numbers, as scale factors:
  ``friction`` (``wheels.friction_mu``), ``accel_scale`` / ``brake_scale``
  (``drive.max_accel_mps2`` / ``max_brake_mps2``), ``servo_rate_scale``
  (``steering.rate_radps``), ``steer_limit_scale`` (``steering.limit_rad``), ``mass_scale``
  (every mass and inertia; the drive and brake torques stay those of the file's numbers, so
  the accel and brake limits become ``max / mass_scale``); ``speed_scale`` also scales
  ``drive.max_speed_mps``; ``front_drive`` shifts ``drive.front_share`` (the front wheels'
  share of drive and brake torque, clamped to [0, 1]: a four-wheel-drive car). ``inertia``
  is not a file number: ``simrunner.car.body.build_car_skeleton`` multiplies the chassis
  box's moments of inertia by ``inertia_scale`` (mass and centre of mass unchanged).
* command path, applied to every ``set_command`` (no extra cost):
  ``steering_offset``, ``steering_gain`` (steer -> gain * steer + offset),
  ``steering_asymmetry`` (then left x (1 + a), right x (1 - a)),
  ``throttle_deadband`` (|speed| < deadband -> no drive: the rear wheels free-wheel),
  ``speed_scale`` (speed -> scale * speed) and ``steering_play`` (backlash: the output moves
  only when the input is more than ``b`` away from it, and then stays ``b`` behind; rate
  independent, so it needs no sub-step).
* command path, filtered at a control sub-step of ``n_sub = max(1, round(CONTROL_DT_S /
  dt_s))`` physics steps (4 ms: 2 steps at the default 2 ms) while any of these is active:
  ``command_latency`` (FIFO; a command acts at the first sub-step at or after
  ``t_set + latency``), ``steering_lag`` and ``motor_lag`` (exact first-order lags),
  ``lift_lag`` (the speed target's lag while it comes down to a lower forward command:
  time constant ``max(motor_lag, lift_lag)``; a target of 0 or below is not lifted),
  ``steering_rate_limit`` (slew limit on the steering target, on top of the servo rate),
  ``tire_slip`` (understeer: effective steer = steer - K * a_lat with the kinematic
  lateral acceleration of the effective steer, a_lat = v^2 tan(steer_eff) / L; solved in
  closed form, steer_eff = steer / (1 + K v^2 / L) for small angles, with the measured
  speed v. Feeding back the measured yaw rate instead would be a stiff loop of gain
  K v^2 / L, up to ~25 in the fit range).
* ``esc_brake_reverse``: a negative speed command while rolling forward brakes to rest, holds
  for ``esc_reverse_delay_s`` at rest, then reverses; a command >= 0 or coasting resets it.
  It is checked at every command, and at the control sub-step only while it brakes, so
  without a forward-to-reverse command the car is bit-identical to the nominal one.
* forces (same sub-step): ``rolling_resistance`` ``c_rr * m * g`` and ``drag`` ``k * v^2``
  act on the chassis against the motion through ``CarSim.apply_external_force_n`` (rolling
  resistance fades in linearly below ``ROLL_EPS_MPS`` so a car at rest does not creep).

Order of the steering path: latency -> gain, offset -> asymmetry -> lag -> rate limit ->
play -> understeer -> CarSim (clamp to the limit, servo rate). Speed path: latency ->
deadband -> speed scale -> ESC brake-before-reverse -> motor lag / lift lag -> CarSim (torque-limited
accel/brake). Coasting (``set_coast``: no drive torque, the rear
wheels roll freely) is a command too: it passes the latency; the deadband also coasts.

Everything is deterministic: no randomness, state saved by :meth:`EffectSim.save_state`.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from dataclasses import dataclass
from typing import Any

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.car.physics import GRAVITY_MPS2, CarSim
from vehicle.description import CarDescription, CarDescriptionError, Effects, Steering

CONTROL_DT_S = 0.004  # control sub-step of the filtered effects (rounded to whole physics steps)
ROLL_EPS_MPS = 0.02  # rolling resistance ramps from 0 to full over |v| in [0, ROLL_EPS_MPS]
ESC_REST_MPS = 0.02  # the ESC counts the car at rest (or rolling) below (above) this speed

# residual signals of the gap workflow (simrunner.workflows.gap.replay.FIT_SIGNALS) that
# ``EffectSpec.observed_by`` names
RESIDUAL_SIGNALS = ("along_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
_LATERAL = ("yaw_rate_radps", "yaw_rad", "cross_m")
_LONGITUDINAL = ("speed_mps", "along_m")


def control_steps(dt_s: float) -> int:
    """Physics steps of ``dt_s`` per control sub-step of the filtered effects (``CONTROL_DT_S``
    rounded to whole steps, at least one): a latency or the ESC's delay acts at whole sub-steps."""
    return max(1, round(CONTROL_DT_S / dt_s))


class EffectError(SimError, KeyError):
    """An unknown effect or effect parameter (the message lists the known ones)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


@dataclass(frozen=True)
class EffectSpec:
    """One catalogue entry. ``params`` are field names of ``vehicle.description.Effects``;
    ``neutral``, ``bounds`` (fit bounds, finite) and ``units`` are per parameter.
    ``revealed_by`` names plan segment kinds of :mod:`simrunner.workflows.excite`;
    ``observed_by`` the gap residual signals (:data:`RESIDUAL_SIGNALS`) in which the effect
    shows, so a log without them cannot reveal it."""

    name: str
    params: tuple[str, ...]
    neutral: tuple[float, ...]
    bounds: tuple[tuple[float, float], ...]
    units: tuple[str, ...]
    meaning: str
    revealed_by: tuple[str, ...]
    observed_by: tuple[str, ...]
    acts_on: str  # "command" | "force" | "build"
    log_scale: bool = False  # the gap fit searches log(value): a factor spanning a decade or more
    # "slip": acts only on a car with wheels.tyre_model = "slip" (else it changes nothing);
    # "speed": only on a speed-commanded car (a duty-driven car drives its two rear motors)
    requires: str = ""

    def applies_to(self, car: CarDescription) -> bool:
        """The effect can act on ``car`` (one whose model has what it changes)."""
        if self.requires == "slip":
            return car.wheels.tyre_model == "slip"
        if self.requires == "speed":
            return car.drive.command == "speed"
        return True

    @property
    def requirement(self) -> str:
        """What a car needs for the effect to act ("" for every car)."""
        needs = {"slip": 'wheels.tyre_model = "slip" (docs/tyres.md)',
                 "speed": 'drive.command = "speed" (a duty-driven car drives its two rear motors)'}
        return needs.get(self.requires, "")


    @property
    def param(self) -> str:
        """The (first and, so far, only) parameter."""
        return self.params[0]


def _spec(name, param, neutral, bounds, unit, meaning, revealed_by, observed_by, acts_on="command",
          log_scale=None, requires="") -> EffectSpec:
    """One-parameter entry; ``log_scale`` defaults to True for a neutral value at infinity
    (a limit that is absent in the nominal model, searched over decades)."""
    return EffectSpec(name, (param,), (neutral,), (bounds,), (unit,), meaning, tuple(revealed_by),
                      tuple(observed_by), acts_on, math.isinf(neutral) if log_scale is None else log_scale, requires)


EFFECTS: dict[str, EffectSpec] = {s.name: s for s in (
    _spec("steering_offset", "steering_offset_rad", 0.0, (-0.1, 0.1), "rad",
          "servo trim: a zero steering command does not point the wheels straight",
          ("straight", "step_steer", "circle"), _LATERAL),
    _spec("steering_gain", "steering_gain", 1.0, (0.5, 1.5), "1",
          "servo/linkage scale: the wheels turn gain x the commanded angle",
          ("circle", "step_steer"), _LATERAL),
    _spec("steering_lag", "steering_lag_s", 0.0, (0.0, 0.3), "s",
          "first-order lag of the steering (servo control loop, linkage compliance)",
          ("step_steer", "chirp"), _LATERAL),
    _spec("steering_rate_limit", "steering_rate_limit_radps", math.inf, (0.5, 20.0), "rad/s",
          "the servo slews slower than the model's servo rate (loaded servo, low voltage)",
          ("step_steer", "chirp"), _LATERAL),
    _spec("command_latency", "command_latency_s", 0.0, (0.0, 0.2), "s",
          "pure delay from a command to the actuators (control loop, PWM update, ESC)",
          ("step_steer", "speed_step", "chirp"), RESIDUAL_SIGNALS),
    _spec("motor_lag", "motor_lag_s", 0.0, (0.0, 1.0), "s",
          "first-order lag of the speed target (motor/ESC speed loop, inertia)",
          ("speed_step", "speed_ramp"), _LONGITUDINAL),
    _spec("throttle_deadband", "throttle_deadband_mps", 0.0, (0.0, 0.5), "m/s",
          "small speed commands do not move the car (ESC neutral band, static friction)",
          ("speed_ramp",), _LONGITUDINAL),
    _spec("rolling_resistance", "rolling_resistance_coeff", 0.0, (0.0, 0.1), "1",
          "constant resisting force c_rr m g (tyre hysteresis, bearings, gears)",
          ("coast",), _LONGITUDINAL, "force"),
    _spec("drag", "drag_coeff_kgpm", 0.0, (0.0, 0.5), "kg/m",
          "resisting force k v^2 (air drag; at these speeds mostly speed-dependent losses)",
          ("coast",), _LONGITUDINAL, "force"),
    _spec("tire_slip", "tire_slip_understeer_radps2pm", 0.0, (0.0, 0.1), "rad/(m/s^2)",
          "understeer from tyre slip angles: the car turns less than the wheels say, more so "
          "at high lateral acceleration", ("circle",), _LATERAL),
    _spec("friction", "friction_scale", 1.0, (0.3, 1.5), "1",
          "grip of the real tyres on the real track relative to wheels.friction_mu",
          ("circle", "tilt test"), _LATERAL, "build"),
    _spec("speed_scale", "speed_scale", 1.0, (0.7, 1.3), "1",
          "ESC/encoder calibration: the car reaches scale x the commanded speed",
          ("straight", "speed_step", "speed_ramp"), _LONGITUDINAL),
    _spec("steering_asymmetry", "steering_asymmetry", 0.0, (-0.3, 0.3), "1",
          "left and right steering differ: left targets x (1 + a), right targets x (1 - a)",
          ("circle", "step_steer", "turn"), _LATERAL),
    _spec("steering_play", "steering_play_rad", 0.0, (0.0, 0.06), "rad",
          "backlash of the steering linkage: after a reversal the wheels stay put until the "
          "servo has crossed the slack 2 b", ("chirp", "random_steer", "step_steer"), _LATERAL),
    _spec("esc_brake_reverse", "esc_reverse_delay_s", 0.0, (0.0, 1.0), "s",
          "a car ESC with brake: a negative command while rolling forward brakes to rest and "
          "reverses only after a hold time at rest", ("reverse",), _LONGITUDINAL),
    _spec("accel_scale", "accel_scale", 1.0, (0.1, 2.0), "1",
          "the car file's drive.max_accel_mps2 is off by this factor (motor torque, battery)",
          ("speed_step",), _LONGITUDINAL, "build", log_scale=True),
    _spec("brake_scale", "brake_scale", 1.0, (0.1, 2.0), "1",
          "the car file's drive.max_brake_mps2 is off by this factor (ESC brake strength)",
          ("brake", "speed_step"), _LONGITUDINAL, "build", log_scale=True),
    _spec("servo_rate_scale", "servo_rate_scale", 1.0, (0.1, 2.0), "1",
          "the car file's steering.rate_radps is off by this factor (servo model, voltage)",
          ("step_steer", "chirp"), _LATERAL, "build"),
    _spec("steer_limit_scale", "steer_limit_scale", 1.0, (0.6, 1.3), "1",
          "the car file's steering.limit_rad is off by this factor (mechanical steering stop)",
          ("circle", "turn"), _LATERAL, "build"),
    _spec("mass_scale", "mass_scale", 1.0, (0.5, 2.0), "1",
          "the car file's masses are off by this factor: with the file's drive and brake torques "
          "a heavier car speeds up and brakes more slowly (and drag slows it less)",
          ("speed_step", "brake"), _LONGITUDINAL, "build"),
    _spec("top_speed", "top_speed_mps", math.inf, (0.3, 10.0), "m/s",
          "the car tops out below the commanded speed (ESC speed limit, gearing, battery): speed "
          "commands are capped at this magnitude",
          ("straight", "speed_step", "speed_ramp"), _LONGITUDINAL),
    _spec("lift_lag", "lift_lag_s", 0.0, (0.0, 3.0), "s",
          "an ESC that coasts or drag-brakes when the throttle is lifted: slowing to a lower forward "
          "command follows a first-order lag (a zero or negative command still brakes)",
          ("speed_step",), _LONGITUDINAL),
    _spec("front_drive", "front_share_shift", 0.0, (-0.5, 0.5), "1",
          "the car drives and brakes its front wheels too (four-wheel drive): the front share of the "
          "torque is the car file's drive.front_share + this; shows where the tyres near their grip",
          ("brake", "speed_step"), RESIDUAL_SIGNALS, "build", requires="speed"),
    _spec("inertia", "inertia_scale", 1.0, (0.2, 2.0), "1",
          "the chassis's moments of inertia differ from those of the model's uniform box (mass near "
          "the centre: < 1); shows only where the tyres slide, in how fast the yaw rate changes",
          ("circle", "turn", "step_steer"), _LATERAL, "build", log_scale=True),
    # the slip tyres' own numbers (wheels.tyre_model = "slip", docs/tyres.md; Pacejka 2012)
    _spec("tyre_stiffness", "tyre_stiffness_scale", 1.0, (0.25, 4.0), "1",
          "the tyres' cornering stiffness differs from the car file's (both axles): softer tyres slip "
          "more, the car turns less for its steering, more so at speed", ("circle", "turn", "step_steer"),
          _LATERAL, "build", log_scale=True, requires="slip"),
    _spec("tyre_balance", "tyre_balance", 0.0, (-0.5, 0.5), "1",
          "the front and rear tyres' stiffness balance differs from the car file's (front x (1 + b), rear "
          "x (1 - b)): the car understeers (b < 0) or oversteers (b > 0) more than the file says",
          ("circle", "turn"), _LATERAL, "build", requires="slip"),
    _spec("tyre_relaxation", "tyre_relaxation_scale", 1.0, (0.2, 5.0), "1",
          "the tyres build up their force over a longer (or shorter) roll than the car file's relaxation "
          "length: the lateral response lags more at low speed", ("step_steer", "chirp"), _LATERAL, "build",
          log_scale=True, requires="slip"),
)}

_DYNAMIC_PARAMS = ("steering_lag_s", "command_latency_s", "motor_lag_s", "lift_lag_s", "tire_slip_understeer_radps2pm",
                   "rolling_resistance_coeff", "drag_coeff_kgpm")


def active_effects(car: CarDescription) -> list[str]:
    """Names of the effects whose parameters differ from neutral, in catalogue order."""
    eff = car.effects
    return [s.name for s in EFFECTS.values()
            if any(getattr(eff, p) != n for p, n in zip(s.params, s.neutral))]


def is_neutral(car: CarDescription) -> bool:
    return not active_effects(car)


def with_effects(car: CarDescription, **params: float) -> CarDescription:
    """A copy of ``car`` with ``car.effects`` fields replaced (keys are Effects field names,
    e.g. ``with_effects(car, motor_lag_s=0.1)``). Unknown names raise :class:`EffectError`."""
    known = {f.name for f in dataclasses.fields(Effects)}
    bad = sorted(set(params) - known)
    if bad:
        raise EffectError(f"unknown effect parameter(s) {', '.join(bad)} (expected one of {', '.join(sorted(known))})")
    return car.replace(effects=dataclasses.replace(car.effects, **{k: float(v) for k, v in params.items()}))


def neutral_car(car: CarDescription) -> CarDescription:
    """``car`` with every effect neutral."""
    return car.replace(effects=Effects())


def built_car(car: CarDescription) -> CarDescription:
    """The car the physics is built from: the car file's numbers times the build-time scale
    factors (``car`` itself when they are all 1). ``wheels.friction_mu`` x ``friction_scale``;
    ``drive.max_speed_mps`` x ``speed_scale`` (a duty-driven car's ``motor_back_emf_nspm`` / it:
    its top speed; its duty is not scaled); ``drive.max_accel_mps2`` x ``accel_scale /
    mass_scale`` and ``max_brake_mps2`` x ``brake_scale / mass_scale``; ``steering.rate_radps``
    x ``servo_rate_scale``; ``steering.limit_rad`` x ``steer_limit_scale``; ``chassis.mass_kg``
    and ``wheels.mass_kg`` x ``mass_scale`` (all inertias follow the masses). ``CarSim`` sets
    the drive and brake torques from the built mass and limits, so with ``mass_scale`` they
    stay those of the file's numbers. ``drive.front_share`` + ``front_share_shift``, clamped to
    [0, 1]. ``wheels.cornering_stiffness_front_per_rad`` x ``tyre_stiffness_scale (1 + tyre_balance)``,
    the rear's x ``tyre_stiffness_scale (1 - tyre_balance)``, ``wheels.relaxation_length_m`` x
    ``tyre_relaxation_scale`` (they act on slip tyres only). A duty-driven car's ``motor_force_n`` and
    ``motor_back_emf_nspm`` x ``accel_scale``
    (derived from the limits when 0, they follow them). A scaled steering limit above the description's range raises
    ``CarDescriptionError``."""
    e = car.effects
    if (e.friction_scale == e.speed_scale == e.accel_scale == e.brake_scale == e.servo_rate_scale
            == e.steer_limit_scale == e.mass_scale == e.tyre_stiffness_scale == e.tyre_relaxation_scale == 1.0
            and e.front_share_shift == e.tyre_balance == 0.0):
        return car
    ch, wh, st, dr = car.chassis, car.wheels, car.steering, car.drive
    m = e.mass_scale
    if e.friction_scale != 1.0:
        wh = dataclasses.replace(wh, friction_mu=wh.friction_mu * e.friction_scale)
    if m != 1.0:
        ch = dataclasses.replace(ch, mass_kg=ch.mass_kg * m)
        wh = dataclasses.replace(wh, mass_kg=wh.mass_kg * m)
    if e.speed_scale != 1.0:
        dr = dataclasses.replace(dr, max_speed_mps=dr.max_speed_mps * e.speed_scale)
        if dr.motor_back_emf_nspm:  # duty drive: the top speed c1 / c2 scales
            dr = dataclasses.replace(dr, motor_back_emf_nspm=dr.motor_back_emf_nspm / e.speed_scale)
    if e.accel_scale != 1.0 or m != 1.0:
        dr = dataclasses.replace(dr, max_accel_mps2=dr.max_accel_mps2 * e.accel_scale / m)
        if e.accel_scale != 1.0 and (dr.motor_force_n or dr.motor_back_emf_nspm):  # duty: force x a, top speed kept
            dr = dataclasses.replace(dr, motor_force_n=dr.motor_force_n * e.accel_scale,
                                     motor_back_emf_nspm=dr.motor_back_emf_nspm * e.accel_scale)
    if e.brake_scale != 1.0 or m != 1.0:
        dr = dataclasses.replace(dr, max_brake_mps2=dr.max_brake_mps2 * e.brake_scale / m)
    if e.front_share_shift != 0.0:
        dr = dataclasses.replace(dr, front_share=min(max(dr.front_share + e.front_share_shift, 0.0), 1.0))
    if e.tyre_stiffness_scale != 1.0 or e.tyre_balance != 0.0:
        wh = dataclasses.replace(
            wh, cornering_stiffness_front_per_rad=wh.cornering_stiffness_front_per_rad * e.tyre_stiffness_scale
            * (1.0 + e.tyre_balance),
            cornering_stiffness_rear_per_rad=wh.cornering_stiffness_rear_per_rad * e.tyre_stiffness_scale
            * (1.0 - e.tyre_balance))
    if e.tyre_relaxation_scale != 1.0:
        wh = dataclasses.replace(wh, relaxation_length_m=wh.relaxation_length_m * e.tyre_relaxation_scale)
    if e.servo_rate_scale != 1.0:
        st = dataclasses.replace(st, rate_radps=st.rate_radps * e.servo_rate_scale)
    if e.steer_limit_scale != 1.0:
        st = dataclasses.replace(st, limit_rad=st.limit_rad * e.steer_limit_scale)
        hi = next(f for f in dataclasses.fields(Steering) if f.name == "limit_rad").metadata["hi"]
        if st.limit_rad > hi:
            raise CarDescriptionError(
                f"{car.name}: effects.steer_limit_scale = {e.steer_limit_scale!r} makes steering.limit_rad "
                f"{st.limit_rad:.4g} rad: expected at most {hi} rad")
    return car.replace(chassis=ch, wheels=wh, steering=st, drive=dr)


def make_sim(car: CarDescription, **carsim_kwargs: Any):
    """The simulator for ``car``: a plain ``CarSim`` when all effects are neutral, else an
    :class:`EffectSim` (same interface). ``carsim_kwargs`` go to ``CarSim`` (dt_s, start,
    surface_z_m, slope_rad, ground_mu, terrain)."""
    if is_neutral(car):
        return CarSim(car, **carsim_kwargs)
    return EffectSim(car, **carsim_kwargs)


class EscMode(enum.Enum):
    """State of the ESC brake-before-reverse logic (``esc_brake_reverse``)."""

    DRIVE = "drive"  # commands pass (forward, or no negative command yet)
    BRAKE = "brake"  # a negative command arrived while rolling forward: brake to rest, hold
    REVERSE = "reverse"  # negative commands pass


@dataclass(frozen=True)
class _FilterState:
    """The command-path state of an EffectSim (saved with the physics state)."""

    raw: tuple[float, float, float | None, bool]  # speed, steer, yaw rate, coast (as commanded)
    coast_on: bool  # coasting applied to the inner CarSim
    sent: tuple | None  # the last command passed to the inner CarSim
    queue: tuple  # pending (t_effective_s, raw) for the latency
    held: tuple[float, float, float | None, bool]  # the delayed command in force
    steer_lag: float
    steer_rl: float
    speed_lag: float
    last_t: float
    substep: int  # physics steps since the last sub-step boundary
    play: float  # output of the steering play (backlash)
    esc: tuple[EscMode, float | None]  # ESC mode, time the car came to rest while braking


@dataclass(frozen=True)
class EffectSimState:
    """Opaque snapshot for :meth:`EffectSim.restore_state` (bit-exact)."""

    inner: Any
    filt: _FilterState
    user_force_n: tuple[float, float]


class EffectSim:
    """A ``CarSim`` with ``car.effects`` applied (module docstring). Same interface as
    ``CarSim``; everything not overridden here is the inner ``CarSim``'s (``self.sim``)."""

    def __init__(self, car: CarDescription, **carsim_kwargs: Any):
        self.car = car
        self.built = built_car(car)  # the physical car (the car file's numbers x build-time scales)
        self.sim = CarSim(self.built, **carsim_kwargs)
        e = car.effects
        self._e = e
        self._dynamic = any(getattr(e, p) != getattr(Effects, p) for p in _DYNAMIC_PARAMS) or (
            e.steering_rate_limit_radps != math.inf)
        self._forces = e.rolling_resistance_coeff != 0.0 or e.drag_coeff_kgpm != 0.0
        self.n_sub = control_steps(self.sim.dt_s)
        self._user_force = (0.0, 0.0)
        raw = (0.0, 0.0, None, False)
        self._raw = raw
        self._queue: deque = deque()
        self._held = raw
        self._mapped: tuple = (None, None)  # (held command, its _static_map), see _update
        self._steer_lag = self._steer_rl = self._speed_lag = 0.0
        self._last_t = self.sim.time_s
        self._substep = 0
        self._coast_on = False
        self._sent: tuple | None = None  # the last command passed to the inner CarSim
        self._play = 0.0
        self._esc: tuple[EscMode, float | None] = (EscMode.DRIVE, None)

    # -- read-outs: the inner CarSim's (the effects act on its inputs) ----------------------
    @property
    def time_s(self) -> float:
        return self.sim.time_s

    @property
    def dt_s(self) -> float:
        return self.sim.dt_s

    @property
    def pose(self) -> Pose2:
        return self.sim.pose

    @property
    def pose3(self):
        return self.sim.pose3

    def wheel_angles_rad(self) -> list[float]:
        return self.sim.wheel_angles_rad()

    def wheel_angle_rad(self, i: int) -> float:
        return self.sim.wheel_angle_rad(i)

    def set_motors(self, left: float, right: float) -> None:
        """As ``CarSim.set_motors``, straight to the car (the command-path effects act on
        set_command)."""
        self.sim.set_motors(left, right)

    @property
    def duties(self) -> tuple[float, float]:
        return self.sim.duties

    @property
    def duty_cmd(self) -> float:
        return self.sim.duty_cmd

    def imu_truth(self, point_m):
        return self.sim.imu_truth(point_m)

    def imu_reader(self, point_m):
        return self.sim.imu_reader(point_m)

    @property
    def terrain(self):
        return self.sim.terrain

    @property
    def z_m(self) -> float:
        return self.sim.z_m

    @property
    def roll_rad(self) -> float:
        return self.sim.roll_rad

    @property
    def pitch_rad(self) -> float:
        return self.sim.pitch_rad

    @property
    def speed_mps(self) -> float:
        return self.sim.speed_mps

    @property
    def lateral_speed_mps(self) -> float:
        return self.sim.lateral_speed_mps

    @property
    def steer_rad(self) -> float:
        """Actual effective (bicycle-equivalent) steering angle, rad: after all effects."""
        return self.sim.steer_rad

    @property
    def yaw_rate_radps(self) -> float:
        return self.sim.yaw_rate_radps

    def knuckle_angles_rad(self) -> tuple[float, float]:
        return self.sim.knuckle_angles_rad()

    def wheel_contacts(self) -> list[tuple[float, float]]:
        return self.sim.wheel_contacts()

    def wheel_contacts_xy(self):
        return self.sim.wheel_contacts_xy()

    def wheel_speeds_radps(self):
        return self.sim.wheel_speeds_radps()

    @property
    def yaw_rate_cmd_radps(self) -> float:
        """The differential yaw rate the inner car applies (after the effects), rad/s."""
        return self.sim.yaw_rate_cmd_radps

    def set_wheel_lock(self, locked: bool) -> None:
        """As ``CarSim.set_wheel_lock`` (tilt test); not part of the command path."""
        self.sim.set_wheel_lock(locked)

    @property
    def speed_cmd_mps(self) -> float:
        """The speed command as given (clamped to the car's limits like CarSim), m/s."""
        return float(min(max(self._raw[0], -self.car.drive.max_speed_mps), self.car.drive.max_speed_mps))

    @property
    def steer_cmd_rad(self) -> float:
        """The steering command as given (clamped to the limit like CarSim), rad."""
        lim = self.car.steering.limit_rad
        return float(min(max(self._raw[1], -lim), lim))

    @property
    def coast(self) -> bool:
        """Coasting as commanded (before latency and deadband)."""
        return self._raw[3]

    # -- commands ------------------------------------------------------------------------
    def set_command(self, speed_mps: float, steer_rad: float, yaw_rate_radps: float | None = None) -> None:
        """Commands as for ``CarSim.set_command`` (coasting, if on, stays on)."""
        self._command((float(speed_mps), float(steer_rad),
                       None if yaw_rate_radps is None else float(yaw_rate_radps), self._raw[3]))

    def set_coast(self, coast: bool) -> None:
        """As ``CarSim.set_coast``: no drive torque while on; it passes the command path
        (latency) like any command. The speed/steering commands are kept."""
        s, d, w, _ = self._raw
        self._command((s, d, w, bool(coast)))

    def _command(self, raw) -> None:
        self._raw = raw
        if self._e.command_latency_s > 0.0:
            self._queue.append((self.sim.time_s + self._e.command_latency_s, raw))
        else:
            self._held = raw
        self._update(user=True)

    def apply_external_force_n(self, fx_n: float, fy_n: float) -> None:
        """A user force on the chassis (car body frame, N), added to the effect forces."""
        self._user_force = (float(fx_n), float(fy_n))
        self._apply_forces()

    def _static_map(self, cmd) -> tuple[float, float, float | None, bool]:
        """Gain, offset, asymmetry, deadband, speed scale and top speed (no state)."""
        e = self._e
        v, d, w, coast = cmd
        d = e.steering_gain * d + e.steering_offset_rad
        if e.steering_asymmetry != 0.0:
            d *= (1.0 + e.steering_asymmetry) if d > 0.0 else (1.0 - e.steering_asymmetry)
        if e.throttle_deadband_mps > 0.0 and abs(v) < e.throttle_deadband_mps:
            coast = True
        if e.speed_scale != 1.0 and self.car.drive.command != "duty":  # on the clamped command (the
            vmax = self.car.drive.max_speed_mps                            # physical top speed scales too)
            v = e.speed_scale * min(max(v, -vmax), vmax)
        if e.top_speed_mps != math.inf:
            v = min(max(v, -e.top_speed_mps), e.top_speed_mps)
        return v, d, w, coast

    def _take_up_play(self, d: float) -> float:
        """Backlash of width 2 b: the output stays until the input is more than b away."""
        b, y = self._e.steering_play_rad, self._play
        if d > y + b:
            y = d - b
        elif d < y - b:
            y = d + b
        self._play = y
        return y

    def _esc_target(self, v: float, coast: bool, t: float) -> float:
        """ESC brake-before-reverse: the speed target the motor gets for the command ``v``."""
        if coast or v >= 0.0:  # forward or neutral resets the ESC
            self._esc = (EscMode.DRIVE, None)
            return v
        mode, rest_t = self._esc
        u = self.sim.speed_mps
        if mode is EscMode.DRIVE:
            mode = EscMode.BRAKE if u > ESC_REST_MPS else EscMode.REVERSE
        if mode is EscMode.BRAKE:
            if abs(u) > ESC_REST_MPS:
                rest_t = None
            elif rest_t is None:
                rest_t = t
            if rest_t is None or t - rest_t < self._e.esc_reverse_delay_s - 1e-9:
                self._esc = (mode, rest_t)
                return 0.0
            mode = EscMode.REVERSE
        self._esc = (mode, None)
        return v

    def _update(self, user: bool = False) -> None:
        """One control update at the current time (all effects of the command path); ``user``:
        called by a command (without filtered effects it is passed on even if unchanged, as
        CarSim would get it)."""
        e, sim = self._e, self.sim
        t = sim.time_s
        dt = t - self._last_t
        self._last_t = t
        q = self._queue
        while q and q[0][0] <= t + 1e-9:
            self._held = q.popleft()[1]
        held = self._held
        if held is not self._mapped[0]:  # a pure function of the held command: mapped once per command
            self._mapped = (held, self._static_map(held))
        v, d, w_cmd, coast = self._mapped[1]
        if e.esc_reverse_delay_s > 0.0:
            v = self._esc_target(v, coast, t)
        if self._dynamic:
            if e.steering_lag_s > 0.0:
                self._steer_lag += -math.expm1(-dt / e.steering_lag_s) * (d - self._steer_lag)
            else:
                self._steer_lag = d
            if e.steering_rate_limit_radps != math.inf:
                step = e.steering_rate_limit_radps * dt
                self._steer_rl += min(max(self._steer_lag - self._steer_rl, -step), step)
            else:
                self._steer_rl = self._steer_lag
            d = self._steer_rl
            if e.steering_play_rad > 0.0:
                d = self._take_up_play(d)
            if e.tire_slip_understeer_radps2pm > 0.0:
                u = sim.speed_mps
                d = d / (1.0 + e.tire_slip_understeer_radps2pm * u * u / self.car.chassis.wheelbase_m)
            target_v = 0.0 if coast else v
            if coast:  # the speed loop restarts from the actual speed when the drive re-engages
                self._speed_lag = sim.speed_mps
            else:
                tau = e.motor_lag_s
                if e.lift_lag_s > 0.0 and 0.0 < target_v < self._speed_lag:  # a throttle lift
                    tau = max(tau, e.lift_lag_s)
                if tau > 0.0:
                    self._speed_lag += -math.expm1(-dt / tau) * (target_v - self._speed_lag)
                else:
                    self._speed_lag = target_v
            v_eff = self._speed_lag
        else:
            if e.steering_play_rad > 0.0:
                d = self._take_up_play(d)
            v_eff = v
        w = None
        if w_cmd is not None:
            # keep the caller's deviation from the default differential (of the command as
            # given, clamped to the car file's limits); the default part follows the effective
            # speed and steering, clamped to the physical limits
            lim, wb, vmax = self.car.steering.limit_rad, self.car.chassis.wheelbase_m, self.car.drive.max_speed_mps
            v0, d0 = min(max(self._held[0], -vmax), vmax), min(max(self._held[1], -lim), lim)
            lim1, vmax1 = self.built.steering.limit_rad, self.built.drive.max_speed_mps
            v_eff = min(max(v_eff, -vmax1), vmax1)
            d1 = min(max(d, -lim1), lim1)
            w = w_cmd + (v_eff * math.sin(d1) - v0 * math.sin(d0)) / wb
        sent = (v_eff, d, w)
        if sent != self._sent or (user and not self._dynamic):
            # an unchanged command is not re-sent: CarSim keeps its targets (as without effects)
            sim.set_command(v_eff, d, w)
            self._sent = sent
        if coast != self._coast_on:
            self._coast_on = coast
            sim.set_coast(coast)
        if self._forces:
            self._apply_forces()

    def _apply_forces(self) -> None:
        e, sim = self._e, self.sim
        fx, fy = self._user_force
        if self._forces:
            vx, vy = sim.speed_mps, sim.lateral_speed_mps
            if e.rolling_resistance_coeff > 0.0:
                f_rr = e.rolling_resistance_coeff * self.built.chassis.mass_kg * GRAVITY_MPS2
                fx -= f_rr * min(max(vx / ROLL_EPS_MPS, -1.0), 1.0)
            if e.drag_coeff_kgpm > 0.0:
                speed = math.hypot(vx, vy)
                fx -= e.drag_coeff_kgpm * speed * vx
                fy -= e.drag_coeff_kgpm * speed * vy
        sim.apply_external_force_n(fx, fy)

    # -- stepping ------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps; filtered effects (and the ESC while it brakes) update
        every ``n_sub`` steps."""
        if not (self._dynamic or self._forces or self._esc[0] is EscMode.BRAKE):
            self.sim.step(n)
            return
        n = int(n)
        while n > 0:
            k = min(n, self.n_sub - self._substep)
            self.sim.step(k)
            n -= k
            self._substep += k
            if self._substep >= self.n_sub:
                self._substep = 0
                self._update()

    # -- state ---------------------------------------------------------------------------
    def save_state(self) -> EffectSimState:
        filt = _FilterState(self._raw, self._coast_on, self._sent, tuple(self._queue), self._held, self._steer_lag,
                            self._steer_rl, self._speed_lag, self._last_t, self._substep, self._play, self._esc)
        return EffectSimState(self.sim.save_state(), filt, self._user_force)

    def restore_state(self, state: EffectSimState) -> None:
        self.sim.restore_state(state.inner)
        f = state.filt
        self._raw, self._queue, self._held = f.raw, deque(f.queue), f.held
        self._steer_lag, self._steer_rl, self._speed_lag = f.steer_lag, f.steer_rl, f.speed_lag
        self._last_t, self._substep = f.last_t, f.substep
        self._play, self._esc = f.play, f.esc
        self._user_force = state.user_force_n
        self._coast_on = f.coast_on  # the inner state restores the inner coasting itself
        self._sent = f.sent

    def place(self, pose: Pose2, speed_mps: float, steer_rad: float = 0.0,
              yaw_rate_radps: float = 0.0) -> None:
        """Move the car to a planar state (``CarSim.place``) and keep the command path as it
        is: pending latency, lag, rate-limit, play and ESC states and the command in force. The gap
        replay calls it after a lead-in that replayed the commands before a window."""
        self.sim.place(pose, speed_mps, steer_rad, yaw_rate_radps)
        if self._forces:
            self._apply_forces()

    def add_solid(self, solid) -> None:
        """The inner CarSim's (:meth:`CarSim.add_solid`)."""
        self.sim.add_solid(solid)

    def touched_solids(self) -> tuple[str, ...]:
        """The inner CarSim's (:meth:`CarSim.touched_solids`)."""
        return self.sim.touched_solids()

    def prime_steering(self, t_s, steer_cmd_rad) -> None:
        """Bring the steering path's state to where earlier steering commands leave it:
        ``steer_cmd_rad[k]`` held from ``t_s[k]`` to ``t_s[k + 1]`` (one more time than
        commands), through gain, offset, asymmetry, lag, rate limit and play (latency
        ignored), from the states :meth:`set_state` left (those of the measured angle). Only
        the steering play needs it: which side of its band the output rests on is remembered
        for as long as the commands stay inside the band, and a measured angle (noisy, or
        inside the band) does not say it; commands that cross the band do. Without a play
        nothing changes. The gap replay calls it after :meth:`set_state`."""
        e = self._e
        if e.steering_play_rad <= 0.0:
            return
        b = e.steering_play_rad
        lag, rl, y = self._steer_lag, self._steer_rl, self._play
        for k, cmd in enumerate(steer_cmd_rad):
            d = self._static_map((0.0, float(cmd), None, False))[1]
            dt = float(t_s[k + 1]) - float(t_s[k])
            lag = lag - math.expm1(-dt / e.steering_lag_s) * (d - lag) if e.steering_lag_s > 0.0 else d
            if e.steering_rate_limit_radps != math.inf:
                step = e.steering_rate_limit_radps * dt
                rl += min(max(lag - rl, -step), step)
            else:
                rl = lag
            y = rl - b if rl > y + b else rl + b if rl < y - b else y
        self._steer_lag, self._steer_rl, self._play = lag, rl, y

    def set_state(self, pose: Pose2, speed_mps: float, steer_rad: float = 0.0,
                  yaw_rate_radps: float = 0.0) -> None:
        """Place the car (as ``CarSim.set_state``: ``steer_rad`` is the actual wheel angle).
        The command path restarts settled at that state: no pending latency, the lag,
        rate-limit and play states at the values that give ``steer_rad`` and ``speed_mps``, the
        ESC driving (reversing if ``speed_mps < 0``), and the held command the one that keeps
        them (steer undone through understeer, asymmetry, offset and gain; speed through the
        speed scale), so a following identical command changes nothing."""
        e = self._e
        self.sim.set_state(pose, speed_mps, steer_rad, yaw_rate_radps)
        pre = float(steer_rad) * (1.0 + e.tire_slip_understeer_radps2pm * float(speed_mps) ** 2
                                  / self.car.chassis.wheelbase_m)
        d = pre
        if e.steering_asymmetry != 0.0:
            d /= (1.0 + e.steering_asymmetry) if d > 0.0 else (1.0 - e.steering_asymmetry)
        v = float(speed_mps) / e.speed_scale if e.speed_scale != 1.0 else float(speed_mps)
        raw = (v, (d - e.steering_offset_rad) / e.steering_gain, None, self._raw[3])
        self._raw = self._held = raw
        self._queue.clear()
        self._steer_lag = self._steer_rl = self._play = pre
        self._esc = (EscMode.REVERSE if speed_mps < 0.0 else EscMode.DRIVE, None)
        self._sent = None
        self._speed_lag = float(speed_mps)
        self._last_t = self.sim.time_s
        if self._forces:
            self._apply_forces()
