"""``simrunner calibrate-camera --scene track --track TRACK``: the camera gap from lines recorded
while driving, each with the car's pose (columns ``x_m``, ``y_m``, ``yaw_rad``).

Each frame's scene is the track at the recorded pose, as the car's camera sees it (the track's
light and reflectances, :class:`simrunner.sensors.imaging.Imager`'s scene without its sensor);
the poses are taken as recorded (not fitted) and motion blur is not modelled. The mean-line
effects of :mod:`.camera_fit` (``gain``, ``black_level``, ``vignetting``, ``blur``) are fitted
over all frames and chosen the same way, on held-out pixels; from the frames come
``startup_frames``, ``saturation``, ``dead_pixels``/``hot_pixels`` (a pixel constant while the
scene changes) and ``fixed_pattern`` (a per-pixel gain both halves of the frames show).
The frame-to-frame ``noise`` needs a still scene: record on a straight for it.
"""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from vehicle.description import CarDescription
from worlds.lighting import DEFAULT_AMBIENT_LUX

from simrunner.workflows.calibration.camera_fit import (CATALOGUE, MARGIN_PX, MODEL_DN, SHAPE_EFFECTS, CameraFit,
                                                        _car_after, _choose_effects, _fit, frame_effects,
                                                        pattern_effect, predicted, row_cos_theta, shape_effects)
from simrunner.workflows.calibration.camera_lines import Recording
from simrunner.workflows.calibration.measured import CalibrationError


class TrackScene:
    """The scene of every recorded frame (reflectance x lux / 500, ``W + 2 margin`` columns)
    and the mean-line model over them, flattened frame after frame (the interface of
    :class:`.camera_fit.StraightView`: ``mean_line(p)``, ``width``)."""

    nuisance = ()  # the poses are given: no scene parameters to fit

    def __init__(self, car: CarDescription, track, poses: np.ndarray) -> None:
        from pieces.pose import Pose2
        from simrunner.sensors.camera import Camera
        from simrunner.sensors.imaging import Imager

        cam = car.camera
        wide = dataclasses.replace(cam, model="linescan", psf_sigma_px=MARGIN_PX / 3.0)  # scene margin
        imager = Imager(Camera(wide, track, load_line_kernel=False), track.lighting,
                        surface_z_m=track.surface_z_m)
        row = cam.default_row
        self.scene = np.stack([imager.scene_lux(([x], [y], [yaw]), row, row + 1)[0]
                               for x, y, yaw in poses]) / DEFAULT_AMBIENT_LUX
        w = cam.width_px
        self.cos_theta = row_cos_theta(cam)
        self.profile = np.asarray(cam.vignetting_profile, np.float64) if cam.vignetting_profile else np.ones(w)
        self.frames, self.width = len(poses), w
        self._pose = Pose2

    def lines(self, p: dict[str, float]) -> np.ndarray:
        """``(N, W)`` modelled lines for the parameters ``p``."""
        sigma = p["blur"]
        if sigma > 1e-3:
            x = np.arange(-MARGIN_PX, MARGIN_PX + 1, dtype=np.float64)
            k = np.exp(-0.5 * (x / sigma) ** 2)
            k /= k.sum()
            s = np.stack([np.convolve(r, k, mode="valid") for r in self.scene])
        else:
            s = self.scene[:, MARGIN_PX:-MARGIN_PX]
        v = self.cos_theta ** p["vignetting"] * self.profile
        return np.clip(p["black_level"] + p["gain"] * v * s, 0.0, 255.0)

    def mean_line(self, p: dict[str, float]) -> np.ndarray:
        return self.lines(p).ravel()


def calibrate_track(rec: Recording, car: CarDescription, track) -> CameraFit:
    """Fit the camera of ``car`` to lines recorded at known poses on ``track``."""
    cam = car.camera
    if rec.poses is None:
        raise CalibrationError(f"{rec.where[0]}: --scene track needs the car's pose with every line: a "
                               f"header with columns x_m, y_m, yaw_rad (and p0 .. p{cam.width_px - 1})")
    if rec.frames.shape[1] != cam.width_px:
        raise CalibrationError(f"{rec.where[0]}: {rec.frames.shape[1]} pixels a line, expected "
                               f"camera.width_px = {cam.width_px}")
    pred = predicted(car)
    fixed = {"offset": 0.0, "scale": 1.0, "floor": 0.157, **{k: pred[k] for k in SHAPE_EFFECTS}}
    scene = TrackScene(car, track, rec.poses)
    before_all = scene.lines(fixed)
    # start-up frames: leading frames whose pattern is not what the car's camera sees there
    # (correlation below 0.5 with the modelled line, whatever the brightness; a flat frame has none)
    def follows(frame, model) -> bool:
        if np.ptp(frame) == 0 or np.ptp(model) == 0:
            return False
        return float(np.corrcoef(frame, model)[0, 1]) >= 0.5

    n_start = 0
    while n_start < len(rec.frames) - 2 and not follows(rec.frames[n_start], before_all[n_start]):
        n_start += 1
    frames = rec.frames[n_start:]
    if len(frames) < 10:
        raise CalibrationError(f"{rec.where[0]}: {len(frames)} usable frames: expected at least 10 (record 100 "
                               f"or more while driving)")
    scene = TrackScene(car, track, rec.poses[n_start:])
    line_before = scene.lines(fixed)
    # dead and hot pixels: constant while the scene under them changes
    constant = np.ptp(frames, axis=0) == 0
    changing = np.ptp(line_before, axis=0) > 20.0
    dead = constant & changing & (frames[0] <= frames.min() + 3.0)
    hot = constant & changing & (frames[0] >= 255.0)
    valid = np.broadcast_to(~(dead | hot), frames.shape).ravel()
    target = frames.ravel()
    chosen = _choose_effects(scene, target, valid, fixed)
    p_after, _ = _fit(scene, target, valid, {k: v for k, v in fixed.items()}, tuple(chosen)) if chosen \
        else (dict(fixed), None)
    for key in ("offset", "scale", "floor"):  # the track scene has no nuisance: poses are given
        p_after[key] = fixed[key]
    line_after = scene.lines(p_after)
    ok = ~(dead | hot)
    rmse_before = float(np.sqrt(np.mean((line_before - frames)[:, ok] ** 2)))
    rmse_after = float(np.sqrt(np.mean((line_after - frames)[:, ok] ** 2)))
    params, hints = shape_effects(chosen, p_after, pred, "the track's light")
    frame_effects(params, hints, car, pred, clipped=float(np.mean(frames[:, ok] >= 255.0)),
                  clipped_what="pixels are", dead=dead, hot=hot, against="scene", n_start=n_start)
    prnu = _track_pattern(frames, line_after, p_after["black_level"], ok)
    response = None
    if prnu is not None:  # measure it pixel by pixel: first half of the frames, tested on the second
        black = p_after["black_level"]
        half = len(frames) // 2
        g_first = _column_gains(frames[:half], line_after[:half], black)
        held_out = np.clip(black + (line_after[half:] - black) * g_first, 0.0, 255.0)
        rmse_after = float(np.sqrt(np.mean((held_out - frames[half:])[:, ok] ** 2)))
        response = _column_gains(frames, line_after, black)
        line_after = np.clip(black + (line_after - black) * response, 0.0, 255.0)
    pattern_effect(params, hints, prnu, pred)
    effects = [name for name in CATALOGUE if name in params]
    signal = float(np.median(np.maximum(line_after - p_after["black_level"], 0.0)[:, ok]))
    pattern = prnu if prnu is not None else pred["prnu"]
    floor = float(math.sqrt(pred["noise_dn"] ** 2 + 1.0 / 12 + (pattern * signal) ** 2))
    unexplained = ""
    if rmse_after > 1.5 * floor + MODEL_DN:
        resid = np.sqrt(np.mean((line_after - frames) ** 2, axis=0)) * ok
        worst = np.argsort(-resid)[:5]
        unexplained = (f"{rmse_after:.2f} grey levels remain (noise and fixed pattern explain {floor:.2f}), "
                       f"largest at columns {', '.join(str(int(c)) for c in sorted(worst))} (poses off, or "
                       f"motion blur at speed?)")
    return CameraFit(effects=effects, parameters=params, hints=hints, rmse_before=rmse_before,
                     rmse_after=rmse_after, noise_floor=floor, nuisance={}, frames_used=len(frames),
                     car_after=_car_after(car, pred, params, response), unexplained=unexplained, scene="track",
                     response_measured=response is not None,
                     lines={"recorded": frames.mean(axis=0), "before": line_before.mean(axis=0),
                            "after": line_after.mean(axis=0)})


def _column_gains(frames, line, black) -> np.ndarray:
    """Each column's mean ratio of recorded to modelled signal where the model is well lit (1
    where it never is): the pixels' own gains."""
    sig = line - black
    lit = sig > 0.5 * np.percentile(sig, 95)
    ratio = np.where(lit, (frames - black) / np.maximum(sig, 1.0), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        g = np.nanmean(ratio, axis=0)
    return np.where(np.sum(lit, axis=0) >= 3, g, 1.0)


def _track_pattern(frames, line, black, ok) -> float | None:
    """A per-pixel gain pattern both halves of the frames show (correlation > 0.5), as the
    spread of its shared part; None when there is none. Pixels count where the modelled line
    is well lit (more than half its brightest)."""
    sig = line - black
    lit = sig > 0.5 * np.percentile(sig, 95)
    half = len(frames) // 2
    pats = []
    for part, model, mask in ((frames[:half], sig[:half], lit[:half]), (frames[half:], sig[half:], lit[half:])):
        ratio = np.where(mask, (part - black) / np.maximum(model, 1.0) - 1.0, np.nan)
        counts = np.sum(mask, axis=0)
        with warnings.catch_warnings():  # columns never lit: no mean, left out below
            warnings.simplefilter("ignore", RuntimeWarning)
            pats.append(np.where(counts >= 3, np.nanmean(ratio, axis=0), np.nan))
    a, b = pats
    use = ok & np.isfinite(a) & np.isfinite(b)
    if use.sum() < 16:
        return None
    a, b = a[use] - np.mean(a[use]), b[use] - np.mean(b[use])
    if np.std(a) == 0 or np.std(b) == 0 or float(np.corrcoef(a, b)[0, 1]) < 0.5:
        return None
    return float(math.sqrt(max(np.mean(a * b), 0.0)))


def record_track(car: CarDescription, track, poses: np.ndarray, *, seed: int = 0) -> np.ndarray:
    """The lines the car's own camera records at ``poses`` (``(N, 3)``: x_m, y_m, yaw_rad) on
    ``track``, from power-up, the car standing at each (no motion blur): ``(N, W)`` float, for
    checking the fit (tests, bench)."""
    from pieces.pose import Pose2
    from simrunner.sensors.camera import Camera
    from simrunner.sensors.imaging import Imager

    cam = car.camera
    camera = Camera(cam, track, load_line_kernel=False)
    rng = np.random.default_rng(seed)
    if cam.model == "ideal":
        return np.array([camera.line_image(Pose2(*p), cam.default_row, rng)[0] for p in poses], float)
    imager = Imager(camera, track.lighting, surface_z_m=track.surface_z_m)
    return np.array([imager.line(Pose2(*p), cam.default_row, exposure_s=cam.exposure_s, normals=rng,
                                 frame_index=k + 1)[0] for k, p in enumerate(poses)], float)
