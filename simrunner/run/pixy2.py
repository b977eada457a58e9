"""The Pixy2 API for controllers: ``pixy = spinner.pixy2()``, then ``pixy.line...``.

The names of the Pixy2 Arduino/C++ library (docs.pixycam.com, "Line tracking API" and
"General API", wiki v2), in Python spelling with the C++ names as aliases::

    def main(spinner):
        pixy = spinner.pixy2()
        pixy.init()
        while True:
            pixy.line.getMainFeatures()          # waits for the next frame (60 a second)
            if pixy.line.numVectors:
                v = pixy.line.vectors[0]         # v.m_x0, v.m_y0 (tail), v.m_x1, v.m_y1 (head)
                ...

The features come from the car's camera frame by :mod:`simrunner.sensors.pixy2` (what is
emulated: docs/pixy2.md). Time: ``get_main_features`` / ``get_all_features`` with
``wait=True`` return the current frame's features when they were not returned yet, else wait
for the next frame (as the Pixy2 does); with ``wait=False`` they let one physics step pass and
return ``PIXY_RESULT_BUSY`` (-2) when no new frame came. A frame's features are computed when
they are read, from the camera at that moment. The setters let no time pass. With
``--mcu-time`` every call (a setter, ``init``, ``get_resolution`` too) is charged as a Spinner
call (:mod:`simrunner.run.mcu`): on the car each is a transaction on the camera's link.
"""
from __future__ import annotations

import struct

from simrunner.errors import CameraError, CommandError
from simrunner.sensors.pixy2 import (LINE_ALL_FEATURES, LINE_BARCODE, LINE_INTERSECTION,
                                     LINE_MAX_INTERSECTION_LINES, LINE_VECTOR, PIXY_RESULT_BUSY,
                                     PIXY_RESULT_OK, Features, IntersectionLine, LineTracker)


def _int(method: str, name: str, value, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) and not (
            hasattr(value, "__index__") and not isinstance(value, float)):
        raise CommandError(f"{method}({name}={value!r}): expected an integer {lo}..{hi}")
    v = int(value)
    if not lo <= v <= hi:
        raise CommandError(f"{method}({name}={value!r}): expected an integer {lo}..{hi}")
    return v


_VECTOR = struct.Struct("<6B")
_INTERSECTION_HEAD = struct.Struct("<4B")
_INTERSECTION_LINE = struct.Struct("<2Bh")
_BARCODE = struct.Struct("<4B")
_COUNTS = struct.Struct("<3i")


def pack_features(line: "Pixy2Line") -> bytes:
    """``line``'s last features as the C structures of ``pixy2_line.h`` (little-endian):
    three int32 counts, then the vectors, intersections and barcodes."""
    out = [_COUNTS.pack(len(line.vectors), len(line.intersections), len(line.barcodes))]
    out += [_VECTOR.pack(v.m_x0, v.m_y0, v.m_x1, v.m_y1, v.m_index, v.m_flags) for v in line.vectors]
    for it in line.intersections:
        lines = list(it.m_intLines) + [IntersectionLine(0, 0)] * (LINE_MAX_INTERSECTION_LINES - len(it.m_intLines))
        out.append(_INTERSECTION_HEAD.pack(it.m_x, it.m_y, it.m_n, 0))
        out += [_INTERSECTION_LINE.pack(ln.m_index, 0, ln.m_angle) for ln in lines]
    out += [_BARCODE.pack(b.m_x, b.m_y, b.m_flags, b.m_code) for b in line.barcodes]
    return b"".join(out)


class Pixy2Line:
    """``pixy.line``: the line-tracking program's calls and their results (``vectors``,
    ``intersections``, ``barcodes`` lists and their counts)."""

    def __init__(self, pixy: "Pixy2") -> None:
        self._pixy = pixy
        self.vectors: list = []
        self.intersections: list = []
        self.barcodes: list = []

    @property
    def num_vectors(self) -> int:
        return len(self.vectors)

    @property
    def num_intersections(self) -> int:
        return len(self.intersections)

    @property
    def num_barcodes(self) -> int:
        return len(self.barcodes)

    def _get(self, method: str, main: bool, features, wait) -> int:
        p = self._pixy
        try:
            feats = _int(method, "features", features, 0, 255)
        except CommandError as err:
            raise p.spinner._fail(err) from None
        tracker = p._tracker()
        if not p.spinner._next_pixy_frame(bool(wait)):
            return PIXY_RESULT_BUSY
        got: Features = tracker.main if main else tracker.all
        self.vectors = list(got.vectors) if feats & LINE_VECTOR else []
        self.intersections = list(got.intersections) if feats & LINE_INTERSECTION else []
        self.barcodes = list(got.barcodes) if feats & LINE_BARCODE else []
        return ((LINE_VECTOR if self.vectors else 0) | (LINE_INTERSECTION if self.intersections else 0)
                | (LINE_BARCODE if self.barcodes else 0))

    def get_main_features(self, features: int = LINE_ALL_FEATURES, wait: bool = True) -> int:
        """The Vector, the intersection it leads into, barcodes; returns the bitmask of the
        kinds returned (0: none), or ``PIXY_RESULT_BUSY`` (polling, no new frame)."""
        return self._get("get_main_features", True, features, wait)

    def get_all_features(self, features: int = LINE_ALL_FEATURES, wait: bool = True) -> int:
        """Every line, intersection and barcode of the frame (as :meth:`get_main_features`)."""
        return self._get("get_all_features", False, features, wait)

    def _set(self, method: str, name: str, value, lo: int, hi: int) -> int:
        try:
            return _int(method, name, value, lo, hi)
        except CommandError as err:
            raise self._pixy.spinner._fail(err) from None

    def set_mode(self, mode: int) -> int:
        """``LINE_MODE_WHITE_LINE`` (light lines on dark), ``LINE_MODE_MANUAL_SELECT_VECTOR``,
        ``LINE_MODE_TURN_DELAYED`` (accepted; turns are not delayed: docs/pixy2.md), or-ed."""
        self._pixy._tracker().mode = self._set("set_mode", "mode", mode, 0, 255)
        return PIXY_RESULT_OK

    def set_next_turn(self, angle: int) -> int:
        """The branch (degrees, 0 = straight on, + = left) taken at the next intersection."""
        self._pixy._tracker().next_turn_deg = self._set("set_next_turn", "angle", angle, -180, 180)
        return PIXY_RESULT_OK

    def set_default_turn(self, angle: int) -> int:
        """The branch taken at intersections without a next turn (0 = straight on)."""
        self._pixy._tracker().default_turn_deg = self._set("set_default_turn", "angle", angle, -180, 180)
        return PIXY_RESULT_OK

    def set_vector(self, index: int) -> int:
        """Make line ``index`` the Vector (manual select mode)."""
        self._pixy._tracker().manual_index = self._set("set_vector", "index", index, 0, 255)
        return PIXY_RESULT_OK

    def reverse_vector(self) -> int:
        """Swap the Vector's head and tail."""
        self._pixy._tracker().reverse_vector()
        return PIXY_RESULT_OK

    # the C++ library's names
    getMainFeatures = get_main_features
    getAllFeatures = get_all_features
    setMode = set_mode
    setNextTurn = set_next_turn
    setDefaultTurn = set_default_turn
    setVector = set_vector
    reverseVector = reverse_vector
    numVectors = num_vectors
    numIntersections = num_intersections
    numBarcodes = num_barcodes


class Pixy2:
    """A Pixy2 on the simulated car (``spinner.pixy2()``): ``line`` (:class:`Pixy2Line`),
    ``frame_width`` / ``frame_height`` (the camera's frame), ``init``, ``change_prog``,
    ``set_camera_brightness``, ``set_lamp``, ``get_resolution``."""

    def __init__(self, spinner) -> None:  # a simrunner.run.spinner.Spinner (not imported: no circle)
        self.spinner = spinner
        cam = spinner._s.car.camera
        self.frame_width = int(cam.width_px)
        self.frame_height = int(cam.height_px)
        self.line = Pixy2Line(self)
        mcu = spinner._s.mcu
        if mcu is not None:  # --mcu-time: each call is the link's transaction on the car (simrunner.run.mcu)
            from simrunner.run.mcu import charge_calls

            charge_calls(self, mcu)
            charge_calls(self.line, mcu)

    def _tracker(self) -> LineTracker:
        """The run's line tracker (one per run, shared by every ``spinner.pixy2()``)."""
        s = self.spinner._s
        if s.pixy2_tracker is None:
            spec, cam = s.car.pixy2, s.car.camera
            if cam.width_px % spec.grid_width_px or cam.height_px % spec.grid_height_px:
                raise self.spinner._fail(CommandError(str(CameraError(
                    f"Pixy2: the line grid {spec.grid_width_px} x {spec.grid_height_px} (pixy2.grid_*) "
                    f"needs a camera frame whose width and height are whole multiples of it, got "
                    f"{cam.width_px} x {cam.height_px} (camera.width_px, camera.height_px): drive with "
                    f"a Pixy2 car, e.g. --car examples/pixy2_car.toml"))))
            s.pixy2_tracker = LineTracker(spec)
        return s.pixy2_tracker

    def init(self, arg: int | None = None) -> int:
        """Checks the car has a Pixy2 frame; returns ``PIXY_RESULT_OK``."""
        self._tracker()
        return PIXY_RESULT_OK

    def change_prog(self, prog: str) -> int:
        """Only the line-tracking program is emulated ("line", "line_tracking")."""
        if not isinstance(prog, str) or not prog.lower().startswith("line"):
            raise self.spinner._fail(CommandError(
                f"change_prog({prog!r}): only the line-tracking program ('line') is emulated"))
        return PIXY_RESULT_OK

    def get_resolution(self) -> int:
        """Sets ``frame_width`` / ``frame_height`` (they are set already; C: ``pixy2_get_resolution``)."""
        return PIXY_RESULT_OK

    def set_camera_brightness(self, brightness: int) -> int:
        """Brightness 0..255 as exposure: ``brightness / 255`` of the frame period (our
        mapping; the Pixy2 does not document its own)."""
        try:
            b = _int("set_camera_brightness", "brightness", brightness, 0, 255)
        except CommandError as err:
            raise self.spinner._fail(err) from None
        cam = self.spinner._s.car.camera
        lo, _hi = cam.exposure_range_s()
        self.spinner.set_exposure(max(lo, b / 255.0 / cam.fps_hz))
        return PIXY_RESULT_OK

    def set_lamp(self, upper: int, lower: int) -> int:
        """Accepted; the lamp's light is not simulated (docs/pixy2.md)."""
        return PIXY_RESULT_OK

    changeProg = change_prog
    getResolution = get_resolution
    setCameraBrightness = set_camera_brightness
    setLamp = set_lamp
    frameWidth = property(lambda self: self.frame_width)
    frameHeight = property(lambda self: self.frame_height)
