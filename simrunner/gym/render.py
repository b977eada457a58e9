"""``render()`` of ``NXPCup-v0``: the debug-video frame of ``simrunner drive --video`` (see
:mod:`simrunner.reports.video`) as an ``(FRAME_H, FRAME_W, 3) uint8`` RGB array."""
from __future__ import annotations

import cv2
import numpy as np

from simrunner.reports.video import Composer, FrameRecord, Layout, TrackView


class EpisodeView:
    """Draws the frames of one episode (the top-down view keeps the path driven so far)."""

    def __init__(self, raster, *, camera, line_row: int, car_length_m: float, car_width_m: float):
        h, w = np.asarray(raster.image).shape
        self._layout = Layout.for_frame((camera.height_px, camera.width_px), w / h)
        x0, y0, x1, y1 = self._layout.top
        self._composer = Composer(self._layout, TrackView(raster, x1 - x0, y1 - y0), 1,
                                  car_length_m, car_width_m)
        self._camera = camera
        self._line_row = line_row

    def frame(self, *, k: int, t_s: float, pose, line: np.ndarray, state: dict,
              text: tuple[str, ...]) -> np.ndarray:
        """The RGB frame at step ``k``; ``line`` is the ``(1, W)`` row the agent observed,
        ``state`` holds speed, steer, speed_cmd, steer_cmd (m/s, rad), lap, off_track."""
        rec = FrameRecord(k, t_s, pose, state, image=self._camera.render(pose), line=line,
                          line_row=self._line_row, text=text)
        self._composer.laps = state.get("laps", 1)
        bgr = self._composer.frame(rec)
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
