"""Start pose (``--start``, ``--start-before-finish``), the free floor (``--track floor``) and
``--keep-driving`` (issue 13 items 5 and 6)."""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings, strategies as st

from pieces.pose import Pose2
from simrunner.cli import main as cli
from simrunner.telemetry.log import read_log
from simrunner.run.runner import drive, resolve_track
from simrunner.run.settings import RunSettings, SettingsError
from simrunner.run.start import along_centreline, start_pose, wheel_points
from vehicle.description import CarDescription

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"
CAR = CarDescription()
BUMPER_M = CAR.chassis.length_m - CAR.chassis.rear_overhang_m  # car frame -> front bumper

STILL = "def main(s):\n    s.get_image()\n"


def write(tmp_path: Path, body: str, name: str = "ctrl.py") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


def gate_frame(pose: Pose2, gate: Pose2) -> tuple[float, float]:
    """(along, across) of ``pose`` in the gate's frame."""
    local = gate.inverse() @ pose
    return local.x_m, local.y_m


# -- --start ------------------------------------------------------------------------------------
def test_start_pose_from_the_cli_in_degrees(tmp_path):
    ctrl = write(tmp_path, STILL)
    res = CliRunner().invoke(cli, ["drive", str(ctrl), "--start", "0.1,-0.02,5",
                                   "--csv", str(tmp_path / "t.csv")])
    assert res.exit_code == 0, res.output
    first = read_log(tmp_path / "t.csv")
    assert first.x_m[0] == pytest.approx(0.1, abs=1e-5) and first.y_m[0] == pytest.approx(-0.02, abs=1e-5)
    assert first.yaw_rad[0] == pytest.approx(math.radians(5), abs=1e-5)


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "1,2,3,4", "nan,0,0", "1,inf,0", ""])
def test_bad_start_text_is_one_line(tmp_path, text):
    res = CliRunner().invoke(cli, ["drive", str(write(tmp_path, STILL)), "--start", text])
    assert res.exit_code == 2 and "expected X,Y,YAW (metres, metres, degrees)" in res.output


def test_a_start_off_the_road_is_refused_before_the_run(tmp_path):
    marker = tmp_path / "ran"
    ctrl = write(tmp_path, f"open({str(marker)!r}, 'w').close()\n" + STILL)
    with pytest.raises(SettingsError, match=r"start: the car at \(5\.000 m, 5\.000 m, 0\.0 deg\) "
                                            r"would have wheel\(s\) FL, FR, RL, RR off the road"):
        drive(ctrl, start=(5.0, 5.0, 0.0))
    assert not marker.exists()
    with pytest.raises(SettingsError, match="give one of them, not both"):
        RunSettings(start=(0, 0, 0), start_before_finish_m=1.0)
    with pytest.raises(SettingsError, match="start_before_finish_m = -1"):
        RunSettings(start_before_finish_m=-1)


# -- --start-before-finish ------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(d=st.floats(0.0, 30.0), side=st.floats(1.0, 5.0), gate_at=st.floats(0.05, 0.95))
def test_along_a_straight_centreline_the_car_is_exactly_that_far_back(d, side, gate_at):
    # a closed rectangle (driving counter-clockwise), the gate on its bottom side heading +x
    centre = np.array([[0, 0], [side, 0], [side, 1.0], [0, 1.0], [0, 0]], dtype=float)
    gate = Pose2(gate_at * side, 0.0, 0.0)
    pose = along_centreline(centre, gate, d)
    perimeter = 2 * side + 2.0
    back = d % perimeter
    if back <= gate.x_m - 1e-9:  # still on the bottom side
        assert (pose.x_m, pose.y_m) == pytest.approx((gate.x_m - back, 0.0), abs=1e-9)
        assert pose.yaw_rad == pytest.approx(0.0, abs=1e-12)
    # the pose is on the loop, heading along it
    on_side = [abs(pose.y_m) < 1e-9, abs(pose.x_m - side) < 1e-9, abs(pose.y_m - 1) < 1e-9, abs(pose.x_m) < 1e-9]
    assert any(on_side)
    # walking the other way round (gate heading against the polyline) mirrors the result
    reverse = along_centreline(centre[::-1], gate, d)
    assert (reverse.x_m, reverse.y_m) == pytest.approx((pose.x_m, pose.y_m), abs=1e-9)


def test_front_bumper_before_the_finish_line_on_a_layout(tmp_path):
    track, _ = resolve_track(EXAMPLES / "oval_start.txt", CAR)
    for d in (0.0, 0.2):  # the straight before the oval's gate is 0.5 m long
        pose = start_pose(track, CAR, RunSettings(start_before_finish_m=d))
        along, across = gate_frame(pose, track.gate)
        assert along == pytest.approx(-(d + BUMPER_M), abs=1e-6) and across == pytest.approx(0, abs=1e-6)


@pytest.mark.parametrize("name", ["nxp_raceway", "nxp_raceway_octagon"])
def test_start_before_finish_on_a_gazebo_track_traces_the_road(name):
    folder = SHARED_TRACKS / name
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    track, _ = resolve_track(folder, CAR)
    assert track.centreline is None  # traced on the raster
    near = start_pose(track, CAR, RunSettings(start_before_finish_m=0.0))
    along, across = gate_frame(near, track.gate)
    assert along == pytest.approx(-BUMPER_M, abs=0.02)
    for d in (0.5, 3.0, 10.0):
        pose = start_pose(track, CAR, RunSettings(start_before_finish_m=d))
        assert track.raster.on_road(wheel_points(CAR, pose)).all()
        # in the middle of the road: as far from the left edge as from the right one
        from simrunner.track.load import road_extents_m

        left, right = road_extents_m(track.raster, pose)
        assert abs(left - right) < 0.1, (d, left, right)


def test_a_lap_from_before_the_finish_starts_at_the_line(tmp_path):
    r = drive(EXAMPLES / "line_follower.py", track=EXAMPLES / "oval_start.txt",
              start_before_finish_m=1.0, csv=tmp_path / "t.csv")
    assert r.outcome == "finished", r.message
    log = read_log(tmp_path / "t.csv")
    gate_x = resolve_track(EXAMPLES / "oval_start.txt", CAR)[0].gate.x_m
    crossed = float(log.t_s[np.argmax(log.x_m >= gate_x)])
    assert r.sim_time_s - r.lap_times_s[0] == pytest.approx(crossed, abs=0.03)


def test_the_thesis_camera_row_test_runs_before_the_finish_line(tmp_path):
    r = drive(EXAMPLES / "camera_row_test.py", start_before_finish_m=0.3, time_limit_s=2.0)
    assert r.outcome == "timeout" and r.laps_completed == 0  # the car stands still


# -- the free floor and --keep-driving ---------------------------------------------------------------
def test_velocity_test_on_the_free_floor(tmp_path):
    ctrl = write(tmp_path, """\
        def main(s):
            s.set_speed(0.5)
            t0 = s.get_time()
            while s.get_time() - t0 < 4.0:
                s.add_data(["x"])
            s.set_speed(0.0)
            s.sleep(1.0)
        """)
    r = drive(ctrl, track="floor", csv=tmp_path / "t.csv")
    assert r.outcome == "controller_returned" and not r.log.off_track.any()
    assert r.log.x_m[-1] > 1.7  # straight on, well beyond any road of the default track
    drive_at_floor_edge = drive(ctrl, track="floor", start=(2.9, 0.0, 0.0))
    assert drive_at_floor_edge.outcome == "controller_returned"  # the floor goes on
    with pytest.raises(SettingsError, match="free floor has no finish line"):
        drive(ctrl, track="floor", start_before_finish_m=1.0)


def test_the_free_floor_has_no_laps_and_a_60_s_limit(tmp_path):
    from simrunner.run.runner import Run

    floor, label = resolve_track("floor", CAR)
    assert label == "floor" and not floor.judged
    assert Run(floor, CAR, RunSettings(laps=5)).settings.time_limit_s == 60.0
    r = drive(write(tmp_path, "def main(s):\n    s.sleep(1e9)\n"), track=floor, time_limit_s=2.0)
    assert r.outcome == "timeout" and r.laps_completed == 0


def test_keep_driving_records_leaving_the_track(tmp_path):
    ctrl = write(tmp_path, """\
        def main(s):
            s.set_speed_and_servo(1.0, 0.4)
            while True:
                s.get_image()
        """)
    oval = Path(__file__).resolve().parents[1] / "examples" / "kit_S.txt"
    stopped = drive(ctrl, track=oval, time_limit_s=6.0, off_track_wheels=1)
    assert stopped.outcome == "off_track"
    kept = drive(ctrl, track=oval, time_limit_s=6.0, keep_driving=True, csv=tmp_path / "t.csv")
    assert kept.outcome == "timeout" and kept.sim_time_s == pytest.approx(6.0)
    log = read_log(tmp_path / "t.csv")
    assert log.off_track.any()
    first_off = float(log.t_s[np.argmax(log.off_track)])
    assert first_off == pytest.approx(stopped.sim_time_s, abs=1e-9)
    assert any(f"left the track" in w and f"t = {first_off:.3f} s" in w for w in kept.warnings)
    assert any(w.startswith("left the course ") and "(first: left the course at START_FINISH (piece 0, line 7)"
               in w for w in kept.warnings)
    res = CliRunner().invoke(cli, ["drive", str(ctrl), "--keep-driving", "--time-limit", "3"])
    assert "outcome: timeout" in res.output
