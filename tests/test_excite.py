"""Excitation plan: contents, CSV round trip, bad files, simulated play-back (open and closed
loop), staying in the hall area with off-nominal cars, the command line."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as hs

from simrunner.car.effects import EFFECTS, with_effects
from simrunner.cli.calib import excite_cmd
from simrunner.telemetry.log import FORMAT_LINE, RunLog, read_log, write_log
from simrunner.workflows.excite import (AREA_M, AREA_MARGIN_M, SEGMENT_KINDS, ExcitationPlan, PlanError,
                                        follow_path, make_plan, run_plan, segment_kind)
from vehicle.description import CarDescription

CAR = CarDescription()
PLAN = make_plan(CAR)


def test_plan_shape_and_contents():
    assert PLAN.rate_hz == 50.0
    assert 80.0 <= PLAN.duration_s <= 100.0
    assert np.allclose(np.diff(PLAN.t_s), 0.02) and PLAN.t_s[0] == 0.0
    kinds = {segment_kind(s) for s in PLAN.segment}
    assert kinds == set(SEGMENT_KINDS)
    assert np.all(np.abs(PLAN.steer_cmd_rad) <= CAR.steering.limit_rad + 1e-12)
    assert np.all(np.abs(PLAN.speed_cmd_mps) <= CAR.drive.max_speed_mps)
    assert PLAN.coast.any() and np.all(PLAN.speed_cmd_mps[PLAN.coast] == 0.0)
    # left and right step steers at several amplitudes
    steps = {float(s.split(":")[1]) for s in PLAN.segment if s.startswith("step_steer:")}
    assert len({abs(a) for a in steps}) >= 2 and min(steps) < 0 < max(steps)
    # circles at full lock, left and right (the steering limit), slowly
    lock = PLAN.kind_mask("circle") & (np.abs(PLAN.steer_cmd_rad) == CAR.steering.limit_rad)
    assert lock.sum() * 0.02 >= 4.0 and np.all(PLAN.speed_cmd_mps[lock] <= 0.5)
    assert set(np.sign(PLAN.steer_cmd_rad[lock])) == {-1.0, 1.0}
    # reverse: a negative speed command right after rolling forward, then forward again; twice
    # (the gap workflow fits one and holds the other out)
    rev = PLAN.kind_mask("reverse")
    first = int(np.argmax(rev))
    assert PLAN.speed_cmd_mps[first - 1] > 0.5 and PLAN.speed_cmd_mps[first] < 0.0
    onsets = np.flatnonzero((PLAN.speed_cmd_mps[1:] < 0.0) & (PLAN.speed_cmd_mps[:-1] > 0.5)) + 1
    assert len(onsets) == 2 and np.all(rev[onsets])
    assert (PLAN.speed_cmd_mps[rev] < 0).sum() * 0.02 >= 2.0 and PLAN.speed_cmd_mps[rev][-1] > 0.0
    # the turns, and only they, carry the reference path
    assert np.array_equal(PLAN.reference_rows(), PLAN.kind_mask("turn"))
    assert len(PLAN.turns()) >= 10


def test_every_effect_is_revealed_by_a_segment_of_the_plan():
    kinds = {segment_kind(s) for s in PLAN.segment}
    assert {e for k in kinds for e in SEGMENT_KINDS[k]} == set(EFFECTS)
    for spec in EFFECTS.values():  # the catalogue names kinds of this plan (friction also the tilt test)
        assert set(spec.revealed_by) & (kinds | {"tilt test"}), spec.name
    assert all(e in EFFECTS for claims in SEGMENT_KINDS.values() for e in claims)


def test_seed_changes_only_the_random_steps_and_duration_extends():
    other = make_plan(CAR, seed=1)
    rnd = PLAN.kind_mask("random_steer")
    # everything before the turn to the first random block (planned for its steps) is the same
    first = max(a for a, _ in PLAN.turns() if a < int(np.argmax(rnd)))
    assert np.array_equal(PLAN.steer_cmd_rad[:first], other.steer_cmd_rad[:first])
    assert PLAN.segment[:first] == other.segment[:first]
    assert not np.array_equal(PLAN.steer_cmd_rad[rnd], other.steer_cmd_rad[other.kind_mask("random_steer")])
    again = make_plan(CAR, seed=1)
    assert np.array_equal(again.steer_cmd_rad, other.steer_cmd_rad) and again.segment == other.segment
    assert np.array_equal(again.ref_x_m, other.ref_x_m, equal_nan=True)
    long = make_plan(CAR, duration_s=150.0)
    assert 145.0 <= long.duration_s <= 155.0 and long.kind_mask("random_steer").sum() > 3 * rnd.sum()
    with pytest.raises(PlanError, match="duration"):
        make_plan(CAR, duration_s=10.0)


def test_csv_round_trip(tmp_path):
    path = PLAN.to_csv(tmp_path / "plan.csv")
    text = path.read_text()
    assert text.startswith("# nxpcup excitation plan")
    assert "\nt,speed_cmd,steer_cmd,coast,segment,ref_x,ref_y,ref_yaw\n" in text
    back = ExcitationPlan.from_csv(path)
    assert back.segment == PLAN.segment and back.rate_hz == 50.0
    assert np.array_equal(back.coast, PLAN.coast)
    assert np.allclose(back.t_s, PLAN.t_s, atol=1e-9)
    assert np.allclose(back.steer_cmd_rad, PLAN.steer_cmd_rad, atol=1e-6)
    assert np.allclose(back.speed_cmd_mps, PLAN.speed_cmd_mps, atol=1e-6)
    assert np.array_equal(back.reference_rows(), PLAN.reference_rows()) and back.turns() == PLAN.turns()
    ref = PLAN.reference_rows()
    assert np.allclose(back.ref_x_m[ref], PLAN.ref_x_m[ref], atol=1e-4)
    assert np.allclose(back.ref_yaw_rad[ref], PLAN.ref_yaw_rad[ref], atol=1e-5)
    assert back.area_centre_m == pytest.approx(PLAN.area_centre_m, abs=1e-4)
    assert PLAN.area_m == back.area_m == AREA_M and "# area_m=6\n" in text
    assert PLAN.margin_m == back.margin_m == AREA_MARGIN_M and "# margin_m=0.6\n" in text
    # the header says where to put the car in the area
    cx, cy = PLAN.area_centre_m
    start = f"{0.5 * AREA_M - cx:.2f} m from the area's west edge and {0.5 * AREA_M - cy:.2f} m"
    assert start in text.replace("\n# ", " ")


@pytest.mark.parametrize("body, match", [
    ("", r"plan.csv:1: empty plan"),
    ("t,speed_cmd\n0,1\n", r"plan.csv:1: header lacks column 'steer_cmd'"),
    ("t,speed_cmd,steer_cmd,foo\n", r"plan.csv:1: unknown column 'foo'"),
    ("t,speed_cmd,steer_cmd\n0,0,0\n0.02,x,0\n", r"plan.csv:3: expected numbers"),
    ("# c\nt,speed_cmd,steer_cmd\n0,0,0\n0.02,0,0\n0.05,0,0\n", r"plan.csv:5: expected t to start at 0"),
    ("t,speed_cmd,steer_cmd,coast\n0,0,0,2\n0.02,0,0,0\n", r"plan.csv:2: expected finite numbers and coast 0 or 1"),
    ("t,speed_cmd,steer_cmd\n0,0,0,1\n", r"plan.csv:2: expected 3 values, got 4"),
    ("t,speed_cmd,steer_cmd,ref_x,ref_y\n0,0,0,1,1\n", r"plan.csv:1: expected all of ref_x,ref_y,ref_yaw or none"),
    ("t,speed_cmd,steer_cmd,ref_x,ref_y,ref_yaw\n0,0,0,1,,0\n0.02,0,0,,,\n",
     r"plan.csv:2: expected three numbers in ref_x,ref_y,ref_yaw or three empty cells"),
    ("t,speed_cmd,steer_cmd,ref_x,ref_y,ref_yaw\n0,0,0,1,inf,0\n0.02,0,0,,,\n",
     r"plan.csv:2: expected finite numbers in ref_x,ref_y,ref_yaw"),
])
def test_bad_plan_files_are_one_line_errors(tmp_path, body, match):
    path = tmp_path / "plan.csv"
    path.write_text(body)
    with pytest.raises(PlanError, match=match) as err:
        ExcitationPlan.from_csv(path)
    assert "\n" not in str(err.value)


EXCITE_COLUMNS = ("frame", "t_s", "x_m", "y_m", "yaw_rad", "speed_mps", "steer_rad", "yaw_rate_radps",
                  "speed_cmd_mps", "steer_cmd_rad", "yaw_rate_cmd_radps", "coast")


def _out_of_area_m(plan: ExcitationPlan, log: RunLog) -> float:
    """How far the logged path gets outside the plan's stated area (0: inside)."""
    return plan.outside_area_m(log.x_m, log.y_m)


def test_area_is_the_stated_square_around_the_middle():
    cx, cy = PLAN.area_centre_m
    assert PLAN.area_bounds_m(0.5) == pytest.approx((cx - 3.5, cx + 3.5, cy - 3.5, cy + 3.5))
    assert PLAN.outside_area_m(np.array([cx, cx + 3.0]), np.array([cy, cy])) == 0.0
    assert PLAN.outside_area_m(np.array([cx]), np.array([cy - 3.25])) == pytest.approx(0.25)
    with pytest.raises(PlanError, match="where its area is"):
        ExcitationPlan(PLAN.t_s, PLAN.speed_cmd_mps, PLAN.steer_cmd_rad, PLAN.coast, PLAN.segment).area_bounds_m()


def test_nominal_play_back_stays_in_the_hall_area_and_writes_its_run_log(tmp_path):
    log = run_plan(PLAN, CAR)
    assert isinstance(log, RunLog) and log.names == EXCITE_COLUMNS  # no lap / off_track: no track
    assert np.array_equal(log.frame, np.arange(len(PLAN))) and np.array_equal(log.t_s, PLAN.t_s)
    assert np.array_equal(log.coast, PLAN.coast) and np.array_equal(log.steer_cmd_rad, PLAN.steer_cmd_rad)
    assert _out_of_area_m(PLAN, log) <= AREA_MARGIN_M
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


# the off-nominal cars of issue 10 item 7, and two combinations of the plan's design envelope
OFF_NOMINAL = {
    "trim +2 deg": {"steering_offset_rad": math.radians(2.0)},
    "trim -2 deg": {"steering_offset_rad": math.radians(-2.0)},
    "speed x0.85": {"speed_scale": 0.85}, "speed x1.15": {"speed_scale": 1.15},
    "gain 0.85": {"steering_gain": 0.85}, "gain 1.15": {"steering_gain": 1.15},
    "trim +2 deg, gain 0.85, speed x1.15": {"steering_offset_rad": math.radians(2.0), "steering_gain": 0.85,
                                            "speed_scale": 1.15},
    "trim +2 deg, gain 0.85": {"steering_offset_rad": math.radians(2.0), "steering_gain": 0.85},  # the worst
}


def _experiment_blocks_in_order(plan: ExcitationPlan, log: RunLog) -> bool:
    """Every run of non-turn rows of the plan appears, commands unchanged, as consecutive
    rows of the log, in the plan's order."""
    at = 0
    for a, b in zip([0] + [e for _, e in plan.turns()], [s for s, _ in plan.turns()] + [len(plan)]):
        if a == b:
            continue
        want = np.stack([plan.speed_cmd_mps[a:b], plan.steer_cmd_rad[a:b], plan.coast[a:b]], 1)
        have = np.stack([log.speed_cmd_mps, log.steer_cmd_rad, log.coast], 1)
        for i in range(at, len(log) - (b - a) + 1):
            if np.array_equal(have[i:i + b - a], want):
                at = i + b - a
                break
        else:
            return False
    return True


# a 1:10 car (F1/10-like numbers): its turning circle is twice the default car's
TENTH = dataclasses.replace(CAR, chassis=dataclasses.replace(CAR.chassis, mass_kg=3.7, wheelbase_m=0.33, track_m=0.28),
                            steering=dataclasses.replace(CAR.steering, limit_rad=0.42, rate_radps=3.2),
                            drive=dataclasses.replace(CAR.drive, max_speed_mps=8.0, max_accel_mps2=6.0,
                                                      max_brake_mps2=8.0),
                            wheels=dataclasses.replace(CAR.wheels, friction_mu=1.05))


@pytest.fixture(scope="module")
def tenth_plan():
    """The 1:10 car's plan (made once, ~3 s: two tests read it; a plan is a frozen value)."""
    return make_plan(TENTH)


def test_a_car_whose_turns_need_more_room_gets_a_larger_area_and_says_so(tmp_path, tenth_plan):
    """The default car fits 6 x 6 m. A 1:10 car's turns do not (at 6 m its predicted path
    gets 0.3 m out): the plan grows the area to the smallest that fits, in 0.5 m steps, and
    keeps the nominal path inside it; a side asked for that does not fit names the one that
    does."""
    from simrunner.workflows.excite import predict_path

    plan = tenth_plan
    assert AREA_M < plan.area_m <= AREA_M + 2.0 and (plan.area_m / 0.5).is_integer()
    xy = predict_path(plan, TENTH)
    assert plan.outside_area_m(xy[:, 0], xy[:, 1]) == 0.0
    with pytest.raises(PlanError, match=rf"area = 6 m: this car's plan does not fit it .* the smallest area it "
                                        rf"fits: {plan.area_m:g} x {plan.area_m:g} m") as err:
        make_plan(TENTH, area_m=6.0)
    assert "\n" not in str(err.value)
    assert make_plan(TENTH, area_m=plan.area_m + 1.0).area_m == plan.area_m + 1.0
    with pytest.raises(PlanError, match="expected 6 .. 15 m"):
        make_plan(CAR, area_m=5.0)
    back = ExcitationPlan.from_csv(plan.to_csv(tmp_path / "p.csv", extent=(0, 1, 0, 1)))
    assert back.area_m == plan.area_m and back.margin_m == plan.margin_m
    # its margin grows with its turning circle (1.8 times the default car's)
    assert plan.margin_m == pytest.approx(AREA_MARGIN_M * 1.8, abs=0.05)
    assert back.area_bounds_m()[1] - back.area_bounds_m()[0] == pytest.approx(plan.area_m)


def test_a_one_tenth_car_off_nominal_stays_in_its_area_closed_loop(tenth_plan):
    """A car of the design envelope on the 1:10 car's plan (trim and gain against its right
    turns) stays within the plan's margin: 0.11 m out, where following the turns at 90 % of
    the steering limit (it cannot steer their arcs then) took it 0.73 m out."""
    plan = tenth_plan
    car = with_effects(TENTH, steering_offset_rad=math.radians(2.0), steering_gain=0.85)
    log = run_plan(plan, car, dt_s=0.005, closed_loop=True, pose_noise_m=0.01, seed=3)
    assert plan.outside_area_m(log.x_m, log.y_m) <= 0.3 < plan.margin_m  # 0.11 m; at 90 %: 0.73 m
    assert log.duration_s < plan.duration_s + 30.0


@pytest.mark.parametrize("name", list(OFF_NOMINAL))
def test_closed_loop_keeps_off_nominal_cars_in_the_area_open_loop_does_not(name):
    """The turns played closed loop from a noisy pose keep the car inside the stated area
    plus the documented margin; the experiments themselves stay open loop (their commands
    are the plan's, in order). 5 ms physics steps keep this fast."""
    car = with_effects(CAR, **OFF_NOMINAL[name])
    log = run_plan(PLAN, car, dt_s=0.005, closed_loop=True, pose_noise_m=0.01, seed=3)
    assert _out_of_area_m(PLAN, log) <= AREA_MARGIN_M, name
    assert log.duration_s < PLAN.duration_s + 30.0  # no turn ran into its time-out
    assert np.allclose(np.diff(log.t_s), 0.02) and np.array_equal(log.frame, np.arange(len(log)))
    assert _experiment_blocks_in_order(PLAN, log)
    if "trim" in name:  # open loop, a trimmed car leaves the area (docs/calibration.md)
        assert _out_of_area_m(PLAN, run_plan(PLAN, car, dt_s=0.005)) > AREA_MARGIN_M


def test_follow_path_arrives_at_the_end_and_closed_loop_needs_turns():
    path = np.stack([np.linspace(0.0, 2.0, 101), np.zeros(101)], 1)
    kw = dict(wheelbase_m=0.175, steer_max_rad=0.36)
    step = follow_path(0.3, 0.2, 0.0, path, 0.0, 0, 0, **kw)
    assert step.steer_cmd_rad < 0.0 and not step.arrived and 10 <= step.progress <= 20  # back to the path
    assert not follow_path(1.9, 0.0, 0.0, path, 0.0, 90, 0, **kw).arrived
    assert follow_path(2.01, 0.05, 0.1, path, 0.0, 95, 0, **kw).arrived
    assert not follow_path(2.01, 0.05, math.pi, path, 0.0, 95, 0, **kw).arrived  # wrong way round
    assert follow_path(0.0, 0.0, 0.0, path, 0.0, 0, 80, **kw).progress >= 80  # led on along the path
    plain = ExcitationPlan(PLAN.t_s, PLAN.speed_cmd_mps, PLAN.steer_cmd_rad, PLAN.coast, PLAN.segment)
    with pytest.raises(PlanError, match="no turns to follow"):
        run_plan(plain, CAR, closed_loop=True)


@settings(max_examples=60, deadline=None)
@given(hs.lists(hs.floats(-3.0, 3.0), min_size=6, max_size=6))
def test_dubins_paths_end_at_the_goal(pose):
    """Every path the planner's turns are made of ends where it should (positions of the
    sampled arcs and straights)."""
    from trackgen.dubins import dubins_points as _dubins_points, dubins_segments as _dubins
    x0, y0, yaw0, x1, y1, yaw1 = pose
    segs = _dubins(x0, y0, yaw0, np.array([x1]), np.array([y1]), np.array([yaw1]), 0.55)
    ok = np.isfinite(segs).all(-1)[:, 0]
    assert ok[:4].sum() >= 1  # one of LSL, RSR, LSR, RSL always exists
    ends = _dubins_points(x0, y0, yaw0, np.nan_to_num(segs), 0.55)[:, 0, -1]
    assert np.allclose(ends[ok], [x1, y1], atol=1e-6)


EFFECT_VALUES = {
    "steering_offset": {"steering_offset_rad": 0.05}, "steering_gain": {"steering_gain": 0.8},
    "steering_lag": {"steering_lag_s": 0.1}, "steering_rate_limit": {"steering_rate_limit_radps": 1.5},
    "command_latency": {"command_latency_s": 0.08}, "motor_lag": {"motor_lag_s": 0.3},
    "throttle_deadband": {"throttle_deadband_mps": 0.3}, "rolling_resistance": {"rolling_resistance_coeff": 0.05},
    "drag": {"drag_coeff_kgpm": 0.2}, "tire_slip": {"tire_slip_understeer_radps2pm": 0.03},
    "friction": {"friction_scale": 0.6},
    "speed_scale": {"speed_scale": 0.9}, "steering_asymmetry": {"steering_asymmetry": 0.15},
    "steering_play": {"steering_play_rad": 0.04}, "esc_brake_reverse": {"esc_reverse_delay_s": 0.3},
    "accel_scale": {"accel_scale": 0.6}, "brake_scale": {"brake_scale": 0.6},
    "servo_rate_scale": {"servo_rate_scale": 0.3}, "steer_limit_scale": {"steer_limit_scale": 0.8},
    "mass_scale": {"mass_scale": 1.6}, "top_speed": {"top_speed_mps": 1.0}, "lift_lag": {"lift_lag_s": 0.5},
    "front_drive": {"front_share_shift": 0.5}, "inertia": {"inertia_scale": 0.4},
    "tyre_stiffness": {"tyre_stiffness_scale": 0.3}, "tyre_balance": {"tyre_balance": 0.4},
    "tyre_relaxation": {"tyre_relaxation_scale": 4.0},
}
# effects that show only where the drive and brake reach the tyres' grip (or the tyres slide): run
# on a car whose limits do (9 m/s^2; the default car's 3.1 m/s^2 leaves the grip untouched)
GRIP_LIMITED = {"front_drive", "inertia"}


@pytest.fixture(scope="module")
def nominal_coarse():
    """The plan's nominal run (5 ms steps) of each car the effects below are run on, simulated
    once for the module (the nominal of a grip-limited or slip-tyre car was simulated again
    for each of its effects; the tests only read it)."""
    runs: dict[CarDescription, RunLog] = {}

    def of(car: CarDescription) -> RunLog:
        if car not in runs:
            runs[car] = run_plan(PLAN, car, dt_s=0.005)
        return runs[car]

    return of


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_leaves_a_trace_in_its_segments(name, nominal_coarse):
    """Speed and yaw rate (pose-independent) differ from nominal in a segment kind that the
    catalogue says reveals the effect (5 ms steps keep this fast)."""
    car = CAR
    if name in GRIP_LIMITED:
        car = CAR.replace(drive=dataclasses.replace(CAR.drive, max_accel_mps2=9.0, max_brake_mps2=9.0))
    if EFFECTS[name].requires == "slip":  # the slip tyres' own numbers: on a car with slip tyres
        assert not EFFECTS[name].applies_to(CAR)
        car = CAR.replace(wheels=dataclasses.replace(CAR.wheels, tyre_model="slip"))
        assert EFFECTS[name].applies_to(car)
    nominal = nominal_coarse(car)
    log = run_plan(PLAN, with_effects(car, **EFFECT_VALUES[name]), dt_s=0.005)
    kinds = [k for k in EFFECTS[name].revealed_by if k in SEGMENT_KINDS]
    mask = np.zeros(len(PLAN), dtype=bool)
    for k in kinds:
        mask |= PLAN.kind_mask(k)
    d_speed = np.abs(log.speed_mps - nominal.speed_mps)[mask].max()
    d_yaw_rate = np.abs(log.yaw_rate_radps - nominal.yaw_rate_radps)[mask].max()
    assert max(d_speed, d_yaw_rate) > 0.1, (name, d_speed, d_yaw_rate)


def test_cli_writes_plan_and_simulated_log_with_every_column(tmp_path):
    plan_path, log_path = tmp_path / "plan.csv", tmp_path / "log.csv"
    res = CliRunner().invoke(excite_cmd, ["-o", str(plan_path), "--simulate", str(log_path), "--closed-loop",
                                          "--pose-noise", "0.01", "--dt", "0.005"])
    assert res.exit_code == 0, res.output
    assert "closed loop" in res.output and "inside the area" in res.output
    log = read_log(log_path)
    assert log.names == EXCITE_COLUMNS and log.coast.any()
    assert np.array_equal(ExcitationPlan.from_csv(plan_path).segment, PLAN.segment)
    res = CliRunner().invoke(excite_cmd, ["-o", str(plan_path), "--closed-loop"])
    assert res.exit_code == 2 and "--simulate" in res.output and "Traceback" not in res.output


def test_cli_tells_an_open_loop_run_that_leaves_the_area_to_close_the_loop(tmp_path):
    car_path = tmp_path / "trim.toml"
    car_path.write_text("[effects]\nsteering_offset_rad = 0.035\n")  # a 2-degree servo trim
    args = ["-o", str(tmp_path / "plan.csv"), "--car", str(car_path), "--simulate", str(tmp_path / "log.csv"),
            "--dt", "0.005"]
    res = CliRunner().invoke(excite_cmd, args)
    assert res.exit_code == 0, res.output
    assert "m outside the area" in res.output and "--closed-loop" in res.output
    res = CliRunner().invoke(excite_cmd, args + ["--closed-loop"])
    assert res.exit_code == 0 and "inside the area" in res.output and "--closed-loop" not in res.output


@settings(max_examples=40, deadline=None)
@given(hs.lists(hs.tuples(hs.floats(-3, 3), hs.floats(-0.5, 0.5), hs.booleans(),
                          hs.text("abcdefghij_:+-.0123456789", min_size=1, max_size=12),
                          hs.one_of(hs.none(), hs.tuples(hs.floats(-9, 9), hs.floats(-9, 9), hs.floats(-3, 3)))),
                min_size=2, max_size=30),
       hs.sampled_from([10.0, 25.0, 50.0, 100.0]))
def test_csv_round_trip_property(tmp_path_factory, rows, rate):
    n = len(rows)
    ref = np.array([r[4] if r[4] is not None else (math.nan,) * 3 for r in rows])
    plan = ExcitationPlan(np.arange(n) / rate, np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                          np.array([r[2] for r in rows], dtype=bool), tuple(r[3] for r in rows), rate_hz=rate,
                          ref_x_m=ref[:, 0], ref_y_m=ref[:, 1], ref_yaw_rad=ref[:, 2])
    path = plan.to_csv(tmp_path_factory.mktemp("p") / "plan.csv", extent=(0.0, 1.0, 0.0, 1.0))
    back = ExcitationPlan.from_csv(path)
    assert back.rate_hz == rate and back.segment == plan.segment and np.array_equal(back.coast, plan.coast)
    assert np.allclose(back.speed_cmd_mps, plan.speed_cmd_mps, atol=1e-6)
    assert np.allclose(back.steer_cmd_rad, plan.steer_cmd_rad, atol=1e-6)
    assert np.array_equal(back.reference_rows(), plan.reference_rows())
    assert np.allclose(back.ref_y_m, plan.ref_y_m, atol=1e-4, equal_nan=True)


@settings(max_examples=60, deadline=None)
@given(hs.text(max_size=200))
def test_from_csv_never_crashes_on_junk(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("j") / "plan.csv"
    path.write_text(text)
    try:
        ExcitationPlan.from_csv(path)
    except PlanError as err:
        assert "\n" not in str(err)


def test_run_plan_plays_in_the_simulator_the_factory_builds(nominal_coarse):
    """``sim_factory`` replaces ``make_sim``: the same simulator gives the same log bit for
    bit; a tilted floor (something the catalogue does not model) changes it."""
    from simrunner.car.effects import make_sim

    built = []

    def same(car, dt_s, start):
        built.append(dt_s)
        return make_sim(car, dt_s=dt_s, start=start)

    log = run_plan(PLAN, CAR, dt_s=0.005, sim_factory=same)
    assert built == [0.005] and np.array_equal(log.x_m, nominal_coarse(CAR).x_m)
    assert np.array_equal(log.speed_mps, nominal_coarse(CAR).speed_mps)
    tilted = run_plan(PLAN, CAR, dt_s=0.005,
                      sim_factory=lambda car, dt_s, start: make_sim(car, dt_s=dt_s, start=start, slope_rad=0.05))
    coasting = PLAN.coast.astype(bool)
    assert np.abs(tilted.speed_mps - nominal_coarse(CAR).speed_mps)[coasting].max() > 0.05


def test_dead_reckoning_integrates_speed_and_gyro_with_their_errors():
    from simrunner.workflows.excite import DeadReckoning

    pose = (0.0, 0.0, 0.0)
    for _ in range(50):  # 1 s at 1 m/s, straight
        pose = DeadReckoning().advance(pose, 1.0, 0.0, 0.02)
    assert pose == pytest.approx((1.0, 0.0, 0.0))
    pose = (0.0, 0.0, 0.0)
    for _ in range(500):  # a full circle of radius 1 m: back at the start
        pose = DeadReckoning().advance(pose, 2 * math.pi / 10.0, 2 * math.pi / 10.0, 0.02)
    assert pose[:2] == pytest.approx((0.0, 0.0), abs=1e-3) and pose[2] == pytest.approx(2 * math.pi)
    biased = DeadReckoning(gyro_bias_radps=0.01, odometry_scale=1.1).advance((0.0, 0.0, 0.0), 1.0, 0.0, 1.0)
    assert biased[2] == pytest.approx(0.01) and math.hypot(*biased[:2]) == pytest.approx(1.1)


def test_closed_loop_from_dead_reckoning_stays_in_the_area_while_the_gyro_bias_is_small():
    """A team without a camera steers the turns from its own wheel speed and gyro
    (docs/calibration.md): with a bias of 0.3 deg/s left after zeroing, the nominal car stays
    within the margin; at 1 deg/s the heading it believes is 1.6 rad off by the end and
    the car gets beyond the margin (0.85 m: the log holds where it really went)."""
    from simrunner.workflows.excite import DeadReckoning

    runs = {b: run_plan(PLAN, CAR, dt_s=0.005, closed_loop=True, seed=3,
                        dead_reckoning=DeadReckoning(gyro_bias_radps=math.radians(b))) for b in (0.0, 0.3, 1.0)}
    assert _out_of_area_m(PLAN, runs[0.0]) == 0.0
    assert 0.0 < _out_of_area_m(PLAN, runs[0.3]) <= AREA_MARGIN_M
    assert _out_of_area_m(PLAN, runs[1.0]) > AREA_MARGIN_M


def test_a_plan_header_with_a_bad_area_and_dead_reckoning_with_nan_are_one_line_errors(tmp_path):
    from simrunner.workflows.excite import DeadReckoning

    text = PLAN.to_csv(tmp_path / "p.csv").read_text()
    lines = text.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("# area_m="))
    for bad in ("7,5", "-3", "nan"):
        lines[at] = f"# area_m={bad}"
        (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
        with pytest.raises(PlanError, match=rf"bad.csv:{at + 1}: expected area_m= a positive number of metres"):
            ExcitationPlan.from_csv(tmp_path / "bad.csv")
    with pytest.raises(PlanError, match="expected finite numbers"):
        DeadReckoning(gyro_bias_radps=math.nan)
    res = CliRunner().invoke(excite_cmd, ["-o", str(tmp_path / "x.csv"), "--simulate", str(tmp_path / "y.csv"),
                                          "--closed-loop", "--dead-reckoning", "nan"])
    assert res.exit_code == 2 and "expected a finite gyro bias" in res.output
