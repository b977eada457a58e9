"""The figure 8 (rules summary section 4.1): laps of the kit's M figure 8 in the time, straight on
at its crossing.

    simrunner drive examples/events/figure8.py --event figure8

On the M layout the car comes out of a 90-degree turn 0.17 m before the crossing (the kit's
crossing has 0.17 m stubs, rules summary section 1.2): the camera row, 0.63 m ahead, sees the
crossing's white square open beside the lane while the car is still turning, and a plain line
follower (examples/line_follower.py) takes the opening for the lane, stops turning and leaves
the course. This controller keeps doing what the row cannot show:
- FOLLOW: the line follower's PD on the lane middle in the camera row.
- An opening two frames in a row (an edge jumping outward, the row all white, a white run much
  wider than the lane; a finish mark's bars show for one frame): ARC: keep the mean steering of
  the frames before it (the turn goes on) for ARC_M of travel (dead reckoning), the distance
  after which the car, seeing the square this way, is out of the turn (0.14 to 0.18 m all pass
  20 of 20 seeds with the default car);
- then STRAIGHT: hold that heading (the rules: straight on at crossings) until the row shows a
  lane again, as wide as the lane it learned (the road beyond the square: a side road is a
  white run across the whole row).
Dead reckoning uses the car's speed and its own steering through the bicycle model (a team's
encoder and servo; a gyro does better). The camera numbers are the default car's
(vehicle/data/nxp_cup_car.toml); the row is read after taking out the lens's cos^4 fall-off (a
flat field a team measures once on a white sheet).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/: the line follower
from line_follower import AutoExposure, KD, KP, MIN_CONTRAST, STEER_LIMIT_RAD, lane_edges, white_table  # noqa: E402

# the default car (vehicle/data/nxp_cup_car.toml)
WHEELBASE_M = 0.175
HFOV_RAD = 1.3
# the controller
LANE_TOLERANCE = 0.25    # a lane seen this much wider or narrower than learned is no lane
JUMP_PX = 5              # an edge moving outward this far in one frame: an opening beside the lane
OPENING_FRAMES = 2       # an opening seen this many frames in a row is a crossing
HOLD_FRAMES = 6          # ARC keeps the mean steering of this many frames before the opening
ARC_M = 0.16             # after the row sees a crossing, the turn before it goes on this far (the default
#                          camera on the kit's M layout: the crossing's stubs are 0.17 m)
MIN_STRAIGHT_M = 0.10    # STRAIGHT lasts at least this (then the row looks beyond the square)
K_HEADING = 2.5          # rad of steering per rad of heading error on STRAIGHT
V_FAST_MPS, V_SLOW_MPS = 2.4, 1.4
V_CROSS_MPS = 1.2        # on ARC and STRAIGHT


def flat_field(width: int, height: int, row: int) -> np.ndarray:
    """The lens's fall-off along image row ``row``: cos^4 of each pixel's angle to the axis."""
    f = (width / 2.0) / math.tan(HFOV_RAD / 2.0)
    u = np.arange(width) + 0.5 - width / 2.0
    v = row + 0.5 - height / 2.0
    return (f / np.sqrt(f * f + u * u + v * v)) ** 4


def main(s):
    height, width = s.image_shape
    row_no = s.line_row
    fall_off = flat_field(width, height, row_no)
    exposure = AutoExposure(s)
    yaw, odo = 0.0, 0.0        # dead reckoning: heading (rad) and distance (m)
    steer, speed, prev_err = 0.0, V_SLOW_MPS, 0.0
    recent = [0.0] * HOLD_FRAMES  # the last frames' steering (before the opening)
    odd = 0                    # frames in a row that showed an opening
    lane_px = None             # the lane's width in the row, learned where both edges are seen
    last_edges = (None, None)
    mode, until, hold = "FOLLOW", 0.0, 0.0
    white = 0.0
    t_prev = s.get_time()
    centre_px = width / 2.0
    while True:
        raw = s.get_image(row_no)[0]
        t = s.get_time()
        dt, t_prev = t - t_prev, t
        v = s.get_speed()
        yaw += v * math.tan(steer) / WHEELBASE_M * dt
        odo += abs(v) * dt
        exposure.update(raw)
        row = np.clip(raw / fall_off, 0, 255).astype(np.uint8)
        white = max(0.995 * white, float(row.max()))
        lo, hi = int(row.min()), int(row.max())
        level = (lo + hi) // 2 if hi - lo >= MIN_CONTRAST else (0 if lo > 0.6 * white else 255)
        edges = lane_edges(row, centre_px, white_table(level))
        left, right = edges if edges is not None else (None, None)
        lane = None     # the lane middle in pixels where the row shows the lane
        opening = False
        if left is not None and right is not None:
            if lane_px is None or abs(right - left - lane_px) <= LANE_TOLERANCE * lane_px:
                lane_px = (right - left) if lane_px is None else 0.9 * lane_px + 0.1 * (right - left)
                lane = 0.5 * (left + right)
            else:
                opening = right - left > lane_px
        elif edges is not None and left is None and right is None:
            opening = lane_px is not None  # all white
        elif lane_px is not None and edges is not None:
            jumped = ((left is not None and last_edges[0] is not None and last_edges[0] - left > JUMP_PX)
                      or (right is not None and last_edges[1] is not None and right - last_edges[1] > JUMP_PX))
            if jumped:
                opening = True
            else:
                lane = left + 0.5 * lane_px if left is not None else right - 0.5 * lane_px
        last_edges = (left, right)
        odd = odd + 1 if opening else 0
        if mode == "FOLLOW" and odd >= OPENING_FRAMES:  # (a finish mark's bars show for one frame)
            mode, until, hold = "ARC", odo + ARC_M, sum(recent) / len(recent)
        if mode == "ARC" and odo >= until:
            mode, until, hold = "STRAIGHT", odo + MIN_STRAIGHT_M, yaw
        if mode == "STRAIGHT" and odo >= until and lane is not None:
            mode = "FOLLOW"
            prev_err = (lane - width / 2.0) / (width / 2.0)
        if mode == "ARC":
            cmd = hold
        elif mode == "STRAIGHT":
            cmd = K_HEADING * (hold - yaw)
        else:
            if lane is not None:
                centre_px = lane
            err = (centre_px - width / 2.0) / (width / 2.0)
            cmd = -KP * err - KD * (err - prev_err)
            prev_err = err
        steer = min(max(cmd, -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        if not opening:
            recent = recent[1:] + [steer]
        if mode != "FOLLOW":
            goal = V_CROSS_MPS
        else:
            goal = V_FAST_MPS - (V_FAST_MPS - V_SLOW_MPS) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += 0.25 * (goal - speed) if goal > speed else (goal - speed)
        s.set_speed_and_servo(speed, steer)
        if s.recording:
            s.add_data([f"edges {edges} {mode} lane {lane_px}", f"steer {steer:+.3f} speed {speed:.2f}"])
