"""The camera procedures of ``simrunner calibrate`` a team can do in a hall (docs/calibration.md):

* ``[camera_dark]``: lines recorded with the lens covered. The black level is the median of
  the pixels' means, the dark signal non-uniformity (DSNU) their spread (less the part the
  temporal noise leaves in a mean), the dark noise the pixels' spread from frame to frame, hot
  pixels those far above the rest (EMVA 1288, dark measurements).
* ``[camera_flat]``: lines recorded looking at an evenly lit white card that fills the view,
  neither clipped nor dark. The fall-off toward the ends is fitted as ``cos(theta)^power``; each
  pixel's response over that is measured and written as ``camera.vignetting_profile`` (with
  ``camera.prnu = 0``: the measured pattern replaces the seeded one); dead pixels are those that
  do not respond.
* ``[camera_sweep]``: the same card at several exposures. The mean signal at the line's centre
  must grow linearly with the exposure until it clips; the photon transfer curve (temporal
  variance against mean signal, EMVA 1288) gives the system gain ``K`` in counts per electron,
  hence the saturation capacity. At 8 bits a camera quieter than about one count shows no
  usable variance: then only linearity and the clipping exposure are reported.

Every file is one recording (one frame a row; :mod:`.camera_lines`), named relative to the
measurements file. Each procedure compares the car file's camera with the recording before and
after (dark level, fall-off at the ends, signal per millisecond) and changes only what it
measured.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from vehicle.description import CarDescription

from simrunner.workflows.calibration.camera_fit import row_cos_theta
from simrunner.workflows.calibration.camera_lines import read_file
from simrunner.workflows.calibration.measured import CalibrationError, Measurements
from simrunner.workflows.calibration.procedure import Check, ProcedureResult, range_checked

HOT_DN = 40.0  # a dark-frame pixel this far above the black level is hot
DEAD_FRACTION = 0.2  # a flat-field pixel below this fraction of its neighbours' response is dead


def _lines(m: Measurements, section: str, name: str, width: int, *, flat_ok: bool) -> np.ndarray:
    path = Path(name)
    if not path.is_absolute():
        path = Path(m.path).parent / path
    try:
        frames, _, _, _ = read_file(path, width, allow_flat=flat_ok)
    except CalibrationError as exc:
        raise CalibrationError(f"{m.where(section, 'lines')}: {exc}") from None
    return frames


def _k8(cam) -> float:
    """Counts (8-bit) per electron of the car file's camera."""
    return cam.analog_gain * (2 ** cam.adc_bits - 1) / cam.saturation_capacity_e / 2 ** (cam.adc_bits - 8)


def _physical(car: CarDescription) -> CarDescription:
    """The car with a physical camera (an ideal one becomes the default line camera, keeping
    its geometry): the procedures measure sensor numbers an ideal camera has not."""
    cam = car.camera
    if cam.model != "ideal":
        return car
    from simrunner.workflows.calibration.camera_fit import GEOMETRY_FIELDS

    return car.replace(camera=dataclasses.replace(CarDescription().camera,
                                                  **{f: getattr(cam, f) for f in GEOMETRY_FIELDS}))


def camera_dark(car: CarDescription, m: Measurements, v: dict, dt_s: float):
    """``[camera_dark]``: black level, DSNU, dark noise and hot pixels from a covered lens."""

    car = _physical(car)
    cam = car.camera
    frames = _lines(m, "camera_dark", v["lines"], cam.width_px, flat_ok=True)
    n = len(frames)
    mean = frames.mean(axis=0)
    black = float(np.median(mean))
    hot = mean > black + HOT_DN
    sd = frames.std(axis=0, ddof=1) if n > 1 else np.zeros(cam.width_px)
    temporal = float(np.median(sd[~hot]))
    spread = float(np.std(mean[~hot]))
    dsnu_dn = math.sqrt(max(spread ** 2 - temporal ** 2 / max(n, 1) - 1.0 / (12 * max(n, 1)), 0.0))
    k8 = _k8(cam)
    scale = 2 ** (cam.adc_bits - 8)
    exposure = v["exposure_s"] if v["exposure_s"] is not None else cam.exposure_s
    dark_current_dn = k8 * cam.dark_current_eps * exposure
    changes, notes = {}, []
    new = dict(black_level_dn=min(max((black - dark_current_dn) * scale, 0.0), 65535.0),
               dsnu_e=min(dsnu_dn / k8, 1e8))
    if temporal > 0.6:  # below about half a count the 8-bit reading hides the noise
        new["dark_noise_e"] = min(math.sqrt(max(temporal ** 2 - 1.0 / 12, 0.0)) / k8, 1e8)
    else:
        notes.append(f"dark noise {temporal:.2f} counts: below what 8-bit lines show; camera.dark_noise_e kept")
    new["hot_pixels"] = int(round(np.count_nonzero(hot) * cam.height_px))
    cam_after = dataclasses.replace(cam, **new)
    for key, value in new.items():
        changes[f"camera.{key}"] = (getattr(cam, key), value)
    after = range_checked(car.replace(camera=cam_after), m, "camera_dark")
    notes.append(f"{n} frames; black level {black:.2f}, pixel-to-pixel spread {spread:.2f}, frame-to-frame "
                 f"{temporal:.2f} counts; {np.count_nonzero(hot)} hot pixel(s)"
                 + (f" at {', '.join(str(int(c)) for c in np.flatnonzero(hot)[:8])}" if hot.any() else ""))
    before_black = cam.black_level_dn / scale + dark_current_dn
    after_black = after.camera.black_level_dn / scale + dark_current_dn
    checks = (Check("dark level (8-bit)", "counts", black, before_black, after_black),
              Check("pixel-to-pixel dark spread", "counts", dsnu_dn, cam.dsnu_e * k8, after.camera.dsnu_e * k8))
    return after, ProcedureResult("camera_dark", "dark frame: black level, DSNU, dark noise, hot pixels",
                                  changes, checks, tuple(notes), {"black_dn": black, "hot": int(hot.sum())})


def camera_flat(car: CarDescription, m: Measurements, v: dict, dt_s: float):
    """``[camera_flat]``: the fall-off toward the ends and each pixel's response."""
    from scipy.optimize import least_squares


    car = _physical(car)
    cam = car.camera
    frames = _lines(m, "camera_flat", v["lines"], cam.width_px, flat_ok=False)
    mean = frames.mean(axis=0)
    scale = 2 ** (cam.adc_bits - 8)
    black = cam.black_level_dn / scale
    if np.mean(mean >= 254.5) > 0.01:
        raise CalibrationError(f"{m.where('camera_flat', 'lines')}: {np.mean(mean >= 254.5) * 100:.0f} % of the "
                               f"flat field is clipped at 255: record it with a shorter exposure")
    signal = mean - black
    if np.median(signal) < 20.0:
        raise CalibrationError(f"{m.where('camera_flat', 'lines')}: the flat field reads {np.median(mean):.0f} "
                               f"(black level {black:.0f}): too dark to measure; light the card or expose longer")
    cos_t = row_cos_theta(cam)
    # dead pixels: far below the pixels around them (kept out of the fall-off fit)
    padded = np.pad(signal, 3, mode="reflect")
    around = np.array([np.median(np.delete(padded[i:i + 7], 3)) for i in range(len(signal))])
    dead = signal < DEAD_FRACTION * around
    use = ~dead

    def resid(x):
        return (x[0] * cos_t ** x[1] - signal)[use]

    sol = least_squares(resid, [float(np.max(signal)), 4.0], bounds=([1e-3, 0.0], [1e4, 12.0]))
    amp, power = (float(a) for a in sol.x)
    smooth = amp * cos_t ** power
    response = np.where(use, signal / np.maximum(smooth, 1e-9), 1.0)
    old_profile = np.asarray(cam.vignetting_profile, np.float64) if cam.vignetting_profile else np.ones(cam.width_px)
    new = dict(vignetting_power=power, vignetting_profile=tuple(float(r) for r in np.clip(response, 0.0, 10.0)),
               prnu=0.0, dead_pixels=int(round(np.count_nonzero(dead) * cam.height_px)))
    after = range_checked(car.replace(camera=dataclasses.replace(cam, **new)), m, "camera_flat")
    changes = {"camera.vignetting_power": (cam.vignetting_power, power),
               "camera.vignetting_profile": (len(cam.vignetting_profile), cam.width_px),  # how many values
               "camera.prnu": (cam.prnu, 0.0),
               "camera.dead_pixels": (cam.dead_pixels, new["dead_pixels"])}
    ends_meas = float(np.mean(signal[[0, 1, -2, -1]]) / np.mean(signal[cam.width_px // 2 - 2:cam.width_px // 2 + 2]))
    falloff = cos_t ** cam.vignetting_power * old_profile
    ends_before = float(np.mean(falloff[[0, 1, -2, -1]]) / np.mean(falloff[cam.width_px // 2 - 2:cam.width_px // 2 + 2]))
    fa = cos_t ** power * np.clip(response, 0.0, 10.0)
    ends_after = float(np.mean(fa[[0, 1, -2, -1]]) / np.mean(fa[cam.width_px // 2 - 2:cam.width_px // 2 + 2]))
    spread = float(np.std(response[use]))
    notes = (f"{len(frames)} frames; fall-off cos^{power:.2f}, pixel-to-pixel response spread {spread * 100:.1f} %; "
             f"{np.count_nonzero(dead)} dead pixel(s)"
             + (f" at {', '.join(str(int(c)) for c in np.flatnonzero(dead)[:8])}" if dead.any() else ""),)
    checks = (Check("line ends / centre (flat field)", "ratio", ends_meas, ends_before, ends_after),)
    return after, ProcedureResult("camera_flat", "flat field: fall-off toward the ends, each pixel's response, "
                                  "dead pixels", changes, checks, notes, {"power": power, "spread": spread})


def camera_sweep(car: CarDescription, m: Measurements, v: dict, dt_s: float):
    """``[camera_sweep]``: linearity, clipping exposure and the photon transfer curve."""

    car = _physical(car)
    cam = car.camera
    exposures = v["exposures_s"]
    if len(v["lines"]) != len(exposures):
        raise CalibrationError(f"{m.where('camera_sweep', 'lines')}: {len(v['lines'])} files for "
                               f"{len(exposures)} exposures: expected one file per exposure")
    w = cam.width_px
    centre = slice(w // 2 - 8, w // 2 + 8)
    scale = 2 ** (cam.adc_bits - 8)
    rows = []
    for t, name in sorted(zip(exposures, v["lines"])):
        frames = _lines(m, "camera_sweep", name, w, flat_ok=True)
        c = frames[:, centre]
        rows.append((t, float(c.mean()), float(np.mean(c.var(axis=0, ddof=1))) if len(frames) > 1 else 0.0))
    t = np.array([r[0] for r in rows])
    mu = np.array([r[1] for r in rows])
    var = np.array([r[2] for r in rows])
    linear = mu < 250.0
    if linear.sum() < 2:
        raise CalibrationError(f"{m.where('camera_sweep', 'exposures_s')}: fewer than 2 exposures below "
                               f"clipping: expected a sweep from dark to clipped")
    slope, icpt = np.polyfit(t[linear], mu[linear], 1)
    fit = slope * t[linear] + icpt
    nonlin = float(np.max(np.abs(fit - mu[linear])) / max(np.ptp(mu[linear]), 1e-9))
    clip_s = (250.0 - icpt) / slope if slope > 0 else math.inf
    notes = [f"signal {slope / 1000:.2f} counts per ms at the centre, {nonlin * 100:.1f} % from a straight line; "
             f"clips at about {clip_s * 1000:.1f} ms"]
    changes = {}
    after = car
    # the photon transfer curve needs temporal noise well above the 8-bit rounding (1/12 count^2):
    # at least 3 exposures, a rising straight line (correlation > 0.8)
    usable = linear & (var > 0.15)
    k8_new = None
    if usable.sum() >= 3:
        k_slope, _ = np.polyfit(mu[usable], var[usable], 1)
        r = float(np.corrcoef(mu[usable], var[usable])[0, 1])
        if k_slope > 0 and r > 0.8:
            k8_new = float(k_slope)
    if k8_new is not None:
        sat_e = cam.analog_gain * (2 ** cam.adc_bits - 1) / scale / k8_new
        sat_e = min(max(sat_e, 100.0), 1e9)
        changes["camera.saturation_capacity_e"] = (cam.saturation_capacity_e, sat_e)
        after = range_checked(car.replace(camera=dataclasses.replace(cam, saturation_capacity_e=sat_e)),
                               m, "camera_sweep")
        notes.append(f"photon transfer: {k8_new:.4g} counts per electron (8-bit), saturation capacity "
                     f"{sat_e:.4g} electrons")
    else:
        notes.append("photon transfer: the temporal noise is below what 8-bit lines show (fewer than 3 "
                     "exposures with a variance above 0.15 count^2 on a rising line): "
                     "camera.saturation_capacity_e kept")
    checks = (Check("counts per electron (8-bit)", "1/e", k8_new if k8_new is not None else math.nan,
                    _k8(cam), _k8(after.camera)),)
    return after, ProcedureResult("camera_sweep", "exposure sweep: linearity, clipping, photon transfer",
                                  changes, checks, tuple(notes), {"slope_counts_per_s": float(slope),
                                                                  "clip_s": float(clip_s)})
