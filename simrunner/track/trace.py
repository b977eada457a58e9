"""The middle of the road traced on the raster, for worlds that carry no centreline (NXP's
Gazebo tracks): :class:`RidgeWalker` and :func:`trace_loop`.

The middle is the ridge of the road's distance transform (distance of each road pixel to the
nearest non-road pixel). A walker moves one step along its heading, then to the largest
distance on a short segment across the heading (the ridge); its heading follows the path,
smoothed. At a crossing the ridge is flat across the whole crossing, so the walker keeps the
offset nearest its own line and goes straight on (the only way through a crossing the
official pieces link, rules summary section 3, "Intersections").
"""
from __future__ import annotations

import math

import numpy as np

from pieces.pose import Pose2
from simrunner.track.raster import TrackRaster

TRACE_STEP_M = 0.01
LOOP_POINT_SPACING_M = 0.05   # the traced loop keeps one point every 5 cm
LOOP_MIN_LENGTH_M = 1.0       # a loop shorter than this is not a track


class RidgeWalker:
    """Walks the ridge of ``raster``'s road from ``(x_m, y_m)`` heading ``yaw_rad``;
    ``half_search_m``: how far across the heading each step looks for the ridge."""

    def __init__(self, raster: TrackRaster, x_m: float, y_m: float, yaw_rad: float,
                 half_search_m: float):
        import cv2

        self.raster = raster
        self._dist = cv2.distanceTransform(np.asarray(raster.road_mask, dtype=np.uint8), cv2.DIST_L2, 5)
        self._h_px, self._w_px = self._dist.shape
        half = max(half_search_m, 2 * raster.m_per_px)
        self._offsets = np.linspace(-half, half, 2 * int(half / raster.m_per_px) + 1)
        self.x_m, self.y_m = x_m, y_m
        self.dx, self.dy = math.cos(yaw_rad), math.sin(yaw_rad)

    def _depth(self, points: np.ndarray) -> np.ndarray:
        px = np.rint(self.raster.world_to_px(points)).astype(np.int64)
        inside = (px[:, 0] >= 0) & (px[:, 0] < self._w_px) & (px[:, 1] >= 0) & (px[:, 1] < self._h_px)
        out = np.zeros(len(px))
        out[inside] = self._dist[px[inside, 1], px[inside, 0]]
        return out

    def step(self, h_m: float) -> bool:
        """One step of ``h_m`` metres; False when the walker is off the road (no ridge)."""
        x, y, dx, dy, offsets = self.x_m, self.y_m, self.dx, self.dy, self._offsets
        nx, ny = x + h_m * dx, y + h_m * dy
        across = np.column_stack((nx - offsets * dy, ny + offsets * dx))
        d = self._depth(across)
        best = np.flatnonzero(d >= d.max() - 0.5)  # the ridge (flat at a crossing: its middle)
        k = int(best[np.argmin(np.abs(offsets[best]))]) if d.max() > 0 else len(offsets) // 2
        nx, ny = float(across[k, 0]), float(across[k, 1])
        ndx, ndy = nx - x, ny - y
        n = math.hypot(ndx, ndy)
        if n > 0:  # the heading follows the path, smoothed
            dx, dy = 0.8 * dx + 0.2 * ndx / n, 0.8 * dy + 0.2 * ndy / n
            m = math.hypot(dx, dy)
            self.dx, self.dy = dx / m, dy / m
        self.x_m, self.y_m = nx, ny
        return bool(d.max() > 0)


def trace_loop(raster: TrackRaster, start: Pose2, road_width_m: float, *,
               max_length_m: float, step_m: float = TRACE_STEP_M) -> np.ndarray | None:
    """The road's middle as a closed loop from ``start`` (on the road, heading the driving
    direction) back to it: ``(N, 2)`` world metres in driving order, one point every
    ``LOOP_POINT_SPACING_M`` (the first: ``start``'s position), the closing point not
    repeated. None when the walk leaves the road or does not come back within
    ``max_length_m`` (a road that is no loop: a dead end, a junction the walk cannot pass).

    ``road_width_m``: the road's width at the start (each step looks a quarter of it to each
    side for the ridge).
    The loop closes when the walk crosses the start's lateral line again, near the start
    (within a quarter of the road width), heading forwards, after at least
    ``LOOP_MIN_LENGTH_M``."""
    walker = RidgeWalker(raster, start.x_m, start.y_m, start.yaw_rad, 0.25 * road_width_m)
    cx, cy = math.cos(start.yaw_rad), math.sin(start.yaw_rad)
    keep_every = max(1, int(round(LOOP_POINT_SPACING_M / step_m)))
    points = []
    travelled, k = 0.0, 0
    along_prev = 0.0
    while travelled < max_length_m:
        if k % keep_every == 0:
            points.append((walker.x_m, walker.y_m))
        if not walker.step(step_m):
            return None
        travelled += step_m
        k += 1
        rx, ry = walker.x_m - start.x_m, walker.y_m - start.y_m
        along, across = rx * cx + ry * cy, -rx * cy + ry * cx
        if (travelled > LOOP_MIN_LENGTH_M and along_prev < 0.0 <= along
                and abs(across) < 0.25 * road_width_m and walker.dx * cx + walker.dy * cy > 0.5):
            return np.asarray(points, dtype=float)
        along_prev = along
    return None
