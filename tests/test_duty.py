"""Motors driven by duty (issue 51 item 1): drive.command = "duty", the motor model per rear
wheel, the H-bridge's coast and brake, set_speed carrying a duty, set_motors in Python and C,
the duty columns of the run log."""
from __future__ import annotations

import dataclasses
import math
import textwrap

import numpy as np
import pytest

from simrunner.car.physics import CarSim
from simrunner.run.runner import drive
from vehicle.description import CarDescription, CarDescriptionError

BASE = CarDescription()


def duty_car(**drive_fields) -> CarDescription:
    return BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty", **drive_fields))


def speeds(car, duties, times_s, *, then=None):
    """The car's speed at ``times_s`` after setting ``duties`` (and ``then`` = (duties, seconds))."""
    sim = CarSim(car)
    sim.set_motors(*duties)
    out, step = [], 0
    for t in times_s:
        n = round(t / sim.dt_s) - step
        sim.step(n)
        step += n
        out.append(sim.speed_mps)
    if then is not None:
        sim.set_motors(*then[0])
        sim.step(round(then[1] / sim.dt_s))
        out.append(sim.speed_mps)
    return out


def test_the_default_car_is_speed_commanded_and_duty_drives_only_the_rear():
    assert BASE.drive.command == "speed"
    with pytest.raises(CarDescriptionError, match=r"drive.command = 'duty' drives the two rear motors"):
        BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty", front_share=0.5))


def closed_form_speed(t_s, v0, v_inf, tau_s):
    """First-order response: the speed of a car whose force is linear in its speed."""
    return v_inf + (v0 - v_inf) * math.exp(-t_s / tau_s)


M_EFF = CarSim(BASE).effective_mass_kg  # the mass the motors accelerate: m + 4 I_spin / r^2
VMAX, AMAX = BASE.drive.max_speed_mps, BASE.drive.max_accel_mps2
TAU_S = VMAX / AMAX  # c1 = m_eff a / 2, c2 = c1 / vmax: m_eff / (2 c2) = vmax / a


@pytest.mark.parametrize("hbridge,duty", [("coast", 1.0), ("coast", 0.4), ("brake", 0.4), ("brake", -0.7)])
def test_duty_from_rest_follows_the_motor_models_closed_form_within_1_percent(hbridge, duty):
    """m_eff dv/dt = 2 (c1 - c2 v) d (coast) or 2 (c1 d - c2 v) (brake), from rest."""
    times = [0.002, 0.1, 0.5, 1.0, 2.0, 4.0, 8.0]
    v = speeds(duty_car(hbridge=hbridge), (duty, duty), times)
    if hbridge == "coast":
        v_inf, tau = math.copysign(VMAX, duty), TAU_S / abs(duty)
    else:
        v_inf, tau = duty * VMAX, TAU_S
    for t, got in zip(times, v):
        assert got == pytest.approx(closed_form_speed(t, 0.0, v_inf, tau), rel=0.01), t
    assert v[0] / 0.002 == pytest.approx(duty * AMAX, rel=0.01)   # 0 -> duty: c1 d / (m_eff / 2)


def test_coast_down_with_rolling_resistance_and_drag_follows_its_closed_form_within_1_percent():
    """Duty 0 with a coasting H-bridge: m_eff dv/dt = -F_rr - k v^2, so
    v(t) = sqrt(F/k) tan(atan(v0 sqrt(k/F)) - sqrt(F k) t / m_eff); the steady speed at full
    duty before solves 2 (c1 - c2 v) = F_rr + k v^2."""
    f_rr, k = 0.6, 0.05
    car = duty_car(hbridge="coast", rolling_resistance_n=f_rr, drag_nspm2=k)
    sim = CarSim(car)
    sim.set_motors(1.0, 1.0)
    sim.step(round(8.0 / sim.dt_s))
    c1 = 0.5 * M_EFF * AMAX
    c2 = c1 / VMAX
    v_steady = (-2 * c2 + math.sqrt(4 * c2 * c2 + 4 * k * (2 * c1 - f_rr))) / (2 * k)
    v0 = sim.speed_mps
    assert v0 == pytest.approx(v_steady, rel=0.01)
    sim.set_motors(0.0, 0.0)
    prev = 0.0
    for t in (0.5, 1.0, 2.0, 3.0):
        sim.step(round((t - prev) / sim.dt_s))
        prev = t
        want = math.sqrt(f_rr / k) * math.tan(math.atan(v0 * math.sqrt(k / f_rr)) - math.sqrt(f_rr * k) * t / M_EFF)
        assert sim.speed_mps == pytest.approx(want, rel=0.01), t


def test_the_h_bridge_coasts_or_brakes_at_duty_zero():
    coast = speeds(duty_car(hbridge="coast"), (0.5, 0.5), [8.0], then=((0.0, 0.0), 0.5))
    brake = speeds(duty_car(hbridge="brake"), (0.5, 0.5), [8.0], then=((0.0, 0.0), 0.5))
    assert coast[1] == pytest.approx(coast[0], rel=1e-3)                          # rolls on
    assert brake[1] == pytest.approx(closed_form_speed(0.5, brake[0], 0.0, TAU_S), rel=0.01)  # back-EMF brakes


def test_set_speed_carries_a_duty_and_set_motors_each_one(tmp_path):
    car = duty_car(hbridge="brake")
    got = []

    def main(s):
        s.configure(speed_norm=lambda speed, angle: speed / 100.0)  # the team's duty in percent
        s.set_speed_and_servo(50.0, 0.0)
        s.sleep(0.5)
        got.append(s.get_speed())
        s.set_motors(0.3, 0.6)
        s.set_servo(0.1)  # steering keeps the motors' own duties
        s.sleep(0.5)
        s.set_speed(20.0)  # a speed command ends them
        s.sleep(0.1)

    r = drive(main, track="floor", car=car, time_limit_s=3.0, csv=tmp_path / "log.csv")
    log = r.log
    assert log.duty_left is not None and "duty_right" in (tmp_path / "log.csv").read_text().splitlines()[1]
    early = (log.t_s > 0.1) & (log.t_s < 0.5)
    assert (log.duty_left[early] == 0.5).all() and (log.duty_right[early] == 0.5).all()
    mid = (log.t_s > 0.6) & (log.t_s < 1.0)
    assert (log.duty_left[mid] == 0.3).all() and (log.duty_right[mid] == 0.6).all()
    assert log.duty_left[-1] == 0.2 == log.duty_right[-1] == log.duty_cmd[-1]
    assert np.isnan(log.duty_cmd[mid]).all() and (log.duty_cmd[early] == 0.5).all()
    assert 0.0 < got[0] < 0.5 * BASE.drive.max_speed_mps


def test_a_speed_commanded_car_takes_the_mean_duty_as_a_share_of_its_top_speed():
    seen = []

    def main(s):
        s.set_motors(0.25, 0.75)
        s.sleep(0.05)
        seen.append(s.get_time())

    r = drive(main, track="floor", time_limit_s=1.0)
    assert r.log.speed_cmd_mps[-1] == pytest.approx(0.5 * BASE.drive.max_speed_mps) and r.log.duty_left is None


def test_c_sets_the_motors(tmp_path):
    car = tmp_path / "duty.toml"
    car.write_text('[drive]\ncommand = "duty"\n')
    src = tmp_path / "motors.c"
    src.write_text(textwrap.dedent("""\
        #include "spinner.h"
        int main(void) {
            spinner_set_motors(0.4f, 0.9f);
            spinner_set_servo(0.05);          /* steering only: the duties stay */
            spinner_sleep(0.3);
            return 0;
        }
        """))
    r = drive(str(src), track="floor", car=car, time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    assert r.log.duty_left[-1] == pytest.approx(0.4) and r.log.duty_right[-1] == pytest.approx(0.9)
    assert r.log.steer_cmd_rad[-1] == pytest.approx(0.05) and r.log.speed_mps[-1] > 0.3


def test_a_duty_beyond_full_is_warned_with_the_duty_unit():
    """A team that forgets its speed_norm sends 50 (percent) as a duty: warned, capped at 1."""
    def main(s):
        s.set_speed_and_servo(50.0, 0.0)
        s.sleep(0.2)

    r = drive(main, track="floor", car=duty_car(), time_limit_s=1.0)
    assert any("duty command 50 " in w and "beyond -1..1" in w for w in r.warnings), r.warnings
    assert r.log.duty_left[-1] == 1.0 == r.log.duty_right[-1]


def test_a_duty_car_restores_bit_exactly_with_its_drag():
    sim = CarSim(duty_car(rolling_resistance_n=0.3, drag_nspm2=0.05))
    sim.set_motors(0.8, 0.6)
    sim.step(503)
    state = sim.save_state()
    sim.step(257)
    first = (sim.pose, sim.speed_mps)
    sim.restore_state(state)
    sim.step(100)
    sim.step(157)
    assert (sim.pose, sim.speed_mps) == first
