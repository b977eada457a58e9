"""The timed race (rules summary section 3): one lap from a standing start behind the
start/finish line, then stop within 2 m after the line (else +1 s).

    simrunner drive examples/events/race.py --event race --track examples/kit_S.txt

The line follower of examples/line_follower.py, and an eye for the kit's finish mark: two short
bars across the lane's middle (0.094 m each, a 0.074 m gap), which darken the middle of the
near camera row MARK_ROW, which lies inside the lane (the bars are only 0.02 m long: at
speed the row's exposure smears them, so "darker" is relative, MARK_DIP of the row's median).
A near row: at the kit's tight turns the far row still looks across the turn when the mark
passes under it. After MIN_LAP_M of its own odometry the first sighting is the finish (the
car starts behind the line): it drives on until its rear axle is past the line and brakes
to a stop.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/: the line follower
from line_follower import (KD, KP, STEER_LIMIT_RAD, V_MAX_MPS, V_MIN_MPS, LaneTracker, SKIP_FRAMES,  # noqa: E402
                           WHITE, next_exposure, white_table)

MIN_LAP_M = 2.5          # shorter than any lap: the next mark seen after this is the finish
MARK_ROW = 110           # a near row: 0.33 m ahead, 0.44 m wide, inside the lane (docs/camera.md)
MARK_AHEAD_M = 0.33      # ... its look-ahead of the rear axle (the default car)
PAST_LINE_M = 0.10       # brake once the rear axle is this far past the line
MARK_DIP = 0.75          # a pixel of the row's middle darker than this x the row's median: a bar


def mark_seen(row: np.ndarray) -> bool:
    """The finish mark's bars darken the middle of the near row, which is all lane (at a curve
    the edge lines enter it from the side: only its middle half is looked at)."""
    w = len(row)
    middle = row[w // 4:3 * w // 4].astype(float)
    return middle.min() < MARK_DIP * float(np.median(row))


def main(s):
    lane = LaneTracker(s.image_shape[1])
    is_white = white_table(WHITE)
    prev, speed, exposure, frames = 0.0, V_MIN_MPS, s.get_exposure(), 0
    travelled, t_prev = 0.0, s.get_time()
    finish_at = None  # odometry at which the rear axle is past the finish line
    while True:
        row = s.get_image(s.line_row)[0]
        t = s.get_time()
        travelled += max(s.get_speed(), 0.0) * (t - t_prev)
        t_prev = t
        frames += 1
        new = next_exposure(exposure, int(row.max())) if frames > SKIP_FRAMES else exposure
        if new != exposure:
            s.set_exposure(new)
            exposure = new
        err = lane.error(row, is_white)
        if finish_at is None and travelled > MIN_LAP_M and mark_seen(s.get_image(MARK_ROW)[0]):
            finish_at = travelled + MARK_AHEAD_M + PAST_LINE_M
        steer = min(max(-KP * err - KD * (err - prev), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev = err
        if finish_at is not None and travelled >= finish_at:
            s.set_speed_and_servo(0.0, steer)  # past the line: brake to a stop
            continue
        target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += 0.25 * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
