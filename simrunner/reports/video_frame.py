"""One frame of the debug video (thesis 3.4, Fig. 3.7): :func:`compose` and its layout.

Layout of a ``1024 x 576`` frame (BGR), every pixel assigned::

    +----------------+---------------------+------------------------+
    | camera image   | camera line (row r) | top-down view: track   |
    | x3, the line   | stretched           | raster, the path so    |
    | row marked     | controller line 1   | far (green; red where  |
    | (384 x 384)    | its text lines      | off track), the car    |
    |                | controller line 2   | (width from the track's|
    +----------------+ ...                 | aspect; floor gray     |
    | API: time,     | (add_data text      | around it)             |
    | speed, steer,  | under the processed |                        |
    | pose, lap ...  | lines, as Fig. 3.7) |                        |
    +----------------+---------------------+------------------------+

The controller's ``add_data(array)`` lines ("processed lines") sit under the camera line
and its ``add_data(text)`` lines under them, as in the thesis's Figure 3.7. Panels have a
dark gray background; the only black left is what the pictures themselves show.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

FRAME_W, FRAME_H = 1024, 576
CAMERA_SCALE = 3  # the camera image (128 x 128 by default) is drawn 3x: 384 x 384
GAP = 6
MIN_TEXT_W = 300  # the middle column is at least this wide (~36 characters)
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_PANEL = (40, 40, 40)
_WHITE = (235, 235, 235)
_GRAY = (160, 160, 160)
_YELLOW = (60, 220, 240)
_RED = (40, 40, 230)
_GREEN = (60, 200, 60)
LINE_H = 48   # height of the stretched camera line
CTRL_LINE_H = 24
TEXT_STEP = 19


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
    pixy2: tuple | None = None  # (all Features, Vector index or None, grid_w, grid_h): drawn on the image
    view: Any = None  # what the camera view is drawn with (VideoRecorder's view_state at the frame)


@dataclass(frozen=True)
class Layout:
    """Panel boxes ``(x0, y0, x1, y1)`` of a frame."""

    camera: tuple[int, int, int, int]
    api: tuple[int, int, int, int]
    middle: tuple[int, int, int, int]
    top: tuple[int, int, int, int] | None

    @classmethod
    def for_frame(cls, image_shape: tuple[int, int], track_aspect: float | None) -> "Layout":
        """The layout for a camera image of ``(H, W)`` and a track raster of width/height
        ``track_aspect`` (None: no top-down view)."""
        h, w = image_shape
        s = min(CAMERA_SCALE * 128 / max(h, w), (FRAME_H - 150) / h)
        cam_w, cam_h = int(round(w * s)), int(round(h * s))
        camera = (0, 0, cam_w, cam_h)
        api = (0, cam_h + GAP, cam_w, FRAME_H)
        x_mid = cam_w + GAP
        if track_aspect is None:
            return cls(camera, api, (x_mid, 0, FRAME_W, FRAME_H), None)
        room = FRAME_W - x_mid - GAP - MIN_TEXT_W
        top_w = int(min(room, max(FRAME_H * track_aspect, 0.5 * room)))
        x_top = FRAME_W - top_w
        return cls(camera, api, (x_mid, 0, x_top - GAP, FRAME_H), (x_top, 0, FRAME_W, FRAME_H))


class TrackView:
    """The whole track raster fitted into a box (the floor's gray around it), with a path
    layer drawn incrementally."""

    def __init__(self, raster, box_w: int, box_h: int, lighting=None, surface_z_m: float = 0.0):
        img = np.asarray(raster.image)
        h, w = img.shape
        self.scale = min(box_w / w, box_h / h)
        size = (max(1, int(w * self.scale)), max(1, int(h * self.scale)))
        small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        if lighting is not None and not lighting.is_default():  # the track as its light shows it
            small = _lit(small, raster, self.scale, lighting, surface_z_m)
        self.box_w, self.box_h = box_w, box_h
        self.off = ((box_w - size[0]) // 2, (box_h - size[1]) // 2)
        floor = int(getattr(raster, "floor_gray", 0))
        canvas = np.full((box_h, box_w), floor, np.uint8)
        canvas[self.off[1]:self.off[1] + size[1], self.off[0]:self.off[0] + size[0]] = small
        self.canvas = cv2.cvtColor(canvas, cv2.COLOR_GRAY2BGR)
        self.origin = (float(raster.origin_xy_m[0]), float(raster.origin_xy_m[1]))
        self.px_per_m = self.scale / float(raster.m_per_px)
        self._last: tuple[int, int] | None = None

    def to_px(self, x_m: float, y_m: float) -> tuple[int, int]:
        """Box pixel (col, row) of a world point (raster pixel centres at integer indices)."""
        col = (x_m - self.origin[0]) * self.px_per_m + 0.5 * self.scale + self.off[0]
        row = (self.origin[1] - y_m) * self.px_per_m + 0.5 * self.scale + self.off[1]
        return int(round(col)), int(round(row))

    def extend(self, pose, off_track: bool, also: np.ndarray | None = None) -> tuple[int, int, int, int] | None:
        """Extend the path to ``pose`` on :attr:`canvas` (and on ``also``, an image of the box's
        size holding the same map, e.g. the box inside a frame's background); returns the box
        ``(x0, y0, x1, y1)`` drawn on (None: the path's first point, nothing drawn)."""
        p, last = self.to_px(pose.x_m, pose.y_m), self._last
        self._last = p
        if last is None:
            return None
        for img in (self.canvas,) if also is None else (self.canvas, also):
            cv2.line(img, last, p, _RED if off_track else _GREEN, 1, cv2.LINE_AA)
        return _around(min(last[0], p[0]), min(last[1], p[1]), max(last[0], p[0]), max(last[1], p[1]),
                       self.canvas.shape)

    def overlay(self, out: np.ndarray, pose, car_length_m: float, car_width_m: float,
                solids=()) -> tuple[int, int, int, int]:
        """Draw the objects standing on the track (``solids``, :class:`worlds.solids.Solid`) and
        the car at ``pose`` on ``out`` (``(box_h, box_w, 3)``, the map with the path); returns the
        box ``(x0, y0, x1, y1)`` of ``out`` drawn on."""
        drawn = []
        for solid in solids:
            shade = int(round(255 * solid.reflectance * 0.5))
            pts = np.array([self.to_px(x, y) for x, y in solid.corners_xy()], np.int32)
            cv2.fillConvexPoly(out, pts, (min(255, shade + 60), shade, shade), cv2.LINE_AA)
            cv2.polylines(out, [pts], True, _RED, 1, cv2.LINE_AA)
            drawn.append(pts)
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        corners = np.array([self.to_px(pose.x_m + c * fx - s * fy, pose.y_m + s * fx + c * fy)
                            for fx, fy in ((car_length_m, 0.0), (0.0, car_width_m / 2), (0.0, -car_width_m / 2))],
                           np.int32)
        cv2.fillConvexPoly(out, corners, _YELLOW, cv2.LINE_AA)
        drawn.append(corners)
        pts = np.concatenate(drawn)
        return _around(pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max(), out.shape)

    def draw(self, pose, off_track: bool, car_length_m: float, car_width_m: float,
             solids=()) -> np.ndarray:
        """Extend the path to ``pose`` and return the box image ``(box_h, box_w, 3)``, with the
        objects standing on the track (``solids``, :class:`worlds.solids.Solid`) on it."""
        self.extend(pose, off_track)
        out = self.canvas.copy()
        self.overlay(out, pose, car_length_m, car_width_m, solids)
        return out


def _lit(small: np.ndarray, raster, scale: float, lighting, surface_z_m: float) -> np.ndarray:
    """``small`` (the raster shrunk by ``scale``) times the illuminance over the default hall's
    (``worlds.lighting.DEFAULT_AMBIENT_LUX``), clipped at white (as trackgen's preview.png)."""
    from worlds.lighting import DEFAULT_AMBIENT_LUX

    hs, ws = small.shape
    m = float(raster.m_per_px) / scale  # metres per small pixel
    x0, y0 = (float(v) for v in raster.origin_xy_m)
    xs = x0 + (np.arange(ws) + 0.5) * m
    ys = y0 - (np.arange(hs) + 0.5) * m
    lux = lighting.illuminance_grid(xs, ys, surface_z_m)
    return np.clip(np.rint(small * (lux / DEFAULT_AMBIENT_LUX)), 0, 255).astype(np.uint8)


def _around(x0: int, y0: int, x1: int, y1: int, shape, margin: int = 2) -> tuple[int, int, int, int]:
    """The box ``(x0, y0, x1, y1)`` (end exclusive) holding the pixels ``x0..x1``, ``y0..y1`` and
    ``margin`` around them (a line's anti-aliasing), clipped to an image of ``shape``."""
    h, w = shape[:2]
    return (max(0, int(x0) - margin), max(0, int(y0) - margin),
            min(w, int(x1) + margin + 1), min(h, int(y1) + margin + 1))


def _put(img, text: str, x: int, y: int, color=_WHITE, scale: float = 0.45) -> None:
    cv2.putText(img, text, (x, y), _FONT, scale, color, 1, cv2.LINE_AA)


def _stretch(row: np.ndarray, w: int, h: int) -> np.ndarray:
    arr = np.asarray(row)
    if arr.dtype != np.uint8:
        arr = np.clip(arr, 0, 255).astype(np.uint8)
    return cv2.cvtColor(cv2.resize(arr.reshape(1, -1), (w, h), interpolation=cv2.INTER_NEAREST),
                        cv2.COLOR_GRAY2BGR)


_API_NAMES = ("time", "frame", "speed", "cmd", "steer", "cmd", "x", "y", "yaw", "lap", "line row")


def _api_places(box) -> list[tuple[int, int]]:
    """Where each of the API panel's rows (``_API_NAMES``) starts: two columns."""
    x0, y0, x1, y1 = box
    half = (x1 - x0) // 2
    per_col = max(1, math.ceil(len(_API_NAMES) / 2))
    step = max(16, min(26, (y1 - y0 - 40) // per_col))
    return [(x0 + 8 + (i // per_col) * half, y0 + 20 + (i % per_col) * step) for i in range(len(_API_NAMES))]


def _api_values(out: np.ndarray, box, rec: FrameRecord, laps: int) -> None:
    """The API panel's values (its names are in the background)."""
    st = rec.state

    def z(v: float, nd: int) -> float:  # no "-0.000"
        return round(v, nd) + 0.0

    values = (f"{rec.t_s:.3f} s", f"{rec.frame}", f"{z(st['speed'], 3):.3f} m/s",
              f"{z(st['speed_cmd'], 3):.3f} m/s", f"{z(math.degrees(st['steer']), 1):.1f} deg",
              f"{z(math.degrees(st['steer_cmd']), 1):.1f} deg", f"{z(rec.pose.x_m, 3):.3f} m",
              f"{z(rec.pose.y_m, 3):.3f} m", f"{z(math.degrees(rec.pose.yaw_rad), 1):.1f} deg",
              f"{st['lap']} / {laps}" if laps else f"{st['lap']}", f"{rec.line_row}")
    for (x, y), value in zip(_api_places(box), values):
        _put(out, value, x + 62, y)
    if st.get("off_track"):
        _put(out, "OFF TRACK", box[0] + 8, box[3] - 10, _RED, 0.7)


def _middle_panel(out: np.ndarray, box, rec: FrameRecord) -> int:
    """The camera line, the controller's processed lines, its text under them; returns the row
    below the last one drawn on."""
    x0, y0, x1, y1 = box
    w = x1 - x0 - 16
    y = y0 + 16
    _put(out, f"camera line (row {rec.line_row})", x0 + 8, y, _GRAY)
    y += 6
    if rec.line is not None:
        out[y:y + LINE_H, x0 + 8:x0 + 8 + w] = _stretch(rec.line, w, LINE_H)
    y += LINE_H + 8
    if rec.lines is not None and len(rec.lines):
        _put(out, "controller", x0 + 8, y + 10, _GRAY)
        y += 16
        for ln in rec.lines:
            if y + CTRL_LINE_H > y1 - 8:
                break
            out[y:y + CTRL_LINE_H, x0 + 8:x0 + 8 + w] = _stretch(ln, w, CTRL_LINE_H)
            y += CTRL_LINE_H + 4
    chars = max(8, w // 8)
    y += 14
    for line in rec.text:
        if y > y1 - 6:
            break
        _put(out, str(line)[:chars], x0 + 8, y)
        y += TEXT_STEP
    return min(y1, y + 8)  # (a text's descenders reach a few pixels below its baseline)


def _pixy2_overlay(out: np.ndarray, box, features, vector_index, grid_w: int, grid_h: int) -> None:
    """The Pixy2's vectors (green, the Vector yellow; arrows point to the head) and
    intersections (red rings), barcodes (their code in a red box) over the camera image, as
    PixyMon's "all features" view."""
    x0, y0, x1, y1 = box
    sx, sy = (x1 - x0) / grid_w, (y1 - y0) / grid_h

    def at(x: int, y: int) -> tuple[int, int]:
        return int(x0 + (x + 0.5) * sx), int(y0 + (y + 0.5) * sy)
    for v in features.vectors:
        color = _YELLOW if v.m_index == vector_index else _GREEN
        cv2.arrowedLine(out, at(v.m_x0, v.m_y0), at(v.m_x1, v.m_y1), color, 2, tipLength=0.08)
    for it in features.intersections:
        cv2.circle(out, at(it.m_x, it.m_y), 7, _RED, 2)
    for b in features.barcodes:
        cx, cy = at(b.m_x, b.m_y)
        cv2.rectangle(out, (cx - 10, cy - 8), (cx + 10, cy + 8), _RED, 1)
        cv2.putText(out, str(b.m_code), (cx - 7, cy + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, _RED, 1, cv2.LINE_AA)


class Composer:
    """Draws the frames of one video (see the module's layout). What does not change from a
    frame to the next (the panels, the API's names, the track map with the path driven so
    far) is kept in a background drawn once; each frame copies it and draws what changes.

    ``track_view`` (None: no top-down view) is extended by every frame (its path)."""

    def __init__(self, layout: Layout, track_view: TrackView | None, laps: int,
                 car_length_m: float = 0.28, car_width_m: float = 0.16):
        self.layout, self.laps, self._car = layout, laps, (car_length_m, car_width_m)
        self._view = track_view if layout.top is not None else None
        bg = np.zeros((FRAME_H, FRAME_W, 3), np.uint8)
        for x0, y0, x1, y1 in (layout.api, layout.middle):
            bg[y0:y1, x0:x1] = _PANEL
        for (x, y), name in zip(_api_places(layout.api), _API_NAMES):
            _put(bg, name, x, y, _GRAY)
        self._top = None
        if self._view is not None:
            bx0, by0, bx1, by1 = layout.top
            h, w = min(by1 - by0, self._view.box_h), min(bx1 - bx0, self._view.box_w)
            bg[by0:by0 + h, bx0:bx0 + w] = self._view.canvas[:h, :w]
            self._top = (slice(by0, by0 + h), slice(bx0, bx0 + w))
        self._bg = bg
        self._out: np.ndarray | None = None  # the frame drawn, kept from one frame to the next
        self._drawn: list[tuple[int, int, int, int]] = []  # boxes the last frame drew over the background

    def frame(self, rec: FrameRecord) -> np.ndarray:
        """The ``(FRAME_H, FRAME_W, 3)`` BGR frame of ``rec``: the composer's own image, drawn
        over by the next call (what the last frame drew over the background is restored from it,
        not the whole frame copied)."""
        layout, view, bg = self.layout, self._view, self._bg
        restore = self._drawn
        fits = False
        if view is not None:  # the path, into the background
            rows, cols = self._top
            fits = bg[rows, cols].shape[:2] == (view.box_h, view.box_w)
            segment = view.extend(rec.pose, bool(rec.state.get("off_track")), bg[rows, cols] if fits else None)
            if not fits:  # a view other than its box's size: its top-left part
                bg[rows, cols] = view.canvas[:rows.stop - rows.start, :cols.stop - cols.start]
                restore = [*restore, (cols.start, rows.start, cols.stop, rows.stop)]
            elif segment is not None:
                sx0, sy0, sx1, sy1 = segment
                restore = [*restore, (cols.start + sx0, rows.start + sy0, cols.start + sx1, rows.start + sy1)]
        out = self._out
        if out is None:
            out = self._out = bg.copy()
        else:
            for x0, y0, x1, y1 in restore:
                out[y0:y1, x0:x1] = bg[y0:y1, x0:x1]
        drawn = []
        # camera image, the selected row marked at both sides
        x0, y0, x1, y1 = layout.camera
        img = cv2.resize(rec.image, (x1 - x0, y1 - y0), interpolation=cv2.INTER_NEAREST)
        out[y0:y1, x0:x1] = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        ry = y0 + int((rec.line_row + 0.5) * (y1 - y0) / rec.image.shape[0])
        cv2.line(out, (x0, ry), (x0 + 8, ry), _RED, 2)
        cv2.line(out, (x1 - 9, ry), (x1 - 1, ry), _RED, 2)
        drawn.append(_around(x0, ry, x1 - 1, ry, out.shape))  # (a 2-px line reaches a pixel past the image)
        if rec.pixy2 is not None:
            _pixy2_overlay(out, layout.camera, *rec.pixy2)
            drawn.append(_around(x0, y0, x1 - 1, y1 - 1, out.shape, margin=16))  # (rings and arrows reach past it)
        _api_values(out, layout.api, rec, self.laps)
        drawn.append(layout.api)
        mx0, my0, mx1, _ = layout.middle
        drawn.append((mx0, my0, mx1, _middle_panel(out, layout.middle, rec)))
        if view is not None:  # the objects on the track and the car, over the map
            solids = rec.state.get("solids", ())
            if fits:
                bx0, by0, bx1, by1 = view.overlay(out[rows, cols], rec.pose, *self._car, solids)
                drawn.append((cols.start + bx0, rows.start + by0, cols.start + bx1, rows.start + by1))
            else:
                box = view.canvas.copy()
                view.overlay(box, rec.pose, *self._car, solids)
                out[rows, cols] = box[:rows.stop - rows.start, :cols.stop - cols.start]
                drawn.append((cols.start, rows.start, cols.stop, rows.stop))
        self._drawn = drawn
        return out


def compose(rec: FrameRecord, track_view: TrackView | None, laps: int,
            car_length_m: float = 0.28, car_width_m: float = 0.16,
            layout: Layout | None = None) -> np.ndarray:
    """One ``(FRAME_H, FRAME_W, 3)`` BGR video frame from a record (see module layout);
    ``layout`` defaults to the one for the record's image and the view's box. A video's
    frames are drawn faster by one :class:`Composer`."""
    if layout is None:
        aspect = None if track_view is None else track_view.box_w / track_view.box_h
        layout = Layout.for_frame(rec.image.shape, aspect)
    return Composer(layout, track_view, laps, car_length_m, car_width_m).frame(rec)
