"""Rays against the objects standing on the track (:class:`worlds.solids.Solid` boxes): what the
cameras see in front of the ground, and what a range sensor measures.

A ray leaves ``origin`` (world, m) along ``direction`` (world, any length: ``t`` is measured
in its units); :func:`cast` finds the nearest box it enters (slab method, in each box's own
frame) and returns the hit distance ``t`` (inf: none), which box, and the world z of the face
normal there (1: the top, 0: a side). A camera shades a face by its tilt: under light from a
uniform overcast sky (a hall's ceiling), a face whose normal is tilted ``theta`` from
vertical receives ``(1 + cos theta) / 2`` of what the floor receives (the isotropic sky
model, Liu and Jordan 1963): the top the full light, the sides half. Both cameras use that
factor: the ideal one on the solid's reflectance x 255, the physical one on its illuminance.
"""
from __future__ import annotations

import math

import numpy as np


def sky_factor(normal_z: np.ndarray) -> np.ndarray:
    """The share of the horizontal illuminance a face with this normal z receives."""
    return 0.5 * (1.0 + normal_z)


def cast(solids, surface_z_m: float, origin: tuple[float, float, float], dx: np.ndarray,
         dy: np.ndarray, dz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest box along each ray ``origin + t (dx, dy, dz)``, ``t > 0``: ``(t, index,
    normal_z)`` arrays of the rays' shape (``t`` inf and ``index`` -1 where none is hit)."""
    ox, oy, oz = origin
    best_t = np.full(np.shape(dx), np.inf)
    best_i = np.full(np.shape(dx), -1, dtype=np.int64)
    best_nz = np.zeros(np.shape(dx))
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, b in enumerate(solids):
            c, s = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
            # the ray in the box's frame (centre at the origin, x along its length)
            px, py, pz = ox - b.x_m, oy - b.y_m, oz - (surface_z_m + 0.5 * b.height_m)
            lx, ly = c * px + s * py, -s * px + c * py
            ux, uy = c * dx + s * dy, -s * dx + c * dy
            near = np.full(np.shape(dx), -np.inf)
            far = np.full(np.shape(dx), np.inf)
            near_axis = np.zeros(np.shape(dx), dtype=np.int8)
            for axis, (p, u, half) in enumerate(((lx, ux, 0.5 * b.length_m), (ly, uy, 0.5 * b.width_m),
                                                 (pz, dz, 0.5 * b.height_m))):
                t1, t2 = (-half - p) / u, (half - p) / u
                lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
                parallel = u == 0
                lo = np.where(parallel, np.where(abs(p) <= half, -np.inf, np.inf), lo)
                hi = np.where(parallel, np.where(abs(p) <= half, np.inf, -np.inf), hi)
                enters = lo > near
                near_axis = np.where(enters, axis, near_axis)
                near = np.maximum(near, lo)
                far = np.minimum(far, hi)
            hit = (near <= far) & (near > 0.0) & (near < best_t)
            best_t = np.where(hit, near, best_t)
            best_i = np.where(hit, i, best_i)
            best_nz = np.where(hit, (near_axis == 2).astype(float), best_nz)
    return best_t, best_i, best_nz


def _straddles(b, surface_z_m: float, origin, normal) -> bool:
    """Whether box ``b`` has corners on both sides of (or on) the plane through ``origin``."""
    c, s = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
    sides = set()
    for lx in (-0.5 * b.length_m, 0.5 * b.length_m):
        for ly in (-0.5 * b.width_m, 0.5 * b.width_m):
            x = b.x_m + c * lx - s * ly - origin[0]
            y = b.y_m + s * lx + c * ly - origin[1]
            for z in (surface_z_m - origin[2], surface_z_m + b.height_m - origin[2]):
                d = normal[0] * x + normal[1] * y + normal[2] * z
                sides.add(d > 0.0)
                if d == 0.0 or len(sides) == 2:
                    return True
    return False


def camera_rays(cam, v: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Car-frame ray directions of image offsets ``v`` (down) and ``u`` (right), in pixels,
    as :meth:`simrunner.sensors.camera.Camera._ground` forms them (the ground is met at ``t =
    height / -dz``)."""
    f = (cam.width_px / 2.0) / math.tan(float(cam.hfov_rad) / 2.0)
    p = float(cam.pitch_rad)
    a = -u / f
    b = -v / f
    dx = math.cos(p) + b * math.sin(p)
    dz = -math.sin(p) + b * math.cos(p)
    return tuple(np.broadcast_arrays(dx, a, dz))


def camera_hits(solids, surface_z_m: float, cam, pose, rays):
    """Where the camera of the car at ``pose`` sees a solid in front of the ground along
    ``rays`` (car frame, :func:`camera_rays`): ``(mask, index, normal_z, hit_x, hit_y)``, or
    None when no ray hits one."""
    dx, dy, dz = rays
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    fwd, h = float(cam.forward_m), float(cam.height_m)
    origin = (pose.x_m + c * fwd, pose.y_m + s * fwd, surface_z_m + h)
    # only the solids in front of the camera (a camera looks forward, tilted down: nothing
    # wholly behind the plane through it across the car is seen)
    near = [i for i, b in enumerate(solids)
            if (b.x_m - origin[0]) * c + (b.y_m - origin[1]) * s > -0.5 * math.hypot(b.length_m, b.width_m)]
    if near and dx.size and float(dx.flat[0]) == float(dx.max()) == float(dx.min()) \
            and float(dz.max()) == float(dz.min()):
        # one image row: its rays fan out in one plane through the camera; a box wholly on one
        # side of that plane is not seen by it (eight dot products instead of the rays' casts)
        ex, ez = float(dx.flat[0]), float(dz.flat[0])
        normal = (c * ez, s * ez, -ex)
        near = [i for i in near if _straddles(solids[i], surface_z_m, origin, normal)]
    if not near:
        return None
    wx, wy = c * dx - s * dy, s * dx + c * dy
    t, idx, nz = cast([solids[i] for i in near], surface_z_m, origin, wx, wy, dz)
    idx = np.where(idx >= 0, np.asarray(near)[np.maximum(idx, 0)], -1)
    with np.errstate(divide="ignore"):
        ground = np.where(dz < 0, h / -dz, np.inf)
    mask = t < ground
    if not mask.any():
        return None
    return mask, idx, nz, origin[0] + t * wx, origin[1] + t * wy
