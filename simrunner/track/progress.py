"""Progress along a track's centreline: arc length ``s_m`` of the car's nearest centreline
point, followed from step to step (no Gymnasium, no physics).

The centreline is the closed polyline of ``SimTrack.centreline`` ``(N, 2)`` in driving
order (the last point joins the first). A point is projected onto the segments within
``window_m`` of arc length around the segment found last time, never onto the whole loop:
where a figure-8 crosses itself the other branch is far away along the loop, so the
projection stays on the branch being driven. ``advance`` returns the signed arc length moved
since the previous call, wrapped into ``(-L/2, L/2]`` (``L`` = loop length): forward is
positive, driving backwards gives negative progress, and crossing the loop's seam (the start)
is no jump.
"""
from __future__ import annotations

import math

import numpy as np

from simrunner.errors import SimError


class CentrelineProgress:
    """Follows the arc length ``s_m`` of a point moving along ``centreline`` ``(N, 2)``."""

    def __init__(self, centreline: np.ndarray, *, window_m: float = 0.4):
        pts = np.asarray(centreline, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
            raise SimError(f"centreline: expected an (N >= 3, 2) array of finite metres, got shape {pts.shape}")
        if np.hypot(*(pts[-1] - pts[0])) < 1e-9:  # already closed: drop the repeated point
            pts = pts[:-1]
        d = np.roll(pts, -1, axis=0) - pts  # segment i: a[i] -> a[i + 1] (mod N)
        lengths = np.hypot(d[:, 0], d[:, 1])
        if np.any(lengths <= 0.0):
            raise SimError("centreline: two consecutive points coincide")
        s0 = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))  # arc length at a[i]
        self.length_m = float(lengths.sum())
        n = self._n = len(pts)
        # per segment, as plain floats (a step projects onto a dozen segments: Python floats
        # are faster than numpy calls on arrays that small): ax, ay, dx, dy, 1/len^2, len, s0
        self._segs = [tuple(float(v) for v in row) for row in
                      np.column_stack((pts, d, 1.0 / lengths**2, lengths, s0))]
        # the segments searched after segment i: those within window_m of arc length of it
        # (at least one on each side)
        self._windows: list[tuple[int, ...]] = []
        for i in range(n):
            idx = [i]
            for step in (1, -1):
                j, dist = i, 0.0
                while len(idx) < n:
                    j = (j + step) % n
                    idx.append(j)
                    dist += float(lengths[j])
                    if dist >= window_m:
                        break
            self._windows.append(tuple(dict.fromkeys(idx)))
        self._seg = 0
        self.s_m = 0.0
        self.lateral_m = 0.0

    def point_at(self, s_m: float) -> tuple[float, float, float]:
        """The centreline point at arc length ``s_m`` (taken modulo the loop length) and the
        driving direction there: ``(x_m, y_m, heading_rad)`` (heading of its segment)."""
        s = float(s_m) % self.length_m
        for ax, ay, dx, dy, _, length, s0 in self._segs:
            if s < s0 + length:
                t = (s - s0) / length
                return ax + t * dx, ay + t * dy, math.atan2(dy, dx)
        ax, ay, dx, dy = self._segs[-1][:4]   # s rounded up to the loop length: its end
        return ax + dx, ay + dy, math.atan2(dy, dx)

    def reset(self, x_m: float, y_m: float) -> None:
        """Start following at ``(x_m, y_m)``: projected onto the whole loop (nearest segment)."""
        self._seg, self.s_m, self.lateral_m = self._project(range(self._n), x_m, y_m)

    def advance(self, x_m: float, y_m: float) -> float:
        """Move to ``(x_m, y_m)``; returns the signed arc length (m) moved along the loop."""
        self._seg, s, self.lateral_m = self._project(self._windows[self._seg], x_m, y_m)
        ds = s - self.s_m
        half = 0.5 * self.length_m
        if ds > half:
            ds -= self.length_m
        elif ds <= -half:
            ds += self.length_m
        self.s_m = s
        return ds

    def _project(self, idx, x_m: float, y_m: float) -> tuple[int, float, float]:
        """Nearest point on the segments ``idx``: (segment, arc length, signed lateral offset
        in m, + = left of the driving direction)."""
        segs = self._segs
        best = math.inf
        found = (0, 0.0, 0.0)
        for i in idx:
            ax, ay, dx, dy, inv2, length, s0 = segs[i]
            rx, ry = x_m - ax, y_m - ay
            t = (rx * dx + ry * dy) * inv2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            ex, ey = rx - t * dx, ry - t * dy
            e2 = ex * ex + ey * ey
            if e2 < best:
                best = e2
                found = (i, s0 + t * length, (dx * ry - dy * rx) / length)
        i, s, lat = found
        return i, (s if s < self.length_m else s - self.length_m), lat
