"""The car's own sensors and its compute time (issue 50): what encoders, an IMU and --mcu-time cost.

1. Encoders and IMU: the line follower of examples/line_follower.py reading both rear encoders,
   the gyroscope and the accelerometer every frame (as a speed loop and a heading filter
   would), with the run log recording them too, on a car file with ``[encoders]`` and
   ``[imu]``, against the plain follower on the default car: closed-loop real-time factor
   (simulated / CPU seconds, the best of ``REPEATS``) of one lap of the default track
   (target >= 0.95 of the plain run's).
   The same four calls as ``get_speed`` (each Spinner sensor call lets one physics step pass)
   show what the calls cost without the sensor models (reading / those: what the models cost a
   controller that reads them); the plain follower on the car with the sensors, what the run
   log's copies of them cost alone (the sensors on, read by no one: on / off).
2. ``--mcu-time 0`` (every Spinner call goes through the charge) against no ``--mcu-time``.
"""
from __future__ import annotations

import importlib.util
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from simrunner.run.runner import drive
from vehicle.description import car_from_dict

REPO = Path(__file__).resolve().parents[1]
FOLLOWER = REPO / "examples" / "line_follower.py"
REPEATS = 3


def _follower_main():
    spec = importlib.util.spec_from_file_location("bench_line_follower", FOLLOWER)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("line_follower", module)
    spec.loader.exec_module(module)
    return module.main


def _reading(main, sensors: bool = True):
    """``main`` reading the encoders and the IMU before every frame (4 calls; ``sensors`` False:
    4 calls of get_speed, the same physics steps and Spinner overhead without the sensor models)."""
    def with_sensors(s):
        get_image = s.get_image

        def frame(*args, **kwargs):
            if sensors:
                s.get_encoder("RL"), s.get_encoder("RR"), s.get_gyro(), s.get_accel()
            else:
                s.get_speed(), s.get_speed(), s.get_speed(), s.get_speed()
            return get_image(*args, **kwargs)

        s.get_image = frame
        main(s)
    return with_sensors


def _best_rtf(controller, **kw) -> float:
    best = 0.0
    for _ in range(REPEATS):
        c0 = time.process_time()
        r = drive(controller, laps=1, **kw)
        best = max(best, r.sim_time_s / (time.process_time() - c0))
    return best


def main() -> None:
    main_fn = _follower_main()
    sensors = car_from_dict(tomllib.loads("[encoders]\n[imu]\n"))
    with tempfile.TemporaryDirectory() as tmp:
        plain = _best_rtf(main_fn, csv=Path(tmp) / "plain.csv")
        read = _best_rtf(_reading(main_fn), car=sensors, csv=Path(tmp) / "sensors.csv")
        calls = _best_rtf(_reading(main_fn, sensors=False), csv=Path(tmp) / "calls.csv")
        logged = _best_rtf(main_fn, car=sensors, csv=Path(tmp) / "logged.csv")
    print(f"closed-loop RTF (CPU, best of {REPEATS}, one lap, log written): plain follower {plain:.1f}x, "
          f"reading 2 encoders + gyro + accelerometer every frame (and logging them) {read:.1f}x "
          f"({read / plain:.2f} of it; target >= 0.95); the same 4 calls as get_speed (each lets a "
          f"physics step pass) {calls:.1f}x ({calls / plain:.2f}), so the sensor models cost "
          f"{read / calls:.3f} of the same calls; the car with them, the plain follower reading none "
          f"(the run log's copies only) {logged:.1f}x ({logged / plain:.3f})")
    fixed = _best_rtf(main_fn, mcu_time=0.0)
    plain = _best_rtf(main_fn)
    print(f"--mcu-time 0 (every call charged): {fixed:.1f}x vs {plain:.1f}x without ({fixed / plain:.2f})")


if __name__ == "__main__":
    main()
