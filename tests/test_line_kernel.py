"""Compiled per-frame kernels (simrunner.sensors.line_kernel) agree bit for bit with the NumPy/OpenCV
code they stand for: cv2.remap (bilinear, constant border), cv2.add noise, Camera.render."""
from __future__ import annotations

import math

import cv2
import numba
import numpy as np
import pytest
import shapely

from pieces.pose import Pose2
from simrunner.sensors import line_kernel as fastpath
from simrunner.sensors.camera import Camera
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from simrunner.run.spinner import BufferedNormals
from vehicle.description import CarDescription


@numba.njit(cache=False)
def _remap(image, map_x, map_y, floor, out):
    for i in range(map_x.size):
        out[i] = fastpath._to_u8(fastpath._bilinear(image, map_x[i], map_y[i], np.float32(floor)))


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


def test_bilinear_kernel_equals_cv2_remap_bit_for_bit():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, size=(50, 70), dtype=np.uint8)
    img[rng.random(img.shape) < 0.3] = 255
    img[rng.random(img.shape) < 0.3] = 0
    n = 128
    bad = 0
    for trial in range(4000):  # ~0.5 M pixels: OpenCV's FMA rounding shows up ~4 times per 2.5 M
        mx, my = (a.astype(np.float32).reshape(1, -1) for a in _maps(rng, trial % 4, 70, 50, n))
        ref = cv2.remap(img, mx, my, cv2.INTER_LINEAR, None, cv2.BORDER_CONSTANT, 40).reshape(-1)
        out = np.empty(n, np.uint8)
        _remap(img, mx[0], my[0], 40.0, out)
        bad += int(np.count_nonzero(out != ref))
    assert bad == 0


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
        img = cam.render(pose)  # cv2.remap path
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
        ref = cam.add_noise(cam.render(pose)[60:61], ref_rng)  # cv2.add path
        assert np.array_equal(cam.line_image(pose, 60, gen_rng), ref)
        assert np.array_equal(cam.line_image(pose, 60, buffered), ref)


class _FixedNormals:
    def __init__(self, values):
        self.values = values

    def standard_normal(self, shape):
        return self.values.reshape(shape).copy()


def test_noise_rounds_half_to_even_and_saturates_like_cv2(cam):
    pose = Pose2(1.5, 0.0, math.pi / 2)
    clean = cam.line_image(pose, 60)
    std = cam._noise_std
    k = np.arange(cam.width_px) - 64.0
    for frac in (0.5, -0.5, 0.25, 0.0):  # exact ties: pixel + (k + 0.5) std / std
        normals = (k + frac) / std if frac else k * 4.0 / std  # ... and saturation at 0 / 255
        ref = cam.add_noise(clean, _FixedNormals(normals))
        assert np.array_equal(cam.line_image(pose, 60, _FixedNormals(normals)), ref)
