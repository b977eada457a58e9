"""Closed-loop speed (issue 3 section 12): a full lap of examples/line_follower.py on the
default track — physics + camera line at its frame rate + controller + judging + telemetry,
video off — against bare physics of the same car measured in the same process
(``CarSim.step(n)`` on a fresh sim, the same number of steps, driving a steady circle).

Targets: closed-loop real-time factor >= 30x and >= 0.8 of the bare rate. Runs are
interleaved and the best of ``REPEATS`` is kept; figures are given in process CPU time
(robust on a shared machine) and in wall time. Also printed: the
per-frame cost of the parts of the loop (camera line + noise, judge, command, read-outs).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from simrunner.camera import Camera
from simrunner.judge import Judge
from simrunner.physics import CarSim
from simrunner.runner import _load_track, default_track, drive
from worlds.car import CarDescription

REPEATS = 3
CONTROLLER = Path(__file__).resolve().parents[1] / "examples" / "line_follower.py"


def _per_call_us(fn, n: int) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6


def main() -> None:
    car = CarDescription()
    track = _load_track(default_track(), car)
    best = {"loop_cpu": math.inf, "loop_wall": math.inf, "bare_cpu": math.inf, "bare_wall": math.inf}
    result = None
    for _ in range(REPEATS):
        result = drive(CONTROLLER, laps=1, time_limit_s=60.0)
        best["loop_cpu"] = min(best["loop_cpu"], result.cpu_time_s)
        best["loop_wall"] = min(best["loop_wall"], result.wall_time_s)
        n_steps = int(round(result.sim_time_s / 0.002))
        sim = CarSim(car, dt_s=0.002, start=track.start, surface_z_m=track.surface_z_m)
        sim.set_command(1.5, 0.2)
        t0, c0 = time.perf_counter(), time.process_time()
        sim.step(n_steps)
        best["bare_cpu"] = min(best["bare_cpu"], time.process_time() - c0)
        best["bare_wall"] = min(best["bare_wall"], time.perf_counter() - t0)
    sim_s = result.sim_time_s
    frames = len(result.telemetry)
    best_bare = best["bare_cpu"]

    # per-frame parts, at the poses of the lap
    cam = Camera(car.camera, track)
    rng = np.random.default_rng(0)
    rows = result.telemetry.rows
    from pieces.pose import Pose2

    poses = [Pose2(r[2], r[3], r[4]) for r in rows]
    row = car.camera.default_row
    it = iter(range(10**9))
    cam_line = _per_call_us(lambda: cam.add_noise(
        cam.render_row(poses[next(it) % len(poses)], row).reshape(1, -1), rng), 2000)
    cam_full = _per_call_us(lambda: cam.add_noise(cam.render(poses[next(it) % len(poses)]), rng), 300)
    sim = CarSim(car, dt_s=0.002, start=track.start, surface_z_m=track.surface_z_m)
    sim.set_command(1.0, 0.1)
    sim.step(100)
    judge = Judge(track, laps=1)
    p, w = sim.pose, sim.wheel_contacts_xy()
    judge_us = _per_call_us(lambda: judge.update(1.0, p, w), 2000)
    k = iter(range(10**9))
    cmd_us = _per_call_us(lambda: sim.set_command(1.0, 0.1 + 1e-4 * (next(k) % 7)), 1000)
    reads_us = _per_call_us(lambda: (sim.pose, sim.speed_mps, sim.steer_rad, sim.yaw_rate_radps,
                                     sim.wheel_contacts_xy()), 2000)
    step_us = best_bare / max(frames - 1, 1) * 1e6

    print(f"lap: {result.outcome}, {result.laps_completed} lap(s) "
          f"{', '.join(f'{t:.2f} s' for t in result.lap_times_s)}; {sim_s:.2f} s simulated, "
          f"{frames} frames at {car.camera.fps_hz:g} fps, dt 2 ms")
    print(f"{'':34s}{'CPU time':>10s}{'wall':>10s}  target")
    for name, key, target in (("RTF closed loop (x real time)", "loop", ">= 30"),
                              ("RTF bare CarSim.step (x)", "bare", "")):
        print(f"{name:34s}{sim_s / best[key + '_cpu']:10.1f}{sim_s / best[key + '_wall']:10.1f}  {target}")
    print(f"{'ratio closed / bare':34s}{best['bare_cpu'] / best['loop_cpu']:10.2f}"
          f"{best['bare_wall'] / best['loop_wall']:10.2f}  >= 0.8")
    print(f"{'physics per frame (us)':34s}{step_us:10.1f}")
    print(f"{'closed loop per frame (us)':34s}{best['loop_cpu'] / max(frames - 1, 1) * 1e6:10.1f}")
    print(f"{'camera line + noise per frame (us)':34s}{cam_line:10.1f}")
    print(f"{'camera full image + noise (us)':34s}{cam_full:10.1f}")
    print(f"{'judge.update per frame (us)':34s}{judge_us:10.1f}")
    print(f"{'set_command per call (us)':34s}{cmd_us:10.1f}")
    print(f"{'sim read-outs per frame (us)':34s}{reads_us:10.1f}")


if __name__ == "__main__":
    main()
