"""Debug video (thesis 3.4, Fig. 3.7): one MP4 frame per recorded camera frame.

Layout of a ``1024 x 576`` frame (BGR)::

    +----------+-------------+--------------------------------------------+
    | API text | camera      | the selected line, stretched (noisy, as    |
    | time     | image x2    | the controller got it)                     |
    | speed    | (row marker)| controller's image lines (add_data(array)) |
    | steer .. +-------------+--------------------------------------------+
    | position | controller  | top-down view: track raster, the path so   |
    | lap      | text lines  | far (green; red where off track), the car  |
    | frame    | (add_data)  |                                            |
    +----------+-------------+--------------------------------------------+

Off the control path: at a recorded frame the main thread only stores a few numbers and
references to small arrays (the image the controller got, if any); a writer thread renders
the camera view when needed, composes the frame and encodes it (``cv2.VideoWriter``,
``mp4v``; OpenCV releases the GIL while encoding). The queue is bounded, so a slow encoder
slows the run instead of filling memory. The file is written as ``NAME.partial.mp4`` and
renamed on :meth:`VideoRecorder.close`, which also runs when the controller crashed.

Frame rate: every camera frame up to 60 fps; above that every ``ceil(fps / 60)``-th frame.
"""
from __future__ import annotations

import math
import os
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from simrunner.errors import SimError

FRAME_W, FRAME_H = 1024, 576
MAX_VIDEO_FPS = 60.0
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_WHITE = (235, 235, 235)
_GRAY = (150, 150, 150)
_YELLOW = (60, 220, 240)
_RED = (40, 40, 230)
_GREEN = (60, 200, 60)
# panel boxes: (x0, y0, x1, y1)
_API_BOX = (0, 0, 208, FRAME_H)
_CAM_BOX = (208, 0, 464, 256)
_TEXT_BOX = (208, 264, 464, FRAME_H)
_LINE_BOX = (472, 20, 1016, 60)
_LINES_BOX = (472, 84, 1016, 256)
_TOP_BOX = (472, 264, 1024, FRAME_H)


@dataclass
class FrameRecord:
    """What one video frame shows (filled by the main thread; small)."""

    frame: int
    t_s: float
    pose: Any  # Pose2 of the car at the frame
    state: dict  # speed, steer, speed_cmd, steer_cmd, lap, laps, off_track, z
    image: np.ndarray | None = None  # (H, W) image the controller got, else rendered later
    line: np.ndarray | None = None  # (1, W) line the controller got
    line_row: int = 0
    text: tuple = ()
    lines: np.ndarray | None = None  # (k, W) controller image lines


class TrackView:
    """The whole track raster fitted into a box, with a path layer drawn incrementally."""

    def __init__(self, raster, box_w: int, box_h: int):
        img = np.asarray(raster.image)
        h, w = img.shape
        self.scale = min(box_w / w, box_h / h)
        size = (max(1, int(w * self.scale)), max(1, int(h * self.scale)))
        small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        self.canvas = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
        self.box_w, self.box_h = box_w, box_h
        self.off = ((box_w - size[0]) // 2, (box_h - size[1]) // 2)
        self.origin = (float(raster.origin_xy_m[0]), float(raster.origin_xy_m[1]))
        self.px_per_m = self.scale / float(raster.m_per_px)
        self._last: tuple[int, int] | None = None

    def to_px(self, x_m: float, y_m: float) -> tuple[int, int]:
        """Box pixel (col, row) of a world point (raster pixel centres at integer indices)."""
        col = ((x_m - self.origin[0]) * self.px_per_m + 0.5 * self.scale)
        row = ((self.origin[1] - y_m) * self.px_per_m + 0.5 * self.scale)
        return int(round(col)), int(round(row))

    def draw(self, pose, off_track: bool, car_length_m: float, car_width_m: float) -> np.ndarray:
        """Extend the path to ``pose`` and return the box image ``(box_h, box_w, 3)``."""
        p = self.to_px(pose.x_m, pose.y_m)
        if self._last is not None:
            cv2.line(self.canvas, self._last, p, _RED if off_track else _GREEN, 1, cv2.LINE_AA)
        self._last = p
        out = np.zeros((self.box_h, self.box_w, 3), np.uint8)
        ch, cw = self.canvas.shape[:2]
        out[self.off[1]:self.off[1] + ch, self.off[0]:self.off[0] + cw] = self.canvas
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        corners = []
        for fx, fy in ((car_length_m, 0.0), (0.0, car_width_m / 2), (0.0, -car_width_m / 2)):
            cx, cy = self.to_px(pose.x_m + c * fx - s * fy, pose.y_m + s * fx + c * fy)
            corners.append((cx + self.off[0], cy + self.off[1]))
        cv2.fillConvexPoly(out, np.array(corners, np.int32), _YELLOW, cv2.LINE_AA)
        return out


def _put(img, text: str, x: int, y: int, color=_WHITE, scale: float = 0.45) -> None:
    cv2.putText(img, text, (x, y), _FONT, scale, color, 1, cv2.LINE_AA)


def _fit(img: np.ndarray, box_w: int, box_h: int, nearest: bool = True) -> np.ndarray:
    """Gray ``img`` scaled (keeping its aspect) into a ``(box_h, box_w, 3)`` BGR image."""
    h, w = img.shape
    s = min(box_w / w, box_h / h)
    size = (max(1, int(w * s)), max(1, int(h * s)))
    small = cv2.resize(img, size, interpolation=cv2.INTER_NEAREST if nearest else cv2.INTER_AREA)
    out = np.zeros((box_h, box_w, 3), np.uint8)
    out[:size[1], :size[0]] = small[:, :, None]
    return out


def compose(rec: FrameRecord, track_view: TrackView | None, laps: int,
            car_length_m: float = 0.28, car_width_m: float = 0.16) -> np.ndarray:
    """One ``(FRAME_H, FRAME_W, 3)`` BGR video frame from a record (see module layout)."""
    out = np.zeros((FRAME_H, FRAME_W, 3), np.uint8)
    st = rec.state
    # API column
    def z(v: float, nd: int) -> float:  # no "-0.000"
        return round(v, nd) + 0.0

    rows = [("time", f"{rec.t_s:8.3f} s"), ("speed", f"{z(st['speed'], 3):6.3f} m/s"),
            ("speed cmd", f"{z(st['speed_cmd'], 3):6.3f} m/s"),
            ("steer", f"{z(math.degrees(st['steer']), 1):6.1f} deg"),
            ("steer cmd", f"{z(math.degrees(st['steer_cmd']), 1):6.1f} deg"),
            ("x", f"{z(rec.pose.x_m, 3):7.3f} m"), ("y", f"{z(rec.pose.y_m, 3):7.3f} m"),
            ("yaw", f"{z(math.degrees(rec.pose.yaw_rad), 1):6.1f} deg"),
            ("lap", f"{st['lap']} / {laps}"), ("frame", f"{rec.frame}"),
            ("line row", f"{rec.line_row}")]
    y = 24
    for name, value in rows:
        _put(out, name, 8, y, _GRAY)
        _put(out, value, 90, y)
        y += 22
    if st.get("off_track"):
        _put(out, "OFF TRACK", 8, y + 10, _RED, 0.6)
    # camera image with the selected row marked
    x0, y0, x1, y1 = _CAM_BOX
    cam = _fit(rec.image, x1 - x0, y1 - y0)
    out[y0:y1, x0:x1] = cam
    h, w = rec.image.shape
    ry = int((rec.line_row + 0.5) * min((x1 - x0) / w, (y1 - y0) / h))
    cv2.line(out, (x0, y0 + ry), (x0 + 6, y0 + ry), _RED, 2)
    cv2.line(out, (x1 - 7, y0 + ry), (x1 - 1, y0 + ry), _RED, 2)
    # the line, stretched
    lx0, ly0, lx1, ly1 = _LINE_BOX
    _put(out, f"camera line (row {rec.line_row})", lx0, ly0 - 6, _GRAY)
    if rec.line is not None:
        out[ly0:ly1, lx0:lx1] = cv2.resize(rec.line.reshape(1, -1), (lx1 - lx0, ly1 - ly0),
                                           interpolation=cv2.INTER_NEAREST)[:, :, None]
    # controller image lines
    mx0, my0, mx1, my1 = _LINES_BOX
    if rec.lines is not None and len(rec.lines):
        _put(out, "controller lines", mx0, my0 - 6, _GRAY)
        lh = max(4, min(24, (my1 - my0) // len(rec.lines) - 4))
        for i, ln in enumerate(rec.lines[: (my1 - my0) // (lh + 4)]):
            yy = my0 + i * (lh + 4)
            arr = np.asarray(ln)
            if arr.dtype != np.uint8:
                arr = np.clip(arr, 0, 255).astype(np.uint8)
            out[yy:yy + lh, mx0:mx1] = cv2.resize(arr.reshape(1, -1), (mx1 - mx0, lh),
                                                  interpolation=cv2.INTER_NEAREST)[:, :, None]
    # controller text
    tx0, ty0, tx1, ty1 = _TEXT_BOX
    y = ty0 + 18
    for line in rec.text:
        if y > ty1 - 4:
            break
        _put(out, str(line)[:34], tx0 + 4, y)
        y += 18
    # top-down view
    if track_view is not None:
        bx0, by0, bx1, by1 = _TOP_BOX
        out[by0:by1, bx0:bx1] = track_view.draw(rec.pose, bool(st.get("off_track")),
                                                car_length_m, car_width_m)
    return out


class VideoRecorder:
    """Collects frame records on the main thread; a writer thread composes and encodes.

    ``render(pose) -> (H, W) uint8`` draws the camera view when the controller took no image
    in a frame. ``camera_fps``: frame rate of the camera; the video keeps every
    ``ceil(fps / 60)``-th frame. ``raster``: the track's ``TrackRaster`` (top-down view).
    """

    def __init__(self, path: str | Path, *, camera_fps: float, render: Callable, raster=None,
                 laps: int = 1, line_row: int = 0, car_length_m: float = 0.28,
                 car_width_m: float = 0.16, queue_size: int = 32):
        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise SimError(f"{self.path}: the debug video must be an .mp4 file")
        self.every = max(1, math.ceil(camera_fps / MAX_VIDEO_FPS - 1e-9))
        self.fps = camera_fps / self.every
        self._tmp = self.path.with_name(self.path.stem + ".partial.mp4")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SimError(f"{self.path}: cannot create its folder ({exc.strerror})") from None
        self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"),
                                       self.fps, (FRAME_W, FRAME_H))
        if not self._writer.isOpened():
            raise SimError(f"{self.path}: OpenCV cannot write an mp4v video here")
        self._render = render
        self._raster = raster
        self._laps = laps
        self._car = (car_length_m, car_width_m)
        self.default_row = line_row
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._error: BaseException | None = None
        self._pending: FrameRecord | None = None
        self._frame = -1
        self._text: list[str] = []
        self._text_frame = -2
        self._lines: list[np.ndarray] = []
        self._lines_frame = -2
        self._last_line: np.ndarray | None = None
        self._last_row = line_row
        self.frames_written = 0
        self._thread = threading.Thread(target=self._run, name="simrunner-video", daemon=True)
        self._thread.start()

    # -- main thread -------------------------------------------------------------------
    def frame_boundary(self, frame: int, t_s: float, pose, state: dict) -> None:
        """Called at every camera frame; records every ``every``-th one."""
        self._frame = frame
        if frame % self.every:
            return
        self._flush_pending()
        self._pending = FrameRecord(frame, t_s, pose, state, line_row=self._last_row)

    def note_image(self, img: np.ndarray, line: int) -> None:
        """The image (``line = -1``) or row the controller just got (copied: the controller
        may change its array before the writer thread draws it)."""
        rec = self._pending
        if rec is None:
            return
        img = img.copy()
        if line < 0:
            rec.image = img
            rec.line_row = self.default_row if self._last_row < 0 else self._last_row
            rec.line = img[rec.line_row:rec.line_row + 1]
        else:
            self._last_row = line
            rec.line_row = line
            rec.line = img
        self._last_line = rec.line

    def add_text(self, lines: list[str]) -> None:
        if self._text_frame != self._frame:
            self._text, self._text_frame = [], self._frame
        self._text.extend(lines)

    def add_lines(self, arr: np.ndarray) -> None:
        if self._lines_frame != self._frame:
            self._lines, self._lines_frame = [], self._frame
        self._lines.extend(np.array(arr, copy=True))

    def _flush_pending(self) -> None:
        rec = self._pending
        if rec is None:
            return
        self._pending = None
        rec.text = tuple(self._text)
        rec.lines = np.stack(self._lines) if self._lines else None
        if rec.line is None and self._last_line is not None:
            rec.line = self._last_line
        self._put(rec)

    def _put(self, item) -> None:
        if self._error is not None:
            raise SimError(f"{self.path}: video writer failed: {self._error}")
        self._queue.put(item)

    def close(self) -> Path | None:
        """Write the last frame, stop the writer, close and rename the file.

        Returns the path, or None if no frame was recorded (then no file is left)."""
        try:
            self._flush_pending()
        finally:
            self._queue.put(None)
            self._thread.join()
            self._writer.release()
        if self._error is not None:
            raise SimError(f"{self.path}: video writer failed: {self._error}")
        if self.frames_written == 0:
            self._tmp.unlink(missing_ok=True)
            return None
        os.replace(self._tmp, self.path)
        return self.path

    def discard(self) -> None:
        """Stop the writer and remove everything written (the run did not start)."""
        try:
            written = self.close()
        except SimError:
            written = None
        self._tmp.unlink(missing_ok=True)
        if written is not None:  # only what this run wrote
            written.unlink(missing_ok=True)

    # -- writer thread -------------------------------------------------------------------
    def _run(self) -> None:
        view = None
        while True:
            rec = self._queue.get()
            if rec is None:
                return
            if self._error is not None:
                continue
            try:
                if view is None and self._raster is not None:
                    view = TrackView(self._raster, _TOP_BOX[2] - _TOP_BOX[0], _TOP_BOX[3] - _TOP_BOX[1])
                if rec.image is None:
                    rec.image = self._render(rec.pose)
                if rec.line is None:
                    rec.line = rec.image[rec.line_row:rec.line_row + 1]
                self._writer.write(compose(rec, view, self._laps, *self._car))
                self.frames_written += 1
            except BaseException as exc:  # keep draining the queue; reported by close()
                self._error = exc
