"""Emergency braking (rules summary section 4.4): two laps, then a black block is put across
the track ahead; stop before it without touching it.

    simrunner drive examples/events/emergency_brake.py --event emergency_brake \\
        --car examples/events/sensor_car.toml

The line follower of examples/line_follower.py (its lane tracker and auto exposure), a bit
slower, and a forward range sensor (``front`` in the car file): once the distance left is what
the car needs to stop (speed^2 / (2 x the braking it counts on) + the distance it rolls while
the sensor takes its next reading + a margin), it brakes to a stop and stays there.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/: the line follower
from line_follower import AutoExposure, LaneTracker, white_table, WHITE  # noqa: E402

V_MAX_MPS, V_MIN_MPS = 1.8, 1.2
KP, KD = 0.8, 0.9
STEER_LIMIT_RAD = 0.40
BRAKE_MPS2 = 2.5      # counted on (the car brakes at 3.1 m/s^2: docs/car.md)
SENSOR_PERIOD_S = 1 / 16.0
MARGIN_M = 0.12       # from the sensor (front bumper) to the block, when stopped


def main(s):
    v_max, v_min = s.param("v_max", V_MAX_MPS), s.param("v_min", V_MIN_MPS)
    lane = LaneTracker(s.image_shape[1])
    is_white = white_table(WHITE)
    prev, speed, exposure = 0.0, v_min, AutoExposure(s)
    stopping = False
    while True:
        row = s.get_image(s.line_row)[0]
        exposure.update(row)
        err = lane.error(row, is_white)
        steer = min(max(-KP * err - KD * (err - prev), -STEER_LIMIT_RAD), STEER_LIMIT_RAD)
        prev = err
        v = s.get_speed()
        d = s.get_distance("front")
        need = v * v / (2 * BRAKE_MPS2) + v * SENSOR_PERIOD_S + MARGIN_M
        if math.isfinite(d) and d <= need:
            stopping = True
        if stopping:
            s.set_speed_and_servo(0.0, steer)
            continue
        target = v_max - (v_max - v_min) * min(1.0, abs(steer) / (0.6 * STEER_LIMIT_RAD))
        speed += 0.25 * (target - speed) if target > speed else (target - speed)
        s.set_speed_and_servo(speed, steer)
