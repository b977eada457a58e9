"""The timed race (rules summary section 3): one lap from a standing start behind the
start/finish line, then stop within 2 m after the line (else +1 s).

    simrunner drive examples/events/race.py --event race --track examples/kit_S.txt

The line follower of examples/line_follower.py, and an eye for the kit's finish mark: two
bars across the lane's middle, seen in a near camera row (marks.py; a near row: at the kit's
tight turns the far row still looks across the turn when the mark passes under it). After
MIN_LAP_M of its own odometry the first sighting is the finish (the car starts behind the
line): it drives on until its rear axle is past the line and brakes to a stop.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/: the line follower
from line_follower import (AutoExposure, KD, KP, STEER_LIMIT_RAD, V_MAX_MPS, V_MIN_MPS, LaneTracker,  # noqa: E402
                           WHITE, white_table)
from marks import MARK_AHEAD_M, MARK_ROW, MarkReader  # noqa: E402  (this folder)

MIN_LAP_M = 2.5          # shorter than any lap: the next mark seen after this is the finish
PAST_LINE_M = 0.10       # brake once the rear axle is this far past the line
ZONE_CLEAR_M = 1.0       # no finish within this after a speed-limit piece's stripes


def main(s):
    lane = LaneTracker(s.image_shape[1])
    is_white = white_table(WHITE)
    prev, speed, exposure = 0.0, V_MIN_MPS, AutoExposure(s)
    travelled, t_prev = 0.0, s.get_time()
    finish_at = None  # odometry at which the rear axle is past the finish line
    marks = MarkReader()
    last_zone = -ZONE_CLEAR_M
    while True:
        row = s.get_image(s.line_row)[0]
        t = s.get_time()
        travelled += max(s.get_speed(), 0.0) * (t - t_prev)
        t_prev = t
        exposure.update(row)
        err = lane.error(row, is_white)
        mark = marks.read(s.get_image(MARK_ROW)[0])  # (every frame: the flat field learns)
        if mark in ("zone_start", "zone_end", "stripes"):
            last_zone = travelled  # a speed-limit piece: its stripes, partly seen, are no finish
        if (finish_at is None and travelled > MIN_LAP_M and mark == "finish"
                and travelled - last_zone > ZONE_CLEAR_M):
            finish_at = travelled + MARK_AHEAD_M + PAST_LINE_M
        steer = min(max(-KP * err - KD * (err - prev), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev = err
        if finish_at is not None and travelled >= finish_at:
            s.set_speed_and_servo(0.0, steer)  # past the line: brake to a stop
            continue
        target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += 0.25 * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
