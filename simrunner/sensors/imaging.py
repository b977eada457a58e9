"""The physical camera (``camera.model = "linescan"`` or ``"area"``): light to electrons to ADC counts.

One chain per pixel, the linear camera model of the EMVA 1288 standard (release 4.0), so the
numbers a camera maker publishes go straight into the car file (docs/camera.md):

1. **Scene.** The ground point the pixel's ray meets (:class:`~simrunner.sensors.camera.Camera`'s
   pinhole geometry) has a reflectance ``rho`` (the track's lane, line or floor reflectance,
   :class:`worlds.lighting.TrackLighting`; by default the raster's grey level / 255: lane
   0.92, edge lines 0.06, floor 0.16) and is lit with an illuminance ``E`` in lux: the
   track's ambient level plus its lamps (inverse-square law, Lambert's cosine, spot cones).
   A matte (Lambertian) surface then has the luminance ``rho E / pi``; the lamps also give a
   glossy highlight, Blinn-Phong ``k_s (s + 8) / (8 pi) cos(n, h)^s E_lamp`` (``k_s`` the
   track's ``specular``, ``s = SHININESS``, ``h`` half-way between the directions to the lamp
   and to the camera).
2. **Lens.** The image-plane illuminance is ``rho E tau / (4 N^2)`` on the optical axis (``tau``
   the lens transmission, ``N`` the f-number), times ``cos(theta)^n`` (``n =
   vignetting_power``, 4 for the natural cos^4 law; ``theta`` the ray's angle to the axis) and
   an optional measured per-column profile. The lens blurs it with a Gaussian point-spread
   function of ``psf_sigma_px`` pixels along the row (the row is sampled ``3 sigma`` beyond
   both ends so the blur sees the scene outside the array) and, for an area camera, across
   the rows too. While the shutter is open the
   car moves: the image is the mean over ``motion_blur_samples`` poses spread across the
   exposure, found by running the car's current speed and yaw rate backwards.
3. **Pixel.** Photons ``mu_p = E_img A t k`` (``A`` the pixel area, ``t`` the exposure, ``k =
   PHOTONS_PER_LM_S`` photons per lumen-second of white light), electrons ``mu_e = eta mu_p (1 +
   PRNU_i) + dark_current t`` with ``eta`` the quantum efficiency and ``PRNU_i``,
   ``DSNU_i`` this camera's fixed pattern (drawn once from ``fixed_pattern_seed``).
4. **Noise.** Shot noise ``sqrt(mu_e)`` in the well and dark (read) noise ``dark_noise_e`` in
   the read-out chain, Gaussian, from the run's standard-normal stream (two normals per pixel
   per frame), only when the image asks for noise (``get_image(line, add_noise=True)``, the
   default).
5. **Saturation and ADC.** Electrons are clipped to ``[0, saturation_capacity_e]`` (the full
   well), then the pixel's dark offset ``DSNU_i`` and the read noise are added (they belong to
   the read-out chain, so they show below the black level too); a dead pixel reads the black level, a hot one the
   ADC's maximum. The ADC reads ``black_level_dn + K e`` with ``K =
   analog_gain (2^bits - 1) / saturation_capacity_e`` (at gain 1 a full pixel reaches the
   ADC's maximum), rounded half to even and clipped to ``[0, 2^bits - 1]``; the image is 8-bit
   (more bits are shifted down to the top 8, fewer shifted up).
6. **Power-up.** The first ``startup_frames`` frames of a run read full: the pixels integrated
   from power-up to the first SI pulse.

The frame time is the end of the read-out: a ``linescan`` frame integrated over
``[t - readout_s - exposure, t - readout_s]``, an ``area`` frame over ``[t - exposure, t]``.
Everything is float64 NumPy in a fixed order: the same inputs and normals give the same bytes.
The debug video's camera view (:meth:`Imager.preview`) samples the scene with OpenCV's
fixed-point bilinear remap instead: at most 1 DN from :meth:`Imager.frame`, at about half the cost.
"""
from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from pieces.pose import Pose2, Pose3
from worlds.lighting import SHININESS, TrackLighting

# Photons per lumen-second of white light: a white LED's spectrum gives ~300 lm per radiant
# watt (luminous efficacy of radiation) at a mean photon energy of ~3.5e-19 J (~560 nm), so
# 1 lm s = 1/300 J = 9.4e15 photons. (Monochromatic 555 nm light would give 4.1e15.)
PHOTONS_PER_LM_S = 9.4e15


def _gaussian_kernel(sigma_px: float) -> np.ndarray:
    """The normalised Gaussian of ``sigma_px`` sampled at whole pixels out to 3 sigma (``[1]``
    for a sharp lens)."""
    if sigma_px <= 0.0:
        return np.ones(1)
    m = int(math.ceil(3.0 * sigma_px))
    x = np.arange(-m, m + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma_px) ** 2)
    return k / k.sum()


_PAD_BEFORE, _PAD_AFTER = 2, 3  # bilinear_f64 clamps corners to -2 .. size + 2


def pad_with_floor(image: np.ndarray, floor: float) -> np.ndarray:
    """``image`` inside a border of ``floor`` (2 pixels before, 3 after each axis: every
    corner :func:`bilinear_f64` reads outside the image), in the image's dtype when that
    holds ``floor`` exactly, else float64: the ``padded`` argument of :func:`bilinear_f64`."""
    pad = ((_PAD_BEFORE, _PAD_AFTER), (_PAD_BEFORE, _PAD_AFTER))
    if np.issubdtype(image.dtype, np.integer):
        info = np.iinfo(image.dtype)
        if float(floor).is_integer() and info.min <= floor <= info.max:
            return np.pad(image, pad, constant_values=int(floor))
    return np.pad(image.astype(np.float64), pad, constant_values=float(floor))


def bilinear_f64(image: np.ndarray, sx: np.ndarray, sy: np.ndarray, floor: float, *,
                 ends_only: bool = False, padded: np.ndarray | None = None) -> np.ndarray:
    """Bilinear float64 value of ``image`` at raster coordinates ``(sx, sy)`` (col, row; any
    equal shapes), ``floor`` for neighbours outside the image (unrounded: the physical
    camera's scene). ``ends_only``: each last-axis line of points is a straight segment, so
    its extreme coordinates are at its two ends (a cheaper inside test). ``padded``:
    ``pad_with_floor(image, floor)``, for points near or outside the border (one read per
    corner instead of a masked one: the same values)."""
    h, w = image.shape
    if ends_only:
        ex, ey = sx[..., ::sx.shape[-1] - 1], sy[..., ::sy.shape[-1] - 1]
        inside = ex.min() >= 0 and ex.max() < w - 1 and ey.min() >= 0 and ey.max() < h - 1
    fx = np.floor(sx)
    fy = np.floor(sy)
    ax = sx - fx
    ay = sy - fy
    flat = image.ravel()
    if not ends_only:
        inside = fx.min() >= 0 and fx.max() < w - 1 and fy.min() >= 0 and fy.max() < h - 1
    if inside:
        idx = fy.astype(np.intp) * w + fx.astype(np.intp)
        p00 = flat.take(idx).astype(np.float64)
        p01 = flat.take(idx + 1).astype(np.float64)
        p10 = flat.take(idx + w).astype(np.float64)
        p11 = flat.take(idx + (w + 1)).astype(np.float64)
    elif padded is not None:  # NaN (a ray through nothing) reads floor, as below
        ix = np.fmin(np.fmax(fx, -2.0), w + 1.0).astype(np.intp)
        iy = np.fmin(np.fmax(fy, -2.0), h + 1.0).astype(np.intp)
        pw = w + _PAD_BEFORE + _PAD_AFTER
        idx = (iy + _PAD_BEFORE) * pw + (ix + _PAD_BEFORE)
        flat = padded.ravel()
        p00 = flat.take(idx).astype(np.float64)
        p01 = flat.take(idx + 1).astype(np.float64)
        p10 = flat.take(idx + pw).astype(np.float64)
        p11 = flat.take(idx + (pw + 1)).astype(np.float64)
    else:
        ix = np.clip(fx, -2.0, w + 1.0).astype(np.intp)
        iy = np.clip(fy, -2.0, h + 1.0).astype(np.intp)

        def corner(dx: int, dy: int) -> np.ndarray:
            cx, cy = ix + dx, iy + dy
            ok = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
            v = flat.take(np.where(ok, cy * w + cx, 0)).astype(np.float64)
            v[~ok] = floor
            return v

        p00, p01, p10, p11 = corner(0, 0), corner(1, 0), corner(0, 1), corner(1, 1)
    p01 -= p00
    p01 *= ax
    p01 += p00  # top
    p11 -= p10
    p11 *= ax
    p11 += p10  # bottom
    p11 -= p01
    p11 *= ay
    p11 += p01
    return p11


def blur_rows(scene: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Each row of ``scene`` (``(R, L)`` float64) convolved with ``kernel`` (``n`` taps),
    ``mode="valid"``: ``(R, L - n + 1)``, a read-only view. Bit for bit
    ``np.stack([np.convolve(r, kernel, "valid") for r in scene])``, in one call: the rows are
    convolved laid end to end (each output is the same dot product of the same ``n``
    values) and the outputs that straddle two rows are left out."""
    n_out = scene.shape[1] - len(kernel) + 1
    joined = np.convolve(np.ascontiguousarray(scene).ravel(), kernel, mode="valid")
    step = joined.itemsize
    return np.lib.stride_tricks.as_strided(joined, (len(scene), n_out), (scene.shape[1] * step, step),
                                           writeable=False)


class Imager:
    """The physical camera of ``camera`` (a :class:`~simrunner.sensors.camera.Camera` whose
    spec has ``model`` ``"linescan"`` or ``"area"``), lit by ``lighting``.

    :meth:`line` and :meth:`frame` give what ``get_image(row)`` and ``get_image()`` return.
    Per-pixel constants (lens fall-off, fixed pattern) are computed once here."""

    def __init__(self, camera, lighting: TrackLighting | None = None, *, surface_z_m: float = 0.0) -> None:
        spec = camera.cam
        if spec.model not in ("linescan", "area"):
            raise ValueError(f"Imager: camera model {spec.model!r} is not a physical camera")
        self.camera = camera
        self.spec = spec
        self.lighting = lighting if lighting is not None else TrackLighting()
        self.surface_z_m = float(surface_z_m)
        # reflectance image: the raster itself when reflectance = grey / 255, else a 16-bit map
        raster = camera.raster
        lut = self.lighting.reflectance_of_gray()
        if np.array_equal(lut, np.arange(256) / 255.0):
            self._refl_image, self._refl_scale = raster.image, 1.0 / 255.0
        else:
            self._refl_image = np.rint(lut[raster.image] * 65535.0).astype(np.uint16)
            self._refl_scale = 1.0 / 65535.0
        self._refl_floor = float(lut[int(raster.floor_gray)]) / self._refl_scale
        w, h = camera.width_px, camera.height_px
        self._kernel = _gaussian_kernel(float(spec.psf_sigma_px))
        self._margin = (len(self._kernel) - 1) // 2
        # ray angle to the optical axis at each pixel centre (pinhole: f_px, u right, v down)
        u = np.arange(w) + 0.5 - w / 2.0
        v = np.arange(h) + 0.5 - h / 2.0
        f = camera.f_px
        cos_theta = f / np.sqrt(f * f + u[None, :] ** 2 + v[:, None] ** 2)
        fall_off = cos_theta ** float(spec.vignetting_power)
        if spec.vignetting_profile:
            fall_off = fall_off * np.asarray(spec.vignetting_profile, np.float64)[None, :]
        lens = float(spec.lens_transmission) / (4.0 * float(spec.f_number) ** 2)
        electrons_per_lux_s = float(spec.quantum_efficiency) * float(spec.pixel_area_um2) * 1e-12 * PHOTONS_PER_LM_S
        # this camera's fixed pattern: one generator per physical camera, not per run
        fp = np.random.default_rng(int(spec.fixed_pattern_seed))
        prnu = fp.standard_normal((h, w)) * float(spec.prnu)
        dsnu = fp.standard_normal((h, w)) * float(spec.dsnu_e)
        n_dead, n_hot = int(spec.dead_pixels), int(spec.hot_pixels)
        places = fp.choice(h * w, n_dead + n_hot, replace=False) if n_dead + n_hot else np.zeros(0, np.intp)
        self.dead = np.zeros((h, w), bool)
        self.hot = np.zeros((h, w), bool)
        self.dead.flat[places[:n_dead]] = True
        self.hot.flat[places[n_dead:]] = True
        # electrons per (lux s) of scene illuminance x reflectance, per pixel
        self.gain_e_per_lux_s = lens * fall_off * electrons_per_lux_s * (1.0 + prnu)
        self.dsnu_e = dsnu
        self.full_e = float(spec.saturation_capacity_e)
        self.adc_max = float(2 ** int(spec.adc_bits) - 1)
        self.k_dn_per_e = float(spec.analog_gain) * self.adc_max / self.full_e
        self._shift = int(spec.adc_bits) - 8
        self._any_defect = bool(n_dead + n_hot)
        self._dark_current_eps = float(spec.dark_current_eps)
        self._dark_noise_e = float(spec.dark_noise_e)
        self._black_dn = float(spec.black_level_dn)
        self._lead_s = float(spec.readout_s) if spec.model == "linescan" else 0.0
        self._rows: dict[tuple[int, int], tuple] = {}
        self._solid_rays: dict[tuple[int, int], tuple] = {}
        self._terrain_rays: dict[tuple[int, int], np.ndarray] = {}  # rows -> car-frame rays (hills)
        self._inv_m = 1.0 / camera.raster.m_per_px
        self._x0_m, self._y0_m = (float(c) for c in camera.raster.origin_xy_m)

    @functools.cached_property
    def _refl_padded(self) -> np.ndarray:
        """The reflectance image in a border of its floor (:func:`pad_with_floor`; made on
        first use: rows that see past the raster, as the upper rows of a whole frame do)."""
        return pad_with_floor(self._refl_image, self._refl_floor)

    # -- geometry ------------------------------------------------------------------
    def _rows_ground(self, r0: int, r1: int):
        """Car-frame ground points of rows ``r0 .. r1 - 1`` sampled ``margin`` pixels beyond
        both ends: ``gx``, ``gy`` (``(r1 - r0, W + 2 margin)``, 0 where the ray misses the
        ground), ``miss`` (bool, same shape) and whether any ray misses; cached."""
        got = self._rows.get((r0, r1))
        if got is None:
            cam, m = self.camera, self._margin
            u = np.arange(-m, cam.width_px + m) + 0.5 - cam.width_px / 2.0
            v = np.arange(r0, r1) + 0.5 - cam.height_px / 2.0
            gx, gy, ok = cam._ground(v[:, None], u[None, :])
            # a row of single rays shares one ground x: its raster footprint is a segment
            segment = bool(ok.all()) and bool(np.all(gx == gx[:, :1]))
            got = (np.where(ok, gx, 0.0), np.where(ok, gy, 0.0), ~ok, not ok.all(), segment)
            self._rows[(r0, r1)] = got
        return got

    def exposure_poses(self, pose: Pose2, exposure_s: float, twist) -> list[Pose2]:
        """The poses averaged over the exposure ending the frame at ``pose``: ``twist =
        (vx_mps, vy_mps, yaw_rate_radps)`` (body frame) run backwards, constant over it."""
        return [Pose2(*p) for p in zip(*self._exposure_arrays(pose, exposure_s, twist))]

    def _exposure_arrays(self, pose: Pose2, exposure_s: float, twist):
        """``exposure_poses`` as three lists: x_m, y_m, yaw_rad."""
        n = int(self.spec.motion_blur_samples)
        if n <= 1 or twist is None:
            return [pose.x_m], [pose.y_m], [pose.yaw_rad]
        vx, vy, w = twist
        lead = self._lead_s
        xs, ys, yaws = [], [], []
        x, y, yaw = pose.x_m, pose.y_m, pose.yaw_rad
        for j in range(n):
            tau = lead + exposure_s * (j + 0.5) / n
            mid = yaw - 0.5 * w * tau
            c, s = math.cos(mid), math.sin(mid)
            xs.append(x - (vx * c - vy * s) * tau)
            ys.append(y - (vx * s + vy * c) * tau)
            yaws.append(yaw - w * tau)
        return xs, ys, yaws

    def _terrain_ground(self, lift: Pose3, r0: int, r1: int):
        """Car-frame ground points of rows ``r0 .. r1 - 1`` (``W + 2 margin`` columns) on a track
        with hills: the rays cast onto the terrain from the frame's pose ``lift`` (a ``Pose3``),
        the hits expressed in its planar frame (``gx``, ``gy``, 0 where they miss) and ``miss``.
        The motion-blur poses move these points as on flat ground (they are mm apart)."""
        cam, m = self.camera, self._margin
        rays = self._terrain_rays.get((r0, r1))
        if rays is None:
            u = (np.arange(-m, cam.width_px + m) + 0.5 - cam.width_px / 2.0)[None, :]
            v = (np.arange(r0, r1) + 0.5 - cam.height_px / 2.0)[:, None]
            rays = self._terrain_rays[(r0, r1)] = cam.rays(v, u)
        wx, wy, miss = cam.world_points(lift, rays=rays)
        c, s = math.cos(lift.yaw_rad), math.sin(lift.yaw_rad)
        dx, dy = wx - lift.x_m, wy - lift.y_m
        gx, gy = c * dx + s * dy, c * dy - s * dx
        gx[miss] = 0.0
        gy[miss] = 0.0
        return gx, gy, miss

    def scene_lux(self, poses, r0: int, r1: int, lift: Pose3 | None = None, *, remap: bool = False) -> np.ndarray:
        """Reflectance x illuminance (lux; plus the lamps' highlights) seen along rows ``r0 ..
        r1 - 1`` over ``W + 2 margin`` columns, the mean over ``poses`` (``(x_m, y_m,
        yaw_rad)`` lists): ``(r1 - r0, W + 2 margin)``. ``lift`` (the frame's ``Pose3``, on a
        track with hills unless the view is clear of them) casts the rays onto the terrain from
        the camera's height, pitch and roll. ``remap``: sample the reflectance with OpenCV's
        bilinear remap (its weights in 1/32 pixel, the value rounded to the image's type: within
        1 DN of the exact sampling in the final image; one pose only), as :meth:`preview` does."""
        inv = self._inv_m
        xs, ys, yaws = poses
        n = len(xs)
        if lift is not None:
            gx, gy, miss = self._terrain_ground(lift, r0, r1)
            any_miss, segment = bool(miss.any()), False
        else:
            gx, gy, miss, any_miss, segment = self._rows_ground(r0, r1)
        if n == 1:
            c, s = math.cos(yaws[0]), math.sin(yaws[0])
            wx = gx * c
            wx -= gy * s
            wx += xs[0]
            wy = gx * s
            wy += gy * c
            wy += ys[0]
        else:
            yaw = np.array(yaws)[:, None, None]
            c, s = np.cos(yaw), np.sin(yaw)
            wx = np.array(xs)[:, None, None] + c * gx - s * gy
            wy = np.array(ys)[:, None, None] + s * gx + c * gy
        sx = wx - self._x0_m
        sx *= inv
        sy = self._y0_m - wy
        sy *= inv
        if remap and n == 1:
            scene = cv2.remap(self._refl_image, sx.astype(np.float32), sy.astype(np.float32), cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=self._refl_floor).astype(np.float64)
        else:
            scene = bilinear_f64(self._refl_image, sx, sy, self._refl_floor, ends_only=segment,
                                 padded=self._refl_padded)
        if any_miss:
            scene[..., miss] = self._refl_floor
        lighting = self.lighting
        if not lighting.lights and not lighting.shades:
            scene *= lighting.ambient_lux * self._refl_scale
        else:
            scene *= lighting.illuminance_lux(wx, wy, self.surface_z_m) * self._refl_scale
            if lighting.specular > 0.0 and lighting.lights:
                scene += self._highlights(wx, wy, xs, ys, yaws)
        if self.camera.solids:
            self._paint_solids(scene, xs, ys, yaws, r0, r1)
        if n == 1:
            return scene
        scene *= 1.0 / n
        return scene.sum(axis=0)

    def _paint_solids(self, scene: np.ndarray, xs, ys, yaws, r0: int, r1: int) -> None:
        """The solids standing on the track in front of the ground, in place: reflectance x the
        illuminance at the hit point x the face's sky factor (:mod:`simrunner.sensors.solids`)."""
        from simrunner.sensors.solids import camera_hits, camera_rays, sky_factor

        cam, solids = self.camera, self.camera.solids
        rays = self._solid_rays.get((r0, r1))
        if rays is None:
            m = self._margin
            u = np.arange(-m, cam.width_px + m) + 0.5 - cam.width_px / 2.0
            v = np.arange(r0, r1) + 0.5 - cam.height_px / 2.0
            rays = self._solid_rays[(r0, r1)] = camera_rays(cam.cam, v[:, None], u[None, :])
        refl = np.array([s.reflectance for s in solids])
        lighting = self.lighting
        for j, pose in enumerate(zip(xs, ys, yaws)):
            hits = camera_hits(solids, self.surface_z_m, cam.cam, Pose2(*pose), rays)
            if hits is None:
                continue
            mask, idx, nz, hx, hy = hits
            if not lighting.lights and not lighting.shades:
                lux = np.full(int(mask.sum()), float(lighting.ambient_lux))
            else:
                lux = lighting.illuminance_lux(hx[mask], hy[mask], self.surface_z_m)
            target = scene if scene.ndim == 2 else scene[j]
            target[mask] = refl[idx[mask]] * lux * sky_factor(nz[mask])

    def _highlights(self, wx, wy, xs, ys, yaws) -> np.ndarray:
        """The lamps' glossy reflection toward the camera (Blinn-Phong, the module docstring)
        at the surface points ``(wx, wy)`` seen from the camera of each pose."""
        spec, z_s = self.spec, self.surface_z_m
        f = float(spec.forward_m)
        if wx.ndim == 3:  # one camera position per pose
            yaw = np.array(yaws)[:, None, None]
            px = np.array(xs)[:, None, None] + f * np.cos(yaw)
            py = np.array(ys)[:, None, None] + f * np.sin(yaw)
        else:
            px, py = xs[0] + f * math.cos(yaws[0]), ys[0] + f * math.sin(yaws[0])
        vx, vy, vz = px - wx, py - wy, float(spec.height_m)
        vn = np.sqrt(vx * vx + vy * vy + vz * vz)
        k = self.lighting.specular * (SHININESS + 8.0) / 8.0
        out = np.zeros(np.shape(wx))
        for lamp in self.lighting.lights:
            lx, ly, lz = lamp.x_m - wx, lamp.y_m - wy, lamp.z_m - z_s
            ln = np.sqrt(lx * lx + ly * ly + lz * lz)
            hx, hy, hz = lx / ln + vx / vn, ly / ln + vy / vn, lz / ln + vz / vn
            cos_h = hz / np.sqrt(hx * hx + hy * hy + hz * hz)
            out += k * cos_h ** SHININESS * lamp.illuminance_lux(wx, wy, z_s)
        return out * self.lighting.shade_factor(wx, wy) if self.lighting.shades else out

    # -- the sensor ----------------------------------------------------------------
    def _expose(self, scene: np.ndarray, r0: int, r1: int, exposure_s: float, normals,
                frame_index: int) -> np.ndarray:
        """ADC image (uint8 ``(r1 - r0, W)``) of ``scene`` (``scene_lux`` of those rows)."""
        spec = self.spec
        blurred = scene
        if self._margin:  # the PSF along the row (k is symmetric); a line is bit for bit
            blurred = blur_rows(scene, self._kernel)  # its frame's row
        rows = slice(r0, r1)
        startup = int(spec.startup_frames)
        if startup and frame_index <= startup:  # frame 1 is the first read after power-up
            e = np.full(blurred.shape, self.full_e)
        else:
            e = self.gain_e_per_lux_s[rows] * blurred
            e *= exposure_s
            e += self._dark_current_eps * exposure_s
            z = None
            if normals is not None:
                z = normals.standard_normal((2,) + e.shape)
                shot = np.maximum(e, 0.0)
                np.sqrt(shot, out=shot)
                shot *= z[0]
                e += shot
            np.minimum(np.maximum(e, 0.0, out=e), self.full_e, out=e)  # the full well
            e += self.dsnu_e[rows]  # the read-out chain, after the well: its dark offset ...
            if z is not None:  # ... and its dark (read) noise, which shows below the black level too
                z[1] *= self._dark_noise_e
                e += z[1]
            if self._any_defect:
                e[self.dead[rows]] = 0.0
                e[self.hot[rows]] = self.full_e * 2.0  # past the ADC's maximum at any gain >= 0.5
        e *= self.k_dn_per_e
        e += self._black_dn
        np.rint(e, out=e)
        np.minimum(np.maximum(e, 0.0, out=e), self.adc_max, out=e)
        out = e.astype(np.int64)
        if self._shift > 0:
            out >>= self._shift
        elif self._shift < 0:
            out <<= -self._shift
        return out.astype(np.uint8)

    def _scene_rows(self, poses, r0: int, r1: int, lift: Pose3 | None = None, remap: bool = False) -> np.ndarray:
        """``scene_lux`` of rows ``r0 .. r1 - 1``; an area camera's lens blurs across rows
        too: the rows around them are sampled (clamped at the image's top and bottom) and
        mixed with the same Gaussian (a line sensor is one row: its blur is along the row
        only)."""
        m = self._margin
        if self.spec.model != "area" or not m:
            return self.scene_lux(poses, r0, r1, lift, remap=remap)
        h = self.camera.height_px
        lo, hi = max(r0 - m, 0), min(r1 - 1 + m, h - 1)
        scene = self.scene_lux(poses, lo, hi + 1, lift, remap=remap)
        out = np.zeros((r1 - r0, scene.shape[1]))
        for j, weight in enumerate(self._kernel):
            src = np.clip(np.arange(r0, r1) + (j - m), 0, h - 1) - lo
            out += weight * scene[src]
        return out

    def line(self, pose: Pose2, row: int, *, exposure_s: float, twist=None, normals=None,
             frame_index: int = 1 << 30) -> np.ndarray:
        """Row ``row`` as ``(1, W) uint8``: the frame ending at ``pose`` after ``exposure_s``
        of integration (``twist``: the car's body-frame ``(vx, vy, yaw rate)`` for motion
        blur; ``normals``: the temporal noise's stream, None for none; ``frame_index``: the
        frame number since power-up, 1 for the first read)."""
        poses = self._exposure_arrays(pose, exposure_s, twist)
        cam = self.camera
        lift = None if cam.terrain is None or cam._view_is_flat(pose, row) else cam.lifted(pose)
        return self._expose(self._scene_rows(poses, row, row + 1, lift), row, row + 1, exposure_s, normals,
                            frame_index)

    def frame(self, pose: Pose2, *, exposure_s: float, twist=None, normals=None,
              frame_index: int = 1 << 30) -> np.ndarray:
        """The whole ``(H, W) uint8`` image (every row exposed as :meth:`line` exposes one)."""
        h = self.camera.height_px
        poses = self._exposure_arrays(pose, exposure_s, twist)
        lift = self.camera.lifted(pose) if self.camera.terrain is not None else None
        return self._expose(self._scene_rows(poses, 0, h, lift), 0, h, exposure_s, normals, frame_index)

    def preview(self, pose: Pose2, *, exposure_s: float) -> np.ndarray:
        """:meth:`frame` at ``pose`` without noise or motion blur, the scene sampled by OpenCV's
        remap (``scene_lux(remap=True)``): within 1 DN of it at about half the cost. The debug
        video's camera view where the controller took no image."""
        h = self.camera.height_px
        poses = self._exposure_arrays(pose, exposure_s, None)
        lift = self.camera.lifted(pose) if self.camera.terrain is not None else None
        return self._expose(self._scene_rows(poses, 0, h, lift, remap=True), 0, h, exposure_s, None, 1 << 30)
