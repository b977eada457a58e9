"""Range sensors (ultrasonic, infrared, time-of-flight): the distance to the nearest object
standing on the track, as the car file's ``[range_sensors.NAME]`` describes the sensor
(:class:`vehicle.description.RangeSensor`).

A sensor sits at ``(x_m, y_m, z_m)`` in the car body frame and looks along ``yaw_rad``; its
cone is ``rays`` horizontal rays spread evenly over ``fov_rad`` (one ray along the axis when
``rays`` is 1). A reading is the nearest hit of any ray on a solid
(:func:`simrunner.sensors.solids.cast`), below ``min_range_m`` read as ``min_range_m``, plus
Gaussian noise of ``noise_std_m``; nothing within ``max_range_m`` reads ``inf``. The floor and
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

    def read(self, name: str, t_s: float, pose, solids, surface_z_m: float) -> float:
        """The reading (m, or inf) of sensor ``name`` at time ``t_s`` of a car at ``pose``."""
        got = self._sensors.get(name)
        if got is None:
            known = ", ".join(self._sensors) or "none: add [range_sensors.NAME] to the car file"
            raise CommandError(f"get_distance({name!r}): no such range sensor (the car's: {known})")
        _, spec = got
        tick = math.floor(t_s * spec.rate_hz + 1e-9)
        held = self._held.get(name)
        if held is not None and held[0] == tick:
            return held[1]
        value = self._measure(name, spec, pose, solids, surface_z_m)
        self._held[name] = (tick, value)
        return value

    def _measure(self, name: str, spec, pose, solids, surface_z_m: float) -> float:
        noise = float(self._rng[name].standard_normal())  # one draw per reading, hit or not
        if not solids:
            return math.inf
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        origin = (pose.x_m + c * spec.x_m - s * spec.y_m, pose.y_m + s * spec.x_m + c * spec.y_m,
                  surface_z_m + spec.z_m)
        n = int(spec.rays)
        angles = np.array([0.0]) if n == 1 else np.linspace(-0.5 * spec.fov_rad, 0.5 * spec.fov_rad, n)
        heading = pose.yaw_rad + spec.yaw_rad + angles
        t, _, _ = cast(solids, surface_z_m, origin, np.cos(heading), np.sin(heading), np.zeros(n))
        d = float(t.min())
        if not d <= spec.max_range_m:
            return math.inf
        return max(d, spec.min_range_m) + spec.noise_std_m * noise
