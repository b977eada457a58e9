"""Range sensors (ultrasonic, infrared, time-of-flight, planar lidar): the distance to the
nearest object standing on the track, as the car file's ``[range_sensors.NAME]`` describes the
sensor (:class:`vehicle.description.RangeSensor`).

A sensor sits at ``(x_m, y_m, z_m)`` in the car body frame and looks along ``yaw_rad``; its
cone is ``rays`` horizontal rays spread evenly over ``fov_rad`` from its right edge to its left
(one ray along the axis when ``rays`` is 1; a full turn, ``fov_rad`` >= 2 pi, has no ray twice:
``2 pi k / rays`` from straight behind). A reading is the nearest hit of any ray on a solid
(:func:`simrunner.sensors.solids.cast`), below ``min_range_m`` read as ``min_range_m``, plus
Gaussian noise of ``noise_std_m``; nothing within ``max_range_m`` reads ``inf``. A ``lidar``
reads every ray so (:meth:`RangeSensors.scan`, each ray its own noise; its ``get_distance`` is
the scan's nearest reading); its rays are taken all at once at the tick (a rotating scanner
sweeps them over its period: at the rules' speeds the car moves a few centimetres meanwhile). The floor and
the track are not seen (the sensor is taken as mounted to look over them). A sensor measures
at ``rate_hz``: the reading of the last tick ``floor(t rate) / rate`` is held until the next
one, so asking twice in a tick gives the same value. Each sensor draws its noise from its own
generator, seeded from the run's seed and the sensor's place in the car file: the camera's
noise stream is not touched.
"""
from __future__ import annotations

import math

import numpy as np

from simrunner.errors import CommandError
from simrunner.sensors.solids import cast


class RangeSensors:
    """The range sensors of one run (``sensors``: the car file's ``(name, RangeSensor)``)."""

    def __init__(self, sensors, seed: int):
        self._sensors = {name: (i, spec) for i, (name, spec) in enumerate(sensors)}
        self._rng = {name: np.random.default_rng([int(seed), 0x52414E47, i])
                     for name, (i, _) in self._sensors.items()}
        self._held: dict[str, tuple[int, float]] = {}

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._sensors)

    def _spec(self, name: str, call: str):
        got = self._sensors.get(name)
        if got is None:
            known = ", ".join(self._sensors) or "none: add [range_sensors.NAME] to the car file"
            raise CommandError(f"{call}({name!r}): no such range sensor (the car's: {known})")
        return got[1]

    def read(self, name: str, t_s: float, pose, solids, surface_z_m: float) -> float:
        """The reading (m, or inf) of sensor ``name`` at time ``t_s`` of a car at ``pose`` (a
        lidar: its scan's nearest reading)."""
        spec = self._spec(name, "get_distance")
        if spec.kind == "lidar":
            return float(self.scan(name, t_s, pose, solids, surface_z_m).min())
        return self._held_value(name, spec, t_s, lambda: self._measure(name, spec, pose, solids, surface_z_m))

    def scan(self, name: str, t_s: float, pose, solids, surface_z_m: float) -> np.ndarray:
        """Every ray's reading ``(rays,)`` (m, or inf) of lidar ``name`` at ``t_s``, in the order of
        :meth:`angles` (a copy)."""
        spec = self._spec(name, "get_scan")
        if spec.kind != "lidar":
            raise CommandError(f"get_scan({name!r}): a {spec.kind} sensor gives one reading "
                               f"(get_distance); get_scan is for kind = \"lidar\"")
        return self._held_value(name, spec, t_s, lambda: self._scan(name, spec, pose, solids, surface_z_m)).copy()

    def angles(self, name: str) -> np.ndarray:
        """The directions of sensor ``name``'s rays, rad in the car frame (+ = left of ahead)."""
        spec = self._spec(name, "scan_angles")
        return spec.yaw_rad + ray_angles(spec)

    def _held_value(self, name: str, spec, t_s: float, measure):
        tick = math.floor(t_s * spec.rate_hz + 1e-9)
        held = self._held.get(name)
        if held is not None and held[0] == tick:
            return held[1]
        value = measure()
        self._held[name] = (tick, value)
        return value

    def _rays(self, spec, pose, solids, surface_z_m: float) -> np.ndarray:
        """Distance (m) along each ray to the nearest solid (inf: none)."""
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        origin = (pose.x_m + c * spec.x_m - s * spec.y_m, pose.y_m + s * spec.x_m + c * spec.y_m,
                  surface_z_m + spec.z_m)
        heading = pose.yaw_rad + spec.yaw_rad + ray_angles(spec)
        t, _, _ = cast(solids, surface_z_m, origin, np.cos(heading), np.sin(heading), np.zeros(len(heading)))
        return t

    def _measure(self, name: str, spec, pose, solids, surface_z_m: float) -> float:
        noise = float(self._rng[name].standard_normal())  # one draw per reading, hit or not
        if not solids:
            return math.inf
        d = float(self._rays(spec, pose, solids, surface_z_m).min())
        if not d <= spec.max_range_m:
            return math.inf
        return max(d, spec.min_range_m) + spec.noise_std_m * noise

    def _scan(self, name: str, spec, pose, solids, surface_z_m: float) -> np.ndarray:
        noise = self._rng[name].standard_normal(int(spec.rays))  # one draw per ray, hit or not
        if not solids:
            return np.full(int(spec.rays), math.inf)
        d = self._rays(spec, pose, solids, surface_z_m)
        out = np.maximum(d, spec.min_range_m) + spec.noise_std_m * noise
        out[~(d <= spec.max_range_m)] = math.inf
        return out


def ray_angles(spec) -> np.ndarray:
    """The rays' directions relative to the sensor's axis (rad): ``rays`` spread evenly over
    ``fov_rad`` from right to left, one along the axis for a single ray, a full turn
    (``fov_rad`` >= 2 pi) without a ray twice."""
    n = int(spec.rays)
    if n == 1:
        return np.array([0.0])
    if spec.fov_rad >= 2.0 * math.pi - 1e-4:
        return -math.pi + 2.0 * math.pi * np.arange(n) / n
    return np.linspace(-0.5 * spec.fov_rad, 0.5 * spec.fov_rad, n)
