"""A line-following controller of the thesis's kind: one camera line, both black edges.

Run it:  simrunner drive examples/line_follower.py [--track ...] [--video run.mp4]

Each frame it reads one image row (the line camera, ``spinner.line_row``), finds the white
lane between the dark edge lines, steers towards the lane's middle (PD on the pixel error)
and slows down while steering hard. Where only one edge is in view it places the middle
half a lane width (learned while both edges are seen) from that edge; where no edge is
seen (a crossroads, or a lane wider than the view) it keeps its last estimate, i.e. the
last steering, as the thesis's team did.

Units: Spinner defaults (m/s, radians, + = left). The gains are per half image width.
"""
from __future__ import annotations

import numpy as np

V_MAX_MPS = 1.9        # on straights
V_MIN_MPS = 1.0        # at full steering
KP = 0.55              # rad of steering per half-image of lateral error
KD = 0.9               # rad per half-image of error change per frame
STEER_LIMIT_RAD = 0.40
WHITE = 128            # gray threshold: lane is white (~235), edges/floor dark (15-40)
SPEED_FILTER = 0.25    # low-pass factor of the speed command per frame


def lane_edges(row: np.ndarray, guess_px: float) -> tuple[int | None, int | None]:
    """First and last column of the white lane run in one image row (None where the run
    reaches the image border, i.e. that edge is not in view). The run chosen is the one
    containing ``guess_px``, else the nearest one; ``(None, None)`` if no pixel is white."""
    white = (row > WHITE).tobytes()  # 1 = white, 0 = dark; bytes.find is fast C
    w = len(white)
    g = min(max(int(guess_px), 0), w - 1)
    if not white[g]:
        r, l = white.find(1, g), white.rfind(1, 0, g)
        if r < 0 and l < 0:
            return None, None
        g = r if l < 0 or (0 <= r and r - g <= g - l) else l
    a, b = white.rfind(0, 0, g), white.find(0, g)
    return (a + 1 if a >= 0 else None), (b - 1 if b >= 0 else None)


def main(spinner):
    s = spinner
    row_index = s.line_row
    width = s.image_shape[1]
    half = width / 2.0
    centre = half            # lane middle estimate, pixels
    lane_px = float(width)   # lane width in pixels at this row (learned)
    prev_err = 0.0
    steer = 0.0
    speed = V_MIN_MPS
    while True:
        row = s.get_image(row_index)[0]
        left, right = lane_edges(row, centre)
        if left is not None and right is not None:
            lane_px = 0.9 * lane_px + 0.1 * (right - left)
            centre = 0.5 * (left + right)
        elif left is not None:
            centre = left + 0.5 * lane_px
        elif right is not None:
            centre = right - 0.5 * lane_px
        # else: no edge in view -> keep the last estimate (and so the last steering)
        err = (centre - half) / half          # + = lane middle is to the car's right
        steer = min(max(-KP * err - KD * (err - prev_err), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev_err = err
        target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += SPEED_FILTER * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
        s.add_data([f"edges {left} {right}  lane {lane_px:.0f} px",
                    f"steer {steer:+.3f} rad  speed {speed:.2f} m/s"])
