"""Debug video (thesis 3.4, Fig. 3.7): one MP4 frame per recorded camera frame.

The frame (``1024 x 576``, BGR) and its layout: :mod:`simrunner.reports.video_frame` (camera
image x3, the API's numbers under it, the camera line stretched with the controller's
processed lines and text under it, the top-down track view).

Off the control path: at a recorded frame the main thread only stores a few numbers and
references to small arrays (the image the controller got, if any); a writer thread renders
the camera view when needed, composes the frame (:class:`~simrunner.reports.video_frame.Composer`:
what stays the same is drawn once) and converts it to YUV, and another encodes it
(:class:`~simrunner.reports.video_encoder.H264Writer`: H.264, which releases the GIL while
encoding). The queue is bounded, so a slow encoder slows the run instead of filling memory.
The file is written as ``NAME.partial.mp4`` and renamed on :meth:`VideoRecorder.close`, which
also runs when the controller crashed.

Frame rate: the camera's at the run's start (the car file's) up to ``max_fps`` (30); above that
the camera's over ``ceil(fps / max_fps)`` (the default 50 fps camera: a 25 fps video). Each video
frame shows the camera frame of its time - the latest at or before it - so the video plays in
the run's simulated time whatever period the camera's frames come at: frames one exposure apart
(a kit's free-running camera), an exposure the controller sets. The default camera's video shows
every second frame; frames coming faster are left out where the video's time needs, slower ones
held for more than one video frame. bench/bench_video.py measures the video's cost.
"""
from __future__ import annotations

import math
import os
import queue
import threading
from pathlib import Path
from typing import Callable

import numpy as np

from simrunner.errors import SimError
from simrunner.reports.video_encoder import H264Writer
from simrunner.reports.video_frame import FRAME_H, FRAME_W, Composer, FrameRecord, Layout, TrackView, compose

__all__ = ["VideoRecorder", "FrameRecord", "TrackView", "Layout", "Composer", "compose", "FRAME_W", "FRAME_H"]

MAX_VIDEO_FPS = 30.0  # the default of VideoRecorder(max_fps=...)


class VideoRecorder:
    """Collects frame records on the main thread; a writer thread composes and encodes.

    ``render(pose) -> (H, W) uint8`` draws the camera view when the controller took no image
    in a frame; with ``view_state``, ``render(pose, view)`` gets what ``view_state()`` returned
    at the frame's start (the writer thread draws later: e.g. the exposure then in force). ``camera_fps``: frame rate of the camera at the start; the video's
    is ``camera_fps / every``, ``every = ceil(camera_fps / max_fps)`` (``max_fps``: the video's highest frame
    rate, fps), and its frame ``j`` shows the latest camera frame at or before ``j / fps`` s (module docstring). ``raster``: the track's ``TrackRaster`` (top-down view), shaded
    by ``lighting`` (a ``worlds.lighting.TrackLighting``) when it is not the default hall.
    ``umask``: the file-creation mask the file is written with (None: the process's at the opening).
    """

    def __init__(self, path: str | Path, *, camera_fps: float, render: Callable, raster=None,
                 laps: int = 1, line_row: int = 0, car_length_m: float = 0.28,
                 car_width_m: float = 0.16, queue_size: int = 32, lighting=None,
                 surface_z_m: float = 0.0, max_fps: float = MAX_VIDEO_FPS,
                 view_state: Callable | None = None, umask: int | None = None):
        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise SimError(f"{self.path}: the debug video must be an .mp4 file")
        if not max_fps > 0:
            raise ValueError(f"VideoRecorder(max_fps={max_fps!r}): expected a frame rate > 0")
        self.every = max(1, math.ceil(camera_fps / max_fps - 1e-9))
        self.fps = camera_fps / self.every
        self._tmp = self.path.with_name(self.path.stem + ".partial.mp4")
        self._umask = umask  # the file's permissions: 0666 less this mask (None: the mask at its opening)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SimError(f"{self.path}: cannot create its folder ({exc.strerror})") from None
        self._writer = H264Writer(self._tmp, self.fps, FRAME_W, FRAME_H, shown_as=self.path)
        self._render = render
        self._view_state = view_state
        self._raster = raster
        self._lighting = (lighting, surface_z_m)  # the top view shows the track's light
        self._laps = laps
        self._car = (car_length_m, car_width_m)
        self.default_row = line_row
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._error: BaseException | None = None
        self._pending: FrameRecord | None = None  # the latest camera frame, until the next one
        self._slot = 0  # the next video frame (at self._slot / self.fps s)
        self._frame = -1
        self._text: list[str] = []
        self._text_frame = -2
        self._lines: list[np.ndarray] = []
        self._lines_frame = -2
        self._last_line: np.ndarray | None = None
        self._last_row = line_row
        self.frames_written = 0
        self._frames: queue.Queue = queue.Queue(maxsize=4)  # composed frames, to the encoder
        self._thread = threading.Thread(target=self._run, name="simrunner-video", daemon=True)
        self._encoder = threading.Thread(target=self._encode, name="simrunner-video-encoder", daemon=True)
        self._thread.start()
        self._encoder.start()

    # -- main thread -------------------------------------------------------------------
    def frame_boundary(self, frame: int, t_s: float, pose, state: dict) -> None:
        """Called at every camera frame (``t_s``: its simulated time). The frame before it goes
        to the video frames whose time is from its own to this one's (none: it is left out;
        what the controller noted in it goes to no frame, but its line, text and processed lines
        stay shown until it notes new ones)."""
        self._frame = frame
        self._flush_pending(t_s)
        self._pending = FrameRecord(frame, t_s, pose, state, line_row=self._last_row)
        if self._view_state is not None:
            self._pending.view = self._view_state()

    def drain(self) -> None:
        """Wait until the writer thread has drawn every frame recorded so far (before the
        scene changes: an object put on the track shows from the frame being recorded on)."""
        if self._thread.is_alive():
            self._queue.join()

    def note_image(self, img: np.ndarray, line: int) -> None:
        """The image (``line = -1``) or row the controller just got (copied: the controller
        may change its array before the writer thread draws it)."""
        if line >= 0:
            self._last_row = line
        row = self.default_row if self._last_row < 0 else self._last_row
        rec = self._pending
        if rec is None:  # (before the first frame)
            self._last_line = (img if line >= 0 else img[row:row + 1]).copy()
            return
        img = img.copy()
        rec.line_row = row
        if line < 0:
            rec.image = img
            rec.line = img[row:row + 1]
        else:
            rec.line = img
        self._last_line = rec.line

    def note_pixy2(self, features, vector_index, grid_w: int, grid_h: int) -> None:
        """The Pixy2's features of the image just noted (drawn over it)."""
        if self._pending is not None:
            self._pending.pixy2 = (features, vector_index, grid_w, grid_h)

    def add_text(self, lines: list[str]) -> None:
        if self._text_frame != self._frame:
            self._text, self._text_frame = [], self._frame
        self._text.extend(lines)

    def add_lines(self, arr: np.ndarray) -> None:
        if self._lines_frame != self._frame:
            self._lines, self._lines_frame = [], self._frame
        self._lines.extend(np.array(arr, copy=True))

    def _flush_pending(self, next_s: float | None) -> None:
        """The pending camera frame to the video frames it shows: those from its time to
        ``next_s``, the next camera frame's (None: the run's end, only one at its own time)."""
        rec = self._pending
        if rec is None:
            return
        self._pending = None
        shows = self._slots_until(rec.t_s if next_s is None else next_s, inclusive=next_s is None)
        if shows == 0:
            return
        rec.text = tuple(self._text)
        rec.lines = np.stack(self._lines) if self._lines else None
        if rec.line is None and self._last_line is not None:
            rec.line = self._last_line
        self._put((rec, shows))

    def _slots_until(self, t_s: float, inclusive: bool) -> int:
        """Take the video frames from the next one due before ``t_s`` (at or before, when
        ``inclusive``; to a microsecond: the frames' times are whole physics steps); how many."""
        limit = t_s + 1e-6 if inclusive else t_s - 1e-6
        first = self._slot
        while self._slot / self.fps < limit:
            self._slot += 1
        return self._slot - first

    def _failure(self) -> SimError:
        """The one line of the writer's fault (its own when it is a SimError: it names the file)."""
        if isinstance(self._error, SimError):
            return SimError(str(self._error))
        return SimError(f"{self.path}: video writer failed: {self._error}")

    def _put(self, item) -> None:
        if self._error is not None:
            raise self._failure()
        self._queue.put(item)

    def close(self) -> Path | None:
        """Write the last frame, stop the writer, close and rename the file.

        Returns the path, or None if no frame was recorded (then no file is left)."""
        try:
            self._flush_pending(None)
        finally:
            self._queue.put(None)
            self._thread.join()
            self._encoder.join()
            try:
                self._writer.close()
            except SimError as exc:
                self._error = self._error or exc
            if self._error is not None:  # a file the encoder could not finish is no video
                self._tmp.unlink(missing_ok=True)
        if self._error is not None:
            raise self._failure()
        if self.frames_written == 0:
            self._tmp.unlink(missing_ok=True)
            return None
        if self._umask is not None:
            os.chmod(self._tmp, 0o666 & ~self._umask)
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

    # -- writer threads: one draws the frames, the other encodes them ---------------------
    def _run(self) -> None:
        composer = None
        try:
            while True:
                item = self._queue.get()
                self._queue.task_done()  # (drain() waits for the frames taken before this one)
                if item is None:
                    return
                rec, shows = item
                if self._error is not None:
                    continue
                try:
                    if rec.image is None:
                        rec.image = (self._render(rec.pose) if self._view_state is None
                                     else self._render(rec.pose, rec.view))
                    if rec.line is None:
                        rec.line = rec.image[rec.line_row:rec.line_row + 1]
                    if composer is None:
                        composer = self._composer(rec.image.shape)
                    yuv = self._writer.yuv(composer.frame(rec))  # (converted while in the cache)
                    for _ in range(shows):  # (a frame held over several of the video's)
                        self._frames.put(yuv)
                except BaseException as exc:  # keep draining the queue; reported by close()
                    self._error = exc
        finally:
            self._frames.put(None)

    def _encode(self) -> None:
        """Encodes the composed frames (OpenCV releases the GIL: this runs beside the
        simulation and the drawing)."""
        while True:
            frame = self._frames.get()
            if frame is None:
                return
            if self._error is not None:
                continue
            try:
                self._writer.write(frame)
                self.frames_written += 1
            except BaseException as exc:  # reported by close()
                self._error = exc

    def _composer(self, image_shape) -> Composer:
        """The frames' composer, for camera images of ``image_shape``."""
        aspect = view = None
        if self._raster is not None:
            h, w = np.asarray(self._raster.image).shape
            aspect = w / h
        layout = Layout.for_frame(image_shape, aspect)
        if layout.top is not None:
            x0, y0, x1, y1 = layout.top
            view = TrackView(self._raster, x1 - x0, y1 - y0, *self._lighting)
        return Composer(layout, view, self._laps, *self._car)
