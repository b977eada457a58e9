"""The physical camera's cost (issue 47): closed-loop laps of examples/line_follower.py on the
default track with the default car (``camera.model = "linescan"``: 19.5 ms exposure + 0.5 ms
read-out, 50 Hz) and the same car with ``model = "ideal"`` (50 Hz),
interleaved, best of ``REPEATS`` in process CPU time; and the camera line alone per frame
(``Camera.line_image`` against ``Imager.line`` with noise and motion blur), warm.

Target: closed-loop real-time factor with the linescan camera >= 0.85 x the ideal camera's.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from simrunner.run.runner import drive, resolve_track
from simrunner.sensors.camera import Camera
from simrunner.sensors.imaging import Imager
from vehicle.description import load_car

REPEATS = 5
CONTROLLER = Path(__file__).resolve().parents[1] / "examples" / "line_follower.py"
RATIO_TARGET = 0.85


def _line_cost_us(fn, n: int = 2000) -> float:
    best = math.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def main() -> None:
    physical = load_car(None)  # the default car: a linescan camera
    ideal = physical.replace(camera=dataclasses.replace(physical.camera, model="ideal"))
    track, _ = resolve_track(None, ideal)
    best = {"ideal": math.inf, "linescan": math.inf}
    laps = {}
    for _ in range(REPEATS):
        for name, car in (("ideal", ideal), ("linescan", physical)):
            r = drive(CONTROLLER, track=track, car=car, laps=1, time_limit_s=60.0)
            best[name] = min(best[name], r.cpu_time_s)
            laps[name] = r
    print(f"{'camera':10s}{'outcome':>10s}{'lap s':>8s}{'frames':>8s}{'RTF (CPU)':>11s}")
    for name, r in laps.items():
        print(f"{name:10s}{r.outcome:>10s}{r.lap_times_s[0] if r.lap_times_s else float('nan'):8.2f}"
              f"{len(r.log) - 1:8d}{r.sim_time_s / best[name]:11.1f}")
    ratio = (laps["linescan"].sim_time_s / best["linescan"]) / (laps["ideal"].sim_time_s / best["ideal"])
    verdict = "met" if ratio >= RATIO_TARGET else "MISSED"
    print(f"RTF linescan / ideal: {ratio:.2f} (target >= {RATIO_TARGET}: {verdict})")

    cam = Camera(physical.camera, track)
    imager = Imager(cam, track.lighting, surface_z_m=track.surface_z_m)
    pose = track.start
    rng = np.random.default_rng(0)
    row = physical.camera.default_row
    exposure = physical.camera.exposure_s
    ideal_us = _line_cost_us(lambda: cam.line_image(pose, row, rng))
    phys_us = _line_cost_us(lambda: imager.line(pose, row, exposure_s=exposure, twist=(2.0, 0.0, 1.0),
                                                normals=rng, frame_index=10))
    still_us = _line_cost_us(lambda: imager.line(pose, row, exposure_s=exposure, normals=rng, frame_index=10))
    print(f"camera line per frame (us, warm): ideal {ideal_us:.0f}, linescan {phys_us:.0f} "
          f"({physical.camera.motion_blur_samples} motion samples), linescan still {still_us:.0f}")
    frame_ms = _line_cost_us(lambda: imager.frame(Pose2(track.start.x_m, track.start.y_m, track.start.yaw_rad),
                                                  exposure_s=exposure, normals=rng), n=20) / 1e3
    print(f"whole 128 x 128 frame, linescan model: {frame_ms:.1f} ms (ideal render: bench_camera)")


if __name__ == "__main__":
    main()
