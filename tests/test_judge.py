"""Judge: laps through the gate, backwards crossings, wheels off the road (simrunner.run.judge)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.run.judge import Judge
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from simrunner.track.load import SimTrack

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"
R_M = 1.5  # centreline radius of a ring track, driven counter-clockwise
HALF_ROAD_M = 0.275  # white 0.51 m + two 0.02 m edge lines
LINE_M = 0.02
WHEELBASE_M, TRACK_M = 0.175, 0.154


def ring_track(start: Pose2 | None = None) -> SimTrack:
    c = shapely.Point(0, 0)
    road = c.buffer(R_M + HALF_ROAD_M, 256).difference(c.buffer(R_M - HALF_ROAD_M, 256))
    white = c.buffer(R_M + HALF_ROAD_M - LINE_M, 256).difference(c.buffer(R_M - HALF_ROAD_M + LINE_M, 256))
    raster = build_raster([layer_from_polygon("edges", road.difference(white), BLACK_GRAY),
                           layer_from_polygon("lane", white, WHITE_GRAY)])
    gate = Pose2(R_M, 0.0, math.pi / 2)
    return SimTrack(name="ring", source=Path("ring"), raster=raster, surface_z_m=0.0,
                    start=start or gate, gate=gate, gate_half_width_m=HALF_ROAD_M,
                    lap_length_m=2 * math.pi * R_M)


def ring_pose(angle_rad: float, radius_m: float = R_M, ccw: bool = True) -> Pose2:
    heading = angle_rad + (math.pi / 2 if ccw else -math.pi / 2)
    return Pose2(radius_m * math.cos(angle_rad), radius_m * math.sin(angle_rad), heading)


def wheels(pose: Pose2) -> np.ndarray:
    """Contact points FL, FR, RL, RR of a car at ``pose`` (rear-axle midpoint)."""
    local = np.array([[WHEELBASE_M, TRACK_M / 2], [WHEELBASE_M, -TRACK_M / 2],
                      [0.0, TRACK_M / 2], [0.0, -TRACK_M / 2]])
    return pose.apply(local)


def drive(judge: Judge, angles_rad: np.ndarray, dt_s: float, ccw: bool = True):
    events = []
    for i, a in enumerate(angles_rad):
        p = ring_pose(a, ccw=ccw)
        events += judge.update(i * dt_s, p, wheels(p))
    return events


@pytest.fixture(scope="module")
def ring():
    return ring_track()


@pytest.mark.parametrize("speed_mps", [1.0, 2.7])
def test_laps_on_a_ring_from_the_gate(ring, speed_mps):
    dt = 0.013  # does not divide the lap time: crossings fall between updates
    lap_t = 2 * math.pi * R_M / speed_mps
    t = np.arange(0.0, 3.3 * lap_t, dt)
    judge = Judge(ring, laps=3)
    events = drive(judge, t * speed_mps / R_M, dt)
    assert judge.laps_completed == 3 and judge.finished
    # chord vs arc between updates: crossing-time error ~ (dt * v)^2 / R, well under 1 ms
    assert judge.lap_times_s == pytest.approx([lap_t] * 3, abs=1e-3)
    kinds = [e.kind for e in events]
    assert kinds == ["lap_start", "lap", "lap_start", "lap", "lap_start", "lap", "finished"]
    assert events[0].t_s == 0.0
    assert judge.distance_m == pytest.approx(speed_mps * t[-1], rel=1e-4)
    assert not judge.off_track


def test_start_behind_gate_starts_timing_at_the_first_crossing():
    behind = -0.3 / R_M
    track = ring_track(start=ring_pose(behind))
    judge = Judge(track, laps=2)
    dt, v = 0.01, 1.5
    t = np.arange(0.0, 8.0, dt)
    events = drive(judge, behind + t * v / R_M, dt)
    starts = [e for e in events if e.kind == "lap_start"]
    assert starts[0].t_s == pytest.approx(0.3 / v, abs=1e-6)
    assert judge.laps_completed == 1
    assert judge.lap_times_s[0] == pytest.approx(2 * math.pi * R_M / v, abs=1e-3)


def test_backward_crossings_never_count(ring):
    judge = Judge(ring, laps=1)
    t = np.arange(0.0, 15.0, 0.01)
    events = drive(judge, -t / R_M, 0.01, ccw=False)  # clockwise, 1 m/s, ~1.6 loops
    assert judge.laps_completed == 0
    # leaving the start line backwards is one backward crossing, each loop another
    assert [e.kind for e in events] == ["lap_start", "gate_backward", "gate_backward"]
    assert events[2].t_s == pytest.approx(2 * math.pi * R_M, abs=1e-3)


def test_reversing_across_the_gate_and_back_does_not_count():
    behind = -0.3 / R_M
    judge = Judge(ring_track(start=ring_pose(behind)), laps=1)
    angles = np.concatenate([np.linspace(behind, 0.2, 50), np.linspace(0.2, -0.2, 50),
                             np.linspace(-0.2, 0.3, 50)])
    events = drive(judge, angles, 0.02)
    assert [e.kind for e in events] == ["lap_start", "gate_backward"]
    assert judge.laps_completed == 0
    # ... and a full lap afterwards counts from the first crossing
    for i, a in enumerate(np.linspace(0.3, 2 * math.pi + 0.1, 400)):
        p = ring_pose(a)
        events += judge.update(3.0 + i * 0.02, p, wheels(p))
    assert judge.laps_completed == 1


def test_short_wiggle_across_the_gate_is_ignored(ring):
    judge = Judge(ring, laps=1)
    angles = np.concatenate([np.linspace(0, 0.1, 10), np.linspace(0.1, -0.1, 10), np.linspace(-0.1, 0.5, 10)])
    events = drive(judge, angles, 0.05)
    assert judge.laps_completed == 0
    assert "lap" not in [e.kind for e in events]


def test_gate_segment_has_finite_width(ring):
    """Crossing the gate's line outside its half width is not a crossing."""
    judge = Judge(ring, laps=1, min_lap_fraction=0.0)
    far = [Pose2(R_M + 0.5, y, math.pi / 2) for y in np.linspace(-0.5, 0.5, 11)]
    events = []
    for i, p in enumerate(far):
        events += judge.update(i * 0.1, p, wheels(p))
    assert not [e for e in events if e.kind in ("lap_start", "lap")]


def test_wheel_off_road_detected_wheel_on_edge_line_not(ring):
    judge = Judge(ring, laps=1)
    outer_edge = R_M + HALF_ROAD_M
    # Car heading north at x = X: its right wheels (FR, RR) are at X + TRACK_M / 2.
    def car_at(right_wheel_x):
        return Pose2(right_wheel_x - TRACK_M / 2, -0.05, math.pi / 2)

    on_line = car_at(outer_edge - LINE_M / 2)  # right wheels on the black edge line
    assert judge.update(0.0, on_line, wheels(on_line)) == []
    assert not judge.off_track
    half_over = car_at(outer_edge + 0.008)  # tyre (0.025 m) still touches the line
    judge.update(0.1, half_over, wheels(half_over))
    assert not judge.off_track
    out = car_at(outer_edge + 0.03)
    events = judge.update(0.2, out, wheels(out))
    assert judge.off_track and judge.off_wheels == ("FR", "RR")
    assert [e.kind for e in events] == ["off_track"] and "FR, RR" in events[0].text
    back = car_at(R_M)
    events = judge.update(0.3, back, wheels(back))
    assert not judge.off_track and [e.kind for e in events] == ["on_track"]


def test_the_other_disciplines_count_a_wheel_off_when_any_part_of_it_is(ring):
    """Rules summary section 4: "no part of any wheel may leave the track" - a tyre over the
    road's edge by a few millimetres is off for ``wheel_off="any_part"`` (the race's rule, the
    default, still counts it on while any part of it touches the road)."""
    outer_edge = R_M + HALF_ROAD_M

    def car_at(right_wheel_x):
        return Pose2(right_wheel_x - TRACK_M / 2, -0.05, math.pi / 2)

    inside = car_at(outer_edge - 0.0125 - 0.006)  # the tyre's outer edge 6 mm inside the road (5 mm pixels)
    over = car_at(outer_edge - 0.0125 + 0.006)    # ... 6 mm over it, its contact point on the road
    strict, whole = Judge(ring, laps=1, wheel_off="any_part"), Judge(ring, laps=1)
    for judge in (strict, whole):
        judge.update(0.0, inside, wheels(inside))
        assert not judge.off_track
    events = strict.update(0.1, over, wheels(over))
    assert strict.off_wheels == ("FR", "RR") and "partly off the track" in events[0].text
    assert whole.update(0.1, over, wheels(over)) == [] and not whole.off_track
    with pytest.raises(SimError, match="wheel_off"):
        Judge(ring, laps=1, wheel_off="some")


def test_bad_arguments(ring):
    with pytest.raises(SimError, match="laps"):
        Judge(ring, laps=0)
    with pytest.raises(SimError, match="min_lap_fraction"):
        Judge(ring, laps=1, min_lap_fraction=1.5)


def test_nxp_raceway_start_is_on_the_road_and_on_the_gate():
    from simrunner.track.load import load_track

    folder = TRACKS / "nxp_raceway"
    if not folder.is_dir():
        pytest.skip(f"NXP tracks not found at {TRACKS} (expected beside the checkout)")
    track = load_track(folder)
    judge = Judge(track, laps=1)
    events = judge.update(0.0, track.start, wheels(track.start))
    assert not judge.off_track
    assert [e.kind for e in events] == ["lap_start"] and judge.lap_started_s == 0.0
    # 0.3 m sideways the right wheels leave the 0.555 m road
    moved = track.start @ Pose2(0.0, -0.3, 0.0)
    judge.update(0.1, moved, wheels(moved))
    assert judge.off_track and judge.off_wheels == ("FR", "RR")


@settings(max_examples=15, deadline=None)
@given(dt=st.floats(0.004, 0.05), speed=st.floats(0.5, 3.0), phase=st.floats(0.0, 1.0))
def test_lap_time_does_not_depend_on_the_update_rate(ring, dt, speed, phase):
    lap_t = 2 * math.pi * R_M / speed
    t = np.arange(0.0, 1.05 * lap_t + 2 * dt, dt) + phase * dt
    judge = Judge(ring, laps=1)
    start = -0.05  # just behind the gate: lap 1 starts at the first crossing
    for ti in t:
        p = ring_pose(start + (ti - t[0]) * speed / R_M)
        judge.update(float(ti), p, wheels(p))
    assert judge.laps_completed == 1
    # the chord between updates cuts the circle: crossing error ~ (speed dt)^2 / (8 R) / speed
    assert judge.lap_times_s[0] == pytest.approx(lap_t, abs=1e-6 + (speed * dt) ** 2 / R_M)


def _polyline_poses(points: list[tuple[float, float]], step_m: float = 0.02) -> list[Pose2]:
    poses = []
    for (x0, y0), (x1, y1) in zip(points[:-1], points[1:]):
        n = max(1, int(math.hypot(x1 - x0, y1 - y0) / step_m))
        yaw = math.atan2(y1 - y0, x1 - x0)
        poses += [Pose2(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
    return poses


def _lower_loop_poses() -> list[Pose2]:
    """The thesis figure-8 driven the wrong way: turning right at the crossroads and driving
    only the lower loop (three times, so the distance alone would pass)."""
    # lower loop: crossroads centre (0.3, 0) south to (0.3, -0.8), 270 deg right turn of
    # radius 0.8 about (-0.5, -0.8), back east along y = 0 through the start gate at x = 0
    arc = [(-0.5 + 0.8 * math.cos(a), -0.8 + 0.8 * math.sin(a))
           for a in np.linspace(0.0, -1.5 * math.pi, 120)]
    loop = [(0.3, 0.0), (0.3, -0.8)] + arc[1:] + [(0.3, 0.0)]
    return _polyline_poses([(0.0, 0.0)] + loop + loop[1:] + loop[1:])


def test_turning_at_the_crossroads_leaves_the_course_and_names_the_piece():
    from simrunner.track.load import load_track

    track = load_track(Path(__file__).resolve().parents[1] / "examples" / "thesis_figure8.txt")
    judge = Judge(track, laps=1)
    events = []
    for i, p in enumerate(_lower_loop_poses()):
        events += judge.update(i * 0.01, p, wheels(p))
    kinds = [e.kind for e in events]
    assert "lap" not in kinds and judge.laps_completed == 0
    off = [e for e in events if e.kind == "off_course"]
    # the layout's first line is the crossroads (examples/thesis_figure8.txt, line 7)
    assert off and off[0].text.startswith("turned at CROSSROADS (piece 0, line 7)")
    assert judge.off_course == "turned at CROSSROADS (piece 0, line 7)"
    # the car turned 0.3 + 0.15 m past the crossing's centre: caught on the crossing road
    assert 0.3 < -float(off[0].text.split(", ")[-1].split(")")[0]) < 0.6
    short = [e for e in events if e.kind == "lap_short"]
    assert short and "after the car turned at CROSSROADS" in short[0].text


def test_without_a_course_the_coverage_rule_catches_the_shortcut():
    import dataclasses

    from simrunner.track.load import load_track

    track = load_track(Path(__file__).resolve().parents[1] / "examples" / "thesis_figure8.txt")
    judge = Judge(dataclasses.replace(track, course=None), laps=1)
    events = []
    for i, p in enumerate(_lower_loop_poses()):
        events += judge.update(i * 0.01, p, wheels(p))
    assert judge.laps_completed == 0 and "off_course" not in [e.kind for e in events]
    short = [e for e in events if e.kind == "lap_short"]
    assert short and "% of the track" in short[0].text
    assert judge.coverage < 0.8


def test_full_figure8_centreline_lap_counts():
    from simrunner.track.load import load_track

    track = load_track(Path(__file__).resolve().parents[1] / "examples" / "thesis_figure8.txt")
    pts = [tuple(p) for p in np.asarray(track.centreline)]
    poses = _polyline_poses(pts + [pts[0], pts[1]])
    judge = Judge(track, laps=1)
    for i, p in enumerate(poses):
        judge.update(i * 0.01, p, wheels(p))
    assert judge.laps_completed == 1


def test_an_inside_line_on_the_kit_oval_drives_less_but_follows_the_whole_course():
    """kit_S: two 0.72 m straights, two half circles of 0.445 m. A car keeping 0.05 m inside
    the centreline drives 2 x 0.72 + 2 pi 0.395 = 3.922 m a lap (0.926 of the centreline)
    and the judge counts it: the course it followed (``lap_courses_m``) is the whole lap."""
    from simrunner.track.load import load_track

    track = load_track(Path(__file__).resolve().parents[1] / "examples" / "kit_S.txt")
    inside = 0.445 - 0.05
    half = [(0.72 + inside * math.sin(a), 0.445 - inside * math.cos(a)) for a in np.linspace(0, math.pi, 60)]
    lap = [(x, y) for x, y in half] + [(0.72 - x, 0.89 - y) for x, y in half]
    poses = _polyline_poses([(-0.3, 0.05)] + lap + lap + [lap[0]], step_m=0.01)
    judge = Judge(track, laps=2)
    for i, p in enumerate(poses):
        judge.update(i * 0.01, p, wheels(p))
    assert judge.laps_completed == 2 and judge.off_course == ""
    course = track.course.length_m
    assert judge.lap_distances_m == pytest.approx([2 * 0.72 + 2 * math.pi * inside] * 2, abs=0.01)
    assert judge.lap_courses_m == pytest.approx([course, course], abs=0.01)
