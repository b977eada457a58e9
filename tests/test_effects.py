"""Effects catalogue: neutral == nominal bit for bit; each effect changes what it should."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.car.effects import (EFFECTS, RESIDUAL_SIGNALS, EffectSim, active_effects, built_car, make_sim,
                                   with_effects)
from simrunner.car.physics import CarSim
from vehicle.description import CarDescription, CarDescriptionError, Effects

CAR = CarDescription()
WB = CAR.chassis.wheelbase_m

NAMES = ["steering_offset", "steering_gain", "steering_lag", "steering_rate_limit", "command_latency",
         "motor_lag", "throttle_deadband", "rolling_resistance", "drag", "tire_slip", "friction",
         "speed_scale", "steering_asymmetry", "steering_play", "esc_brake_reverse", "accel_scale", "brake_scale",
         "servo_rate_scale", "steer_limit_scale", "mass_scale", "top_speed", "lift_lag", "front_drive",
         "inertia", "tyre_stiffness", "tyre_balance", "tyre_relaxation"]


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
        assert spec.observed_by and set(spec.observed_by) <= set(RESIDUAL_SIGNALS), spec.name
    assert {f.name for f in dataclasses.fields(Effects)} == {p for s in EFFECTS.values() for p in s.params}


def test_observed_by_names_the_gap_residual_signals():
    from simrunner.workflows.gap.replay import FIT_SIGNALS
    assert tuple(RESIDUAL_SIGNALS) == tuple(FIT_SIGNALS)
    assert set(EFFECTS["motor_lag"].observed_by) == {"speed_mps", "along_m"}
    assert set(EFFECTS["steering_offset"].observed_by) == {"yaw_rate_radps", "yaw_rad", "cross_m"}


def test_neutral_build_scales_build_the_same_car():
    assert built_car(CAR) is CAR
    with pytest.raises(CarDescriptionError, match=r"steer_limit_scale = 3\.0 .* at most 1\.2"):
        built_car(with_effects(CAR, steer_limit_scale=3.0))


def test_neutral_is_plain_carsim_and_bit_identical():
    assert type(make_sim(CAR)) is CarSim and active_effects(CAR) == []

    def cmd(t):  # speed and steering changes, an explicit differential part of the time
        return (1.5, 0.25, 1.5 * math.sin(0.25) / WB + 0.1) if t > 0.6 else (1.0 + t, -0.1 * t)
    a = trace(CarSim(CAR), cmd, 1.2)
    b = trace(EffectSim(CAR), cmd, 1.2)
    assert np.array_equal(a, b)


def test_esc_delay_without_a_forward_to_reverse_command_is_nominal_bit_for_bit():
    def cmd(t):  # forward, then braking to 0, then reversing from rest: the ESC never intervenes
        return (1.2, 0.2) if t < 0.4 else ((0.0, -0.1) if t < 1.2 else (-0.5, 0.1))
    a = trace(CarSim(CAR), cmd, 1.6)
    assert a[-1, 4] < -0.4
    assert np.array_equal(a, trace(make_sim(with_effects(CAR, esc_reverse_delay_s=0.3)), cmd, 1.6))


def test_with_effects_rejects_unknown_names():
    with pytest.raises(KeyError, match="steering_ofset"):
        with_effects(CAR, steering_ofset=0.1)


@pytest.mark.parametrize("extra", [{}, {"steering_play_rad": 0.03, "esc_reverse_delay_s": 0.1, "speed_scale": 0.9,
                                      "steering_asymmetry": 0.1, "mass_scale": 1.2},
                                     {"front_share_shift": 0.5, "esc_reverse_delay_s": 0.1}])
def test_deterministic_and_state_restore_bit_exact(extra):
    car = with_effects(CAR, command_latency_s=0.05, steering_lag_s=0.05, motor_lag_s=0.1, drag_coeff_kgpm=0.1,
                       **extra)

    def cmd(t):  # forward, a steering reversal, then a reverse command while rolling
        return (1.2 if t < 0.35 else -0.5, 0.2 if t > 0.3 else -0.1)
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


@pytest.mark.parametrize("speed, steer", [(1.5, 0.12), (-0.8, -0.1)])
def test_set_state_starts_settled_at_the_given_state(speed, steer):
    car = with_effects(CAR, steering_offset_rad=0.05, steering_gain=0.8, steering_lag_s=0.1, motor_lag_s=0.2,
                       command_latency_s=0.05, tire_slip_understeer_radps2pm=0.02, steering_asymmetry=0.1,
                       steering_play_rad=0.02, speed_scale=0.9, esc_reverse_delay_s=0.2)
    sim = make_sim(car)
    sim.set_state(Pose2(1.0, 2.0, 0.3), speed, steer)
    sim.step(100)
    assert sim.steer_rad == pytest.approx(steer, abs=1e-4)  # understeer follows the measured speed
    assert sim.speed_mps == pytest.approx(speed, abs=0.01)  # reversing: the ESC stays in reverse
    sim.set_command(sim.speed_cmd_mps, sim.steer_cmd_rad)  # the held command: nothing changes
    sim.step(100)
    assert (sim.steer_rad, sim.speed_mps) == pytest.approx((steer, speed), abs=0.01)


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


def test_speed_scale_scales_the_speed_reached():
    for scale in (0.9, 1.1):
        rows = trace(make_sim(with_effects(CAR, speed_scale=scale)), lambda t: (1.5, 0.0), 2.0)
        assert rows[-1, 4] == pytest.approx(scale * 1.5, abs=0.002)
    top = trace(make_sim(with_effects(CAR, speed_scale=0.9)), lambda t: (9.0, 0.0), 3.0)  # clamped, then scaled
    assert top[-1, 4] == pytest.approx(0.9 * CAR.drive.max_speed_mps, abs=0.01)


def _turn_radius_m(car, steer):
    sim = make_sim(car)
    sim.set_state(Pose2(), 1.0)
    trace(sim, lambda t: (1.0, steer), 1.0)
    return 1.0 / sim.yaw_rate_radps


def test_steering_asymmetry_turns_tighter_to_the_left():
    a = 0.1
    car = with_effects(CAR, steering_asymmetry=a)
    left, right = _turn_radius_m(car, 0.2), -_turn_radius_m(car, -0.2)
    assert left == pytest.approx(WB / math.tan(0.2 * (1 + a)), rel=0.01)  # 0.784 m
    assert right == pytest.approx(WB / math.tan(0.2 * (1 - a)), rel=0.01)  # 0.963 m
    assert left < _turn_radius_m(CAR, 0.2) < right


def test_steering_play_ignores_small_reversals_then_catches_up():
    b = 0.05
    sim = make_sim(with_effects(CAR, steering_play_rad=b))
    sim.set_state(Pose2(), 1.0)
    steer = []
    for d in (0.2, 0.15, 0.12, 0.05, 0.1):
        trace(sim, lambda t: (1.0, d), 0.2)
        steer.append(sim.steer_rad)
    # the slack is taken up (0.2 - b); reversals smaller than 2 b do nothing; a larger one
    # moves the wheels b behind the command; turning back within the slack leaves them
    assert steer == pytest.approx([0.15, 0.15, 0.15, 0.10, 0.10], abs=1e-9)


@pytest.mark.parametrize("before, lag", [(0.0, 0.0), (0.4, 0.0), (0.0, 0.08)])
def test_prime_steering_rests_the_play_on_the_side_the_commands_came_from(before, lag):
    """A wheel angle measured inside the play's band does not say which side the output
    rests on; the commands before do: coming up from 0 it rests b below the command, coming
    down from 0.4 b above (a lag or not). Without a play ``prime_steering`` changes nothing."""
    b, cmd = 0.03, 0.2
    sim = make_sim(with_effects(CAR, steering_play_rad=b, steering_lag_s=lag))
    sim.set_state(Pose2(), 1.0, cmd + 0.01)  # measured 0.21: inside the band, on neither edge
    t = np.linspace(0.0, 3.0, 151)
    sim.prime_steering(t, np.where(t[:-1] < 1.0, before, cmd))
    trace(sim, lambda t_: (1.0, cmd), 0.5)
    assert sim.steer_rad == pytest.approx(cmd - b if before < cmd else cmd + b, abs=1e-4)
    plain, unprimed = make_sim(CAR), make_sim(with_effects(CAR, steering_lag_s=0.08))
    for s_ in (plain, unprimed):
        s_.set_state(Pose2(), 1.0, cmd)
        before_state = s_.save_state()
        s_.prime_steering(t, np.full(150, 0.4))
        assert repr(s_.save_state()) == repr(before_state)


def _reverse_times_s(car):
    """Rolling forward at 1.5 m/s, command -1 m/s: (time to rest, time to -0.5 m/s)."""
    sim = make_sim(car)
    sim.set_state(Pose2(), 1.5)
    t0 = sim.time_s
    rows = trace(sim, lambda t: (-1.0, 0.0), 2.0, every=1)
    rest = rows[int(np.argmax(rows[:, 4] < 0.02)), 0] - t0
    return rest, _crossing_time(rows * [1, 1, 1, 1, -1, 1], 4, 0.5) - t0, rows


def test_esc_brakes_to_rest_before_it_reverses():
    delay = 0.3
    rest0, rev0, _ = _reverse_times_s(CAR)
    rest1, rev1, rows = _reverse_times_s(with_effects(CAR, esc_reverse_delay_s=delay))
    assert rest1 == pytest.approx(rest0, abs=0.005)  # both brake at max_brake: 1.5 / 3.1 = 0.48 s
    probe = EffectSim(with_effects(CAR, esc_reverse_delay_s=delay))
    sub_step = probe.n_sub * probe.dt_s  # the hold is resolved to the control sub-step
    assert delay - 0.01 <= rev1 - rev0 <= delay + 2 * sub_step  # 0.646 s -> 0.940 s
    held = (rows[:, 0] > rows[0, 0] + rest1 + 0.01) & (rows[:, 0] < rows[0, 0] + rest1 + delay - 0.01)
    assert np.abs(rows[held, 4]).max() < 0.02  # at rest during the hold
    # from rest (or after a neutral command) it reverses at once, as without the effect
    def from_rest(car):
        return _crossing_time(trace(make_sim(car), lambda t: (-1.0, 0.0), 0.5, every=1) * [1, 1, 1, 1, -1, 1], 4, 0.5)
    assert from_rest(with_effects(CAR, esc_reverse_delay_s=delay)) == pytest.approx(from_rest(CAR), abs=1e-9)


def _time_to_speed_s(car, v=2.0):
    rows = trace(make_sim(car), lambda t: (v, 0.0), 3.0, every=1)
    return _crossing_time(rows, 4, 0.95 * v), rows[-1, 4]


def _braking_distance_m(car):
    sim = make_sim(car)
    sim.set_state(Pose2(), 2.0)
    rows = trace(sim, lambda t: (0.0, 0.0), 2.0, every=1)
    assert abs(rows[-1, 4]) < 1e-6
    return rows[-1, 1]


def test_accel_and_brake_scales_change_the_drive_limits():
    t_nom, _ = _time_to_speed_s(CAR)  # 0 -> 1.9 m/s at 3.1 m/s^2: 0.61 s
    t_half, v_half = _time_to_speed_s(with_effects(CAR, accel_scale=0.5))
    assert t_half / t_nom == pytest.approx(2.0, rel=0.02) and v_half == pytest.approx(2.0, abs=1e-3)
    d_nom = _braking_distance_m(CAR)  # v^2 / (2 a) = 0.645 m
    assert _braking_distance_m(with_effects(CAR, brake_scale=0.5)) / d_nom == pytest.approx(2.0, rel=0.01)
    assert _braking_distance_m(with_effects(CAR, accel_scale=0.5)) == pytest.approx(d_nom, abs=1e-9)


def test_mass_scale_same_top_speed_slower_to_reach_and_stop():
    heavy = with_effects(CAR, mass_scale=2.0)
    t_nom, _ = _time_to_speed_s(CAR)
    t_heavy, v_heavy = _time_to_speed_s(heavy)
    assert v_heavy == pytest.approx(2.0, abs=1e-3)  # same top speed
    assert t_heavy / t_nom == pytest.approx(2.0, rel=0.02)  # the file's torque on twice the mass
    assert _braking_distance_m(heavy) / _braking_distance_m(CAR) == pytest.approx(2.0, rel=0.01)
    # drag slows the heavier car less: m_eff dv/dt = -k v^2 with twice m_eff
    m_eff = CAR.chassis.mass_kg + 4 * 0.5 * CAR.wheels.mass_kg
    _, v_heavy = coast_down(with_effects(CAR, drag_coeff_kgpm=0.2, mass_scale=2.0))
    assert v_heavy == pytest.approx(1.0 / (1.0 / 2.0 + 0.2 / (2.0 * m_eff)), abs=0.02)  # 1.69 m/s, light 1.46


def test_servo_rate_scale_slows_a_step_steer():
    def time_to_steer_s(car):
        sim = make_sim(car)
        sim.set_state(Pose2(), 0.5)
        return _crossing_time(trace(sim, lambda t: (0.5, 0.3), 0.3, every=1), 5, 0.299)
    t_nom = time_to_steer_s(CAR)  # 0.3 rad at 6 rad/s: 0.05 s
    assert time_to_steer_s(with_effects(CAR, servo_rate_scale=0.5)) / t_nom == pytest.approx(2.0, rel=0.05)


def test_steer_limit_scale_widens_the_full_lock_circle():
    car = with_effects(CAR, steer_limit_scale=0.8)
    assert _turn_radius_m(car, 0.4) == pytest.approx(WB / math.tan(0.8 * 0.4), rel=0.01)  # 0.53 m, not 0.42 m
    assert _turn_radius_m(car, 0.2) == pytest.approx(_turn_radius_m(CAR, 0.2), abs=1e-9)  # below the stop: as nominal


def test_top_speed_caps_the_speed_whatever_the_command():
    def run(car):
        sim = make_sim(car)
        tr = trace(sim, lambda t: (2.5, 0.0), 3.0)
        return tr[-1, 4]

    assert run(CAR) == pytest.approx(2.5, abs=0.02)
    assert run(with_effects(CAR, top_speed_mps=1.3)) == pytest.approx(1.3, abs=0.02)
    assert run(with_effects(CAR, top_speed_mps=5.0)) == run(CAR)  # above the command: no change


def test_lift_lag_slows_a_lift_to_a_lower_forward_command_but_not_a_stop_or_a_speed_up():
    """From 2 m/s to a 1 m/s command: the lift lag's first-order decay (63 % of the drop
    after tau, where the nominal car is there at once); a 0 command still brakes at the
    nominal rate, and speeding up is the nominal car's bit for bit."""
    tau = 0.4

    def speed_after(car, target, t_s):
        sim = make_sim(car)
        sim.set_state(Pose2(), 2.0)
        t0 = sim.time_s
        rows = trace(sim, lambda t: (target, 0.0), t_s + 0.05)
        return rows[np.searchsorted(rows[:, 0], t0 + t_s - 1e-9), 4]

    lifted = with_effects(CAR, lift_lag_s=tau)
    drop = (2.0 - speed_after(lifted, 1.0, tau)) / 1.0
    assert drop == pytest.approx(1.0 - math.exp(-1.0), abs=0.05)
    assert speed_after(CAR, 1.0, tau) == pytest.approx(1.0, abs=0.02)
    assert speed_after(lifted, 0.0, 0.5) == pytest.approx(speed_after(CAR, 0.0, 0.5), abs=1e-9)

    def up(t):
        return (1.0 + 0.5 * t, 0.1)
    a = trace(EffectSim(CAR), up, 1.0)
    assert np.array_equal(a, trace(make_sim(lifted), up, 1.0))


# drive and brake limits the rear tyres alone cannot hold (9 m/s^2 with mu 1): where the
# front wheels' share of the torque shows
GRIPPY = CAR.replace(drive=dataclasses.replace(CAR.drive, max_accel_mps2=9.0, max_brake_mps2=9.0))


def test_front_drive_brakes_and_accelerates_at_the_limit_the_rear_tyres_alone_cannot_hold():
    """From 3 m/s to a stop at 9 m/s^2: the rear-drive car locks up its rear wheels (about
    twice the v^2 / 2a = 0.5 m), the four-wheel-drive car stops close to 0.5 m; braking in a
    turn, the rear-drive car spins about twice as far round; speeding up, the four-wheel-drive
    car reaches 2.4 m/s almost at 9 m/s^2. Within the grip (the default car's 3.1 m/s^2)
    the share changes nothing measurable."""
    def brake(car, steer):
        sim = make_sim(car)
        sim.set_state(Pose2(), 3.0, steer)
        trace(sim, lambda t: (0.0, steer), 1.0, every=1)
        assert abs(sim.speed_mps) < 1e-3
        return sim.pose

    awd = with_effects(GRIPPY, front_share_shift=0.5)
    rwd_stop, awd_stop = brake(GRIPPY, 0.0).x_m, brake(awd, 0.0).x_m
    assert rwd_stop > 1.8 * 0.5 and awd_stop == pytest.approx(0.5, rel=0.15)
    assert abs(brake(GRIPPY, 0.3).yaw_rad) > 1.6 * abs(brake(awd, 0.3).yaw_rad)
    assert _time_to_speed_s(awd, 2.5)[0] < 0.6 * _time_to_speed_s(GRIPPY, 2.5)[0]
    assert _time_to_speed_s(awd, 2.5)[0] == pytest.approx(0.95 * 2.5 / 9.0, rel=0.15)
    assert _braking_distance_m(with_effects(CAR, front_share_shift=0.5)) == pytest.approx(
        _braking_distance_m(CAR), rel=1e-3)


def test_front_share_in_the_car_file_is_the_shifted_share_and_clamps_to_0_1():
    """``drive.front_share`` in the car file builds the same car as the shift on a rear-drive
    file; a shift below 0 on a rear-drive file clamps to rear drive: the nominal car bit for bit."""
    filed = GRIPPY.replace(drive=dataclasses.replace(GRIPPY.drive, front_share=0.5))
    assert type(make_sim(filed)) is CarSim
    assert built_car(with_effects(GRIPPY, front_share_shift=0.5)).drive == filed.drive
    assert built_car(with_effects(filed, front_share_shift=0.7)).drive.front_share == 1.0

    def cmd(t):
        return (2.5, 0.2) if t < 0.5 else (-1.0, -0.3)
    assert np.array_equal(trace(make_sim(filed), cmd, 1.0),
                          trace(make_sim(with_effects(GRIPPY, front_share_shift=0.5)), cmd, 1.0))
    assert np.array_equal(trace(CarSim(GRIPPY), cmd, 1.0),
                          trace(make_sim(with_effects(GRIPPY, front_share_shift=-0.3)), cmd, 1.0))


def test_inertia_scales_the_chassis_moments_and_shows_only_where_the_tyres_slide():
    """The chassis box's three moments times the scale (mass and centre unchanged). A step
    steer within the grip (1 m/s, 0.2 rad: 1.2 m/s^2) gives nearly the same yaw rate whatever
    the inertia; past the grip (2.5 m/s, 0.35 rad: ~13 m/s^2 asked of mu g = 9.8) a lighter
    chassis turns faster: the yaw rate 0.1 s after the step orders 0.4 > 1 > 2.5."""
    from simrunner.car.body import build_car_skeleton
    nominal, light = build_car_skeleton(CAR).chassis, build_car_skeleton(with_effects(CAR, inertia_scale=0.5)).chassis
    assert np.allclose(np.asarray(light.getInertia().getMoment()), 0.5 * np.asarray(nominal.getInertia().getMoment()),
                       rtol=1e-12, atol=0.0)
    assert light.getMass() == nominal.getMass()
    assert np.array_equal(light.getLocalCOM(), nominal.getLocalCOM())

    def yaw_rates(scale, speed, steer):
        sim = make_sim(with_effects(CAR, inertia_scale=scale))
        sim.set_state(Pose2(), speed, 0.0)
        return trace(sim, lambda t: (speed, steer), 0.6, every=1)[:, 3]

    def rate_at(yaw, t_s):
        k = round(t_s / 0.002)
        return (yaw[k + 1] - yaw[k - 1]) / 0.004

    grip = {s: np.diff(yaw_rates(s, 1.0, 0.2)) / 0.002 for s in (0.4, 1.0, 2.5)}
    assert np.abs(grip[0.4] - grip[1.0]).max() < 0.05 and np.abs(grip[2.5] - grip[1.0]).max() < 0.1
    slide = {s: rate_at(yaw_rates(s, 2.5, 0.35), 0.1) for s in (0.4, 1.0, 2.5)}
    assert slide[0.4] > 1.15 * slide[1.0] > 1.15 ** 2 * slide[2.5], slide
