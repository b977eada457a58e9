"""simrunner excite for a duty-driven car (issue 51 item 6): the plan's speed steps are sent as
duty steps (the motor model's steady state), and the closed-loop turns keep the car in its area."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli.calib import excite_cmd
from simrunner.telemetry.log import read_log
from simrunner.workflows.calibration.duty import motor_of
from simrunner.workflows.excite import ExcitationPlan, PlanError, area_margin_m, make_plan, run_plan
from simrunner.workflows.gap.logs import is_duty_log
from vehicle.description import CarDescription

BASE = CarDescription()


def duty_car(hbridge: str, **drive) -> CarDescription:
    return BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty", hbridge=hbridge, **drive))


@pytest.fixture(scope="module")
def speed_plan():
    """The default (speed-command) car's plan, made once (three tests read it; a frozen value)."""
    return make_plan(BASE)


@pytest.mark.parametrize("hbridge", ["brake", "coast"])
def test_a_duty_plan_holds_its_speeds_and_stays_in_its_area(hbridge, speed_plan):
    car = duty_car(hbridge, rolling_resistance_n=0.3, drag_nspm2=0.05)
    plan = make_plan(car)
    assert np.array_equal(plan.speed_cmd_mps, speed_plan.speed_cmd_mps)  # the same experiments
    assert plan.duty_cmd is not None and np.all(np.abs(plan.duty_cmd) <= 1.0)
    mo = motor_of(car)
    fast = int(np.argmax(plan.speed_cmd_mps))  # the duty that holds the top planned speed
    v, d = plan.speed_cmd_mps[fast], plan.duty_cmd[fast]
    force = 2 * (mo.c1 * d - mo.c2 * v * (1.0 if hbridge == "brake" else d))
    assert force == pytest.approx(mo.rolling_n + mo.drag * v * v, rel=1e-6)
    log = run_plan(plan, car, closed_loop=True)
    assert is_duty_log(log)
    assert plan.outside_area_m(log.x_m, log.y_m) <= area_margin_m(car)
    assert np.max(log.speed_mps) > 0.8 * np.max(plan.speed_cmd_mps)


def test_duty_plans_refuse_what_cannot_work(speed_plan):
    with pytest.raises(PlanError, match=r"no rolling resistance or drag"):
        make_plan(duty_car("coast"))
    with pytest.raises(PlanError, match=r"the plan has no duty_cmd column"):
        run_plan(speed_plan, duty_car("brake"))


def test_the_cli_writes_and_plays_a_duty_plan(tmp_path):
    car = tmp_path / "duty.toml"
    car.write_text('[drive]\ncommand = "duty"\n')
    plan_path, log_path = tmp_path / "plan.csv", tmp_path / "log.csv"
    res = CliRunner().invoke(excite_cmd, ["-o", str(plan_path), "--car", str(car), "--simulate", str(log_path),
                                          "--closed-loop"])
    assert res.exit_code == 0, res.output
    plan = ExcitationPlan.from_csv(plan_path)
    assert plan.duty_cmd is not None and "duty_cmd" in plan_path.read_text().splitlines()[
        next(i for i, ln in enumerate(plan_path.read_text().splitlines()) if not ln.startswith("#"))]
    assert is_duty_log(read_log(log_path))
