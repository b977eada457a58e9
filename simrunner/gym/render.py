"""``render()`` of ``NXPCup-v0``: the debug-video frame of ``simrunner drive --video`` (see
:mod:`simrunner.run.video`) as an ``(576, 1024, 3) uint8`` RGB array."""
from __future__ import annotations

import cv2
import numpy as np

from simrunner.run.video import _TOP_BOX, FrameRecord, TrackView, compose


class EpisodeView:
    """Draws the frames of one episode (the top-down view keeps the path driven so far)."""

    def __init__(self, raster, *, camera, line_row: int, car_length_m: float, car_width_m: float):
        self._view = TrackView(raster, _TOP_BOX[2] - _TOP_BOX[0], _TOP_BOX[3] - _TOP_BOX[1])
        self._camera = camera
        self._line_row = line_row
        self._car = (car_length_m, car_width_m)

    def frame(self, *, k: int, t_s: float, pose, line: np.ndarray, state: dict,
              text: tuple[str, ...]) -> np.ndarray:
        """The RGB frame at step ``k``; ``line`` is the ``(1, W)`` row the agent observed,
        ``state`` holds speed, steer, speed_cmd, steer_cmd (m/s, rad), lap, off_track."""
        rec = FrameRecord(k, t_s, pose, state, image=self._camera.render(pose), line=line,
                          line_row=self._line_row, text=text)
        bgr = compose(rec, self._view, state.get("laps", 1), *self._car)
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
