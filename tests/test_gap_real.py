"""The gap workflow's per-log machinery on real car logs (shared/data/real_logs: an F1/10 car,
particle-filter pose at 21-28 Hz with irregular stamps, wheel odometry, reversing).

Skipped when the data are absent (``NXPCUP_REAL_LOGS`` names another folder). Only the
cheap parts run here - read, check, glitches, smoothing, windows, a replay on the kinematic
stand-in - not the whole workflow (slow). Facts asserted about a file are facts of that
file (its README), not thresholds tuned to it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from simrunner.telemetry.log import LogError, read_log
from simrunner.workflows.gap.glitches import GlitchKind, find_glitches, glitch_mask, time_gaps
from simrunner.workflows.gap.logs import check_measured, derive
from simrunner.workflows.gap.regimes import REGIMES, segment
from simrunner.workflows.gap.replay import (FIT_SIGNALS, make_windows, replay, residuals, signals_of,
                                            split_windows, window_mask)
from helpers import kin_factory
from vehicle.description import load_car

REAL = Path(os.environ.get("NXPCUP_REAL_LOGS", Path(__file__).resolve().parents[2] / "shared/data/real_logs"))
LOGS = ("f1tenth_DS2.csv", "f1tenth_DS3.csv")
pytestmark = pytest.mark.skipif(not (REAL / LOGS[0]).exists(), reason=f"no real logs in {REAL}")


@pytest.fixture(scope="module")
def car():
    return load_car(REAL / "f1tenth_car.toml")


@pytest.fixture(scope="module", params=LOGS)
def prepared(request, car):
    log = check_measured(read_log(REAL / request.param))
    glitches = find_glitches(log, car)
    exclude = glitch_mask(log, glitches)
    derived = derive(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude=exclude)
    windows = make_windows(log, 2.0, exclude=exclude)
    return request.param, log, glitches, exclude, derived, windows


def test_real_logs_read_and_support_every_signal(prepared):
    _, log, *_ = prepared
    assert signals_of(log) == FIT_SIGNALS
    assert log.duration_s > 100.0


def test_glitches_lie_in_the_log(prepared):
    _, log, glitches, exclude, *_ = prepared
    t = log.t_s
    for g in glitches:
        assert t[0] <= g.t_start_s < g.t_end_s <= t[-1] and g.detail
    assert exclude.shape == (len(log),) and exclude.sum() < 0.05 * len(log)


def test_real_logs_pass_the_conventions_check(prepared, car):
    """A real car's pose, odometry and commands in the run log's conventions are not refused
    (simrunner.workflows.gap.conventions: the heading follows 99.7-99.8 % of the path's chords
    here, against 85 % asked)."""
    from simrunner.workflows.gap.conventions import check_conventions

    _, log, _, exclude, *_ = prepared
    check_conventions(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude)


def test_ds2_jump_and_gaps_are_found():
    glitches = find_glitches(check_measured(read_log(REAL / "f1tenth_DS2.csv")))
    # the 9.6-m step of the pose happens across 27.8 s without any sample (README: "a 9.6-m
    # localisation jump"): a time gap, with the step named
    big = [g for g in glitches if g.t_start_s <= 115.2 and g.t_end_s >= 142.9]
    assert [g.kind for g in big] == [GlitchKind.TIME_GAP] and "moved 9.58 m" in big[0].detail
    assert sum(g.kind is GlitchKind.TIME_GAP for g in glitches) >= 3  # also 1.98 s and 1.75 s without samples
    # the pose jumps 0.84 m in one step while the car stands (odometry 0 m/s)
    assert any(g.kind is GlitchKind.JUMP and g.t_start_s == pytest.approx(145.714, abs=0.01) for g in glitches)


def test_windows_avoid_glitches_and_gaps(prepared):
    _, log, glitches, exclude, derived, windows = prepared
    t = log.t_s
    gaps = time_gaps(t)
    for w in windows:
        assert not exclude[w.start:w.stop].any() and not gaps[w.start:w.stop - 1].any()
    covered = sum(t[w.stop - 1] - t[w.start] for w in windows)
    usable = log.duration_s - float(np.sum(np.diff(t)[gaps]))
    assert covered > 0.85 * usable
    fit, held = split_windows(windows)
    assert len(fit) >= 20 and len(held) >= 10
    inside = window_mask(len(log), windows)
    for name in ("x_m", "y_m", "yaw_rad", "speed_mps", "yaw_rate_radps", "steer_rad"):
        assert np.isfinite(getattr(derived, name)[inside]).all()


def test_regimes_and_a_replay_run(prepared, car):
    _, log, _, _, derived, windows = prepared
    masks = segment(log, derived, car)
    assert set(masks) == set(REGIMES) and masks["reversing"].any()
    some = windows[::8]
    res = residuals(log, derived, replay(car, log, derived, some, dt_s=0.005, sim_factory=kin_factory))
    inside = window_mask(len(log), some)
    for s in FIT_SIGNALS:
        assert np.isfinite(res[s][inside]).all()
        assert np.isnan(res[s][~inside]).all()


# -- the same runs with partial sensors, as a team would log them (bench/real_topics.py) ----------
@pytest.mark.skipif(not (REAL / "raw" / "DS2" / "imuData.csv").exists(), reason="no raw topic files")
@pytest.mark.parametrize("data_set", ["DS2", "DS3"])
def test_real_partial_sensor_logs_read_through_a_mapping_and_prepare(data_set, tmp_path, car):
    """The raw topics merged into an encoder + gyro log and a pose-only log with the topics'
    own names and units (split ROS stamps, gyro in deg/s, a quaternion), read through a column
    mapping: each gives the signals its sensors support and clean windows, and the gyro, read
    in deg/s, turns with the pose (same sign and scale: the topic's unit)."""
    from bench.real_topics import COLUMNS, partial_log_csv
    from simrunner.telemetry.columns import column_map_from
    from simrunner.workflows.gap.conventions import check_conventions

    logs = {}
    for sensors in ("encoder_gyro", "pose"):
        path = tmp_path / f"{sensors}.csv"
        assert partial_log_csv(REAL / "raw" / data_set, path, sensors) > 2000
        logs[sensors] = log = check_measured(read_log(path, columns=column_map_from(None, COLUMNS[sensors])))
        assert log.t_s[0] > 1.6e9 and log.duration_s > 100.0  # ROS time, as logged
        glitches = find_glitches(log, car)
        # the encoder's hard braking (a wheel that locks for a second) is the car's, no spike
        assert not [g for g in glitches if g.kind is GlitchKind.SPIKE]
        exclude = glitch_mask(log, glitches)
        check_conventions(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude)
        derived = derive(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude=exclude)
        fit, held = split_windows(make_windows(log, 2.0, exclude=exclude))
        assert len(fit) >= 20 and len(held) >= 10
        inside = window_mask(len(log), fit + held)
        assert np.isfinite(derived.yaw_rate_radps[inside]).all() and np.isfinite(derived.speed_mps[inside]).all()
    assert signals_of(logs["encoder_gyro"]) == ("speed_mps", "yaw_rate_radps")
    assert signals_of(logs["pose"]) == ("along_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps")
    gyro, pose = logs["encoder_gyro"], logs["pose"]
    pose_rate = np.gradient(np.unwrap(pose.yaw_rad), pose.t_s)
    gyro_at_pose = np.interp(pose.t_s, gyro.t_s, gyro.yaw_rate_radps)
    turning = np.abs(pose_rate) > 0.3
    slope = np.sum(gyro_at_pose[turning] * pose_rate[turning]) / np.sum(pose_rate[turning] ** 2)
    assert 0.7 < slope < 1.3
    # the gyro read without its unit (deg/s taken as rad/s) is refused, naming the unit
    as_logged = [c for c in COLUMNS["encoder_gyro"] if not c.startswith("yaw_rate_radps")] + ["yaw_rate_radps=gyro_z"]
    raw = read_log(tmp_path / "encoder_gyro.csv", columns=column_map_from(None, as_logged))
    with pytest.raises(LogError, match='yaw_rate_radps: .*unit = "deg/s"'):
        check_conventions(raw, car.chassis.wheelbase_m, car.steering.limit_rad, glitch_mask(raw, find_glitches(raw, car)))


def test_ds2_has_one_brake_to_reverse_and_it_stays_in_the_fit(car):
    """DS2 (README: reversing) commands reverse while rolling forward once at speed (113.9 s,
    from 4.4 m/s) and once from rest (87.8 s, a smoothed 0.11 m/s for one sample): only the
    first is a brake-to-reverse window, and a lone group stays in the fit windows."""
    from simrunner.workflows.gap.workflow import prepare, window_strata

    part = prepare(read_log(REAL / "f1tenth_DS2.csv"), car)
    windows = sorted(part.fit_windows + part.held_windows, key=lambda w: w.start)
    strata = window_strata(part.log, part.derived, segment(part.log, part.derived, car), windows,
                           car.drive.max_brake_mps2)
    onset = [w for w, s in zip(windows, strata) if s == "brake_to_reverse"]
    assert len(onset) == 1 and part.log.t_s[onset[0].start] < 113.95 < part.log.t_s[onset[0].stop - 1]
    assert onset[0] in part.fit_windows
    loose = window_strata(part.log, part.derived, segment(part.log, part.derived, car), windows)
    assert loose.count("brake_to_reverse") == 2  # with settings.moving_mps alone the blip at rest counts
