"""The camera's pixel arithmetic in NumPy: the line of the closed loop (:func:`camera_row`, bit
for bit the numba kernel :func:`simrunner.sensors.line_kernel.camera_row`: same arguments,
same pixels), whole frames (:func:`sample_u8`), supersampling (:func:`block_mean_u8`) and noise
(:func:`add_noise_u8`). Every rounding is stated here and done here, not left to a library:
bilinear values are float32 fused multiply-adds, pixels are rounded half to even and
saturated to 0..255, noise is rounded half to even before it is added. (The camera once
used ``cv2.remap``, ``cv2.resize`` and ``cv2.add``; OpenCV 5.1 changed ``cv2.add``'s ties.)

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

import functools

import numpy as np

_CORNERS = np.array([0, 0, 1, 1])  # column offsets of p00, p10, p01, p11
_ROWS = np.array([0, 1, 0, 1])     # row offsets of the same


@functools.lru_cache(maxsize=8)
def _offsets(w: int) -> np.ndarray:
    """Flat-index offsets of p00, p10, p01, p11 in an image ``w`` pixels wide."""
    return _ROWS * w + _CORNERS


def _round_odd(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``p + c`` in float64 rounded to odd: the nearest-rounded sum, moved one ulp towards
    the exact sum when it is inexact and its last bit is even (TwoSum gives the error)."""
    s = p + c
    bb = s - p
    err = (p - (s - bb)) + (c - bb)
    fix = (err != 0) & ((s.view(np.int64) & 1) == 0)
    if fix.any():
        s = np.where(fix, np.nextafter(s, np.where(err > 0, np.inf, -np.inf)), s)
    return s


def _round32(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``p + c`` (float64 arrays whose exact sum is wanted) correctly rounded to float32,
    returned as float64."""
    return _round_odd(p, c).astype(np.float32).astype(np.float64)


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


def camera_row(image, gy, x_gain, x_ground, x_pose, y_gain, y_ground, y_pose, floor,
               noisy, normals, pos, std, out, monotone: bool = False) -> None:
    """One camera row into ``out`` ``(1, W) uint8``, optionally with noise: the arguments
    and result of :func:`simrunner.sensors.line_kernel.camera_row` (see there).
    ``monotone``: ``gy`` is sorted (either way), so the row's extreme raster coordinates
    are at its ends (a camera row's ground points are)."""
    h, w = image.shape
    sx = gy * x_gain
    sx += x_ground
    sx += x_pose
    sx = sx.astype(np.float32)
    sy = gy * y_gain
    sy += y_ground
    sy += y_pose
    sy = sy.astype(np.float32)
    if monotone:
        x_lo, x_hi = (sx[0], sx[-1]) if sx[0] <= sx[-1] else (sx[-1], sx[0])
        y_lo, y_hi = (sy[0], sy[-1]) if sy[0] <= sy[-1] else (sy[-1], sy[0])
    else:
        x_lo, x_hi, y_lo, y_hi = sx.min(), sx.max(), sy.min(), sy.max()
    if 1.0 <= x_lo and x_hi < w - 1 and 1.0 <= y_lo and y_hi < h - 1:
        v = _inside(image, sx, sy)
    else:
        v = _anywhere(image, sx, sy, float(np.float32(floor)))
    # round half to even, saturate to 0..255 (ufuncs: np.clip's wrapper costs more here)
    np.rint(v, out=v)
    np.minimum(np.maximum(v, 0.0, out=v), 255.0, out=v)
    if noisy:  # whole numbers plus rounded noise: whole numbers, only saturated again
        v += np.rint(normals[pos:pos + out.shape[1]] * std)
        np.minimum(np.maximum(v, 0.0, out=v), 255.0, out=v)
    out[0] = v


def sample_u8(image: np.ndarray, sx: np.ndarray, sy: np.ndarray, floor: float) -> np.ndarray:
    """Bilinear samples of ``image (H, W) uint8`` at float32 raster coordinates ``(sx, sy)``
    (col, row; any equal shapes) as uint8 of that shape: the kernel's float32 value (fused
    multiply-adds, ``floor`` outside the image), rounded half to even, saturated to 0..255.
    The whole-frame camera (``Camera.render``) samples with it; rows are exactly
    :func:`camera_row`'s pixels."""
    shape = np.shape(sx)
    fx = np.asarray(sx, np.float32).ravel()
    fy = np.asarray(sy, np.float32).ravel()
    h, w = image.shape
    inside = (fx >= 1.0) & (fx < w - 1) & (fy >= 1.0) & (fy < h - 1)
    v = np.empty(fx.size)
    if inside.all():
        v[:] = _inside(image, fx, fy)
    else:  # the cheap exact path where it applies (most pixels of a frame)
        v[inside] = _inside(image, fx[inside], fy[inside])
        fl = float(np.float32(floor))
        far = (fx < -1.0) | (fx >= w) | (fy < -1.0) | (fy >= h)  # all four neighbours outside
        v[far] = fl
        rest = ~(inside | far)
        if rest.any():
            v[rest] = _anywhere(image, fx[rest], fy[rest], fl)
    np.rint(v, out=v)
    return np.clip(v, 0.0, 255.0).astype(np.uint8).reshape(shape)


def block_mean_u8(img: np.ndarray, k: int) -> np.ndarray:
    """The mean of each ``k x k`` block of ``img (H*k, W*k) uint8`` as ``(H, W) uint8``,
    rounded half to even (exact: integer sums, ties decided by the quotient's parity)."""
    h, w = img.shape[0] // k, img.shape[1] // k
    total = img[:h * k, :w * k].reshape(h, k, w, k).sum(axis=(1, 3), dtype=np.int64)
    n = k * k
    q, r = np.divmod(total, n)
    q += (2 * r > n) | ((2 * r == n) & (q % 2 == 1))
    return q.astype(np.uint8)


def add_noise_u8(img: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """``img`` plus ``noise`` (float64, same shape) by the camera's rule: the noise is
    rounded half to even to a whole number first, then added to the pixel, and the sum is
    saturated to 0..255 (so a tie ``pixel + k.5`` rounds by the parity of ``k``, not of the
    sum). uint8 images give exactly :func:`camera_row`'s noisy pixels; other dtypes are
    rounded half to even after the sum. Returns uint8 of ``img``'s shape."""
    v = np.rint(noise)
    v += img
    if img.dtype != np.uint8:
        np.rint(v, out=v)
    return np.clip(v, 0.0, 255.0).astype(np.uint8)


def _inside(image: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """The bilinear float32 values (as float64) of float32 coordinates with all four
    neighbours inside and both coordinates >= 1. Then a fraction is a multiple of 2**-23
    below 1, so ``ax * (p01 - p00) + p00`` is an exact float64 (a multiple of 2**-23 below
    2**9) rounded once to float32, and so is ``bottom - top`` (both multiples of 2**-23
    below 2**8); ``ay * d + top`` (a multiple of 2**-46 below 2**9: up to 55 bits) may be
    inexact in float64, so it is checked for ties (:func:`_round32_normal`)."""
    w = image.shape[1]
    fx = np.floor(sx)
    fy = np.floor(sy)
    ax = (sx - fx).astype(np.float64)
    ay = (sy - fy).astype(np.float64)
    idx = fy.astype(np.intp)
    idx *= w
    idx += fx.astype(np.intp)
    flat = image.ravel()
    p00 = flat.take(idx).astype(np.float64)
    idx += 1
    top = flat.take(idx).astype(np.float64)
    idx += w
    p11 = flat.take(idx).astype(np.float64)
    idx -= 1
    p10 = flat.take(idx).astype(np.float64)
    top -= p00  # p01 - p00, p11 - p10: whole numbers, exact
    p11 -= p10
    top *= ax
    p11 *= ax
    top += p00
    p11 += p10
    top = top.astype(np.float32).astype(np.float64)  # top, bottom: exact sums rounded once
    d = (p11.astype(np.float32) - top.astype(np.float32)).astype(np.float64)
    d *= ay  # exact: 24 + 24 bits
    return _round32_normal(d, top)


def _round32_normal(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """:func:`_round32` for sums whose float64 result is 0 or a normal float32 magnitude:
    rounding twice (to float64, then float32) differs from rounding once only when the
    float64 sum lands exactly half-way between two float32 values (its 29 low bits are
    ``1000...0``) without being exact; only those are recomputed."""
    s = p + c
    tie = (s.view(np.int64) & 0x1FFFFFFF) == 0x10000000
    if tie.any():
        i = np.flatnonzero(tie)
        s[i] = _round_odd(p[i], c[i])
    return s.astype(np.float32).astype(np.float64)


def _anywhere(image: np.ndarray, sx: np.ndarray, sy: np.ndarray, fl: float) -> np.ndarray:
    """The bilinear values of any float32 coordinates (``fl`` outside the image)."""
    h, w = image.shape
    fx = np.floor(sx)
    fy = np.floor(sy)
    ax = (sx - fx).astype(np.float64)  # exact in float32
    ay = (sy - fy).astype(np.float64)
    # pixels far outside read the floor whatever their index: clip before the integer cast
    ix = np.clip(fx, -2.0, w + 1.0).astype(np.intp)
    iy = np.clip(fy, -2.0, h + 1.0).astype(np.intp)
    p = _corners(image, ix, iy, fl)
    left = p[:, :2]  # p00, p10
    # p01 - p00 and p11 - p10 are whole numbers: exact in float32
    tb = _fma32(ax[:, None], p[:, 2:] - left, left)  # top, bottom
    top = tb[:, 0]
    v = _fma32(ay, _round32(tb[:, 1], -top), top)
    outside = (ix + 1 < 0) | (ix >= w) | (iy + 1 < 0) | (iy >= h)
    if outside.any():
        v[outside] = fl
    return v
