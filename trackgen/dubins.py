"""Shortest turn-straight-turn paths between two poses (Dubins CSC words), for closing a
random layout exactly (:mod:`trackgen.random`).

A path is three segments: an arc of ``radius_m`` turning left (``+1``) or right (``-1``) by
``arc1_rad`` (in [0, 2 pi)), a straight of ``straight_m`` (>= 0) and a second arc. Only the
four CSC words (LSL, RSR, LSR, RSL) are produced; the CCC words are not needed here (a
caller that finds no usable word draws another layout). Frames as in :mod:`pieces.pose`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pieces.pose import Pose2

TWO_PI = 2.0 * math.pi


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


def _mod(angle_rad: float) -> float:
    a = math.fmod(angle_rad, TWO_PI)
    return a + TWO_PI if a < 0.0 else a


def _centre(pose: Pose2, turn: int, radius_m: float) -> tuple[float, float]:
    """Centre of the circle of radius ``radius_m`` the car at ``pose`` turns around."""
    return (pose.x_m - turn * radius_m * math.sin(pose.yaw_rad),
            pose.y_m + turn * radius_m * math.cos(pose.yaw_rad))


def csc_paths(start: Pose2, goal: Pose2, radius_m: float) -> list[CscPath]:
    """Every feasible CSC path from ``start`` to ``goal``, shortest first."""
    out = []
    for t1 in (1, -1):
        for t2 in (1, -1):
            c0x, c0y = _centre(start, t1, radius_m)
            c1x, c1y = _centre(goal, t2, radius_m)
            vx, vy = c1x - c0x, c1y - c0y
            dist = math.hypot(vx, vy)
            theta = math.atan2(vy, vx)
            if t1 == t2:
                phi, straight = theta, dist
            else:
                if dist < 2.0 * radius_m:
                    continue
                straight = math.sqrt(max(dist * dist - 4.0 * radius_m * radius_m, 0.0))
                # left then right: v = straight * dir(phi) + 2 r * right(phi), and mirrored
                phi = theta + t1 * math.atan2(2.0 * radius_m, straight)
            arc1 = _mod(t1 * (phi - start.yaw_rad))
            arc2 = _mod(t2 * (goal.yaw_rad - phi))
            out.append(CscPath(t1, arc1, straight, t2, arc2, radius_m))
    return sorted(out, key=lambda p: p.length_m)
