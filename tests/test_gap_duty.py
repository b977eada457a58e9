"""simrunner gap on duty logs (issue 51 item 3): a log whose motor command is a PWM duty is
replayed with the car in duty mode (one duty, or each motor's), its duty's range and sign are
checked, and the motor's numbers come out as effects."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from simrunner.run.runner import drive
from simrunner.telemetry.log import LogError, read_log, write_log
from simrunner.workflows.calibration.duty import motor_of
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.synth import make_measured_log
from simrunner.workflows.gap.workflow import run_gap
from vehicle.description import CarDescription

BASE = CarDescription()
DUTY = BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty"))


def hidden_motor_car(scale: float) -> CarDescription:
    """A duty car whose motors push ``scale`` x the file's (same top speed)."""
    mo = motor_of(DUTY)
    return DUTY.replace(drive=dataclasses.replace(DUTY.drive, motor_force_n=scale * mo.c1,
                                                  motor_back_emf_nspm=scale * mo.c2))


def duty_run(car, tmp_path, *, each: bool = False, seconds: float = 20.0):
    """A 'real' log of ``car``: duty steps and a weaving steer (``each``: the two motors apart)."""
    duties = [0.3, 0.6, 0.2, 0.8, 0.4, 0.0, 0.5, 0.7, 0.3, 0.6]

    def main(s):
        while s.get_time() < seconds:
            t = s.get_time()
            d = duties[int(t / 2.0) % len(duties)]
            s.set_servo(0.25 * math.sin(0.9 * t))
            if each:
                s.set_motors(d, 0.7 * d)
            else:
                s.set_speed(d)
            s.sleep(0.02)

    path = tmp_path / "duty.csv"
    drive(main, track="floor", car=car, time_limit_s=seconds, csv=path)
    return read_log(path)


def test_a_duty_log_replays_in_duty_mode_and_names_the_motors_force(tmp_path):
    log = duty_run(hidden_motor_car(1.35), tmp_path)
    result = run_gap(log, BASE, jobs=1, effects=["accel_scale", "speed_scale", "motor_lag"])
    assert result.car.drive.command == "duty"
    assert result.effects == ["accel_scale"]
    assert result.parameters["accel_scale"] == pytest.approx(1.35, rel=0.1)
    assert result.gap_after < 0.2 * result.gap_before


def test_each_motors_duty_is_replayed(tmp_path):
    """duty_left / duty_right apart (the controller's differential): the car itself replays its
    log almost exactly (only the replay's coarser step and window starts differ)."""
    car = hidden_motor_car(1.0)
    log = duty_run(car, tmp_path, each=True, seconds=12.0)
    assert np.isnan(log.duty_cmd[1:]).all() and not np.allclose(log.duty_left, log.duty_right)
    result = run_gap(log, car, jobs=1, effects=["accel_scale"])
    assert result.rmse_before["position_m"] < 0.02 and result.effects == []


@pytest.fixture(scope="module")
def short_duty_log(tmp_path_factory):
    """8 s of the nominal duty car (two tests read it; a RunLog's columns are read-only)."""
    return duty_run(hidden_motor_car(1.0), tmp_path_factory.mktemp("duty"), seconds=8.0)


def test_a_duty_in_percent_or_reversed_is_refused_with_the_fix(short_duty_log):
    log = short_duty_log
    percent = dataclasses.replace(log, duty_cmd=log.duty_cmd * 100.0, duty_left=None, duty_right=None)
    with pytest.raises(LogError, match=r"'duty_cmd': expected a duty in -1..1 .*--column 'duty_cmd=YOUR_COLUMN / 100'"):
        run_gap(percent, BASE)
    reversed_ = dataclasses.replace(log, duty_cmd=-log.duty_cmd, duty_left=None, duty_right=None)
    with pytest.raises(LogError, match=r"duty_cmd: the measured speed is .*x the duty.*sign is reversed"):
        run_gap(reversed_, BASE)


def test_duty_and_speed_logs_are_not_mixed(short_duty_log):
    duty = short_duty_log
    speed, _ = make_measured_log(None, rng=np.random.default_rng(1), start_s=0.0, duration_s=8.0)
    with pytest.raises(GapError, match=r"expected duty logs as the others"):
        run_gap([duty, speed], BASE)


@pytest.mark.parametrize("explicit", [False, True])
def test_speed_and_accel_scale_act_on_a_duty_cars_motors(explicit):
    """speed_scale: the top speed c1 / c2 (not the duty); accel_scale: the force c1 (and c2: the
    top speed kept); the same whether the file gives c1, c2 or derives them from its limits."""
    from simrunner.car.effects import make_sim, with_effects

    car = hidden_motor_car(1.0) if explicit else DUTY
    car = car.replace(drive=dataclasses.replace(car.drive, hbridge="brake"))
    mo = motor_of(car)

    def steady(c, duty=0.5):
        sim = make_sim(c)
        sim.set_command(duty, 0.0)
        sim.step(round(8.0 / sim.dt_s))
        return sim.speed_mps

    base = steady(car)
    assert base == pytest.approx(0.5 * mo.c1 / mo.c2, rel=0.01)
    assert steady(with_effects(car, speed_scale=1.2)) == pytest.approx(1.2 * base, rel=0.01)
    assert steady(with_effects(car, accel_scale=1.5)) == pytest.approx(base, rel=0.01)
    fast = make_sim(with_effects(car, accel_scale=1.5))
    fast.set_command(1.0, 0.0)
    fast.step(5)
    assert fast.speed_mps / (5 * fast.dt_s) == pytest.approx(1.5 * 2 * mo.c1 / mo.m_eff_kg, rel=0.03)


def test_the_h_bridge_mode_is_chosen_from_the_log(tmp_path):
    """A coasting H-bridge's duty log against the file's brake mode: the answer switches it
    (car.toml says coast) and says so."""
    from simrunner.workflows.gap.report import summary_text

    coast = hidden_motor_car(1.0)
    coast = coast.replace(drive=dataclasses.replace(coast.drive, hbridge="coast"))
    log = duty_run(coast, tmp_path, seconds=14.0)
    result = run_gap(log, BASE, jobs=1, effects=["motor_lag"])
    assert result.car.drive.hbridge == "coast"
    assert "H-bridge (drive.hbridge, a duty log): coast (the car file says brake)" in summary_text(result)
    assert result.settings["hbridge"]["held_cost"]["coast"] < result.settings["hbridge"]["held_cost"]["brake"]
    # from then on the answer is the one for a file that said coast: the signals' scales, the
    # robust loss and the held-out gap come from the coasting car's residuals (the braking
    # car's, 15x larger, made the gap 9e-5 and hid every effect)
    told = run_gap(log, BASE.replace(drive=dataclasses.replace(BASE.drive, hbridge="coast")), jobs=1,
                   effects=["motor_lag"])
    assert told.settings["hbridge"]["chosen"] == "coast"
    for key in ("scales", "robust_scale"):
        assert result.settings[key] == told.settings[key]
    assert result.gap_before == told.gap_before
