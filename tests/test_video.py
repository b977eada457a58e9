"""Debug video: frame layout, frame count and size, written off the control path."""
from __future__ import annotations

import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.run.runner import drive
from simrunner.reports.video import FRAME_H, FRAME_W, FrameRecord, Layout, VideoRecorder, compose

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _frames(path):
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    n, shapes = 0, set()
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        n += 1
        shapes.add(frame.shape)
    cap.release()
    return n, shapes


def test_drive_writes_one_video_frame_per_camera_frame(tmp_path):
    ctrl = tmp_path / "c.py"
    ctrl.write_text(textwrap.dedent("""\
        def main(s):
            s.set_speed_and_servo(0.8, 0.0)
            for i in range(30):
                row = s.get_image(s.line_row)
                s.add_data([f"frame {i}"])
                s.add_data(255 - row)
        """))
    r = drive(ctrl, video=tmp_path / "v.mp4", csv=tmp_path / "t.csv")
    assert r.outcome == "controller_returned"
    n, shapes = _frames(tmp_path / "v.mp4")
    assert n == 31 == len(r.log)  # frames 0..30 at the camera's 50 fps
    assert shapes == {(FRAME_H, FRAME_W, 3)}
    assert not (tmp_path / "v.partial.mp4").exists()
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(50.0)


def test_video_is_closed_and_kept_when_the_controller_crashes(tmp_path):
    ctrl = tmp_path / "c.py"
    ctrl.write_text("def main(s):\n    for _ in range(10):\n        s.get_image()\n    raise RuntimeError('boom')\n")
    r = drive(ctrl, video=tmp_path / "v.mp4")
    assert r.outcome == "controller_error"
    n, _ = _frames(tmp_path / "v.mp4")
    assert n == 11


def _record(**kw):
    img = np.full((128, 128), 200, np.uint8)
    img[:, :10] = 0
    rec = dict(frame=3, t_s=0.06, pose=Pose2(0, 0, 0),
               state=dict(speed=1.0, steer=0.1, speed_cmd=1.2, steer_cmd=0.1, lap=0, off_track=False),
               image=img, line=img[60:61], line_row=60, text=("hello",), lines=None)
    rec.update(kw)
    return FrameRecord(**rec)


def test_compose_layout_has_camera_line_and_track_panels():
    rec = _record(lines=np.zeros((2, 128), np.uint8))
    layout = Layout.for_frame((128, 128), None)
    out = compose(rec, None, laps=1)
    assert out.shape == (FRAME_H, FRAME_W, 3) and out.dtype == np.uint8
    assert out[100, 300].tolist() == [200, 200, 200]  # camera image x3 at x 0..384
    assert out[100, 20].tolist() == [0, 0, 0]  # its dark left columns (0..9 -> 0..29)
    x0 = layout.middle[0] + 8
    assert out[40, x0 + 200].tolist() == [200, 200, 200]  # the line, stretched
    assert out[40, x0 + 5].tolist() == [0, 0, 0]  # its dark left part


def test_camera_image_is_drawn_three_times_its_size():
    img = np.full((128, 128), 255, np.uint8)
    out = compose(_record(image=img, line=img[60:61], text=()), None, laps=1)
    white = np.all(out == 255, axis=2)
    rows, cols = np.flatnonzero(white.any(axis=1)), np.flatnonzero(white[:, :400].any(axis=0))
    assert rows[0] == 0 and cols[0] == 0
    # the white block of the camera image (the row markers are red): 384 x 384
    assert np.count_nonzero(white[:, :390].any(axis=0)) == 384
    assert np.count_nonzero(white[:390, :384].all(axis=1)) >= 380


def test_controller_text_sits_under_its_processed_lines():
    """Thesis Fig. 3.7: camera line, under it the controller's line, under that its text."""
    lines = np.full((1, 128), 90, np.uint8)
    rec = _record(lines=lines, text=("first text line", "second"))
    layout = Layout.for_frame((128, 128), 0.7)
    out = compose(rec, None, laps=1, layout=layout)
    x0, _, x1, _ = layout.middle
    middle = out[:, x0:x1]
    line_rows = np.flatnonzero(np.all(middle == 90, axis=2).sum(axis=1) > 100)
    text_rows = np.flatnonzero((middle.min(axis=2) > 200).sum(axis=1) > 0)
    text_rows = text_rows[text_rows > 80]  # below the camera line (its values are 200/0)
    assert line_rows.size >= 20  # the processed line, stretched to its height
    assert text_rows.size and 0 < text_rows[0] - line_rows[-1] < 40


def test_video_frame_uses_its_area(tmp_path):
    """The frame of a real run: under 10 % black (73 % with the old layout)."""
    r = drive(EXAMPLES / "line_follower.py", video=tmp_path / "v.mp4", time_limit_s=1.0)
    assert r.outcome == "timeout"
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    fractions = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        fractions.append(float(np.mean(frame.max(axis=2) < 16)))
    cap.release()
    assert len(fractions) >= 50 and max(fractions) < 0.10, max(fractions)


def test_high_camera_rates_are_capped_at_60_video_fps(tmp_path):
    rec = VideoRecorder(tmp_path / "v.mp4", camera_fps=200.0, render=lambda pose: np.zeros((8, 8), np.uint8))
    assert rec.every == 4 and rec.fps == 50.0
    for k in range(9):
        rec.frame_boundary(k, k / 200, Pose2(), dict(speed=0, steer=0, speed_cmd=0, steer_cmd=0,
                                                     lap=0, off_track=False))
    assert rec.close() == tmp_path / "v.mp4"
    assert _frames(tmp_path / "v.mp4")[0] == 3  # frames 0, 4, 8


def test_video_path_must_be_mp4(tmp_path):
    with pytest.raises(SimError, match=r"\.mp4"):
        VideoRecorder(tmp_path / "v.avi", camera_fps=50, render=None)
