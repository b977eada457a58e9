"""The Pixy2 (issue 47, item 4): line tracking from a frame (lines, intersections, tracking,
the Vector and its turns), the Python API, the C and C++ APIs, and Pixy2 controllers that
lap the tracks."""
from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simrunner.errors import CameraError
from simrunner.telemetry.log import read_log
from simrunner.run.native.build import INCLUDE_DIR
from simrunner.run.runner import drive
from simrunner.sensors.pixy2 import (LINE_ALL_FEATURES, LINE_FLAG_INTERSECTION_PRESENT,
                                     LINE_INTERSECTION, LINE_MODE_WHITE_LINE, LINE_VECTOR,
                                     PIXY_RESULT_BUSY, LineTracker, grid_image, scan_points)
from vehicle.description import Pixy2, load_car

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
PIXY_CAR = EXAMPLES / "pixy2_car.toml"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"
W, H = 316, 208  # the Pixy2 frame; the grid is 79 x 52 (4 x 4 blocks)
WHITE, BLACK = 220, 20
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and not os.environ.get("CC"),
                              reason="no C compiler (apt-get install build-essential)")


def frame_with(*segments, width_px: float = 12.0, background=WHITE, ink=BLACK) -> np.ndarray:
    """A frame with dark straight strokes ``(x0, y0, x1, y1)`` in grid pixels, ``width_px``
    frame pixels wide (4 frame pixels = 1 grid pixel)."""
    yy, xx = np.mgrid[0:H, 0:W]
    img = np.full((H, W), background, np.float64)
    for x0, y0, x1, y1 in segments:
        a = np.array([x0 + 0.5, y0 + 0.5]) * 4.0
        b = np.array([x1 + 0.5, y1 + 0.5]) * 4.0
        d = b - a
        t = np.clip(((xx - a[0]) * d[0] + (yy - a[1]) * d[1]) / (d @ d), 0.0, 1.0)
        dist = np.hypot(xx - (a[0] + t * d[0]), yy - (a[1] + t * d[1]))
        img[dist <= width_px / 2.0] = ink
    return img.astype(np.uint8)


def tracker(**kw) -> LineTracker:
    return LineTracker(dataclasses.replace(Pixy2(), **kw))


# -- the tracker ------------------------------------------------------------------------------
def test_a_dark_run_between_two_edges_is_one_point_half_way():
    row = np.full(40, 200.0)
    row[10:13] = 20.0  # pixels 10, 11, 12
    assert scan_points(row, threshold=10, d=2, min_w=0, max_w=10) == [11.0]
    row[10:30] = 20.0  # wider than max_w: floor, not a line
    assert scan_points(row, threshold=10, d=2, min_w=0, max_w=10) == []
    row[:] = 200.0
    row[10:] = 20.0  # a falling edge and no rising one: the lane's end, not a line
    assert scan_points(row, threshold=10, d=2, min_w=0, max_w=10) == []


def test_a_vertical_line_is_one_vector_from_its_lower_end_up():
    lt = tracker()
    feats = lt.process(frame_with((40, 50, 40, 5)))
    assert len(feats.vectors) == 1
    v = feats.vectors[0]
    assert (v.m_x0, v.m_x1) == (40, 40) and v.m_y0 >= 48 and v.m_y1 <= 7  # tail low, head high
    assert lt.main.vectors == feats.vectors  # the only line is the Vector
    assert feats.intersections == ()


def test_a_level_line_has_its_tail_at_the_left_end():
    v, = tracker().process(frame_with((10, 30, 70, 30))).vectors
    assert v.m_x0 < v.m_x1 and v.m_y0 == v.m_y1 == 30


def test_a_crossing_is_an_intersection_of_four_lines_at_right_angles():
    lt = tracker()
    feats = lt.process(frame_with((40, 51, 40, 4), (8, 25, 72, 25)))
    assert len(feats.vectors) == 4
    it, = feats.intersections
    assert abs(it.m_x - 40) <= 1 and abs(it.m_y - 25) <= 1 and it.m_n == 4
    # relative to the Vector (the line coming up from the bottom): on, left, right, back
    assert sorted(ln.m_angle for ln in it.m_intLines) == pytest.approx([-90, 0, 90, 180], abs=4)
    vec, = lt.main.vectors
    assert vec.m_flags & LINE_FLAG_INTERSECTION_PRESENT and vec.m_y0 > vec.m_y1
    assert lt.main.intersections == feats.intersections


def test_the_next_turn_picks_the_branch_at_the_intersection_then_the_default_again():
    lt = tracker()

    def t_at(y: int) -> np.ndarray:  # a T coming closer: the stem from the bottom, the bar at y
        return frame_with((40, 51, 40, y), (8, y, 72, y))
    lt.process(t_at(21))
    lines = {ln.m_angle: ln.m_index for ln in lt.main.intersections[0].m_intLines}
    assert sorted(lines) == pytest.approx([-90, 90, 180], abs=4)
    left_index = lines[min(lines, key=lambda a: abs(a - 90))]
    stem_index = lt.vector_index
    lt.next_turn_deg = 90
    for y in range(23, 39, 2):
        lt.process(t_at(y))
        assert lt.vector_index == stem_index and lt.pending_index == left_index
    for y in range(39, 49, 2):  # the intersection reaches the bottom fifth: the branch takes over
        lt.process(t_at(y))
    assert lt.vector_index == left_index and lt.next_turn_deg is None  # the next turn is used once
    v, = lt.main.vectors
    assert v.m_x1 < v.m_x0  # pointing away from the intersection, to the left


def test_white_lines_only_in_white_line_mode():
    img = frame_with((40, 50, 40, 5), background=30, ink=220)
    assert tracker().process(img).vectors == ()
    lt = tracker()
    lt.mode = LINE_MODE_WHITE_LINE
    assert len(lt.process(img).vectors) == 1


def test_a_line_keeps_its_index_while_it_moves_a_little_and_a_jump_is_a_new_line():
    lt = tracker()
    first, = lt.process(frame_with((30, 50, 30, 5))).vectors
    moved, = lt.process(frame_with((32, 50, 32, 5))).vectors
    assert moved.m_index == first.m_index
    jumped, = lt.process(frame_with((60, 50, 60, 5))).vectors
    assert jumped.m_index != first.m_index


def test_reverse_vector_swaps_head_and_tail_from_then_on():
    lt = tracker()
    img = frame_with((40, 50, 40, 5))
    v, = lt.process(img).vectors
    lt.reverse_vector()
    r, = lt.process(img).vectors
    assert (r.m_x0, r.m_y0, r.m_x1, r.m_y1) == (v.m_x1, v.m_y1, v.m_x0, v.m_y0)


def test_a_curved_line_comes_as_straight_vectors_end_to_end():
    t = np.linspace(0.0, np.pi / 2, 40)
    pts = np.stack((10 + 40 * (1 - np.cos(t)), 50 - 40 * np.sin(t)), axis=1)
    img = frame_with(*[(*pts[i], *pts[i + 1]) for i in range(len(pts) - 1)])
    vs = tracker().process(img).vectors
    assert len(vs) >= 2
    ends = {(v.m_x1, v.m_y1) for v in vs}
    assert sum((v.m_x0, v.m_y0) in ends for v in vs) == len(vs) - 1  # one chain


@settings(max_examples=40, deadline=None)
@given(x0=st.floats(6, 72), x1=st.floats(6, 72), y_top=st.floats(3, 20))
def test_any_steep_line_is_found_where_it_is(x0, x1, y_top):
    """Property: a straight dark line (at most 45 deg from vertical) gives vectors whose ends
    lie within 1.5 grid px of the drawn line, together spanning most of it."""
    if abs(x1 - x0) > (49 - y_top):
        return
    a, b = np.array([x0, 49.0]), np.array([x1, y_top])
    vs = tracker().process(frame_with((x0, 49.0, x1, y_top))).vectors
    assert vs
    d = b - a
    for v in vs:
        for p in ((v.m_x0, v.m_y0), (v.m_x1, v.m_y1)):
            off = abs(d[0] * (p[1] - a[1]) - d[1] * (p[0] - a[0])) / np.hypot(*d)
            assert off <= 1.5
    span = max(v.m_y0 for v in vs) - min(v.m_y1 for v in vs)
    assert span >= 0.8 * (49 - y_top)


def test_same_frames_same_features():
    frames = [frame_with((40 + k, 50, 38 + k, 5), (8, 20 + k, 72, 22 + k)) for k in range(4)]
    a, b = tracker(), tracker()
    assert [a.process(f) for f in frames] == [b.process(f) for f in frames]


def test_a_frame_that_is_no_multiple_of_the_grid_is_refused_naming_the_car_file():
    with pytest.raises(CameraError, match=r"128 x 128.*examples/pixy2_car\.toml"):
        grid_image(np.zeros((128, 128), np.uint8), 79, 52)


# -- the Python API in a run ---------------------------------------------------------------------
def test_python_api_waits_for_frames_polls_and_filters(tmp_path):
    seen = {}

    def main(s):
        pixy = s.pixy2()
        assert pixy.init() == 0 and pixy.changeProg("line") == 0
        seen["size"] = (pixy.frameWidth, pixy.frameHeight)
        # frames 0 and 1 read saturated (camera.startup_frames = 1: frame 1 is the first read)
        seen["startup"] = [(pixy.line.getMainFeatures(), pixy.line.numVectors) for _ in range(2)]
        t0 = s.get_time()
        got = pixy.line.getMainFeatures()
        seen["first"] = (got, pixy.line.numVectors, s.get_time() - t0)
        pixy.line.getAllFeatures(LINE_VECTOR)
        seen["waited"] = s.get_time() - t0
        seen["busy"] = pixy.line.getAllFeatures(LINE_ALL_FEATURES, False)
        seen["only_intersections"] = (pixy.line.getAllFeatures(LINE_INTERSECTION), pixy.line.numVectors)
        s.set_speed_and_servo(1.0, 0.0)
        s.sleep(0.2)

    r = drive(main, car=PIXY_CAR, time_limit_s=1.0, seed=0)
    assert r.outcome != "controller_error", r.message
    assert seen["size"] == (W, H)
    assert seen["startup"] == [(0, 0), (0, 0)]
    got, n, dt = seen["first"]
    assert got & LINE_VECTOR and n == 1           # the Vector of the start
    assert dt == pytest.approx(1 / 60, abs=0.003)  # waited for the next 60 Hz frame
    assert seen["waited"] == pytest.approx(2 / 60, abs=0.003)
    assert seen["busy"] == PIXY_RESULT_BUSY        # polled right after a frame
    assert seen["only_intersections"][1] == 0      # vectors not asked for


def test_the_pixy2_on_a_car_without_a_pixy2_frame_ends_the_run_saying_what_to_use(tmp_path):
    def main(s):
        s.pixy2().init()

    r = drive(main, time_limit_s=1.0, csv=tmp_path / "run.csv")
    assert r.outcome == "controller_error"
    assert "128 x 128" in r.message and "examples/pixy2_car.toml" in r.message


def test_a_bad_turn_angle_ends_the_run_naming_the_call():
    def main(s):
        s.pixy2().line.setNextTurn(500)

    r = drive(main, car=PIXY_CAR, time_limit_s=1.0)
    assert r.outcome == "controller_error" and "set_next_turn(angle=500)" in r.message


def test_the_video_draws_the_vectors(tmp_path):
    def main(s):
        pixy = s.pixy2()
        for _ in range(3):
            pixy.line.getAllFeatures()

    r = drive(main, car=PIXY_CAR, time_limit_s=0.2, video=tmp_path / "run.mp4")
    assert (tmp_path / "run.mp4").stat().st_size > 0 and r.outcome != "controller_error"


# -- the followers -----------------------------------------------------------------------------------
def _tracks():
    return [SHARED_TRACKS / n for n in ("nxp_raceway", "nxp_raceway_octagon") if (SHARED_TRACKS / n).is_dir()]


@pytest.fixture(scope="module")
def python_lap(tmp_path_factory):
    """The Python follower's lap of the default track (run once: two tests read it)."""
    return drive(EXAMPLES / "pixy2_follower.py", car=PIXY_CAR, laps=1, seed=0,
                 csv=tmp_path_factory.mktemp("pixy2") / "p.csv")


def test_the_python_pixy2_follower_laps_the_default_track(python_lap):
    assert python_lap.outcome == "finished", python_lap.message


@pytest.mark.parametrize("track", _tracks(), ids=lambda t: t.name)
def test_the_python_pixy2_follower_laps(track):
    r = drive(EXAMPLES / "pixy2_follower.py", car=PIXY_CAR, track=track, laps=1, seed=0)
    assert r.outcome == "finished", r.message


@needs_cc
def test_the_cpp_pixy2_follower_laps_as_the_python_one(tmp_path, python_lap):
    c = drive(EXAMPLES / "pixy2_follower.cpp", car=PIXY_CAR, laps=1, seed=0, csv=tmp_path / "c.csv")
    p = python_lap
    assert c.outcome == "finished", c.message
    # the same method; the C++ Spinner passes floats: the lap within a frame
    assert abs(c.lap_times_s[0] - p.lap_times_s[0]) <= 2 / 60


@needs_cc
def test_c_api_features_and_a_bad_call_at_its_line(tmp_path, capfd):
    src = tmp_path / "pixy.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "pixy2_line.h"
        #include "spinner.h"
        int main(void) {
            pixy2_line_features f;
            pixy2_init();
            pixy2_line_get_main_features(LINE_ALL_FEATURES, true, &f);  /* frames 0, 1: power-up */
            int8_t got = pixy2_line_get_main_features(LINE_ALL_FEATURES, true, &f);
            got = pixy2_line_get_main_features(LINE_ALL_FEATURES, true, &f);
            printf("main %d %d tail %d %d\\n", got, f.numVectors, f.vectors[0].m_x0, f.vectors[0].m_y0);
            got = pixy2_line_get_all_features(LINE_ALL_FEATURES, false, &f);
            printf("poll %d\\n", got);
            pixy2_line_set_next_turn(500);
            return 0;
        }
        """))
    r = drive(src, car=PIXY_CAR, time_limit_s=1.0, csv=tmp_path / "run.csv")
    out = capfd.readouterr().out
    assert "main 1 1 tail" in out and f"poll {PIXY_RESULT_BUSY}" in out
    assert r.outcome == "controller_error"
    assert r.message.startswith(f"{src}:13:") and "set_next_turn(angle=500)" in r.message
    assert len(read_log(tmp_path / "run.csv")) >= 2


@needs_cc
def test_pixy2_headers_compile_cleanly_with_strict_warnings(tmp_path):
    cpp = tmp_path / "strict.cpp"
    cpp.write_text('#include <Pixy2.h>\nint main() { Pixy2 pixy; (void)pixy; return 0; }\n')
    c = tmp_path / "strict.c"
    c.write_text('#include "pixy2_line.h"\nint main(void) { pixy2_line_features f; (void)f; return 0; }\n')
    for compiler, path in (("c++", cpp), ("cc", c)):
        proc = subprocess.run([compiler, "-fsyntax-only", "-Wall", "-Wextra", "-pedantic",
                               f"-I{INCLUDE_DIR}", str(path)], capture_output=True, text=True)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_the_pixy2_car_file_loads():
    car = load_car(PIXY_CAR)
    assert (car.camera.width_px, car.camera.height_px, car.camera.fps_hz) == (W, H, 60.0)
    assert car.camera.width_px % car.pixy2.grid_width_px == 0
