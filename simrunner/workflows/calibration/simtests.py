"""The thesis chapter-5 test cases, run in the simulator (``make_sim``: car effects apply).

Each function runs one short simulation of ``car`` and returns the number the team
measures on the real car. Acceleration and braking run on high-traction ground, as in the
thesis (5.2.2: "the traction of all wheels is set to high values"): ``wheels.friction_mu``
is raised to ``HIGH_MU`` for them. All functions are deterministic.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from pieces.pose import Pose2
from simrunner.car.effects import make_sim
from vehicle.description import CarDescription

HIGH_MU = 3.0
SLIDE_M = 0.01  # the tilt test: the car "slides" if it moves more than this in SLIDE_TIME_S
SLIDE_TIME_S = 0.5
MAX_SLOPE_DEG = 68.0  # CarSim accepts |slope| < 1.2 rad
SETTLE_S = 0.3  # steady running before a brake


def front_bumper_x_m(car: CarDescription) -> float:
    """Car-frame x of the front bumper (front face of the chassis box), m."""
    return car.chassis.length_m - car.chassis.rear_overhang_m


def _high_traction(car: CarDescription) -> CarDescription:
    wheels = dataclasses.replace(car.wheels, friction_mu=max(car.wheels.friction_mu, HIGH_MU))
    effects = dataclasses.replace(car.effects, friction_scale=1.0)
    return car.replace(wheels=wheels, effects=effects)


def _run(sim, seconds: float) -> None:
    sim.step(max(0, round(seconds / sim.dt_s)))


def window_distance_m(car: CarDescription, speed_mps: float, settle_s: float, window_s: float,
                      dt_s: float = 0.002) -> float:
    """Thesis Fig. 5.5: from rest, command ``speed_mps`` straight ahead, wait ``settle_s``,
    then the distance covered in the next ``window_s``."""
    sim = make_sim(car, dt_s=dt_s)
    sim.set_command(speed_mps, 0.0)
    _run(sim, settle_s)
    p0 = sim.pose
    _run(sim, window_s)
    p1 = sim.pose
    return math.hypot(p1.x_m - p0.x_m, p1.y_m - p0.y_m)


def accel_distance_m(car: CarDescription, speed_mps: float, time_s: float, dt_s: float = 0.002) -> float:
    """Thesis 5.2.2 (a + d of Fig. 5.6): from rest, command ``speed_mps``; distance after
    ``time_s`` (high traction)."""
    sim = make_sim(_high_traction(car), dt_s=dt_s)
    sim.set_command(speed_mps, 0.0)
    _run(sim, time_s)
    return math.hypot(sim.pose.x_m, sim.pose.y_m)


def brake_distance_m(car: CarDescription, speed_mps: float, dt_s: float = 0.002, max_s: float = 10.0) -> float:
    """Thesis 5.2.3 (b of Fig. 5.6): running steadily at ``speed_mps``, command 0; distance
    from the brake command to standstill (high traction)."""
    sim = make_sim(_high_traction(car), dt_s=dt_s)
    sim.set_state(Pose2(), speed_mps)
    sim.set_command(speed_mps, 0.0)
    _run(sim, SETTLE_S)
    p0 = sim.pose
    sim.set_command(0.0, 0.0)
    chunk = max(1, round(0.01 / sim.dt_s))
    t_end = sim.time_s + max_s
    while sim.time_s < t_end:
        sim.step(chunk)
        if abs(sim.speed_mps) < 1e-3:
            break
    p1 = sim.pose
    return math.hypot(p1.x_m - p0.x_m, p1.y_m - p0.y_m)


def turn_radius_m(car: CarDescription, speed_mps: float = 0.5, dt_s: float = 0.002) -> float:
    """Thesis 5.3.1: full left lock at walking pace; radius of the rear-axle centre's circle,
    |v| / yaw rate averaged over 1 s after 1 s of settling. Steering gain, offset and
    understeer are switched off: the test measures the mechanical limit."""
    eff = dataclasses.replace(car.effects, steering_gain=1.0, steering_offset_rad=0.0,
                              tire_slip_understeer_radps2pm=0.0)
    sim = make_sim(car.replace(effects=eff), dt_s=dt_s)
    sim.set_command(speed_mps, car.steering.limit_rad)
    _run(sim, 1.0)
    chunk = max(1, round(0.02 / sim.dt_s))
    v, w = [], []
    for _ in range(50):
        sim.step(chunk)
        v.append(math.hypot(sim.speed_mps, sim.lateral_speed_mps))
        w.append(sim.yaw_rate_radps)
    return float(np.mean(v) / np.mean(w))


def slides(car: CarDescription, slope_rad: float, orientation: str = "downhill", dt_s: float = 0.002) -> bool:
    """Thesis 5.4 tilt test: wheels locked on ground tilted by ``slope_rad``, the car facing
    down the slope (``downhill``) or across it (``sideways``); does it move more than
    ``SLIDE_M`` in ``SLIDE_TIME_S``?"""
    start = Pose2(0.0, 0.0, 0.0 if orientation == "downhill" else 0.5 * math.pi)
    sim = make_sim(car, dt_s=dt_s, start=start, slope_rad=slope_rad)
    sim.set_wheel_lock(True)
    _run(sim, SLIDE_TIME_S)
    p = sim.pose
    return math.hypot(p.x_m - start.x_m, p.y_m - start.y_m) > SLIDE_M


def slip_angle_rad(car: CarDescription, orientation: str = "downhill", dt_s: float = 0.002,
                   tol_rad: float = 1e-3) -> float:
    """Smallest tilt at which the car slides (bisection between 0 and ``MAX_SLOPE_DEG``);
    ``inf`` if it holds at ``MAX_SLOPE_DEG``."""
    lo, hi = 0.0, math.radians(MAX_SLOPE_DEG)
    if not slides(car, hi, orientation, dt_s):
        return math.inf
    while hi - lo > tol_rad:
        mid = 0.5 * (lo + hi)
        if slides(car, mid, orientation, dt_s):
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def built_mass_kg(car: CarDescription) -> float:
    """Total mass of the dartpy skeleton built from ``car``, kg."""
    from simrunner.car.body import build_car_skeleton

    return float(build_car_skeleton(car).skeleton.getMass())


# -- camera (thesis Fig. 5.2) -------------------------------------------------------------
def _camera(car: CarDescription, raster=None):
    from simrunner.sensors.camera import Camera
    from simrunner.track.raster import TrackRaster

    if raster is None:
        img = np.zeros((1, 1), np.uint8)
        raster = TrackRaster(img, img.astype(bool), 1.0, (0.0, 0.0))
    return Camera(car.camera, raster, load_line_kernel=False)  # only render / look_ahead_m


def row_ground_distances_m(car: CarDescription) -> np.ndarray:
    """``(H,)`` distance ahead of the front bumper of the ground seen at the middle of each
    image row (``inf`` at or above the horizon)."""
    cam = _camera(car)
    bumper = front_bumper_x_m(car)
    return np.array([cam.look_ahead_m(r) - bumper for r in range(car.camera.height_px)])


def row_for_distance(car: CarDescription, distance_m: float) -> int:
    """The image row whose ground point is nearest ``distance_m`` ahead of the bumper."""
    d = row_ground_distances_m(car)
    return int(np.argmin(np.where(np.isfinite(d), np.abs(d - distance_m), np.inf)))


def rows_seeing_line(car: CarDescription, distance_m: float, line_width_m: float = 0.025) -> list[int]:
    """Fig. 5.2 as the thesis ran it: a black line across a white floor ``distance_m`` ahead
    of the front bumper; the rows whose middle pixel sees it dark."""
    from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, TrackRaster

    m_per_px = 0.002
    x0, x1, half_w = -0.5, front_bumper_x_m(car) + distance_m + 1.5, 1.5
    w, h = int((x1 - x0) / m_per_px) + 1, int(2 * half_w / m_per_px) + 1
    img = np.full((h, w), WHITE_GRAY, np.uint8)
    xs = x0 + np.arange(w) * m_per_px
    centre = front_bumper_x_m(car) + distance_m
    img[:, np.abs(xs - centre) <= 0.5 * line_width_m] = BLACK_GRAY
    raster = TrackRaster(img, np.ones_like(img, bool), m_per_px, (x0, half_w), floor_gray=WHITE_GRAY)
    camera = _camera(car, raster)
    if car.camera.model == "ideal":
        frame = camera.render(Pose2())
        mid = frame[:, car.camera.width_px // 2].astype(int)
        return [int(r) for r in np.flatnonzero(mid < (WHITE_GRAY + BLACK_GRAY) // 2)]
    from simrunner.sensors.imaging import Imager  # the car's own camera, noiseless, in a 500 lux hall

    frame = Imager(camera).frame(Pose2(), exposure_s=car.camera.exposure_s)
    mid = frame[:, car.camera.width_px // 2].astype(float)
    lo, hi = np.percentile(mid, 5), np.percentile(mid, 95)
    return [int(r) for r in np.flatnonzero(mid < 0.5 * (lo + hi))] if hi - lo > 20 else []
