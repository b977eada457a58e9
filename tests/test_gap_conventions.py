"""Sign and unit conventions of a measured log (simrunner.workflows.gap.conventions): a
column logged reversed or in another unit is refused with its name and the fix; a log in the
run log's conventions, with car effects in it, never is."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli.gap import gap
from simrunner.telemetry.log import LogError, write_log
from simrunner.workflows.gap.conventions import check_conventions
from simrunner.workflows.gap.glitches import find_glitches, glitch_mask
from simrunner.workflows.gap.synth import make_measured_log
from vehicle.description import CarDescription

CAR = CarDescription()
SENSORS = ("both", "pose_speed", "pose", "speed_gyro")


def check(log):
    return check_conventions(log, CAR.chassis.wheelbase_m, CAR.steering.limit_rad,
                             glitch_mask(log, find_glitches(log)))


@pytest.fixture(scope="module")
def logs():
    """20 s of the excitation plan (straights, step steers, circles), each sensor set."""
    return {s: make_measured_log(None, rng=np.random.default_rng(3), sensors=s, duration_s=20.0)[0]
            for s in SENSORS}


@pytest.mark.parametrize("sensors", SENSORS)
def test_a_log_in_the_run_log_conventions_passes(logs, sensors):
    check(logs[sensors])


def test_what_a_log_shows_too_little_of_is_listed_as_not_checked(logs):
    """Every check is made on 20 s of the plan with a pose (nothing listed); without a pose
    the speed sensor's unit has nothing to be compared with; a log that only drives straight
    on shows no steering, so its sign (and the gyro's unit) go unchecked, and the report and
    its JSON say so instead of passing them in silence."""
    assert check(logs["both"]) == () and check(logs["pose"]) == ()
    assert check(logs["speed_gyro"]) == ("speed_mps's unit (no pose to compare it with; only its sign, "
                                         "against the command)",)
    straight = logs["speed_gyro"].with_columns(steer_cmd_rad=np.zeros(len(logs["speed_gyro"])))
    assert any(u.startswith("steer_cmd_rad's sign (too little turning) and yaw_rate_radps's unit")
               for u in check(straight))
    pose = logs["pose"]
    short = pose.subset(int(np.searchsorted(pose.t_s, 3.0)))  # the ramp from rest: little travel, no turn
    assert {"yaw_rad's sign and unit (too little travel)", "steer_cmd_rad's sign (too little turning)"} <= set(
        check(short))


@pytest.mark.parametrize("effect, value", [("steering_gain", 0.55), ("steering_offset", -0.06),
                                           ("speed_scale", 1.3), ("top_speed", 1.0), ("tire_slip", 0.03),
                                           ("command_latency", 0.15), ("esc_brake_reverse", 0.6)])
def test_car_effects_are_not_taken_for_a_convention(effect, value):
    log, _ = make_measured_log(effect, value=value, rng=np.random.default_rng(4), sensors="both", duration_s=20.0)
    check(log)
    check(log.with_columns(x_m=None, y_m=None, yaw_rad=None))  # as an encoder + gyro log


DEG = 180.0 / np.pi
# mistake -> (columns scaled by factors, text the refusal holds)
MISTAKES = {
    "gyro reversed": (dict(yaw_rate_radps=-1.0), "yaw_rate_radps: is -"),
    "gyro in deg/s": (dict(yaw_rate_radps=DEG), 'unit = "deg/s"'),
    "speed reversed": (dict(speed_mps=-1.0), "speed_mps: is -"),
    "speed in km/h": (dict(speed_mps=3.6), 'unit = "km/h"'),
    "speed in mm/s": (dict(speed_mps=1000.0), 'unit = "mm/s"'),
    "heading in degrees": (dict(yaw_rad=DEG), 'yaw_rad: points along the motion'),
    "heading clockwise": (dict(yaw_rad=-1.0), "yaw_rad: points along the motion"),
    "steering + = right": (dict(steer_cmd_rad=-1.0), "steer_cmd_rad: the car turns"),
    "steering in degrees": (dict(steer_cmd_rad=DEG), "steer_cmd_rad: reaches"),
    "steering in servo units": (dict(steer_cmd_rad=512 / 0.4), "steer_cmd_rad: reaches"),
    "speed command reversed": (dict(speed_cmd_mps=-1.0), "speed_cmd_mps: the measured"),
    "speed command as a duty fraction": (dict(speed_cmd_mps=1 / 3.1), "speed_mps or speed_cmd_mps: the measured speed is"),
}


def scaled(log, factors):
    return log.with_columns(**{c: f * getattr(log, c) for c, f in factors.items()})


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_a_reversed_or_misunited_column_is_refused_with_its_name_and_the_fix(logs, mistake):
    factors, expected = MISTAKES[mistake]
    bad = scaled(logs["both"], factors)
    with pytest.raises(LogError) as err:
        check(bad)
    text = str(err.value)
    assert text.startswith(f"{bad.source}:1: ") and expected in text and "\n" not in text
    assert "map it" in text  # what to do about it


@pytest.mark.parametrize("sensors, column, mistake", [
    ("speed_gyro", "steer_cmd_rad or yaw_rate_radps", dict(steer_cmd_rad=-1.0)),
    ("speed_gyro", "steer_cmd_rad or yaw_rate_radps", dict(yaw_rate_radps=-1.0)),
    ("speed_gyro", "speed_cmd_mps or speed_mps", dict(speed_mps=-1.0)),
    ("speed_gyro", "yaw_rate_radps: is", dict(yaw_rate_radps=180.0 / np.pi)),
    ("pose", "steer_cmd_rad: the car turns", dict(steer_cmd_rad=-1.0)),
    ("pose", "yaw_rad: points along the motion", dict(yaw_rad=180.0 / np.pi)),
])
def test_without_a_second_view_the_message_names_every_column_that_may_be_wrong(logs, sensors, column, mistake):
    bad = scaled(logs[sensors], mistake)
    with pytest.raises(LogError, match=column):
        check(bad)


def test_cli_refuses_a_reversed_steering_column_exit_2_one_line_nothing_written(logs, tmp_path):
    log = logs["pose_speed"]
    path = tmp_path / "reversed.csv"
    write_log(log.with_columns(steer_cmd_rad=-log.steer_cmd_rad), path)
    out = tmp_path / "out"
    res = CliRunner().invoke(gap, [str(path), "-o", str(out), "--no-progress"])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert lines == [f"simrunner gap: {path}:1: steer_cmd_rad: " + lines[0].split(": steer_cmd_rad: ", 1)[1]]
    assert "expected + = left" in lines[0] and "Traceback" not in res.output
    assert not out.exists() and list(tmp_path.iterdir()) == [path]


def test_a_standing_car_s_localisation_jitter_is_not_taken_for_motion(logs):
    """A minute at rest with 3 cm of pose jitter in any direction (a particle filter), then the
    drive: the heading is judged on the path's chords that really travel, and passes."""
    drive = logs["pose"]
    rng = np.random.default_rng(7)
    n = 3000  # 60 s at 50 Hz
    still_t = np.arange(n) * 0.02
    cols = {"t_s": np.r_[still_t, drive.t_s + still_t[-1] + 0.02],
            "x_m": np.r_[drive.x_m[0] + 0.03 * rng.standard_normal(n), drive.x_m],
            "y_m": np.r_[drive.y_m[0] + 0.03 * rng.standard_normal(n), drive.y_m],
            "yaw_rad": np.r_[drive.yaw_rad[0] + 0.02 * rng.standard_normal(n), drive.yaw_rad],
            "speed_cmd_mps": np.r_[np.zeros(n), drive.speed_cmd_mps],
            "steer_cmd_rad": np.r_[np.zeros(n), drive.steer_cmd_rad]}
    from simrunner.telemetry.log import log_from_columns

    check(log_from_columns(cols, "still-then-drive"))
