"""The speed-limit zone (rules summary section 4.3): slow to about half speed where the
4-stripe piece starts the zone, back up at the 3-stripe piece that ends it.

    simrunner drive examples/events/speed_limit.py --event speed_limit

The line follower of examples/line_follower.py, and an eye for the stripes in a near camera
row (marks.py). The stripes run along the lane (0.30 m long), so a piece shows for several
frames: each new stretch of stripes after STRIPES_APART_M without any is the next piece, and
the zone starts at the first and ends at the second (so a piece seen only in part, the car off
the lane's middle, still counts). In the zone the car holds ZONE_SPEED of its mean speed over
the metre before it; it drives a little slower than the line follower, to have room to brake.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/: the line follower
from line_follower import (AutoExposure, KD, KP, STEER_LIMIT_RAD, V_MIN_MPS, LaneTracker,  # noqa: E402
                           WHITE, white_table)
from marks import MARK_ROW, MarkReader  # noqa: E402  (this folder)

ZONE_SPEED = 0.45        # of the speed before the zone ("about half"; the judge: at most 0.6)
STRIPES_APART_M = 0.5    # stripes this far apart belong to different pieces
V_TOP_MPS = 1.9          # slower than the line follower: the zone's start is seen 0.33 m ahead
APPROACH_M = 1.0         # "the speed before the zone": the mean over about the last metre
ON_PIECE_M = 0.15        # the stripes start 0.21 m into a piece, seen 0.33 m ahead: the piece
#                          itself starts 0.12 m after they are first seen


def main(s):
    lane = LaneTracker(s.image_shape[1])
    is_white = white_table(WHITE)
    marks = MarkReader()
    prev, speed, exposure = 0.0, V_MIN_MPS, AutoExposure(s)
    travelled, t_prev = 0.0, s.get_time()
    last_stripes, pieces, limit, lift_at = -1e9, 0, None, None
    mean_v = 0.0
    while True:
        row = s.get_image(s.line_row)[0]
        t = s.get_time()
        v = s.get_speed()
        step = max(v, 0.0) * (t - t_prev)
        travelled += step
        t_prev = t
        mean_v += min(1.0, step / APPROACH_M) * (v - mean_v)
        exposure.update(row)
        if marks.read(s.get_image(MARK_ROW)[0]) in ("zone_start", "zone_end", "stripes"):
            if travelled - last_stripes > STRIPES_APART_M:  # a new piece
                pieces += 1
                if pieces % 2 == 1:
                    limit = ZONE_SPEED * mean_v
                else:  # the 3-stripe piece: back to speed where it starts
                    lift_at = travelled + ON_PIECE_M
            last_stripes = travelled
        if lift_at is not None and travelled >= lift_at:
            limit = lift_at = None
        err = lane.error(row, is_white)
        steer = min(max(-KP * err - KD * (err - prev), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev = err
        target = V_TOP_MPS - (V_TOP_MPS - V_MIN_MPS) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        if limit is not None:
            target = min(target, limit)
        speed += 0.25 * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
