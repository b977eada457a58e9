"""The NumPy camera line (simrunner.sensors.line_row) equals the numba kernel
(simrunner.sensors.line_kernel) bit for bit: inside the raster, across its borders, far
outside, with and without noise, and on sums whose float32 rounding is a near tie."""
from __future__ import annotations

import numpy as np
import pytest

from simrunner.sensors import line_row

line_kernel = pytest.importorskip("simrunner.sensors.line_kernel")


def _args(rng, kind: int, w: int, h: int, n: int = 128):
    gy = np.sort(rng.uniform(-0.3, 0.3, n))
    if kind == 0:  # inside
        x_pose, y_pose = rng.uniform(130, w - 130), rng.uniform(130, h - 130)
    elif kind == 1:  # across a border
        x_pose, y_pose = rng.choice([-20.0, w + 20.0]) + rng.normal(0, 30), rng.uniform(-40, h + 40)
    elif kind == 2:  # far outside
        x_pose, y_pose = rng.uniform(-1e4, 1e4), rng.uniform(-1e4, 1e4)
    else:  # coordinates close to whole numbers and to 0: tiny fractions, ties
        x_pose, y_pose = rng.integers(0, 3) + rng.choice([0.0, 1e-7, -1e-7, 1e-30]), rng.uniform(0, 2)
        gy = gy * rng.choice([0.0, 1e-6, 1.0])
    return (gy, rng.uniform(-250, 250), rng.uniform(-50, 50), x_pose,
            rng.uniform(-250, 250), rng.uniform(-50, 50), y_pose, float(rng.integers(0, 256)),
            bool(rng.integers(0, 2)), rng.standard_normal(n + 20), int(rng.integers(0, 20)),
            float(rng.uniform(0, 12)))


@pytest.mark.parametrize("kind", [0, 1, 2, 3])
def test_numpy_row_equals_numba_kernel(kind):
    rng = np.random.default_rng(10 + kind)
    img = rng.integers(0, 256, size=(280, 320), dtype=np.uint8)
    img[rng.random(img.shape) < 0.3] = 255
    img[rng.random(img.shape) < 0.3] = 0
    bad = 0
    for _ in range(600):
        args = _args(rng, kind, 320, 280)
        a = np.empty((1, 128), np.uint8)
        b = np.empty((1, 128), np.uint8)
        line_kernel.camera_row(img, *args, a)
        line_row.camera_row(img, *args, b)
        bad += int(np.count_nonzero(a != b))
        line_row.camera_row(img, *args, b, monotone=True)  # gy is sorted
        bad += int(np.count_nonzero(a != b))
    assert bad == 0


def test_unsorted_rows_and_fractions_near_ties():
    """Unsorted ground points, and coordinates ``n + k / 2**23`` (the smallest fractions the
    inside path sees) whose sums land on float32 half-way points."""
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, size=(80, 80), dtype=np.uint8)
    a = np.empty((1, 128), np.uint8)
    b = np.empty((1, 128), np.uint8)
    bad = 0
    for _ in range(400):
        # gain 1 on "gy": the coordinates themselves, in random order
        coords = rng.integers(1, 77) + rng.permutation(rng.integers(0, 64, 128)) * 2.0 ** -23
        other = rng.uniform(2, 70)
        for xg, yg in ((1.0, 0.0), (0.0, 1.0)):
            args = (coords, xg, 0.0, 0.0 if xg else other, yg, 0.0, 0.0 if yg else other,
                    40.0, False, np.zeros(0), 0, 0.0)
            line_kernel.camera_row(img, *args, a)
            line_row.camera_row(img, *args, b)
            bad += int(np.count_nonzero(a != b))
    assert bad == 0


def test_round32_is_correctly_rounded_at_ties():
    """Sums that land on float32 half-way points only after a first float64 rounding."""
    rng = np.random.default_rng(5)
    a = rng.uniform(1, 2, 4000).astype(np.float32).astype(np.float64)
    half_ulp = np.spacing(a.astype(np.float32)).astype(np.float64) / 2
    tiny = rng.choice([2.0 ** -60, -(2.0 ** -60), 2.0 ** -80], a.size)
    got = line_row._round32(a + half_ulp, tiny)
    from fractions import Fraction

    for i in range(0, a.size, 7):
        exact = Fraction(a[i]) + Fraction(half_ulp[i]) + Fraction(tiny[i])
        lo = np.float32(a[i])
        hi = np.nextafter(lo, np.float32(np.inf))
        d_lo, d_hi = abs(exact - Fraction(float(lo))), abs(exact - Fraction(float(hi)))
        assert got[i] == (float(lo) if d_lo < d_hi else float(hi)), i
    # the plain float64 sum rounded to float32 gets some of these wrong (double rounding)
    plain = (a + half_ulp + tiny).astype(np.float32).astype(np.float64)
    assert np.count_nonzero(plain != got) > 0
