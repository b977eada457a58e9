"""The car's own sensors and its compute time (issue 50): what encoders, an IMU and --mcu-time cost.

1. Encoders and IMU (target: RTF with them on >= 0.95 x off): closed-loop real-time factor
   (simulated / CPU seconds, the best of ``REPEATS``) of one lap of the default track by the
   line follower of examples/line_follower.py, log written.
   - on / off for a controller that does not read them: the plain follower on a car file with
     ``[encoders]`` and ``[imu]`` (the run log records them every frame) against the same
     follower on the default car;
   - on / off for a controller that reads them: the follower reading both rear encoders, the
     gyroscope and the accelerometer every frame (as a speed loop and a heading filter would)
     against the same follower making the same four calls as ``get_speed`` (each Spinner
     sensor call lets one physics step pass, the API's time rule: the same steps and call
     overhead without the sensor models).
   Also printed: the reading follower against the plain one (what the four calls and their
   physics steps cost together).
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
REPEATS = 5


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


def _rtf(controller, **kw) -> float:
    c0 = time.process_time()
    r = drive(controller, laps=1, **kw)
    return r.sim_time_s / (time.process_time() - c0)


def _best_rtf(controller, **kw) -> float:
    return max(_rtf(controller, **kw) for _ in range(REPEATS))


def main() -> None:
    main_fn = _follower_main()
    sensors = car_from_dict(tomllib.loads("[encoders]\n[imu]\n"))
    runs = {"plain": (main_fn, {}), "logged": (main_fn, {"car": sensors}),
            "calls": (_reading(main_fn, sensors=False), {}), "read": (_reading(main_fn), {"car": sensors})}
    best = dict.fromkeys(runs, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(REPEATS):  # alternately: a slow spell of the machine falls on all four
            for name, (controller, kw) in runs.items():
                best[name] = max(best[name], _rtf(controller, csv=Path(tmp) / f"{name}.csv", **kw))
    plain, logged, calls, read = (best[k] for k in ("plain", "logged", "calls", "read"))
    print(f"closed-loop RTF (CPU, best of {REPEATS}, one lap, log written; target: on >= 0.95 x off):")
    print(f"  a controller not reading them (the run log records them): on {logged:.1f}x, off {plain:.1f}x: "
          f"{logged / plain:.3f}")
    print(f"  a controller reading 2 encoders + gyro + accelerometer every frame: on {read:.1f}x, off (the "
          f"same 4 calls as get_speed, each a physics step) {calls:.1f}x: {read / calls:.3f}")
    print(f"  (the reading follower vs the plain one, the calls' steps and the models together: "
          f"{read / plain:.3f})")
    fixed = _best_rtf(main_fn, mcu_time=0.0)
    plain = _best_rtf(main_fn)
    print(f"--mcu-time 0 (every call charged): {fixed:.1f}x vs {plain:.1f}x without ({fixed / plain:.2f})")


if __name__ == "__main__":
    main()
