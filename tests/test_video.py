"""Debug video: frame layout, frame count and size, written off the control path."""
from __future__ import annotations

import textwrap

import cv2
import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.run.runner import drive
from simrunner.run.video import FRAME_H, FRAME_W, FrameRecord, VideoRecorder, compose


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


def test_compose_layout_has_camera_line_and_track_panels():
    img = np.full((128, 128), 200, np.uint8)
    img[:, :10] = 0
    rec = FrameRecord(frame=3, t_s=0.06, pose=Pose2(0, 0, 0),
                      state=dict(speed=1.0, steer=0.1, speed_cmd=1.2, steer_cmd=0.1, lap=0,
                                 off_track=False),
                      image=img, line=img[60:61], line_row=60, text=("hello",),
                      lines=np.zeros((2, 128), np.uint8))
    out = compose(rec, None, laps=1)
    assert out.shape == (FRAME_H, FRAME_W, 3) and out.dtype == np.uint8
    assert out[100, 300].tolist() == [200, 200, 200]  # camera image scaled x2 at x 208..464
    assert out[40, 800].tolist() == [200, 200, 200]  # the line, stretched
    assert out[40, 480].tolist() == [0, 0, 0]  # its dark left part


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
