"""The camera line of the closed loop in NumPy: :func:`camera_row`, bit for bit the numba
kernel :func:`simrunner.sensors.line_kernel.camera_row` (same arguments, same pixels).

Why NumPy: the compiled kernel costs ~2 us a frame but loading numba and its cached machine
code costs ~0.5 s of every process (numba, its typing registries and the scipy.linalg it
pulls in): more than a one-lap run's whole loop. This version costs ~50 us a frame (0.15 s
over 60 simulated seconds at 50 Hz) and nothing at start-up.

Exactness. The kernel computes, per pixel, float32 fused multiply-adds
``fma(a, b, c) = round32(a * b + c)`` (one rounding) and a float32 subtraction. Here the
product of two float32 values is exact in float64 (24 + 24 bits < 53), the sum is formed
in float64 with its exact error (TwoSum), and the float64 result is rounded *to odd* (an
inexact sum whose last bit is even moves one ulp towards the exact value): rounding that to
float32 gives the correctly rounded result, since 53 >= 24 + 2 (Boldo and Melquiond,
"Emulation of FMA and correctly rounded sums: proved algorithms using rounding to odd",
IEEE Trans. Computers 57(4), 2008). tests/test_line_row.py checks it against the kernel.
"""
from __future__ import annotations

import numpy as np

_CORNERS = np.array([0, 0, 1, 1])  # column offsets of p00, p10, p01, p11
_ROWS = np.array([0, 1, 0, 1])     # row offsets of the same


def _round32(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``p + c`` (float64 arrays whose exact sum is wanted) correctly rounded to float32,
    returned as float64."""
    s = p + c
    bb = s - p
    err = (p - (s - bb)) + (c - bb)
    inexact = err != 0
    if inexact.any():
        fix = inexact & ((s.view(np.int64) & 1) == 0)
        if fix.any():
            s = np.where(fix, np.nextafter(s, np.where(err > 0, np.inf, -np.inf)), s)
    return s.astype(np.float32).astype(np.float64)


def _fma32(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """float32 ``a * b + c`` with one rounding; operands and result float32 values held in
    float64 arrays."""
    return _round32(a * b, c)


def _corners(image: np.ndarray, ix: np.ndarray, iy: np.ndarray, floor: float) -> np.ndarray:
    """``(n, 4)`` float64 pixels p00, p10, p01, p11 around ``(ix, iy)``; ``floor`` outside."""
    h, w = image.shape
    if ix.min() >= 0 and ix.max() < w - 1 and iy.min() >= 0 and iy.max() < h - 1:
        idx = iy * w + ix
        return image.ravel().take(idx[:, None] + (_ROWS * w + _CORNERS)).astype(np.float64)
    cx = ix[:, None] + _CORNERS
    cy = iy[:, None] + _ROWS
    ok = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
    p = image[np.where(ok, cy, 0), np.where(ok, cx, 0)].astype(np.float64)
    p[~ok] = floor
    return p


def _to_u8(v: np.ndarray) -> np.ndarray:
    """Round half to even and saturate to 0..255, as float64 (in place)."""
    np.rint(v, out=v)
    return np.clip(v, 0.0, 255.0, out=v)


def camera_row(image, gy, x_gain, x_ground, x_pose, y_gain, y_ground, y_pose, floor,
               noisy, normals, pos, std, out) -> None:
    """One camera row into ``out`` ``(1, W) uint8``, optionally with noise: the arguments
    and result of :func:`simrunner.sensors.line_kernel.camera_row` (see there)."""
    h, w = image.shape
    fl = float(np.float32(floor))
    sx = (gy * x_gain + x_ground + x_pose).astype(np.float32)
    sy = (gy * y_gain + y_ground + y_pose).astype(np.float32)
    fx = np.floor(sx)
    fy = np.floor(sy)
    ax = (sx - fx).astype(np.float64)  # exact in float32
    ay = (sy - fy).astype(np.float64)
    # pixels far outside read the floor whatever their index: clip before the integer cast
    ix = np.clip(fx, -2.0, w + 1.0).astype(np.intp)
    iy = np.clip(fy, -2.0, h + 1.0).astype(np.intp)
    p = _corners(image, ix, iy, fl)
    left = p[:, :2]  # p00, p10
    ax2 = ax[:, None]
    # p01 - p00 and p11 - p10 are whole numbers: exact in float32
    tb = _fma32(ax2, p[:, 2:] - left, left)  # top, bottom
    top = tb[:, 0]
    v = _fma32(ay, _round32(tb[:, 1], -top), top)
    outside = (ix + 1 < 0) | (ix >= w) | (iy + 1 < 0) | (iy >= h)
    if outside.any():
        v[outside] = fl
    v = _to_u8(v)
    if noisy:
        n = out.shape[1]
        v += np.rint(np.asarray(normals[pos:pos + n], dtype=np.float64) * std)
        v = _to_u8(v)
    out[0] = v
