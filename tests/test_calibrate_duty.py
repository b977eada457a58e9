"""simrunner calibrate [duty] (issue 51 item 1): the motor model of a duty-driven car recovered from
steady speeds, 0 -> duty and a coast-down simulated on a hidden car; what no test reveals is kept;
bad files are one-line errors."""
from __future__ import annotations

import dataclasses
import math

import pytest
from click.testing import CliRunner

from simrunner.cli.calib import calibrate_cmd
from simrunner.workflows.calibration import duty as D
from simrunner.workflows.calibration.calibrate import CalibrationError, calibrate
from simrunner.workflows.calibration.measured import load_measurements, measurements_from_dict
from vehicle.description import CarDescription, load_car

BASE = CarDescription()
HIDDEN = {"motor_force_n": 1.4, "motor_back_emf_nspm": 0.5, "rolling_resistance_n": 0.4, "drag_nspm2": 0.03}


def hidden_car(hbridge: str) -> CarDescription:
    return BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty", hbridge=hbridge, **HIDDEN))


def measured(car: CarDescription, *, speeds=True, accel=True, coast=True, coast_time=True) -> dict:
    """What a team measures on ``car`` (here: simulated)."""
    out = {"hbridge": car.drive.hbridge}
    if speeds:
        out["duties"] = [0.3, 0.6, 0.9]
        out["speeds_mps"] = [D.sim_steady_speed_mps(car, d) for d in out["duties"]]
    if accel:
        out["accel_time_s"], out["accel_distance_m"] = 1.0, D.sim_accel_distance_m(car, 1.0, 1.0)
    if coast:
        dist, t = D.sim_coast_down(car, 2.0)
        out["coast_speed_mps"], out["coast_distance_m"] = 2.0, dist
        if coast_time:
            out["coast_time_s"] = t
    return {"duty": out}


@pytest.mark.parametrize("hbridge", ["brake", "coast"])
def test_all_three_tests_recover_the_hidden_motor(hbridge):
    r = calibrate(measurements_from_dict(measured(hidden_car(hbridge))))
    dr = r.car_after.drive
    assert dr.command == "duty" and dr.hbridge == hbridge
    for name, want in HIDDEN.items():
        assert getattr(dr, name) == pytest.approx(want, rel=0.03), name
    for check in r.procedure("duty").checks:  # the calibrated car repeats every test
        assert check.after == pytest.approx(check.measured, rel=0.01), check.label


def test_a_coast_down_alone_gives_rolling_resistance_and_keeps_the_motor():
    """Distance only: F_rr (drag kept at the file's 0); c1 and c2 stay the file's (derived) values."""
    true = hidden_car("brake").replace(drive=dataclasses.replace(hidden_car("brake").drive, drag_nspm2=0.0))
    r = calibrate(measurements_from_dict(measured(true, speeds=False, accel=False, coast_time=False)))
    dr, res = r.car_after.drive, r.procedure("duty")
    assert dr.rolling_resistance_n == pytest.approx(0.4, rel=0.02) and dr.drag_nspm2 == 0.0
    before = D.motor_of(BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty")))
    assert dr.motor_force_n == pytest.approx(before.c1) and dr.motor_back_emf_nspm == pytest.approx(before.c2)
    assert any("kept from the car file" in n and "motor_force_n" in n for n in res.notes)


def test_steady_speeds_at_two_duties_give_the_top_speed_and_the_deadband():
    """Brake H-bridge: v = (c1 d - F/2) / c2 is a line in d; with c1 kept, c2 and F_rr follow."""
    true = hidden_car("brake")
    c1_kept = D.motor_of(BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty"))).c1
    true = true.replace(drive=dataclasses.replace(true.drive, motor_force_n=c1_kept, drag_nspm2=0.0))
    r = calibrate(measurements_from_dict(measured(true, accel=False, coast=False)))
    assert r.car_after.drive.motor_back_emf_nspm == pytest.approx(0.5, rel=0.02)
    assert r.car_after.drive.rolling_resistance_n == pytest.approx(0.4, rel=0.05)


def test_the_model_follows_the_simulated_car():
    """The fit's one-dimensional model and the dartpy car agree (what makes the fit valid)."""
    car = hidden_car("coast")
    mo = D.motor_of(car)
    assert mo.steady_speed_mps(0.5) == pytest.approx(D.sim_steady_speed_mps(car, 0.5), rel=0.005)
    assert mo.accel_distance_m(0.8, 1.5) == pytest.approx(D.sim_accel_distance_m(car, 0.8, 1.5), rel=0.005)
    for model, sim in zip(mo.coast_down(1.5), D.sim_coast_down(car, 1.5)):
        assert model == pytest.approx(sim, rel=0.01)


@pytest.mark.parametrize("body, match", [
    ("[duty]\nhbridge = 'brake'\n", r"m.toml:1: duty: expected at least one test"),
    ("[duty]\nduties = [0.5]\n", r"m.toml:2: duty.duties: expected speeds_mps with it"),
    ("[duty]\nduties = [0.5, 0.7]\nspeeds_mps = [1.0]\n", r"m.toml:3: duty.speeds_mps: expected 2 values"),
    ("[duty]\nduties = [1.5]\nspeeds_mps = [1.0]\n", r"m.toml:2: duty.duties: expected a list of numbers"),
    ("[duty]\nhbridge = 'fast'\ncoast_speed_mps = 2\ncoast_distance_m = 3\n", r"m.toml:2: duty.hbridge: expected one of"),
    ("[duty]\ncoast_time_s = 3\naccel_time_s = 1\naccel_distance_m = 0.5\n", r"m.toml:2: duty.coast_time_s"),
])
def test_bad_duty_measurements_are_one_line_errors(tmp_path, body, match):
    path = tmp_path / "m.toml"
    path.write_text(body)
    with pytest.raises(CalibrationError, match=match) as err:
        calibrate(load_measurements(path))
    assert "\n" not in str(err.value)


def test_cli_writes_a_duty_car(tmp_path):
    meas = tmp_path / "m.toml"
    meas.write_text("[duty]\ncoast_speed_mps = 2.0\ncoast_distance_m = 4.0\n")
    out = tmp_path / "car.toml"
    res = CliRunner().invoke(calibrate_cmd, [str(meas), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "drive.command: speed -> duty" in res.output and "coast-down distance from 2 m/s" in res.output
    car = load_car(out)
    m_eff = D.motor_of(car).m_eff_kg
    assert car.drive.command == "duty"
    assert car.drive.rolling_resistance_n == pytest.approx(m_eff * 4.0 / (2 * 4.0), rel=0.02)  # m v^2 / 2D
    assert "Source: simrunner calibrate [duty]" in out.read_text()


def test_the_example_file_calibrates():
    from pathlib import Path
    example = Path(__file__).resolve().parents[1] / "examples" / "measured_duty_car.toml"
    r = calibrate(load_measurements(example))
    assert r.procedure("duty").values["rms"] < 0.02
    assert all(f for f in r.procedure("duty").values["free"])
