"""The debug video's encoder: H.264 in an MP4 file, through PyAV (FFmpeg's libx264).

H.264 (Constrained Baseline, YUV 4:2:0, x264's ``ultrafast`` preset) plays in browsers, on
GitHub and in every player; the MPEG-4 Part 2 (``mp4v``) that OpenCV's own writer offers does
not play in browsers, and OpenCV converted each BGR frame to YUV with FFmpeg's swscale, which
cost as much as the encoding itself. Here OpenCV's SIMD conversion (``COLOR_BGR2YUV_I420``,
:meth:`H264Writer.yuv`: the debug video calls it on the thread that drew the frame, while the
frame is in the CPU's cache) makes the picture, which PyAV hands to x264 without a copy. x264 runs one thread (the video's cost stays on one core
beside the simulation, and a batch of runs with videos does not oversubscribe the machine) at a
constant quantiser, 18: on the default lap's frames it gives the size and quality of x264's
default constant-rate factor (CRF 23: 0.85 MB, PSNR 41.7 vs 41.5 dB; the panels' text stays
sharp) for ~20 % less encoding time, since CRF's rate control makes x264 analyse a
half-resolution copy of every frame. x264 with one thread is deterministic: the same frames
give the same file.

Where PyAV's FFmpeg has no libx264 (an LGPL build), the file is MPEG-4 Part 2 at a fixed quantiser.
``bench/bench_video.py`` measures the whole video's cost.
"""
from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from simrunner.errors import SimError

# the encoders tried, in order: H.264; MPEG-4 Part 2 where PyAV's FFmpeg has no libx264 (an
# LGPL build), at a fixed quantiser of 3 (FFmpeg's scale 1..31: the panels' text stays sharp)
ENCODERS = (("libx264", {"preset": "ultrafast", "qp": "18"}),
            ("mpeg4", {"flags": "+qscale", "global_quality": str(3 * 118)}))  # 118: FF_QP2LAMBDA


class H264Writer:
    """Writes ``(height, width, 3)`` BGR uint8 frames at ``fps`` to ``path`` (an MP4 file).

    ``write`` and ``close`` may run on a thread of their own (the encoder releases the GIL)."""

    def __init__(self, path: str | Path, fps: float, width: int, height: int, *, shown_as: str | Path | None = None):
        try:
            import av
        except ModuleNotFoundError:
            raise SimError("--video needs PyAV, which is not installed: pip install av") from None
        if width % 2 or height % 2:
            raise ValueError(f"H264Writer: {width} x {height}: H.264 at 4:2:0 needs even sizes")
        self.path, self.width, self.height = Path(path), width, height
        self.shown = Path(shown_as) if shown_as is not None else self.path  # the name in messages
        rate = Fraction(fps).limit_denominator(1001)
        try:  # (PyAV opens the file at the first frame: a path that cannot be written fails now)
            open(self.path, "wb").close()
            self._container = av.open(str(self.path), "w", format="mp4")
        except OSError as exc:
            raise SimError(f"{self.shown}: cannot write the video ({exc.strerror or exc})") from None
        stream = None
        for codec, options in ENCODERS:
            try:
                stream = self._container.add_stream(codec, rate=rate, options=dict(options))
            except Exception:  # noqa: BLE001 - not in this FFmpeg build (av.codec.codec.UnknownCodecError)
                continue
            stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
            stream.thread_count = 1
            break
        if stream is None:
            self._container.close()
            self.path.unlink(missing_ok=True)
            raise SimError(f"{self.shown}: PyAV's FFmpeg has none of the encoders "
                           f"{', '.join(c for c, _ in ENCODERS)}: reinstall it (pip install --force-reinstall av)")
        self.codec = stream.codec_context.name
        self._stream = stream
        self._av = av
        self.frames = 0
        self._broken: str | None = None  # why the file could not be written (it is then only closed)

    def yuv(self, bgr: np.ndarray) -> np.ndarray:
        """A ``(height, width, 3)`` BGR frame as the encoder's picture: YUV 4:2:0 planes (Y, then
        U, then V) in one ``(height * 3 / 2, width)`` array (OpenCV's SIMD conversion)."""
        if bgr.shape != (self.height, self.width, 3):
            raise ValueError(f"H264Writer: a frame of {bgr.shape}, expected {(self.height, self.width, 3)}")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420)

    def write(self, frame: np.ndarray) -> None:
        """Encode one frame (the next in time): BGR ``(height, width, 3)`` or :meth:`yuv`'s
        picture. A file that cannot be written (a full disk) raises :class:`SimError`, then and
        at every later frame."""
        if self._broken is not None:
            raise SimError(f"{self.shown}: cannot write the video ({self._broken})")
        yuv = frame if frame.shape == (self.height * 3 // 2, self.width) else self.yuv(frame)
        picture = self._av.VideoFrame.from_numpy_buffer(yuv, format="yuv420p")  # (no copy: x264 copies it)
        picture.pts = self.frames
        self.frames += 1
        try:
            self._container.mux(self._stream.encode(picture))
        except Exception as exc:  # noqa: BLE001 - FFmpeg's errors (av.error.*): the disk, the file
            self._broken = _reason(exc)
            raise SimError(f"{self.shown}: cannot write the video ({self._broken})") from None

    def close(self) -> None:
        """Flush the encoder and finish the file (once; later calls do nothing). A fault
        :meth:`write` has not reported raises :class:`SimError`. After a failed write the file
        is only closed: muxing more into it crashes PyAV 18 (a segmentation fault)."""
        if self._container is None:
            return
        container, self._container = self._container, None
        failure = None
        if self._broken is None:
            try:
                container.mux(self._stream.encode(None))
            except Exception as exc:  # noqa: BLE001
                failure = self._broken = _reason(exc)
        try:
            container.close()
        except Exception as exc:  # noqa: BLE001
            if failure is None and self._broken is None:
                failure = self._broken = _reason(exc)
        if failure is not None:
            raise SimError(f"{self.shown}: cannot write the video ({failure})")


def _reason(exc: BaseException) -> str:
    """An FFmpeg error in a few words: the OS's reason (``No space left on device``) where
    there is one."""
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
