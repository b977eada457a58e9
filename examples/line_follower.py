"""A line-following controller of the thesis's kind: one camera line, both black edges.

Run it:  simrunner drive examples/line_follower.py [--track ...] [--video run.mp4]

Each frame it reads one image row (the line camera, ``spinner.line_row``), finds the white
lane between the dark edge lines, steers towards the lane's middle (PD on the pixel error)
and slows down while steering hard. Where only one edge is in view it places the middle
half a lane width (learned while both edges are seen) from that edge; where the whole row
is white (a crossroads) it goes straight on; where nothing white is seen (line lost) it
keeps its last estimate, i.e. the last steering, as the thesis's team did.

Light: like a team's code on the real car it keeps the line bright but unclipped by setting
the camera's exposure (0.5 to 30 ms): 20 % shorter while the brightest pixel clips (255), 25 %
longer while it is below 100 (a dim row), else unchanged; it ignores the first
SKIP_FRAMES frames after power-up (a line camera's first frames are garbage); the ideal
camera ignores the exposure: its images do not depend on light. Under a dark zone even 30 ms may leave the lane below the
fixed threshold of 128: ``--param threshold=0`` then cuts each row half-way between its
darkest and brightest pixel instead (docs/camera.md shows both on a dim track).

Units: Spinner defaults (m/s, radians, + = left). The gains are per half image width.
Parameters (``--param NAME=VALUE``, e.g. for ``simrunner batch`` sweeps): ``v_max``,
``v_min`` (m/s), ``kp``, ``kd``, ``threshold`` (gray, 0 = adaptive); the defaults are the
constants below.
"""
from __future__ import annotations

import numpy as np

V_MAX_MPS = 2.8        # on straights
V_MIN_MPS = 1.5        # at full steering
KP = 0.8               # rad of steering per half-image of lateral error
KD = 0.9               # rad per half-image of error change per frame
STEER_LIMIT_RAD = 0.40
WHITE = 128            # gray threshold: lane is white (~235), edges/floor dark (15-40)
MIN_CONTRAST = 40      # adaptive threshold: a row darker-to-brighter by less sees no lane
SPEED_FILTER = 0.25    # low-pass factor of the speed command per frame
EXPOSURE_MIN_S, EXPOSURE_MAX_S = 0.0005, 0.030  # auto exposure limits
PEAK_LOW, PEAK_HIGH = 100, 255  # brightest pixel: too dim, clipped
SKIP_FRAMES = 3        # frames after power-up not used for the exposure
_WHITE_TABLES: dict[int, bytes] = {}


def white_table(threshold: int) -> bytes:
    """gray byte -> 1 if brighter than ``threshold`` else 0 (for bytes.translate), cached."""
    table = _WHITE_TABLES.get(threshold)
    if table is None:
        table = _WHITE_TABLES[threshold] = bytes(int(v > threshold) for v in range(256))
    return table


_IS_WHITE = white_table(WHITE)


def next_exposure(exposure_s: float, peak: int) -> float:
    """Auto exposure: shorter when the brightest pixel clips, longer when it is dim."""
    if peak >= PEAK_HIGH:
        factor = 0.8
    elif peak < PEAK_LOW:
        factor = 1.25
    else:
        return exposure_s
    return min(max(exposure_s * factor, EXPOSURE_MIN_S), EXPOSURE_MAX_S)


def row_threshold(row: np.ndarray) -> int:
    """Adaptive threshold: half-way between the row's darkest and brightest pixel (255, i.e.
    nothing white, when they differ by less than MIN_CONTRAST)."""
    lo, hi = int(row.min()), int(row.max())
    return (lo + hi) // 2 if hi - lo >= MIN_CONTRAST else 255


def lane_edges(row: np.ndarray, guess_px: float, is_white: bytes = _IS_WHITE) -> tuple[int | None, int | None] | None:
    """First and last column of the white lane run in one image row (None where the run
    reaches the image border, i.e. that edge is not in view). The run chosen is the one
    containing ``guess_px``, else the nearest one. ``None`` if no pixel is white (lost)."""
    white = row.tobytes().translate(is_white)  # 1 = white, 0 = dark; bytes.find is fast C
    w = len(white)
    g = min(max(int(guess_px), 0), w - 1)
    if not white[g]:
        r, l = white.find(1, g), white.rfind(1, 0, g)
        if r < 0 and l < 0:
            return None
        g = r if l < 0 or (0 <= r and r - g <= g - l) else l
    a, b = white.rfind(0, 0, g), white.find(0, g)
    return (a + 1 if a >= 0 else None), (b - 1 if b >= 0 else None)


class AutoExposure:
    """The exposure control of :func:`main` for ``spinner``: :meth:`update` with each row read
    (the first SKIP_FRAMES rows after power-up are not used)."""

    def __init__(self, spinner):
        self.s = spinner
        self.exposure = spinner.get_exposure()
        self.frames = 0

    def update(self, row: np.ndarray) -> None:
        self.frames += 1
        new = next_exposure(self.exposure, int(row.max())) if self.frames > SKIP_FRAMES else self.exposure
        if new != self.exposure:
            self.s.set_exposure(new)
            self.exposure = new


class LaneTracker:
    """The lane middle in one image row, remembered between frames (pixels).

    Both edges seen: the middle of them (and the lane width is learned). One edge seen: half
    a lane width from it. All white (a crossroads): straight on. No white at all (lost):
    the last estimate, i.e. the last steering, as the thesis's team did.
    """

    def __init__(self, width_px: int):
        self.half = width_px / 2.0
        self.centre = self.half
        self.lane_px = float(width_px)
        self.edges: tuple | None = (None, None)
        self.at_crossing = False

    def error(self, row: np.ndarray, is_white: bytes = _IS_WHITE) -> float:
        """Lateral error in half-image units, + = the lane middle is right of the car."""
        self.edges = edges = lane_edges(row, self.centre, is_white)
        left, right = edges if edges is not None else (None, None)
        self.at_crossing = edges is not None and left is None and right is None
        if left is not None and right is not None:
            self.lane_px = 0.9 * self.lane_px + 0.1 * (right - left)
            self.centre = 0.5 * (left + right)
        elif left is not None:
            self.centre = left + 0.5 * self.lane_px
        elif right is not None:
            self.centre = right - 0.5 * self.lane_px
        elif self.at_crossing:
            self.centre = self.half
        return (self.centre - self.half) / self.half


def main(spinner):
    s = spinner
    v_max, v_min = s.param("v_max", V_MAX_MPS), s.param("v_min", V_MIN_MPS)
    kp, kd = s.param("kp", KP), s.param("kd", KD)
    threshold = int(s.param("threshold", WHITE))
    lane = LaneTracker(s.image_shape[1])
    prev_err, speed = 0.0, v_min
    exposure = AutoExposure(s)
    while True:
        row = s.get_image(s.line_row)[0]
        err = lane.error(row, white_table(row_threshold(row) if threshold == 0 else threshold))
        exposure.update(row)
        if lane.at_crossing:
            prev_err = err  # no derivative kick when the estimate is reset
        steer = min(max(-kp * err - kd * (err - prev_err), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev_err = err
        target = v_max - (v_max - v_min) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += SPEED_FILTER * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
        if s.recording:  # debug text for the video (formatting it costs time every frame)
            s.add_data([f"edges {lane.edges}  lane {lane.lane_px:.0f} px",
                        f"steer {steer:+.3f} rad  speed {speed:.2f} m/s"])
