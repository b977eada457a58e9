"""The line follower written in the real car's units (thesis 3.3 and Appendix A.2).

Run it:  simrunner drive examples/real_car_units.py

The faculty team's car takes servo values -512..512 with the direction swapped (positive =
right) and a motor duty in percent; the simulator speaks radians (+ = left) and m/s. The
norm functions translate, so the control code stays what runs on the car::

    s = spinner.configure(
        turn_norm=lambda speed, angle: -angle / 512 * STEER_LIMIT_RAD,   # -512..512 -> rad
        speed_norm=lambda speed, angle: speed / 100 * MAX_SPEED_MPS,     # duty % -> m/s
        speed_denorm=lambda v, angle: v / MAX_SPEED_MPS * 100,           # m/s -> duty %
    )

(``Spinner(turn_norm=...)`` inside ``main`` does the same, like the thesis's constructor.)
Helpers come from the sibling file: a controller's folder is on ``sys.path``.
"""
from line_follower import LaneTracker

STEER_LIMIT_RAD = 0.40
MAX_SPEED_MPS = 3.1
KP, KD = 1024, 1152          # servo units per half image (= 0.8 and 0.9 rad)
DUTY_MAX, DUTY_MIN = 90, 48  # percent (= 2.8 and 1.5 m/s)


def main(spinner):
    s = spinner.configure(
        turn_norm=lambda speed, angle: -angle / 512 * STEER_LIMIT_RAD,
        speed_norm=lambda speed, angle: speed / 100 * MAX_SPEED_MPS,
        speed_denorm=lambda v, angle: v / MAX_SPEED_MPS * 100,
    )
    lane = LaneTracker(s.image_shape[1])
    prev_err = 0.0
    while True:
        err = lane.error(s.getImage(s.line_row)[0])  # + = lane to the right
        if lane.at_crossing:
            prev_err = err
        servo = max(-512, min(512, KP * err + KD * (err - prev_err)))  # + = right here
        prev_err = err
        duty = DUTY_MAX - (DUTY_MAX - DUTY_MIN) * min(1.0, abs(servo) / (0.6 * 512))
        s.setSpeedAndServo(duty, servo)
        s.addData([f"servo {servo:+.0f}", f"duty {duty:.0f} %  speed {s.getSpeed():.0f} %"])
