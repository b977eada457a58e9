"""Excitation plan: contents, CSV round trip, bad files, simulated play-back."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from simrunner.car.effects import EFFECTS, with_effects
from simrunner.run.log import FORMAT_LINE, RunLog, read_log, write_log
from simrunner.workflows.excite import (AREA_M, SEGMENT_KINDS, ExcitationPlan, PlanError, make_plan, run_plan,
                                        segment_kind)
from vehicle.description import CarDescription

CAR = CarDescription()
PLAN = make_plan(CAR)


def test_plan_shape_and_contents():
    assert PLAN.rate_hz == 50.0
    assert 60.0 <= PLAN.duration_s <= 75.0
    assert np.allclose(np.diff(PLAN.t_s), 0.02) and PLAN.t_s[0] == 0.0
    kinds = {segment_kind(s) for s in PLAN.segment}
    assert kinds == set(SEGMENT_KINDS)
    assert np.all(np.abs(PLAN.steer_cmd_rad) <= CAR.steering.limit_rad + 1e-12)
    assert np.all(np.abs(PLAN.speed_cmd_mps) <= CAR.drive.max_speed_mps)
    assert PLAN.coast.any() and np.all(PLAN.speed_cmd_mps[PLAN.coast] == 0.0)
    # left and right step steers at several amplitudes
    steps = {float(s.split(":")[1]) for s in PLAN.segment if s.startswith("step_steer:")}
    assert len({abs(a) for a in steps}) >= 2 and min(steps) < 0 < max(steps)
    # every effect is revealed by a segment kind in the plan (friction also by the tilt test)
    revealed = {e for k in kinds for e in SEGMENT_KINDS[k]}
    assert revealed == set(EFFECTS)
    for spec in EFFECTS.values():
        assert set(spec.revealed_by) & (kinds | {"tilt test"}), spec.name


def test_seed_changes_only_the_random_steps_and_duration_extends():
    other = make_plan(CAR, seed=1)
    rnd = PLAN.kind_mask("random_steer")
    n = min(len(PLAN), len(other))
    assert np.array_equal(PLAN.steer_cmd_rad[:n][~rnd[:n]][:1000], other.steer_cmd_rad[:n][~rnd[:n]][:1000])
    assert not np.array_equal(PLAN.steer_cmd_rad[rnd], other.steer_cmd_rad[other.kind_mask("random_steer")])
    assert np.array_equal(make_plan(CAR, seed=1).steer_cmd_rad, other.steer_cmd_rad)
    long = make_plan(CAR, duration_s=100.0)
    assert 95.0 <= long.duration_s <= 105.0
    with pytest.raises(PlanError, match="duration"):
        make_plan(CAR, duration_s=10.0)


def test_csv_round_trip(tmp_path):
    path = PLAN.to_csv(tmp_path / "plan.csv")
    text = path.read_text()
    assert text.startswith("# nxpcup excitation plan") and "t,speed_cmd,steer_cmd,coast,segment" in text
    back = ExcitationPlan.from_csv(path)
    assert back.segment == PLAN.segment and back.rate_hz == 50.0
    assert np.array_equal(back.coast, PLAN.coast)
    assert np.allclose(back.t_s, PLAN.t_s, atol=1e-9)
    assert np.allclose(back.steer_cmd_rad, PLAN.steer_cmd_rad, atol=1e-6)
    assert np.allclose(back.speed_cmd_mps, PLAN.speed_cmd_mps, atol=1e-6)


@pytest.mark.parametrize("body, match", [
    ("", r"plan.csv:1: empty plan"),
    ("t,speed_cmd\n0,1\n", r"plan.csv:1: header lacks column 'steer_cmd'"),
    ("t,speed_cmd,steer_cmd,foo\n", r"plan.csv:1: unknown column 'foo'"),
    ("t,speed_cmd,steer_cmd\n0,0,0\n0.02,x,0\n", r"plan.csv:3: expected numbers"),
    ("# c\nt,speed_cmd,steer_cmd\n0,0,0\n0.02,0,0\n0.05,0,0\n", r"plan.csv:5: expected t to start at 0"),
    ("t,speed_cmd,steer_cmd,coast\n0,0,0,2\n0.02,0,0,0\n", r"plan.csv:2: expected finite numbers and coast 0 or 1"),
    ("t,speed_cmd,steer_cmd\n0,0,0,1\n", r"plan.csv:2: expected 3 values, got 4"),
])
def test_bad_plan_files_are_one_line_errors(tmp_path, body, match):
    path = tmp_path / "plan.csv"
    path.write_text(body)
    with pytest.raises(PlanError, match=match) as err:
        ExcitationPlan.from_csv(path)
    assert "\n" not in str(err.value)


EXCITE_COLUMNS = ("frame", "t_s", "x_m", "y_m", "yaw_rad", "speed_mps", "steer_rad", "yaw_rate_radps",
                  "speed_cmd_mps", "steer_cmd_rad", "yaw_rate_cmd_radps", "coast")


def test_nominal_play_back_stays_in_the_hall_area_and_writes_its_run_log(tmp_path):
    log = run_plan(PLAN, CAR)
    assert isinstance(log, RunLog) and log.names == EXCITE_COLUMNS  # no lap / off_track: no track
    assert np.array_equal(log.frame, np.arange(len(PLAN))) and np.array_equal(log.t_s, PLAN.t_s)
    assert np.array_equal(log.coast, PLAN.coast) and np.array_equal(log.steer_cmd_rad, PLAN.steer_cmd_rad)
    assert np.ptp(log.x_m) < AREA_M - 0.3
    assert np.ptp(log.y_m) < AREA_M - 0.3
    out = write_log(log, tmp_path / "log.csv")
    assert out.read_text().splitlines()[:2] == [FORMAT_LINE, ",".join(EXCITE_COLUMNS)]
    back = read_log(out)
    assert back.names == EXCITE_COLUMNS and np.array_equal(back.coast, log.coast)
    assert np.allclose(back.x_m, log.x_m, atol=1e-6) and np.allclose(back.speed_cmd_mps, PLAN.speed_cmd_mps)
    # the coast segment really coasts: no losses in the nominal model
    coasts = [(a, b) for seg, a, b in PLAN.segments() if seg.startswith("coast:")]
    assert len(coasts) == 2  # the coast-down and the end of the random steps
    for a, b in coasts:
        part = (PLAN.t_s >= a) & (PLAN.t_s < b)
        assert np.ptp(log.speed_mps[part]) < 0.02 and log.speed_mps[part].min() > 0.7


EFFECT_VALUES = {
    "steering_offset": {"steering_offset_rad": 0.05}, "steering_gain": {"steering_gain": 0.8},
    "steering_lag": {"steering_lag_s": 0.1}, "steering_rate_limit": {"steering_rate_limit_radps": 1.5},
    "command_latency": {"command_latency_s": 0.08}, "motor_lag": {"motor_lag_s": 0.3},
    "throttle_deadband": {"throttle_deadband_mps": 0.3}, "rolling_resistance": {"rolling_resistance_coeff": 0.05},
    "drag": {"drag_coeff_kgpm": 0.2}, "tire_slip": {"tire_slip_understeer_radps2pm": 0.03},
    "friction": {"friction_scale": 0.6},
}


@pytest.fixture(scope="module")
def nominal_coarse():
    return run_plan(PLAN, CAR, dt_s=0.005)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_leaves_a_trace_in_its_segments(name, nominal_coarse):
    """Speed and yaw rate (pose-independent) differ from nominal in a segment kind that the
    catalogue says reveals the effect (5 ms steps keep this fast)."""
    log = run_plan(PLAN, with_effects(CAR, **EFFECT_VALUES[name]), dt_s=0.005)
    kinds = [k for k in EFFECTS[name].revealed_by if k in SEGMENT_KINDS]
    mask = np.zeros(len(PLAN), dtype=bool)
    for k in kinds:
        mask |= PLAN.kind_mask(k)
    d_speed = np.abs(log.speed_mps - nominal_coarse.speed_mps)[mask].max()
    d_yaw_rate = np.abs(log.yaw_rate_radps - nominal_coarse.yaw_rate_radps)[mask].max()
    assert max(d_speed, d_yaw_rate) > 0.1, (name, d_speed, d_yaw_rate)



@settings(max_examples=40, deadline=None)
@given(hs.lists(hs.tuples(hs.floats(-3, 3), hs.floats(-0.5, 0.5), hs.booleans(),
                          hs.text("abcdefghij_:+-.0123456789", min_size=1, max_size=12)), min_size=2, max_size=30),
       hs.sampled_from([10.0, 25.0, 50.0, 100.0]))
def test_csv_round_trip_property(tmp_path_factory, rows, rate):
    n = len(rows)
    plan = ExcitationPlan(np.arange(n) / rate, np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                          np.array([r[2] for r in rows], dtype=bool), tuple(r[3] for r in rows), rate_hz=rate)
    path = plan.to_csv(tmp_path_factory.mktemp("p") / "plan.csv", extent=(0.0, 1.0, 0.0, 1.0))
    back = ExcitationPlan.from_csv(path)
    assert back.rate_hz == rate and back.segment == plan.segment and np.array_equal(back.coast, plan.coast)
    assert np.allclose(back.speed_cmd_mps, plan.speed_cmd_mps, atol=1e-6)
    assert np.allclose(back.steer_cmd_rad, plan.steer_cmd_rad, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(hs.text(max_size=200))
def test_from_csv_never_crashes_on_junk(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("j") / "plan.csv"
    path.write_text(text)
    try:
        ExcitationPlan.from_csv(path)
    except PlanError as err:
        assert "\n" not in str(err)
