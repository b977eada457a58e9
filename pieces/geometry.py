"""2D building blocks: exact arcs sampled by sagitta, and bands offset along true normals.

A centreline is given as samples ``points (N, 2)`` metres with exact tangent headings
``headings (N,)`` radians. A band between lateral offsets ``d_right < d_left`` (metres,
positive to the left of travel) is the polygon swept by the normal segment; on an arc its
sides are exact concentric arcs sampled at the same angles, and its end edges lie exactly
on the normals at the first and last sample, i.e. on the port edges. Bands that share an
offset share the very same vertices, so lane and edge-line footprints touch without
overlap.
"""
from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon


MAX_ARC_SEGMENTS = 1000
"""Most chords of one arc: a larger arc than ~100 m radius at the finest tolerance is drawn
with this many chords (its chord error then exceeds the tolerance), so that memory and
time per piece stay bounded whatever the radius."""


def arc_segments(angle_rad: float, max_radius_m: float, tolerance_m: float) -> int:
    """Number of equal chords so that no chord strays more than ``tolerance_m`` (sagitta)
    from an arc of radius ``max_radius_m`` spanning ``angle_rad``; at least 1, at most
    :data:`MAX_ARC_SEGMENTS`."""
    if tolerance_m >= max_radius_m:
        return max(1, math.ceil(abs(angle_rad) / (math.pi / 2)))
    step = 2.0 * math.acos(1.0 - tolerance_m / max_radius_m)
    if not step > 0.0:  # tolerance below the float resolution of the radius
        return MAX_ARC_SEGMENTS
    return min(MAX_ARC_SEGMENTS, max(1, math.ceil(abs(angle_rad) / step - 1e-12)))


def arc_samples(radius_m: float, angle_rad: float, direction: int, n: int,
                start_xy: tuple[float, float] = (0.0, 0.0),
                start_yaw_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``n + 1`` points ``(n+1, 2)`` and headings ``(n+1,)`` along a circular arc that starts
    at ``start_xy`` heading ``start_yaw_rad`` and turns by ``angle_rad`` to the left
    (``direction=+1``) or right (``-1``)."""
    phi = np.linspace(0.0, angle_rad, n + 1)
    # Local arc, start at origin heading +x: (R sin phi, +-R(1 - cos phi)), heading +-phi.
    lx = radius_m * np.sin(phi)
    ly = direction * radius_m * (1.0 - np.cos(phi))
    c, s = math.cos(start_yaw_rad), math.sin(start_yaw_rad)
    pts = np.column_stack([start_xy[0] + c * lx - s * ly, start_xy[1] + s * lx + c * ly])
    return pts, start_yaw_rad + direction * phi


def offset_line(points: np.ndarray, headings: np.ndarray, d_m: float) -> np.ndarray:
    """Points ``(N, 2)`` moved ``d_m`` along the left normal of each heading."""
    return points + d_m * np.column_stack([-np.sin(headings), np.cos(headings)])


def band(points: np.ndarray, headings: np.ndarray, d_right_m: float, d_left_m: float) -> Polygon:
    """Polygon between the offset lines at ``d_right_m`` and ``d_left_m`` (``d_right_m <
    d_left_m``), closed by the normal segments at both ends."""
    left = offset_line(points, headings, d_left_m)
    right = offset_line(points, headings, d_right_m)
    return Polygon(np.vstack([right, left[::-1]]))


def rect(x0: float, y0: float, x1: float, y1: float) -> Polygon:
    """Axis-aligned rectangle ``[x0, x1] x [y0, y1]``."""
    return shapely.box(x0, y0, x1, y1)


def road_bands(points: np.ndarray, headings: np.ndarray, lane_width_m: float,
               edge_width_m: float) -> tuple[Polygon, shapely.MultiPolygon]:
    """Lane band and the two edge-line bands (one MultiPolygon) along a centreline."""
    h = lane_width_m / 2.0
    lane = band(points, headings, -h, h)
    left = band(points, headings, h, h + edge_width_m)
    right = band(points, headings, -h - edge_width_m, -h)
    return lane, shapely.MultiPolygon([right, left])
