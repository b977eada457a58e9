"""Pose2: SE(2) algebra (composition, inverse, apply) as exact as float allows."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2, wrap_angle

coord = st.floats(-50.0, 50.0, allow_nan=False)
yaw = st.floats(-10.0, 10.0, allow_nan=False)
poses = st.builds(Pose2, coord, coord, yaw)

TOL_M, TOL_RAD = 1e-9, 1e-12


def close(a: Pose2, b: Pose2, tol_m: float = TOL_M, tol_rad: float = TOL_RAD) -> bool:
    d_m, d_rad = a.distance_to(b)
    return d_m < tol_m and d_rad < tol_rad


@settings(max_examples=200, deadline=None)
@given(poses, poses, poses)
def test_composition_is_associative(a, b, c):
    assert close((a @ b) @ c, a @ (b @ c))


@settings(max_examples=200, deadline=None)
@given(poses)
def test_inverse_composes_to_identity(a):
    assert close(a @ a.inverse(), Pose2())
    assert close(a.inverse() @ a, Pose2())
    assert close(a.inverse().inverse(), a)


@settings(max_examples=200, deadline=None)
@given(poses, poses, st.lists(st.tuples(coord, coord), min_size=1, max_size=5))
def test_apply_matches_composition_and_matrix(a, b, pts):
    pts = np.array(pts)
    np.testing.assert_allclose((a @ b).apply(pts), a.apply(b.apply(pts)), atol=1e-9)
    hom = np.column_stack([pts, np.ones(len(pts))]) @ a.as_matrix().T
    np.testing.assert_allclose(hom[:, :2], a.apply(pts), atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e3, 1e3, allow_nan=False))
def test_wrap_angle_range(angle):
    w = wrap_angle(angle)
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(angle), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(angle), abs_tol=1e-9)


def test_reversed_turns_heading_half_way_round():
    p = Pose2(1.0, 2.0, 0.3)
    r = p.reversed()
    assert (r.x_m, r.y_m) == (1.0, 2.0)
    assert math.isclose(wrap_angle(r.yaw_rad - p.yaw_rad), -math.pi)
    assert close(r.reversed(), p)


def test_shapely_affine_matches_apply():
    import shapely
    from shapely.affinity import affine_transform

    p = Pose2(0.5, -1.5, 2.0)
    moved = affine_transform(shapely.Point(0.3, 0.7), p.as_shapely_affine())
    np.testing.assert_allclose([moved.x, moved.y], p.apply([[0.3, 0.7]])[0], atol=1e-12)


@pytest.mark.parametrize("yaw_rad", [0.0, math.pi / 2, -math.pi, 3 * math.pi])
def test_yaw_is_normalised(yaw_rad):
    assert -math.pi <= Pose2(0, 0, yaw_rad).yaw_rad < math.pi
