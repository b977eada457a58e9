"""The camera's pixel arithmetic, proved against its stated rules computed by hand (exact
rational arithmetic, float32 rounding done here), not against any library: the bilinear sample
(float32 fused multiply-adds, round half to even, saturate), the noise (rounded before it is
added), the supersampling block mean; and the compiled kernels (simrunner.sensors.line_kernel)
and NumPy paths (simrunner.sensors.line_row) agree bit for bit with Camera.render."""
from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numba
import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.sensors import line_kernel as fastpath
from simrunner.sensors.camera import Camera
from simrunner.sensors.line_row import add_noise_u8, block_mean_u8, sample_u8
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from simrunner.run.spinner import BufferedNormals
from vehicle.description import CarDescription


@numba.njit(cache=False)
def _remap(image, map_x, map_y, floor, out):
    for i in range(map_x.size):
        out[i] = fastpath._to_u8(fastpath._bilinear(image, map_x[i], map_y[i], np.float32(floor)))


def _round32(q: Fraction) -> Fraction:
    """``q`` rounded to the nearest float32 (ties to an even significand), exactly."""
    if q == 0:
        return Fraction(0)
    a = abs(q)
    e = a.numerator.bit_length() - a.denominator.bit_length()
    if a < Fraction(2) ** e:
        e -= 1
    scale = Fraction(2) ** (23 - e)  # a * scale in [2**23, 2**24)
    m = a * scale
    n = m.numerator // m.denominator
    rest = m - n
    if rest > Fraction(1, 2) or (rest == Fraction(1, 2) and n % 2):
        n += 1
    return (n / scale) * (1 if q > 0 else -1)


def _round_half_even(q: Fraction) -> int:
    n = math.floor(q)
    rest = q - n
    if rest > Fraction(1, 2) or (rest == Fraction(1, 2) and n % 2):
        n += 1
    return n


def _round_half_even_u8(q: Fraction) -> int:
    return min(max(_round_half_even(q), 0), 255)


def _rule_pixel(image: np.ndarray, sx: np.float32, sy: np.float32, floor: int) -> int:
    """The bilinear rule of simrunner.sensors.line_kernel, by hand: neighbours outside read
    ``floor`` (all four outside: ``floor``), ``t = fma(ax, p01 - p00, p00)``,
    ``b = fma(ax, p11 - p10, p10)``, ``v = fma(ay, b - t, t)`` each rounded once to float32,
    then rounded half to even and saturated."""
    h, w = image.shape
    fx, fy = Fraction(float(sx)), Fraction(float(sy))
    ix, iy = math.floor(fx), math.floor(fy)
    if ix + 1 < 0 or ix >= w or iy + 1 < 0 or iy >= h:
        return floor

    def p(c, r):
        return Fraction(int(image[r, c])) if 0 <= c < w and 0 <= r < h else Fraction(floor)

    ax, ay = fx - ix, fy - iy
    top = _round32(ax * (p(ix + 1, iy) - p(ix, iy)) + p(ix, iy))
    bottom = _round32(ax * (p(ix + 1, iy + 1) - p(ix, iy + 1)) + p(ix, iy + 1))
    return _round_half_even_u8(_round32(ay * _round32(bottom - top) + top))


def test_rule_by_hand_on_exact_ties():
    """Bilinear values that land on x.5 exactly round to the even neighbour."""
    img = np.array([[10, 11, 12, 13], [20, 21, 22, 23], [30, 31, 32, 33]], np.uint8)
    cases = [((0.5, 0.0), 10),    # 10.5 -> 10
             ((1.5, 0.0), 12),    # 11.5 -> 12
             ((2.0, 0.25), 14),   # 12 + 0.25 * 10 = 14.5 -> 14
             ((1.0, 1.75), 28),   # 21 + 0.75 * 10 = 28.5 -> 28
             ((2.5, 1.25), 25)]   # 22.5 + 0.25 * 10 = 25.0
    for (sx, sy), want in cases:
        out = sample_u8(img, np.float32([sx]), np.float32([sy]), 0.0)
        assert int(out[0]) == want == _rule_pixel(img, np.float32(sx), np.float32(sy), 0)
    # border: the floor enters as a neighbour, and beyond one pixel the floor alone
    assert int(sample_u8(img, np.float32([-0.5]), np.float32([0.0]), 40.0)[0]) == 25  # (40 + 10) / 2
    assert int(sample_u8(img, np.float32([3.5]), np.float32([0.0]), 40.0)[0]) == 26   # 26.5 -> 26
    assert int(sample_u8(img, np.float32([-1.5]), np.float32([1.0]), 40.0)[0]) == 40
    assert int(sample_u8(img, np.float32([9.0]), np.float32([9.0]), 40.0)[0]) == 40


def _maps(rng, kind: int, w: int, h: int, n: int):
    if kind == 0:  # anywhere, partly outside
        return rng.uniform(-3, w + 3, n), rng.uniform(-3, h + 3, n)
    if kind == 1:  # inside, fine fractions
        return (rng.integers(0, w - 1, n) + rng.integers(0, 4096, n) / 4096,
                rng.integers(0, h - 1, n) + rng.integers(0, 4096, n) / 4096)
    edges_x = np.array([-1.0, -0.5, -1e-7, -1e-30, 0.0, 1e-30, 1e-7, w - 1.00001, w - 1.0, w - 0.5, w, w + 1e-5])
    edges_y = np.array([-1.0, -0.5, -1e-7, 0.0, 1e-7, h - 1.001, h - 1.0, h - 0.5, h])
    jitter = rng.normal(0, 1e-6, n) * (rng.random(n) < 0.5)
    if kind == 2:  # columns at and around the borders
        return rng.choice(edges_x, n) + jitter, rng.uniform(-2, h + 2, n)
    return rng.uniform(-2, w + 2, n), rng.choice(edges_y, n) + jitter  # rows at the borders


def test_kernel_and_numpy_sampler_follow_the_rule_bit_for_bit():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, size=(50, 70), dtype=np.uint8)
    img[rng.random(img.shape) < 0.3] = 255
    img[rng.random(img.shape) < 0.3] = 0
    n = 128
    for trial in range(24):
        mx, my = (a.astype(np.float32) for a in _maps(rng, trial % 4, 70, 50, n))
        want = np.array([_rule_pixel(img, x, y, 40) for x, y in zip(mx, my)], np.uint8)
        out = np.empty(n, np.uint8)
        _remap(img, mx, my, 40.0, out)
        assert np.array_equal(out, want)
        assert np.array_equal(sample_u8(img, mx, my, 40.0), want)
        assert np.array_equal(sample_u8(img, mx.reshape(8, 16), my.reshape(8, 16), 40.0), want.reshape(8, 16))


@settings(max_examples=300, deadline=None)
@given(sx=st.floats(-3, 12, width=32), sy=st.floats(-3, 8, width=32),
       pixels=st.lists(st.integers(0, 255), min_size=60, max_size=60))
def test_numpy_sampler_follows_the_rule_anywhere(sx, sy, pixels):
    img = np.array(pixels, np.uint8).reshape(6, 10)
    xs = np.float32([sx, 2 + (sx % 1), sx])  # also one inside (the cheap path) per example
    ys = np.float32([sy, 2 + (sy % 1), 2 + (sy % 1)])
    want = [_rule_pixel(img, x, y, 40) for x, y in zip(xs, ys)]
    assert sample_u8(img, xs, ys, 40.0).tolist() == want


def test_noise_is_rounded_before_it_is_added_by_hand():
    pixels = np.array([100, 100, 100, 100, 100, 101, 101, 250, 3, 0, 255], np.uint8)
    noise = np.array([0.5, 1.5, 2.5, -0.5, -1.5, 0.5, 1.5, 10.2, -7.7, -0.4, 0.4])
    want = [100, 102, 102, 100, 98, 101, 103, 255, 0, 0, 255]
    assert add_noise_u8(pixels, noise).tolist() == want
    # not the sum's parity: 101 + 0.5 = 101.5 would give 102
    assert add_noise_u8(pixels.astype(np.float64), noise).tolist() == want


def test_block_mean_rounds_half_to_even_by_hand():
    blocks = np.array([[1, 2, 2, 3, 0, 1, 5, 5],
                       [1, 2, 2, 3, 0, 2, 5, 6]], np.uint8)  # sums 6, 10, 3, 21
    assert block_mean_u8(blocks, 2).tolist() == [[2, 2, 1, 5]]  # 1.5, 2.5, 0.75, 5.25
    assert block_mean_u8(np.full((3, 3), 7, np.uint8), 3).tolist() == [[7]]
    big = np.full((4, 4), 255, np.uint8)
    big[0, :2] = 247  # 16 * 255 - 16 = mean 254.0
    assert block_mean_u8(big, 4).tolist() == [[254]]


def _ring_raster():
    c = shapely.Point(0, 0)
    road = c.buffer(1.775, 128).difference(c.buffer(1.225, 128))
    white = c.buffer(1.755, 128).difference(c.buffer(1.245, 128))
    return build_raster([layer_from_polygon("edges", road.difference(white), BLACK_GRAY),
                         layer_from_polygon("lane", white, WHITE_GRAY)])


@pytest.fixture(scope="module")
def cam():
    return Camera(CarDescription().camera, _ring_raster())


def _poses(rng, n):
    """Poses on the ring, across it and far off the raster (the border gray)."""
    r = rng.uniform(0.5, 3.0, n)
    a = rng.uniform(-math.pi, math.pi, n)
    yaw = a + math.pi / 2 + rng.normal(0, 0.5, n)
    return [Pose2(ri * math.cos(ai), ri * math.sin(ai), y) for ri, ai, y in zip(r, a, yaw)] + [Pose2(9.0, 9.0, 1.0)]


def test_line_image_equals_render_rows(cam):
    rng = np.random.default_rng(2)
    rows = [r for r in range(cam.height_px) if cam._row_gx[r] is not None]
    assert CarDescription().camera.default_row in rows
    for pose in _poses(rng, 40):
        img = cam.render(pose)  # the whole-frame path (sample_u8)
        for r in (rows[0], 60, rows[-1], int(rng.integers(rows[0], rows[-1]))):
            line = cam.line_image(pose, r)
            assert line.shape == (1, cam.width_px) and line.dtype == np.uint8
            assert np.array_equal(line[0], img[r])
            assert np.array_equal(cam.render_row(pose, r), img[r])


def test_line_image_noise_equals_add_noise_with_the_same_stream(cam):
    rng = np.random.default_rng(3)
    poses = _poses(rng, 30)
    ref_rng, gen_rng = np.random.default_rng(7), np.random.default_rng(7)
    buffered = BufferedNormals(np.random.default_rng(7), chunk=300)  # refills inside rows
    for pose in poses:
        ref = cam.add_noise(cam.render(pose)[60:61], ref_rng)  # the whole-frame path
        assert np.array_equal(cam.line_image(pose, 60, gen_rng), ref)
        assert np.array_equal(cam.line_image(pose, 60, buffered), ref)


class _FixedNormals:
    def __init__(self, values):
        self.values = values

    def standard_normal(self, shape):
        return self.values.reshape(shape).copy()


def test_line_image_noise_ties_by_hand():
    """The camera's noise on exact ties: noise std 1, so the normals are the noise."""
    spec = dataclasses.replace(CarDescription().camera, noise_std=1.0)
    cam = Camera(spec, _ring_raster())
    pose = Pose2(1.5, 0.0, math.pi / 2)
    clean = cam.line_image(pose, 60).astype(np.int64)
    k = np.arange(cam.width_px) - 64.0
    for frac in (0.5, -0.5, 0.25, 0.0):
        noise = k + frac if frac else k * 4.0  # ... and saturation at 0 / 255
        want = np.clip(clean + np.array([_round_half_even(Fraction(v)) for v in noise]), 0, 255)
        assert np.array_equal(cam.line_image(pose, 60, _FixedNormals(noise)), want)
        assert np.array_equal(cam.add_noise(clean.astype(np.uint8), _FixedNormals(noise)), want)
