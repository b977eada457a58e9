"""A free floor: ``simrunner drive --track floor`` (open-loop tests such as the thesis's
velocity test, Fig. 5.5, examples/velocity_test.py).

An empty floor with nothing painted on it: the camera sees the floor's gray everywhere, the
car starts at the origin heading +x on the flat ground the simulator always has, and the run
is not judged (no laps, no off track): it ends at the time limit or when ``main`` returns.
The raster covers ``FLOOR_SIZE_M`` around the origin (the debug video's and the plot's
top-down view); the car may drive past it (the floor goes on).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from simrunner.track.load import SimTrack
from simrunner.track.raster import FLOOR_GRAY, TrackRaster

FLOOR_NAME = "floor"
FLOOR_SIZE_M = 6.0
FLOOR_M_PER_PX = 0.05


def floor_track(size_m: float = FLOOR_SIZE_M, m_per_px: float = FLOOR_M_PER_PX) -> SimTrack:
    """The free floor: a ``SimTrack`` with ``judged`` False (see the module docstring)."""
    n = int(round(size_m / m_per_px)) + 1
    image = np.full((n, n), FLOOR_GRAY, dtype=np.uint8)
    road = np.ones((n, n), dtype=bool)  # everywhere is drivable: nothing is off the track
    image.flags.writeable = False
    road.flags.writeable = False
    half = (n - 1) * m_per_px / 2.0
    raster = TrackRaster(image=image, road_mask=road, m_per_px=m_per_px, origin_xy_m=(-half, half))
    return SimTrack(name=FLOOR_NAME, source=Path(FLOOR_NAME), raster=raster, surface_z_m=0.0,
                    start=Pose2(), gate=Pose2(), gate_half_width_m=half, lap_length_m=size_m,
                    judged=False)
