"""Effects catalogue: neutral == nominal bit for bit; each effect changes what it should."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.car.effects import EFFECTS, EffectSim, active_effects, make_sim, with_effects
from simrunner.car.physics import CarSim
from vehicle.description import CarDescription, Effects

CAR = CarDescription()
WB = CAR.chassis.wheelbase_m

NAMES = ["steering_offset", "steering_gain", "steering_lag", "steering_rate_limit", "command_latency",
         "motor_lag", "throttle_deadband", "rolling_resistance", "drag", "tire_slip", "friction"]


def trace(sim, commands, seconds: float, every: int = 10) -> np.ndarray:
    """Run ``commands(t) -> (speed, steer[, yaw_rate])`` every ``every`` steps; rows of
    (t, x, y, yaw, speed, steer) after each step."""
    rows = []
    for k in range(round(seconds / sim.dt_s)):
        if k % every == 0:
            sim.set_command(*commands(sim.time_s))
        sim.step(1)
        p = sim.pose
        rows.append((sim.time_s, p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, sim.steer_rad))
    return np.array(rows)


def test_catalogue_names_and_fields():
    assert list(EFFECTS) == NAMES
    defaults = Effects()
    for spec in EFFECTS.values():
        for param, neutral, (lo, hi) in zip(spec.params, spec.neutral, spec.bounds):
            assert getattr(defaults, param) == neutral, spec.name
            assert math.isfinite(lo) and math.isfinite(hi) and lo < hi
        assert spec.meaning and spec.revealed_by and spec.acts_on in ("command", "force", "build")
    assert {f.name for f in dataclasses.fields(Effects)} == {p for s in EFFECTS.values() for p in s.params}


def test_neutral_is_plain_carsim_and_bit_identical():
    assert type(make_sim(CAR)) is CarSim and active_effects(CAR) == []

    def cmd(t):  # speed and steering changes, an explicit differential part of the time
        return (1.5, 0.25, 1.5 * math.sin(0.25) / WB + 0.1) if t > 0.6 else (1.0 + t, -0.1 * t)
    a = trace(CarSim(CAR), cmd, 1.2)
    b = trace(EffectSim(CAR), cmd, 1.2)
    assert np.array_equal(a, b)


def test_with_effects_rejects_unknown_names():
    with pytest.raises(KeyError, match="steering_ofset"):
        with_effects(CAR, steering_ofset=0.1)


def test_deterministic_and_state_restore_bit_exact():
    car = with_effects(CAR, command_latency_s=0.05, steering_lag_s=0.05, motor_lag_s=0.1, drag_coeff_kgpm=0.1)

    def cmd(t):
        return (1.2, 0.2 if t > 0.3 else -0.1)
    a = trace(EffectSim(car), cmd, 0.8)
    assert np.array_equal(a, trace(EffectSim(car), cmd, 0.8))
    sim = EffectSim(car)
    trace(sim, cmd, 0.4)
    saved = sim.save_state()
    first = trace(sim, cmd, 0.4)
    sim.restore_state(saved)
    assert np.array_equal(first, trace(sim, cmd, 0.4))


def test_steering_offset_curves_a_zero_steer_run():
    sim = make_sim(with_effects(CAR, steering_offset_rad=0.05))
    sim.set_state(Pose2(), 1.0)
    rows = trace(sim, lambda t: (1.0, 0.0), 1.0)
    expected_yaw = 1.0 * math.tan(0.05) / WB * 1.0  # kinematic; the servo needs ~8 ms
    assert rows[-1, 3] == pytest.approx(expected_yaw, rel=0.05)
    assert rows[-1, 2] > 0.1  # drifted left
    nominal = CarSim(CAR)
    nominal.set_state(Pose2(), 1.0)
    assert abs(trace(nominal, lambda t: (1.0, 0.0), 1.0)[-1, 3]) < 1e-6


def test_steering_gain_scales_the_wheel_angle():
    rows = trace(make_sim(with_effects(CAR, steering_gain=0.6)), lambda t: (0.5, 0.25), 0.4)
    assert rows[-1, 5] == pytest.approx(0.6 * 0.25, rel=0.01)


def test_steering_lag_reaches_63_percent_at_tau():
    tau = 0.1
    sim = make_sim(with_effects(CAR, steering_lag_s=tau))
    sim.set_state(Pose2(), 0.5)
    rows = trace(sim, lambda t: (0.5, 0.1), 0.3)
    at_tau = rows[np.searchsorted(rows[:, 0], tau - 1e-9), 5]
    assert at_tau / 0.1 == pytest.approx(1.0 - math.exp(-1.0), abs=0.05)  # servo + sub-step: ~2 %
    assert rows[-1, 5] == pytest.approx(0.1 * (1.0 - math.exp(-3.0)), abs=0.005)


def test_steering_rate_limit_slows_the_servo():
    sim = make_sim(with_effects(CAR, steering_rate_limit_radps=1.0))
    rows = trace(sim, lambda t: (0.5, 0.3), 0.4)
    half = rows[np.searchsorted(rows[:, 0], 0.15 - 1e-9), 5]
    assert half == pytest.approx(0.15, abs=0.01)  # 1 rad/s instead of the servo's 6 rad/s
    assert rows[-1, 5] == pytest.approx(0.3, abs=1e-6)


def _crossing_time(rows, col, level):
    i = int(np.argmax(rows[:, col] > level))
    assert rows[i, col] > level
    return rows[i, 0]


def test_command_latency_delays_a_speed_step_by_the_latency():
    def step_run(car):
        sim = make_sim(car)
        sim.set_state(Pose2(), 1.0)
        return trace(sim, lambda t: (1.2, 0.0) if t >= 0.1 - 1e-9 else (1.0, 0.0), 0.5, every=1)
    t_nom = _crossing_time(step_run(CAR), 4, 1.1)
    sim_car = with_effects(CAR, command_latency_s=0.1)
    t_lat = _crossing_time(step_run(sim_car), 4, 1.1)
    sim = EffectSim(sim_car)
    sub_step = sim.n_sub * sim.dt_s  # the latency is resolved to the control sub-step
    assert 0.1 - 1e-9 <= t_lat - t_nom <= 0.1 + sub_step + 1e-9


def test_motor_lag_gives_first_order_speed_rise():
    tau = 0.2
    sim = make_sim(with_effects(CAR, motor_lag_s=tau))
    sim.set_state(Pose2(), 1.0)
    t0 = sim.time_s
    rows = trace(sim, lambda t: (1.2, 0.0), 0.6)  # 1 m/s^2 at most: below the accel limit
    rise = (rows[np.searchsorted(rows[:, 0], t0 + tau - 1e-9), 4] - 1.0) / 0.2
    assert rise == pytest.approx(1.0 - math.exp(-1.0), abs=0.04)
    nominal = CarSim(CAR)
    nominal.set_state(Pose2(), 1.0)
    fast = trace(nominal, lambda t: (1.2, 0.0), 0.6)
    assert (fast[np.searchsorted(fast[:, 0], t0 + tau - 1e-9), 4] - 1.0) / 0.2 > 0.97


def test_throttle_deadband_keeps_small_commands_still():
    sim = make_sim(with_effects(CAR, throttle_deadband_mps=0.3))
    rows = trace(sim, lambda t: (0.25, 0.0), 0.5)
    assert abs(rows[-1, 1]) < 1e-3  # no drive below the deadband
    rows = trace(sim, lambda t: (0.5, 0.0), 0.5)
    assert rows[-1, 4] == pytest.approx(0.5, abs=0.01)  # above it: as commanded


def coast_down(car, seconds=1.0):
    sim = make_sim(car)
    sim.set_state(Pose2(), 2.0)
    sim.set_coast(True)
    sim.step(round(seconds / sim.dt_s))
    return sim.pose.x_m, sim.speed_mps


def test_rolling_resistance_and_drag_shorten_the_coast_down():
    m_eff = CAR.chassis.mass_kg + 4 * 0.5 * CAR.wheels.mass_kg  # spinning wheels (I = m r^2 / 2)
    x0, v0 = coast_down(CAR)
    assert v0 == pytest.approx(2.0, abs=0.005)  # nominal: no losses
    x_rr, v_rr = coast_down(with_effects(CAR, rolling_resistance_coeff=0.05))
    assert v_rr == pytest.approx(2.0 - 0.05 * 9.81 * CAR.chassis.mass_kg / m_eff, abs=0.02)
    x_d, v_d = coast_down(with_effects(CAR, drag_coeff_kgpm=0.2))
    assert v_d == pytest.approx(1.0 / (1.0 / 2.0 + 0.2 / m_eff), abs=0.02)  # m dv/dt = -k v^2
    assert x_rr < x0 - 0.1 and x_d < x0 - 0.1


def test_tire_slip_understeers_more_at_speed():
    k = 0.02

    def yaw_rate(car, v):
        sim = make_sim(car)
        sim.set_state(Pose2(), v)
        trace(sim, lambda t: (v, 0.2), 0.6)
        return sim.yaw_rate_radps
    slow, fast = 0.5, 1.5
    for v in (slow, fast):
        ratio = yaw_rate(with_effects(CAR, tire_slip_understeer_radps2pm=k), v) / yaw_rate(CAR, v)
        assert ratio == pytest.approx(1.0 / (1.0 + k * v * v / WB), rel=0.03)


@pytest.mark.parametrize("deg", [40.0, 43.0])
def test_friction_scale_below_one_slides_where_nominal_holds(deg):
    def slid_m(car):
        sim = make_sim(car, slope_rad=math.radians(deg))
        sim.set_wheel_lock(True)
        sim.step(400)
        return math.hypot(sim.pose.x_m, sim.pose.y_m)
    assert slid_m(CAR) < 1e-4  # mu = 1: holds below 45 deg
    assert slid_m(with_effects(CAR, friction_scale=0.8)) > 0.05  # mu 0.8: slides above 38.7 deg


def test_set_state_starts_settled_at_the_given_state():
    car = with_effects(CAR, steering_offset_rad=0.05, steering_gain=0.8, steering_lag_s=0.1, motor_lag_s=0.2,
                       command_latency_s=0.05, tire_slip_understeer_radps2pm=0.02)
    sim = make_sim(car)
    sim.set_state(Pose2(1.0, 2.0, 0.3), 1.5, 0.12)
    sim.step(100)
    assert sim.steer_rad == pytest.approx(0.12, abs=1e-4)  # understeer follows the measured speed
    assert sim.speed_mps == pytest.approx(1.5, abs=0.01)


def test_place_moves_the_car_but_keeps_commands_in_flight():
    """The gap replay's lead-in: ``place`` after some commands keeps a latency's pending
    command (``set_state`` would drop it) and re-places only the physical state."""
    car = with_effects(CAR, command_latency_s=0.1)
    sim = make_sim(car)  # dt 2 ms
    sim.set_state(Pose2(), 1.0, 0.0)
    sim.set_command(1.0, 0.2)
    sim.step(25)  # 0.05 s: the new steering is still in the latency queue
    assert sim.sim.steer_cmd_rad == 0.0
    sim.place(Pose2(3.0, 4.0, 0.5), 1.0, 0.0)
    assert (sim.pose.x_m, sim.pose.y_m) == pytest.approx((3.0, 4.0), abs=1e-3)
    sim.step(30)  # 0.06 s later it acts, as if the car had not been moved
    assert sim.sim.steer_cmd_rad == pytest.approx(0.2)
    # a plain CarSim keeps its command through place as well
    plain = make_sim(CAR)
    plain.set_command(0.8, -0.1)
    plain.place(Pose2(1.0, 0.0, 0.0), 0.5, 0.0)
    assert (plain.speed_cmd_mps, plain.steer_cmd_rad) == (0.8, -0.1)
