"""The car's camera: an exact pinhole view of the track, by ground-plane projection.

Conventions (DESIGN.md): the image is ``(H, W) uint8``, row 0 is the top of the image
(farthest from the car), column 0 is the car's LEFT side of the view. The camera sits in the
car body frame (origin at the rear-axle midpoint on the ground, x forward, y left, z up) at
``(forward_m, 0, height_m)``, looking forward along +x, tilted down by ``pitch_rad``, with no
roll or yaw. ``height_m`` is measured above the track surface (the car stands on it), so the
track's own height in the world (``SimTrack.surface_z_m``) needs no correction.

Pinhole model with square pixels: ``f_px = (W / 2) / tan(hfov / 2)``; the pixel
``(row, col)`` centre is ``u = col + 0.5 - W / 2`` right of and ``v = row + 0.5 - H / 2``
below the principal point (the image centre). Its ray in the car frame is
``d = forward_axis - (u / f_px) * left_axis - (v / f_px) * up_axis`` with
``forward_axis = (cos p, 0, -sin p)``, ``left_axis = (0, 1, 0)``, ``up_axis = (sin p, 0, cos p)``.

On flat ground every ray that goes down meets the ground at one point; those points
are computed once per camera (``ground_xy_m``, car frame). A frame is then: move those
points by the car pose into the world, convert to raster pixels and sample the top-down
raster bilinearly (:func:`simrunner.sensors.line_row.sample_u8`: float32 fused multiply-adds,
rounded half to even, the floor gray outside the raster). Rays that point at or above the horizon,
or meet the ground farther than ``max_range_m``, see the floor/background gray. With
``supersample=k`` each pixel averages a ``k x k`` grid of sub-pixel rays (box filter),
which removes aliasing of thin far lines at k^2 times the cost (the block mean rounded half
to even).

Objects standing on the track (``solids``: :class:`worlds.solids.Solid` boxes, set by the run
when a discipline places them) hide the ground behind them: where a pixel's ray meets one
before the ground the pixel is the box's shade (:mod:`simrunner.sensors.solids`: its
reflectance x 255 x the sky factor of the face), at the pixel's centre ray.

On a track with hills (the track's ``terrain``, :class:`worlds.terrain.Terrain`) the ground is
not flat: each frame the pixel rays leave the camera where the car's 3-D pose puts it (a
:class:`pieces.pose.Pose3` from the physics: height, pitch and roll, so the view tilts as the
car pitches over a crest; a plain ``Pose2`` is lifted onto the terrain, pitched along its
slope) and :meth:`worlds.terrain.Terrain.ray_cast` finds where they meet the floor or a hill
(a crest hides what lies behind it); the raster is sampled there as on flat ground, with the
same range limit (horizontal distance from the camera). Where the car stands level on the
floor and a line row's rays stay clear of every hill (``_view_is_flat``), the flat maps and
the line kernel serve as on a flat track.

The line camera (``line_image``: one row plus noise, every frame of a run) is one compiled
call (:mod:`simrunner.sensors.line_row`, NumPy; the numba kernel :mod:`simrunner.sensors.line_kernel`
computes the same pixels) that computes the same maps and pixels as ``render``.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from pieces.pose import Pose2, Pose3
from simrunner.errors import CameraError
from simrunner.sensors.line_row import add_noise_u8, block_mean_u8, sample_u8
from simrunner.track.raster import TrackRaster
from worlds.terrain import Terrain

_NO_NORMALS = np.zeros(0)
_SLOPE_PROBE_M = 0.05  # a Pose2 lifted onto a hill takes the slope over +-5 cm (Camera.lifted)
_FLAT = Terrain()
_CLEAR_M = 0.02  # _view_is_flat: the car's axle and camera and the row's rays this far from every hill
def _line_kernel():
    """The line-row function: :func:`simrunner.sensors.line_row.camera_row` (NumPy, bit for bit
    the numba kernel :mod:`simrunner.sensors.line_kernel`, without numba's ~0.5 s load)."""
    from simrunner.sensors.line_row import camera_row

    return camera_row


def _raster_of(raster_or_track) -> TrackRaster:
    return raster_or_track if isinstance(raster_or_track, TrackRaster) else raster_or_track.raster


class Camera:
    """Pinhole camera of ``cam`` (a ``vehicle.description.Camera``) looking at ``raster`` (a
    ``TrackRaster``, or a ``SimTrack`` whose raster is used). ``supersample`` below 1, or
    an image row outside ``0..H-1``, raises :class:`simrunner.errors.CameraError`."""

    def __init__(self, cam, raster, *, max_range_m: float = 10.0, supersample: int = 1,
                 load_line_kernel: bool = True) -> None:
        if int(supersample) < 1:
            raise CameraError(f"supersample must be >= 1, got {supersample!r}")
        self.cam = cam
        terrain = getattr(raster, "terrain", None)
        self.terrain = terrain if terrain else None  # the track's hills (None: flat ground)
        # the hills' bounding boxes (x0, y0, x1, y1), for the flat shortcut of _view_is_flat
        self._hill_boxes = [tuple(np.r_[h.corners_xy().min(axis=0), h.corners_xy().max(axis=0)].tolist())
                            for h in self.terrain.hills] if self.terrain is not None else []
        self.raster = _raster_of(raster)
        self.width_px = int(cam.width_px)
        self.height_px = int(cam.height_px)
        self.max_range_m = float(max_range_m)
        self.supersample = k = int(supersample)
        self.f_px = (self.width_px / 2.0) / math.tan(float(cam.hfov_rad) / 2.0)
        # Sub-pixel ray grid (H*k, W*k): sample centres inside each pixel.
        sub = (np.arange(k) + 0.5) / k
        cols = (np.arange(self.width_px)[:, None] + sub[None, :]).ravel()
        rows = (np.arange(self.height_px)[:, None] + sub[None, :]).ravel()
        gx, gy, ok = self._ground(rows[:, None] - self.height_px / 2.0,
                                  cols[None, :] - self.width_px / 2.0)
        if self.terrain is not None:  # the sub-pixel rays in the car frame, for world_points
            self._grid_v = rows - self.height_px / 2.0
            self._grid_u = cols - self.width_px / 2.0
            self._grid_rays: dict[tuple, np.ndarray] = {}  # rows (start, stop) -> their car-frame rays
        self.ground_xy_m = np.stack((gx, gy), axis=-1)  # (H*k, W*k, 2), nan where no ground
        self._gx = np.where(ok, gx, 0.0)
        self._gy = np.where(ok, gy, 0.0)
        self._miss = ~ok
        # per image row: does any of its sub-rows miss the ground (then maps need the mask)
        self._row_misses = self._miss.reshape(self.height_px, -1).any(axis=1).tolist()
        # one ray per pixel: the ground points of a row share their x (the ray's distance
        # depends on the row only), so a row's maps need only its y values
        self._row_gx: list[float | None] = [None] * self.height_px
        if k == 1:
            for r in range(self.height_px):
                if not self._row_misses[r] and np.all(self._gx[r] == self._gx[r, 0]):
                    self._row_gx[r] = float(self._gx[r, 0])
        # rows whose ground y values are sorted: their extreme raster coordinates are at the
        # ends (line_row.camera_row's cheap inside test)
        d = np.diff(self._gy, axis=1)
        self._row_monotone = (np.all(d >= 0, axis=1) | np.all(d <= 0, axis=1)).tolist()
        self._any_miss = bool(self._miss.any())
        self._inv_m = 1.0 / self.raster.m_per_px
        self._x0_m, self._y0_m = (float(v) for v in self.raster.origin_xy_m)
        self._floor = int(self.raster.floor_gray)
        self._floor_f = float(self._floor)
        self._noise_std = float(cam.noise_std)
        self.solids: tuple = ()  # objects standing on the track (worlds.solids.Solid)
        self._solid_rays: dict[int, tuple] = {}  # image row -> its car-frame rays
        # load the line kernel now, not inside a timed, watchdog-guarded run
        # (``load_line_kernel=False``: on first use instead, for callers that may never need it)
        line_rows = [r for r, gx in enumerate(self._row_gx) if gx is not None]
        if line_rows and load_line_kernel:
            self.line_image(Pose2(), line_rows[0])

    @functools.cached_property
    def _kernel(self):
        """The compiled line kernel (loaded on first use, then an attribute of this camera)."""
        return _line_kernel()

    # -- geometry ------------------------------------------------------------------
    def _ground(self, v: np.ndarray, u: np.ndarray):
        """Ground hit of rays at image offsets ``v`` (down) and ``u`` (right), in pixels."""
        p = float(self.cam.pitch_rad)
        h = float(self.cam.height_m)
        a = -u / self.f_px  # along the car's left
        b = -v / self.f_px  # along the camera's up axis
        dx = math.cos(p) + b * math.sin(p)
        dz = -math.sin(p) + b * math.cos(p)
        dx, a, dz = np.broadcast_arrays(dx, a, dz)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(dz < 0, h / -dz, np.inf)
            gx = float(self.cam.forward_m) + t * dx
            gy = t * a
        ok = np.isfinite(t) & (np.hypot(gx - float(self.cam.forward_m), gy) <= self.max_range_m)
        return np.where(ok, gx, np.nan), np.where(ok, gy, np.nan), ok

    def rays(self, v, u) -> np.ndarray:
        """Car-frame directions ``(..., 3)`` of the rays at image offsets ``v`` (down) and ``u``
        (right), in pixels (module docstring; not normalised)."""
        p = float(self.cam.pitch_rad)
        a = -np.asarray(u, dtype=float) / self.f_px
        b = -np.asarray(v, dtype=float) / self.f_px
        dx = math.cos(p) + b * math.sin(p)
        dz = -math.sin(p) + b * math.cos(p)
        return np.stack(np.broadcast_arrays(dx, a, dz), axis=-1)

    def lifted(self, pose: Pose2) -> Pose3:
        """``pose`` as a :class:`~pieces.pose.Pose3`: itself if it is one, else on the terrain
        (the height under the rear axle, pitched along the slope there, no roll)."""
        if isinstance(pose, Pose3):
            return pose
        if self.terrain is None:
            return Pose3(pose.x_m, pose.y_m, pose.yaw_rad)
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        d = _SLOPE_PROBE_M
        h0, hb, hf = (float(v) for v in self.terrain.height_m(
            [pose.x_m, pose.x_m - d * c, pose.x_m + d * c], [pose.y_m, pose.y_m - d * s, pose.y_m + d * s]))
        return Pose3(pose.x_m, pose.y_m, pose.yaw_rad, h0, -math.atan2(hf - hb, 2.0 * d))

    def world_points(self, pose: Pose2, v=None, u=None, *, rays: np.ndarray | None = None):
        """Where the rays at image offsets ``v``, ``u`` (pixels, broadcast; or their car-frame
        directions ``rays`` from :meth:`rays`) of a camera on a car at ``pose`` meet the ground,
        floor or hill (:meth:`worlds.terrain.Terrain.ray_cast`): world ``x``, ``y`` (m) and
        ``miss`` (bool: no ground within ``max_range_m``, horizontally from the camera)."""
        p3 = self.lifted(pose)
        rot = p3.rotation()
        origin = np.array([p3.x_m, p3.y_m, p3.z_m]) + rot @ np.array(
            [float(self.cam.forward_m), 0.0, float(self.cam.height_m)])
        d = (self.rays(v, u) if rays is None else rays) @ rot.T
        flat = np.hypot(d[..., 0], d[..., 1])
        flat[flat == 0.0] = 1e-300
        max_t = self.max_range_m / flat
        terrain = self.terrain if self.terrain is not None else _FLAT
        t = terrain.ray_cast(origin, d, max_t)
        miss = t == np.inf
        t[miss] = 0.0
        return origin[0] + t * d[..., 0], origin[1] + t * d[..., 1], miss

    def ground_point_of_pixel(self, row: float, col: float) -> tuple[float, float]:
        """Car-frame ground point ``(x_m, y_m)`` seen at the centre of pixel ``(row, col)``;
        ``(nan, nan)`` if that ray does not meet the ground within ``max_range_m``."""
        gx, gy, _ = self._ground(np.float64(row + 0.5 - self.height_px / 2.0),
                                 np.float64(col + 0.5 - self.width_px / 2.0))
        return float(gx), float(gy)

    def look_ahead_m(self, row: float) -> float:
        """Car-frame x (metres ahead of the rear axle) of the ground seen at the middle of
        ``row`` (on the image's vertical centre line); ``inf`` at or above the horizon."""
        gx, _, ok = self._ground(np.float64(row + 0.5 - self.height_px / 2.0), np.float64(0.0))
        return float(gx) if bool(ok) else math.inf

    def visible_width_m(self, row: float) -> float:
        """Ground width (m) spanned by ``row`` from the left edge of column 0 to the right edge
        of the last column; ``inf`` if the row does not see the ground."""
        v = np.float64(row + 0.5 - self.height_px / 2.0)
        _, yl, okl = self._ground(v, np.float64(-self.width_px / 2.0))
        _, yr, okr = self._ground(v, np.float64(self.width_px / 2.0))
        return float(yl - yr) if bool(okl) and bool(okr) else math.inf

    # -- rendering -----------------------------------------------------------------
    def _maps(self, pose: Pose2, rows: slice, misses: bool):
        """``(map_x, map_y)`` float32 remap coordinates (raster col, row) of the ray grid ``rows``."""
        inv = self._inv_m
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        gx, gy = self._gx[rows], self._gy[rows]
        # world = pose (x, y) + R(yaw) g; px col = (X - x0)/m, row = (y0 - Y)/m
        map_x = ((c * inv) * gx - (s * inv) * gy + (pose.x_m - self._x0_m) * inv).astype(np.float32)
        map_y = (-(s * inv) * gx - (c * inv) * gy + (self._y0_m - pose.y_m) * inv).astype(np.float32)
        if misses:
            miss = self._miss[rows]
            map_x[miss] = -10.0
            map_y[miss] = -10.0
        return map_x, map_y

    def _view_is_flat(self, pose: Pose2, row: int) -> bool:
        """On a track with hills: True when the car stands level on the floor (a ``Pose3`` within
        0.1 mm and 1 mrad of it) and neither it nor the rays of image row ``row`` come within
        ``_CLEAR_M`` of a hill; the row is then the flat ground's (same pixels to < 1 um)."""
        if isinstance(pose, Pose3) and (abs(pose.z_m) > 1e-4 or abs(pose.pitch_rad) > 1e-3
                                        or abs(pose.roll_rad) > 1e-3):
            return False
        gx = self._row_gx[row]
        if gx is None:
            return False
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        xs, ys = [pose.x_m], [pose.y_m]  # the rear axle, the camera and the row's two ends
        for px, py in ((float(self.cam.forward_m), 0.0), (gx, float(self._gy[row, 0])), (gx, float(self._gy[row, -1]))):
            xs.append(pose.x_m + c * px - s * py)
            ys.append(pose.y_m + s * px + c * py)
        x0, x1 = min(xs) - _CLEAR_M, max(xs) + _CLEAR_M
        y0, y1 = min(ys) - _CLEAR_M, max(ys) + _CLEAR_M
        return not any(x0 <= bx1 and bx0 <= x1 and y0 <= by1 and by0 <= y1 for bx0, by0, bx1, by1 in self._hill_boxes)

    def _terrain_maps(self, pose: Pose2, rows: slice):
        """:meth:`_maps` on a track with hills: the ray grid's rows ``rows`` cast onto the terrain."""
        key = (rows.start, rows.stop)
        rays = self._grid_rays.get(key)
        if rays is None:
            rays = self._grid_rays[key] = self.rays(self._grid_v[rows][:, None], self._grid_u[None, :])
        wx, wy, miss = self.world_points(pose, rays=rays)
        inv = self._inv_m
        map_x = ((wx - self._x0_m) * inv).astype(np.float32)
        map_y = ((self._y0_m - wy) * inv).astype(np.float32)
        map_x[miss] = -10.0
        map_y[miss] = -10.0
        return map_x, map_y

    def _sample(self, pose: Pose2, rows: slice, misses: bool) -> np.ndarray:
        if self.terrain is not None:
            map_x, map_y = self._terrain_maps(pose, rows)
        else:
            map_x, map_y = self._maps(pose, rows, misses)
        img = sample_u8(self.raster.image, map_x, map_y, self._floor_f)
        k = self.supersample
        return img if k == 1 else block_mean_u8(img, k)

    def render(self, pose: Pose2) -> np.ndarray:
        """The image ``(H, W) uint8`` seen from a car whose body frame is at ``pose``."""
        img = self._sample(pose, slice(None), self._any_miss)
        if self.solids:
            for r in range(self.height_px):
                self._paint_solids(img[r:r + 1], pose, r)
        return img

    def _paint_solids(self, img: np.ndarray, pose: Pose2, row: int) -> None:
        """Paint the solids seen along image row ``row`` into ``img`` ``(1, W)``, in place."""
        from simrunner.sensors.solids import camera_hits, camera_rays, sky_factor

        rays = self._solid_rays.get(row)
        if rays is None:
            u = np.arange(self.width_px) + 0.5 - self.width_px / 2.0
            rays = self._solid_rays[row] = camera_rays(self.cam, np.float64(row + 0.5 - self.height_px / 2.0), u)
        hits = camera_hits(self.solids, 0.0, self.cam, pose, rays)
        if hits is None:
            return
        mask, idx, nz, _, _ = hits
        refl = np.array([s.reflectance for s in self.solids])[idx[mask]]
        img[0, mask] = np.clip(np.rint(255.0 * refl * sky_factor(nz[mask])), 0, 255).astype(np.uint8)

    def render_row(self, pose: Pose2, row: int) -> np.ndarray:
        """One image row ``(W,) uint8``, equal to ``render(pose)[row]`` (cheaper)."""
        return self.line_image(pose, row)[0]

    def line_image(self, pose: Pose2, row: int, normals=None) -> np.ndarray:
        """What the Spinner's ``get_image(row)`` returns: ``render_row(pose, row)`` as a
        ``(1, W) uint8`` image, with ``add_noise(img, normals)`` unless ``normals`` is None,
        in one call (:func:`simrunner.sensors.line_row.camera_row`) for the rows whose
        ground points share one x (all rows of a camera without supersampling that see only
        ground). ``normals``: a ``numpy.random.Generator`` or a
        :class:`simrunner.run.spinner.BufferedNormals` (its ``take``)."""
        gx = (self._row_gx[row] if type(row) is int and 0 <= row < self.height_px and not self.solids
              and (self.terrain is None or self._view_is_flat(pose, row)) else None)
        if gx is None:
            row = int(row)
            if not 0 <= row < self.height_px:
                raise CameraError(f"row {row} outside the image (0..{self.height_px - 1})")
            k = self.supersample
            img = self._sample(pose, slice(row * k, (row + 1) * k), self._row_misses[row])[:1]
            if self.solids:
                self._paint_solids(img, pose, row)
            return img if normals is None else self.add_noise(img, normals)
        # _maps with the row's common x folded into scalars: the same float64 operations, term
        # for term, so the same pixels (a - s*g == a + (-s)*g exactly), fewer operations; the
        # kernel rounds the sums to float32 maps and samples like sample_u8
        inv = self._inv_m
        yaw = pose.yaw_rad
        ci, si = math.cos(yaw) * inv, math.sin(yaw) * inv
        out = np.empty((1, self.width_px), np.uint8)
        if normals is None:
            buf, pos = _NO_NORMALS, 0
        else:
            take = getattr(normals, "take", None)
            buf, pos = take(self.width_px) if take else (normals.standard_normal(self.width_px), 0)
        self._kernel(self.raster.image, self._gy[row], -si, ci * gx, (pose.x_m - self._x0_m) * inv,
                   -ci, -si * gx, (self._y0_m - pose.y_m) * inv, self._floor_f,
                   normals is not None, buf, pos, self._noise_std, out,
                   monotone=self._row_monotone[row])
        return out

    def add_noise(self, img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A copy of ``img`` (any shape) plus Gaussian noise of std ``noise_std`` (0-255
        scale) as uint8: the noise rounded half to even, added, saturated to 0..255
        (:func:`simrunner.sensors.line_row.add_noise_u8`). Only ``rng`` supplies randomness."""
        a = np.asarray(img)
        # = rng.normal(0, std, shape), draw for draw (normal is loc + scale * standard normal)
        noise = rng.standard_normal(a.shape)
        noise *= self._noise_std
        return add_noise_u8(a, noise)
