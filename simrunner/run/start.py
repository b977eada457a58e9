"""Where the car starts: the track's start pose, a given pose, or a distance before the
finish line (``--start X,Y,YAW``, ``--start-before-finish METRES``; docs/drive.md).

``start_before_finish_m = d`` (thesis 5.1.2, Fig. 5.1/5.2: the car moved back from the finish
line by the distance the camera should look ahead): the car stands on the track's centre,
heading along it in the driving direction, with its front bumper ``d`` metres before the
finish line measured along the centre. The front bumper is ``chassis.length_m -
chassis.rear_overhang_m`` ahead of the car frame (rear-axle midpoint), so the car frame is
``d + that`` before the line. The centre is the track's centreline (layouts, trackgen
folders); for a world without one (NXP's Gazebo tracks) the road's centre is traced back
from the finish line on the raster (:func:`trace_back`: middle of the road across the
heading, every 1 cm; crossings are passed straight).

Every start on a track is checked: the four wheels' contact points must be on the road (a
free floor has no edge: any pose goes).
"""
from __future__ import annotations

import math

import numpy as np

from pieces.pose import Pose2
from simrunner.run.settings import RunSettings, SettingsError
from simrunner.track.load import SimTrack, road_extents_m
from simrunner.track.trace import TRACE_STEP_M, RidgeWalker


def start_pose(track: SimTrack, car, settings: RunSettings) -> Pose2:
    """The car's start pose for ``settings`` on ``track`` (``car``: a ``CarDescription``);
    :class:`SettingsError` when it cannot be placed or a wheel would be off the road."""
    if settings.start is not None:
        pose, what = Pose2(*settings.start), "start"
    elif settings.start_before_finish_m is not None:
        if not track.judged:
            raise SettingsError("start_before_finish_m: the free floor has no finish line "
                                "(give a start pose instead)")
        d = settings.start_before_finish_m
        back = d + car.chassis.length_m - car.chassis.rear_overhang_m
        if track.centreline is not None and len(track.centreline) >= 2:
            pose = along_centreline(track.centreline, track.gate, back)
        else:
            pose = trace_back(track, back)
        what = f"start_before_finish_m = {d:g}"
    else:
        return track.start
    if track.judged:  # a free floor has no road edge
        check_on_road(track, car, pose, what)
    return pose


def wheel_points(car, pose: Pose2) -> np.ndarray:
    """``(4, 2)`` world contact points of the wheels (FL, FR, RL, RR) at ``pose``."""
    L, half = car.chassis.wheelbase_m, car.chassis.track_m / 2.0
    return pose.apply(np.array([[L, half], [L, -half], [0.0, half], [0.0, -half]]))


def check_on_road(track: SimTrack, car, pose: Pose2, what: str) -> None:
    on = track.raster.on_road(wheel_points(car, pose))
    if not on.all():
        raise SettingsError(
            f"{what}: the car at ({pose.x_m:.3f} m, {pose.y_m:.3f} m, "
            f"{math.degrees(pose.yaw_rad):.1f} deg) would have wheel(s) "
            f"{', '.join(n for n, ok in zip(('FL', 'FR', 'RL', 'RR'), on) if not ok)} off the road "
            f"of {track.name}")


def along_centreline(centre: np.ndarray, gate: Pose2, back_m: float) -> Pose2:
    """The pose ``back_m`` before ``gate`` along the closed polyline ``centre`` (driving
    order), heading along it."""
    pts = np.asarray(centre, dtype=float)
    if np.allclose(pts[0], pts[-1]):
        pts = pts[:-1]
    seg = np.roll(pts, -1, axis=0) - pts
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 1e-12
    pts, seg, length = pts[keep], seg[keep], length[keep]
    cum = np.concatenate(([0.0], np.cumsum(length)))
    total = float(cum[-1])
    g = np.array([gate.x_m, gate.y_m])
    t = np.clip(np.einsum("ij,ij->i", g - pts, seg) / length ** 2, 0.0, 1.0)
    near = pts + t[:, None] * seg
    i = int(np.argmin(np.hypot(*(near - g).T)))
    heading = np.array([math.cos(gate.yaw_rad), math.sin(gate.yaw_rad)])
    sign = 1.0 if float(seg[i] @ heading) >= 0.0 else -1.0  # polyline against the gate: walk it back
    s_gate = float(cum[i] + t[i] * length[i])
    s = (s_gate - sign * back_m) % total
    j = min(int(np.searchsorted(cum, s, side="right")) - 1, len(pts) - 1)
    f = (s - cum[j]) / length[j]
    p = pts[j] + f * seg[j]
    yaw = math.atan2(sign * seg[j][1], sign * seg[j][0])
    return Pose2(float(p[0]), float(p[1]), yaw)


def trace_back(track: SimTrack, back_m: float, step_m: float = TRACE_STEP_M) -> Pose2:
    """Walk ``back_m`` backwards along the road from the finish line on the raster, keeping
    to the middle of the road (:class:`simrunner.track.trace.RidgeWalker`: every step moves
    ``step_m`` along the heading, then to the ridge of the road's distance transform across
    it; straight on at a crossing); the pose heads forwards."""
    raster, gate = track.raster, track.gate
    left, right = road_extents_m(raster, gate)
    walker = RidgeWalker(raster, gate.x_m, gate.y_m, gate.yaw_rad + math.pi, 0.25 * (left + right))
    travelled = 0.0
    while travelled < back_m - 1e-12:
        h = min(step_m, back_m - travelled)
        walker.step(h)
        travelled += h
    return Pose2(walker.x_m, walker.y_m, math.atan2(walker.dy, walker.dx) + math.pi)
