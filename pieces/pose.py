"""SE(2) poses: the one placement type of the project.

Frame convention (documented once, used everywhere): the world is right-handed with
x forward/east, y left/north, z up; yaw is measured counter-clockwise from +x, in radians,
normalised to [-pi, pi). A pose ``P`` maps points from its local frame into its parent
frame: ``P.apply(p_local) == p_parent``. Composition ``A @ B`` is "B expressed in A's
frame", so a piece placed at ``world_from_piece`` has its exit in the world at
``world_from_piece @ piece.ports["exit"]``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle into [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class Pose2:
    """Immutable planar pose: position in metres, heading in radians."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_m", float(self.x_m))
        object.__setattr__(self, "y_m", float(self.y_m))
        object.__setattr__(self, "yaw_rad", wrap_angle(float(self.yaw_rad)))

    def __matmul__(self, other: "Pose2") -> "Pose2":
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return Pose2(
            self.x_m + c * other.x_m - s * other.y_m,
            self.y_m + s * other.x_m + c * other.y_m,
            self.yaw_rad + other.yaw_rad,
        )

    def inverse(self) -> "Pose2":
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return Pose2(-c * self.x_m - s * self.y_m, s * self.x_m - c * self.y_m, -self.yaw_rad)

    def apply(self, points_m: np.ndarray) -> np.ndarray:
        """Map local points ``(N, 2)`` into the parent frame; returns ``(N, 2)`` float."""
        pts = np.asarray(points_m, dtype=float).reshape(-1, 2)
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        rot = np.array([[c, -s], [s, c]])
        return pts @ rot.T + np.array([self.x_m, self.y_m])

    def as_matrix(self) -> np.ndarray:
        """Homogeneous ``(3, 3)`` matrix."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.array([[c, -s, self.x_m], [s, c, self.y_m], [0.0, 0.0, 1.0]])

    def as_affine2d(self) -> np.ndarray:
        """``(2, 3)`` affine matrix (for manifold3d CrossSection.transform)."""
        return self.as_matrix()[:2, :]

    def as_shapely_affine(self) -> list[float]:
        """``[a, b, d, e, xoff, yoff]`` for ``shapely.affinity.affine_transform``."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return [c, -s, s, c, self.x_m, self.y_m]

    def distance_to(self, other: "Pose2") -> tuple[float, float]:
        """Position error (m) and absolute heading error (rad) between two poses."""
        return (
            math.hypot(self.x_m - other.x_m, self.y_m - other.y_m),
            abs(wrap_angle(self.yaw_rad - other.yaw_rad)),
        )

    def reversed(self) -> "Pose2":
        """Same point, opposite heading (a port seen from the other side)."""
        return Pose2(self.x_m, self.y_m, self.yaw_rad + math.pi)


@dataclass(frozen=True)
class Pose3(Pose2):
    """A car's pose off the flat floor (on a hill): the planar pose plus the body frame's
    height ``z_m`` above the track's surface, its ``pitch_rad`` (positive = nose down) and
    ``roll_rad`` (positive = left side up), Z-Y-X Euler angles: the body's rotation is
    ``Rz(yaw) Ry(pitch) Rx(roll)``. Everything that takes a ``Pose2`` takes it (as its planar part)."""

    z_m: float = 0.0
    pitch_rad: float = 0.0
    roll_rad: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("z_m", "pitch_rad", "roll_rad"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def rotation(self) -> np.ndarray:
        """``(3, 3)`` body -> world rotation ``Rz(yaw) Ry(pitch) Rx(roll)``."""
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        cp, sp = math.cos(self.pitch_rad), math.sin(self.pitch_rad)
        cr, sr = math.cos(self.roll_rad), math.sin(self.roll_rad)
        return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                         [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                         [-sp, cp * sr, cp * cr]])
