"""Dubins paths: the shortest paths between two poses of a car that turns no tighter than a
radius (L. E. Dubins, 1957; the closed forms of Shkel and Lumelsky, 2001). One solver, used
to close random layouts exactly (:mod:`trackgen.random`, :func:`csc_paths`) and by the
excitation planner's turns (:mod:`simrunner.workflows.excite`, vectorised over goals).

A path is three segments of the word's letters: ``L`` an arc turning left, ``R`` right,
``S`` a straight. :func:`dubins_segments` gives all six words (CSC: LSL, RSR, LSR, RSL; CCC:
RLR, LRL) for arrays of goals; :func:`csc_paths` the feasible CSC words between two poses as
:class:`CscPath` (a caller that finds no usable one draws another layout). Frames as in
:mod:`pieces.pose` (x forward, y left, yaw counter-clockwise, radians).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pieces.pose import Pose2

TWO_PI = 2.0 * math.pi
WORDS = ("LSL", "RSR", "LSR", "RSL", "RLR", "LRL")
"""The words of :func:`dubins_segments`, in the order of its first axis."""
TURN_SIGN = {"L": 1.0, "S": 0.0, "R": -1.0}
"""Turn direction of each letter (+1 left, -1 right, 0 straight)."""


def dubins_segments(x0, y0, yaw0, x1, y1, yaw1, radius_m: float) -> np.ndarray:
    """``(6, C, 3)``: the three segment lengths (in radii: arc angles in radians, straight
    lengths over ``radius_m``) of each :data:`WORDS` path of radius ``radius_m`` from the
    pose ``(x0, y0, yaw0)`` to the poses ``(x1, y1, yaw1)`` (arrays ``(C,)``); NaN where a
    word has no path. Arc angles are in ``[0, 2 pi)``."""
    tau = TWO_PI
    dx, dy = (np.asarray(x1) - x0) / radius_m, (np.asarray(y1) - y0) / radius_m
    d, phi = np.hypot(dx, dy), np.arctan2(dy, dx)
    a, b = np.mod(yaw0 - phi, tau), np.mod(yaw1 - phi, tau)
    sa, sb, ca, cb, cab = np.sin(a), np.sin(b), np.cos(a), np.cos(b), np.cos(a - b)
    out = np.full((6,) + d.shape + (3,), np.nan)
    with np.errstate(invalid="ignore"):
        # LSL and RSR always exist (p^2 is the circles' squared distance): rounding below 0 is 0
        at, p = np.arctan2(cb - ca, d + sa - sb), np.sqrt(np.maximum(2 + d * d - 2 * cab + 2 * d * (sa - sb), 0.0))
        out[0] = np.stack([np.mod(at - a, tau), p, np.mod(b - at, tau)], -1)
        at, p = np.arctan2(ca - cb, d - sa + sb), np.sqrt(np.maximum(2 + d * d - 2 * cab + 2 * d * (sb - sa), 0.0))
        out[1] = np.stack([np.mod(a - at, tau), p, np.mod(at - b, tau)], -1)
        p = np.sqrt(-2 + d * d + 2 * cab + 2 * d * (sa + sb))  # LSR
        at = np.arctan2(-ca - cb, d + sa + sb) - np.arctan2(-2.0, p)
        out[2] = np.stack([np.mod(at - a, tau), p, np.mod(at - b, tau)], -1)
        p = np.sqrt(d * d - 2 + 2 * cab - 2 * d * (sa + sb))  # RSL
        at = np.arctan2(ca + cb, d - sa - sb) - np.arctan2(2.0, p)
        out[3] = np.stack([np.mod(a - at, tau), p, np.mod(b - at, tau)], -1)
        p = np.mod(tau - np.arccos((6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8), tau)  # RLR
        t = np.mod(a - np.arctan2(ca - cb, d - sa + sb) + p / 2, tau)
        out[4] = np.stack([t, p, np.mod(a - b - t + p, tau)], -1)
        p = np.mod(tau - np.arccos((6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8), tau)  # LRL
        t = np.mod(-a - np.arctan2(ca - cb, d + sa - sb) + p / 2, tau)
        out[5] = np.stack([t, p, np.mod(b - a - t + p, tau)], -1)
    return out


def dubins_points(x0: float, y0: float, yaw0: float, segs: np.ndarray, radius_m: float, n: int = 8) -> np.ndarray:
    """``(6, C, 3 n, 2)``: ``n`` points along each segment of the paths ``segs`` of
    :func:`dubins_segments` from one pose."""
    shape = segs.shape[:2]
    x, y, yaw = np.full(shape, x0), np.full(shape, y0), np.full(shape, yaw0)
    frac = np.arange(1, n + 1) / n
    out = []
    for j in range(3):
        sign = np.array([TURN_SIGN[w[j]] for w in WORDS])[:, None, None]
        ang = segs[:, :, j, None] * frac  # (6, C, n)
        th = yaw[..., None] + sign * ang
        arc_x = x[..., None] + sign * radius_m * (np.sin(th) - np.sin(yaw)[..., None])
        arc_y = y[..., None] - sign * radius_m * (np.cos(th) - np.cos(yaw)[..., None])
        line_x = x[..., None] + radius_m * ang * np.cos(yaw)[..., None]
        line_y = y[..., None] + radius_m * ang * np.sin(yaw)[..., None]
        px, py = np.where(sign == 0.0, line_x, arc_x), np.where(sign == 0.0, line_y, arc_y)
        out.append(np.stack([px, py], -1))
        x, y, yaw = px[..., -1], py[..., -1], th[..., -1]
    return np.concatenate(out, axis=2)


@dataclass(frozen=True)
class CscPath:
    """One CSC path: turn ``turn1`` (+1 left, -1 right) by ``arc1_rad``, straight
    ``straight_m``, turn ``turn2`` by ``arc2_rad``; all arcs of ``radius_m``."""

    turn1: int
    arc1_rad: float
    straight_m: float
    turn2: int
    arc2_rad: float
    radius_m: float

    @property
    def length_m(self) -> float:
        return self.radius_m * (self.arc1_rad + self.arc2_rad) + self.straight_m


def csc_paths(start: Pose2, goal: Pose2, radius_m: float) -> list[CscPath]:
    """Every feasible CSC path from ``start`` to ``goal`` (:func:`dubins_segments`), shortest
    first (ties in the order LSL, LSR, RSL, RSR)."""
    segs = dubins_segments(start.x_m, start.y_m, start.yaw_rad, np.array([goal.x_m]), np.array([goal.y_m]),
                           np.array([goal.yaw_rad]), radius_m)[:, 0]
    out = []
    for word in ("LSL", "LSR", "RSL", "RSR"):
        arc1, straight, arc2 = (float(v) for v in segs[WORDS.index(word)])
        if math.isnan(straight):
            continue
        out.append(CscPath(int(TURN_SIGN[word[0]]), arc1, straight * radius_m, int(TURN_SIGN[word[2]]), arc2,
                           radius_m))
    return sorted(out, key=lambda p: p.length_m)
