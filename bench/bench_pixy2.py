"""The Pixy2's cost (issue 47, item 4): laps of examples/pixy2_follower.py with
examples/pixy2_car.toml on the default track (and the two NXP tracks of ``../shared/tracks``
when present), best of ``REPEATS`` in process CPU time, against examples/line_follower.py
with the default car on the same tracks; and, warm, the Pixy2's frame (316 x 208, the
physical camera) and its line tracker per frame.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from simrunner.run.runner import drive, resolve_track
from simrunner.sensors.camera import Camera
from simrunner.sensors.imaging import Imager
from simrunner.sensors.pixy2 import LineTracker
from vehicle.description import load_car

REPO = Path(__file__).resolve().parents[1]
PIXY_CAR = REPO / "examples" / "pixy2_car.toml"
PIXY_FOLLOWER = REPO / "examples" / "pixy2_follower.py"
LINE_FOLLOWER = REPO / "examples" / "line_follower.py"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"
REPEATS = 3


def _warm_ms(fn, n: int = 30) -> float:
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e3


def main() -> None:
    car = load_car(PIXY_CAR)
    tracks = [("default", None)] + [(n, SHARED_TRACKS / n) for n in ("nxp_raceway", "nxp_raceway_octagon")
                                    if (SHARED_TRACKS / n).is_dir()]
    print(f"{'track':22s}{'controller':16s}{'outcome':>10s}{'lap s':>8s}{'frames':>8s}{'RTF (CPU)':>11s}")
    for name, spec in tracks:
        track, _ = resolve_track(spec, car)
        for label, controller, run_car in (("pixy2_follower", PIXY_FOLLOWER, car), ("line_follower", LINE_FOLLOWER, None)):
            best, r = math.inf, None
            for _ in range(REPEATS):
                r = drive(controller, track=track, car=run_car, laps=1, seed=0, time_limit_s=90.0)
                best = min(best, r.cpu_time_s)
            lap = r.lap_times_s[0] if r.lap_times_s else float("nan")
            print(f"{name:22s}{label:16s}{r.outcome:>10s}{lap:8.2f}{len(r.log) - 1:8d}{r.sim_time_s / best:11.1f}")

    track, _ = resolve_track(None, car)
    cam = Camera(car.camera, track, load_line_kernel=False)
    imager = Imager(cam, track.lighting, surface_z_m=track.surface_z_m)
    rng = np.random.default_rng(0)
    frame = imager.frame(track.start, exposure_s=car.camera.exposure_s, normals=rng, frame_index=10)
    frame_ms = _warm_ms(lambda: imager.frame(track.start, exposure_s=car.camera.exposure_s, normals=rng,
                                             frame_index=10))
    tracker = LineTracker(car.pixy2)
    track_ms = _warm_ms(lambda: tracker.process(frame), n=100)
    print(f"per Pixy2 frame (ms, warm): camera frame {car.camera.width_px} x {car.camera.height_px} "
          f"{frame_ms:.2f}, line tracker {track_ms:.2f} ({len(tracker.all.vectors)} vectors)")


if __name__ == "__main__":
    main()
