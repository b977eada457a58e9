"""Compiled (numba) kernels of the per-frame closed loop: the camera line with its noise.

The Spinner's line camera (``get_image(row)``) costs one call of :func:`camera_row` per frame
instead of a dozen NumPy/OpenCV calls. The kernels compute exactly what the code they replace
computes, bit for bit (tests/test_line_kernel.py checks them against it):

* the remap coordinates of :meth:`simrunner.sensors.camera.Camera.render_row`: float64 sums in the
  same order, rounded to float32;
* the bilinear sample of an 8-bit image at float32 ``(sx, sy)``: the pixel at
  ``(ix + ax, iy + ay)`` (``ix = floor(sx)``, ``ax = sx - ix`` in float32) is
  ``t = fma(ax, p01 - p00, p00)``, ``b = fma(ax, p11 - p10, p10)``,
  ``v = fma(ay, b - t, t)`` in float32 with single-rounding fused multiply-adds, rounded half
  to even and saturated to 0..255; neighbours outside the image read ``floor``, a pixel with
  all four outside is ``floor``. (This is what ``cv2.remap(..., INTER_LINEAR,
  BORDER_CONSTANT, floor)`` of OpenCV 4.11-5.1 computes on FMA hardware, which the camera
  used to call; the rule is ours now. The ``llvm.fma`` intrinsic is exact on every CPU, so
  the kernel does not depend on FMA hardware.)
* the noise of :meth:`simrunner.sensors.camera.Camera.add_noise`: ``pixel + rint(normal * std)``
  (the noise rounded half to even first, so an exact tie ``pixel + k.5`` rounds by the
  parity of ``k``, not of the sum), saturated to 0..255, with ``normal`` from the run's
  standard-normal stream.

Compilation: ``cache=True`` — the first use in a fresh checkout compiles (~1-2 s) and
writes the machine code to ``simrunner/sensors/__pycache__`` (numba's own cache directory when that
is not writable, or ``NUMBA_CACHE_DIR``); later processes load it (tens of ms).
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def _fma_f32(typingctx, a, b, c):
    """``a * b + c`` in float32 with one rounding (``llvm.fma.f32``)."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(f32, [f32, f32, f32]),
                                            "llvm.fma.f32")
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, inline="always")
def _pixel(image, ix, iy, border):
    """``image[iy, ix]`` as float32, ``border`` outside the image."""
    h, w = image.shape
    if 0 <= ix < w and 0 <= iy < h:
        return np.float32(image[iy, ix])
    return border


@njit(cache=True, inline="always")
def _bilinear(image, sx, sy, floor):
    """The bilinear sample (module docstring) of one pixel at float32 ``(sx, sy)``:
    the float32 result before rounding to uint8 (``floor`` when all neighbours are outside)."""
    h, w = image.shape
    ix = int(np.floor(sx))
    iy = int(np.floor(sy))
    ax = sx - np.float32(ix)
    ay = sy - np.float32(iy)
    if 0 <= ix < w - 1 and 0 <= iy < h - 1:
        p00 = np.float32(image[iy, ix])
        p01 = np.float32(image[iy, ix + 1])
        p10 = np.float32(image[iy + 1, ix])
        p11 = np.float32(image[iy + 1, ix + 1])
    elif ix + 1 < 0 or ix >= w or iy + 1 < 0 or iy >= h:
        return floor
    else:
        p00 = _pixel(image, ix, iy, floor)
        p01 = _pixel(image, ix + 1, iy, floor)
        p10 = _pixel(image, ix, iy + 1, floor)
        p11 = _pixel(image, ix + 1, iy + 1, floor)
    top = _fma_f32(ax, p01 - p00, p00)
    bottom = _fma_f32(ax, p11 - p10, p10)
    return _fma_f32(ay, bottom - top, top)


@njit(cache=True, inline="always")
def _to_u8(v):
    """Round half to even and saturate to 0..255."""
    r = np.rint(v)
    if r < 0.0:
        return np.uint8(0)
    if r > 255.0:
        return np.uint8(255)
    return np.uint8(r)


@njit(cache=True)
def camera_row(image, gy, x_gain, x_ground, x_pose, y_gain, y_ground, y_pose, floor,
               noisy, normals, pos, std, out):
    """One camera row into ``out`` ``(1, W) uint8``, optionally with noise.

    ``image (H, W) uint8`` is the top-down raster; ``gy (W,) float64`` the row's car-frame
    ground y (m). Raster coordinates (col, row) of pixel ``i``:
    ``map_x = float32((gy[i] * x_gain + x_ground) + x_pose)``, ``map_y`` likewise with the
    ``y_`` scalars (the caller folds pose, ground x and raster scale into them, see
    ``Camera.render_row``). ``floor``: border gray. ``noisy``: add ``normals[pos + i] * std``
    to pixel ``i`` (``normals`` float64, at least ``pos + W`` long), then round.
    """
    fl = np.float32(floor)
    for i in range(out.shape[1]):
        g = gy[i]
        sx = np.float32(g * x_gain + x_ground + x_pose)
        sy = np.float32(g * y_gain + y_ground + y_pose)
        v = _bilinear(image, sx, sy, fl)
        if noisy:
            out[0, i] = _to_u8(np.rint(normals[pos + i] * std) + np.float64(_to_u8(v)))
        else:
            out[0, i] = _to_u8(v)

